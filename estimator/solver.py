r"""Maximum-likelihood output-error estimation for many maneuvers at once: :func:`estimate`.

Cost (Jategaonkar 2006, §4.3), residuals ``e = z - y`` of channel ``c`` at sample ``i``::

    J(theta, R) = 1/2 sum_c sum_i e_ci^2 / R_c + 1/2 sum_c N_c ln R_c

``R`` (diagonal, one variance per channel) is estimated in closed form from the residuals between
Gauss-Newton steps (relaxation strategy, §4.10); the Gauss-Newton steps solve the normal equations
in their arrow structure (:mod:`estimator.normal_equations`), Levenberg-Marquardt-damped, bounds
as an active set.

Convergence is judged on the *undamped* Gauss-Newton step ``M^-1 g`` (bounds active), never on a
step the damping shrank: converged when it is below ``step_tol_sigma`` Cramér-Rao deviations for
every parameter, or when the decrease it predicts, ``g^T M^-1 g / 2`` (log-likelihood units), is
below ``decrease_tol``, or when no step achieves more than ``decrease_tol`` (then along the
undamped direction too; a poor quadratic model there is reported). Status codes follow scipy's
convention (:class:`~estimator.verdict.Status`: positive = converged). A converged minimum may
still be wrong: the verdict (:mod:`estimator.verdict`) also weighs the fit-quality diagnostics
(:mod:`estimator.diagnostics`: residuals against each channel's own noise floor, stuck channels,
unit errors, outliers, turbulence) and the identifiability checks.

Start: by default a staged, data-driven start (:mod:`estimator.start`) fits the attitude, then
speed and height, then the flow channels before the full estimation, so that large IMU biases
from zero start values reach the right minimum.

Identifiability is judged where it matters, at the solution (and, for what needs no residuals,
before the iterations): parameters no sample depends on (a table breakpoint beyond the flown
range) and combinations the data cannot separate (a free table offset beside free biases: one
member of each such set is held, the fewest that restore the rank) are held at their start
values; at the solution, a parameter whose Cramér-Rao deviation exceeds half its allowed range is
held too, and the estimation iterates again. So it does where a round crawled to the iteration
limit and the screen there holds a parameter it left free (a gain whose argument the iterations
drove to zero, e.g. a sideslip gain in maneuvers without sideslip: Gauss-Newton crawls along the
curved valley of the product); otherwise the iteration limit stays a failure. Each held parameter
keeps its reason (:attr:`EstimationResult.state`).

Standard deviations: Cramér-Rao, ``sqrt(diag(M^-1))``, with the correlations; and the honest ones
(:mod:`estimator.uncertainty`): coloured and cross-correlated residuals with a modelled spectrum,
and the IMU's noise as process noise.

Where each part lives: this module orchestrates (starts, screening rounds, robust pass, result);
the iterations are :mod:`estimator.gauss_newton`, the identifiability screen, covariance and parameter
states :mod:`estimator.identifiability`, the deviations :mod:`estimator.uncertainty`.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Mapping
from dataclasses import replace
from functools import partial

import numpy as np
from threadpoolctl import threadpool_limits

from estimator.filter_error import FilterErrorLikelihood, feedback_findings
from estimator.gauss_newton import Iterated, gauss_newton, staged_start
from estimator.identifiability import (
    covariance,
    crosswind_findings,
    high_correlations,
    maneuver_nuisance,
    parameter_findings,
    parameter_states,
    screen,
)
from estimator.io.modelset import declarations_of
from estimator.likelihood import OutputErrorLikelihood, evaluate
from estimator.model import Evaluation, Model, ModelEvaluationError
from estimator.normal_equations import Structure, build_normal, channel_variances, ml_cost, residual_sums
from estimator.options import SolverOptions
from estimator.parameters import FLIGHT_KINDS
from estimator.problem import SENSOR_SIGNALS, STATE_PARAMS, Problem
from estimator.result import EstimationResult, ResidualStats
from estimator.uncertainty import deviations, imu_noise_note, imu_noise_unknown
from estimator.verdict import Finding, Severity, Status, judge

#: Output-error iterations at most before the filter-error method's turbulence diagnosis.
PREFIT_ITERATIONS = 10
#: Filter-error iterations at most before the maneuvers without wind states are diagnosed again.
PROBE_ITERATIONS = 5
#: Fresh linearisations at most once the filter-error noise statistics are held.
REFRESH_ROUNDS = 3
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


def estimate(problem: Problem, options: SolverOptions | None = None) -> EstimationResult:
    """Estimate the free parameters of ``problem`` by maximum likelihood (output error).

    Parameters
    ----------
    problem : the problem (data, channel models, parameters with start values).
    options : solver settings.

    Returns
    -------
    EstimationResult with estimates, Cramér-Rao and coloured-residual deviations, correlations,
    residual statistics, the solver status, the fit-quality findings and the verdict.

    Raises
    ------
    ValueError
        For a problem that cannot be estimated as asked: no free parameter, or no channel with data
        (the message says which and how to fix it). Everything that goes wrong in the estimation
        itself — the model leaving its domain, nothing determined, no convergence, a fault in the
        data — is a result with a failure verdict, not an exception.

    Notes
    -----
    Runs with one BLAS thread (restored on return): every matrix here is small, and waking
    OpenBLAS's worker threads for each of them costs more than the arithmetic.
    """
    opt = options or SolverOptions()
    starts = (opt.start,) if isinstance(opt.start, str) else tuple(dict.fromkeys(opt.start))
    with threadpool_limits(limits=1, user_api="blas"):
        best: EstimationResult | None = None
        tried = []
        for s in starts:
            res = _estimate_robust(problem, replace(opt, start=s))
            tried.append(f"{s}: {res.verdict.name.lower()}, cost {_final_cost(res):.6g}")
            if best is None or _rank(res) < _rank(best):
                best = res
        assert best is not None
        if len(starts) > 1:
            best = best.with_findings((Finding(
                "starts", Severity.NOTE,
                f"estimated from {len(starts)} starts ({'; '.join(tried)}); the best verdict, then the "
                "lowest cost, is kept"),))
        return best


def _final_cost(res: EstimationResult) -> float:
    return res.cost_history[-1] if res.cost_history else np.inf


def _rank(res: EstimationResult) -> tuple[int, float]:
    return res.verdict.rank, _final_cost(res)


def _estimate_guarded(problem: Problem, opt: SolverOptions) -> EstimationResult:
    """:func:`_estimate`, with a numerical breakdown (the model leaving its domain, a singular
    matrix) turned into a failed result: a verdict, not an exception, for data that cause it."""
    t0 = time.perf_counter()
    try:
        return _estimate(problem, opt)
    except (ModelEvaluationError, np.linalg.LinAlgError) as exc:
        return _failed(problem, problem.parameters.values, t0,
                       f"the estimation broke down numerically: {type(exc).__name__}: {exc}",
                       "read the channel named; check its data and units, or start closer to the data")


def _estimate_robust(problem: Problem, opt: SolverOptions) -> EstimationResult:
    """:func:`_estimate`, and with ``opt.robust`` once more without the outliers it found."""
    res = _estimate_guarded(problem, opt)
    if not opt.robust or not res.outliers:
        return res
    excluded = dict(res.outliers)
    sub = _without_samples(problem, excluded)
    sub = replace(sub, parameters=sub.parameters.with_values(res.values))
    again = _estimate_guarded(sub, replace(opt, start="given"))
    notes = tuple(Finding(
        "excluded", Severity.NOTE,
        f"robust option: {t.size} outlier sample(s) of {ch} in maneuver {man} excluded from the fit "
        f"(at t = {', '.join(f'{v:.3f}' for v in t[:5])}{' ...' if t.size > 5 else ''} s)",
        channel=ch, maneuver=man, t_s=tuple(float(v) for v in t)) for (man, ch), t in excluded.items())
    return again.with_findings(notes, iterations=res.iterations)


def _without_samples(problem: Problem, samples: dict[tuple[str, str], np.ndarray]) -> Problem:
    """The problem with some samples of some channels removed (NaN: not in the cost)."""
    col = {c.name: c.column for c in problem.channels}
    mans = []
    for m in problem.maneuvers:
        meas = dict(m.measurements)
        for (man, ch), t in samples.items():
            if man != m.id or col.get(ch) not in meas:
                continue
            v = np.array(meas[col[ch]], dtype=float)
            idx = np.searchsorted(m.t_s, t)
            idx = idx[(idx < m.t_s.size)]
            idx = idx[np.isclose(m.t_s[idx], t[: idx.size], atol=1e-9 + 1e-6 * m.dt_s)]
            v[idx] = np.nan
            meas[col[ch]] = v
        mans.append(replace(m, measurements=meas))
    return replace(problem, maneuvers=tuple(mans))


def _estimate(problem: Problem, opt: SolverOptions) -> EstimationResult:
    t0 = time.perf_counter()
    model = Model(problem)
    ps = problem.parameters
    nch = len(problem.channels)
    requested = ps.free_mask
    if not requested.any():
        raise ValueError(f"{problem.source}: no free parameters; free some in the problem file")
    lo = np.array([p.bounds[0] for p in ps])
    hi = np.array([p.bounds[1] for p in ps])
    start = np.clip(ps.values, lo, hi)
    theta = start.copy()
    try:
        evals = evaluate(model, theta, True)
    except ModelEvaluationError as exc:
        return _failed(problem, start, t0, f"the model cannot be evaluated at the start values: {exc}",
                       "check the units and signs of the channel named (a measurement far outside its "
                       "model's range cannot be fitted), or give start values closer to the data")
    sse, cnt = residual_sums(evals, nch)
    if not cnt.any():
        raise ValueError(f"{problem.source}: no channel has data in any maneuver")
    stage_notes: list[str] = []
    if opt.start == "staged":
        staged, stage_notes = staged_start(problem, theta, requested, opt)
        try:
            # the stages fit subsets of the channels: an implicit channel left out may be outside
            # its domain where they ended; then the full estimation starts from the given values
            evals = evaluate(model, staged, True)
            theta = staged
        except ModelEvaluationError as exc:
            stage_notes.append(f"the staged start is left: the full model cannot be evaluated where it "
                               f"ended ({exc}); the estimation starts from the given values")
        sse, cnt = residual_sums(evals, nch)
    # the screen before the iterations also holds what looks undetermined there, which keeps a
    # parameter the data hardly see from wandering to a bound on the way; the screen at the
    # solution judges every requested parameter again, and frees what the data determine there
    st, holds = screen(problem, Structure(problem, requested), evals, channel_variances(sse, cnt), opt,
                        loose=True)
    if not st.free.any():
        return _failed(problem, theta, t0, "no free parameter is determined by the data: "
                       + "; ".join(f"{h.kind}: {', '.join(h.confounding.parameters[:12])}" for h in holds),
                       "fly maneuvers that excite the parameters asked for, or fix them in the problem file",
                       Status.UNDETERMINED)
    held = requested & ~st.free
    stage_notes += _restore_held(model, theta, start, held)
    iterations, history = 0, []
    if opt.method == "filter_error":
        theta, turbulent, n_oem = _turbulent_maneuvers(problem, model, theta, st, opt)
        lik = FilterErrorLikelihood(model, opt.wind, turbulent)
        iterations += n_oem
        if turbulent is not None:
            stage_notes.append(
                f"filter-error method: the output-error fit first ({n_oem} iterations); the "
                f"diagnostics found turbulence in {len(turbulent)} of {len(problem.maneuvers)} "
                "maneuvers, which get wind states; "
                + ("the filter-error iterations start where that fit started" if turbulent else
                   "without them the method is output error, which goes on from that fit"))
    else:
        lik = OutputErrorLikelihood(model)
    evals = lik.evaluate(theta, True)
    if isinstance(lik, FilterErrorLikelihood) and lik.windy.any() and not lik.windy.all():
        # a few filter-error iterations, then the maneuvers without wind states whose innovations
        # are turbulent get them too (at once, not at the solution: 70 maneuvers, 4 missed by the
        # output-error fit, 18 filter-error iterations to a solution, 7 more after widening)
        try:
            probe = gauss_newton(model, theta, st, replace(
                opt, max_iterations=min(opt.max_iterations, PROBE_ITERATIONS)), evals, lik=lik)
        except ModelEvaluationError as exc:  # as below: a safeguard
            return _failed(problem, theta, t0, str(exc), "report this as a bug, with the data")
        theta, evals = probe.theta, probe.evals
        iterations += probe.iterations
        history += probe.history
        lik, evals, missed = _widened(problem, st, theta, evals, lik)
        if missed:
            stage_notes.append(_missed_note(missed, f"after {probe.iterations} filter-error iterations"))
    sol_held, sol_holds = np.zeros_like(requested), []  # what screens at a solution held
    for rnd in range(1, max(opt.screen_rounds, 1) + 1):
        try:
            it = gauss_newton(model, theta, st, opt, evals, lik=lik)
        except ModelEvaluationError as exc:  # cannot happen after a successful start: a safeguard
            return _failed(problem, theta, t0, str(exc), "report this as a bug, with the data")
        theta, evals = it.theta, it.evals
        iterations += it.iterations
        history += it.history
        crawled = it.status == Status.ITERATION_LIMIT
        if not (it.status.converged or crawled) or rnd == opt.screen_rounds:
            break
        # identifiability at the solution: the whole screen again, from the requested free set
        # less what a screen at an earlier solution held (judged again where the estimation went
        # without it, a parameter can look determined, a bilinear term's sensitivity moving with
        # its partner, be freed, and the last round would estimate it unscreened: study (c)'s
        # calm r4, the vanes' sideslip reference offset held, freed, then on its bound). The
        # filter-error method judges by its own information: its wind states take some of what
        # the output-error residuals show
        base = Structure(problem, requested & ~sol_held)
        fem_normal = None
        if isinstance(lik, FilterErrorLikelihood) and lik.noise is not None:
            # filtered once for the screen's widest structure; each pass takes its sub-blocks
            fem_normal = partial(lik.normal_of, blocks=lik.normal_blocks(base, evals, lik.noise))
        st_new, holds_new = screen(problem, base, evals, channel_variances(it.sse, it.cnt), opt,
                                    loose=True, normal=fem_normal)
        holds_new = sol_holds + holds_new
        if it.status.converged:  # a solution: its holds stay (not a round that crawled)
            sol_held, sol_holds = requested & ~st_new.free, holds_new
        if crawled and not (st.free & ~st_new.free).any():
            # the iteration limit stays a failure unless what the round crawled along is held now
            break
        if np.array_equal(st_new.free, st.free):
            holds = holds_new
            break
        # a round that crawled to the iteration limit along a direction the screen now holds (a
        # bilinear gain whose argument the iterations drove to zero: f(alpha) * (beta + b) in
        # maneuvers without sideslip, where the start's sideslip made the gain look determined)
        # iterates again without it; the next round must converge on its own
        if crawled:
            keys = problem.parameters.keys
            stage_notes.append(
                f"round {rnd} reached the iteration limit ({it.message}); the identifiability screen "
                f"there holds {', '.join(keys[i] for i in np.flatnonzero(st.free & ~st_new.free))}, "
                "which the data do not determine: estimated again without them")
        stage_notes += _restore_held(model, theta, start, st.free & ~st_new.free)
        st, holds = st_new, holds_new
        evals = lik.evaluate(theta, True)
    # the noise held for good: its linearisation (the wind sensitivities) is the one of the 6th
    # relaxation; iterate again on fresh ones until they no longer move the estimate
    refresh_move = None
    if isinstance(lik, FilterErrorLikelihood) and lik.held and it.status.converged:
        for _ in range(REFRESH_ROUNDS):
            lik.refresh(evals)
            before = theta
            try:
                it = gauss_newton(model, theta, st, opt, lik.evaluate(theta, True), lik=lik)
            except ModelEvaluationError as exc:  # as above: a safeguard
                return _failed(problem, theta, t0, str(exc), "report this as a bug, with the data")
            theta, evals = it.theta, it.evals
            iterations += it.iterations
            history += it.history
            refresh_move = theta - before
            if it.iterations <= 1 or not it.status.converged:
                break
    # a safety net: the check after the first filter-error iterations (above) can miss a maneuver
    missed = frozenset()
    if it.status.converged or it.status == Status.ITERATION_LIMIT:
        lik, evals, missed = _widened(problem, st, theta, evals, lik)
    if missed:
        try:
            it = gauss_newton(model, theta, st, opt, evals, lik=lik)
        except ModelEvaluationError as exc:  # as above: a safeguard
            return _failed(problem, theta, t0, str(exc), "report this as a bug, with the data")
        theta, evals = it.theta, it.evals
        iterations += it.iterations
        history += it.history
        stage_notes.append(_missed_note(missed, "at its solution") + f" ({it.iterations} iterations)")
    return _finish(problem, model, theta, start, st, holds, evals, it, iterations, history, stage_notes,
                   opt, t0, lik, refresh_move)


def _widened(problem: Problem, st: Structure, theta: np.ndarray, evals: Evaluation, lik):
    """``(lik, evals, missed)``: the likelihood with wind states also in the maneuvers without them
    whose innovations (their residuals) the diagnostics call turbulent at ``evals``, the
    evaluation for it and those maneuvers (unchanged, and empty, for the output-error method,
    ``wind.where = "all"`` or none missed). The output-error fit that chose the maneuvers can
    miss some: the estimator benchmark's 70 turbulent maneuvers, 4 (their turbulence findings
    then failed the verdict)."""
    if not isinstance(lik, FilterErrorLikelihood) or lik.windy.all():
        return lik, evals, frozenset()
    from estimator.diagnostics import DiagnosticOptions, diagnose

    noise = lik.relax(evals, lik.stats(evals))
    diagnosis = diagnose(*_fit_traces(problem, evals, st, lik.predictions(evals, noise)),
                         DiagnosticOptions(g_mps2=problem.g_mps2, turbulence_spread=math.inf))
    ids = [m.id for m in problem.maneuvers]
    quiet = {i for i, w in zip(ids, lik.windy, strict=True) if not w}
    missed = frozenset(f.maneuver for f in diagnosis.findings
                       if f.code == "turbulence" and f.maneuver in quiet)
    if not missed:
        return lik, evals, missed
    lik = lik.widened(frozenset(i for i, w in zip(ids, lik.windy, strict=True) if w) | missed)
    return lik, lik.evaluate(theta, True), missed


def _missed_note(missed: frozenset[str], when: str) -> str:
    return (f"filter-error method: {when} the diagnostics of the innovations found turbulence in "
            f"{len(missed)} maneuver(s) without wind states ({', '.join(sorted(missed)[:8])}"
            f"{' ...' if len(missed) > 8 else ''}), which the output-error fit had not shown: given "
            "wind states")


def _turbulent_maneuvers(problem: Problem, model: Model, theta: np.ndarray, st: Structure,
                         opt: SolverOptions) -> tuple[np.ndarray, frozenset[str] | None, int]:
    """The filter-error method's start, the maneuvers that get its wind states and the
    iterations spent finding them.

    With :class:`~estimator.filter_error.WindOptions` ``where = "diagnosed"`` (the default) an
    output-error fit runs first; the maneuvers whose residuals there the diagnostics call
    turbulent get wind states (at the staged start the diagnostics missed some of the turbulent
    maneuvers: its residuals still carry what the fit removes). The filter-error iterations then
    start from ``theta``, not from that fit: in turbulence the output-error fit is drawn away
    from the filter-error minimum along directions the filter-error iterations then crawl back
    (70 turbulent maneuvers of the estimator benchmark: 38 filter-error iterations to the
    iteration limit from that fit, 10 to convergence from the staged start). Where no maneuver
    is turbulent the method is output error and goes on from that fit. ``"all"``: every
    maneuver, from ``theta``.
    """
    if opt.wind is not None and opt.wind.where == "all":
        return theta, None, 0
    from estimator.diagnostics import DiagnosticOptions, diagnose

    # the diagnostics need the residuals' pattern, not a converged fit: in turbulence the
    # output-error iterations crawl (planning study (c): 3 of 8 light-turbulence fits then started
    # the filter-error iterations from a fit stopped at the 40-iteration limit, and failed)
    it = gauss_newton(model, theta, st, replace(opt, max_iterations=min(opt.max_iterations,
                                                                         PREFIT_ITERATIONS)))
    # any spread between the sensors' residuals: the verdict's turbulence finding asks them to
    # agree within 3x (one gust moves every sensor alike), but a maneuver's gusts can be mostly
    # vertical (study (c), light: alpha 0.46 against sideslip 0.15 deg, 3.02x); left without wind
    # states, that maneuver dragged the filter-error fit to a wrong minimum (a table node 100
    # deviations off), which only the diagnostics of its innovations then caught
    diagnosis = diagnose(*_fit_traces(problem, it.evals, st),
                         DiagnosticOptions(g_mps2=problem.g_mps2, turbulence_spread=math.inf))
    turbulent = frozenset(f.maneuver for f in diagnosis.findings if f.code == "turbulence")
    start = it.theta if not turbulent and np.all(np.isfinite(it.theta)) else theta
    return start, turbulent, it.iterations


def _restore_held(model: Model, theta: np.ndarray, start: np.ndarray, held: np.ndarray) -> list[str]:
    """Put newly held parameters back at their start values (in place), unless the model cannot be
    evaluated there (an implicit model whose table the start values make steeper than 1:1 next to
    estimated neighbours): then they stay where the estimation left them, and a note says so."""
    moved = held & (theta != start)
    if not moved.any():
        return []
    trial = theta.copy()
    trial[moved] = start[moved]
    try:
        evaluate(model, trial, False)
    except ModelEvaluationError as exc:
        keys = model.problem.parameters.keys
        return [f"{', '.join(keys[i] for i in np.flatnonzero(moved))} held at the values the estimation "
                f"had reached, not at their start values: the model cannot be evaluated there ({exc})"]
    theta[moved] = start[moved]
    return []


def _failed(problem: Problem, theta: np.ndarray, t0: float, why: str, advice: str,
            status: Status = Status.MODEL_ERROR) -> EstimationResult:
    """A result for an estimation that could not run (the model fails, nothing is determined)."""
    n = len(problem.parameters)
    nan = np.full(n, np.nan)
    requested = problem.parameters.free_mask
    return EstimationResult.build(
        problem=problem, values=theta, std_crb=nan, std_colored=nan, correlation_keys=(),
        correlation=np.zeros((0, 0)), R={}, residuals=(), iterations=0, cost_history=(),
        status=status, message=why, confounding=(), elapsed_s=time.perf_counter() - t0,
        free_estimated=np.zeros(n, dtype=bool),
        state=tuple("fixed" if not f else "not estimated" for f in requested),
        state_reason=tuple("" if not f else "the estimation failed" for f in requested),
        findings=(Finding(status.name.lower(), Severity.FAILURE, why, advice),),
    )


def _finish(problem, model, theta, start, st, holds, evals, it, iterations, history, stage_notes, opt, t0,
            lik=None, refresh_move=None) -> EstimationResult:
    """Covariances, diagnostics, findings and verdict at the estimate (``refresh_move``: how far
    the filter-error method's last fresh linearisation moved it, SI)."""
    ps = problem.parameters
    keys = ps.keys
    filter_error = isinstance(lik, FilterErrorLikelihood)
    wind_findings: list[Finding] = []
    wind = wind_model = None
    if filter_error:
        noise = lik.relax(evals, lik.stats(evals))
        R = noise.R
        history = history + [lik.cost(evals, noise)]
        N = lik.normal(st, evals, noise)
        wind_findings = (lik.findings(noise, opt.colored, lik.noise_drift(evals) if lik.held else None)
                         + lik.answer_findings(evals, noise))
        wind = lik.wind_table(evals, noise)
        wind_model = lik.wind_model(noise)  # what Table 2 reruns the smoother with
    else:
        R = channel_variances(it.sse, it.cnt)
        history = history + [ml_cost(it.sse, it.cnt, R)]
        N = build_normal(st, evals, R)
    cov = covariance(N, st, problem, opt)
    unident, correlated = cov.unident, cov.correlated
    # the filter-error method's honest deviations: the coloured innovations' and the IMU noise
    dev = deviations(model, theta, N, st, R, cov, replace(opt, colored=False) if filter_error else opt)
    widened: set[str] = set()
    if filter_error and opt.colored:
        dev = lik.honest_deviations(st, evals, noise, N, dev, opt, theta)
        # the feedback check widens the delays the aircraft's answer to the gusts biases: where it
        # widened every delay an answer finding names, what it says is in the honest deviations,
        # information (a NOTE); a delay it could not judge keeps the warning
        widened = {keys[f.parameter] for f in dev.feedback if math.isfinite(f.std_after_s)}
        wind_findings = [replace(f, severity=Severity.NOTE)
                         if f.code == "gust_answer" and f.parameters and set(f.parameters) <= widened else f
                         for f in wind_findings]
        wind_findings = wind_findings + feedback_findings(lik.model.problem.parameters.parameters,
                                                          dev.feedback)
    correlated = correlated + high_correlations(dev.correlation, [keys[i] for i in st.glob],
                                                 opt.correlation_warn)
    # a set still unidentifiable here (the screen's rounds ran out) is reported with the holds
    confounding = [h.confounding for h in holds] + [conf for conf, _ in unident] + correlated
    # what each parameter is: estimated, on a bound, held (why) or fixed
    state, reason = parameter_states(problem, theta, start, st, holds, dev.unresolved, unident, opt)
    # which maneuvers inform each global parameter (its coupling block with their locals)
    informs = {keys[g]: {problem.maneuvers[k].id for k in range(len(problem.maneuvers))
                         if N.HGL[k].shape[1] and np.any(N.HGL[k][j] != 0.0)}
               for j, g in enumerate(st.glob)}
    findings = (imu_noise_unknown(dev.imu_psd)
                + parameter_findings(problem, holds, unident, correlated, state, reason, opt, informs)
                + crosswind_findings(problem, evals, st, informs)
                + imu_noise_note(dev, st, keys, opt) + _iteration_findings(it, stage_notes)
                + _near_bounds(problem, theta, st, state,
                               np.where(np.isfinite(dev.std_colored), dev.std_colored, dev.std_crb))
                + wind_findings + _unsettled(refresh_move, dev.std_crb, problem, dev.std_colored)
                + _not_invertible(problem, evals, st))
    findings = _widened_said(findings, widened)
    diagnosis_table, outliers = None, {}
    if opt.diagnose:
        # the filter-error method's measurements against its one-step predictions: the innovations
        findings, diagnosis_table, outliers = _diagnosed(
            problem, evals, st, state, findings, lik.predictions(evals, noise) if filter_error else None)
    verdict = judge(it.status, findings)
    message = it.message
    return EstimationResult.build(
        std_imu_noise=dev.std_imu, imu_noise_psd=dev.imu_psd,
        problem=problem, values=theta, std_crb=dev.std_crb, std_colored=dev.std_colored,
        correlation_keys=tuple(keys[i] for i in st.glob), correlation=dev.correlation,
        correlation_colored=dev.correlation_colored,
        R=dict(zip((c.name for c in problem.channels), R, strict=True)),
        residuals=_stats(problem, evals), iterations=iterations, cost_history=tuple(history),
        status=it.status, message=message, confounding=tuple(confounding),
        elapsed_s=time.perf_counter() - t0, free_estimated=st.free.copy(), state=tuple(state),
        state_reason=tuple(reason), findings=tuple(findings), verdict=verdict,
        fit_quality=diagnosis_table, outliers=outliers, wind=wind, wind_model=wind_model,
    )


def _not_invertible(problem: Problem, evals: Evaluation, st: Structure) -> list[Finding]:
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


def _near_bounds(problem: Problem, theta: np.ndarray, st: Structure, state: list[str],
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


def _widened_said(findings: list[Finding], widened: set[str]) -> list[Finding]:
    """A delay near its bound whose honest deviation the filter-error method's feedback check widened
    (``widened``: their keys; said by ``delay_feedback`` or ``delay_weak_instrument``) is said by
    that note: its near-bound finding becomes a note too (the demo's turbulent block: the airspeed
    delay 291 ms, widened to 5.2 s). A delay the check could not judge keeps its warning."""
    return [replace(f, severity=Severity.NOTE, advice="",
                    message=f"{f.message}; its honest deviation is the feedback check's widened one "
                    "(delay_feedback, delay_weak_instrument)")
            if f.code == "near_bound" and f.parameters and set(f.parameters) <= widened else f
            for f in findings]


def _unsettled(move: np.ndarray | None, std: np.ndarray, problem: Problem,
               std_honest: np.ndarray | None = None) -> list[Finding]:
    """The filter-error method's last fresh linearisation of the wind sensitivities
    (:meth:`estimator.filter_error.FilterErrorLikelihood.refresh`) still moved the estimate by more
    than a deviation (nothing otherwise): a warning where it moved a calibration parameter, a note
    where only the maneuvers' own parameters moved (their initial conditions, steady winds and IMU
    biases: what describes the flight, not the calibration; the demo's turbulent block, 9.3
    deviations on one maneuver's initial velocities and steady wind)."""
    if move is None:
        return []
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.abs(move) / std
    z = np.where(np.isfinite(z), z, 0.0)
    if z.max() <= 1.0:
        return []
    ps = problem.parameters.parameters
    keys = problem.parameters.keys
    worst = [keys[i] for i in np.argsort(-z)[:6] if z[i] > 1.0]
    # a calibration parameter moved by more than its honest deviation (which the user reads) is what
    # the estimate's users must know; within it, the move is covered
    with np.errstate(invalid="ignore", divide="ignore"):
        zh = z if std_honest is None else np.abs(move) / np.where(np.isfinite(std_honest), std_honest, std)
    calibration = [i for i in np.flatnonzero(np.nan_to_num(zh) > 1.0) if ps[i].kind not in FLIGHT_KINDS]
    named = ", ".join(f"{keys[i]} {zh[i]:.1f}" for i in sorted(calibration, key=lambda i: -zh[i])[:6])
    what = (f"; calibration parameters beyond their honest deviations: {named} of them" if calibration else
            "; the calibration parameters move within their honest deviations, the rest are the "
            "maneuvers' own (initial conditions, steady winds, IMU biases)")
    return [Finding(
        "unsettled", Severity.WARNING if calibration else Severity.NOTE,
        f"filter-error method: with the noise statistics held, each fresh linearisation of the wind "
        f"sensitivities still moves the estimate, the last by up to {z.max():.1f} Cramér-Rao "
        f"deviations ({', '.join(worst)}): the estimate is the optimum of the last linearisation, "
        f"and uncertain by about that much beyond its deviations{what}",
        "look for a model-structure error the wind states partly take up (a scale factor or table "
        "the model set lacks: fit the calm maneuvers by output error and read its diagnostics)"
        if calibration else "",
        parameters=tuple(dict.fromkeys([keys[i] for i in calibration] + worst)), value=float(z.max()))]


def _iteration_findings(it: Iterated, stage_notes: list[str]) -> list[Finding]:
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


def _diagnosed(problem: Problem, evals: Evaluation, st: Structure, state: list[str], findings: list[Finding],
               y: list[np.ndarray] | None = None) -> tuple[list[Finding], object, dict]:
    """The fit-quality diagnostics at the estimate: their findings before ``findings``, the table
    and the outliers found (``y``: :func:`_fit_traces`)."""
    from estimator.diagnostics import DiagnosticOptions, diagnose

    ps = problem.parameters
    diagnosis = diagnose(*_fit_traces(problem, evals, st, y), DiagnosticOptions(g_mps2=problem.g_mps2))
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


def _fit_traces(problem: Problem, ev: Evaluation, st: Structure, y: list[np.ndarray] | None = None):
    """The diagnostics' inputs: every channel of every maneuver at the estimate, and each
    maneuver's IMU inputs and reconstructed states (``y``: per channel, what to judge the
    measurements against instead of the model output; the filter-error method's predictions)."""
    from estimator.diagnostics import ChannelFit, ManeuverInputs

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


def _stats(problem: Problem, ev: Evaluation) -> tuple[ResidualStats, ...]:
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
