"""One Monte Carlo replication: instrument, estimate, compare with the truth.

:func:`run_replication` takes the truths of the maneuvers flown once (or flies those whose air
changes), instruments every maneuver with the replication's drawn errors and noise seeds, writes
them as a scratch ``fpr fly`` dataset (the estimator reads flight data only through the documented
format, so a replication sees exactly what a user's calibration would), builds the estimation
problem, estimates, and returns a :class:`ReplicationResult`: every free parameter's estimate
beside its truth with its Cramér-Rao and coloured-residual deviations and z-scores
(:func:`campaigns.truth.recovery_table`), and per channel the scatter of the residuals (the
paper's Table 2) and of the calibrated channel against the true flow angle
(:func:`calibrated_channel_errors`).
"""

from __future__ import annotations

import json
import re
import tempfile
import time
import traceback
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from threadpoolctl import threadpool_limits

# the private helpers of campaigns.truth map a parameter name to its key for a maneuver and a
# canonical channel to its dataset column; the calibrated-channel errors below use the same keys
from campaigns.truth import (
    _dataset_column,
    channel_values,
    problem_tables,
    recovery_table,
    true_parameters,
    true_signals,
)
from estimator.io import problem_from_dataset
from estimator.problem import Problem
from estimator.result import STATUS_TEXT, EstimationResult
from estimator.solver import SolverOptions, estimate
from synth.campaign import software_versions
from synth.dataset import FORMAT, FORMAT_VERSION, write_maneuver, write_manifest
from synth.flight import fly_maneuver
from synth.instrument import instrument
from synth.local_flow import load_adc_baseline, load_local_flow_truth
from synth.maneuvers import ManeuverSpec
from synth.truth import TruthTrajectory

from .scenario import ManeuverDraw, Scenario, draws_table

#: columns of the per-replication table (one row per parameter, channel accuracy or drawn value)
COLUMNS = ("replication", "record", "name", "family", "kind", "unit", "estimate", "truth", "error",
           "std_crb", "std_colored", "z_crb", "z_colored", "mean", "std", "three_sigma", "n")
#: the angle signals a flow channel's model may take; the calibrated channel estimates the one its
#: model depends on most
_ANGLE_SIGNALS = ("alpha_s", "beta_s", "flank_s")
#: maneuver keys: one per (job, segment), as synth.campaign numbers them (so the noise of a
#: maneuver does not depend on which other maneuvers are flown)
_SEGMENTS_PER_JOB = 64


@dataclass(frozen=True)
class ReplicationResult:
    """What one replication found (display units: deg, deg/s, ms, as the estimator reports).

    Attributes
    ----------
    index : the replication.
    ok : the estimation converged and the tables are filled.
    status : the estimator's status (1 converged, 0 iteration limit, 2 stalled, -1 failed) or -1
        when the replication raised before or during estimation.
    message : the estimator's message, or the error and its traceback.
    noise_seed : the master seed of the replication's noise sources.
    scenario_hash : the scenario it belongs to.
    elapsed_s : wall time of the replication (not part of the tables: they stay bit-identical).
    parameters : one row per free parameter with a truth (see :data:`COLUMNS`).
    channels : per channel and kind ("residual", "calibrated"): mean, std, three_sigma, n.
    draws : the drawn values (path, instance, component, value SI).
    warnings : what the data import warned about.
    """

    index: int
    ok: bool
    status: int
    message: str
    noise_seed: int
    scenario_hash: str
    elapsed_s: float = 0.0
    parameters: pd.DataFrame = field(default_factory=pd.DataFrame, repr=False)
    channels: pd.DataFrame = field(default_factory=pd.DataFrame, repr=False)
    draws: pd.DataFrame = field(default_factory=pd.DataFrame, repr=False)
    warnings: tuple[str, ...] = ()

    def meta(self) -> dict:
        """The scalars, JSON-ready (stored in the Parquet file's metadata / the failure record)."""
        return {"replication": self.index, "ok": self.ok, "status": self.status,
                "status_text": STATUS_TEXT.get(self.status, str(self.status)), "message": self.message,
                "noise_seed": self.noise_seed, "scenario_hash": self.scenario_hash,
                "elapsed_s": self.elapsed_s, "warnings": list(self.warnings)}

    def to_pandas(self) -> pd.DataFrame:
        """One long table: parameter rows, channel rows and drawn-value rows (:data:`COLUMNS`)."""
        parts = []
        if len(self.parameters):
            parts.append(self.parameters.assign(record="parameter"))
        if len(self.channels):
            parts.append(self.channels.assign(record="channel"))
        if len(self.draws):
            d = self.draws
            parts.append(pd.DataFrame({
                "record": "draw",
                "name": [p + (f"[{i}]" if i else "") + f"[{c}]"
                         for p, i, c in zip(d["path"], d["instance"], d["component"], strict=True)],
                "family": d["path"], "kind": "draw", "unit": "SI", "estimate": d["value"]}))
        df = pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=list(COLUMNS))
        df["replication"] = self.index
        for c in COLUMNS:
            if c not in df:
                df[c] = "" if c in ("record", "name", "family", "kind", "unit") else np.nan
        df = df[list(COLUMNS)]
        text = ["record", "name", "family", "kind", "unit"]
        df[text] = df[text].fillna("").astype(str)
        num = [c for c in COLUMNS if c not in text and c != "replication"]
        df[num] = df[num].astype(float)
        df["replication"] = df["replication"].astype(np.int64)
        return df

    @classmethod
    def from_pandas(cls, df: pd.DataFrame, meta: Mapping) -> ReplicationResult:
        """Inverse of :meth:`to_pandas` + :meth:`meta` (drawn values come back as records)."""
        p = df[df["record"] == "parameter"].drop(columns="record").reset_index(drop=True)
        c = df[df["record"] == "channel"].drop(columns="record").reset_index(drop=True)
        d = df[df["record"] == "draw"]
        # name = path[instance][component] (instance absent for fleet-wide draws)
        parts = [re.fullmatch(r"(?:\[(.*?)\])?\[(\d+)\]", n[len(p):])
                 for n, p in zip(d["name"], d["family"], strict=True)]
        draws = pd.DataFrame({"path": d["family"].to_numpy(),
                              "instance": [m.group(1) or "" for m in parts],
                              "component": [int(m.group(2)) for m in parts],
                              "value": d["estimate"].to_numpy()})
        return cls(index=int(meta["replication"]), ok=bool(meta["ok"]), status=int(meta["status"]),
                   message=str(meta["message"]), noise_seed=int(meta["noise_seed"]),
                   scenario_hash=str(meta["scenario_hash"]), elapsed_s=float(meta.get("elapsed_s", 0)),
                   parameters=p, channels=c, draws=draws.reset_index(drop=True),
                   warnings=tuple(meta.get("warnings", ())))


# ---------------------------------------------------------------------------- the worker's state


@dataclass(frozen=True)
class Models:
    """The local-flow truth and ADC baseline of a scenario, loaded once per process."""

    truth_model: object
    adc_baseline: object

    @classmethod
    def of(cls, scenario: Scenario) -> Models:
        c = scenario.campaign
        return cls(load_local_flow_truth(c.local_flow_truth), load_adc_baseline(c.adc_baseline))


def fly(scenario: Scenario, md: ManeuverDraw) -> tuple[TruthTrajectory, ...]:
    """Fly one maneuver of the scenario in its (drawn) environment: the truth segments.

    Raises :class:`synth.flight.FlightError` when it cannot be flown.
    """
    fleet = scenario.campaign.fleet
    cfg = fleet.configuration(md.job.configuration_id)
    return tuple(fly_maneuver(ManeuverSpec.from_dict(md.job.maneuver), fleet.airframe, cfg.aircraft,
                              md.environment))


def _entry(scenario: Scenario, md: ManeuverDraw, seg_no: int, n_seg: int, truth: TruthTrajectory,
           inst, mid: str) -> dict:
    """The manifest entry of one instrumented maneuver, as synth.campaign writes it (the same
    keys: keep the two in step until synth.campaign offers this as a function)."""
    fleet = scenario.campaign.fleet
    cfg = fleet.configuration(md.job.configuration_id)
    spec = ManeuverSpec.from_dict(md.job.maneuver)
    data = inst.data
    return {
        "id": mid, "file": f"maneuvers/{mid}.parquet", "job_index": md.job.index,
        "configuration": cfg.id, "aircraft": cfg.aircraft.id, "nose_sensor": cfg.nose_sensor,
        "sensors": list(cfg.sensors), "kind": spec.kind, "segment": seg_no, "n_segments": n_seg,
        "mach_nominal": spec.mach, "mach_mean": float(np.mean(truth.mach)),
        "mach_min": float(np.min(truth.mach)), "mach_max": float(np.max(truth.mach)),
        "altitude_m": spec.altitude_m, "gear_down": bool(spec.gear_down),
        "duration_s": float(data["t_s"].iloc[-1] - data["t_s"].iloc[0]), "n_samples": int(len(data)),
        "sample_rate_hz": scenario.campaign.common_rate_hz,
        "r_cg_body_m_mean": np.mean(truth.r_cg_body_m, axis=0).tolist(),
        "g_mps2_mean": float(np.mean(truth.g_mps2)), "maneuver": spec.to_dict(),
        "environment": md.environment.to_dict(), "injected": inst.injected,
        "channel_units": inst.channel_units,
        "own_rate_columns": list(inst.own_rate_columns),
        "flight_meta": {k: v for k, v in truth.meta.items() if k != "spec"},
    }


def write_scratch_dataset(scenario: Scenario, draws: Sequence[ManeuverDraw],
                          truths: Mapping[int, Sequence[TruthTrajectory]], models: Models,
                          directory: Path) -> dict[str, pd.DataFrame]:
    """Instrument every maneuver with its drawn errors and write an ``fpr fly`` dataset.

    Returns maneuver id -> its table (measured and ``true_*`` columns), kept for the accuracy
    against the truth.
    """
    fleet = scenario.campaign.fleet
    (directory / "maneuvers").mkdir(parents=True, exist_ok=True)
    entries, tables = [], {}
    for md in draws:
        cfg = fleet.configuration(md.job.configuration_id)
        segments = truths[md.job.index]
        for seg_no, truth in enumerate(segments):
            inst = instrument(truth, fleet.airframe, cfg, md.errors,
                              maneuver_key=md.job.index * _SEGMENTS_PER_JOB + seg_no,
                              common_rate_hz=scenario.campaign.common_rate_hz,
                              truth_model=models.truth_model, adc_baseline=models.adc_baseline)
            mid = f"m{md.job.index:04d}" + (f"s{seg_no}" if len(segments) > 1 else "")
            entry = _entry(scenario, md, seg_no, len(segments), truth, inst, mid)
            write_maneuver(directory / entry["file"], inst.data, entry)
            entries.append(entry)
            tables[mid] = inst.data
    airframe = fleet.airframe
    write_manifest(directory, {
        "format": FORMAT, "format_version": FORMAT_VERSION,
        "campaign": {"name": scenario.name, "source": scenario.source, "seed": scenario.seed},
        "software": software_versions(),
        "airframe": {"name": airframe.name, "jsbsim_model": airframe.jsbsim_model,
                     "reference_point": airframe.reference_point,
                     "positions_body_m": {k: v.tolist() for k, v in airframe.positions_body_m.items()}},
        "common_rate_hz": scenario.campaign.common_rate_hz,
        "maneuvers": entries, "failures": [],
    })
    return tables


# ---------------------------------------------------------------------------- accuracy tables


def residual_accuracy(result: EstimationResult) -> pd.DataFrame:
    """Per channel, the residual (measurement - model) pooled over the maneuvers: mean, std,
    3-sigma (the paper's Table 2 scatter), in display units."""
    rows = []
    res = result.residuals_table()
    if not len(res):
        return pd.DataFrame(columns=["name", "kind", "unit", "mean", "std", "three_sigma", "n"])
    for ch, g in res.groupby("channel", sort=True):
        n = g["n"].to_numpy(dtype=float)
        mean = float(np.sum(n * g["mean"]) / n.sum())
        ms = float(np.sum(n * g["rms"] ** 2) / n.sum())
        std = float(np.sqrt(max(ms - mean * mean, 0.0)))
        scale, unit = result.channel_display.get(ch, (1.0, ""))
        rows.append({"name": ch, "kind": "residual", "unit": unit, "mean": mean * scale,
                     "std": std * scale, "three_sigma": 3.0 * std * scale, "n": n.sum()})
    return pd.DataFrame(rows)


def calibrated_channel_errors(problem: Problem, result: EstimationResult,
                              tables: Mapping[str, pd.DataFrame]) -> dict[str, np.ndarray]:
    """The error of each calibrated flow channel against the true flow angle at its sensor, SI.

    The calibrated channel inverts the estimated model: the angle ``a_hat`` at which the model
    gives the measurement ``z``. To first order (the errors are tenths of a degree, the tables'
    curvature over that is negligible) ``a_hat - a_true = (z - y_hat(a_true)) / (dy_hat/da)``, with
    ``y_hat`` the model at the estimate evaluated on the true flow at the sensor. The measurement
    is compared with the truth at the channel's true lag (``time_shift_s`` of its column): this is
    the error in the value, not in the timing. The model's other inputs (CG angles, TAS, rates)
    are their true values. Small and replaceable: issue 4 builds the proper calibrated-channel
    function in ``campaigns/``.

    Returns
    -------
    channel name -> errors over every maneuver's samples (rad).
    """
    ps = problem.parameters
    theta = result.values
    tabs_all = problem_tables(problem)
    chan_col = {c.name: c.column for c in problem.channels}
    out: dict[str, list[np.ndarray]] = {}
    for ch in problem.channels:
        if ch.sensor is None:
            continue
        expr = ch.expression
        angles = [a for a in _ANGLE_SIGNALS if a in expr.names]
        col = _dataset_column(ch.column)
        for m in problem.maneuvers:
            df = tables.get(m.id)
            clean_col = f"true_clean_{col}"
            if df is None or ch.column not in m.measurements or clean_col not in df or not angles:
                continue
            lag = float(m.meta.get("injected", {}).get(f"time_shift_s.{col}", 0.0))
            t_true = df["t_s"].to_numpy()
            z = m.measurements[ch.column]
            ts = m.t_s - lag
            ok = (ts >= t_true[0]) & (ts <= t_true[-1]) & np.isfinite(z)

            def at(column: str) -> np.ndarray:
                return np.interp(ts[ok], t_true, df[column].to_numpy())  # noqa: B023 (used at once)

            sig = true_signals(at, df.columns, ch.sensor)
            clean = at(clean_col)
            sig |= {"z": clean, "zhat": clean}
            for name in expr.names - set(sig):
                if name in ps.specs:
                    continue
                other = chan_col.get(name, name)
                if other in m.measurements:  # another channel's measurement (f4(alpha_zsp))
                    sig[name] = m.measurements[other][ok]
                elif name in m.signals:
                    sig[name] = m.signals[name][ok]
            try:
                params, tabs = channel_values(problem, theta, m, ch, tabs_all)
            except KeyError:  # a parameter this maneuver's aircraft does not have
                continue
            if any(a not in sig for a in angles):
                continue
            dual = expr.evaluate(sig, params, tabs, state_signals=frozenset(angles))
            slopes = {a: np.broadcast_to(dual.dsignal.get(a, 0.0), clean.shape) for a in angles}
            main = max(angles, key=lambda a: float(np.mean(np.abs(slopes[a]))))
            y_hat = np.broadcast_to(dual.value, clean.shape)
            out.setdefault(ch.name, []).append((z[ok] - y_hat) / slopes[main])
    return {c: np.concatenate(v) for c, v in out.items()}


def calibrated_accuracy(problem: Problem, result: EstimationResult,
                        tables: Mapping[str, pd.DataFrame]) -> pd.DataFrame:
    """Per flow channel: mean, std and 3-sigma of (calibrated channel - true angle), display units."""
    display = {c.name: (c.display_scale, c.display_unit) for c in problem.channels}
    rows = []
    for ch, e in sorted(calibrated_channel_errors(problem, result, tables).items()):
        scale, unit = display[ch]
        rows.append({"name": ch, "kind": "calibrated", "unit": unit, "mean": float(np.mean(e)) * scale,
                     "std": float(np.std(e)) * scale, "three_sigma": 3.0 * float(np.std(e)) * scale,
                     "n": float(e.size)})
    return pd.DataFrame(rows)


# ---------------------------------------------------------------------------- the replication


def run_replication(scenario: Scenario, index: int, truths: Mapping[int, Sequence[TruthTrajectory]],
                    models: Models | None = None) -> ReplicationResult:
    """Run replication ``index``: draw, instrument, estimate, compare (module docstring).

    Parameters
    ----------
    scenario : the scenario.
    index : the replication, 0-based.
    truths : job index -> truth segments of the maneuvers flown once (the others are flown here).
    models : the local-flow truth and ADC baseline (loaded when not given).

    Exceptions propagate (:func:`run_replication_safely` records them).
    """
    # one BLAS thread, whatever the executor: a multi-threaded OpenBLAS sums in another order
    # (Dask workers run single-threaded, local processes do not), which moved the least-squares
    # truth projection by 1e-13 between executors; the estimator itself already runs on one
    with threadpool_limits(limits=1):
        return _run_replication(scenario, index, truths, models)


def _run_replication(scenario: Scenario, index: int, truths: Mapping[int, Sequence[TruthTrajectory]],
                     models: Models | None) -> ReplicationResult:
    t0 = time.perf_counter()
    models = models or Models.of(scenario)
    draw = scenario.draw(index)
    own = dict(truths)
    for md in draw.maneuvers:
        if md.reflown or md.job.index not in own:
            own[md.job.index] = fly(scenario, md)
    est = scenario.estimator
    with tempfile.TemporaryDirectory(prefix=f"fpr-mc-r{index:05d}-") as tmp:
        tables = write_scratch_dataset(scenario, draw.maneuvers, own, models, Path(tmp))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            problem = problem_from_dataset(
                tmp, select=est.select, model=est.model, channels=est.channels,
                overrides=est.parameters or None, lever_arm=est.lever_arm, g_mps2=est.g_mps2)
            result = estimate(problem, SolverOptions(max_iterations=est.max_iterations,
                                                     colored=est.colored))
            truth = true_parameters(problem) if result.success else None
        # the scratch directory's name differs per run: keep it out of the (compared) messages
        notes = tuple(dict.fromkeys(str(w.message).replace(tmp, "<replication data>") for w in caught))
        if not result.success:
            return ReplicationResult(
                index=index, ok=False, status=result.status,
                message=f"estimation {STATUS_TEXT.get(result.status, result.status)}: {result.message}",
                noise_seed=draw.noise_seed, scenario_hash=scenario.hash,
                elapsed_s=time.perf_counter() - t0, draws=pd.DataFrame(draws_table(draw)), warnings=notes)
        rec = recovery_table(result, truth)
        channels = pd.concat([residual_accuracy(result), calibrated_accuracy(problem, result, tables)],
                             ignore_index=True)
    params = pd.DataFrame({
        "name": rec.index.astype(str), "family": [k.split("[")[0] for k in rec.index],
        "kind": rec["kind"].astype(str), "unit": rec["display_unit"].astype(str),
        "estimate": rec["value_display"], "truth": rec["truth_display"], "error": rec["error_display"],
        "std_crb": rec["std_crb_display"], "std_colored": rec["std_colored_display"],
        "z_crb": rec["z_crb"], "z_colored": rec["z_colored"],
    }).reset_index(drop=True)
    channels["family"] = channels["name"]
    return ReplicationResult(
        index=index, ok=True, status=result.status, message=result.message, noise_seed=draw.noise_seed,
        scenario_hash=scenario.hash, elapsed_s=time.perf_counter() - t0, parameters=params,
        channels=channels, draws=pd.DataFrame(draws_table(draw)), warnings=notes)


def run_replication_safely(scenario: Scenario, index: int,
                           truths: Mapping[int, Sequence[TruthTrajectory]],
                           models: Models | None = None) -> ReplicationResult:
    """:func:`run_replication`, with any exception turned into a failed result (error and
    traceback in its message) so that one bad replication does not stop the others."""
    t0 = time.perf_counter()
    try:
        return run_replication(scenario, index, truths, models)
    except Exception as exc:  # recorded, not raised: the campaign goes on
        try:
            noise_seed = scenario.draw(index).noise_seed
        except Exception:  # the draw itself failed; the traceback below says why
            noise_seed = -1
        return ReplicationResult(
            index=index, ok=False, status=-1,
            message=f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}", noise_seed=noise_seed,
            scenario_hash=scenario.hash, elapsed_s=time.perf_counter() - t0)


def failure_record(result: ReplicationResult) -> str:
    """The JSON text of a failed replication's record."""
    return json.dumps(result.meta(), indent=1, sort_keys=True) + "\n"
