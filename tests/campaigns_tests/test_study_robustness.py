"""Issue 10's robustness study, campaigns/studies/robustness.py: a tiny run writes its table, plot,
CSV and conclusions and resumes without recomputing; the true-minimum classification, the table
and the conclusions follow constructed numbers; the reference fit solves the judged fit's problem.
The full study is a benchmark (campaigns/studies/results/robustness.*)."""

from __future__ import annotations

import json
import math
import tempfile
import types
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from campaigns.montecarlo import parse_scenario
from campaigns.montecarlo.replication import Models, fly, write_scratch_dataset
from campaigns.studies import robustness as rob
from campaigns.truth import true_parameters

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("robustness")
    args = ["--out", str(out / "work"), "--results", str(out / "results"), "--size", "tiny", "--workers", "1"]
    assert rob.main(args) == 0
    return out, args


@pytest.mark.slow
def test_tiny_run_writes_table_plot_csv_and_conclusions(tiny_run):
    out, _ = tiny_run
    text = (out / "results" / "robustness.txt").read_text()
    lines = text.splitlines()
    assert any(line.startswith("$ python -m campaigns.studies.robustness --out ") and "--size tiny" in line
               for line in lines)
    assert any(line.startswith("machine: ") for line in lines)
    assert any(line.startswith("code: ") for line in lines)
    assert "this invocation: wall " in text and "1 replications computed" in text
    assert "success@wrong" in text and "at_true_min" in text
    conclusions = text.split("conclusions:\n")[1]
    assert conclusions.startswith("From the default (zero) start ") and conclusions.rstrip().endswith(".")
    png = (out / "results" / "robustness.png").read_bytes()
    assert png.startswith(PNG_MAGIC) and len(png) > 10_000

    df = pd.read_csv(out / "results" / "robustness.csv")
    assert len(df) == 1 and df["scale"].iloc[0] == 3.0
    row = df.iloc[0]
    # the outcome is what the classification makes of the recorded numbers
    assert row["outcome"] == rob.classify(bool(row["judged_success"]), row["dcost"])
    assert np.isfinite(row["judged_cost"]) and np.isfinite(row["reference_cost"])
    assert row["dcost"] == pytest.approx(row["judged_cost"] - row["reference_cost"], abs=1e-9)
    # the fit from the truth is a fit: attitude residuals at the INS noise (0.03 deg), vane biases
    # within a hundredth of a degree of their truth
    assert row["reference_att_rms_max_deg"] < 2.0 * rob.INS_NOISE_DEG
    assert row["reference_vane_err_max_deg"] < 0.05
    # the table and the per-replication line say the same as the CSV
    at = int(row["outcome"] in (rob.SUCCESS_TRUE, rob.FAILURE_TRUE))
    assert f"{at}/1 ({100 * at} %)" in text and row["outcome"] in text


@pytest.mark.slow
def test_tiny_run_resumes_without_recomputing(tiny_run):
    out, args = tiny_run
    record = rob.record_file(out / "work", 3.0, 0)
    before = record.stat().st_mtime_ns
    assert rob.main(args) == 0
    assert record.stat().st_mtime_ns == before
    text = (out / "results" / "robustness.txt").read_text()
    assert "0 replications computed" in text and "over 2 invocations (resumed)" in text


def _record(scale: float, rep: int, success: bool, dcost: float, att_deg: float = 0.026,
            vane_err_deg: float = 0.01, reference_cost: float = -389000.0, verdict: str | None = "SUCCESS",
            findings: tuple[str, ...] = ()) -> dict:
    """A replication record as :func:`robustness.run_pair` writes it, with the given numbers."""
    def fit(cost: float, ok: bool, att: float, err: float, v: str | None, f: tuple[str, ...]) -> dict:
        return {"status": 1, "status_text": "converged step", "message": "m", "success": ok, "verdict": v,
                "findings": list(f), "iterations": 7, "wall_s": 1.0, "cost": cost, "n_estimated": 90,
                "att_rms_deg": {"phi": att}, "att_rms_max_deg": att, "vane_bias_err_deg": {"b_l[PV1]": err}}
    return {"scale": scale, "replication": rep, "noise_seed": 1, "scenario_hash": "h",
            "judged": fit(reference_cost + dcost, success, att_deg, vane_err_deg, verdict, findings),
            "reference": fit(reference_cost, True, 0.026, 0.01, "SUCCESS", ()),
            "dcost": dcost, "dtheta_max_sigma": 0.01 if abs(dcost) < 1 else 9000.0, "dtheta_argmax": "dq[m0]",
            "n_compared": 90, "held_by_reference_only": [], "held_at_judged_values": [],
            "accel_bias_max_mps2": 0.4, "gyro_bias_max_deg_s": 0.9, "warnings": [], "wall_s": 2.0}


def test_a_record_that_raised_is_run_again(tmp_path):
    ok, err = tmp_path / "r00000.json", tmp_path / "r00001.json"
    ok.write_text(json.dumps(_record(1.0, 0, True, 1e-4)))
    err.write_text(json.dumps({"replication": 1, "scale": 1.0, "error": "ValueError: x", "wall_s": 0.1}))
    assert rob.finished(ok) and not rob.finished(err) and not rob.finished(tmp_path / "r00002.json")


def test_classification_of_constructed_fits():
    tol = rob.COST_TOL_NLL
    assert rob.classify(True, 1e-4) == rob.SUCCESS_TRUE
    assert rob.classify(True, -tol) == rob.SUCCESS_TRUE  # the tolerance is inclusive, either side
    assert rob.classify(False, tol) == rob.FAILURE_TRUE  # a false alarm
    assert rob.classify(True, 1.01 * tol) == rob.SUCCESS_WRONG
    assert rob.classify(True, 3.5e5) == rob.SUCCESS_WRONG  # the case: must never happen
    assert rob.classify(False, 3.5e5) == rob.FAILURE_WRONG  # caught
    assert rob.classify(True, -2.0) == rob.BELOW  # the fit from the truth stopped short
    assert rob.classify(False, math.nan) == rob.FAILURE_WRONG  # the judged fit has no cost
    assert rob.classify(True, math.nan, reference_cost=math.nan) == rob.NO_REFERENCE
    assert rob.classify_record({"replication": 0, "error": "ValueError: x"}) == rob.ERROR
    assert [rob.location(d) for d in (0.0, 0.5, -0.5, math.nan)] == ["true", "wrong", "below", "unknown"]


@pytest.mark.slow
def test_table_and_conclusions_follow_the_numbers(tmp_path):
    records = [_record(1.0, 0, True, 2e-4), _record(1.0, 1, True, -1e-3),
               _record(3.0, 0, True, 1e-5),
               _record(3.0, 1, True, 3.6e5, att_deg=12.0, vane_err_deg=1.1),  # success at a wrong minimum
               _record(3.0, 2, False, 3.9e5, att_deg=18.0, vane_err_deg=0.7, verdict="FAILURE",
                       findings=("failure: wrong_minimum",)),  # caught
               _record(3.0, 3, False, 0.02, verdict="FAILURE", findings=("failure: turbulence (phi)",))]
    df = rob.records_frame(records)
    assert list(df["outcome"]) == [rob.SUCCESS_TRUE, rob.SUCCESS_TRUE, rob.SUCCESS_TRUE, rob.SUCCESS_WRONG,
                                   rob.FAILURE_WRONG, rob.FAILURE_TRUE]
    table = rob.scale_table(df, (1.0, 3.0)).set_index("scale")
    assert table.loc[1.0, ["reps", "at_true_min", "success_at_wrong", "failures"]].tolist() == [2, 2, 0, 0]
    assert table.loc[3.0, ["reps", "at_true_min", "success_at_wrong", "failures", "false_alarms"]].tolist() \
        == [4, 2, 1, 2, 1]
    assert table.loc[3.0, "att_rms_max_deg"] == 18.0
    assert table.loc[3.0, "dJ_at_min_max"] == pytest.approx(0.02)
    text = rob.scale_table_text(table.reset_index())
    assert "2/2 (100 %)" in text and "2/4 (50 %)" in text
    c = rob.conclusions(df, table.reset_index())
    assert "4 of 6 fits reached the true minimum (1x 2/2, 3x 2/4)" in c and "missed at 3x" in c
    assert "success at a wrong minimum: 1 of 6 (1x 0, 3x 1); the requirement (0) is NOT met" in c
    assert "attitude residuals of 12-18 deg rms" in c and "vane biases 0.7-1.1 deg off the truth" in c
    assert "1 at a wrong minimum (caught), 1 at the true minimum (false alarms; their findings: failure: " \
           "turbulence (phi))" in c
    # without the bad ones: every target met, said so
    good = rob.records_frame(records[:3])
    c = rob.conclusions(good, rob.scale_table(good, (1.0, 3.0)))
    assert "the target of 100 % is met at every scale" in c and "the requirement (0) is met" in c
    assert "No fit ended with a failure verdict" in c
    path = rob.plot(df, (1.0, 3.0), tmp_path / "p.png", 4)
    assert path.read_bytes().startswith(PNG_MAGIC)


def test_reference_problem_starts_at_the_truth_and_holds_what_the_judged_fit_held():
    config = rob.SIZES["tiny"]
    scenario = parse_scenario(rob.scenario_raw(3.0, config, 1))
    draw = scenario.draw(0)
    truths = {md.job.index: fly(scenario, md) for md in draw.maneuvers}
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        write_scratch_dataset(scenario, draw.maneuvers, truths, Models.of(scenario), Path(tmp))
        problem = scenario.estimator.problem(tmp)
        truth = dict(true_parameters(problem).values)
    ps = problem.parameters
    keys = list(ps.keys)
    # the IMU biases start at zero (the default start), their truths are 3x typical
    dq = next(k for k in keys if k.startswith("dq["))
    assert ps[dq].value == 0.0 and abs(truth[dq]) > 0.01
    held, kept = next(k for k in keys if k.startswith("dr[")), next(k for k in keys if k.startswith("dp["))
    estimated = ps.free_mask.copy()
    estimated[ps.index(held)] = False
    judged_values = ps.values + 0.001
    judged = types.SimpleNamespace(free_estimated=estimated, values=judged_values)
    ref = rob.reference_problem(problem, judged, truth, keep=[kept]).parameters
    assert ref[dq].value == truth[dq] and ref[dq].free
    assert ref[held].value == judged_values[ps.index(held)] and not ref[held].free
    assert ref[kept].value == judged_values[ps.index(kept)] and ref[kept].free
    assert np.array_equal(ref.free_mask, estimated)
    no_truth = [k for k, e in zip(keys, estimated, strict=True) if e and k not in truth]
    for k in no_truth:  # (pressure-altitude scale factors, DGPS offsets) start where the judged fit did
        assert ref[k].value == judged_values[ps.index(k)]
    json.dumps(rob.scenario_raw(-3.0, config, 1))  # the scenario is plain data (its hash is taken)
    assert rob.scenario_raw(-3.0, config, 1)["draw"]["errors"]["imu.gyro_bias_deg_s"]["std"] > 0
