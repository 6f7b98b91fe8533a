"""Monte Carlo engine (issue 5): determinism, resume after interruption, failures, Dask = local.

A tiny scenario: one configuration, two 20 s maneuvers at Mach 0.6, the attitude, air-data and
vane channels only, the vane tables fixed (a few free calibration parameters), drawn IMU biases and
vane delays. A replication takes about a second.
"""

from __future__ import annotations

import copy
import json
import shutil
import tomllib

import numpy as np
import pandas as pd
import pytest

from campaigns import montecarlo_cli
from campaigns.montecarlo import ScenarioError, parse_scenario, run_montecarlo, runner, summarize
from campaigns.montecarlo import replication as replication_module
from campaigns.montecarlo.runner import finished_replications, read_replication, replication_file

RAW = {
    "name": "mc_test",
    "seed": 31,
    "replications": 4,
    "local_flow_truth": "local_flow_linear",
    "adc_baseline": "adc_baseline_linear",
    "environment": {"planet": "flat", "wind_ned_mps": [5.0, -3.0, 0.0], "turbulence": "none"},
    "errors": {"preset": "typical", "nose_probe_irregularity": False},
    "flights": [{"configurations": ["PV1-NP"], "mach": [0.6], "maneuvers": ["pitch_doublet", "3211"],
                 "maneuver": {"duration_s": 20.0}}],
    "draw": {"errors": {
        "imu.accel_bias_mps2": {"dist": "normal", "std": 0.05, "scope": "maneuver"},
        "sensors.vane_left.delay_ms": {"dist": "uniform", "half_width": 15.0},
    }},
    "estimator": {
        "channels": ["phi", "theta", "psi", "tas", "h", "h_dgps", "alpha_zl", "alpha_zr"],
        # two short longitudinal maneuvers leave k_h held and v0 barely determined: the solver
        # then creeps (40 iterations were not always enough; 100 always were, at ~10 ms each)
        "max_iterations": 100,
        "parameters": {"f1": {"free": False}, "f2": {"free": False}},
    },
}


def _scenario(**changes):
    raw = copy.deepcopy(RAW)
    raw.update(changes)
    return parse_scenario(raw, source="test_montecarlo")


def _tables(out, indices):
    return {k: read_replication(replication_file(out, k)).to_pandas() for k in indices}


@pytest.fixture(scope="module")
def base_run(tmp_path_factory):
    """Replications 0..2 in this process; the reference every other run is compared with."""
    out = tmp_path_factory.mktemp("mc") / "base"
    report = run_montecarlo(_scenario(), out, replications=3, workers=1)
    return out, report


def test_scenario_draws_are_deterministic_and_differ_between_replications():
    s = _scenario()
    a, b, again = s.draw(0), s.draw(1), s.draw(0)
    assert a.values == again.values and a.noise_seed == again.noise_seed
    assert a.noise_seed != b.noise_seed
    assert a.maneuvers[0].errors.seeds != b.maneuvers[0].errors.seeds
    va = dict(((p, i, c), v) for p, i, c, v in a.values)
    vb = dict(((p, i, c), v) for p, i, c, v in b.values)
    assert va.keys() == vb.keys() and all(va[k] != vb[k] for k in va)
    # per-maneuver scope: each maneuver its own accelerometer bias; per-replication: one vane delay
    acc = [md.errors.imu.accel_bias_mps2 for md in a.maneuvers]
    assert acc[0] != acc[1]
    delays = {md.errors.sensors["vane_left"].delay_s for md in a.maneuvers}
    assert len(delays) == 1 and abs(delays.pop() - 0.030) <= 0.015
    # calm air, nothing drawn in the environment: every maneuver is flown once for all replications
    assert len(s.fixed_jobs) == 2


def test_drawn_wind_and_turbulence_are_reflown_per_replication():
    s = _scenario(environment={"planet": "flat", "turbulence": "light"},
                  draw={"environment": {"wind_ned_mps": {"dist": "uniform", "half_width": [8.0, 8.0, 0.0]}}})
    assert not s.fixed_jobs
    e0, e1 = s.draw(0).maneuvers[0].environment, s.draw(1).maneuvers[0].environment
    assert e0.wind_ned_mps != e1.wind_ned_mps and e0.turbulence_seed != e1.turbulence_seed
    assert e0.wind_ned_mps[2] == 0.0 and max(abs(w) for w in e0.wind_ned_mps) <= 8.0


@pytest.mark.parametrize("change, message", [
    ({"draw": {"errors": {"imu.acel_bias_mps2": {"dist": "normal", "std": 0.1}}}}, "imu.acel_bias_mps2"),
    ({"draw": {"errors": {"imu.accel_bias_mps2": {"dist": "normal"}}}}, "needs std"),
    ({"draw": {"errors": {"imu.accel_bias_mps2": {"dist": "normal", "std": [1, 2]}}}}, "has 2 values"),
    ({"errors": {"preset": "typical", "seeds": {"imu_noise": 3}}}, "same noise"),
    ({"replications": 0}, "replications"),
])
def test_bad_scenarios_are_refused_with_the_key_named(change, message):
    with pytest.raises(ScenarioError, match=message):
        _scenario(**change)


def test_same_seed_gives_identical_replications_in_any_order(base_run, tmp_path):
    out, report = base_run
    assert report.ran == (0, 1, 2) and report.flights_flown == 2 and not report.failed
    # a second run, in another directory, of replications 2 and 0 only: bit-identical tables
    other = tmp_path / "other"
    run_montecarlo(_scenario(), other, replications=3, workers=1, indices=[2, 0])
    assert sorted(finished_replications(other)) == [0, 2]
    ref, again = _tables(out, (0, 2)), _tables(other, (0, 2))
    for k in (0, 2):
        pd.testing.assert_frame_equal(ref[k], again[k], check_exact=True)
    # different replications: different draws, noise and estimates
    r0, r1 = (read_replication(replication_file(out, k)) for k in (0, 1))
    assert r0.noise_seed != r1.noise_seed
    assert not np.array_equal(r0.draws["value"], r1.draws["value"])
    p0, p1 = (r.parameters.set_index("name") for r in (r0, r1))
    determined = np.isfinite(p0["std_crb"])  # the others are held at their start values
    assert determined.sum() > 20 and (p0["estimate"][determined] != p1["estimate"][determined]).all()
    # the tables hold what the summary needs: free calibration parameters with truth and deviations
    p = r0.parameters.set_index("name")
    assert {"b_l[PV1]", "b_r[PV1]", "tau_alpha_zl", "dax[m0000]"} <= set(p.index)
    assert np.isfinite(p.loc["b_l[PV1]", ["truth", "std_crb", "std_colored", "z_crb"]].astype(float)).all()
    ch = r0.channels.set_index(["name", "kind"])
    assert ("alpha_zl", "calibrated") in ch.index and ("theta", "residual") in ch.index
    assert 0.0 < ch.loc[("alpha_zl", "calibrated"), "three_sigma"] < 1.0  # deg


def test_interrupted_run_resumes_to_exactly_n_files(base_run, tmp_path, monkeypatch):
    out = tmp_path / "resume"
    scenario = _scenario()
    run_montecarlo(scenario, out, workers=1, indices=[0, 1])
    first = {k: (replication_file(out, k).stat().st_mtime_ns, replication_file(out, k).read_bytes())
             for k in (0, 1)}
    real = runner.replication_task

    def killed_at_3(payload, index, truths):
        if index == 3:
            raise KeyboardInterrupt  # the operator's Ctrl-C (or a kill) in the middle of the run
        return real(payload, index, truths)

    monkeypatch.setattr(runner, "replication_task", killed_at_3)
    with pytest.raises(KeyboardInterrupt):
        run_montecarlo(scenario, out, workers=1)
    assert sorted(finished_replications(out)) == [0, 1, 2]
    monkeypatch.setattr(runner, "replication_task", real)
    # the same command again, now with two worker processes: only 3 is left to do
    report = run_montecarlo(scenario, out, workers=2)
    assert report.ran == (3,) and report.skipped == 3 and report.flights_flown == 0
    files = sorted(p.name for p in (out / "replications").iterdir())
    assert files == [f"r{k:05d}.parquet" for k in range(4)]  # exactly N, no duplicates, no tmp files
    for k, (mtime, data) in first.items():
        assert replication_file(out, k).stat().st_mtime_ns == mtime
        assert replication_file(out, k).read_bytes() == data
    # the worker processes computed what this process computed for the reference run
    ref, ours = _tables(base_run[0], (0, 1, 2)), _tables(out, (0, 1, 2))
    for k in ref:
        pd.testing.assert_frame_equal(ref[k], ours[k], check_exact=True)
    assert run_montecarlo(scenario, out, workers=1).ran == ()  # nothing left


def test_failed_replication_is_recorded_and_others_continue(tmp_path, monkeypatch):
    out = tmp_path / "fail"
    real = replication_module.run_replication

    def broken_at_1(scenario, index, truths, models=None):
        if index == 1:
            raise RuntimeError("instrument exploded in replication 1")
        return real(scenario, index, truths, models)

    monkeypatch.setattr(replication_module, "run_replication", broken_at_1)
    report = run_montecarlo(_scenario(), out, replications=3, workers=1)
    assert report.failed == (1,) and report.ran == (0, 1, 2)
    assert finished_replications(out) == {0: "ok", 1: "failed", 2: "ok"}
    record = json.loads(replication_file(out, 1, failed=True).read_text())
    assert record["status"] == -1 and "instrument exploded in replication 1" in record["message"]
    assert "Traceback" in record["message"] and record["noise_seed"] == _scenario().draw(1).noise_seed
    summary = summarize(out)
    assert summary.n_ok == 2 and summary.n_failed == 1
    assert "instrument exploded" in summary.text()
    # a resume skips it; --retry-failed runs it again and the failure record goes
    monkeypatch.setattr(replication_module, "run_replication", real)
    assert run_montecarlo(_scenario(), out, replications=3, workers=1).ran == ()
    again = run_montecarlo(_scenario(), out, replications=3, workers=1, retry_failed=True)
    assert again.ran == (1,) and not again.failed
    assert sorted(p.name for p in (out / "replications").iterdir()) == [f"r{k:05d}.parquet" for k in range(3)]


def test_non_converged_estimation_is_a_failure_with_the_estimators_message(tmp_path):
    raw_est = dict(RAW["estimator"], max_iterations=1)
    report = run_montecarlo(_scenario(estimator=raw_est), tmp_path / "nc", replications=1, workers=1)
    assert report.failed == (0,)
    record = json.loads(replication_file(tmp_path / "nc", 0, failed=True).read_text())
    assert record["status"] == 0 and "iteration limit" in record["message"]


def test_another_scenario_is_refused_in_the_same_directory(base_run):
    out, _ = base_run
    with pytest.raises(ScenarioError, match="another scenario"):
        run_montecarlo(_scenario(seed=32), out, replications=3, workers=1)


def test_summary_and_cli(base_run, capsys):
    out, _ = base_run
    summary = summarize(out)
    table = summary.to_pandas()
    assert summary.n_ok == 3 and set(table.loc["b_l[PV1]", ["bias", "rmse", "mc_std", "ratio_crb"]].index)
    row = table.loc["b_l[PV1]"]
    assert row["n"] == 3 and row["rmse"] >= abs(row["bias"]) and row["ratio_crb"] > 0
    assert np.isclose(row["ratio_crb"], row["mc_std"] / row["crb_mean"])
    parser = montecarlo_cli.argparse.ArgumentParser()
    montecarlo_cli.add_parser(parser.add_subparsers(dest="command"))
    status = montecarlo_cli.run(parser.parse_args(["montecarlo-summary", str(out)]))
    text = capsys.readouterr().out
    assert status == 0 and "b_l[PV1]" in text and "ratio_crb" in text and "alpha_zl" in text
    assert (out / "summary.png").stat().st_size > 10_000 and (out / "summary_parameters.csv").exists()


def test_dask_local_cluster_gives_the_local_results(base_run, tmp_path):
    distributed = pytest.importorskip("dask.distributed", reason="dask[distributed] is not installed")
    out = tmp_path / "dask"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        report = run_montecarlo(_scenario(), out, replications=3, scheduler=cluster.scheduler_address)
    assert report.executor.startswith("dask(") and report.ran == (0, 1, 2) and not report.failed
    ref, ours = _tables(base_run[0], (0, 1, 2)), _tables(out, (0, 1, 2))
    for k in ref:
        pd.testing.assert_frame_equal(ref[k], ours[k], check_exact=True)


SCENARIO_TOML = """
name = "mc_test"
seed = 31
replications = 4
local_flow_truth = "local_flow_linear"
adc_baseline = "adc_baseline_linear"
[environment]
planet = "flat"
wind_ned_mps = [5.0, -3.0, 0.0]
turbulence = "none"
[errors]
preset = "typical"
nose_probe_irregularity = false
[[flights]]
configurations = ["PV1-NP"]
mach = [0.6]
maneuvers = ["pitch_doublet", "3211"]
maneuver = { duration_s = 20.0 }
[draw.errors]
"imu.accel_bias_mps2" = { dist = "normal", std = 0.05, scope = "maneuver" }
"sensors.vane_left.delay_ms" = { dist = "uniform", half_width = 15.0 }
[estimator]
channels = ["phi", "theta", "psi", "tas", "h", "h_dgps", "alpha_zl", "alpha_zr"]
max_iterations = 100
parameters = { f1 = { free = false }, f2 = { free = false } }
"""


def test_cli_resumes_a_run_from_the_scenario_file(base_run, tmp_path, capsys):
    assert tomllib.loads(SCENARIO_TOML) == RAW  # the file is the scenario of base_run
    path = tmp_path / "mc_test.toml"
    path.write_text(SCENARIO_TOML)
    out = tmp_path / "cli"
    shutil.copytree(base_run[0], out)  # replications 0..2 done; the file asks for 4
    status = montecarlo_cli.main(["montecarlo", str(path), "--out", str(out), "--workers", "1"])
    text = capsys.readouterr().out
    assert status == 0, text
    assert "1 replications run now, 3 already done, 4 requested" in text and "tau_alpha_zl" in text
    assert sorted(finished_replications(out)) == [0, 1, 2, 3]
    assert (out / "summary.txt").read_text().startswith("Monte Carlo mc_test: 4 replications, 4 converged")
    # a scenario that is not this one is refused, with the way out named
    path.write_text(SCENARIO_TOML.replace("seed = 31", "seed = 30"))
    assert montecarlo_cli.main(["montecarlo", str(path), "--out", str(out), "--workers", "1"]) == 2
    assert "another scenario" in capsys.readouterr().err
