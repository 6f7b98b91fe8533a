"""``fpr example``: the small flight a user tries first (campaigns/example.py).

It writes three CSV files and the problem file naming them; the problem reads with the drone's
channels; one estimation recovers the injected calibration within 3 Cramér-Rao deviations (the
flight is analytic: the injected errors and white noise are all the files hold); the same seed
writes the same bytes; a folder already holding the example's files is refused, untouched.
"""

from __future__ import annotations

import warnings

import pytest

from campaigns.cli import main
from campaigns.example import B_A_DEG, B_B_DEG, C_A_DEG, D2R, EXAMPLE_FILES, K_A, K_B, TAU_S
from estimator.io import load_problem
from estimator.solver import SolverOptions, estimate

Z_MAX = 3.0  # Cramér-Rao deviations: the noise is white, the model exact


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    folder = tmp_path_factory.mktemp("example")
    assert main(["example", str(folder)]) == 0
    return folder


def test_the_example_reads_as_a_users_flight(example):
    assert sorted(p.name for p in example.iterdir()) == sorted(EXAMPLE_FILES)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # every channel has data: nothing to warn about
        problem = load_problem(example / "uav.toml")
    assert [m.id for m in problem.maneuvers] == ["U1_0", "U1_1", "U1_2"]
    assert sum(m.n for m in problem.maneuvers) == 2103
    assert [c.name for c in problem.channels] == ["phi", "theta", "psi", "tas", "h", "alpha_v", "beta_v"]


def test_one_estimation_recovers_the_injected_calibration(example):
    res = estimate(load_problem(example / "uav.toml"), SolverOptions())
    assert res.success, res.message
    # one aircraft: c_a is held at 0 and b_a carries the fleet offset too
    truth = {"b_a[U1]": (B_A_DEG["U1"] + C_A_DEG) * D2R, "b_b[U1]": B_B_DEG["U1"] * D2R, "k_a": K_A,
             "k_b": K_B, "tau_a": TAU_S["a"], "tau_b": TAU_S["b"], "tau_tas": TAU_S["tas"]}
    z = {k: (res.value(k) - v) / res.std(k) for k, v in truth.items()}
    assert all(abs(v) < Z_MAX for v in z.values()), z


def test_the_same_seed_writes_the_same_bytes_and_a_taken_folder_is_refused(example, tmp_path, capsys):
    assert main(["example", str(tmp_path)]) == 0
    for name in EXAMPLE_FILES:
        assert (tmp_path / name).read_bytes() == (example / name).read_bytes(), name
    before = {n: (tmp_path / n).read_bytes() for n in EXAMPLE_FILES}
    assert main(["example", str(tmp_path), "--seed", "3"]) == 2
    assert "already exist" in capsys.readouterr().err
    assert {n: (tmp_path / n).read_bytes() for n in EXAMPLE_FILES} == before
    # a file where the folder should be: refused, saying what to give instead
    assert main(["example", str(tmp_path / "uav.toml")]) == 2
    assert "give a folder" in capsys.readouterr().err
