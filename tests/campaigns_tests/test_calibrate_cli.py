"""`fpr calibrate` end to end: a problem file pointing at a CSV in engineering units, and a dataset.

The CSV is written from a synthetic maneuver the way a user would bring flight data: degrees,
knots, feet, g, a header with their own column names, a time column that does not start at zero.
The command must read it through the documented problem file, converge, write its results, and
recover the injected IMU biases within three Cramér-Rao deviations.
"""

from __future__ import annotations

import contextlib
import io
import json
import shutil

import numpy as np
import pandas as pd
import pytest
from _campaigns import linear_campaign

from campaigns.benchmarks.user_files import USER_COLUMNS, write_user_files
from campaigns.cli import EXIT_STATUS, main
from synth.dataset import load_dataset

CAMPAIGN = linear_campaign("cli", 5, [
    {"configurations": ["PV1-NP"], "mach": [0.6], "maneuvers": ["pitch_doublet", "pullup_rudder_doublets"],
     "altitude_m": 6000.0}], wind_ned_mps=[4.0, 2.0, 0.0], quiet_imu=True)


@pytest.fixture(scope="module")
def dataset(fly_once):
    return fly_once(CAMPAIGN, "cli")


@pytest.fixture(scope="module")
def dataset_run(dataset, tmp_path_factory):
    """``fpr calibrate DATASET --single --free h0`` with its figures, once for the module:
    ``(exit status, standard output, results folder)``. Shared: copy the folder before writing
    into it. The figures take most of a run's time; the estimation itself is under a second."""
    out = tmp_path_factory.mktemp("cli-dataset-run") / "res"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(["calibrate", str(dataset), "--single", "--free", "h0", "--out", str(out)])
    return code, buf.getvalue(), out


def _write_user_files(ds_dir, tmp_path):
    """One CSV of both maneuvers end to end (user units and names) and its problem file
    (:func:`campaigns.benchmarks.user_files.write_user_files`)."""
    channels = ["phi", "theta", "psi", "tas", "h", "alpha_zl", "alpha_zr"]
    columns = {k: USER_COLUMNS[k] for k in ("ax", "ay", "az", "p", "q", "r", *channels)}
    problem = write_user_files(ds_dir, tmp_path / "user", columns, channels, "CLI test flight",
                               sensors=("imu", "vane_left", "vane_right"),
                               tail="\n[parameter.h0]\nfree = true\n")
    return problem, load_dataset(ds_dir)


@pytest.mark.slow
def test_calibrate_a_problem_file_of_user_data(dataset, tmp_path, capsys):
    problem, ds = _write_user_files(dataset, tmp_path)
    out = tmp_path / "results"
    code = main(["calibrate", str(problem), "--single", "--out", str(out), "--no-plots"])
    text = capsys.readouterr().out
    for name in ("result.json", "parameters.csv", "residuals.csv", "correlation.csv", "findings.csv"):
        assert (out / name).exists(), name
    doc = json.loads((out / "result.json").read_text())
    # the exit status carries the verdict, which must be a success here (clean data, linear flow)
    assert doc["status"] > 0 and doc["verdict_code"] > 0, text
    assert code == EXIT_STATUS[doc["verdict"]], text
    params = pd.read_csv(out / "parameters.csv", index_col="key")
    inj = ds.manifest["maneuvers"][0]["injected"]
    truth = dict(zip(("dax", "day", "daz"), inj["imu.accel_bias_mps2"], strict=True))
    truth |= dict(zip(("dp", "dq", "dr"), inj["imu.gyro_bias_rps"], strict=True))
    # every IMU bias the data determine lies within 3 Cramér-Rao deviations of the truth; the
    # longitudinal ones must be determined in every maneuver (the lateral ones of a pitch doublet
    # with only AOA channels may be held as undetermined: their deviation is then NaN)
    for entry in ds.manifest["maneuvers"]:
        mid = entry["id"]
        for name, value in truth.items():
            row = params.loc[f"{name}[{mid}]"]
            if name in ("dax", "daz", "dq"):
                assert np.isfinite(row.std_crb), f"{name}[{mid}] not estimated"
            if np.isfinite(row.std_crb):
                z = (row.value - value) / row.std_crb
                assert abs(z) < 3, f"{name}[{mid}]: z = {z:.2f}"


@pytest.mark.slow
def test_calibrate_a_dataset_writes_the_recovery_table(dataset_run):
    code, text, out = dataset_run
    # a pitch doublet and a pull-up with rudder doublets: nothing separates the sideslip sensors'
    # biases from each maneuver's initial sideslip but kinematic couplings; the verdict says so
    assert code == EXIT_STATUS["SUCCESS_WITH_WARNINGS"], text
    assert "b_sb[PV1] is confounded with the initial condition(s) v0[m0000], v0[m0001]" in text
    assert "recovery against the injected truth" in text
    rec = pd.read_csv(out / "recovery.csv", index_col=0)
    delays = rec[rec["kind"] == "time_delay"]
    assert len(delays) >= 5 and np.all(np.abs(delays["z_crb"]) < 3), delays
    assert (out / "time_history_match.png").stat().st_size > 10_000


def test_calibrate_says_what_is_wrong_with_a_missing_file(tmp_path, capsys):
    bad = tmp_path / "p.toml"
    bad.write_text('[sensors]\nimu = [0, 0, 0]\n[[files]]\npath = "nope.csv"\n')
    assert main(["calibrate", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "nope.csv" in capsys.readouterr().err


@pytest.mark.slow
def test_calibrate_never_mixes_results_of_two_runs(dataset, dataset_run, tmp_path, capsys):
    # the first run: the module's run with its figures, copied (its listing, .fpr-written.json,
    # with it: the folder is exactly what that run left)
    first_code, _, first = dataset_run
    assert first_code in (0, 3)
    out = tmp_path / "res"
    shutil.copytree(first, out)
    assert (out / "recovery.csv").exists() and (out / "time_history_match.png").exists()
    # a second run into the same directory must be asked for, and then replaces everything
    assert main(["calibrate", str(dataset), "--single", "--out", str(out), "--no-plots"]) == 2
    assert "--overwrite" in capsys.readouterr().err
    again = ["calibrate", str(dataset), "--single", "--out", str(out), "--no-plots", "--overwrite",
             "--no-colored"]
    assert main(again) in (0, 3)  # a success: with or without warnings
    assert not (out / "time_history_match.png").exists(), "a stale figure survived"
    # the tables are the second run's: h0 was free in the first run only
    params = pd.read_csv(out / "parameters.csv", index_col="key")
    assert not params.loc[params["name"] == "h0", "free"].any(), "a stale parameters.csv survived"
    assert (out / "recovery.csv").exists()
    # a directory holding anything else is never touched
    other = tmp_path / "mine"
    other.mkdir()
    (other / "notes.txt").write_text("keep me")
    assert main(["calibrate", str(dataset), "--single", "--out", str(other), "--overwrite"]) == 2
    assert (other / "notes.txt").exists()
