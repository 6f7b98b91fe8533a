"""Monte Carlo engine (issue 5): determinism, resume after interruption, failures, Dask = local;
the summary (issue 10): per-kind coverage, held parameters, verdicts, the accuracy definition.

A tiny scenario: one configuration, two 20 s maneuvers at Mach 0.6, the attitude, air-data and
vane channels only, the vane tables fixed (a few free calibration parameters), drawn IMU biases and
vane delays. A replication takes about half a second. The summary's statistics are also checked on
small synthetic replication tables, where every number is known.
"""

from __future__ import annotations

import copy
import json
import math
import shutil
import tomllib
import warnings

import numpy as np
import pandas as pd
import pytest

from campaigns import montecarlo_cli, workflow_truth
from campaigns.montecarlo import (
    ReplicationResult,
    ScenarioError,
    parse_scenario,
    run_montecarlo,
    runner,
    summarize,
    summarize_results,
)
from campaigns.montecarlo import replication as replication_module
from campaigns.montecarlo.flight_cache import flight_file, read_flight
from campaigns.montecarlo.runner import finished_replications, read_replication, replication_file
from campaigns.montecarlo.summary import kind_table, load_results
from estimator import StateEquations, problem_from_dataset, workflow

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
        # converged once a step would gain less than one log-likelihood unit (the default, 1e-3,
        # only creeps on here): these tests are about the engine's files, processes and tables,
        # not the last digits of the estimates, and a replication takes half the time
        "solver": {"decrease_tol": 1.0},
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


@pytest.mark.slow
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
    # the parameters both estimated (a held one is left out of the table, or has no deviation)
    both = [k for k in p0.index.intersection(p1.index)
            if np.isfinite(p0.loc[k, "std_crb"]) and np.isfinite(p1.loc[k, "std_crb"])]
    assert len(both) > 20 and (p0.loc[both, "estimate"] != p1.loc[both, "estimate"]).all()
    # the tables hold what the summary needs: free calibration parameters with truth and deviations
    p = r0.parameters.set_index("name")
    assert {"b_l[PV1]", "b_r[PV1]", "tau_alpha_zl", "dax[m0000]"} <= set(p.index)
    assert np.isfinite(p.loc["b_l[PV1]", ["truth", "std_crb", "std_colored", "z_crb"]].astype(float)).all()
    ch = r0.channels.set_index(["name", "kind"])
    assert ("alpha_zl", "calibrated") in ch.index and ("theta", "residual") in ch.index
    assert 0.0 < ch.loc[("alpha_zl", "calibrated"), "three_sigma"] < 1.0  # deg
    # the estimator's verdict is recorded beside its solver status
    for r in (r0, r1):
        assert r.verdict_code in (1, 2) and r.n_failures == 0 and r.n_warnings == len(r.findings)
        assert r.meta()["verdict"] in ("success", "success with warnings")


@pytest.mark.slow
def test_interrupted_run_resumes_to_exactly_n_files(base_run, tmp_path, monkeypatch):
    # N = 3, base_run's: replication 0 by a first run, 1 by a run interrupted at 2, 2 by the resume
    # in worker processes, so that each of the three runs writes one and the worker's is compared
    out = tmp_path / "resume"
    scenario = _scenario(replications=3)
    run_montecarlo(scenario, out, workers=1, indices=[0])

    def stamp(k):
        return replication_file(out, k).stat().st_mtime_ns, replication_file(out, k).read_bytes()

    first = {0: stamp(0)}
    real = runner.replication_task

    def killed_at_2(payload, index, truths):
        if index == 2:
            raise KeyboardInterrupt  # the operator's Ctrl-C (or a kill) in the middle of the run
        return real(payload, index, truths)

    monkeypatch.setattr(runner, "replication_task", killed_at_2)
    with pytest.raises(KeyboardInterrupt):
        run_montecarlo(scenario, out, workers=1)
    assert sorted(finished_replications(out)) == [0, 1]
    assert stamp(0) == first[0]  # a finished replication is not run again
    first[1] = stamp(1)
    monkeypatch.setattr(runner, "replication_task", real)
    # the same command again, now with two worker processes: only 2 is left to do
    report = run_montecarlo(scenario, out, workers=2)
    assert report.ran == (2,) and report.skipped == 2 and report.flights_flown == 0
    files = sorted(p.name for p in (out / "replications").iterdir())
    assert files == [f"r{k:05d}.parquet" for k in range(3)]  # exactly N, no duplicates, no tmp files
    for k, before in first.items():
        assert stamp(k) == before
    # each run computed what this process computed for the reference run (2: a worker process)
    ref, ours = _tables(base_run[0], (0, 1, 2)), _tables(out, (0, 1, 2))
    for k in ref:
        pd.testing.assert_frame_equal(ref[k], ours[k], check_exact=True)
    assert run_montecarlo(scenario, out, workers=1).ran == ()  # nothing left


@pytest.mark.slow
def test_failed_replication_is_recorded_and_others_continue(tmp_path, monkeypatch):
    # the first of two fails: the one after it still runs (two replications are enough to see it)
    out = tmp_path / "fail"
    real = replication_module.run_replication

    def broken_at_0(scenario, index, truths, models=None):
        if index == 0:
            raise RuntimeError("instrument exploded in replication 0")
        return real(scenario, index, truths, models)

    monkeypatch.setattr(replication_module, "run_replication", broken_at_0)
    report = run_montecarlo(_scenario(), out, replications=2, workers=1)
    assert report.failed == (0,) and report.ran == (0, 1)
    assert finished_replications(out) == {0: "failed", 1: "ok"}
    record = json.loads(replication_file(out, 0, failed=True).read_text())
    assert record["status"] == -1 and "instrument exploded in replication 0" in record["message"]
    assert "Traceback" in record["message"] and record["noise_seed"] == _scenario().draw(0).noise_seed
    summary = summarize(out)
    assert summary.n_ok == 1 and summary.n_failed == 1
    assert "instrument exploded" in summary.text()
    # a resume skips it; --retry-failed runs it again and the failure record goes
    monkeypatch.setattr(replication_module, "run_replication", real)
    assert run_montecarlo(_scenario(), out, replications=2, workers=1).ran == ()
    again = run_montecarlo(_scenario(), out, replications=2, workers=1, retry_failed=True)
    assert again.ran == (0,) and not again.failed
    assert sorted(p.name for p in (out / "replications").iterdir()) == [f"r{k:05d}.parquet" for k in range(2)]


@pytest.mark.slow
def test_non_converged_estimation_is_a_failure_with_the_estimators_message(tmp_path):
    raw_est = dict(RAW["estimator"], max_iterations=1)
    report = run_montecarlo(_scenario(estimator=raw_est), tmp_path / "nc", replications=1, workers=1)
    assert report.failed == (0,)
    record = json.loads(replication_file(tmp_path / "nc", 0, failed=True).read_text())
    assert record["status"] == 0 and "iteration limit" in record["message"]
    assert record["verdict_code"] == -1 and record["verdict"] == "failure"
    # the summary reads the failure record whole: counted as a failure verdict, left out
    summary = summarize(tmp_path / "nc")
    assert summary.n_ok == 0 and summary.n_failure_verdict == 1
    assert "1 left out of the statistics because their verdict was failure" in summary.text()


@pytest.mark.slow
def test_another_scenario_is_refused_in_the_same_directory(base_run):
    out, _ = base_run
    with pytest.raises(ScenarioError, match="another scenario"):
        run_montecarlo(_scenario(seed=32), out, replications=3, workers=1)


@pytest.mark.slow
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
    assert "per parameter kind" in text and "within_3colored" in text
    assert (out / "summary.png").stat().st_size > 10_000 and (out / "summary_parameters.csv").exists()
    kinds = summary.kinds
    assert {"imu_bias", "time_delay", "bias", "initial_condition"} <= set(kinds.index)
    assert list(kinds.index[:3]) == ["imu_bias", "time_delay", "bias"]
    assert (kinds["n"] > 0).all() and ((kinds["within_3crb"] >= 0) & (kinds["within_3crb"] <= 1)).all()
    assert kinds.loc["time_delay", "n"] == 3 * kinds.loc["time_delay", "parameters"]


@pytest.mark.slow
def test_dask_local_cluster_gives_the_local_results(base_run, tmp_path):
    distributed = pytest.importorskip("dask.distributed", reason="dask[distributed] is not installed")
    out = tmp_path / "dask"
    # two replications, one per worker process (the flights scattered to both): what is compared
    # is each replication's table, bit for bit, not how many there are
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        report = run_montecarlo(_scenario(), out, replications=2, scheduler=cluster.scheduler_address)
    assert report.executor.startswith("dask(") and report.ran == (0, 1) and not report.failed
    ref, ours = _tables(base_run[0], (0, 1)), _tables(out, (0, 1))
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
[estimator.solver]
decrease_tol = 1.0
"""


@pytest.mark.slow
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
    assert (out / "summary.txt").read_text().startswith("Monte Carlo mc_test: 4 replications, 4 summarised")
    # a scenario that is not this one is refused, with the way out named
    path.write_text(SCENARIO_TOML.replace("seed = 31", "seed = 30"))
    assert montecarlo_cli.main(["montecarlo", str(path), "--out", str(out), "--workers", "1"]) == 2
    assert "another scenario" in capsys.readouterr().err


# ---------------------------------------------------------------------------- the summary's statistics


def _result(index: int, rows: list[tuple], ok: bool = True, verdict: int | None = 1,
            findings: tuple = ()) -> ReplicationResult:
    """A replication with parameter rows (name, kind, error, std_crb, std_colored)."""
    params = pd.DataFrame([{
        "name": name, "family": name.split("[")[0], "kind": kind, "unit": "deg", "estimate": 1.0 + err,
        "truth": 1.0, "error": err, "std_crb": crb, "std_colored": col, "z_crb": err / crb,
        "z_colored": err / col} for name, kind, err, crb, col in rows])
    n_fail = sum(f[0] == "failure" for f in findings)
    return ReplicationResult(index=index, ok=ok, status=1, message="", noise_seed=index, scenario_hash="h",
                             parameters=params if ok else pd.DataFrame(), verdict_code=verdict,
                             n_warnings=len(findings) - n_fail, n_failures=n_fail, findings=findings)


def test_kind_table_on_a_synthetic_replication_table():
    # imu_bias: z_crb = -4, -2, 0, 1, 3.5 (3 of 5 within 3); coloured deviations twice as large
    # (z = -2, -1, 0, 0.5, 1.75: all within); a held row (no deviation) is not an estimate
    imu = [("dax[m0]", "imu_bias", e, 0.1, 0.2) for e in (-0.4, -0.2, 0.0, 0.1, 0.35)]
    rows = [*imu, ("tau_x", "time_delay", 1.0, 2.0, 2.0), ("tau_x", "time_delay", -1.0, 2.0, 2.0),
            ("dax[m1]", "imu_bias", 7.0, math.nan, math.nan), ("f1[0]", "table", 0.5, 0.1, 1.0),
            ("zz", "other_kind", 0.1, 0.1, 0.1), ("u0[m0]", "initial_condition", 0.0, 1.0, 1.0)]
    params = pd.concat([_result(0, rows).parameters], ignore_index=True)
    k = kind_table(params)
    assert list(k.index) == ["imu_bias", "time_delay", "table", "initial_condition", "other_kind"]
    imu_row = k.loc["imu_bias"]
    assert imu_row["n"] == 5 and imu_row["parameters"] == 1  # the held dax[m1] is no estimate
    assert imu_row["within_3crb"] == pytest.approx(0.6) and imu_row["within_3colored"] == 1.0
    z = np.array([-4.0, -2.0, 0.0, 1.0, 3.5])
    assert imu_row["z_std_crb"] == pytest.approx(np.std(z, ddof=1))
    assert imu_row["z_std_colored"] == pytest.approx(np.std(z / 2, ddof=1))
    assert imu_row["median_abs_z_crb"] == pytest.approx(2.0)
    assert imu_row["median_abs_z_colored"] == pytest.approx(1.0)
    assert k.loc["time_delay", "z_std_crb"] == pytest.approx(np.std([0.5, -0.5], ddof=1))
    assert k.loc["table", "within_3crb"] == 0.0 and k.loc["table", "within_3colored"] == 1.0
    assert math.isnan(k.loc["initial_condition", "z_std_crb"])  # one estimate: no spread


def test_a_held_parameter_is_left_out_of_every_statistic_alike():
    # b in five replications: estimated in three (errors 0.1, 0.2, 0.6; CRB 0.1, 0.2, 0.3), held
    # at its start value in two (start - truth = 5, no deviation); absent from a sixth (as the
    # estimator's recovery table leaves a held parameter out)
    errs, crbs = (0.1, 0.2, 0.6), (0.1, 0.2, 0.3)
    results = [_result(i, [("b[A]", "bias", e, c, 2 * c)])
               for i, (e, c) in enumerate(zip(errs, crbs, strict=True))]
    results += [_result(3 + i, [("b[A]", "bias", 5.0, math.nan, math.nan)]) for i in range(2)]
    results += [_result(5, [("tau", "time_delay", 0.0, 1.0, 1.0)])]
    s = summarize_results(results, name="held")
    row = s.parameters.loc["b[A]"]
    assert row["n"] == 3 and row["n_not_estimated"] == 3
    assert row["bias"] == pytest.approx(np.mean(errs))
    assert row["mc_std"] == pytest.approx(np.std(errs, ddof=1))
    assert row["rmse"] == pytest.approx(np.sqrt(np.mean(np.square(errs))))
    assert row["crb_mean"] == pytest.approx(np.mean(crbs)) and row["colored_mean"] == pytest.approx(0.4)
    assert row["ratio_crb"] == pytest.approx(np.std(errs, ddof=1) / np.mean(crbs))
    assert row["truth_mean"] == pytest.approx(1.0) and row["within_3sigma"] == 1.0
    assert (s.z.loc[s.z["name"] == "b[A]", "replication"].tolist() == [0, 1, 2])
    fam = s.families.loc["b"]
    assert fam["n"] == 3 and fam["bias"] == pytest.approx(np.mean(errs))
    assert s.kinds.loc["bias", "n"] == 3


def test_verdicts_are_counted_and_failures_left_out(tmp_path):
    warn = (("warning", "turbulence", "residual whiteness ratio 1.4 in theta"),)
    fail = (("failure", "wrong_minimum", "attitude residual 3 deg\nsecond line"),
            ("warning", "turbulence", "residual whiteness ratio 2.0"))
    results = [_result(0, [("b[A]", "bias", 0.1, 0.1, 0.1)]),
               _result(1, [("b[A]", "bias", 0.2, 0.1, 0.1)], verdict=2, findings=warn),
               _result(2, [], ok=False, verdict=-1, findings=fail),
               _result(3, [], ok=False, verdict=None)]
    s = summarize_results(results, name="verdicts")
    assert s.n_ok == 2 and s.n_failed == 2 and s.n_failure_verdict == 1
    assert s.verdicts["replications"].to_dict() == {"success": 1, "success with warnings": 1, "failure": 1,
                                                    "none (raised, or no verdict recorded)": 1}
    assert s.verdicts["in_statistics"].to_dict()["failure"] == 0
    assert s.parameters.loc["b[A]", "n"] == 2
    text = s.text()
    assert "verdicts: 1 success, 1 success with warnings, 1 failure" in text
    assert ("1 left out of the statistics because their verdict was failure, 1 because they failed "
            "otherwise") in text
    f = s.findings.set_index("code")
    assert list(s.findings["code"]) == ["wrong_minimum", "turbulence"]  # failures first
    assert f.loc["turbulence", "replications"] == 2 and f.loc["turbulence", "findings"] == 2
    assert f.loc["wrong_minimum", "example"] == "attitude residual 3 deg"  # the first line
    # a failure record keeps its verdict through the file
    (tmp_path / "replications").mkdir()
    for r in results[2:]:
        runner.write_replication(tmp_path, r)
    back = load_results(tmp_path)
    assert [(r.index, r.verdict_code, r.n_failures, r.findings) for r in back] == [
        (2, -1, 1, results[2].findings), (3, None, 0, ())]


@pytest.mark.slow
def test_channel_accuracy_is_three_rms_about_zero(base_run):
    # one definition, imported: the workflow's Table 2 (3 x rms about zero; a mean offset counts)
    assert replication_module.three_sigma is workflow.three_sigma
    e = np.array([0.3, 0.5, 0.1, 0.7])  # mean 0.4, std 0.2236
    row = replication_module._accuracy_row("x", "calibrated", "deg", e)
    assert row["three_sigma"] == pytest.approx(3.0 * np.sqrt(np.mean(e**2)))
    assert row["three_sigma"] == pytest.approx(3.0 * math.hypot(row["mean"], row["std"]))
    assert row["three_sigma"] > 3.0 * row["std"] * 1.5  # the mean offset counts (3 std alone: 0.67)
    ch = read_replication(replication_file(base_run[0], 0)).channels
    np.testing.assert_allclose(ch["three_sigma"], 3.0 * np.hypot(ch["mean"], ch["std"]), rtol=1e-9)


@pytest.mark.slow
def test_calibrated_channels_are_the_workflow_reports_and_a_flat_segment_is_a_note(base_run, monkeypatch):
    out, _ = base_run
    scenario = _scenario()
    truths = {j: read_flight(flight_file(out / "flights", j)) for j in (0, 1)}
    seen = {}

    def recorded(problem, result, truth_cache=None):  # the truths the projection read, shared
        seen.update(workflow_truth.calibrated_errors(problem, result, truth_cache))
        return seen

    monkeypatch.setattr(replication_module, "calibrated_errors", recorded)
    r = replication_module.run_replication(scenario, 0, truths)
    # in this process, the table of the reference run's worker: bit-identical
    pd.testing.assert_frame_equal(r.to_pandas(), read_replication(replication_file(out, 0)).to_pandas(),
                                  check_exact=True)
    cal = r.channels[r.channels["kind"] == "calibrated"].set_index("name")
    assert set(cal.index) == set(seen) >= {"alpha_zl", "alpha_zr"}
    for name, df in seen.items():
        e_deg = np.degrees(df["error_rad"].to_numpy())
        assert cal.loc[name, "three_sigma"] == pytest.approx(workflow.three_sigma(e_deg), rel=1e-12)
        assert cal.loc[name, "n"] == e_deg.size

    def flat(problem, result, truth_cache=None):
        raise ValueError("channel alpha_zl: its model does not depend on alpha_s at some samples")

    monkeypatch.setattr(replication_module, "calibrated_errors", flat)
    r = replication_module.run_replication(scenario, 0, truths)
    assert r.ok and len(r.parameters) and not (r.channels["kind"] == "calibrated").any()
    assert any("calibrated channels not computed" in w and "alpha_zl" in w for w in r.warnings)


def test_a_replications_problem_has_the_scenarios_gravity_and_lever_arm(tiny_dataset):
    """``[estimator] g_mps2`` and ``lever_arm`` reach the problem each replication estimates."""
    est = _scenario(estimator={**RAW["estimator"], "g_mps2": 9.79, "lever_arm": "differentiated"}).estimator
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        problem = est.problem(tiny_dataset)
        direct = problem_from_dataset(tiny_dataset, channels=est.channels, overrides=est.parameters,
                                      equations=StateEquations(g_mps2=9.79, lever_arm="differentiated"))
    assert (problem.g_mps2, problem.lever_arm) == (9.79, "differentiated")
    assert [c.name for c in problem.channels] == list(RAW["estimator"]["channels"])
    assert problem.parameters.keys == direct.parameters.keys
    assert (direct.g_mps2, direct.lever_arm) == (9.79, "differentiated")
