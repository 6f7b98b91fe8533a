"""The workflow against the truth of a synthetic dataset: what the paper could not measure.

- **True accuracy**: each calibrated channel (the measurement run back through its estimated
  calibration model, :mod:`estimator.calibrated`) minus the true flow angle at its sensor, 3 sigma
  per sensor and Mach bin. The model's other inputs (``alpha_t``, the sidewash ``beta_s``, rates,
  airspeed) are the true ones, and each sample is compared with the truth at the time the channel
  actually saw (its injected total lag): this is the calibration's angle error, not its timing
  error (the time shifts are in the recovery table).
- **Installation biases**: the apportioned per-aircraft installation biases against the injected
  ones minus the fleet mean (the only part the data can tell apart from a correction-model bias).
- **Recovery**: every final estimate against its truth (:mod:`campaigns.truth`).
- **Wind** (filter-error method): each maneuver's smoothed turbulent wind against JSBSim's, both
  with their maneuver mean removed (the free initial velocities absorb the mean wind), rms per
  axis.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from campaigns.truth import (
    IMU_REFERENCE,
    SENSOR_SIGNAL_KINDS,
    _sensor_col,
    channel_values,
    maneuver_column,
    problem_tables,
    recovery_table,
    true_parameters,
    true_signals,
    truths_of,
)
from estimator.calibrated import calibrated_channel
from estimator.io import load_truth
from estimator.parameters import make_key
from estimator.problem import Problem
from estimator.result import EstimationResult
from estimator.workflow import RAD2DEG, WorkflowResult, apportion_biases, three_sigma


def calibrated_errors(problem: Problem, result: EstimationResult,
                      truth_cache: dict | None = None) -> dict[str, pd.DataFrame]:
    """Channel -> samples of (calibrated - true flow angle at the sensor): maneuver, t_s,
    true_rad, error_rad, alpha_t_rad (true angle of attack at the CG). ``truth_cache``: the
    maneuvers' truth read once for several callers (:func:`campaigns.truth.truths_of`)."""
    values = result.values
    tables = problem_tables(problem)
    chan_col = {c.name: c.column for c in problem.channels}
    out: dict[str, list[pd.DataFrame]] = {}
    truth_of = truths_of(problem, truth_cache)
    for m in problem.maneuvers:
        tr = truth_of[m.id]
        t_tr = tr["t_s"].to_numpy()
        inj = m.meta.get("injected", {})
        for ch in problem.channels:
            if ch.measures is None or ch.column not in m.measurements:
                continue
            target = _sensor_col(SENSOR_SIGNAL_KINDS[ch.measures], ch.sensor)
            if target not in tr:
                continue
            z = m.measurements[ch.column]
            keep = np.isfinite(z)
            # the truth at the time the sensor saw it: the column's injected total lag
            t_seen = (m.t_s - float(inj.get(f"time_shift_s.{maneuver_column(ch.column, m)}", 0.0)))[keep]

            def at(c: str, t_seen=t_seen, tr=tr, t_tr=t_tr) -> np.ndarray:
                return np.interp(t_seen, t_tr, tr[c].to_numpy())

            sig = true_signals(at, tr.columns, ch.sensor)
            for name in ch.expression.names - set(sig) - {"z", "zhat"}:
                if name in problem.parameters.specs:
                    continue
                data = m.measurements.get(chan_col.get(name, name), m.signals.get(name))
                if data is not None:
                    sig[name] = data[keep]
            params, tabs = channel_values(problem, values, m, ch, tables)
            x = calibrated_channel(ch, z[keep], sig, params, tabs)
            x_true = sig[ch.measures]
            out.setdefault(ch.name, []).append(pd.DataFrame({
                "maneuver": m.id, "t_s": m.t_s[keep], "true_rad": x_true, "error_rad": x - x_true,
                "alpha_t_rad": sig["alpha_t"]}))
    return {c: pd.concat(v, ignore_index=True) for c, v in out.items()}


def true_accuracy(wf: WorkflowResult, truth_cache: dict | None = None
                  ) -> tuple[pd.DataFrame, dict[tuple[float, str], dict]]:
    """Table 2 against the truth, and the error samples per (Mach, gear) stage for plots
    (``truth_cache``: :func:`campaigns.truth.truths_of`'s)."""
    rows, samples = [], {}
    limit = wf.alpha_limit_deg
    for st in wf.usable:
        errs = calibrated_errors(st.problem, st.result, truth_cache)
        samples[(st.mach, "down" if st.gear_down else "up")] = errs
        for name, df in errs.items():
            req = wf.declarations.requirements.get(name)
            if req is None:
                continue
            e = df["error_rad"].to_numpy() * RAD2DEG
            note = ""
            if req.low_alpha_only and limit is not None:
                e = e[df["alpha_t_rad"].to_numpy() * RAD2DEG < limit]
                note = f"alpha < {limit:.0f} deg"
            s = three_sigma(e)
            rows.append({"sensor": req.sensor, "channel": name, "mach": st.mach,
                         "gear": "down" if st.gear_down else "up", "n": int(e.size),
                         "three_sigma_deg": s, "desired_deg": req.desired_deg,
                         "passed": bool(s <= req.desired_deg), "note": note,
                         "mean_error_deg": float(np.mean(e)) if e.size else math.nan})
    return pd.DataFrame(rows), samples


def installation_recovery(wf: WorkflowResult, truth_cache: dict | None = None) -> pd.DataFrame:
    """Apportioned installation biases against their truth, deg (``truth_cache``:
    :func:`campaigns.truth.truths_of`'s).

    The truth is the same apportionment applied to the *true* vane biases of the reference bin's
    first estimation (the projection of :mod:`campaigns.truth`): a vane's installation bias reaches
    the calibrated channel through the airdata computer's local-to-free-stream correction, i.e.
    scaled by its slope (about 0.8), so the injected raw-angle bias (also listed) is not the
    channel's; and only deviations from the fleet mean are observable.
    """
    if wf.installation.empty:
        return pd.DataFrame()
    families = dict(wf.declarations.apportion)  # label -> bias family
    rows = []
    for mach, g in wf.installation.groupby("mach"):
        st = next(s for s in wf.first if s.mach == mach)
        truth = true_parameters(st.problem, st.result.free_estimated, truth_cache).values
        ac = [a for a in sorted({m.aircraft for m in st.problem.maneuvers})
              if all(make_key(fam, a) in truth for fam in families.values())]
        if not ac:
            continue
        ap = apportion_biases({k: {a: truth[make_key(fam, a)] for a in ac} for k, fam in families.items()})
        inj = {}
        for m in st.problem.maneuvers:
            i = m.meta.get("injected", {})
            # the synthesizer's raw installation bias of the vane the family belongs to
            inj.setdefault(m.aircraft, {fam: i.get(f"{_sensor_of(st.problem, fam)}.installation_bias_rad",
                                                   math.nan) for fam in families.values()})
        for a in g.index:
            if a not in ap.index:
                continue
            r = wf.installation.loc[a]
            for side, fam in families.items():
                t = ap.loc[a, f"installation_{side}"] * RAD2DEG
                est, std = r[f"installation_{side}_deg"], r[f"std_installation_{side}_deg"]
                std_col = r.get(f"std_colored_installation_{side}_deg", math.nan)
                rows.append({"aircraft": a, "vane": side, "mach": mach, "estimate_deg": est,
                             "truth_deg": t, "error_deg": est - t, "std_deg": std, "z": (est - t) / std,
                             "std_colored_deg": std_col, "z_colored": (est - t) / std_col,
                             "injected_raw_deg": float(inj[a][fam]) * RAD2DEG})
    return pd.DataFrame(rows)


def _sensor_of(problem: Problem, family: str) -> str | None:
    """The sensor of the channel whose model uses a bias family (its installation bias's truth)."""
    return next((c.sensor for c in problem.channels if family in c.expression.names), None)


def recovery(wf: WorkflowResult, truth_cache: dict | None = None) -> pd.DataFrame:
    """Every final estimate with a truth (calibration parameters, time delays, IMU biases, and the
    steady wind of a model set with the INS velocities; ``truth_cache``:
    :func:`campaigns.truth.truths_of`'s)."""
    frames = []
    for st in wf.usable:
        t = recovery_table(st.result, true_parameters(st.problem, st.result.free_estimated, truth_cache))
        wind = t.index.str.startswith(("wind_n[", "wind_e[", "wind_d["))
        t = t[t["kind"].isin(["imu_bias", "time_delay", "bias", "scale", "table"]) | wind].copy()
        t.insert(0, "gear", "down" if st.gear_down else "up")
        t.insert(0, "mach", st.mach)
        frames.append(t)
    return pd.concat(frames) if frames else pd.DataFrame()


def wind_errors(problem: Problem, result: EstimationResult) -> tuple[pd.DataFrame, dict[str, dict]]:
    """The filter-error wind history of ``result`` against the truth, per maneuver.

    Returns
    -------
    A table (maneuver, axis, rms_error_mps, true_std_mps, est_std_mps: the rms of the smoother's
    deviation) and, per maneuver, the series for a figure (``t_s``, ``estimated``, ``std``,
    ``truth``: (N, 3) each, means removed). Empty for an output-error result.
    """
    wh = result.wind_history
    rows, series = [], {}
    if wh is None:
        return pd.DataFrame(rows), series
    for m in problem.maneuvers:
        part = wh[wh["maneuver"] == m.id]
        if not len(part):
            continue
        tr = load_truth(problem, m.id)
        inj = m.meta.get("injected", {})
        # the model's clock is the IMU's: its sample at t shows the flight at t - (IMU lag)
        t = part["t_s"].to_numpy() - float(inj.get(f"time_shift_s.{IMU_REFERENCE}", 0.0))
        truth = np.stack([np.interp(t, tr["t_s"].to_numpy(), tr[f"true_wind_{a}_mps"].to_numpy())
                          for a in "ned"], axis=1)
        est = part[["wind_n_mps", "wind_e_mps", "wind_d_mps"]].to_numpy()
        std = part[["std_n_mps", "std_e_mps", "std_d_mps"]].to_numpy()
        truth = truth - truth.mean(axis=0)
        est = est - est.mean(axis=0)
        for i, axis in enumerate(("north", "east", "down")):
            rows.append({"maneuver": m.id, "kind": m.meta.get("kind", ""), "axis": axis,
                         "rms_error_mps": float(np.sqrt(np.mean((est[:, i] - truth[:, i]) ** 2))),
                         "true_std_mps": float(np.std(truth[:, i])),
                         "est_std_mps": float(np.sqrt(np.mean(std[:, i] ** 2)))})
        series[m.id] = {"t_s": part["t_s"].to_numpy(), "estimated": est, "std": std, "truth": truth}
    return pd.DataFrame(rows), series
