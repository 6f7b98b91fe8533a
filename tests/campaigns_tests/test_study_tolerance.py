"""Planning study (c), campaigns/studies/tolerance.py: a tiny run writes sane outputs; the
conclusions follow the numbers. The full study is a benchmark (campaigns/studies/results/)."""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pandas as pd
import pytest

from campaigns.montecarlo import read_replication
from campaigns.montecarlo.runner import replication_file
from campaigns.studies import scaffold, tolerance


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("tolerance")
    assert tolerance.main(["--out", str(out), "--size", "tiny", "--replications", "1", "--workers", "1"]) == 0
    return out


@pytest.mark.slow
def test_tiny_study_writes_table_plot_and_conclusions(tiny_run):
    text = (tiny_run / "tolerance.txt").read_text()
    assert text.splitlines()[4].startswith("$ python -m campaigns.studies.tolerance --out ")
    assert "machine:" in text and "wall " in text
    factors = tolerance.TINY.factors
    conclusions = text.split("conclusions:\n")[1]
    # one sentence per factor; a variant (IMU biases started at their mean) joins its factor's
    main = [f for f in factors if f.variant_of is None]
    assert sum(line.startswith("- ") for line in conclusions.splitlines()) == len(main) < len(factors)
    for f in main:
        assert f.title in conclusions
    png = (tiny_run / "tolerance.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000

    df = pd.read_csv(tiny_run / "tolerance.csv")
    assert len(df) == sum(len(f.levels) for f in factors)
    # light turbulence: the estimator's verdict is a failure (the output-error method models no air
    # motion), recorded as a failed replication with the reason; every other point estimates
    turb = (df["factor"] == "turbulence") & (df["level"].astype(str) == "light")
    assert (df.loc[~turb, "n_ok"] == 1).all() and (df.loc[~turb, "n_failed"] == 0).all()
    assert (df.loc[turb, "n_failed"] == 1).all() and df.loc[turb, "failures"].str.contains("turbulence").all()
    df = df[~turb]
    # the vanes (the only flow channels of the tiny scenario) are calibrated to a tenth of a degree
    vane = df["acc_vane AOA"].to_numpy()
    assert np.all((vane > 0.05) & (vane < 0.5)), vane
    assert df["acc_nose-probe AOSS"].isna().all()
    # every factor's base level is the base scenario: one run, the same numbers
    base = df[df["run"] == df["run"].iloc[0]]
    assert len(base) >= 4 and base["acc_vane AOA"].nunique() == 1
    # a delay of 100 ms on every flow sensor is estimated: the vane delays to a millisecond
    delay = df[(df["factor"] == "flow_delay") & (df["level"].astype(str) == "100")].iloc[0]
    assert delay["tau_err_max_ms"] < 1.0 and delay["tau_at_bound"] == 0


@pytest.mark.slow
def test_tiny_study_resumes_without_recomputing(tiny_run):
    before = {p: p.stat().st_mtime_ns for p in tiny_run.glob("points/*/replications/*.parquet")}
    # every level of every factor has its run, except the base levels: they share one; the light
    # turbulence's replication is a failure (a record, not a result file)
    levels = sum(len(f.levels) for f in tolerance.TINY.factors)
    bases = sum(f.base_level in f.levels for f in tolerance.TINY.factors)
    assert len(before) == levels - bases + 1 - 1
    assert len(list(tiny_run.glob("points/turbulence_light/replications/*.failed.json"))) == 1
    # the same command again; the figure is the first invocation's subject (checked above), not the
    # resumption's: this invocation draws none (the first one's stays, for the other tests)
    no_figure = dataclasses.replace(tolerance.STUDY_SPEC, plot=lambda df, config, path, n: path)
    argv = ["--out", str(tiny_run), "--size", "tiny", "--replications", "1", "--workers", "1"]
    assert scaffold.main(no_figure, argv) == 0
    assert {p: p.stat().st_mtime_ns for p in tiny_run.glob("points/*/replications/*.parquet")} == before
    # the header says what this invocation computed and what all of them cost
    text = (tiny_run / "tolerance.txt").read_text()
    assert "replications computed;" in text and "over 2 invocations (resumed)" in text
    assert re.search(r"^this invocation: .*, 0 replications computed;", text, re.M), text[:2000]
    assert f"{len(before) + 1} replications in all" in text  # the failed one was computed too


def _factor(name: str) -> tolerance.Factor:
    return next(f for f in tolerance.FULL.factors if f.name == name)


def _row(level: str, vane: float, resid: float = 0.15, **extra) -> dict:
    row = {"factor": "x", "level": level, "n_ok": 10, "n_failed": 0, "resid_vane_deg": resid,
           "failures": "", **extra}
    for g in tolerance.SENSOR_GROUPS:
        row[f"acc_{g}"] = 0.2
    row["acc_vane AOA"] = vane
    return row


def test_conclusion_names_the_last_passing_level_the_failing_sensor_and_a_bound():
    f = _factor("flow_delay")
    rows = pd.DataFrame([_row("0", 0.14), _row("200", 0.3),
                         _row("400", 2.5, tau_truth_beyond_bound=7, tau_truth_max_ms=392.0)])
    text = tolerance.conclusion(f, rows)
    assert "holds up to 200" in text and "at 400" in text and "vane AOA (2.50 > 0.5 deg)" in text
    assert "the true tau (up to 392 ms) lies beyond its bounds [-300, 300] ms" in text
    assert "not the method's" in text
    ok = tolerance.conclusion(f, rows.iloc[:2])
    assert "whole range swept, up to 200" in ok
    # every estimation failed: said so, with the failure and the truth beyond the bound
    none = pd.DataFrame([_row("0", 0.14), _row("400", math.nan, resid=math.nan, n_ok=0, n_failed=10,
                                               failures="10 estimation iteration limit",
                                               tau_truth_beyond_bound=7, tau_truth_max_ms=392.0)])
    text = tolerance.conclusion(f, none)
    assert "at 400 every estimation ended with a failure verdict (10 estimation iteration limit)" in text
    assert "beyond" in text


def test_conclusion_tells_a_wrong_minimum_and_the_start_value_from_the_variant():
    f, v = _factor("imu_bias"), _factor("imu_started")
    rows = pd.DataFrame([_row("0", 0.14), _row("1", 0.14), _row("3", 3.2, resid=11.0, n_pass=2),
                         _row("10", 2.1, resid=12.0)])
    variant = pd.DataFrame([_row("3", 0.15), _row("10", 0.9)])
    text = tolerance.conclusion(f, rows, variant=(v, variant))
    assert "holds up to 1" in text and "at 3 it is lost for vane AOA (3.20 > 0.5 deg)" in text
    assert "(2 of 10 replications meet every requirement)" in text
    assert "wrong minimum (median vane residual 3-sigma 0.15 -> 11.00 deg, 10 of 10 reported as " \
           "a success" in text
    assert "started at their mean, every requirement holds at 3" in text and "start value" in text
    assert "at 10 it is still lost for vane AOA" in text


def test_conclusion_for_an_unmodelled_factor_cites_the_residuals_and_failed_estimations():
    f = _factor("turbulence")
    rows = pd.DataFrame([_row("none", 0.14), _row("light", 0.8, resid=0.9, n_ok=8, n_failed=2,
                                                  failures="2 estimation iteration limit")])
    text = tolerance.conclusion(f, rows)
    assert "holds at none" in text and "already at light 2 of 10 estimations ended with a failure verdict " \
           "(2 estimation iteration limit), and it is lost for vane AOA" in text
    assert "grows from 0.15 to 0.90 deg" in text


def test_a_level_where_some_estimations_fail_does_not_hold():
    """Failure verdicts count against a level even when the fits that succeeded are accurate: the
    accuracy of the few that passed is not the accuracy a campaign at that level can expect."""
    f = _factor("imu_bias")
    rows = pd.DataFrame([_row("0", 0.14), _row("3", 0.14),
                         _row("10", 0.14, n_ok=1, n_failed=7, failures="7 misfit")])
    text = tolerance.conclusion(f, rows)
    assert "whole range" not in text, text
    assert "holds up to 3" in text and "at 10" in text, text
    assert "7 of 8 estimations ended with a failure verdict (7 misfit); the 1 that succeeded meets every " \
           "requirement" in text, text
    variant = pd.DataFrame([_row("10", 0.14, n_ok=2, n_failed=6, failures="6 misfit")])
    text = tolerance.conclusion(f, rows, variant=(_factor("imu_started"), variant))
    assert "at 10 it is still lost (6 of 8 estimations ended with a failure verdict: 6 misfit)" in text, text


def test_failing_groups_ignores_missing_sensors():
    row = _row("1", 0.6)
    row["acc_side-probe AOA"] = math.nan
    assert tolerance.failing_groups(row) == ["vane AOA"]


@pytest.mark.slow
def test_swept_truth_is_the_truth_the_replication_compared_with(tiny_run):
    """The projection used for points whose estimations all failed gives the truths a converged
    replication of the same point holds."""
    point = next(p for p in tolerance.study_points(tolerance.TINY, tiny_run)
                 if p.factor.name == "flow_delay" and p.level == 100.0)
    values, families = tolerance.swept_truth(point)["tau"]
    rep = read_replication(replication_file(point.directory, 0)).parameters
    rep = rep[rep["family"].isin(families)]
    assert len(values) == len(rep) >= 2 and sorted(families) == sorted(rep["family"])
    np.testing.assert_allclose(np.sort(values), np.sort(rep["truth"].to_numpy()), rtol=1e-9)
    assert np.all(values > 80.0) and np.all(values < 100.0)  # 100 ms, less the IMU's lag


def test_a_replication_without_computed_accuracy_does_not_pass():
    """NaN accuracy where another replication has one (a calibration that cannot be applied) is
    not a pass, and is counted apart; a group no replication has (no such sensor) is not asked."""
    from campaigns.studies.tolerance.analysis import DESIRED_3SIGMA_DEG, passing

    groups = list(DESIRED_3SIGMA_DEG)
    good = {g: 0.5 * DESIRED_3SIGMA_DEG[g] for g in groups}
    bad = dict(good, **{groups[0]: 2.0 * DESIRED_3SIGMA_DEG[groups[0]]})
    unknown = dict.fromkeys(groups, math.nan)
    acc = pd.DataFrame([good, bad, unknown])
    assert passing(acc) == (1, 1)
    # a sensor no replication flew is not asked for
    acc[groups[-1]] = math.nan
    assert passing(acc) == (1, 1)
    assert passing(pd.DataFrame([good, good])) == (2, 0)
