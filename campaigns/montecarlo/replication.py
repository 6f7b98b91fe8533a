"""One Monte Carlo replication: instrument, estimate, compare with the truth.

:func:`run_replication` takes the truths of the maneuvers flown once (or flies those whose air
changes), instruments every maneuver with the replication's drawn errors and noise seeds, writes
them as a scratch ``fpr fly`` dataset (the estimator reads flight data only through the documented
format, so a replication sees exactly what a user's calibration would), builds the estimation
problem, estimates, and returns a :class:`ReplicationResult`: every estimated parameter's estimate
beside its truth with its Cramér-Rao and coloured-residual deviations and z-scores
(:func:`campaigns.truth.recovery_table`), the estimator's verdict and how many warnings and
failures it found, and per channel the scatter of the residuals (measurement - model at Table 2's
samples, :func:`estimator.workflow.stage_residuals`) and the accuracy of the calibrated channel
against the true flow angle at its sensor (:func:`campaigns.workflow_truth.calibrated_errors`, the
workflow report's own computation). Every accuracy is :func:`estimator.workflow.three_sigma`, 3 x
the rms about zero (a mean offset is an error too), the definition of the rest of the project.

The "residual" rows are the residual's scatter, Table 2's ``scatter_three_sigma_deg``, not Table 2
itself, which adds the calibration's own uncertainty ``J_c C J_c^T`` that the estimator reports
(:mod:`estimator.accuracy`): here that uncertainty is measured instead, by the spread of the
estimates against their truth over the replications and by the "calibrated" rows; a row of sample
statistics (mean, std, 3 x rms) keeps ``three_sigma = 3 hypot(mean, std)``.
"""

from __future__ import annotations

import contextlib
import json
import re
import shutil
import tempfile
import time
import traceback
import warnings
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd
from threadpoolctl import threadpool_limits

from campaigns.truth import TruthProjection, recovery_table, true_parameters
from campaigns.workflow_truth import calibrated_errors
from estimator.parameters import family_of
from estimator.problem import Problem
from estimator.result import STATUS_TEXT, EstimationResult
from estimator.solver import estimate
from estimator.verdict import Verdict
from estimator.workflow import RAD2DEG, apportion, stage_residuals, three_sigma, vane_biases
from synth.campaign import software_versions
from synth.dataset import (
    FORMAT,
    FORMAT_VERSION,
    RecordedPiece,
    airframe_manifest,
    maneuver_key,
    write_maneuver,
    write_manifest,
)
from synth.flight import fly_maneuver
from synth.instrument import instrument
from synth.local_flow import load_adc_baseline, load_local_flow_truth
from synth.maneuvers import ManeuverSpec
from synth.truth import TruthTrajectory

from .scenario import ManeuverDraw, Scenario, draws_table

#: columns of the per-replication table (one row per parameter, channel accuracy or drawn value)
COLUMNS = ("replication", "record", "name", "family", "kind", "unit", "estimate", "truth", "error",
           "std_crb", "std_colored", "z_crb", "z_colored", "mean", "std", "three_sigma", "n")
#: the estimator's verdict codes (:class:`estimator.verdict.Verdict`) -> their names, for tables
VERDICT_NAMES = {v.code: v.name.lower().replace("_", " ") for v in Verdict}
#: a replication's scratch dataset directory, in the run folder's ``.scratch/`` or (a Dask worker)
#: the system's temporary folder (its name differs per run; kept out of the messages)
_SCRATCH = re.compile(r"[^\s'\"]*(?:fpr-mc-|\.scratch/)r\d{5}-[a-z0-9_]{8}")
#: the name of a scratch directory in a ``.scratch/`` folder (:func:`scratch_in`)
SCRATCH_NAME = re.compile(r"r\d{5}-[a-z0-9_]{8}")
#: the scratch directories of the replications running in this process (a worker stopped by the
#: run removes them on its way out: :func:`remove_scratch_directories`)
_OPEN_SCRATCH: set[str] = set()
#: where this process puts its replications' scratch directories (None: the system's temporary
#: folder); :func:`scratch_in`
_SCRATCH_ROOT: list[str | None] = [None]


@dataclass(frozen=True)
class ReplicationResult:
    """What one replication found (display units: deg, deg/s, ms, as the estimator reports).

    Attributes
    ----------
    index : the replication.
    ok : the estimator's verdict is a success (with or without warnings) and the tables are
        filled; a failure verdict is a failed replication, left out of the statistics.
    status : the solver's status (:class:`estimator.verdict.Status`: positive = converged, 0
        iteration limit, negative = stalled or failed) or -1 when the replication raised before or
        during estimation.
    message : the estimator's message, or the error and its traceback.
    noise_seed : the master seed of the replication's noise sources.
    scenario_hash : the scenario it belongs to.
    elapsed_s : wall time of the replication, s. Not in the replication's file (nor in
        :meth:`meta`), which stays bit-identical between runs: the runner keeps it in the run's
        ``timings.csv`` and :func:`~campaigns.montecarlo.summary.load_results` puts it back.
    parameters : one row per free parameter with a truth (see :data:`COLUMNS`).
    channels : per channel and kind ("residual", "calibrated"): mean, std, three_sigma, n.
    draws : the drawn values (path, instance, component, value SI).
    warnings : what the data import warned about (and what could not be computed).
    verdict_code : the estimator's verdict (:data:`VERDICT_NAMES`: 1 success, 2 success with
        warnings, -1 failure), or None when no estimation finished (the replication raised).
    n_warnings, n_failures : the estimator's findings of severity warning and failure.
    findings : (severity, code, message) of each warning and failure finding, most severe first.
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
    verdict_code: int | None = None
    n_warnings: int = 0
    n_failures: int = 0
    findings: tuple[tuple[str, str, str], ...] = ()

    @property
    def verdict(self) -> str:
        """The verdict's name ("success", "success with warnings", "failure"; "none" without one)."""
        return "none" if self.verdict_code is None else VERDICT_NAMES.get(self.verdict_code,
                                                                          str(self.verdict_code))

    def meta(self) -> dict:
        """The scalars, JSON-ready (stored in the Parquet file's metadata / the failure record);
        only what the replication's inputs decide (no wall time)."""
        return {"replication": self.index, "ok": self.ok, "status": self.status,
                "status_text": STATUS_TEXT.get(self.status, str(self.status)), "message": self.message,
                "noise_seed": self.noise_seed, "scenario_hash": self.scenario_hash,
                "warnings": list(self.warnings),
                "verdict_code": self.verdict_code, "verdict": self.verdict,
                "n_warnings": self.n_warnings, "n_failures": self.n_failures,
                "findings": [list(f) for f in self.findings]}

    @classmethod
    def from_meta(cls, meta: Mapping, **tables: pd.DataFrame) -> ReplicationResult:
        """A result from its :meth:`meta` (a failure record) and, for a finished one, its tables
        (``parameters``, ``channels``, ``draws``); keys a file of an older version lacks take
        their defaults (and its ``elapsed_s``, when it has one, is read)."""
        code = meta.get("verdict_code")
        return cls(index=int(meta["replication"]), ok=bool(meta["ok"]), status=int(meta["status"]),
                   message=str(meta["message"]), noise_seed=int(meta["noise_seed"]),
                   scenario_hash=str(meta["scenario_hash"]), elapsed_s=float(meta.get("elapsed_s", 0.0)),
                   warnings=tuple(meta.get("warnings", ())),
                   verdict_code=None if code is None else int(code),
                   n_warnings=int(meta.get("n_warnings", 0)), n_failures=int(meta.get("n_failures", 0)),
                   findings=tuple(tuple(str(x) for x in f) for f in meta.get("findings", ())),
                   **tables)

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
        return cls.from_meta(meta, parameters=p, channels=c, draws=draws.reset_index(drop=True))


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


def write_scratch_dataset(scenario: Scenario, draws: Sequence[ManeuverDraw],
                          truths: Mapping[int, Sequence[TruthTrajectory]], models: Models,
                          directory: Path) -> dict[str, pd.DataFrame]:
    """Instrument every maneuver with its drawn errors and write an ``fpr fly`` dataset.

    Returns maneuver id -> its table (measured and ``true_*`` columns), for callers that want the
    truth in memory (the replication's accuracy reads it back from the files, as the workflow
    report does).
    """
    fleet = scenario.campaign.fleet
    (directory / "maneuvers").mkdir(parents=True, exist_ok=True)
    entries, tables = [], {}
    for md in draws:
        cfg = fleet.configuration(md.job.configuration_id)
        segments = truths[md.job.index]
        spec = ManeuverSpec.from_dict(md.job.maneuver)
        for seg_no, truth in enumerate(segments):
            # the seed key and the entry of synth.campaign's own datasets
            inst = instrument(truth, fleet.airframe, cfg, md.errors,
                              maneuver_key=maneuver_key(md.job.index, seg_no),
                              common_rate_hz=scenario.campaign.common_rate_hz,
                              truth_model=models.truth_model, adc_baseline=models.adc_baseline)
            entry = RecordedPiece(job_index=md.job.index, segment=seg_no, n_segments=len(segments),
                                  configuration=cfg, spec=spec, environment=md.environment,
                                  truth=truth, instrumented=inst,
                                  sample_rate_hz=scenario.campaign.common_rate_hz).manifest_entry()
            write_maneuver(directory / entry["file"], inst.data, entry)
            entries.append(entry)
            tables[entry["id"]] = inst.data
    write_manifest(directory, {
        "format": FORMAT, "format_version": FORMAT_VERSION,
        "campaign": {"name": scenario.name, "source": scenario.source, "seed": scenario.seed},
        "software": software_versions(),
        "airframe": airframe_manifest(fleet.airframe),
        "common_rate_hz": scenario.campaign.common_rate_hz,
        "maneuvers": entries, "failures": [],
    })
    return tables


# ---------------------------------------------------------------------------- accuracy tables

#: columns of the accuracy tables (one row per channel)
_ACCURACY_COLUMNS = ["name", "kind", "unit", "mean", "std", "three_sigma", "n"]


def _accuracy_row(name: str, kind: str, unit: str, e_display: np.ndarray) -> dict:
    """Mean, (population) std, 3-sigma (:func:`estimator.workflow.three_sigma`, 3 x rms about zero)
    and sample count of errors already in display units."""
    return {"name": name, "kind": kind, "unit": unit, "mean": float(np.mean(e_display)),
            "std": float(np.std(e_display)), "three_sigma": three_sigma(e_display),
            "n": float(e_display.size)}


def residual_accuracy(problem: Problem, result: EstimationResult) -> pd.DataFrame:
    """Per channel, the residual (measurement - model) pooled over the maneuvers at the estimate.

    The residuals are the workflow's (:func:`estimator.workflow.stage_residuals`, the samples of
    the paper's Table 2), their scatter only: Table 2's ``scatter_three_sigma_deg``, without the
    calibration's own uncertainty that Table 2 adds (module docstring: the Monte Carlo measures
    that part against the truth), so the calibration deviations are not computed.

    Parameters
    ----------
    problem : the estimated problem.
    result : its estimate.

    Returns
    -------
    One row per channel: name, kind ("residual"), unit (display), mean, std, three_sigma (3 x rms
    about zero), all in display units (deg for angles, m/s, m), and n (samples).
    """
    rows = []
    for ch, r in sorted(stage_residuals((problem, result), calibration=False).items()):
        e = r.e[np.isfinite(r.e)]
        if not e.size:
            continue
        scale, unit = result.channel_display.get(ch, (1.0, ""))
        rows.append(_accuracy_row(ch, "residual", unit, e * scale))
    return pd.DataFrame(rows, columns=_ACCURACY_COLUMNS)


def calibrated_accuracy(problem: Problem, result: EstimationResult,
                        truth_cache: dict | None = None) -> tuple[pd.DataFrame, tuple[str, ...]]:
    """Per flow channel, the calibrated channel minus the true flow angle at its sensor.

    The errors are the workflow report's (:func:`campaigns.workflow_truth.calibrated_errors`): the
    measurement run back through the estimated calibration model exactly
    (:func:`estimator.calibrated.calibrated_channel`), the model's other inputs at their true
    values, compared with the truth at the time the sensor saw it (its injected total lag) — the
    calibration's error in the value, not in the timing. The problem must come from a synthetic
    dataset that is still on disk (the truth is read from its files).

    Parameters
    ----------
    problem : the estimated problem (from a synthetic dataset).
    result : its estimate.
    truth_cache : the maneuvers' truth, read once with the projection
        (:func:`campaigns.truth.truths_of`).

    Returns
    -------
    (table, notes): one row per flow channel — name, kind ("calibrated"), unit, mean, std,
    three_sigma (3 x rms about zero), display units (deg), n (samples) — and what could not be
    computed: a model that does not depend on its flow angle somewhere (a table segment estimated
    flat) cannot be inverted; the table is then empty and the note says why.
    """
    display = {c.name: (c.display_scale, c.display_unit) for c in problem.channels}
    try:
        errors = calibrated_errors(problem, result, truth_cache)
    except ValueError as exc:
        return pd.DataFrame(columns=_ACCURACY_COLUMNS), (f"calibrated channels not computed: {exc}",)
    rows = []
    for ch, df in sorted(errors.items()):
        e = df["error_rad"].to_numpy(dtype=float)
        e = e[np.isfinite(e)]
        if not e.size:
            continue
        scale, unit = display[ch]
        rows.append(_accuracy_row(ch, "calibrated", unit, e * scale))
    return pd.DataFrame(rows, columns=_ACCURACY_COLUMNS), ()


# ---------------------------------------------------------------------------- the estimator's verdict


def verdict_of(result: EstimationResult) -> tuple[int, int, int, tuple[tuple[str, str, str], ...]]:
    """The estimator's verdict code, its warning and failure counts, and those findings.

    Parameters
    ----------
    result : an estimate.

    Returns
    -------
    (code, n_warnings, n_failures, findings): ``result.verdict.code`` (1 success, 2 success with
    warnings, -1 failure), the numbers of findings of severity warning and failure, and
    (severity, code, message) of each of those, most severe first.
    """
    shown = []
    for f in result.findings:
        severity = f.severity.name.lower()
        if severity in ("warning", "failure"):
            shown.append((severity, str(f.code), str(f.message)))
    shown.sort(key=lambda f: f[0] != "failure")  # stable: failures first, the estimator's order kept
    n_fail = sum(f[0] == "failure" for f in shown)
    return int(result.verdict.code), len(shown) - n_fail, n_fail, tuple(shown)


def _truth_of(problem: Problem, result: EstimationResult,
              truth_cache: dict | None = None) -> TruthProjection:
    """The truth of the problem's parameters, anchored where the estimator held a parameter
    (``truth_cache``: :func:`campaigns.truth.truths_of`'s)."""
    return true_parameters(problem, result.free_estimated, truth_cache)


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
        return _scrubbed(_run_replication(scenario, index, truths, models))


def _scrubbed(result: ReplicationResult) -> ReplicationResult:
    """``result`` with the scratch directory's path in its texts replaced by ``<replication
    data>``: the path differs per run, and the replication's file must not."""
    def scrub(text: str) -> str:
        return _SCRATCH.sub("<replication data>", text)

    return replace(result, message=scrub(result.message),
                   warnings=tuple(dict.fromkeys(scrub(w) for w in result.warnings)),
                   findings=tuple((sev, code, scrub(msg)) for sev, code, msg in result.findings))


def set_scratch_root(folder: str | Path | None) -> str | None:
    """Put this process's replication scratch datasets in ``folder`` (an existing folder; None:
    the system's temporary folder); returns the previous setting. The runner sets the run folder's
    ``.scratch/`` for its own process and in each pool worker, so that a killed run's scratch data
    stay inside the run folder, where the next run removes them."""
    previous, _SCRATCH_ROOT[0] = _SCRATCH_ROOT[0], None if folder is None else str(folder)
    return previous


@contextlib.contextmanager
def scratch_in(folder: str | Path | None) -> Iterator[None]:
    """:func:`set_scratch_root` for the duration of a block."""
    previous = set_scratch_root(folder)
    try:
        yield
    finally:
        set_scratch_root(previous)


@contextlib.contextmanager
def _scratch_directory(index: int) -> Iterator[str]:
    """A temporary directory for replication ``index``'s scratch dataset (``rNNNNN-XXXXXXXX`` in
    the folder :func:`set_scratch_root` set, else ``fpr-mc-rNNNNN-XXXXXXXX`` in the system's
    temporary folder), known to :func:`remove_scratch_directories` while it exists."""
    root = _SCRATCH_ROOT[0]
    prefix = f"r{index:05d}-" if root is not None else f"fpr-mc-r{index:05d}-"
    with tempfile.TemporaryDirectory(prefix=prefix, dir=root) as tmp:
        _OPEN_SCRATCH.add(tmp)
        try:
            yield tmp
        finally:
            _OPEN_SCRATCH.discard(tmp)


def remove_scratch_directories() -> None:
    """Remove the scratch directories of the replications running in this process — for a worker
    process that is being stopped (its replications are abandoned; nothing of them is kept)."""
    for tmp in list(_OPEN_SCRATCH):
        shutil.rmtree(tmp, ignore_errors=True)
        _OPEN_SCRATCH.discard(tmp)


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
    with _scratch_directory(index) as tmp:
        write_scratch_dataset(scenario, draw.maneuvers, own, models, Path(tmp))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            problem = est.problem(tmp)
            # every [estimator.solver] option (the shipped scenarios: max_iterations 40, colored)
            result = estimate(problem, est.solver)
            # each maneuver's truth read once, for the projection and the calibrated channels
            truth_frames: dict = {}
            truth = _truth_of(problem, result, truth_frames) if result.success else None
        notes = tuple(dict.fromkeys(str(w.message) for w in caught))  # scrubbed by run_replication
        status = int(result.status)
        code, n_warn, n_fail, findings = verdict_of(result)
        judged = {"verdict_code": code, "n_warnings": n_warn, "n_failures": n_fail, "findings": findings}
        if not result.success:
            why = "".join(f"; {sev}: {msg}" for sev, _, msg in findings
                          if sev == "failure" and msg not in result.message)
            return ReplicationResult(
                index=index, ok=False, status=status,
                message=f"estimation verdict {VERDICT_NAMES.get(code, code)} (solver: "
                        f"{STATUS_TEXT.get(status, status)}): {result.message}{why}",
                noise_seed=draw.noise_seed, scenario_hash=scenario.hash,
                elapsed_s=time.perf_counter() - t0, draws=pd.DataFrame(draws_table(draw)), warnings=notes,
                **judged)
        rec = recovery_table(result, truth)
        calibrated, not_computed = calibrated_accuracy(problem, result, truth_frames)
        channels = pd.concat([residual_accuracy(problem, result), calibrated], ignore_index=True)
    params = pd.DataFrame({
        "name": rec.index.astype(str), "family": [family_of(k) for k in rec.index],
        "kind": rec["kind"].astype(str), "unit": rec["display_unit"].astype(str),
        "estimate": rec["value_display"], "truth": rec["truth_display"], "error": rec["error_display"],
        "std_crb": rec["std_crb_display"], "std_colored": rec["std_colored_display"],
        "z_crb": rec["z_crb"], "z_colored": rec["z_colored"],
    }).reset_index(drop=True)
    params = pd.concat([params, installation_rows(problem, result, truth)], ignore_index=True)
    channels["family"] = channels["name"]
    return ReplicationResult(
        index=index, ok=True, status=status, message=result.message, noise_seed=draw.noise_seed,
        scenario_hash=scenario.hash, elapsed_s=time.perf_counter() - t0, parameters=params,
        channels=channels, draws=pd.DataFrame(draws_table(draw)), warnings=notes + not_computed, **judged)


def installation_rows(problem: Problem, result: EstimationResult, truth: TruthProjection) -> pd.DataFrame:
    """The vane installation biases (paper §4.1: each aircraft's vane bias minus the fleet mean of
    ``(b_l + b_r) / 2``, :func:`estimator.workflow.apportion`) against the same apportionment of
    the true biases, as parameter rows (kind ``installation_bias``, deg): the quantity the fleet
    calibration fixes, free of the correction-model part every aircraft shares (and of the share
    of a model-structure error they share). Empty with fewer than two aircraft."""
    ac, vals, cov, cov_col = vane_biases(problem, result)
    keys = [f"b_l[{a}]" for a in ac] + [f"b_r[{a}]" for a in ac]
    if len(ac) < 2 or not all(k in truth.values for k in keys):
        return pd.DataFrame(columns=["name", "family", "kind", "unit", "estimate", "truth", "error",
                                     "std_crb", "std_colored", "z_crb", "z_colored"])
    n = len(ac)
    est = apportion(dict(zip(ac, vals[:n], strict=True)), dict(zip(ac, vals[n:], strict=True)), cov)
    col = apportion(dict(zip(ac, vals[:n], strict=True)), dict(zip(ac, vals[n:], strict=True)), cov_col)
    tru = apportion({a: truth.values[f"b_l[{a}]"] for a in ac}, {a: truth.values[f"b_r[{a}]"] for a in ac})
    rows = []
    for a in ac:
        for side in ("left", "right"):
            k = f"installation_{side}"
            e, t = est.loc[a, k] * RAD2DEG, tru.loc[a, k] * RAD2DEG
            s_crb, s_col = est.loc[a, f"std_{k}"] * RAD2DEG, col.loc[a, f"std_{k}"] * RAD2DEG
            rows.append({"name": f"{k}[{a}]", "family": k, "kind": "installation_bias", "unit": "deg",
                         "estimate": e, "truth": t, "error": e - t, "std_crb": s_crb, "std_colored": s_col,
                         "z_crb": (e - t) / s_crb, "z_colored": (e - t) / s_col})
    return pd.DataFrame(rows)


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
        return _scrubbed(ReplicationResult(
            index=index, ok=False, status=-1,
            message=f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}", noise_seed=noise_seed,
            scenario_hash=scenario.hash, elapsed_s=time.perf_counter() - t0))


def failure_record(result: ReplicationResult) -> str:
    """The JSON text of a failed replication's record."""
    return json.dumps(result.meta(), indent=1, sort_keys=True) + "\n"
