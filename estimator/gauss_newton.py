"""The Gauss-Newton iterations: :func:`gauss_newton` and the staged start that runs it per stage.

Levenberg-Marquardt-safeguarded Gauss-Newton steps on the normal equations
(:mod:`estimator.normal_equations`), ``R`` relaxed between steps, bounds as an active set.
Convergence is judged on the *undamped* Gauss-Newton step (module docstring of
:mod:`estimator.solver`), never on a step the damping shrank.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from estimator.identifiability import has_data
from estimator.likelihood import Iterated, OutputErrorLikelihood, evaluate
from estimator.model import Evaluation, Model, ModelEvaluationError
from estimator.normal_equations import (
    Structure,
    bounded_solve,
    build_normal,
    full_step,
    residual_sums,
)
from estimator.problem import Problem
from estimator.start import staged_plan
from estimator.verdict import Status

if TYPE_CHECKING:
    from estimator.options import SolverOptions


class _Linearised(NamedTuple):
    """An iterate of :func:`gauss_newton` with its noise statistics, cost, normal equations and
    undamped Gauss-Newton step (``moved``: its size in deviations, in ``order``)."""

    theta: np.ndarray
    noise: object
    cost0: float
    N: object
    gn: np.ndarray
    moved: np.ndarray
    moved_max: float
    predicted: float


def _linearised(lik, st: Structure, theta: np.ndarray, evals: Evaluation, stats, order: np.ndarray,
                rank_rtol: float) -> _Linearised:
    """The noise statistics relaxed at ``theta``, the cost, the normal equations and the undamped
    Gauss-Newton step, which judges convergence (a damped one shrinks with the damping)."""
    noise = lik.relax(evals, stats)
    cost0 = lik.cost(stats, noise)
    N = lik.normal(st, evals, noise)
    gn, _, _, Sinv, Ainv, _ = bounded_solve(N, st, theta, 0.0, rank_rtol)
    sig = np.zeros(theta.size)
    sig[st.glob] = np.diag(Sinv)
    for k, idx in enumerate(st.local_of_arr):
        if idx.size:
            sig[idx] = np.diag(Ainv[k])
    sig = np.sqrt(np.maximum(sig, 1e-300))
    moved = np.abs(gn[order]) / sig[order]
    moved_max = float(moved.max()) if moved.size else 0.0
    predicted = 0.5 * float(gn @ full_step(st, N.gG, N.gL, theta.size))
    return _Linearised(theta, noise, cost0, N, gn, moved, moved_max, predicted)


def _converged(at: _Linearised, opt: SolverOptions) -> tuple[Status, str] | None:
    """Converged on the undamped step or on the decrease it predicts (None: not yet)."""
    if at.moved_max < opt.step_tol_sigma:
        return Status.CONVERGED_STEP, (f"converged: the undamped Gauss-Newton step is {at.moved_max:.1e} "
                                       f"deviations at most (< {opt.step_tol_sigma})")
    if at.predicted < opt.decrease_tol:
        return Status.CONVERGED_DECREASE, (
            f"converged: the Gauss-Newton model predicts a further cost decrease of "
            f"{max(at.predicted, 0.0):.1e} (< {opt.decrease_tol}); largest step "
            f"{at.moved_max:.1e} deviations")
    return None


def _search(lik, st: Structure, at: _Linearised, lam: float, opt: SolverOptions, scanned: bool):
    """``(best, evaluated, lam, scan)``: the step taken from ``at`` — ``best`` (decrease, iterate,
    its evaluation, its stats, evaluated with the Jacobian) or None —, how many trial points the
    model could be evaluated at, the damping after the search and whether it scanned the undamped
    direction (``scanned``: whether the last search did)."""
    theta, cost0, noise = at.theta, at.cost0, at.noise
    best = None
    evaluated = 0
    for attempt in range(12):
        step = bounded_solve(at.N, st, theta, lam, opt.rank_rtol)[0]
        trial = np.clip(theta + step, st.lo, st.hi)
        # the first trial is usually accepted and is then the next iterate: evaluate it with
        # the Jacobian right away (the values are the same either way) — unless the last search
        # had to scan: this one most likely will too, and the Jacobian would be thrown away
        with_jac = attempt == 0 and not scanned
        try:
            trial_ev = lik.evaluate(trial, with_jac)
        except ModelEvaluationError:
            # the step left the model's domain (e.g. a table steeper than 1:1 in an implicit
            # model): a rejected step, damped further
            lam = max(lam, 1e-6) * 10.0
            continue
        evaluated += 1
        stats_t = lik.stats(trial_ev)
        cost_t = lik.cost(stats_t, noise)
        if np.isfinite(cost_t) and cost_t < cost0:
            best = (cost0 - cost_t, trial, trial_ev, stats_t, with_jac)
            break
        lam = max(lam, 1e-6) * 10.0
    scan = best is None or best[0] < max(opt.decrease_tol, 0.1 * at.predicted)
    if scan:
        # the damped steps achieve (next to) nothing: search along the undamped Gauss-Newton
        # direction itself, whose quadratic model can be poor along a parameter the data barely
        # determine (one that enters the outputs only to second order, like v0 without a
        # sideslip channel). What no step achieves, the minimum does not offer either.
        # The steps shrink tenfold; once the cost rises from one step to the next (still below
        # cost0), the search ends: where the cost has one dip along the ray, as a smooth cost
        # has, the smaller steps lie further up the slope back to cost0 and the step taken is
        # the one trying all nine would take; along a ray with several dips (a kink) it may be
        # a step of smaller decrease, still a decrease.
        previous = np.inf
        for t in 10.0 ** -np.arange(0, 9):
            trial = np.clip(theta + t * at.gn, st.lo, st.hi)
            try:
                trial_ev = lik.evaluate(trial, False)
            except ModelEvaluationError:
                previous = np.inf
                continue
            evaluated += 1
            stats_t = lik.stats(trial_ev)
            cost_t = lik.cost(stats_t, noise)
            if not np.isfinite(cost_t):
                previous = np.inf
                continue
            if cost0 - cost_t > (best[0] if best else 0.0):
                best = (cost0 - cost_t, trial, trial_ev, stats_t, False)
            if previous < cost_t < cost0:
                break
            previous = cost_t
    return best, evaluated, lam, scan


def _no_decrease(best, at: _Linearised, lam: float, opt: SolverOptions, keys: list[str],
                 order: np.ndarray) -> tuple[Status, str, tuple[str, ...]]:
    """How the iterations end where no step decreases the cost by ``decrease_tol``: the status,
    its message and the parameters along which the Gauss-Newton model is poor."""
    moved, moved_max, predicted = at.moved, at.moved_max, at.predicted
    achieved = best[0] if best is not None else 0.0
    poor = tuple(keys[order[i]] for i in np.argsort(-moved) if moved[i] >= 1.0)
    if moved_max < 10.0 * opt.step_tol_sigma:
        # within a tenth of a deviation of the minimum, where round-off (or a kink of an
        # interpolated delay or table) keeps the cost from decreasing any further
        return Status.CONVERGED_STEP, (
            f"converged: the undamped Gauss-Newton step is {moved_max:.1e} deviations "
            f"at most; no step decreases the cost by more than {achieved:.1e} (round-off)"), poor
    if best is None:
        # not even a tiny step along the gradient lowers the cost: the gradient does not
        # describe the cost here (a kink, a model or Jacobian fault), so this is no minimum
        return Status.STALLED, (
            f"stalled: no step decreases the cost at all (damping grew to {lam:.1e}, and "
            "along the undamped direction too), yet the Gauss-Newton model predicts "
            f"{predicted:.3g} with a step of {moved_max:.2g} deviations "
            f"({keys[order[int(np.argmax(moved))]]}): the gradient does not describe "
            "the cost here"), poor
    return Status.CONVERGED_DECREASE, (
        f"converged: no step decreases the cost by more than {achieved:.1e} "
        f"(< {opt.decrease_tol}), although the Gauss-Newton model predicts "
        f"{predicted:.3g} with a step of {moved_max:.2g} deviations "
        f"({', '.join(poor[:4]) or keys[order[int(np.argmax(moved))]]}): the "
        "quadratic model is poor there"), poor


def _at_the_limit(moved_max: float, opt: SolverOptions) -> tuple[Status, str]:
    """How the iterations end at the iteration limit."""
    if moved_max < 10.0 * opt.step_tol_sigma:
        # as where no step decreases the cost: within a tenth of a deviation of the minimum (a
        # predicted decrease of 0.005 at most, a likelihood ratio of 1.005), the iterations crawl
        # along a weakly determined direction (a delay near its bound, the realism level's slow
        # errors) without moving the estimate by anything its deviations resolve
        return Status.CONVERGED_STEP, (
            f"converged: at the iteration limit ({opt.max_iterations}) the undamped Gauss-Newton "
            f"step is {moved_max:.1e} deviations at most (< {10.0 * opt.step_tol_sigma:g}), "
            "within a tenth of a deviation of the minimum")
    return Status.ITERATION_LIMIT, (f"not converged: iteration limit ({opt.max_iterations}) reached; "
                                    f"the undamped Gauss-Newton step is still {moved_max:.2g} deviations")


#: How a start stage that ends where its quadratic model turned poor says so (staged_start)
POOR_MODEL_END = ("ended where its quadratic model turned poor (a step achieved under a tenth of "
                  "the decrease it predicted, and that under one log-likelihood unit): the rest is "
                  "left to the estimation")
#: ... only near the stage's minimum: the whole decrease the undamped step predicts below this
#: (log-likelihood units: within about 1.4 joint deviations of it, in its basin). Far from it a
#: first step can be poorly predicted too (large IMU biases from a zero start), and there the
#: stage's iterations are what keeps the fit out of a wrong minimum
POOR_MODEL_NEAR = 1.0


def gauss_newton(model: Model, theta: np.ndarray, st: Structure, opt: SolverOptions,
                 evals: Evaluation | None = None, label: str = "", lik=None,
                 end_where_poor: bool = False) -> Iterated:
    """Levenberg-Marquardt-safeguarded Gauss-Newton iterations with relaxation of ``R`` (module
    docstring) until the undamped step is negligible; ``lik`` the likelihood (default: the
    output-error one, :class:`~estimator.likelihood.OutputErrorLikelihood`).

    ``end_where_poor``: end after the first step that achieved under a tenth of the decrease the
    undamped step predicts (the damped steps did, and so did the search along the undamped
    direction), that prediction below :data:`POOR_MODEL_NEAR`, with the status
    ``CONVERGED_DECREASE`` and the message :data:`POOR_MODEL_END` — a stage of the staged start,
    whose premise is a nearly linear sub-problem.
    """
    nch = len(model.problem.channels)
    keys = model.problem.parameters.keys
    lik = OutputErrorLikelihood(model) if lik is None else lik
    theta = theta.copy()
    if evals is None:
        evals = lik.evaluate(theta, True)
    stats = lik.stats(evals)
    lam = opt.lm_lambda0
    scanned = False
    history: list[float] = []
    status, message = Status.ITERATION_LIMIT, ""
    moved_max = np.inf
    poor: tuple[str, ...] = ()
    it = 0
    order = np.concatenate([st.glob] + [v for v in st.local_of_arr if v.size]).astype(int)
    for it in range(1, opt.max_iterations + 1):
        at = _linearised(lik, st, theta, evals, stats, order, opt.rank_rtol)
        history.append(at.cost0)
        moved_max = at.moved_max
        converged = _converged(at, opt)
        if converged is not None:
            status, message = converged
            break
        best, evaluated, lam, scanned = _search(lik, st, at, lam, opt, scanned)
        if not evaluated:
            status = Status.STALLED
            message = ("stalled: the model cannot be evaluated at any step from here (each leaves its "
                       f"domain; e.g. an implicit model that does not converge); the undamped "
                       f"Gauss-Newton step is {moved_max:.2g} deviations")
            break
        if best is None or best[0] < opt.decrease_tol:
            if best is not None:  # take the little there is
                theta, stats = best[1], best[3]
                evals = lik.evaluate(theta, True)
            status, message, poor = _no_decrease(best, at, lam, opt, keys, order)
            break
        decrease, theta, trial_ev, stats, with_jac = best
        lam = max(lam * 0.1, 1e-9)
        evals = trial_ev if with_jac else lik.evaluate(theta, True)
        if opt.verbose:
            rel = decrease / max(abs(at.cost0), 1e-300)
            print(f"{label}iteration {it:3d}: cost {at.cost0: .6e}, rel. decrease {rel:.2e}, undamped step "
                  f"{moved_max:.2e} sigma ({keys[order[int(np.argmax(at.moved))]]}), lambda {lam:.1e}")
        if end_where_poor and scanned and decrease < 0.1 * at.predicted and at.predicted < POOR_MODEL_NEAR:
            status, message = Status.CONVERGED_DECREASE, POOR_MODEL_END
            break
    else:
        status, message = _at_the_limit(moved_max, opt)
    sse, cnt = residual_sums(evals, nch)
    return Iterated(theta, evals, sse, cnt, status, message, it, history, moved_max, poor)


class IterationError(Exception):
    """Iterations that started where the model could be evaluated left its domain on the way (a
    safeguard: it does not happen after a successful start). ``theta``: where they started."""

    def __init__(self, theta: np.ndarray, message: str):
        super().__init__(message)
        self.theta = theta


def iterate(model: Model, theta: np.ndarray, st: Structure, opt: SolverOptions,
            evals: Evaluation | None, lik) -> Iterated:
    """:func:`gauss_newton` with ``lik`` from ``theta`` (``evals`` there, or None: evaluated
    first), the model failing on the way an :class:`IterationError`."""
    try:
        return gauss_newton(model, theta, st, opt, evals, lik=lik)
    except ModelEvaluationError as exc:
        raise IterationError(theta, str(exc)) from None


def staged_start(problem: Problem, theta: np.ndarray, free: np.ndarray, opt: SolverOptions,
                 model: Model | None = None) -> tuple[np.ndarray, list[str], Evaluation | None]:
    """Run the stages of :func:`estimator.start.staged_plan` from ``theta``; returns the last
    stage's estimate, one line per stage and ``model`` evaluated there with the Jacobian where
    the last stage that moved it ran on ``model`` (else None). ``model``: the whole problem's,
    which a stage with every channel uses (a model of its own would hold the data and the
    sensitivities' scratch a second time: at the paper's bin size, 70 maneuvers, about 100 MB at
    the start's peak)."""
    notes = []
    ended: Evaluation | None = None
    every = tuple(range(len(problem.channels)))
    for stage in staged_plan(problem, free):
        if stage.channels == every and model is not None:
            sub, model_k = problem, model
        else:
            sub = replace(problem, channels=tuple(problem.channels[i] for i in stage.channels))
            model_k = Model(sub)
        try:
            ev = evaluate(model_k, theta, True)
        except ModelEvaluationError as exc:
            notes.append(f"start stage {stage.name}: skipped ({exc})")
            continue
        st = Structure(sub, stage.free)
        # a stage frees only what its channels depend on; the rest waits for a later stage
        N = build_normal(st, ev, np.ones(len(sub.channels)))
        st = Structure(sub, stage.free & has_data(N, st, opt.min_support_samples))
        if not st.free.any():
            continue
        # a stage is a nearly linear sub-problem (estimator.start): where its quadratic model
        # turns poor near its minimum, what is left is a crawl along weakly determined directions,
        # which the estimation, every parameter free, takes with the same safeguards
        it = gauss_newton(model_k, theta, st, opt, ev, label=f"start ({stage.name}) ", end_where_poor=True)
        theta = it.theta
        ended = it.evals if model_k is model else None  # the full model at theta, with the Jacobian
        how = "ended where its quadratic model turned poor" if it.message == POOR_MODEL_END \
            else it.status.name.lower()
        notes.append(f"start stage {stage.name}: {len(stage.channels)} channels, {int(st.free.sum())} "
                     f"free, {it.iterations} iterations, {how}")
        if opt.verbose:
            print(notes[-1])
    return theta, notes, ended
