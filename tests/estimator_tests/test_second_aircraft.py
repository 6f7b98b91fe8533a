"""A second aircraft calibrated with no Python edited (issue 12, must-show 2).

``estimator/models/uav_example.toml`` declares a fleet of jet target drones: one angle-of-attack
vane, one sideslip vane, a pitot-static airspeed, an INS and a height, each vane with a bias and
a scale factor, and everything the workflow and its report need (Table 2's rows, the bias family
to apportion, the reference Mach, the initial conditions' sources, the figures' channels). No
Python names its channels.

The data are made as a user's would come, by the pieces of ``fpr example``
(``campaigns/example.py``): CSV files (angles in deg, rates in deg/s) and a problem file naming the
model set. The flight is the analytic one of ``campaigns/analytic_flight.py``
(states and IMU inputs that satisfy the state equations exactly): three aircraft, four maneuvers
each, two at 500 m (Mach 0.44: the Mach 0.4 bin) and two at 8000 m (Mach 0.49: the 0.5 bin); each
vane reads its model with the injected installation biases, fleet offset, scale factors and time
shifts, every channel with white noise, the IMU with biases and no noise (the output-error method
has no process noise). Then:

- ``load_problem`` reads it with the UAV's channels and the model set's declarations, and starts
  the initial conditions from the UAV's vanes;
- the single estimation recovers every calibration parameter within 3 Cramér-Rao deviations;
- the workflow splits the vane biases into the fleet mean and installation biases (within
  3 deviations of the truth), re-estimates the fleet's offset with them held, and its Table 2 and
  report name the UAV's sensors and draw its figures at the model set's reference Mach 0.4;
- ``fpr calibrate`` on the problem file does the same.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pandas as pd
import pytest

from campaigns.example import (
    B_A_DEG,
    B_B_DEG,
    C_A_DEG,
    D2R,
    K_A,
    K_B,
    TAU_S,
    uav_maneuver,
    write_problem_file,
)
from estimator.io import load_problem
from estimator.io.modelset import declarations_of

ALTITUDES_M = (500.0, 8000.0)
Z_MAX = 3.0


@pytest.fixture(scope="module")
def uav_problem_file(tmp_path_factory):
    """The fleet's CSV files and problem file (seed 12); returns its path and the true Mach means."""
    folder = tmp_path_factory.mktemp("uav")
    rng = np.random.default_rng(12)
    files, machs = [], {}
    for ac in B_A_DEG:
        for k, h0 in enumerate(ALTITUDES_M * 2):
            name = f"{ac}_{k}"
            df, machs[name] = uav_maneuver(rng, h0, t0_s=7.0 * k + 3.0 * int(ac[1]), aircraft=ac)
            df.to_csv(folder / f"{name}.csv", index=False)
            files.append((f"{name}.csv", ac))
    path = write_problem_file(folder / "uav.toml", files, "UAV fleet, hand-made data")
    return path, machs


@pytest.fixture(scope="module")
def problem(uav_problem_file):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # every channel has data: nothing to warn about
        return load_problem(uav_problem_file[0])


@pytest.mark.slow
def test_the_problem_file_reads_with_the_uav_channels_and_declarations(problem, uav_problem_file):
    assert [c.name for c in problem.channels] == ["phi", "theta", "psi", "tas", "h", "alpha_v", "beta_v"]
    decl = declarations_of(problem)
    assert decl.source.endswith("uav_example.toml")
    assert {c: r.sensor for c, r in decl.requirements.items()} == {"alpha_v": "AOA vane",
                                                                  "beta_v": "sideslip vane"}
    assert decl.apportion == {"vane": "b_a"} and decl.reference_mach == 0.4
    # the Mach bins the workflow will find: 0.4 at 500 m, 0.5 at 8000 m
    machs = uav_problem_file[1]
    assert {round(m, 1) for m in machs.values()} == {0.4, 0.5}
    # the initial conditions start from the UAV's vanes (the model set's [initial_conditions]):
    # w0 = V sin(alpha) within what the vane's bias and scale and the noise allow
    ps = problem.parameters
    for m in problem.maneuvers:
        w0 = ps[f"w0[{m.id}]"].value
        v0 = ps[f"v0[{m.id}]"].value
        alpha = np.mean(m.measurements["alpha_v"][:5])
        beta = np.mean(m.measurements["beta_v"][:5])
        tas = np.mean(m.measurements["tas"][:5])
        assert w0 == pytest.approx(tas * math.sin(alpha) * math.cos(beta))
        assert v0 == pytest.approx(tas * math.sin(beta))
        assert abs(alpha) > 0.01  # a real angle of attack, not the no-source default of 0


@pytest.mark.slow
def test_the_single_estimation_recovers_the_uav_calibration(problem):
    from estimator.solver import SolverOptions, estimate

    res = estimate(problem, SolverOptions())
    assert res.success, res.message
    # with every aircraft's b_a free, c_a is held at 0 and each b_a carries the fleet offset too
    truth = {**{f"b_a[{a}]": (b + C_A_DEG) * D2R for a, b in B_A_DEG.items()},
             **{f"b_b[{a}]": b * D2R for a, b in B_B_DEG.items()},
             "k_a": K_A, "k_b": K_B, "tau_a": TAU_S["a"], "tau_b": TAU_S["b"], "tau_tas": TAU_S["tas"]}
    z = {k: (res.value(k) - v) / res.std(k) for k, v in truth.items()}
    assert all(abs(v) < Z_MAX for v in z.values()), z
    assert res.value("c_a") == 0.0


@pytest.fixture(scope="module")
def workflow(problem):
    from estimator.workflow import run_workflow

    return run_workflow(problem)


@pytest.mark.slow
def test_the_workflow_apportions_the_uav_vane_and_names_its_sensors(workflow):
    wf = workflow
    assert wf.success, [f.text() for f in wf.findings]
    used = wf.maneuvers[wf.maneuvers["used"]]
    assert sorted(used["bin"].unique()) == [0.4, 0.5]
    # installation biases: b_a minus the fleet mean, taken at the model set's reference Mach
    inst = wf.installation
    assert set(inst["mach"]) == {0.4} and wf.reference_mach == 0.4
    mean_b = np.mean(list(B_A_DEG.values()))
    for a, b in B_A_DEG.items():
        est, std = inst.loc[a, "installation_vane_deg"], inst.loc[a, "std_installation_vane_deg"]
        assert abs(est - (b - mean_b)) < Z_MAX * std, (a, est, b - mean_b, std)
    assert {"b_a_deg", "mean_bias_deg", "fleet_mean_deg"} <= set(wf.vane_bias.columns)
    # with the installation biases held, c_a takes the fleet mean: c_a + mean(b_a)
    for st in wf.final:
        r = st.result
        assert abs(r.value("c_a") - (C_A_DEG + mean_b) * D2R) < Z_MAX * r.std("c_a"), st.mach
        assert not r.parameters.free_mask[r.parameters.index("b_a[U1]")]
    # Table 2: the UAV's sensors, within their desired accuracy (3 x 0.05 deg of noise)
    acc = wf.accuracy
    assert set(acc["sensor"]) == {"AOA vane", "sideslip vane"}
    assert set(acc["channel"]) == {"alpha_v", "beta_v"}
    assert acc["passed"].all() and (acc["three_sigma_deg"] < 0.25).all(), acc
    assert wf.alpha_limit_deg is None and wf.alpha_limit_growth.empty  # no usable-alpha channel


@pytest.mark.slow
def test_the_report_shows_the_uav_channels_at_its_reference_mach(workflow, tmp_path):
    from estimator.calibration import build_report

    out = build_report(workflow, tmp_path / "report", "UAV fleet")
    page = out["report"].read_text()
    for frag in ("AOA vane", "sideslip vane", "Fig. 5: alpha_v measurement - model vs model at Mach 0.40",
                 "Fig. 5: beta_v measurement - model vs model at Mach 0.40", "average vane bias b_a",
                 "Time-history match"):
        assert frag in page, frag
    for name in ("alpha_zl", "beta_znp", "b_l", "nose-probe"):  # nothing of the other aircraft
        assert name not in page, name
    t2 = pd.read_csv(tmp_path / "report" / "table2_model.csv")
    assert set(t2["sensor"]) == {"AOA vane", "sideslip vane"}
    inst = pd.read_csv(tmp_path / "report" / "installation_biases.csv")
    assert "installation_vane_deg" in inst.columns


@pytest.mark.slow
def test_fpr_calibrate_runs_the_uav_problem_file(uav_problem_file, tmp_path, capsys):
    from campaigns.cli import EXIT_STATUS, main

    out = tmp_path / "cli"
    # no --reference-mach: the model set's 0.4 is the default
    code = main(["calibrate", str(uav_problem_file[0]), "--out", str(out)])
    text = capsys.readouterr().out
    assert code in (EXIT_STATUS["SUCCESS"], EXIT_STATUS["SUCCESS_WITH_WARNINGS"]), text
    assert "AOA vane" in text and "sideslip vane" in text, text
    t2 = pd.read_csv(out / "table2_model.csv")
    assert set(t2["sensor"]) == {"AOA vane", "sideslip vane"} and t2["passed"].all()
    assert set(pd.read_csv(out / "installation_biases.csv")["mach"]) == {0.4}
