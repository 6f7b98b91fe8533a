"""Robustness study: do fits from the default (zero) start reach the true minimum when
the IMU biases are large, and is a fit that does not reported as a failure?

Setting: one aircraft (PV1-NP) at Mach 0.5, 6000 m, a pitch doublet, a wind-up turn
and a steady-heading sideslip (105 s, split into its 35 s segments as usual), the default
campaign's world (typical errors of SPEC §6, the realistic local-flow truth and airdata-computer
baseline, a steady wind of (6, -4, 0) m/s, calm air), the IMU biases scaled to ``k`` times the
typical preset (``synth.errors.ErrorConfig.typical``: accelerometer (0.10, -0.08, 0.15) m/s^2,
gyro (0.2, -0.3, 0.15) deg/s; ``k`` = 1, 2, 3, -3) and drawn per maneuver around that value
(standard deviations ``|k|`` x 0.05 m/s^2 and ``|k|`` x 0.1 deg/s, the spread of planning study
(c), :mod:`campaigns.studies.tolerance`; :func:`campaigns.studies.common.set_imu_bias`). Each
scale is a Monte Carlo scenario of :mod:`campaigns.montecarlo` (same master seed for every scale:
replication ``r`` of every scale has the same noise and the same standardised IMU-bias draws, only
scaled).

Per replication, on the same instrumented data (:mod:`campaigns.montecarlo` draws, flies and
instruments it), two fits:

* the **judged fit**: ``estimate`` with the estimator's default options, from the default start
  values of the problem (``problem_from_dataset``: IMU biases 0, initial conditions from the
  data, the model set's calibration start values);
* the **reference fit**, started from the truth (:func:`campaigns.truth.true_parameters`; the
  solver's own start strategy off, ``start="given"``), which defines the true minimum. It solves
  the same problem as the judged fit: the parameters the judged fit held (at its start values, as
  undetermined) are held at the same values, so that the two costs differ only through where the
  iteration ended. A parameter without a truth (a pressure-altitude scale factor, a DGPS offset)
  starts where the judged fit starts. The estimator decides what the data determine on the
  trajectory it starts from: when, from the truth, it holds a parameter the judged fit estimated
  (a table breakpoint with few samples), the reference fit runs once more with those parameters
  held at the judged fit's values (:func:`reference_fit`), so that the two problems stay the same.

The judged fit is **at the true minimum** when its final cost exceeds the reference's by at most
:data:`COST_TOL_NLL`. Why that tolerance: the cost is the negative log-likelihood with the residual
covariance at its maximum-likelihood value, ``J = 1/2 sum_c N_c (1 + ln R_c)``. Near a minimum
``J(theta) - J(theta*) = d^2 / 2``, ``d`` the distance between the two parameter vectors in units of
the Cramér-Rao covariance (the worst direction), so ``Delta J <= 0.1`` means the two fits are less
than 0.45 of a Cramér-Rao deviation apart in any combination of the parameters (a likelihood ratio
of 1.1: statistically the same estimate). It is well above what the solver's own convergence test
leaves (a predicted further decrease below 1e-3), and more than five orders of magnitude below a
wrong minimum of the kind large IMU biases lead a fit from zero to (attitude residuals of 10 deg
against 0.03 deg of noise: ``Delta J`` ~ 1/2 N ln(R_wrong / R_true) ~ 3e4 per attitude channel).
A judged fit whose cost lies *below* the reference's by more than the tolerance found a better
minimum than the fit from the truth; it is counted apart ("below the reference"), not as a wrong
minimum.

Reported beside the cost, not part of the definition: the largest difference of a parameter
estimated by both fits, in units of the reference fit's Cramér-Rao deviation,
``max |theta - theta_ref| / std_ref``, against :data:`PARAM_TOL_SIGMA` (0.1). At the same minimum it
measures the convergence tolerance (how far short of the minimum each fit stopped), which is why it
does not decide which minimum a fit is in; and the time delays enter through interpolation between
samples, so the cost is only piecewise quadratic in them: two fits of one cost may differ by more
in a delay.

Outcome of a judged fit: at the true minimum or not, crossed with what the result says (its
``success``: the verdict's, SUCCESS or SUCCESS_WITH_WARNINGS). "Success at a wrong minimum" is a
fit not at the true minimum whose result says success; it must never happen. A failure at the true
minimum is a false alarm. Recorded per fit: solver status and message, verdict and the warning and
failure findings, iterations, wall time, final cost, the largest attitude residual rms (phi, theta,
psi; any maneuver), the vane biases' errors against the truth.

Run (resumable: the same command again skips finished replications; the numbers of a replication
are bit-identical on a rerun, wall times aside; a run directory is tied to its scenarios, not to
the code: after changing the estimator, start a new ``--out``)::

    python -m campaigns.studies.robustness --out runs/robustness --results campaigns/studies/results
    python -m campaigns.studies.robustness --out /tmp/rob --size tiny    # a smoke run

It writes ``robustness.txt`` (headed by the command, machine, code commit and wall time: the table
per scale, one line per replication, conclusions drawn from the numbers), ``robustness.png`` and
``robustness.csv`` (one row per replication) into ``--results`` (default: ``--out``); each scale's
replications stay in ``OUT/runs/x<k>/pairs/`` (one JSON record each).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import tempfile
import textwrap
import time
import traceback
import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from threadpoolctl import threadpool_limits

from campaigns.montecarlo import Scenario, parse_scenario
from campaigns.montecarlo.replication import Models, fly, write_scratch_dataset
from campaigns.montecarlo.runner import RunLock, prepare_output
from campaigns.montecarlo.scenario import scenario_hash
from campaigns.studies import scaffold
from campaigns.studies.common import (
    IMU_SPREAD_ACCEL_MPS2,
    IMU_SPREAD_GYRO_DEG_S,
    VANE_BIAS_FAMILIES,
    WIND_NED_MPS,
    set_imu_bias,
    typical_imu_biases_deg,
)
from campaigns.studies.scaffold import Invocations, fmt, paragraph
from campaigns.truth import true_parameters
from estimator.problem import Problem
from estimator.result import STATUS_TEXT, EstimationResult
from estimator.solver import SolverOptions, estimate
from synth.dataset import atomic_write_bytes
from synth.errors import ErrorConfig

STUDY = "robustness"
#: the master seed of every scale's scenario (replication r draws from (SEED, r))
SEED = 2041
#: a judged fit whose final cost exceeds the reference's by at most this is at the true minimum
#: (negative log-likelihood units; module docstring)
COST_TOL_NLL = 0.1
#: parameters of two fits at one minimum should agree to this many Cramér-Rao deviations (reported)
PARAM_TOL_SIGMA = 0.1
#: a fit not at the true minimum whose attitude residuals are within this factor of the reference
#: fit's stopped short of the true minimum rather than in another valley (said in the conclusions)
NEAR_ATT_RATIO = 1.5
#: the attitude channels whose residual rms is reported
ATTITUDE_CHANNELS = ("phi", "theta", "psi")
#: the INS attitude noise of the typical preset, deg (what a fit's attitude residuals come down to)
INS_NOISE_DEG = math.degrees(ErrorConfig.typical().ins.euler_noise_rad)

#: outcomes of a judged fit (:func:`classify`), in table order
OUTCOMES = ("success at the true minimum", "failure at the true minimum", "success at a wrong minimum",
            "failure at a wrong minimum", "below the reference", "no reference", "error")
SUCCESS_TRUE, FAILURE_TRUE, SUCCESS_WRONG, FAILURE_WRONG, BELOW, NO_REFERENCE, ERROR = OUTCOMES
_OUTCOME_COLOUR = dict(zip(OUTCOMES, ("tab:green", "tab:orange", "tab:red", "tab:blue", "tab:purple", "0.5",
                                      "k"), strict=True))


# ---------------------------------------------------------------------------- the scenarios


@dataclasses.dataclass(frozen=True)
class StudyConfig:
    """What a study size flies.

    Attributes
    ----------
    scales : the IMU-bias scales, multiples of the typical preset.
    replications : replications per scale.
    flights : the scenario's ``[[flights]]`` (one aircraft, one Mach number).
    estimator : the scenario's ``[estimator]`` (empty: the estimator's defaults, every channel).
    """

    scales: tuple[float, ...]
    replications: int
    flights: tuple[Mapping[str, Any], ...]
    estimator: Mapping[str, Any] = dataclasses.field(default_factory=dict)


SIZES: dict[str, StudyConfig] = {
    # the study's setting: PV1-NP at Mach 0.5 flies a pitch doublet, a wind-up turn and the SHSS
    # (105 s in 35 s segments), each with the defaults of synth.maneuvers
    "full": StudyConfig(scales=(1.0, 2.0, 3.0, -3.0), replications=10, flights=(
        {"configurations": ["PV1-NP"], "mach": [0.5], "altitude_m": 6000.0,
         "maneuvers": ["pitch_doublet", "windup_turn", "shss"]},)),
    # a smoke run: one 20 s pitch doublet at 3x typical, one replication, the vanes' channels only
    # with their tables held (a doublet determines neither the sideslip models nor the tables), and
    # v0 and the lateral accelerometer bias held (without a sideslip channel they would enter the
    # outputs only to second order, through TAS: a degenerate problem)
    "tiny": StudyConfig(scales=(3.0,), replications=1, flights=(
        {"configurations": ["PV1-NP"], "mach": [0.5], "altitude_m": 6000.0, "maneuvers": ["pitch_doublet"],
         "maneuver": {"duration_s": 20.0}},),
        estimator={"channels": ["phi", "theta", "psi", "tas", "h", "h_dgps", "alpha_zl", "alpha_zr"],
                   "parameters": {"f1": {"free": False}, "f2": {"free": False}, "v0": {"free": False},
                                  "day": {"free": False}}}),
}


def scale_label(scale: float) -> str:
    """``2`` for 2.0, ``-3`` for -3.0 (tables, directory names)."""
    return f"{scale:g}"


def scenario_raw(scale: float, config: StudyConfig, replications: int) -> dict:
    """The Monte Carlo scenario (TOML tables) of one IMU-bias scale.

    The default campaign's world (``campaigns/default.toml``: fleet, realistic local-flow truth and
    ADC baseline, steady wind, typical errors) with the IMU biases at ``scale`` x typical, drawn per
    maneuver with a spread ``|scale|`` x that of study (c); the estimator's defaults.
    """
    raw: dict[str, Any] = {
        "name": f"{STUDY}_x{scale_label(scale)}",
        "description": f"robustness: IMU biases {scale_label(scale)} x typical, zero start",
        "seed": SEED, "replications": int(replications), "fleet": "fleet_default",
        "local_flow_truth": "local_flow_truth", "adc_baseline": "adc_baseline", "common_rate_hz": 40.0,
        "environment": {"planet": "flat", "wind_ned_mps": list(WIND_NED_MPS), "turbulence": "none"},
        "errors": {"preset": "typical"},
        "flights": [dict(f) for f in config.flights],
        "draw": {"turbulence": "frozen", "errors": {}},
        "estimator": dict(config.estimator),
    }
    set_imu_bias(raw, scale)
    for key in ("imu.accel_bias_mps2", "imu.gyro_bias_deg_s"):  # a spread, whatever the sign of the scale
        raw["draw"]["errors"][key]["std"] = abs(raw["draw"]["errors"][key]["std"])
    return raw


def run_directory(out_dir: Path, scale: float) -> Path:
    """The directory of one scale's replications."""
    return Path(out_dir) / "runs" / f"x{scale_label(scale)}"


def record_file(out_dir: Path, scale: float, index: int) -> Path:
    """The JSON record of one replication (both fits and their comparison)."""
    return run_directory(out_dir, scale) / "pairs" / f"r{index:05d}.json"


# ---------------------------------------------------------------------------- one replication


def _asked(scenario: Scenario) -> dict[str, Any]:
    """The solver options the scenario's ``[estimator]`` sets explicitly (the rest: the defaults)."""
    est, raw = scenario.estimator, scenario.raw.get("estimator", {})
    return {k: getattr(est, k) for k in ("max_iterations", "colored") if k in raw}


def judged_options(scenario: Scenario) -> SolverOptions:
    """The judged fit's options: the estimator's defaults (its start strategy included), as far as
    the scenario does not set them."""
    return SolverOptions(**_asked(scenario))


def reference_options(scenario: Scenario) -> SolverOptions:
    """The reference fit's options: from the given (true) values, no coloured deviations (only the
    Cramér-Rao deviations are used)."""
    return SolverOptions(**{**_asked(scenario), "colored": False, "start": "given"})


def reference_problem(problem: Problem, judged: EstimationResult, truth: Mapping[str, float],
                      keep: Sequence[str] = ()) -> Problem:
    """The judged fit's problem started from the truth.

    Parameters
    ----------
    problem : the problem of the judged fit.
    judged : the judged fit (``free_estimated``, ``values``: SI).
    truth : parameter key -> true value, SI (:func:`campaigns.truth.true_parameters`).
    keep : parameters the judged fit estimated that start at its value rather than the truth.

    Returns
    -------
    The problem with the parameters the judged fit estimated free, started at their true value
    (where there is one; otherwise, and for ``keep``, at the judged fit's value), and those it held
    fixed at its values (its start values).
    """
    ps = problem.parameters
    estimated = judged.free_estimated
    if estimated is None or not np.any(estimated):  # the judged fit estimated nothing: the problem's set
        estimated = ps.free_mask
    values = {p.key: float(truth[p.key]) if (e and p.key in truth and p.key not in keep) else float(v)
              for p, e, v in zip(ps, estimated, judged.values, strict=True)}
    free = {p.key: bool(e) for p, e in zip(ps, estimated, strict=True)}
    return dataclasses.replace(problem, parameters=ps.with_values(values).with_free(free))


def reference_fit(scenario: Scenario, problem: Problem, judged: EstimationResult,
                  truth: Mapping[str, float]) -> tuple[EstimationResult, list[str]]:
    """The reference fit (:func:`reference_problem`), and the parameters it held at the judged fit's
    values.

    The estimator decides which parameters the data determine from the trajectory it starts on
    (a table breakpoint's samples, an undetermined combination): from the truth it may hold a
    parameter that the judged fit, from its own start, estimated. Its minimum is then that of a
    smaller problem, a little above the judged fit's even at the same minimum. So when it holds such
    parameters, it runs once more with them started (and so held) at the judged fit's values: the
    two fits then solve the same problem, and they reach the same cost if and only if the judged
    fit is at the true minimum (a handful of poorly determined parameters held at a wrong
    minimum's values does not bring the rest to it).
    """
    options = reference_options(scenario)
    reference = estimate(reference_problem(problem, judged, truth), options)
    _, _, _, held = parameter_distance(judged, reference)
    if not held:
        return reference, []
    return estimate(reference_problem(problem, judged, truth, keep=held), options), held


def final_cost(result: EstimationResult) -> float:
    """The final cost (negative log-likelihood) of a fit; NaN when it has none."""
    return float(result.cost_history[-1]) if result.cost_history else math.nan


def fit_record(result: EstimationResult, truth: Mapping[str, float]) -> dict[str, Any]:
    """What one fit gave, JSON-ready.

    Parameters
    ----------
    result : the fit.
    truth : parameter key -> true value, SI.

    Returns
    -------
    status (code and text), message, success, verdict (name), the
    warning and failure findings (``"severity: code (channel)"``), iterations, wall time (s), final
    cost (negative log-likelihood), parameters estimated, the largest attitude residual rms per
    channel over the maneuvers and their maximum (deg), the vane biases' estimate - truth (deg).
    """
    verdict = result.verdict
    findings = result.findings
    att: dict[str, float] = {}
    for r in result.residuals:
        if r.channel in ATTITUDE_CHANNELS:
            att[r.channel] = max(att.get(r.channel, 0.0), math.degrees(r.rms))
    vane = {}
    for p in result.parameters:
        if p.name in VANE_BIAS_FAMILIES and p.key in truth:
            vane[p.key] = (p.value - truth[p.key]) * p.display_scale
    return {
        "status": int(result.status), "status_text": STATUS_TEXT.get(int(result.status), str(result.status)),
        "message": result.message, "success": bool(result.success),
        "verdict": verdict.name,
        "findings": [f"{f.severity.name.lower()}: {f.code}" + (f" ({f.channel})" if f.channel else "")
                     for f in findings if int(f.severity) > 0],
        "iterations": int(result.iterations), "wall_s": float(result.elapsed_s), "cost": final_cost(result),
        "n_estimated": int(np.sum(result.free_estimated)) if result.free_estimated is not None else 0,
        "att_rms_deg": att, "att_rms_max_deg": max(att.values()) if att else math.nan,
        "vane_bias_err_deg": vane,
    }


def parameter_distance(judged: EstimationResult, reference: EstimationResult
                       ) -> tuple[float, str, int, list[str]]:
    """Largest ``|theta - theta_ref| / std_ref`` over the parameters both fits estimated (with a
    finite Cramér-Rao deviation in the reference fit).

    Returns
    -------
    (the largest distance in deviations (NaN: none compared), its parameter, how many compared,
    the parameters the judged fit estimated and the reference fit held).
    """
    a = judged.free_estimated if judged.free_estimated is not None else np.zeros(len(judged.values), bool)
    b = reference.free_estimated if reference.free_estimated is not None else np.zeros_like(a)
    std = np.asarray(reference.std_crb, dtype=float)
    both = a & b & np.isfinite(std) & (std > 0)
    keys = judged.parameters.keys
    held = [keys[i] for i in np.flatnonzero(a & ~b)]
    if not both.any():
        return math.nan, "", 0, held
    d = np.abs(judged.values[both] - reference.values[both]) / std[both]
    i = int(np.argmax(d))
    return float(d[i]), keys[int(np.flatnonzero(both)[i])], int(both.sum()), held


def run_pair(scenario: Scenario, index: int, truths: Mapping[int, Sequence],
             models: Models) -> dict[str, Any]:
    """Replication ``index`` of a scale: draw and instrument its data (the Monte Carlo engine's
    draw, flights and instrumentation), build the problem as ``fpr calibrate`` does, fit from the
    default start and from the truth, compare.

    Parameters
    ----------
    scenario : the scale's scenario.
    index : the replication, 0-based.
    truths : job index -> the truth segments of its flight (the same in every replication).
    models : the scenario's local-flow truth and ADC baseline.

    Returns
    -------
    the replication's record (JSON-ready): ``judged`` and ``reference`` (:func:`fit_record`), the
    cost difference ``dcost`` (judged - reference), the parameter distance (:func:`parameter_distance`),
    the drawn IMU biases' largest magnitudes.
    """
    t0 = time.perf_counter()
    # one BLAS thread, as the engine's replications: the same sums in the same order everywhere
    with threadpool_limits(limits=1):
        draw = scenario.draw(index)
        est = scenario.estimator
        with tempfile.TemporaryDirectory(prefix=f"fpr-robustness-r{index:05d}-") as tmp:
            write_scratch_dataset(scenario, draw.maneuvers, truths, models, Path(tmp))
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                problem = est.problem(tmp)
                truth = dict(true_parameters(problem).values)
                judged = estimate(problem, judged_options(scenario))
                reference, kept = reference_fit(scenario, problem, judged, truth)
            notes = list(dict.fromkeys(str(w.message).replace(tmp, "<replication data>") for w in caught))
    dist, where, n, held = parameter_distance(judged, reference)
    accel = [np.max(np.abs(md.errors.imu.accel_bias_mps2)) for md in draw.maneuvers]
    gyro = [np.max(np.abs(md.errors.imu.gyro_bias_rps)) for md in draw.maneuvers]
    j, r = fit_record(judged, truth), fit_record(reference, truth)
    return {
        "scale": None, "replication": index, "noise_seed": draw.noise_seed, "scenario_hash": scenario.hash,
        "judged": j, "reference": r, "dcost": j["cost"] - r["cost"],
        "dtheta_max_sigma": dist, "dtheta_argmax": where, "n_compared": n, "held_by_reference_only": held,
        "held_at_judged_values": kept,
        "accel_bias_max_mps2": float(max(accel)), "gyro_bias_max_deg_s": math.degrees(max(gyro)),
        "warnings": notes, "wall_s": time.perf_counter() - t0,
    }


#: per worker process: parsed scenarios and their models by hash, flights by what decides them
_PROCESS: dict[str, dict] = {"scenarios": {}, "flights": {}}


def _flights(scenario: Scenario) -> dict[int, tuple]:
    """The truth of every maneuver of the scenario, flown once per process. A flight does not depend
    on the errors (they are injected afterwards): the scales share them."""
    cache = _PROCESS["flights"]
    out = {}
    for md in scenario.draw(0).maneuvers:
        key = json.dumps([md.job.configuration_id, md.job.maneuver, md.environment.to_dict()], sort_keys=True,
                         default=str)
        if key not in cache:
            cache[key] = fly(scenario, md)
        out[md.job.index] = cache[key]
    return out


def pair_task(raw: Mapping[str, Any], scale: float, index: int) -> dict[str, Any]:
    """Run one replication in a worker; an exception becomes an error record (the study goes on)."""
    t0 = time.perf_counter()
    try:
        key = scenario_hash(raw) + str(raw["replications"])
        if key not in _PROCESS["scenarios"]:
            scenario = parse_scenario(raw, source=f"campaigns.studies.{STUDY}:{raw['name']}")
            _PROCESS["scenarios"][key] = (scenario, Models.of(scenario))
        scenario, models = _PROCESS["scenarios"][key]
        rec = run_pair(scenario, index, _flights(scenario), models)
    except Exception as exc:  # recorded, not raised
        rec = {"replication": index, "error": f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}",
               "wall_s": time.perf_counter() - t0}
    rec["scale"] = scale
    return rec


# ---------------------------------------------------------------------------- running


def finished(path: Path) -> bool:
    """A replication's record exists and is not an error record (those are run again on a rerun)."""
    return path.exists() and "error" not in json.loads(path.read_text())


def run_study(config: StudyConfig, out_dir: Path, replications: int, workers: int,
              log: Callable[[str], None] = print) -> int:
    """Run (or resume) every scale's missing replications (and those that raised), ``workers`` at a
    time (one process each; 1: in this process); the records are written atomically by this
    process. Returns the number of replications computed now."""
    raws = {s: scenario_raw(s, config, replications) for s in config.scales}
    todo: list[tuple[float, int]] = []
    with contextlib.ExitStack() as stack:
        for s, raw in raws.items():
            d = run_directory(out_dir, s)
            # the engine's output-directory check: a directory of another scenario is refused
            prepare_output(parse_scenario(raw, source=f"campaigns.studies.{STUDY}:{raw['name']}"), d)
            stack.enter_context(RunLock(d))
            (d / "pairs").mkdir(exist_ok=True)
            todo += [(s, k) for k in range(replications) if not finished(record_file(out_dir, s, k))]
        done = len(config.scales) * replications - len(todo)
        log(f"{len(todo)} replications to compute ({done} done before)")

        def write(rec: dict[str, Any]) -> None:
            path = record_file(out_dir, rec["scale"], rec["replication"])
            atomic_write_bytes(path, (json.dumps(rec, indent=1, sort_keys=True) + "\n").encode())
            what = rec.get("error", "").splitlines()[0] if "error" in rec else (
                f"{classify_record(rec)}, dJ {rec['dcost']:.3g}")
            log(f"  x{scale_label(rec['scale'])} r{rec['replication']}: {what} ({rec['wall_s']:.1f} s)")

        scaffold.run_in_processes(pair_task, [(raws[s], s, k) for s, k in todo], workers, write)
    return len(todo)


# ---------------------------------------------------------------------------- classification


def location(dcost: float, tol: float = COST_TOL_NLL) -> str:
    """Where a judged fit ended against the reference.

    Parameters
    ----------
    dcost : the judged fit's final cost minus the reference's (negative log-likelihood units).
    tol : the tolerance of "the same minimum" (:data:`COST_TOL_NLL`; module docstring).

    Returns
    -------
    "true" (``|dcost| <= tol``), "wrong" (above), "below" (below by more than ``tol``) or
    "unknown" (``dcost`` is NaN: a fit without a cost).
    """
    if not np.isfinite(dcost):
        return "unknown"
    if abs(dcost) <= tol:
        return "true"
    return "wrong" if dcost > 0 else "below"


def classify(success: bool, dcost: float, tol: float = COST_TOL_NLL, reference_cost: float = 0.0) -> str:
    """The outcome of a judged fit.

    Parameters
    ----------
    success : what its result says (the verdict's success: SUCCESS or SUCCESS_WITH_WARNINGS).
    dcost : its final cost minus the reference's (negative log-likelihood units).
    tol : the tolerance of "the same minimum" (:data:`COST_TOL_NLL`).
    reference_cost : the reference fit's final cost; NaN when the model cannot be evaluated at the
        truth (no true minimum to compare with).

    Returns
    -------
    one of :data:`OUTCOMES`: success or failure at the true minimum or at a wrong minimum (a judged
    fit without a cost, the model not evaluable, is at a wrong minimum as far as anyone can tell),
    "below the reference" or "no reference".
    """
    if not np.isfinite(reference_cost):
        return NO_REFERENCE
    where = location(dcost, tol)
    if where == "below":
        return BELOW
    at = "the true minimum" if where == "true" else "a wrong minimum"
    return f"{'success' if success else 'failure'} at {at}"


def classify_record(rec: Mapping[str, Any]) -> str:
    """:func:`classify` of a replication record ("error" for a replication that raised)."""
    if "error" in rec:
        return ERROR
    return classify(bool(rec["judged"]["success"]), float(rec["dcost"]),
                    reference_cost=float(rec["reference"]["cost"]))


def load_records(config: StudyConfig, out_dir: Path, replications: int) -> list[dict[str, Any]]:
    """Every existing record of replications 0..N-1 of every scale."""
    out = []
    for s in config.scales:
        for k in range(replications):
            p = record_file(out_dir, s, k)
            if p.exists():
                out.append(json.loads(p.read_text()))
    return out


def records_frame(records: Sequence[Mapping[str, Any]]) -> pd.DataFrame:
    """One row per replication (the CSV): outcome, both fits' status, verdict, iterations, wall
    time, cost, attitude residual and vane-bias errors, the cost and parameter differences."""
    rows = []
    for rec in records:
        row: dict[str, Any] = {"scale": rec["scale"], "replication": rec["replication"],
                               "outcome": classify_record(rec)}
        if "error" in rec:
            rows.append({**row, "error": rec["error"].splitlines()[0]})
            continue
        row |= {"noise_seed": rec["noise_seed"], "location": location(rec["dcost"]), "dcost": rec["dcost"],
                "dtheta_max_sigma": rec["dtheta_max_sigma"], "dtheta_argmax": rec["dtheta_argmax"],
                "n_compared": rec["n_compared"], "held_by_reference_only": len(rec["held_by_reference_only"]),
                "held_at_judged_values": len(rec["held_at_judged_values"]),
                "accel_bias_max_mps2": rec["accel_bias_max_mps2"],
                "gyro_bias_max_deg_s": rec["gyro_bias_max_deg_s"]}
        for who in ("judged", "reference"):
            f = rec[who]
            row |= {f"{who}_{k}": f[k] for k in ("success", "verdict", "status", "status_text", "iterations",
                                                 "wall_s", "cost", "att_rms_max_deg")}
            row[f"{who}_findings"] = "; ".join(f["findings"])
            errs = list(f["vane_bias_err_deg"].values())
            row[f"{who}_vane_err_max_deg"] = max((abs(e) for e in errs), default=math.nan)
            for key, e in f["vane_bias_err_deg"].items():
                row[f"{who}_err_{key}_deg"] = e
        row["judged_message"] = rec["judged"]["message"]
        rows.append(row)
    df = pd.DataFrame(rows)
    for col in _FRAME_COLUMNS:  # present even when no replication (or only an error) is there
        if col not in df:
            df[col] = pd.Series(dtype=object if col in ("outcome", "location", "judged_verdict",
                                                        "judged_findings", "judged_status_text") else float)
    return df


#: columns :func:`records_frame` always has
_FRAME_COLUMNS = ("scale", "replication", "outcome", "location", "dcost", "dtheta_max_sigma",
                  "judged_success", "judged_verdict", "judged_status_text", "judged_iterations",
                  "judged_wall_s", "judged_att_rms_max_deg", "judged_vane_err_max_deg", "judged_findings",
                  "reference_iterations", "reference_wall_s", "reference_att_rms_max_deg")


def scale_table(df: pd.DataFrame, scales: Sequence[float]) -> pd.DataFrame:
    """One row per scale (numbers; :func:`scale_table_text` formats them): replications, judged fits
    at the true minimum (count), success at a wrong minimum (count; must be 0), failure verdicts
    (and of them false alarms: at the true minimum), successes with warnings, below the reference,
    errors, the judged fits' median iterations and wall time (the reference fits' beside), the
    largest |cost difference| and parameter distance of the fits at the true minimum, the largest
    attitude residual rms (deg) and |vane-bias error| (deg) of the judged fits."""
    rows = []
    for s in scales:
        g = df[df["scale"] == s] if len(df) else pd.DataFrame(columns=["outcome"])
        count = {o: int((g["outcome"] == o).sum()) for o in OUTCOMES}
        at = g[g["outcome"].isin((SUCCESS_TRUE, FAILURE_TRUE))]
        ok = g[g["outcome"] != ERROR]

        def med(col: str, frame: pd.DataFrame = ok) -> float:
            return float(frame[col].median()) if len(frame) and col in frame else math.nan

        def mx(col: str, frame: pd.DataFrame = ok) -> float:
            return float(frame[col].abs().max()) if len(frame) and col in frame else math.nan

        rows.append({
            "scale": s, "reps": len(g), "at_true_min": count[SUCCESS_TRUE] + count[FAILURE_TRUE],
            "success_at_wrong": count[SUCCESS_WRONG],
            "failures": int((~ok["judged_success"].astype(bool)).sum()) if len(ok) else 0,
            "false_alarms": count[FAILURE_TRUE],
            "warned": int((ok["judged_verdict"] == "SUCCESS_WITH_WARNINGS").sum()) if len(ok) else 0,
            "below_ref": count[BELOW], "no_ref": count[NO_REFERENCE], "errors": count[ERROR],
            "it_med": med("judged_iterations"), "wall_med_s": med("judged_wall_s"),
            "ref_it_med": med("reference_iterations"), "ref_wall_med_s": med("reference_wall_s"),
            "dJ_at_min_max": mx("dcost", at), "dth_at_min_max": mx("dtheta_max_sigma", at),
            "att_rms_max_deg": mx("judged_att_rms_max_deg"),
            "vane_err_max_deg": mx("judged_vane_err_max_deg"),
        })
    return pd.DataFrame(rows)


def scale_table_text(table: pd.DataFrame) -> str:
    """:func:`scale_table` as text: the fraction at the true minimum as ``n/N (p %)``."""
    out = table.rename(columns={"success_at_wrong": "success@wrong"}).copy()
    out["scale"] = [scale_label(s) for s in out["scale"]]
    out["at_true_min"] = [f"{a}/{n} ({100.0 * a / n:.0f} %)" if n else "-"
                          for a, n in zip(table["at_true_min"], table["reps"], strict=True)]
    return _text_table(out, {"it_med": ".0f", "wall_med_s": ".2f", "ref_it_med": ".0f",
                             "ref_wall_med_s": ".2f", "dJ_at_min_max": ".2g", "dth_at_min_max": ".2g",
                             "att_rms_max_deg": ".3g", "vane_err_max_deg": ".2f"})


def _text_table(df: pd.DataFrame, spec: Mapping[str, str]) -> str:
    out = df.copy()
    for c, f in spec.items():
        if c in out:
            out[c] = [fmt(float(v), f) if isinstance(v, int | float | np.number) and not isinstance(v, bool)
                      else str(v) for v in out[c]]
    return out.to_string(index=False)


def replications_text(df: pd.DataFrame) -> str:
    """One line per replication: outcome, the judged fit's verdict, status, iterations, wall time,
    cost difference, parameter distance, attitude residual, vane-bias error; the reference's
    iterations and attitude residual."""
    if not len(df):
        return "(no replication)"
    ok = df[df["outcome"] != ERROR]
    cols = {"scale": "scale", "replication": "rep", "outcome": "outcome", "judged_verdict": "verdict",
            "judged_status_text": "status", "judged_iterations": "it", "judged_wall_s": "wall_s",
            "dcost": "dJ", "dtheta_max_sigma": "dth_sig", "judged_att_rms_max_deg": "att_deg",
            "judged_vane_err_max_deg": "vane_err_deg", "reference_iterations": "ref_it",
            "reference_att_rms_max_deg": "ref_att_deg"}
    shown = ok[[c for c in cols if c in ok]].rename(columns=cols).copy()
    shown["scale"] = [scale_label(s) for s in shown["scale"]]
    shown["verdict"] = [v if isinstance(v, str) else "-" for v in shown["verdict"]]
    text = _text_table(shown, {"wall_s": ".2f", "dJ": ".3g", "dth_sig": ".2g", "att_deg": ".3g",
                               "vane_err_deg": ".2f", "ref_att_deg": ".3g"})
    errors = df[df["outcome"] == ERROR]
    for _, r in errors.iterrows():
        text += f"\nx{scale_label(r['scale'])} r{r['replication']}: error: {r.get('error', '')}"
    return text


# ---------------------------------------------------------------------------- conclusions


def _span(values: Sequence[float], spec: str = ".2g") -> str:
    a = np.asarray([v for v in values if np.isfinite(v)], dtype=float)
    if not a.size:
        return "-"
    lo, hi = format(a.min(), spec), format(a.max(), spec)
    return lo if lo == hi else f"{lo}-{hi}"


def conclusions(df: pd.DataFrame, table: pd.DataFrame) -> str:
    """A paragraph drawn from the numbers: the fraction at the true minimum per scale against the
    target (100 %), the successes at a wrong minimum (must be 0), what a wrong minimum looks like
    (attitude residuals, vane biases), the failures (caught, false alarms), how closely the fits
    at the true minimum agree with the reference, and what the judged fits cost."""
    if not len(df):
        return "No replication has finished: nothing to conclude."
    ok = df[df["outcome"] != ERROR]
    n = len(df)
    at_n = int(ok["outcome"].isin((SUCCESS_TRUE, FAILURE_TRUE)).sum())
    per = ", ".join(f"{scale_label(r.scale)}x {r.at_true_min}/{r.reps}" for r in table.itertuples())
    missed = [f"{scale_label(r.scale)}x" for r in table.itertuples() if r.at_true_min < r.reps]
    parts = [f"From the default (zero) start {at_n} of {n} fits reached the true minimum ({per}); the target "
             f"of 100 % is {'met at every scale' if not missed else 'missed at ' + ', '.join(missed)}."]
    n_wrong = int(table["success_at_wrong"].sum())
    by_scale = ", ".join(f"{scale_label(r.scale)}x {r.success_at_wrong}" for r in table.itertuples())
    parts.append(f"Reported as success at a wrong minimum: {n_wrong} of {n} ({by_scale}); the "
                 f"requirement (0) is {'met' if not n_wrong else 'NOT met'}.")
    wrong = ok[ok["location"] == "wrong"]
    true = ok[ok["location"] == "true"]
    if len(wrong):
        texts = sorted(set(wrong["judged_status_text"]))
        parts.append(
            f"The {len(wrong)} fits at a wrong minimum (solver status: {', '.join(texts)}) lie "
            f"{_span(wrong['dcost'], '.2g')} above the reference in cost, with attitude residuals of "
            f"{_span(wrong['judged_att_rms_max_deg'])} deg rms (largest channel; at the true minimum "
            f"{_span(true['judged_att_rms_max_deg'])} deg, INS noise {INS_NOISE_DEG:.2g} deg) and the vane "
            f"biases {_span(wrong['judged_vane_err_max_deg'])} deg off the truth (the worse of the two; at "
            f"the true minimum {_span(true['judged_vane_err_max_deg'])} deg).")
        near = wrong[wrong["judged_att_rms_max_deg"] <= NEAR_ATT_RATIO * wrong["reference_att_rms_max_deg"]]
        if len(near):
            parts.append(f"{len(near)} of them left attitude residuals within {NEAR_ATT_RATIO:g}x the "
                         f"reference fit's (cost {_span(near['dcost'], '.2g')} above it, parameters "
                         f"{_span(near['dtheta_max_sigma'], '.2g')} deviations away): near the true minimum "
                         "but stopped short of it, rather than in another valley.")
    caught = ok[ok["outcome"] == FAILURE_WRONG]
    alarms = ok[ok["outcome"] == FAILURE_TRUE]
    if len(caught) or len(alarms):
        why = sorted({f for x in alarms["judged_findings"] if isinstance(x, str) for f in x.split("; ") if f})
        parts.append(f"Failure verdicts: {len(caught)} at a wrong minimum (caught), {len(alarms)} at the "
                     "true minimum (false alarms" + (f"; their findings: {', '.join(why)}" if why else "")
                     + ").")
    else:
        parts.append("No fit ended with a failure verdict.")
    warned = ok[ok["judged_verdict"] == "SUCCESS_WITH_WARNINGS"]
    if len(warned):
        why = sorted({f for x in warned["judged_findings"] if isinstance(x, str) for f in x.split("; ") if f})
        parts.append(f"{len(warned)} successes carry warnings" + (f" ({', '.join(why)})" if why else "")
                     + "; the reference fits' findings: " + (", ".join(sorted(
                         {f for x in ok["reference_findings"] if isinstance(x, str) for f in x.split("; ")
                          if f})) or "none") + ".")
    if len(true):
        d = true["dtheta_max_sigma"].to_numpy(dtype=float)
        close = int(np.sum(d <= PARAM_TOL_SIGMA))
        parts.append(
            f"The {len(true)} fits at the true minimum differ from the reference by "
            f"{_span(true['dcost'].abs(), '.1e')} in cost (tolerance {COST_TOL_NLL:g}) and {close} of them "
            f"agree with it within {PARAM_TOL_SIGMA:g} Cramer-Rao deviations in every parameter "
            f"(largest difference {_span(d, '.2g')} deviations).")
    below = ok[ok["location"] == "below"]
    if len(below):
        parts.append(f"{len(below)} fits ended below the reference's cost by "
                     f"{_span(-below['dcost'], '.2g')}: the fit from the truth stopped short of the "
                     "best minimum there (a doubt on the reference).")
    if len(ok):
        parts.append(f"A judged fit took {_span(ok['judged_iterations'], '.0f')} iterations (median "
                     f"{ok['judged_iterations'].median():.0f}) and {_span(ok['judged_wall_s'], '.2g')} s "
                     f"(median {ok['judged_wall_s'].median():.2g} s); the reference from the truth "
                     f"{ok['reference_iterations'].median():.0f} iterations, "
                     f"{ok['reference_wall_s'].median():.2g} s (medians).")
    noref = ok[ok["outcome"] == NO_REFERENCE]
    if len(noref):
        parts.append(f"{len(noref)} replications have no reference (the model cannot be evaluated at the "
                     "truth) and count as not at the true minimum.")
    errs = df[df["outcome"] == ERROR]
    if len(errs):
        parts.append(f"{len(errs)} replications raised an error (listed above) and count as not at the true "
                     "minimum.")
    return " ".join(parts)


# ---------------------------------------------------------------------------- plot


def plot(df: pd.DataFrame, scales: Sequence[float], path: Path, replications: int) -> Path:
    """Three panels against the scale (replications spread side by side): the judged fit's cost
    over the reference's (symmetric log scale, the tolerance band shaded), the parameter distance
    in Cramér-Rao deviations, the largest attitude residual rms; coloured by outcome."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.ticker import FormatStrFormatter

    fig = Figure(figsize=(14.0, 5.6), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, 3)
    ok = df[df["outcome"] != ERROR] if len(df) else df
    xs = {s: i for i, s in enumerate(scales)}
    width = 0.6

    def x_of(frame: pd.DataFrame) -> np.ndarray:
        off = (frame["replication"].to_numpy(dtype=float) + 0.5) / max(replications, 1) - 0.5
        return np.array([xs[s] for s in frame["scale"]]) + width * off

    # (axis, column, title, scale, the least range shown: a decade or more, so that ticks are labelled)
    panels = ((axes[0], "dcost", "judged cost - reference cost (neg. log-likelihood)", "symlog", None),
              (axes[1], "dtheta_max_sigma", "max |theta - theta_ref| / std_ref (Cramer-Rao)", "log",
               (1e-3, 1.0)),
              (axes[2], "judged_att_rms_max_deg", "largest attitude residual rms, deg", "log", (1e-2, 1.0)))
    for ax, col, title, scale, least in panels:
        for outcome in OUTCOMES:
            g = ok[ok["outcome"] == outcome] if len(ok) else ok
            if not len(g) or col not in g:
                continue
            y = g[col].to_numpy(dtype=float)
            if scale == "log":
                y = np.maximum(y, 1e-6)
            success = g["judged_success"].to_numpy(dtype=bool)
            ax.scatter(x_of(g)[success], y[success], color=_OUTCOME_COLOUR[outcome], marker="o", s=28)
            ax.scatter(x_of(g)[~success], y[~success], color=_OUTCOME_COLOUR[outcome], marker="x", s=36)
        if scale == "symlog":
            ax.set_yscale("symlog", linthresh=1e-3)  # linear within +-0.001, the solver's own tolerance
            ax.axhspan(-COST_TOL_NLL, COST_TOL_NLL, color="tab:green", alpha=0.12, lw=0)
        else:
            ax.set_yscale("log")
            lo, hi = ax.get_ylim()
            ax.set_ylim(min(lo, least[0]), max(hi, least[1]))
            ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
        if col == "dtheta_max_sigma":
            ax.axhline(PARAM_TOL_SIGMA, color="k", ls="--", lw=0.8)
        if col == "judged_att_rms_max_deg":
            ax.axhline(INS_NOISE_DEG, color="k", ls="--", lw=0.8)
            ax.annotate("INS attitude noise", (0.01, INS_NOISE_DEG), xycoords=("axes fraction", "data"),
                        fontsize=7, va="bottom")
        ax.set_xticks(range(len(scales)), [f"{scale_label(s)}x" for s in scales])
        ax.set_xlim(-0.6, len(scales) - 0.4)
        ax.set_xlabel("IMU biases, x typical")
        ax.set_title(title, fontsize=9)
        ax.grid(True, which="major", alpha=0.3)
    handles = [Line2D([], [], color=_OUTCOME_COLOUR[o], marker="o", ls="", label=o) for o in OUTCOMES[:-1]]
    handles += [Line2D([], [], color="0.4", marker="o", ls="", label="result says success"),
                Line2D([], [], color="0.4", marker="x", ls="", label="result says failure")]
    fig.legend(handles=handles, fontsize=8, loc="outside lower center", ncol=4)
    fig.suptitle("Robustness: fits from the default (zero) start against a fit from the truth, "
                 f"{replications} replications per scale (shaded: |dJ| <= {COST_TOL_NLL:g}, the true "
                 "minimum)", fontsize=10)
    fig.savefig(path, dpi=100)
    return path


# ---------------------------------------------------------------------------- report


def report(df: pd.DataFrame, config: StudyConfig, replications: int, command: str,
           invocations: Invocations) -> str:
    """The text file: header (command, machine, code, cost), setting, legend, tables, conclusions."""
    accel, gyro = typical_imu_biases_deg()
    table = scale_table(df, config.scales)
    flights = "; ".join(f"{'+'.join(b['configurations'])} at Mach {b['mach']}, {b['altitude_m']:g} m: "
                        f"{', '.join(b['maneuvers'])}" + (f" ({b['maneuver']})" if "maneuver" in b else "")
                        for b in config.flights)
    shss = " (SHSS split into its segments)" if any("shss" in b["maneuvers"] for b in config.flights) else ""
    lines = [
        *scaffold.header_lines(
            "Robustness: fits from the estimator's default (zero) start with the IMU biases at "
            "k x typical, judged against a fit started from the truth (the true minimum).", command, __file__,
            f"{replications} replications per scale, {len(config.scales)} scales", invocations),
        *paragraph(f"setting: {flights}{shss}; the default campaign's world: "
                   "typical errors, local_flow_truth / adc_baseline, steady wind (6, -4, 0) m/s, calm air, "
                   f"flat earth; IMU biases k x typical (accel {accel} m/s^2, gyro "
                   f"{[round(g, 3) for g in gyro]} deg/s), drawn per maneuver with std |k| x "
                   f"{IMU_SPREAD_ACCEL_MPS2:g} m/s^2 and |k| x {IMU_SPREAD_GYRO_DEG_S:g} deg/s; new noise "
                   f"every replication (seed {SEED}; replication r of every scale has the same noise and "
                   "standardised draws). Judged fit: the estimator's default options and start values. "
                   "Reference fit: the same problem (the judged fit's held parameters held at its values) "
                   "started from the truth (campaigns.truth), the start strategy off; where it held a "
                   "parameter the judged fit estimated, run again with that one held at the judged fit's "
                   "value."),
        *paragraph(f"columns: at_true_min = judged fits whose final cost is within {COST_TOL_NLL:g} "
                   "(negative log-likelihood) of the reference's; success@wrong = fits not at the true "
                   "minimum whose result says success (must be 0); failures = failure verdicts, "
                   "false_alarms = of them at the true minimum; warned = success with warnings; below_ref = "
                   "judged cost below the reference's by more than the tolerance; it_med, wall_med_s = "
                   "median iterations (as the result counts them: not a staged start's own) and wall time "
                   "(the start's included) of the judged fits (ref_: of the reference fits); "
                   "dJ_at_min_max, dth_at_min_max = largest |cost difference| and largest "
                   "max|theta - theta_ref|/std_ref (Cramer-Rao deviations of the reference, parameters "
                   f"estimated by both; {PARAM_TOL_SIGMA:g} expected at one minimum) of the fits at the true "
                   "minimum; att_rms_max_deg = largest attitude (phi, theta, psi) residual rms of any "
                   "maneuver, deg; vane_err_max_deg = largest |vane bias - truth| (b_l, b_r), deg; both over "
                   "the judged fits."),
        scale_table_text(table),
        "",
        "per replication (the judged fit; verdict '-' = the result has none, status only; dJ = judged - "
        "reference cost; dth_sig, att_deg, vane_err_deg as above):",
        replications_text(df),
        "",
        "conclusions:",
        *textwrap.wrap(conclusions(df, table), width=108),
    ]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------- command line


STUDY_SPEC = scaffold.Study(
    name=STUDY, file=__file__, sizes=SIZES, unit="scale",
    description="Robustness: IMU biases at k x typical (1, 2, 3, -3), fits from the default "
    "(zero) start judged against a fit from the truth: the fraction at the true minimum and the fits "
    "reported as success at a wrong minimum. Resumable: run the same command again.",
    workers_help="replications run at once, one process each (default: 2; 1 runs in this process)",
    size_help="full: the study; tiny: a smoke run (one 20 s pitch doublet at 3x, one replication)",
    run=lambda config, out_dir, n, workers, log: (run_study(config, out_dir, n, workers, log), None),
    analyse=lambda config, out_dir, n, _: records_frame(load_records(config, out_dir, n)),
    report=report, plot=lambda df, config, path, n: plot(df, config.scales, path, n), table=lambda df: df)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m campaigns.studies.robustness --out DIR [--results DIR] [--replications N] ...``"""
    return scaffold.main(STUDY_SPEC, argv)


if __name__ == "__main__":
    raise SystemExit(main())
