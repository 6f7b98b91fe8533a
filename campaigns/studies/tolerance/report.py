"""Planning study (c), its report: the text table, one conclusion per factor drawn from the numbers,
and the text file (header, setting, legend, table, conclusions)."""

from __future__ import annotations

import math
import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from campaigns.studies import scaffold
from campaigns.studies.common import IMU_SPREAD_ACCEL_MPS2, IMU_SPREAD_GYRO_DEG_S, typical_imu_biases_deg
from campaigns.studies.scaffold import Invocations, paragraph
from campaigns.studies.tolerance.analysis import bounds_display, failing_groups
from campaigns.studies.tolerance.config import (
    DESIRED_3SIGMA_DEG,
    SENSOR_GROUPS,
    SHORT_TITLE,
    STUDY_CODE,
    WIND_TOWARDS_DEG,
    Factor,
    StudyConfig,
    base_scenario,
    study_points,
)
from synth.errors import ErrorConfig


def _tightest(r: Mapping[str, Any]) -> str:
    margins = {g: r[f"acc_{g}"] / req for g, req in DESIRED_3SIGMA_DEG.items()
               if np.isfinite(r.get(f"acc_{g}", math.nan))}
    if not margins:
        return ""
    g = max(margins, key=margins.get)
    return f" (at {r['level']} the tightest is {g}: {r[f'acc_{g}']:.2f} of {DESIRED_3SIGMA_DEG[g]:g} deg)"


def _swept_size(factor: Factor, r: Mapping[str, Any]) -> str:
    """How large the swept parameters' true values were at a level: " (|truth| up to: tau 292 ms)"."""
    parts = [f"{label} {r[f'{label}_truth_max_{unit}']:.3g} {unit}" for label, _, unit in factor.swept
             if np.isfinite(r.get(f"{label}_truth_max_{unit}", math.nan))]
    return f" (|truth| up to {', '.join(parts)})" if parts else ""


def _largest_change(rows: pd.DataFrame, base: Mapping[str, Any]) -> str:
    """The largest change of a requirement group's accuracy from the base over the rows."""
    best, where = 0.0, None
    for _, q in rows.iterrows():
        for g in DESIRED_3SIGMA_DEG:
            d = q.get(f"acc_{g}", math.nan) - base.get(f"acc_{g}", math.nan)
            if np.isfinite(d) and abs(d) >= abs(best):
                best, where = d, (g, q["level"])
    if where is None:
        return ""
    return f"; the largest change from the base is {best:+.2g} deg ({where[0]} at {where[1]})"


def _first_failure(rows: pd.DataFrame) -> tuple[list[pd.Series], pd.Series | None, list[str]]:
    """The rows that pass every requirement before the first that does not, that row and what it
    misses (``["convergence"]`` when no estimation succeeded, ``"verdict"`` among the sensor groups
    when some ended with a failure verdict)."""
    passed = []
    for _, r in rows.iterrows():
        # a level holds only where the estimations succeed: failure verdicts count against it
        bad = (failing_groups(r) + (["verdict"] if r.get("n_failed", 0) else [])
               if r.get("n_ok", 0) else ["convergence"])
        if bad:
            return passed, r, bad
        passed.append(r)
    return passed, None, []


def _bound_note(factor: Factor, r: Mapping[str, Any], bounds: Mapping[str, tuple[float, float]]) -> str:
    """Where a swept parameter's truth lies beyond its bounds (or its estimates sit on them):
    "the true tau (up to 392 ms) lies beyond its bounds [-300, 300] ms (estimates up to 92 ms off)",
    or "" when nothing is on a bound."""
    parts = []
    for label, families, unit in factor.swept:
        if not (r.get(f"{label}_truth_beyond_bound", 0) > 0 or r.get(f"{label}_at_bound", 0) > 0):
            continue
        lo, hi = bounds.get(families[0], (-math.inf, math.inf))
        err = r.get(f"{label}_err_max_{unit}", math.nan)
        truth = r.get(f"{label}_truth_max_{unit}", math.nan)
        parts.append(f"the true {label} (up to {truth:.3g} {unit}) lies beyond its bounds "
                     f"[{lo:g}, {hi:g}] {unit}"
                     + (f" (estimates up to {err:.3g} {unit} off)" if np.isfinite(err) else ""))
    return " and ".join(parts)


def conclusion(factor: Factor, rows: pd.DataFrame, base: Mapping[str, Any] | None = None,
               variant: tuple[Factor, pd.DataFrame] | None = None,
               bounds: Mapping[str, tuple[float, float]] | None = None) -> str:
    """One sentence on a factor, drawn from its rows (levels in order): up to which level every
    requirement holds, where it is first lost and for which sensors, and why as far as the numbers
    tell — a true value beyond a bound of the model set, a fit in a wrong minimum (residuals grown)
    or a model that does not fit (unmodelled factors) — the failed estimations, a timing lost to a
    bound while the values pass, and what a variant with another estimator set-up (IMU biases
    started at their mean) changes.

    Parameters
    ----------
    factor, rows : the factor and its rows of :func:`~campaigns.studies.tolerance.analysis.collect`.
    base : the base scenario's row (residual and scatter/CRB reference; default: the first row).
    variant : the variant factor and its rows.
    bounds : parameter family -> bounds, display units (default: the tejas model set's).
    """
    bounds = bounds_display() if bounds is None else bounds
    rows = rows[rows["level"] != "typical"] if (rows["level"] != "typical").any() else rows
    base = rows.iloc[0] if base is None else base
    passed, r, bad = _first_failure(rows)
    text = _holds_text(factor, rows, base, passed, r)
    if r is not None:
        text += _lost_text(factor, r, bad) + _why_lost_text(factor, r, base, bad, bounds)
    # bounds reached where the values still pass: the timing (or bias) is lost, not the value
    for q in passed:
        note = _bound_note(factor, q, bounds)
        if note:
            text += (f"; at {q['level']} {note}: the values still pass because the accuracy is measured at "
                     "each channel's true lag, but that much of the timing is lost, to the bound and not to "
                     "the method")
    partial = [q for _, q in rows.iterrows() if q.get("n_failed", 0) and q.get("n_ok", 0)
               and (r is None or q["level"] != r["level"])]  # the first failing level is told above
    if partial:
        text += "; failed estimations: " + ", ".join(
            f"{int(q['n_failed'])} of {int(q['n_ok'] + q['n_failed'])} at {q['level']} ({q['failures']})"
            for q in partial)
    if variant is not None:
        text += _variant_text(variant, rows, bounds)
    return text + "."


def _holds_text(factor: Factor, rows: pd.DataFrame, base: Mapping[str, Any], passed: Sequence[pd.Series],
                r: pd.Series | None) -> str:
    """The sentence's start: up to which level every requirement holds (and, when one fails, the
    words leading to the first failing level)."""
    name = factor.title
    if r is None:
        return (f"{name}: every desired accuracy holds over the whole range swept, up to "
                f"{rows['level'].iloc[-1]}{_swept_size(factor, passed[-1])}{_tightest(passed[-1])}"
                f"{_largest_change(rows, base)}")
    if len(passed) > 1:
        return (f"{name}: every desired accuracy holds up to {passed[-1]['level']}"
                f"{_swept_size(factor, passed[-1])}{_tightest(passed[-1])}; at ")
    if passed:
        return (f"{name}: every desired accuracy holds at {passed[0]['level']}{_tightest(passed[0])}; "
                "already at ")
    return f"{name}: already at "


def _lost_text(factor: Factor, r: pd.Series, bad: Sequence[str]) -> str:
    """The first failing level: its failure verdicts, the groups it loses, the replications that
    pass."""
    n = int(r.get("n_ok", 0) + r.get("n_failed", 0))
    lost = [g for g in bad if g not in ("verdict", "convergence")]
    if bad == ["convergence"]:
        return f"{r['level']} every estimation ended with a failure verdict ({r.get('failures', '')})"
    text = f"{r['level']}{_swept_size(factor, r)} "
    if "verdict" in bad:
        n_ok, n_pass = int(r["n_ok"]), int(r.get("n_pass", r["n_ok"]))
        # the medians meet every requirement; each replication need not
        met = (("meets" if n_ok == 1 else "meet") + " every requirement" if n_pass == n_ok else
               f"{n_pass} meet every requirement (the medians do)")
        text += (f"{int(r['n_failed'])} of {n} estimations ended with a failure verdict "
                 f"({r.get('failures', '')})" + (", and " if lost else
                                                 f"; of the {n_ok} that succeeded " + met
                                                 if n_pass != n_ok else
                                                 f"; the {n_ok} that succeeded " + met))
    if lost:
        text += "it is lost for " + ", ".join(
            f"{g} ({r[f'acc_{g}']:.2f} > {DESIRED_3SIGMA_DEG[g]:g} deg)" for g in lost)
        if np.isfinite(r.get("n_pass", math.nan)):
            text += f" ({int(r['n_pass'])} of {n} replications meet every requirement)"
    return text


def _why_lost_text(factor: Factor, r: pd.Series, base: Mapping[str, Any], bad: Sequence[str],
                   bounds: Mapping[str, tuple[float, float]]) -> str:
    """Why the first failing level fails, as far as the numbers tell: a bound, a wrong minimum, a
    model that no longer fits, an error the residuals do not show; and optimistic Cramér-Rao
    bounds."""
    n = int(r.get("n_ok", 0) + r.get("n_failed", 0))
    lost = [g for g in bad if g not in ("verdict", "convergence")]
    text = ""
    note = _bound_note(factor, r, bounds)
    base_res, res = base.get("resid_vane_deg", math.nan), r.get("resid_vane_deg", math.nan)
    grown = np.isfinite(res) and np.isfinite(base_res) and res > 1.5 * base_res
    if note:
        text += f"; there {note} (estimator/models/tejas.toml): the loss is the bound's, not the method's"
    elif factor.swept and grown:
        text += (f"; the estimates stay inside their bounds but the fit stops in a wrong minimum (median "
                 f"vane residual 3-sigma {base_res:.2f} -> {res:.2f} deg, {int(r.get('n_ok', 0))} of {n} "
                 "reported as a success)")
    elif not factor.swept and grown:
        text += (f"; the vane residual 3-sigma grows from {base_res:.2f} to {res:.2f} deg: the data carry "
                 "air motion the calibration model alone does not follow (all of it misfit for the "
                 "output-error method, no process noise; the filter-error method's wind states take "
                 "it up)")
    elif np.isfinite(res) and lost:  # (a loss by failure verdicts alone was seen in the residuals)
        text += (f"; the vane residual 3-sigma stays near {res:.2f} deg (base {base_res:.2f}): an error "
                 "the fit does not see in its residuals")
    ratio, base_ratio = r.get("ratio_crb", math.nan), base.get("ratio_crb", math.nan)
    if np.isfinite(ratio) and np.isfinite(base_ratio) and ratio > 2.0 * base_ratio:
        within = r.get("within_3sigma", math.nan)
        text += (f", and the Cramer-Rao bounds turn optimistic (scatter/CRB {ratio:.1f}, base "
                 f"{base_ratio:.1f}; {within:.0%} of the estimates within 3 sigma)")
    return text


def _variant_text(variant: tuple[Factor, pd.DataFrame], rows: pd.DataFrame,
                  bounds: Mapping[str, tuple[float, float]]) -> str:
    """What the variant (another estimator set-up) changes at the levels where the factor fails."""
    vf, vrows = variant
    how = vf.title.split(", ", 1)[-1]
    text = ""
    for _, q in vrows.iterrows():
        mine = rows[rows["level"] == q["level"]]
        lost_here = len(mine) and (failing_groups(mine.iloc[0]) or not mine.iloc[0].get("n_ok", 0)
                                   or mine.iloc[0].get("n_failed", 0))
        groups = failing_groups(q) if q.get("n_ok", 0) else []
        n_q, n_bad = int(q.get("n_ok", 0) + q.get("n_failed", 0)), int(q.get("n_failed", 0))
        if lost_here and not groups and not n_bad:
            text += (f"; {how}, every requirement holds at {q['level']}{_tightest(q)}: the loss is the "
                     "start value's (0), not the biases' size")
        elif lost_here:
            note = _bound_note(vf, q, bounds)
            text += (f"; {how}, at {q['level']} it is still lost" + (" for " + ", ".join(groups) if groups
                                                                    else "")
                     + (f" ({n_bad} of {n_q} estimations ended with a failure verdict: "
                        f"{q.get('failures', '')})" if n_bad else "")
                     + (f" ({note})" if note else ""))
    return text


def _fmt(v: Any, spec: str = ".3f") -> str:
    if isinstance(v, float | np.floating):
        return "nan" if not np.isfinite(v) else format(v, spec)
    return str(v)


def table_text(df: pd.DataFrame) -> str:
    """The study's table, one line per point."""
    head = (f"{'factor':<11} {'level':>8} {'ok/fail':>7} {'pass':>4} "
            + " ".join(f"{SHORT_TITLE[g]:>6}" for g in SENSOR_GROUPS)
            + f" {'fails':<16} {'b_l,b_r err':>11} {'scat/CRB':>8} {'in3sig':>6} {'scat/hon':>8}"
            f" {'in3hon':>6} {'res_vane':>8}"
            "  swept parameter error rms (max)")
    lines = [head, "-" * len(head)]
    for _, r in df.iterrows():
        lines.append(
            f"{r['factor']:<11} {r['level']:>8} {int(r.get('n_ok', 0)):>3}/{int(r.get('n_failed', 0)):<3} "
            f"{_fmt(r.get('n_pass', math.nan), '.0f'):>4} "
            + " ".join(f"{_fmt(r.get(f'acc_{g}', math.nan)):>6}" for g in SENSOR_GROUPS)
            + f" {str(r.get('fails', '')):<16} {_fmt(r.get('vane_bias_err_deg', math.nan), '.4f'):>11}"
            f" {_fmt(r.get('ratio_crb', math.nan), '.2f'):>8}"
            f" {_fmt(r.get('within_3sigma', math.nan), '.2f'):>6}"
            f" {_fmt(r.get('ratio_colored', math.nan), '.2f'):>8}"
            f" {_fmt(r.get('within_3sigma_colored', math.nan), '.2f'):>6}"
            f" {_fmt(r.get('resid_vane_deg', math.nan)):>8}  {r.get('swept', '-')}"
            + (f"  [{r['failures']}]" if isinstance(r.get("failures"), str) and r.get("failures") else "")
            + (f"  [{int(r['n_unjudged'])} converged without a calibration that can be applied]"
               if r.get("n_unjudged", 0) and np.isfinite(r.get("n_unjudged")) else ""))
    return "\n".join(lines)



def _typical_delays_text() -> str:
    """The typical preset's flow-sensor delays and recorder latencies, ms."""
    typ = ErrorConfig.typical()
    sensors = ", ".join(f"{n} {1e3 * e.delay_s:g}" for n, e in typ.sensors.items())
    recorders = ", ".join(f"{n} {1e3 * e.delay_s:g}" for n, e in typ.recorders.items())
    return f"sensors {sensors}; recorder latencies {recorders} ms"


def _bounds_text(factors: Sequence[Factor]) -> str:
    bounds = bounds_display()
    seen: dict[tuple[float, float, str], list[str]] = {}
    for f in factors:
        for _, families, unit in f.swept:
            for fam in families:
                lo, hi = bounds.get(fam, (-math.inf, math.inf))
                if fam not in seen.setdefault((lo, hi, unit), []):
                    seen[(lo, hi, unit)].append(fam)
    return "; ".join(f"{', '.join(fams)} in [{lo:g}, {hi:g}] {unit}" for (lo, hi, unit), fams in seen.items())


def report(df: pd.DataFrame, config: StudyConfig, replications: int, command: str,
           invocations: Invocations) -> str:
    """The text file: header (command, machine, cost), metric legend, table, conclusions.

    ``invocations``: one record per invocation of the study on this output directory (wall_s,
    cpu_s, replications_run, load_start, load_end, code), this one last.
    """
    base = base_scenario(config)
    flights = "; ".join(f"{'+'.join(b['configurations'])} x Mach {b['mach']} x {', '.join(b['maneuvers'])}"
                        for b in base["flights"])
    accel_mps2, gyro_deg_s = typical_imu_biases_deg()
    est = base["estimator"]
    runs = df["run"].nunique() if "run" in df else len(df)

    desired = ", ".join(f"{SHORT_TITLE[g]} {v:g}" for g, v in DESIRED_3SIGMA_DEG.items())
    lines = [
        *scaffold.header_lines(
            "Planning study (c): how large may IMU biases, time delays, winds and turbulence be before the "
            "desired accuracy is lost? One factor at a time around the base scenario; every point a Monte "
            "Carlo run (campaigns/montecarlo).", command, STUDY_CODE,
            f"{replications} replications per point, {runs} distinct runs", invocations),
        *paragraph(f"base scenario: {flights}; errors preset typical (nose-probe irregularity off); "
              f"{base['local_flow_truth']} / {base['adc_baseline']} (representable by the model set: a loss "
              f"of accuracy is the swept factor's); {base['environment']['planet']} earth, calm air; IMU "
              f"biases drawn per maneuver (std {IMU_SPREAD_ACCEL_MPS2:g} m/s^2, {IMU_SPREAD_GYRO_DEG_S:g} "
              f"deg/s at scale 1). Estimator: {est.get('model', 'tejas')} model set, channels "
              f"{est.get('channels', 'all')}, at most {est.get('max_iterations', 40)} iterations"
              + (f", the {est['solver']['method'].replace('_', '-')} method" if est.get('solver', {}).get(
                  'method') else "") + "."),
        *paragraph(f"levels: IMU biases x typical (accel {accel_mps2} m/s^2, gyro "
              f"{[round(g, 3) for g in gyro_deg_s]} deg/s; the per-maneuver spread scaled too); flow delay "
              f"= the delay of every flow sensor (typical: {_typical_delays_text()}); INS latency on the "
              f"INS recorder; steady wind towards {WIND_TOWARDS_DEG:g} deg; turbulence redrawn every "
              f"replication. Bounds of the swept parameters: {_bounds_text(config.factors)}."),
        *paragraph("columns: vane_a, sp_a, sp_b, np_b, boom_a, boom_b = calibrated vane AOA (worse of the "
              "two), side-probe AOA, side-probe AOSS, nose-probe AOSS, boom AOA, boom AOSS (worse of "
              "upper/lower): |mean| + 3 std of (calibrated channel - true flow angle) over all samples, "
              f"deg, median over the replications; desired: {desired} deg (the boom has no stated "
              "requirement; np_b pools every AOA flown). The calibrated channel is compared with the "
              "truth at the channel's true lag: the columns measure the error in value, not in timing. "
              "ok/fail = converged / failed estimations; pass = converged replications meeting every "
              "desired accuracy (one whose calibrated channels cannot be computed, a table flat "
              "somewhere, does not pass: counted in [..]); fails = groups whose median misses the desired "
              "accuracy; b_l,b_r err = rms of estimate - truth of the vane biases, deg; scat/CRB = median "
              "over the calibration parameters (delays, biases, scales, tables) of the Monte Carlo "
              "scatter / mean Cramer-Rao std; in3sig = fraction of calibration estimates within 3 CRB "
              "sigmas of the truth; scat/hon, in3hon = the same against the honest (coloured-residual "
              "or -innovation) deviations the result reports; res_vane = vane residual 3-sigma "
              "(measurement - model: the scatter of the paper's Table 2), deg; swept parameter error = rms "
              "(max |.|) of estimate - truth of the swept parameter's estimates that the data determine, the "
              "largest |truth|, the number of estimates on a bound; [..] = failed estimations."),
        table_text(df),
        "",
        "conclusions:",
    ]
    base_run = next(q.directory.name for q in study_points(config, Path("."))
                    if q.level == q.factor.base_level)
    base_rows = df[df["run"] == base_run] if "run" in df else df.iloc[:0]
    base_row = base_rows.iloc[0] if len(base_rows) else None
    for f in config.factors:
        rows = df[df["factor"] == f.name].reset_index(drop=True)
        if f.variant_of is not None or not len(rows):
            continue
        variants = [(v, df[df["factor"] == v.name].reset_index(drop=True))
                    for v in config.factors if v.variant_of == f.name]
        text = conclusion(f, rows, base=base_row, variant=variants[0] if variants else None)
        lines += textwrap.wrap(text, width=108, initial_indent="- ", subsequent_indent="  ")
    return "\n".join(lines) + "\n"
