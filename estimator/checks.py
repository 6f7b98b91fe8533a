"""The checks of a fit at its estimate: the findings the solver adds to the likelihood's own.

- :func:`iteration_findings` — the start's notes, a poor quadratic model, no convergence;
- :func:`near_bounds` — estimates within :data:`NEAR_BOUND_DEVIATIONS` deviations of a bound;
- :func:`not_invertible` — a flow channel whose estimated calibration cannot be applied
  (:data:`MIN_CALIBRATION_SLOPE`);
- :func:`widened_said` — a delay near its bound whose deviation the feedback check widened is said
  by that note;
- :func:`diagnosed` — the fit-quality diagnostics (:mod:`estimator.diagnostics`) at the estimate,
  their findings first, a residual finding naming the parameters on a bound that can cause it, and
  :func:`fit_traces`, the diagnostics' inputs from an evaluation;
- :func:`residual_stats` — each channel's residual statistics, maneuver by maneuver.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from estimator.diagnostics import ChannelFit, DiagnosticOptions, ManeuverInputs, diagnose
from estimator.identifiability import maneuver_nuisance
from estimator.io.modelset import declarations_of
from estimator.model import Evaluation
from estimator.normal_equations import Structure
from estimator.problem import SENSOR_SIGNALS, STATE_PARAMS, Problem
from estimator.result import ResidualStats
from estimator.verdict import Finding, Severity

if TYPE_CHECKING:
    from estimator.gauss_newton import Iterated

#: A calibration model's slope (reading per unit flow angle) below which it cannot be applied: a
#: quarter, half the lowest the model sets allow a sensor (tejas: the nose probe's gain f5 >= 0.5);
#: below it the calibrated channel amplifies the reading's noise and errors more than 4x, and
#: Newton's inversion (estimator.calibrated) leaves the table's range (study (c): a vane table
#: segment estimated at slope 0.04, 12-16 deg, with only a poor-model warning)
MIN_CALIBRATION_SLOPE = 0.25
#: An estimated calibration parameter closer to a bound than this many of its honest deviations is
#: a warning: its interval (+-2 deviations, 95 %) reaches the bound, where the Gaussian deviation no
#: longer describes the estimate (the bound truncates it) and the data want the parameter at the edge
#: of its physical range (the filter-error demo: the airspeed delay at 0.29 s, bound 0.3 s, deviation
#: 0.034 s, 0.3 s off its truth; not flagged while it stayed 0.3 deviations inside the bound)
NEAR_BOUND_DEVIATIONS = 2.0


def iteration_findings(it: Iterated, stage_notes: list[str]) -> list[Finding]:
    """Findings of the start stages and the iterations: the start's notes, a poor quadratic model
    at the estimate, no convergence."""
    findings = [Finding("start", Severity.NOTE, "; ".join(stage_notes))] if stage_notes else []
    if it.status.converged and "at the iteration limit" in it.message:
        # accepted at the limit within a tenth of a deviation of the minimum (estimator.gauss_newton)
        findings.append(Finding(
            "crawled", Severity.NOTE,
            f"{it.message}: the iterations crawled along a weakly determined direction; the estimate "
            "is taken, as the step left is small against every deviation",
            value=float(it.step_sigma) if np.isfinite(it.step_sigma) else None))
    if it.poor:
        findings.append(Finding(
            "poor_model", Severity.WARNING,
            f"at the estimate the Gauss-Newton model is poor along {', '.join(it.poor[:6])}: it predicts a "
            f"step of {it.step_sigma:.2g} deviations, yet no step decreases the cost; the data barely "
            "determine these parameters (to first order), so their deviations are not to be trusted",
            "fix them at known values, or add channels or maneuvers that see them (e.g. a sideslip "
            "sensor for v0)", parameters=it.poor))
    if not it.status.converged:
        findings.append(Finding(
            "not_converged", Severity.FAILURE, it.message,
            "raise --max-iterations if the step was still shrinking; otherwise read the other findings: "
            "a fault in the data or a wrong minimum stops the iteration too"))
    return findings


def near_bounds(problem: Problem, theta: np.ndarray, st: Structure, state: list[str],
                 std: np.ndarray) -> list[Finding]:
    """A warning for each estimated parameter (not a maneuver's nuisance scale or offset, whose
    bound is only noted: :func:`estimator.identifiability.maneuver_nuisance`) within
    :data:`NEAR_BOUND_DEVIATIONS` deviations ``std`` (SI; the honest ones where computed) of a
    bound: one on the bound is ``on_bound``'s. Where that interval spans more than half the
    allowed range the parameter is weakly determined rather than pushed to an edge, and the
    warning says so."""
    out = []
    for i, p in enumerate(problem.parameters.parameters):
        if state[i] != "estimated" or maneuver_nuisance(p) or not (np.isfinite(std[i]) and std[i] > 0.0):
            continue
        gap = np.array([theta[i] - st.lo[i], st.hi[i] - theta[i]])
        side = int(np.argmin(gap))
        if not gap[side] < NEAR_BOUND_DEVIATIONS * std[i]:
            continue
        k = p.display_scale  # shown as the reports show it (deg, ms)
        bound = (st.lo, st.hi)[side][i] * k
        unit = "" if p.display_unit in ("", "1") else f" {p.display_unit}"
        where = (f"{p.key} = {theta[i] * k:.6g}{unit} is {gap[side] / std[i]:.1f} of its deviations "
                 f"({std[i] * k:.3g}{unit}) from its {('lower', 'upper')[side]} bound {bound:.6g}{unit}")
        if NEAR_BOUND_DEVIATIONS * std[i] > 0.25 * (st.hi[i] - st.lo[i]):  # +-2 sigma > half the range
            why = (": weakly determined, its interval of +-2 deviations spans more than half its "
                   "allowed range, so the bounds, not the data, confine it")
            advice = ("fix it at a known value, or fly maneuvers that excite it; do not read its "
                      "deviation as its accuracy")
        else:
            why = (": the data want it at the edge of its physical range, and the bound truncates "
                   "what its deviation describes")
            advice = ("read it as suspect: check the data of the channels it enters (units, signs, a "
                      "fault) or a model-structure error it may take up (in turbulence: what the wind "
                      "states take up) before using it or widening the bounds")
        out.append(Finding("near_bound", Severity.WARNING, where + why, advice, parameters=(p.key,),
                           value=float(gap[side] / std[i])))
    return out


def not_invertible(problem: Problem, evals: Evaluation, st: Structure) -> list[Finding]:
    """A failure per flow channel whose estimated calibration cannot be applied: where the model's
    slope with respect to the flow angle it measures is nearly flat (below
    :data:`MIN_CALIBRATION_SLOPE`) or has the other sign than over most of the flight, flow angles
    far apart give nearly one reading and the measurement cannot be turned back into a flow angle
    (a table estimated flat or folded between two nodes; planning study (c), light turbulence: a
    filter-error fit converged so, with only a poor-model warning)."""
    out = []
    keys = problem.parameters.keys
    for ce in evals.channels:
        if ce.slope is None or not ce.slope.size:
            continue
        ch = problem.channels[ce.channel]
        sign = 1.0 if np.median(ce.slope) >= 0.0 else -1.0
        bad = ce.slope * sign < MIN_CALIBRATION_SLOPE
        if not bad.any():
            continue
        where = []
        for b, k in enumerate(ce.mans):
            r0, r1 = int(ce.rseg[b]), int(ce.rseg[b + 1])
            hit = np.flatnonzero(bad[r0:r1])
            if hit.size:
                m = problem.maneuvers[int(k)]
                t = m.t_s[ce.rows[r0:r1][hit]]
                where.append(f"{m.id} {t[0]:.2f}-{t[-1]:.2f} s ({hit.size} samples)")
        params = tuple(dict.fromkeys(keys[i] for b in range(len(ce.mans)) for i in ce.colmap[b]
                                     if st.free[i] and problem.parameters.parameters[i].kind == "table"))
        out.append(Finding(
            "not_invertible", Severity.FAILURE,
            f"{ch.name}: its estimated calibration cannot be applied - the model's slope with respect "
            f"to {ch.measures} is {float(np.min(ce.slope * sign)):.3g} at the least (below "
            f"{MIN_CALIBRATION_SLOPE:g}, or of the wrong sign) in {int(bad.sum())} of {bad.size} "
            f"samples: {'; '.join(where[:4])}{' ...' if len(where) > 4 else ''}; there flow angles far "
            "apart give nearly one reading",
            "a table estimated flat or folded between nodes: read the fit's other findings (a poor "
            "model, turbulence), bound or regularise the table, or fly maneuvers that cover that "
            "range of the flow angle",
            channel=ch.name, parameters=params[:12], value=float(np.min(ce.slope * sign))))
    return out


def widened_said(findings: list[Finding], widened: set[str]) -> list[Finding]:
    """A delay near its bound whose honest deviation the filter-error method's feedback check widened
    (``widened``: their keys; said by ``delay_feedback`` or ``delay_weak_instrument``) is said by
    that note: its near-bound finding becomes a note too (the demo's turbulent block: the airspeed
    delay 291 ms, widened to 5.2 s). A delay the check could not judge keeps its warning."""
    return [replace(f, severity=Severity.NOTE, advice="",
                    message=f"{f.message}; its honest deviation is the feedback check's widened one "
                    "(delay_feedback, delay_weak_instrument)")
            if f.code == "near_bound" and f.parameters and set(f.parameters) <= widened else f
            for f in findings]


def diagnosed(problem: Problem, evals: Evaluation, st: Structure, state: list[str], findings: list[Finding],
               y: list[np.ndarray] | None = None) -> tuple[list[Finding], object, dict]:
    """The fit-quality diagnostics at the estimate: their findings before ``findings``, the table
    and the outliers found (``y``: :func:`fit_traces`)."""
    ps = problem.parameters
    diagnosis = diagnose(*fit_traces(problem, evals, st, y), DiagnosticOptions(g_mps2=problem.g_mps2))
    # the data's findings first: a fault in the data explains the parameters' findings, not the
    # other way round (findings are shown by severity, in this order within one)
    # parameters on a bound that can cause a residual finding rather than follow from it: a
    # channel's time delays, and the state equations' (IMU biases, initial conditions) of the
    # finding's maneuver. Not tables or scales: gusts push those onto their bounds themselves.
    on_bound: dict[str, list[str]] = {}
    for i, s in enumerate(state):
        p = ps.parameters[i]
        if s == "on_bound" and p.name in STATE_PARAMS:
            on_bound.setdefault(p.instance, []).append(p.key)
        elif s == "on_bound" and p.kind == "time_delay":
            on_bound.setdefault("*", []).append(p.key)
    calib_on_bound = {ps.parameters[i].key for i, s in enumerate(state)
                      if s == "on_bound" and ps.parameters[i].kind in ("bias", "scale", "table")}
    beyond = _beyond_usable_alpha(problem, diagnosis.usable_alpha_deg)
    findings = ([_beside_bounds(f, on_bound, calib_on_bound) for f in diagnosis.findings]
                + [_bound_beyond_usable(f, beyond) for f in findings])
    return findings, diagnosis.table, dict(diagnosis.outliers)


def _beyond_usable_alpha(problem: Problem, usable_alpha_deg: Mapping[str, float]) -> dict[str, str]:
    """Table values beyond the usable alpha range of the channels that use them: key -> the channel.

    A table of the angle of attack entered only by ``low_alpha_only`` channels (the nose probe's
    sideslip gain) whose node and the node below it lie at or above the usable angle of attack the
    diagnostics found for them (a node shapes the table from the one below) is not part of the
    calibration Table 2 vouches for (paper Fig. 7: the nose probe is not modelled there), so a
    bound it sits on is information."""
    users: dict[str, set[str]] = {}
    for ch in problem.channels:
        for t in ch.expression.tables:
            # only a table of the angle of attack: the usable range is one of alpha
            arg = re.search(rf"\b{re.escape(t)}\(\s*([A-Za-z_]\w*)", ch.model)
            if arg is not None and arg.group(1).startswith("alpha"):
                users.setdefault(t, set()).add(ch.name)
    out = {}
    for p in problem.parameters.parameters:
        if p.kind != "table" or p.name not in users:
            continue
        chans = users[p.name]
        if not all(c in usable_alpha_deg for c in chans):
            continue
        spec = problem.parameters.specs[p.name]
        node = -1 if p.element is None else int(p.element)
        bps = np.asarray(spec.breakpoints, dtype=float)
        # a piecewise-linear table's node shapes it from the node below: beyond the usable range
        # only where that one already is
        if 0 < node < bps.size and math.degrees(bps[node - 1]) >= min(usable_alpha_deg[c] for c in chans):
            out[p.key] = sorted(chans)[0]
    return out


def _bound_beyond_usable(f: Finding, beyond: Mapping[str, str]) -> Finding:
    """An estimate on or near its bound that is a table value beyond its channel's usable alpha
    range (:func:`_beyond_usable_alpha`): a NOTE that says so."""
    if f.code not in ("on_bound", "near_bound") or f.severity < Severity.WARNING or not f.parameters:
        return f
    if not all(k in beyond for k in f.parameters):
        return f
    ch = beyond[f.parameters[0]]
    return replace(f, severity=Severity.NOTE, advice="",
                   message=f"{f.message}; it lies beyond {ch}'s usable alpha range (paper Fig. 7), "
                   "outside the calibration Table 2 vouches for")


#: Residual patterns a parameter stopped at its bound produces as well as the data's own faults.
_BOUND_MIMICS = frozenset({"turbulence", "misfit", "scale_error", "noise_floor", "coloured"})


def _beside_bounds(f: Finding, on_bound: dict[str, list[str]],
                   calib_on_bound: frozenset[str] | set[str] = frozenset()) -> Finding:
    """A residual finding whose channels' parameters sit on a bound names them as a possible cause.

    A parameter the data push beyond its bound leaves exactly the residual it could not absorb: flow
    delays of 400 ms against bounds of +-300 ms leave coloured flow residuals common to every sensor,
    which read as turbulence; IMU biases beyond theirs leave kinematic misfits (planning study (c)).
    The finding says the bound may be the cause, and to widen it before blaming the air or the
    sensor. Two become failures, the fit held away from the data by its bounds: a kinematic misfit
    in a maneuver whose state-equation parameters (IMU biases, initial conditions) sit on a bound,
    and a flow channel's residual beyond its desired accuracy with one of its own calibration
    parameters (bias, scale, table) on a bound (the model cannot represent the sensor within its
    physical range: the real UAV flight's five-hole probe, its scale factors on -0.5). ``on_bound``:
    maneuver id -> its state-equation parameters on a bound, ``"*"`` -> the time delays on a bound;
    ``calib_on_bound``: the calibration parameters on a bound.
    """
    calib = [k for k in f.parameters if k in calib_on_bound]
    if f.code == "noise_floor" and f.severity >= Severity.WARNING and calib:
        names = ", ".join(calib[:6])
        f = replace(
            f, severity=Severity.FAILURE,
            message=f"{f.message}; with {names} on {'their bounds' if len(calib) > 1 else 'its bound'}: "
            "the calibration model cannot represent this sensor within its physical range",
            advice=f"do not use this channel's calibration: check its data (units, sign, the sensor's "
            f"position and what it measures) and the model set's model for it; widen the bounds of {names} "
            "only if they are narrower than the sensor's physics")
    state = list(on_bound.get(f.maneuver or "", ()))
    hit = [k for k in f.parameters if k in on_bound.get("*", ())] + state
    if f.code not in _BOUND_MIMICS or not hit:
        return f
    if f.code == "misfit" and state and f.severity < Severity.FAILURE:
        # not the slow errors of real data: the state equations could not follow the data
        f = replace(f, severity=Severity.FAILURE, message=f.message.split(": slow, coloured errors")[0]
                    + ": the fit does not explain this kinematic channel, whose model is exact kinematics",
                    advice="read the other findings first (a data fault drags the fit); otherwise start from "
                    "better values (IMU biases, initial conditions) and check this channel's data")
    names = ", ".join(hit)
    return replace(
        f, message=f"{f.message}; or the bound{'s' if len(hit) > 1 else ''} of {names}, where "
        + ("the estimates stopped: the data push them beyond" if len(hit) > 1 else
           "the estimate stopped: the data push it beyond"),
        advice=f"if the range of {names} in the problem file is too narrow for this installation, widen "
        f"the bounds of {names} and estimate again (a delay or IMU bias beyond its bound leaves this "
        f"pattern too); if it stays: {f.advice}")


def fit_traces(problem: Problem, ev: Evaluation, st: Structure, y: list[np.ndarray] | None = None):
    """The diagnostics' inputs: every channel of every maneuver at the estimate, and each
    maneuver's IMU inputs and reconstructed states (``y``: per channel, what to judge the
    measurements against instead of the model output; the filter-error method's predictions)."""
    ps = problem.parameters
    keys = ps.keys
    requirements = declarations_of(problem).requirements
    fits = []
    for ce_i, ce in enumerate(ev.channels):
        ch = problem.channels[ce.channel]
        req = requirements.get(ch.name)
        for b, k in enumerate(ce.mans):
            m = problem.maneuvers[int(k)]
            r0, r1 = ce.rseg[b], ce.rseg[b + 1]
            rows = ce.rows[r0:r1]
            meas = np.asarray(m.measurements[ch.column], dtype=float)
            fin = np.isfinite(meas)
            # the channel model's own free parameters (not the state equations')
            params = tuple(dict.fromkeys(keys[i] for i in ce.colmap[b]
                                         if st.free[i] and ps.parameters[i].name not in STATE_PARAMS))
            fits.append(ChannelFit(
                maneuver=m.id, channel=ch.name, flow=bool(ch.expression.names & SENSOR_SIGNALS),
                t_s=m.t_s[rows],
                z=ce.z[r0:r1], y=(ce.y if y is None else y[ce_i])[r0:r1], measured_t_s=m.t_s[fin],
                measured=meas[fin], unit=ch.unit,
                display_scale=ch.display_scale, display_unit=ch.display_unit, parameters=params,
                desired_3sigma=None if req is None else math.radians(req.desired_deg),
                low_alpha_only=bool(req is not None and req.low_alpha_only)))
    pos = {int(k): i for i, k in enumerate(ev.maneuvers)}
    col = {c.name: c.column for c in problem.channels}
    inputs = []
    for k, m in enumerate(problem.maneuvers):
        if k not in pos:
            continue
        X = ev.X[ev.seg[pos[k]]:ev.seg[pos[k] + 1]]
        eul = np.full((m.n, 3), np.nan)
        for j, name in enumerate(("phi", "theta", "psi")):
            c = col.get(name)
            if c is not None and c in m.measurements:
                eul[:, j] = m.measurements[c]
        inputs.append(ManeuverInputs(maneuver=m.id, t_s=m.t_s, accel_imu_mps2=m.accel_imu_mps2,
                                     omega_rps=m.omega_rps, states=X, euler_measured_rad=eul))
    return fits, inputs


def residual_stats(problem: Problem, ev: Evaluation) -> tuple[ResidualStats, ...]:
    """Each channel's residual statistics at ``ev``, maneuver by maneuver (the result's
    ``residuals``)."""
    blocks = []
    for ce in ev.channels:
        e = ce.e
        for b, k in enumerate(ce.mans):
            blocks.append((int(k), ce.channel, e[ce.rseg[b]:ce.rseg[b + 1]]))
    out = []
    for k, c, e in sorted(blocks, key=lambda x: (x[0], x[1])):  # maneuver by maneuver
        out.append(ResidualStats(
            maneuver=problem.maneuvers[k].id, channel=problem.channels[c].name, n=int(e.size),
            mean=float(e.mean()), std=float(e.std()), rms=float(np.sqrt(np.mean(e * e))),
        ))
    return tuple(out)
