"""Planning study (c): how large may IMU biases, time delays, winds and turbulence be before the
desired accuracy is lost?

One factor at a time around a base scenario (typical errors of SPEC §6, calm air), every point a
Monte Carlo run of :mod:`campaigns.montecarlo` (N replications: new noise, IMU biases drawn per
maneuver, estimation, comparison with the truth). Per point: the 3-sigma accuracy of every
calibrated flow-angle channel against the true flow angle, pass/fail against the desired accuracy
(paper Table 2: vane AOA ±0.5 deg, side-probe AOA and AOSS ±1 deg, nose-probe AOSS ±0.5 deg), the
estimate-minus-truth error of the swept parameter (and whether its estimate sits on a bound of the
model set), the Monte Carlo scatter against the Cramér-Rao bounds and the failed estimations.

Factors (levels in :data:`FULL`):

* ``imu_bias``: the IMU biases, a multiple of the typical preset (accelerometer and gyro bias and
  the per-maneuver spread drawn around them). The biases are estimated per maneuver.
* ``flow_delay``: the delay of every flow-angle sensor (vanes, probes, boom), ms. Estimated.
* ``ins_delay``: the INS recorder's latency (Euler angles), ms. Estimated.
* ``wind``: a steady wind, m/s. Not a state of the model, and it need not be: in a steady uniform
  wind the air-relative velocity obeys the same kinematic equations as the inertial one
  (dV_a/dt = a - omega x V_a in body axes), so the free initial velocity absorbs it, turns included;
  winds that change along the path (shear, gusts, turbulence) are not absorbed.
* ``turbulence``: JSBSim's MIL-F-8785C turbulence, a new realisation per replication. Not
  modelled (the output-error method has no process noise).

Accuracy of a calibrated channel in one replication: ``|mean| + 3 std`` of (calibrated channel -
true flow angle) over every sample of every maneuver, so that a systematic offset counts too; a
requirement group (two vanes, two boom sideslip vanes) takes its worse channel. A point passes a
requirement when the median over the replications meets it.

Run (resumable: the same command again skips finished replications)::

    python -m campaigns.studies.tolerance --out runs/tolerance --results campaigns/studies/results
    python -m campaigns.studies.tolerance --out /tmp/tol --size tiny --replications 1   # a smoke run

It writes ``tolerance.txt`` (the table, headed by the command, machine and wall time, ending with
one conclusion per factor drawn from the numbers), ``tolerance.png`` (one panel per factor) and
``tolerance.csv`` into ``--results`` (default: ``--out``); each point's Monte Carlo run stays in
``OUT/points/``.
"""

from __future__ import annotations

import argparse
import copy
import math
import os
import shlex
import sys
import tempfile
import textwrap
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from campaigns.montecarlo import ScenarioError, parse_scenario, run_montecarlo
from campaigns.montecarlo.replication import Models, ReplicationResult, fly, write_scratch_dataset
from campaigns.montecarlo.summary import CALIBRATION_KINDS, load_results, summarize_results
from campaigns.studies.invocations import Invocation, invocations_text, machine_text
from campaigns.truth import true_parameters
from estimator.io import problem_from_dataset
from estimator.io.modelset import load_model_set
from synth.errors import PROBE_SENSORS, VANE_SENSORS, ErrorConfig
from synth.workers import worker_pool

#: desired 3-sigma accuracy per requirement group, deg (paper Table 2)
DESIRED_3SIGMA_DEG: Mapping[str, float] = {
    "vane AOA": 0.5, "side-probe AOA": 1.0, "side-probe AOSS": 1.0, "nose-probe AOSS": 0.5,
}
#: requirement group -> calibrated channels (the group's accuracy is its worst channel's); the
#: boom has no stated requirement and is shown for information
SENSOR_GROUPS: Mapping[str, tuple[str, ...]] = {
    "vane AOA": ("alpha_zl", "alpha_zr"),
    "side-probe AOA": ("alpha_zsp",),
    "side-probe AOSS": ("beta_zsp",),
    "nose-probe AOSS": ("beta_znp",),
    "boom AOA": ("alpha_zb",),
    "boom AOSS": ("beta_zbu", "beta_zbl"),
}
#: short column titles of the groups in the text table
_SHORT = {"vane AOA": "vane_a", "side-probe AOA": "sp_a", "side-probe AOSS": "sp_b",
          "nose-probe AOSS": "np_b", "boom AOA": "boom_a", "boom AOSS": "boom_b"}
#: a steady wind blows towards this heading (the air mass moves towards it), deg from north
WIND_TOWARDS_DEG = 120.0
#: the vane biases, reported at every point: the calibration's headline parameters
VANE_BIAS_FAMILIES = ("b_l", "b_r")

Level = float | str
#: one record per invocation of the study on an output directory (its cost, when resumed)
INVOCATIONS_FILE = "tolerance_invocations.json"


# ---------------------------------------------------------------------------- the factors


def _typical_imu() -> tuple[list[float], list[float]]:
    """The typical preset's accelerometer (m/s^2) and gyro (deg/s) biases."""
    imu = ErrorConfig.typical().imu
    return list(imu.accel_bias_mps2), [math.degrees(b) for b in imu.gyro_bias_rps]


#: the spread of the per-maneuver IMU biases around their value at scale 1 (as mc_20maneuvers)
IMU_SPREAD_ACCEL_MPS2 = 0.05
IMU_SPREAD_GYRO_DEG_S = 0.1


def _set_imu_bias(raw: dict, scale: Level) -> None:
    s = float(scale)
    accel_mps2, gyro_deg_s = _typical_imu()
    imu = raw["errors"].setdefault("imu", {})
    imu["accel_bias_mps2"] = [s * a for a in accel_mps2]
    imu["gyro_bias_deg_s"] = [s * g for g in gyro_deg_s]
    draws = raw["draw"].setdefault("errors", {})
    draws["imu.accel_bias_mps2"] = {"dist": "normal", "std": abs(s) * IMU_SPREAD_ACCEL_MPS2,
                                     "scope": "maneuver"}
    draws["imu.gyro_bias_deg_s"] = {"dist": "normal", "std": abs(s) * IMU_SPREAD_GYRO_DEG_S,
                                    "scope": "maneuver"}


def _set_imu_bias_started(raw: dict, scale: Level) -> None:
    """IMU biases as :func:`_set_imu_bias`, and the estimator's start values of the per-maneuver
    biases at their mean (the per-maneuver spread remains to be found); ``None``: no change."""
    if scale is None:
        return
    _set_imu_bias(raw, scale)
    s = float(scale)
    accel_mps2, gyro_deg_s = _typical_imu()
    params = raw["estimator"].setdefault("parameters", {})
    for name, v in zip(("dax", "day", "daz"), accel_mps2, strict=True):
        params[name] = {**params.get(name, {}), "value": s * v}
    for name, v in zip(("dp", "dq", "dr"), gyro_deg_s, strict=True):
        params[name] = {**params.get(name, {}), "value_deg": s * v}


def _set_flow_delay(raw: dict, delay_ms: Level) -> None:
    if delay_ms == "typical":
        return
    sensors = raw["errors"].setdefault("sensors", {})
    for name in (*VANE_SENSORS, *PROBE_SENSORS):
        sensors.setdefault(name, {})["delay_ms"] = float(delay_ms)


def _set_ins_delay(raw: dict, delay_ms: Level) -> None:
    recorders = raw["errors"].setdefault("recorders", {})
    recorders.setdefault("ins", {})["delay_ms"] = float(delay_ms)


def _set_wind(raw: dict, wind_mps: Level) -> None:
    w, a = float(wind_mps), math.radians(WIND_TOWARDS_DEG)
    raw["environment"]["wind_ned_mps"] = [w * math.cos(a), w * math.sin(a), 0.0]


def _set_turbulence(raw: dict, level: Level) -> None:
    raw["environment"]["turbulence"] = str(level)


@dataclass(frozen=True)
class Factor:
    """One swept factor.

    Attributes
    ----------
    name : short name (point directories, CSV).
    title : what is swept, with its unit (plot panel, table).
    levels : the swept levels (numbers, or names such as ``"light"``; ``"typical"`` = the preset's
        own per-sensor values, not plotted).
    base_level : the level of the base scenario (every other factor's runs use it).
    apply : sets a level in a scenario mapping, in place.
    swept : (label, parameter families, display unit) whose estimate-minus-truth error is reported.
    variant_of : the factor this one repeats with another estimator set-up (its conclusion is
        added to that factor's).
    """

    name: str
    title: str
    levels: tuple[Level, ...]
    base_level: Level
    apply: Callable[[dict, Level], None]
    swept: tuple[tuple[str, tuple[str, ...], str], ...] = ()
    variant_of: str | None = None

    def label(self, level: Level) -> str:
        """The level as written in tables and directory names."""
        return f"{level:g}" if isinstance(level, int | float) else str(level)

    @property
    def numeric(self) -> bool:
        """Levels are numbers (plotted on a numeric axis; ``"typical"`` left out)."""
        return all(isinstance(lv, int | float) for lv in self.levels if lv != "typical")


def make_factors(imu_scales: Sequence[float], imu_started_scales: Sequence[float],
                 flow_delays_ms: Sequence[Level], ins_delays_ms: Sequence[float],
                 winds_mps: Sequence[float], turbulence: Sequence[str]) -> tuple[Factor, ...]:
    """The six factors with the given levels (the base levels: 1, -, typical, 0, 0, none)."""
    imu = (("accel", ("dax", "day", "daz"), "m/s^2"), ("gyro", ("dp", "dq", "dr"), "deg/s"))
    return (
        Factor("imu_bias", "IMU biases (x typical)", tuple(imu_scales), 1.0, _set_imu_bias, imu),
        Factor("imu_started", "IMU biases (x typical), started at their mean", tuple(imu_started_scales),
               None, _set_imu_bias_started, imu, variant_of="imu_bias"),
        Factor("flow_delay", "flow-sensor delay (ms)", tuple(flow_delays_ms), "typical", _set_flow_delay,
               (("tau", ("tau_alpha_zl", "tau_alpha_zr", "tau_sp", "tau_np", "tau_ba", "tau_bu",
                         "tau_bl"), "ms"),)),
        Factor("ins_delay", "INS latency (ms)", tuple(ins_delays_ms), 0.0, _set_ins_delay,
               (("tau", ("tau_phi", "tau_theta", "tau_psi"), "ms"),)),
        Factor("wind", "steady wind (m/s)", tuple(winds_mps), 0.0, _set_wind),
        Factor("turbulence", "turbulence (MIL-F-8785C)", tuple(turbulence), "none", _set_turbulence),
    )


# ---------------------------------------------------------------------------- the scenarios

#: the base scenario (a Monte Carlo scenario mapping, see campaigns/montecarlo/scenario.py): two
#: configurations (PV1 with the nose probe, PT1 with the boom) x Mach 0.6 x five maneuver kinds,
#: typical errors, the model-representable local-flow truth and ADC baseline (as mc_20maneuvers:
#: any loss of accuracy is then caused by the swept factor, not by a model that cannot fit)
FULL_BASE: Mapping[str, Any] = {
    "name": "tolerance",
    "description": "planning study (c): tolerance to IMU biases, delays, wind and turbulence",
    "seed": 2031,
    "replications": 10,
    "fleet": "fleet_default",
    "local_flow_truth": "local_flow_linear",
    "adc_baseline": "adc_baseline_linear",
    "common_rate_hz": 40.0,
    "environment": {"planet": "flat", "wind_ned_mps": [0.0, 0.0, 0.0], "turbulence": "none"},
    "errors": {"preset": "typical", "nose_probe_irregularity": False},
    "flights": [
        {"configurations": ["PV1-NP", "PT1-BOOM"], "mach": [0.6], "altitude_m": 6000.0,
         "maneuvers": ["pitch_doublet", "3211", "roller_coaster", "pullup_rudder_doublets"]},
        {"configurations": ["PV1-NP", "PT1-BOOM"], "mach": [0.6], "altitude_m": 6000.0,
         "maneuvers": ["windup_turn"], "maneuver": {"alpha_max_rad": 0.2094, "nz_max": 4.5}},
    ],
    "draw": {"turbulence": "redraw", "errors": {}},
    "estimator": {"model": "tejas", "max_iterations": 40, "colored": True,
                  "parameters": {"h0": {"free": True}}},
}

#: a smoke-test scenario: one configuration, two 20 s maneuvers, the vane channels only, the vane
#: tables held (about a second per replication)
TINY_BASE: Mapping[str, Any] = {
    **FULL_BASE,
    "name": "tolerance_tiny",
    "flights": [{"configurations": ["PV1-NP"], "mach": [0.6], "maneuvers": ["pitch_doublet", "3211"],
                 "maneuver": {"duration_s": 20.0}}],
    # no sideslip channel: v0 and the lateral accelerometer bias would enter the outputs only to
    # second order (through TAS), a degenerate problem; they are held (at the data's start, 0)
    "estimator": {"channels": ["phi", "theta", "psi", "tas", "h", "h_dgps", "alpha_zl", "alpha_zr"],
                  "max_iterations": 100, "parameters": {"f1": {"free": False}, "f2": {"free": False},
                                                        "v0": {"free": False}, "day": {"free": False}}},
}


@dataclass(frozen=True)
class StudyConfig:
    """A study: base scenario, factors and their levels, N."""

    base: Mapping[str, Any]
    factors: tuple[Factor, ...]
    replications: int


FULL = StudyConfig(FULL_BASE, make_factors(
    imu_scales=(0.0, 1.0, 1.5, 2.0, 3.0, 10.0), imu_started_scales=(3.0, 10.0),
    flow_delays_ms=("typical", 200.0, 300.0, 400.0), ins_delays_ms=(0.0, 100.0, 200.0, 300.0),
    winds_mps=(0.0, 10.0, 20.0), turbulence=("none", "light", "moderate")), replications=8)
TINY = StudyConfig(TINY_BASE, make_factors(
    imu_scales=(1.0, 3.0), imu_started_scales=(3.0,), flow_delays_ms=("typical", 100.0),
    ins_delays_ms=(0.0, 100.0), winds_mps=(0.0, 10.0), turbulence=("none", "light")), replications=1)
SIZES = {"full": FULL, "tiny": TINY}


@dataclass(frozen=True)
class Point:
    """One (factor, level) of the study and the Monte Carlo run that answers it."""

    factor: Factor
    level: Level
    raw: dict
    directory: Path


def base_scenario(config: StudyConfig) -> dict:
    """The base scenario mapping: every factor at its base level."""
    raw = copy.deepcopy(dict(config.base))
    for f in config.factors:
        f.apply(raw, f.base_level)
    return raw


def study_points(config: StudyConfig, out_dir: Path) -> list[Point]:
    """Every (factor, level) with its scenario; points with the same scenario (each factor's base
    level is the base scenario) share one run directory."""
    base = base_scenario(config)
    seen: dict[str, Path] = {}
    points = []
    for f in config.factors:
        for level in f.levels:
            raw = copy.deepcopy(base)
            f.apply(raw, level)
            raw["name"] = f"{config.base['name']}_{f.name}_{f.label(level)}"
            key = parse_scenario({**raw, "name": ""}, source="tolerance").hash
            directory = seen.setdefault(key, Path(out_dir) / "points" / f"{f.name}_{f.label(level)}")
            if directory.name != f"{f.name}_{f.label(level)}":
                raw["name"] = f"{config.base['name']}_{directory.name}"  # the shared run's name
            points.append(Point(f, level, raw, directory))
    return points


# ---------------------------------------------------------------------------- running


def _run_point(raw: dict, directory: str, replications: int) -> tuple[str, float, str, int]:
    """Run (or resume) one point's Monte Carlo in this process: (directory, wall s, error text,
    replications computed now)."""
    t0 = time.perf_counter()
    try:
        scenario = parse_scenario(raw, source=f"campaigns.studies.tolerance:{raw['name']}")
        report = run_montecarlo(scenario, directory, replications=replications, workers=1)
    except ScenarioError as exc:  # a maneuver that cannot be flown in this air: the point says so
        return directory, time.perf_counter() - t0, str(exc), 0
    return directory, time.perf_counter() - t0, "", len(report.ran)


def run_points(points: Sequence[Point], replications: int, workers: int,
               log: Callable[[str], None] = print) -> tuple[dict[Path, str], int]:
    """Run every distinct point's Monte Carlo (each in one process, ``workers`` at a time; the
    runs are resumable). Returns directory -> error text of the points that could not run, and
    the number of replications computed now."""
    unique: dict[Path, dict] = {}
    for p in points:
        unique.setdefault(p.directory, p.raw)
    # the reflown ones (turbulence) first: they are the longest
    order = sorted(unique, key=lambda d: unique[d]["environment"].get("turbulence", "none") == "none")
    errors: dict[Path, str] = {}
    ran = [0]

    def done(directory: str, wall_s: float, error: str, n_ran: int) -> None:
        note = f"  ERROR {error.splitlines()[0]}" if error else ""
        log(f"  {Path(directory).name}: {n_ran} replications in {wall_s:.1f} s{note}")
        ran[0] += n_ran
        if error:
            errors[Path(directory)] = error

    if workers <= 1:
        for d in order:
            done(*_run_point(unique[d], str(d), replications))
        return errors, ran[0]
    with worker_pool(workers) as pool:  # workers end with this process; Ctrl-C stops them
        futures = [pool.submit(_run_point, unique[d], str(d), replications) for d in order]
        for fut in as_completed(futures):
            done(*fut.result())
    return errors, ran[0]


# ---------------------------------------------------------------------------- metrics


def _bounds_display() -> dict[str, tuple[float, float]]:
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


def point_metrics(results: Sequence[ReplicationResult], factor: Factor,
                  bounds: Mapping[str, tuple[float, float]]) -> dict[str, Any]:
    """The metrics of one point from its replications (see the module docstring).

    Returns
    -------
    dict with ``n_ok``, ``n_failed``, ``failures`` (status text counts), ``n_pass`` (converged
    replications meeting every desired accuracy), per group ``acc_<group>``
    (median over replications, deg), ``acc_max_<group>``, ``swept`` (label -> (rms error, max
    |error|, unit, bound hits, undetermined estimates)), ``vane_bias_err_deg`` (rms),
    ``ratio_crb`` (median over the calibration parameters of scatter / mean CRB std),
    ``within_3sigma`` (fraction of calibration estimates within 3 CRB sigmas of the truth),
    ``resid_vane_deg`` (median vane residual 3-sigma).
    """
    ok = [r for r in results if r.ok]
    failed = [r for r in results if not r.ok]
    m: dict[str, Any] = {"n_ok": len(ok), "n_failed": len(failed)}
    why: dict[str, int] = {}
    for r in failed:
        # what failed it: the estimator's first failure finding (turbulence, not converged, ...), or
        # the start of the message of a replication that raised
        codes = [code for sev, code, _ in r.findings if sev == "failure"]
        raised = r.message.split(":")[0] if r.message else str(r.status)
        text = codes[0].replace("_", " ") if codes else raised
        why[text] = why.get(text, 0) + 1
    m["failures"] = ", ".join(f"{n} {w}" for w, n in why.items())
    acc = pd.DataFrame([group_accuracy(r) for r in ok], columns=list(SENSOR_GROUPS))
    # replications whose every requirement group meets its desired accuracy (NaN: no such sensor)
    m["n_pass"] = int(sum(all(not acc.at[i, g] > req for g, req in DESIRED_3SIGMA_DEG.items())
                          for i in acc.index))
    for g in SENSOR_GROUPS:
        col = acc[g].dropna() if len(acc) else pd.Series(dtype=float)
        m[f"acc_{g}"] = float(col.median()) if len(col) else math.nan
        m[f"acc_max_{g}"] = float(col.max()) if len(col) else math.nan
    params = pd.concat([r.parameters for r in ok], ignore_index=True) if ok else pd.DataFrame(
        columns=["name", "family", "kind", "estimate", "error", "std_crb", "z_crb"])
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
    m["swept"] = swept
    m["vane_bias_err_deg"] = _rms(params.loc[params["family"].isin(VANE_BIAS_FAMILIES), "error"])
    summary = summarize_results(list(results))
    cal = summary.parameters[summary.parameters["kind"].isin(CALIBRATION_KINDS)]
    m["ratio_crb"] = float(np.nanmedian(cal["ratio_crb"])) if len(cal) and len(ok) > 1 else math.nan
    z = params.loc[params["kind"].isin(CALIBRATION_KINDS), "z_crb"].to_numpy(dtype=float)
    z = z[np.isfinite(z)]
    m["within_3sigma"] = float(np.mean(np.abs(z) < 3.0)) if z.size else math.nan
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
        problem = problem_from_dataset(tmp, select=est.select, model=est.model, channels=est.channels,
                                       overrides=est.parameters or None, lever_arm=est.lever_arm,
                                       g_mps2=est.g_mps2)
        values = true_parameters(problem).values
    specs = problem.parameters.specs
    out = {}
    for label, families, _ in point.factor.swept:
        keys = [k for k in values if k.split("[")[0] in families]
        out[label] = (np.array([values[k] * specs[k.split("[")[0]].display_scale for k in keys]),
                      [k.split("[")[0] for k in keys])
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
    bounds = _bounds_display()
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
        row["fails"] = ", ".join(_SHORT[g] for g in failing_groups(row)) or "pass"
        rows.append(row)
    return pd.DataFrame(rows)


# ---------------------------------------------------------------------------- conclusions


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
    factor, rows : the factor and its rows of :func:`collect`.
    base : the base scenario's row (residual and scatter/CRB reference; default: the first row).
    variant : the variant factor and its rows.
    bounds : parameter family -> bounds, display units (default: the tejas model set's).
    """
    bounds = _bounds_display() if bounds is None else bounds
    rows = rows[rows["level"] != "typical"] if (rows["level"] != "typical").any() else rows
    base = rows.iloc[0] if base is None else base
    passed, r, bad = _first_failure(rows)
    name = factor.title
    if r is None:
        text = (f"{name}: every desired accuracy holds over the whole range swept, up to "
                f"{rows['level'].iloc[-1]}{_swept_size(factor, passed[-1])}{_tightest(passed[-1])}"
                f"{_largest_change(rows, base)}")
    else:
        if len(passed) > 1:
            text = (f"{name}: every desired accuracy holds up to {passed[-1]['level']}"
                    f"{_swept_size(factor, passed[-1])}{_tightest(passed[-1])}; at ")
        elif passed:
            text = (f"{name}: every desired accuracy holds at {passed[0]['level']}{_tightest(passed[0])}; "
                    "already at ")
        else:
            text = f"{name}: already at "
        n = int(r.get("n_ok", 0) + r.get("n_failed", 0))
        lost = [g for g in bad if g not in ("verdict", "convergence")]
        if bad == ["convergence"]:
            text += f"{r['level']} every estimation ended with a failure verdict ({r.get('failures', '')})"
        else:
            text += f"{r['level']}{_swept_size(factor, r)} "
            if "verdict" in bad:
                text += (f"{int(r['n_failed'])} of {n} estimations ended with a failure verdict "
                         f"({r.get('failures', '')})" + (", and " if lost else
                                                         f"; the {int(r['n_ok'])} that succeeded "
                                                         + ("meets" if r["n_ok"] == 1 else "meet")
                                                         + " every requirement"))
            if lost:
                text += "it is lost for " + ", ".join(
                    f"{g} ({r[f'acc_{g}']:.2f} > {DESIRED_3SIGMA_DEG[g]:g} deg)" for g in lost)
                if np.isfinite(r.get("n_pass", math.nan)):
                    text += f" ({int(r['n_pass'])} of {n} replications meet every requirement)"
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
            text += (f"; the vane residual 3-sigma grows from {base_res:.2f} to {res:.2f} deg: the model "
                     "(no process noise) no longer fits the data")
        elif np.isfinite(res) and lost:  # (a loss by failure verdicts alone was seen in the residuals)
            text += (f"; the vane residual 3-sigma stays near {res:.2f} deg (base {base_res:.2f}): an error "
                     "the fit does not see in its residuals")
        ratio, base_ratio = r.get("ratio_crb", math.nan), base.get("ratio_crb", math.nan)
        if np.isfinite(ratio) and np.isfinite(base_ratio) and ratio > 2.0 * base_ratio:
            within = r.get("within_3sigma", math.nan)
            text += (f", and the Cramer-Rao bounds turn optimistic (scatter/CRB {ratio:.1f}, base "
                     f"{base_ratio:.1f}; {within:.0%} of the estimates within 3 sigma)")
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
        vf, vrows = variant
        how = vf.title.split(", ", 1)[-1]
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
    return text + "."


# ---------------------------------------------------------------------------- output


def _fmt(v: Any, spec: str = ".3f") -> str:
    if isinstance(v, float | np.floating):
        return "nan" if not np.isfinite(v) else format(v, spec)
    return str(v)


def table_text(df: pd.DataFrame) -> str:
    """The study's table, one line per point."""
    head = (f"{'factor':<11} {'level':>8} {'ok/fail':>7} {'pass':>4} "
            + " ".join(f"{_SHORT[g]:>6}" for g in SENSOR_GROUPS)
            + f" {'fails':<16} {'b_l,b_r err':>11} {'scat/CRB':>8} {'in3sig':>6} {'res_vane':>8}"
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
            f" {_fmt(r.get('resid_vane_deg', math.nan)):>8}  {r.get('swept', '-')}"
            + (f"  [{r['failures']}]" if isinstance(r.get("failures"), str) and r.get("failures") else ""))
    return "\n".join(lines)


def _typical_flow_delay_ms() -> float:
    """The mean of the typical preset's flow-sensor delays, ms (where "typical" is plotted)."""
    return float(np.mean([1e3 * e.delay_s for e in ErrorConfig.typical().sensors.values()]))


def _panel(ax, f: Factor, rows: pd.DataFrame, variant: bool = False) -> None:
    """Draw one factor's accuracies into ``ax`` (a variant: hollow markers, dashed)."""
    labels = list(rows["level"])
    if f.numeric:
        x = np.array([_typical_flow_delay_ms() if v == "typical" else float(v) for v in labels])
    else:
        x = np.arange(len(labels), dtype=float)
    span = float(np.ptp(x)) if len(x) > 1 else 1.0
    for j, g in enumerate(SENSOR_GROUPS):
        col = f"acc_{g}"
        if col not in rows or not np.isfinite(rows[col].to_numpy(dtype=float)).any():
            continue
        y = rows[col].to_numpy(dtype=float)
        top = rows[f"acc_max_{g}"].to_numpy(dtype=float)
        ax.errorbar(x + (j - 2.5) * 0.006 * span, y, yerr=[np.zeros_like(y), np.maximum(top - y, 0.0)],
                    marker="os^vDP"[j], ms=5, capsize=2, lw=1.2, color=f"C{j}",
                    mfc="none" if variant else f"C{j}",
                    ls="--" if variant else ("-" if g in DESIRED_3SIGMA_DEG else ":"),
                    label=None if variant else g)
    for xi, (_, r) in zip(x, rows.iterrows(), strict=True):
        n_ok, n_failed = int(r.get("n_ok", 0) or 0), int(r.get("n_failed", 0) or 0)
        if n_failed:
            ax.annotate(f"{n_failed}/{n_ok + n_failed} failed" + (" (started at mean)" if variant else ""),
                        (xi, 0.97 if not variant else 0.90), xycoords=("data", "axes fraction"),
                        ha="center", va="top", fontsize=7, color="C3")
        if r["level"] == "typical":
            ax.annotate("typical", (xi, 0.06), xycoords=("data", "axes fraction"), ha="center", fontsize=7)
    if not f.numeric:
        ax.set_xticks(x, labels)


def plot(df: pd.DataFrame, factors: Sequence[Factor], path: Path, replications: int) -> Path:
    """One panel per factor: each sensor group's accuracy (median over the replications, bar to
    the worst) against the level, the desired accuracies as dashed lines; a variant factor (IMU
    biases started at their mean) is drawn in its factor's panel with hollow markers; the last
    panel holds the legend."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import FormatStrFormatter, LogLocator

    shown = [f for f in factors if f.variant_of is None]
    ncol = 3
    nrow = math.ceil((len(shown) + 1) / ncol)
    fig = Figure(figsize=(5.0 * ncol, 4.0 * nrow), layout="constrained")
    FigureCanvasAgg(fig)
    handles: list = []
    for i, f in enumerate(shown):
        ax = fig.add_subplot(nrow, ncol, i + 1)
        _panel(ax, f, df[df["factor"] == f.name])
        title = f.title
        for v in factors:
            if v.variant_of == f.name and (df["factor"] == v.name).any():
                _panel(ax, v, df[df["factor"] == v.name], variant=True)
                title += f"\nhollow, dashed: {v.title.split(', ', 1)[-1]}"
        for req in sorted(set(DESIRED_3SIGMA_DEG.values())):
            ax.axhline(req, color="k", ls="--", lw=0.8)
        ax.set_yscale("log")
        ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.yaxis.set_minor_locator(LogLocator(base=10.0, subs=(2.0, 5.0)))
        ax.yaxis.set_minor_formatter(FormatStrFormatter("%g"))
        ax.tick_params(axis="y", which="minor", labelsize=7)
        ax.set_xlabel(f.title)
        ax.set_ylabel("|mean| + 3 sigma vs truth, deg")
        ax.set_title(title, fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        if len(ax.get_legend_handles_labels()[0]) > len(handles):
            handles = list(zip(*ax.get_legend_handles_labels(), strict=True))
    leg = fig.add_subplot(nrow, ncol, len(shown) + 1)
    leg.axis("off")
    if handles:
        leg.legend([h for h, _ in handles], [lb for _, lb in handles], loc="upper left", fontsize=9,
                   title="calibrated channel (worst of a pair)")
    desired = "\n".join(f"  {g}: {v:g} deg" for g, v in DESIRED_3SIGMA_DEG.items())
    leg.text(0.0, 0.35, f"dashed lines: the desired 3-sigma accuracy\n{desired}\n"
             "dotted: the boom (no stated requirement)\n"
             "red: estimations that failed (no accuracy from them)", fontsize=9, va="top",
             transform=leg.transAxes)
    fig.suptitle("Planning study (c): calibrated-channel accuracy against the truth, median of "
                 f"{replications} replications (bar to the worst)", fontsize=11)
    fig.savefig(path, dpi=100)
    return path


def _typical_delays_text() -> str:
    """The typical preset's flow-sensor delays and recorder latencies, ms."""
    typ = ErrorConfig.typical()
    sensors = ", ".join(f"{n} {1e3 * e.delay_s:g}" for n, e in typ.sensors.items())
    recorders = ", ".join(f"{n} {1e3 * e.delay_s:g}" for n, e in typ.recorders.items())
    return f"sensors {sensors}; recorder latencies {recorders} ms"


def _bounds_text(factors: Sequence[Factor]) -> str:
    bounds = _bounds_display()
    seen: dict[tuple[float, float, str], list[str]] = {}
    for f in factors:
        for _, families, unit in f.swept:
            for fam in families:
                lo, hi = bounds.get(fam, (-math.inf, math.inf))
                if fam not in seen.setdefault((lo, hi, unit), []):
                    seen[(lo, hi, unit)].append(fam)
    return "; ".join(f"{', '.join(fams)} in [{lo:g}, {hi:g}] {unit}" for (lo, hi, unit), fams in seen.items())


def report(df: pd.DataFrame, config: StudyConfig, replications: int, command: str,
           invocations: Sequence[Mapping[str, Any]]) -> str:
    """The text file: header (command, machine, cost), metric legend, table, conclusions.

    ``invocations``: one record per invocation of the study on this output directory (wall_s,
    cpu_s, replications_run, load_start, load_end, code), this one last.
    """
    base = base_scenario(config)
    flights = "; ".join(f"{'+'.join(b['configurations'])} x Mach {b['mach']} x {', '.join(b['maneuvers'])}"
                        for b in base["flights"])
    accel_mps2, gyro_deg_s = _typical_imu()
    est = base["estimator"]
    runs = df["run"].nunique() if "run" in df else len(df)

    def para(text: str) -> list[str]:
        return [*textwrap.wrap(text, width=108), ""]

    desired = ", ".join(f"{_SHORT[g]} {v:g}" for g, v in DESIRED_3SIGMA_DEG.items())
    lines = [
        *para("Planning study (c): how large may IMU biases, time delays, winds and turbulence be before "
              "the desired accuracy is lost? One factor at a time around the base scenario; every point "
              "a Monte Carlo run (campaigns/montecarlo)."),
        f"$ {command}",
        *machine_text(__file__, invocations[-1].get("code_start")).splitlines(),
        f"{replications} replications per point, {runs} distinct runs",
        *invocations_text(invocations),
        "",
        *para(f"base scenario: {flights}; errors preset typical (nose-probe irregularity off); "
              f"{base['local_flow_truth']} / {base['adc_baseline']} (representable by the model set: a loss "
              f"of accuracy is the swept factor's); {base['environment']['planet']} earth, calm air; IMU "
              f"biases drawn per maneuver (std {IMU_SPREAD_ACCEL_MPS2:g} m/s^2, {IMU_SPREAD_GYRO_DEG_S:g} "
              f"deg/s at scale 1). Estimator: {est.get('model', 'tejas')} model set, channels "
              f"{est.get('channels', 'all')}, at most {est.get('max_iterations', 40)} iterations."),
        *para(f"levels: IMU biases x typical (accel {accel_mps2} m/s^2, gyro "
              f"{[round(g, 3) for g in gyro_deg_s]} deg/s; the per-maneuver spread scaled too); flow delay "
              f"= the delay of every flow sensor (typical: {_typical_delays_text()}); INS latency on the "
              f"INS recorder; steady wind towards {WIND_TOWARDS_DEG:g} deg; turbulence redrawn every "
              f"replication. Bounds of the swept parameters: {_bounds_text(config.factors)}."),
        *para("columns: vane_a, sp_a, sp_b, np_b, boom_a, boom_b = calibrated vane AOA (worse of the "
              "two), side-probe AOA, side-probe AOSS, nose-probe AOSS, boom AOA, boom AOSS (worse of "
              "upper/lower): |mean| + 3 std of (calibrated channel - true flow angle) over all samples, "
              f"deg, median over the replications; desired: {desired} deg (the boom has no stated "
              "requirement; np_b pools every AOA flown). The calibrated channel is compared with the "
              "truth at the channel's true lag: the columns measure the error in value, not in timing. "
              "ok/fail = converged / failed estimations; pass = converged replications meeting every "
              "desired accuracy; fails = groups whose median misses the desired "
              "accuracy; b_l,b_r err = rms of estimate - truth of the vane biases, deg; scat/CRB = median "
              "over the calibration parameters (delays, biases, scales, tables) of the Monte Carlo "
              "scatter / mean Cramer-Rao std; in3sig = fraction of calibration estimates within 3 CRB "
              "sigmas of the truth; res_vane = vane residual 3-sigma (measurement - model, the paper's "
              "Table 2), deg; swept parameter error = rms (max |.|) of estimate - truth of the swept "
              "parameter's estimates that the data determine, the largest |truth|, the number of "
              "estimates on a bound; [..] = failed estimations."),
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


# ---------------------------------------------------------------------------- command line


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m campaigns.studies.tolerance --out DIR [--replications N] ...``"""
    p = argparse.ArgumentParser(
        prog="python -m campaigns.studies.tolerance",
        description="Planning study (c): sweep IMU biases, flow-sensor and INS delays, steady wind and "
        "turbulence one at a time; Monte Carlo accuracy of the calibrated channels against the truth "
        "and pass/fail against the desired accuracy. Resumable: run the same command again.")
    p.add_argument("--out", required=True, type=Path, help="work directory (each point's Monte Carlo run)")
    p.add_argument("--results", type=Path, default=None,
                   help="where tolerance.txt / .png / .csv go (default: --out)")
    p.add_argument("--replications", type=int, default=None, metavar="N",
                   help=f"replications per point (default: {FULL.replications}; tiny: {TINY.replications})")
    p.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1),
                   help="points run at once, one process each (default: 2)")
    p.add_argument("--size", choices=sorted(SIZES), default="full",
                   help="full: the study; tiny: one configuration, two maneuvers, two levels per factor")
    args = p.parse_args(argv)
    config = SIZES[args.size]
    n = args.replications or config.replications
    if n < 1:
        p.error("--replications must be >= 1")
    results = args.results or args.out
    results.mkdir(parents=True, exist_ok=True)
    invocation = Invocation(__file__)
    points = study_points(config, args.out)
    print(f"{len({q.directory for q in points})} distinct runs x {n} replications into {args.out}/points",
          flush=True)
    errors, n_ran = run_points(points, n, args.workers, log=lambda s: print(s, flush=True))
    df = collect(points, n, errors)
    command = "python -m campaigns.studies.tolerance " + " ".join(shlex.quote(a) for a in (
        sys.argv[1:] if argv is None else argv))
    invocations = invocation.finish(args.out / INVOCATIONS_FILE, command, n_ran)
    text = report(df, config, n, command, invocations)
    (results / "tolerance.txt").write_text(text)
    df.to_csv(results / "tolerance.csv", index=False)
    plot(df, config.factors, results / "tolerance.png", n)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
