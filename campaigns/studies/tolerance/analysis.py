"""Planning study (c), its analysis: per point, from its replications, the calibrated channels'
accuracy against the truth per requirement group, pass/fail, the swept parameters' errors and
bounds, the scatter against the Cramér-Rao bounds; one row per point (:func:`collect`)."""

from __future__ import annotations

import math
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from campaigns.montecarlo import parse_scenario
from campaigns.montecarlo.replication import Models, ReplicationResult, fly, write_scratch_dataset
from campaigns.montecarlo.summary import CALIBRATION_KINDS, load_results, summarize_results
from campaigns.studies.common import VANE_BIAS_FAMILIES
from campaigns.studies.tolerance.config import DESIRED_3SIGMA_DEG, SENSOR_GROUPS, SHORT_TITLE, Factor, Point
from campaigns.truth import true_parameters
from estimator.io.modelset import load_model_set
from estimator.parameters import family_of


def bounds_display() -> dict[str, tuple[float, float]]:
    """Parameter family -> (low, high) bounds of the tejas model set, display units."""
    _, params = load_model_set("tejas")
    return {p.name: (p.bounds[0] * p.display_scale, p.bounds[1] * p.display_scale) for p in params}


def _rms(a: np.ndarray) -> float:
    a = np.asarray(a, dtype=float)
    a = a[np.isfinite(a)]
    return float(np.sqrt(np.mean(a * a))) if a.size else math.nan


def group_accuracy(result: ReplicationResult) -> dict[str, float]:
    """One replication: requirement group -> worst channel's ``|mean| + 3 std`` (deg) of the
    calibrated channel against the true flow angle (NaN: no such channel)."""
    c = result.channels
    cal = c[c["kind"] == "calibrated"].set_index("name") if len(c) else pd.DataFrame()
    out = {}
    for group, names in SENSOR_GROUPS.items():
        vals = [abs(float(cal.at[n, "mean"])) + float(cal.at[n, "three_sigma"])
                for n in names if n in cal.index]
        out[group] = max(vals) if vals else math.nan
    return out


def passing(acc: pd.DataFrame) -> tuple[int, int]:
    """``(passing, unjudged)`` replications of a point from their group accuracies (one row per
    converged replication, one column per requirement group, deg, NaN: not computed).

    A replication passes when every group meets its desired accuracy. A group no replication has
    (NaN throughout: no such sensor) is not asked for; a replication whose accuracy could not be
    computed where another's could (a calibration that cannot be applied: a table estimated flat
    somewhere) does not pass, and is counted as unjudged.
    """
    present = [g for g in DESIRED_3SIGMA_DEG if g in acc and acc[g].notna().any()]
    ok = [all(acc.at[i, g] <= DESIRED_3SIGMA_DEG[g] for g in present) for i in acc.index]
    unjudged = [any(pd.isna(acc.at[i, g]) for g in present) for i in acc.index]
    return int(sum(ok)), int(sum(unjudged))


def _failure_reasons(failed: Sequence[ReplicationResult]) -> str:
    """"2 turbulence, 1 not converged": what failed the replications, counted."""
    why: dict[str, int] = {}
    for r in failed:
        # what failed it: the estimator's first failure finding (turbulence, not converged, ...), or
        # the start of the message of a replication that raised
        codes = [code for sev, code, _ in r.findings if sev == "failure"]
        raised = r.message.split(":")[0] if r.message else str(r.status)
        text = codes[0].replace("_", " ") if codes else raised
        why[text] = why.get(text, 0) + 1
    return ", ".join(f"{n} {w}" for w, n in why.items())


def _swept_errors(params: pd.DataFrame, factor: Factor, bounds: Mapping[str, tuple[float, float]]
                  ) -> dict[str, tuple[float, float, str, int, int]]:
    """Per swept parameter (label): rms and largest |estimate - truth|, its unit, the estimates on a
    bound, the estimates the data do not determine."""
    swept = {}
    for label, families, unit in factor.swept:
        # an estimate the data do not determine (no Cramer-Rao std) is held at its start value and
        # says nothing about the estimator: counted apart
        every = params[params["family"].isin(families)]
        rows = every[np.isfinite(every["std_crb"].to_numpy(dtype=float))]
        held = len(every) - len(rows)
        err = rows["error"].to_numpy(dtype=float)
        hits = 0
        for fam, est in zip(rows["family"], rows["estimate"].to_numpy(dtype=float), strict=True):
            lo, hi = bounds.get(fam, (-math.inf, math.inf))
            tol = 1e-6 * max(1.0, abs(lo), abs(hi))
            hits += int(est <= lo + tol or est >= hi - tol)
        swept[label] = (_rms(err), float(np.nanmax(np.abs(err))) if err.size else math.nan, unit, hits, held)
    return swept


def point_metrics(results: Sequence[ReplicationResult], factor: Factor,
                  bounds: Mapping[str, tuple[float, float]]) -> dict[str, Any]:
    """The metrics of one point from its replications (see the module docstring).

    Returns
    -------
    dict with ``n_ok``, ``n_failed``, ``failures`` (status text counts), ``n_pass`` (converged
    replications meeting every desired accuracy), ``n_unjudged`` (converged replications whose
    accuracy could not be computed where the others' could: not passing), per group ``acc_<group>``
    (median over replications, deg), ``acc_max_<group>``, ``swept`` (label -> (rms error, max
    |error|, unit, bound hits, undetermined estimates)), ``vane_bias_err_deg`` (rms),
    ``ratio_crb`` (median over the calibration parameters of scatter / mean CRB std),
    ``within_3sigma`` (fraction of calibration estimates within 3 CRB sigmas of the truth),
    ``ratio_colored``, ``within_3sigma_colored`` (the same against the honest deviations),
    ``resid_vane_deg`` (median vane residual 3-sigma).
    """
    ok = [r for r in results if r.ok]
    failed = [r for r in results if not r.ok]
    m: dict[str, Any] = {"n_ok": len(ok), "n_failed": len(failed), "failures": _failure_reasons(failed)}
    acc = pd.DataFrame([group_accuracy(r) for r in ok], columns=list(SENSOR_GROUPS))
    m["n_pass"], m["n_unjudged"] = passing(acc)
    for g in SENSOR_GROUPS:
        col = acc[g].dropna() if len(acc) else pd.Series(dtype=float)
        m[f"acc_{g}"] = float(col.median()) if len(col) else math.nan
        m[f"acc_max_{g}"] = float(col.max()) if len(col) else math.nan
    params = pd.concat([r.parameters for r in ok], ignore_index=True) if ok else pd.DataFrame(
        columns=["name", "family", "kind", "estimate", "error", "std_crb", "z_crb"])
    m["swept"] = _swept_errors(params, factor, bounds)
    m["vane_bias_err_deg"] = _rms(params.loc[params["family"].isin(VANE_BIAS_FAMILIES), "error"])
    summary = summarize_results(list(results))
    cal = summary.parameters[summary.parameters["kind"].isin(CALIBRATION_KINDS)]
    m["ratio_crb"] = float(np.nanmedian(cal["ratio_crb"])) if len(cal) and len(ok) > 1 else math.nan
    m["ratio_colored"] = (float(np.nanmedian(cal["ratio_colored"])) if len(cal) and len(ok) > 1
                          and np.isfinite(cal["ratio_colored"]).any() else math.nan)
    for key, col in (("within_3sigma", "z_crb"), ("within_3sigma_colored", "z_colored")):
        z = (params.loc[params["kind"].isin(CALIBRATION_KINDS), col].to_numpy(dtype=float)
             if col in params else np.zeros(0))
        z = z[np.isfinite(z)]
        m[key] = float(np.mean(np.abs(z) < 3.0)) if z.size else math.nan
    res = [float(r.channels.loc[(r.channels["kind"] == "residual")
                                & r.channels["name"].isin(SENSOR_GROUPS["vane AOA"]), "three_sigma"].max())
           for r in ok if len(r.channels)]
    m["resid_vane_deg"] = float(np.nanmedian(res)) if res else math.nan
    return m


def failing_groups(m: Mapping[str, Any]) -> list[str]:
    """The requirement groups a point's median accuracy misses (a NaN, no data, is not a miss)."""
    return [g for g, req in DESIRED_3SIGMA_DEG.items() if m[f"acc_{g}"] > req]


def swept_truth(point: Point) -> dict[str, tuple[np.ndarray, list[str]]]:
    """The true values (display units) of the swept parameters in replication 0 of a point: its
    maneuvers flown and instrumented as the replication does, the problem built, the truth
    projected (:func:`campaigns.truth.true_parameters`); for points whose estimations all failed
    (a failure record holds no estimates), to tell whether the truth lies beyond a bound.

    Returns
    -------
    label (of ``point.factor.swept``) -> (true values, their parameter families).
    """
    scenario = parse_scenario(point.raw, source=f"campaigns.studies.tolerance:{point.raw['name']}")
    draw = scenario.draw(0)
    truths = {md.job.index: fly(scenario, md) for md in draw.maneuvers}
    est = scenario.estimator
    with tempfile.TemporaryDirectory(prefix="fpr-tolerance-truth-") as tmp:
        write_scratch_dataset(scenario, draw.maneuvers, truths, Models.of(scenario), Path(tmp))
        problem = est.problem(tmp)
        values = true_parameters(problem).values
    specs = problem.parameters.specs
    out = {}
    for label, families, _ in point.factor.swept:
        keys = [k for k in values if family_of(k) in families]
        out[label] = (np.array([values[k] * specs[family_of(k)].display_scale for k in keys]),
                      [family_of(k) for k in keys])
    return out


def _beyond(values: np.ndarray, families: Sequence[str], names: Sequence[str],
            bounds: Mapping[str, tuple[float, float]]) -> int:
    """How many true values lie outside their family's bounds."""
    n = 0
    for fam, v in zip(names, values, strict=True):
        lo, hi = bounds.get(fam, (-math.inf, math.inf))
        n += int(fam in families and not lo <= v <= hi)
    return n


def collect(points: Sequence[Point], replications: int, errors: Mapping[Path, str],
            truth_of_failed: bool = True) -> pd.DataFrame:
    """One row per point: factor, level and :func:`point_metrics` (flattened); per swept
    parameter also the largest |truth| and how many truths lie beyond their bounds (from the
    converged replications, or from :func:`swept_truth` when none converged)."""
    bounds = bounds_display()
    rows = []
    cache: dict[Path, list[ReplicationResult]] = {}
    for p in points:
        row: dict[str, Any] = {"factor": p.factor.name, "level": p.factor.label(p.level),
                               "run": p.directory.name}
        if p.directory in errors:
            rows.append({**row, "n_ok": 0, "n_failed": replications,
                         "failures": errors[p.directory].splitlines()[0]})
            continue
        if p.directory not in cache:
            cache[p.directory] = load_results(p.directory, replications)
        results = cache[p.directory]
        m = point_metrics(results, p.factor, bounds)
        for k, v in m.items():
            if k == "swept":
                for label, (rms, mx, unit, hits, held) in v.items():
                    row[f"{label}_err_rms_{unit}"] = rms
                    row[f"{label}_err_max_{unit}"] = mx
                    row[f"{label}_at_bound"] = hits
                    row[f"{label}_undetermined"] = held
                row["swept"] = v
            else:
                row[k] = v
        ok = [r for r in results if r.ok]
        for label, families, unit in p.factor.swept:
            if ok:
                par = pd.concat([r.parameters for r in ok], ignore_index=True)
                par = par[par["family"].isin(families)]
                truth, names = par["truth"].to_numpy(dtype=float), list(par["family"])
            elif truth_of_failed and results:
                truth, names = swept_truth(p)[label]
            else:
                continue
            row[f"{label}_truth_max_{unit}"] = float(np.max(np.abs(truth))) if truth.size else math.nan
            row[f"{label}_truth_beyond_bound"] = _beyond(truth, families, names, bounds)
        row["swept"] = "; ".join(
            f"{label} {rms:.3g} ({mx:.3g}) {unit}"
            + (f" of |truth| <= {row[f'{label}_truth_max_{unit}']:.3g}" if f"{label}_truth_max_{unit}" in row
               else "")
            + (f", {hits} at bound" if hits else "") + (f", {held} undetermined" if held else "")
            for label, (rms, mx, unit, hits, held) in row.get("swept", {}).items()) or "-"
        row["fails"] = ", ".join(SHORT_TITLE[g] for g in failing_groups(row)) or "pass"
        rows.append(row)
    return pd.DataFrame(rows)

