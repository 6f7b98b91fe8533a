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

Start: by default staged (:mod:`estimator.start`: attitude, then speed and height, then the flow
channels), so that large IMU biases from zero start values reach the right minimum.

Identifiability (:mod:`estimator.identifiability`): held at their start values are parameters no
sample depends on, the fewest members of sets the data cannot separate and, at the solution, one
whose Cramér-Rao deviation exceeds half its allowed range. The estimation then iterates again, also
after a round that crawled to the iteration limit if the screen there holds a parameter; otherwise
the limit stays a failure. Each held parameter keeps its reason (:attr:`EstimationResult.state`).

Standard deviations: Cramér-Rao, ``sqrt(diag(M^-1))``, with the correlations; and the honest ones
(:mod:`estimator.uncertainty`: coloured, cross-correlated residuals and the IMU noise).

Where each part lives: this module orchestrates (starts, screening rounds, robust pass, result)
and chooses the likelihood once, by ``method`` (:mod:`estimator.likelihood`, or
:class:`estimator.filter_error.FilterErrorLikelihood`), whose hooks do what its method needs
around the iterations (:mod:`estimator.gauss_newton`); the screen, covariance and parameter states
are :mod:`estimator.identifiability`, the checks at the estimate :mod:`estimator.checks`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from threadpoolctl import threadpool_limits

from estimator.checks import (
    diagnosed,
    iteration_findings,
    near_bounds,
    not_invertible,
    residual_stats,
    widened_said,
)
from estimator.filter_error import FilterErrorLikelihood
from estimator.gauss_newton import Iterated, IterationError, iterate, staged_start
from estimator.identifiability import (
    covariance,
    crosswind_findings,
    high_correlations,
    parameter_findings,
    parameter_states,
    screen,
)
from estimator.io.build import without_samples
from estimator.likelihood import Likelihood, OutputErrorLikelihood, evaluate
from estimator.model import Evaluation, Model, ModelEvaluationError
from estimator.normal_equations import Structure, channel_variances, residual_sums
from estimator.options import SolverOptions
from estimator.problem import Problem
from estimator.result import EstimationResult
from estimator.uncertainty import imu_noise_note, imu_noise_unknown
from estimator.verdict import Finding, Severity, Status, judge


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
    sub = without_samples(problem, excluded)
    sub = replace(sub, parameters=sub.parameters.with_values(res.values))
    again = _estimate_guarded(sub, replace(opt, start="given"))
    notes = tuple(Finding(
        "excluded", Severity.NOTE,
        f"robust option: {t.size} outlier sample(s) of {ch} in maneuver {man} excluded from the fit "
        f"(at t = {', '.join(f'{v:.3f}' for v in t[:5])}{' ...' if t.size > 5 else ''} s)",
        channel=ch, maneuver=man, t_s=tuple(float(v) for v in t)) for (man, ch), t in excluded.items())
    return again.with_findings(notes, iterations=res.iterations)


@dataclass
class _Run:
    """One estimation: what it started from, and what it gathers on the way to its result."""

    problem: Problem
    model: Model
    opt: SolverOptions
    t0: float
    start: np.ndarray  # the problem's values within their bounds
    requested: np.ndarray  # the free parameters asked for
    notes: list[str] = field(default_factory=list)  # the start's and the rounds' notes
    iterations: int = 0
    history: list[float] = field(default_factory=list)  # the cost at each iteration

    def spent(self, iterations: int, history: list[float], notes: Sequence[str] = ()) -> None:
        self.iterations += iterations
        self.history += history
        self.notes += notes


def _likelihood(model: Model, opt: SolverOptions) -> Likelihood:
    """The likelihood of ``opt.method``: the one place that asks which method it is."""
    if opt.method == "filter_error":
        return FilterErrorLikelihood(model, opt.wind)
    return OutputErrorLikelihood(model)


def _estimate(problem: Problem, opt: SolverOptions) -> EstimationResult:
    t0 = time.perf_counter()
    model = Model(problem)
    ps = problem.parameters
    requested = ps.free_mask
    if not requested.any():
        raise ValueError(f"{problem.source}: no free parameters; free some in the problem file")
    lo = np.array([p.bounds[0] for p in ps])
    hi = np.array([p.bounds[1] for p in ps])
    run = _Run(problem, model, opt, t0, np.clip(ps.values, lo, hi), requested)
    began = _begin(run)
    if isinstance(began, EstimationResult):
        return began
    theta, st, holds, start_evals = began
    try:
        lik = _likelihood(model, opt)
        pre = lik.before_iterations(theta, st, opt, start_evals)
        del start_evals  # held by pre where the method uses it; not beside the filter-error one's own
        run.spent(pre.iterations, pre.history, pre.notes)
        lik, it, st, holds = _rounds(run, pre.likelihood, pre.theta, pre.evals, st, holds)
        post = lik.after_iterations(it, st, opt)
        run.spent(post.iterations, post.history, post.notes)
    except IterationError as exc:  # cannot happen after a successful start: a safeguard
        return _failed(problem, exc.theta, t0, str(exc), "report this as a bug, with the data")
    return _finish(run, post.likelihood, post.it, st, holds)


def _begin(run: _Run) -> tuple[np.ndarray, Structure, list, Evaluation | None] | EstimationResult:
    """Where the iterations start (the staged start's estimate, or the given values), the free
    parameters the screen before them leaves, what it holds and the model there with the Jacobian
    (None if the screen moved a parameter back to its start value); a failed result where the
    model cannot be evaluated at the start or the data determine no free parameter."""
    problem, model, opt, t0, start = run.problem, run.model, run.opt, run.t0, run.start
    nch = len(problem.channels)
    theta = start.copy()
    staged = opt.start == "staged"
    try:
        # before a staged start this evaluation only checks that the model can be evaluated and
        # counts the data: a Jacobian would go unused, its scratch held beside every stage's (131
        # MB each at the paper's size, 70 maneuvers)
        evals = evaluate(model, theta, not staged)
    except ModelEvaluationError as exc:
        return _failed(problem, start, t0, f"the model cannot be evaluated at the start values: {exc}",
                       "check the units and signs of the channel named (a measurement far outside its "
                       "model's range cannot be fitted), or give start values closer to the data")
    sse, cnt = residual_sums(evals, nch)
    if not cnt.any():
        raise ValueError(f"{problem.source}: no channel has data in any maneuver")
    if staged:
        ended, stage_notes, ended_evals = staged_start(problem, theta, run.requested, opt, model)
        run.notes += stage_notes
        try:
            # the stages fit subsets of the channels: an implicit channel left out may be outside
            # its domain where they ended; then the full estimation starts from the given values
            evals = evaluate(model, ended, True) if ended_evals is None else ended_evals
            theta = ended
        except ModelEvaluationError as exc:
            run.notes.append(f"the staged start is left: the full model cannot be evaluated where it "
                             f"ended ({exc}); the estimation starts from the given values")
            evals = evaluate(model, theta, True)
        sse, cnt = residual_sums(evals, nch)
    # the screen before the iterations also holds what looks undetermined there, which keeps a
    # parameter the data hardly see from wandering to a bound on the way; the screen at the
    # solution judges every requested parameter again, and frees what the data determine there
    st, holds = screen(problem, Structure(problem, run.requested), evals, channel_variances(sse, cnt), opt,
                       loose=True)
    if not st.free.any():
        return _failed(problem, theta, t0, "no free parameter is determined by the data: "
                       + "; ".join(f"{h.kind}: {', '.join(h.confounding.parameters[:12])}" for h in holds),
                       "fly maneuvers that excite the parameters asked for, or fix them in the problem file",
                       Status.UNDETERMINED)
    before = theta.copy()
    run.notes += _restore_held(model, theta, start, run.requested & ~st.free)
    # the evaluation at the start with the Jacobian, for the iterations (unless the screen put a
    # parameter back at its start value)
    return theta, st, holds, (evals if np.array_equal(theta, before) else None)


def _rounds(run: _Run, lik: Likelihood, theta: np.ndarray, evals: Evaluation, st: Structure, holds: list):
    """``(lik, it, st, holds)``: the estimation's rounds, each the Gauss-Newton iterations and, at
    their solution, the identifiability screen again; a round the screen holds more in is
    followed by another without them."""
    problem, model, opt, requested = run.problem, run.model, run.opt, run.requested
    sol_held, sol_holds = np.zeros_like(requested), []  # what screens at a solution held
    for rnd in range(1, max(opt.screen_rounds, 1) + 1):
        it = iterate(model, theta, st, opt, evals, lik)
        theta, evals = it.theta, it.evals
        run.spent(it.iterations, it.history)
        crawled = it.status == Status.ITERATION_LIMIT
        if not (it.status.converged or crawled) or rnd == opt.screen_rounds:
            break
        # identifiability at the solution: the whole screen again, from the requested free set
        # less what a screen at an earlier solution held (judged again where the estimation went
        # without it, a parameter can look determined, a bilinear term's sensitivity moving with
        # its partner, be freed, and the last round would estimate it unscreened: study (c)'s
        # calm r4, the vanes' sideslip reference offset held, freed, then on its bound), by the
        # likelihood's own information where it has its own (the filter-error method's)
        base = Structure(problem, requested & ~sol_held)
        st_new, holds_new = screen(problem, base, evals, channel_variances(it.sse, it.cnt), opt,
                                   loose=True, normal=lik.screen_normal(base, evals))
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
            run.notes.append(
                f"round {rnd} reached the iteration limit ({it.message}); the identifiability screen "
                f"there holds {', '.join(keys[i] for i in np.flatnonzero(st.free & ~st_new.free))}, "
                "which the data do not determine: estimated again without them")
        run.notes += _restore_held(model, theta, run.start, st.free & ~st_new.free)
        st, holds = st_new, holds_new
        evals = lik.evaluate(theta, True)
    return lik, it, st, holds


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


def _finish(run: _Run, lik: Likelihood, it: Iterated, st: Structure, holds: list) -> EstimationResult:
    """Covariances, diagnostics, findings and verdict at the estimate ``it``."""
    problem, opt = run.problem, run.opt
    theta, evals = it.theta, it.evals
    keys = problem.parameters.keys
    fit = lik.at_estimate(theta, st, evals, it, opt)
    cov = covariance(fit.N, st, problem, opt)
    dev = lik.deviations(fit, cov, opt)
    own = lik.findings(fit, dev, opt)
    correlated = cov.correlated + high_correlations(dev.correlation, [keys[i] for i in st.glob],
                                                    opt.correlation_warn)
    # a set still unidentifiable here (the screen's rounds ran out) is reported with the holds
    confounding = [h.confounding for h in holds] + [conf for conf, _ in cov.unident] + correlated
    # what each parameter is: estimated, on a bound, held (why) or fixed
    state, reason = parameter_states(problem, theta, run.start, st, holds, dev.unresolved, cov.unident, opt)
    # which maneuvers inform each global parameter (its coupling block with their locals)
    informs = {keys[g]: {problem.maneuvers[k].id for k in range(len(problem.maneuvers))
                         if fit.N.HGL[k].shape[1] and np.any(fit.N.HGL[k][j] != 0.0)}
               for j, g in enumerate(st.glob)}
    findings = (imu_noise_unknown(dev.imu_psd)
                + parameter_findings(problem, holds, cov.unident, correlated, state, reason, opt, informs)
                + crosswind_findings(problem, evals, st, informs)
                + imu_noise_note(dev, st, keys, opt) + iteration_findings(it, run.notes)
                + near_bounds(problem, theta, st, state,
                              np.where(np.isfinite(dev.std_colored), dev.std_colored, dev.std_crb))
                + own
                + not_invertible(problem, evals, st))
    # the delays the feedback check widened (the filter-error method's): their near-bound notes
    widened = {keys[f.parameter] for f in dev.feedback if math.isfinite(f.std_after_s)}
    findings = widened_said(findings, widened)
    diagnosis_table, outliers = None, {}
    if opt.diagnose:
        # the measurements against what the likelihood predicts (the filter-error method's: the
        # innovations)
        findings, diagnosis_table, outliers = diagnosed(problem, evals, st, state, findings,
                                                        lik.predictions(evals, fit.noise))
    return EstimationResult.build(
        std_imu_noise=dev.std_imu, imu_noise_psd=dev.imu_psd,
        problem=problem, values=theta, std_crb=dev.std_crb, std_colored=dev.std_colored,
        correlation_keys=tuple(keys[i] for i in st.glob), correlation=dev.correlation,
        correlation_colored=dev.correlation_colored,
        R=dict(zip((c.name for c in problem.channels), fit.R, strict=True)),
        residuals=residual_stats(problem, evals), iterations=run.iterations,
        cost_history=tuple(run.history + [fit.cost]), status=it.status, message=it.message,
        confounding=tuple(confounding), elapsed_s=time.perf_counter() - run.t0,
        free_estimated=st.free.copy(), state=tuple(state), state_reason=tuple(reason),
        findings=tuple(findings), verdict=judge(it.status, findings), fit_quality=diagnosis_table,
        outliers=outliers, **lik.result_fields(fit))


