"""The Gauss-Newton iterations: :func:`_gauss_newton` and the staged start that runs it per stage.

Levenberg-Marquardt-safeguarded Gauss-Newton steps on the normal equations
(:mod:`estimator.normal_equations`), ``R`` relaxed between steps, bounds as an active set.
Convergence is judged on the *undamped* Gauss-Newton step (module docstring of
:mod:`estimator.solver`), never on a step the damping shrank.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from estimator.identifiability import _has_data
from estimator.model import Evaluation, Model, ModelEvaluationError
from estimator.normal_equations import (
    Structure,
    bounded_solve,
    build_normal,
    channel_variances,
    full_step,
    ml_cost,
    residual_sums,
)
from estimator.problem import Problem
from estimator.start import staged_plan
from estimator.verdict import Status

if TYPE_CHECKING:
    from estimator.solver import SolverOptions


@dataclass
class _Iterated:
    """What a Gauss-Newton run left: the iterate, its evaluation and how it ended."""

    theta: np.ndarray
    evals: Evaluation
    sse: np.ndarray
    cnt: np.ndarray
    status: Status
    message: str
    iterations: int
    history: list[float]
    step_sigma: float  # the last undamped Gauss-Newton step, in deviations (largest)
    poor: tuple[str, ...] = ()  # where that step exceeded a deviation at convergence (poor model)


def _evaluate(model: Model, theta: np.ndarray, jacobian: bool) -> Evaluation:
    # the iterations need each block's normal-equation terms, not the Jacobian itself: fresh
    # memory for it each time costs more (page by page from the operating system) than
    # evaluating the last iterate once more for the Morelli-Klein deviations
    return model.evaluate_all(theta, jacobian=jacobian, keep_jacobian=False)


class OutputErrorLikelihood:
    """The output-error cost of the iterations (module docstring of :mod:`estimator.solver`):
    residual sums per channel, ``R`` in closed form between the steps.

    The iterations see a likelihood through five methods, so that another one (the filter-error
    method, :class:`estimator.filter_error.FilterErrorLikelihood`) runs the same Gauss-Newton
    iterations: ``evaluate`` (the model at a parameter vector, with or without the Jacobian),
    ``stats`` (what the cost needs of an evaluation), ``relax`` (the noise statistics at an
    iterate, held through its step), ``cost`` and ``normal`` (the normal equations).
    """

    def __init__(self, model: Model):
        self.model = model
        self.n_channels = len(model.problem.channels)

    def evaluate(self, theta: np.ndarray, jacobian: bool) -> Evaluation:
        return _evaluate(self.model, theta, jacobian)

    def stats(self, ev: Evaluation):
        return residual_sums(ev, self.n_channels)

    def relax(self, ev: Evaluation, stats):
        return channel_variances(*stats)

    def cost(self, stats, noise) -> float:
        return ml_cost(*stats, noise)

    def normal(self, st: Structure, ev: Evaluation, noise):
        return build_normal(st, ev, noise)


def _gauss_newton(model: Model, theta: np.ndarray, st: Structure, opt: SolverOptions,
                  evals: Evaluation | None = None, label: str = "", lik=None) -> _Iterated:
    """Levenberg-Marquardt-safeguarded Gauss-Newton iterations with relaxation of ``R`` (module
    docstring) until the undamped step is negligible; ``lik`` the likelihood (default: the
    output-error one, :class:`OutputErrorLikelihood`)."""
    nch = len(model.problem.channels)
    keys = model.problem.parameters.keys
    lik = OutputErrorLikelihood(model) if lik is None else lik
    theta = theta.copy()
    if evals is None:
        evals = lik.evaluate(theta, True)
    stats = lik.stats(evals)
    noise = None
    lam = opt.lm_lambda0
    history: list[float] = []
    status, message = Status.ITERATION_LIMIT, ""
    moved_max = np.inf
    poor: tuple[str, ...] = ()
    it = 0
    order = np.concatenate([st.glob] + [v for v in st.local_of_arr if v.size]).astype(int)
    for it in range(1, opt.max_iterations + 1):
        noise = lik.relax(evals, stats)
        cost0 = lik.cost(stats, noise)
        history.append(cost0)
        N = lik.normal(st, evals, noise)
        # the undamped Gauss-Newton step judges convergence: a damped one shrinks with the damping
        gn, _, _, Sinv, Ainv, _ = bounded_solve(N, st, theta, 0.0, opt.rank_rtol)
        sig = np.zeros(theta.size)
        sig[st.glob] = np.diag(Sinv)
        for k, idx in enumerate(st.local_of_arr):
            if idx.size:
                sig[idx] = np.diag(Ainv[k])
        sig = np.sqrt(np.maximum(sig, 1e-300))
        moved = np.abs(gn[order]) / sig[order]
        moved_max = float(moved.max()) if moved.size else 0.0
        predicted = 0.5 * float(gn @ full_step(st, N.gG, N.gL, theta.size))
        if moved_max < opt.step_tol_sigma:
            status = Status.CONVERGED_STEP
            message = (f"converged: the undamped Gauss-Newton step is {moved_max:.1e} deviations at "
                       f"most (< {opt.step_tol_sigma})")
            break
        if predicted < opt.decrease_tol:
            status = Status.CONVERGED_DECREASE
            message = (f"converged: the Gauss-Newton model predicts a further cost decrease of "
                       f"{max(predicted, 0.0):.1e} (< {opt.decrease_tol}); largest step "
                       f"{moved_max:.1e} deviations")
            break
        best = None  # (decrease, iterate, its evaluation, its stats, evaluated with the Jacobian)
        evaluated = 0  # trial points the model could be evaluated at
        for attempt in range(12):
            step = bounded_solve(N, st, theta, lam, opt.rank_rtol)[0]
            trial = np.clip(theta + step, st.lo, st.hi)
            try:
                # the first trial is usually accepted and is then the next iterate: evaluate it
                # with the Jacobian right away (the values are the same either way)
                trial_ev = lik.evaluate(trial, attempt == 0)
            except ModelEvaluationError:
                # the step left the model's domain (e.g. a table steeper than 1:1 in an implicit
                # model): a rejected step, damped further
                lam = max(lam, 1e-6) * 10.0
                continue
            evaluated += 1
            stats_t = lik.stats(trial_ev)
            cost_t = lik.cost(stats_t, noise)
            if np.isfinite(cost_t) and cost_t < cost0:
                best = (cost0 - cost_t, trial, trial_ev, stats_t, attempt == 0)
                break
            lam = max(lam, 1e-6) * 10.0
        if best is None or best[0] < max(opt.decrease_tol, 0.1 * predicted):
            # the damped steps achieve (next to) nothing: search along the undamped Gauss-Newton
            # direction itself, whose quadratic model can be poor along a parameter the data barely
            # determine (one that enters the outputs only to second order, like v0 without a
            # sideslip channel). What no step achieves, the minimum does not offer either.
            for t in 10.0 ** -np.arange(0, 9):
                trial = np.clip(theta + t * gn, st.lo, st.hi)
                try:
                    trial_ev = lik.evaluate(trial, False)
                except ModelEvaluationError:
                    continue
                evaluated += 1
                stats_t = lik.stats(trial_ev)
                cost_t = lik.cost(stats_t, noise)
                if np.isfinite(cost_t) and cost0 - cost_t > (best[0] if best else 0.0):
                    best = (cost0 - cost_t, trial, trial_ev, stats_t, False)
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
            achieved = best[0] if best is not None else 0.0
            poor = tuple(keys[order[i]] for i in np.argsort(-moved) if moved[i] >= 1.0)
            if moved_max < 10.0 * opt.step_tol_sigma:
                # within a tenth of a deviation of the minimum, where round-off (or a kink of an
                # interpolated delay or table) keeps the cost from decreasing any further
                status = Status.CONVERGED_STEP
                message = (f"converged: the undamped Gauss-Newton step is {moved_max:.1e} deviations "
                           f"at most; no step decreases the cost by more than {achieved:.1e} (round-off)")
            elif best is None:
                # not even a tiny step along the gradient lowers the cost: the gradient does not
                # describe the cost here (a kink, a model or Jacobian fault), so this is no minimum
                status = Status.STALLED
                message = (f"stalled: no step decreases the cost at all (damping grew to {lam:.1e}, and "
                           "along the undamped direction too), yet the Gauss-Newton model predicts "
                           f"{predicted:.3g} with a step of {moved_max:.2g} deviations "
                           f"({keys[order[int(np.argmax(moved))]]}): the gradient does not describe "
                           "the cost here")
            else:
                status = Status.CONVERGED_DECREASE
                message = (f"converged: no step decreases the cost by more than {achieved:.1e} "
                           f"(< {opt.decrease_tol}), although the Gauss-Newton model predicts "
                           f"{predicted:.3g} with a step of {moved_max:.2g} deviations "
                           f"({', '.join(poor[:4]) or keys[order[int(np.argmax(moved))]]}): the "
                           "quadratic model is poor there")
            break
        decrease, theta, trial_ev, stats, with_jac = best
        lam = max(lam * 0.1, 1e-9)
        evals = trial_ev if with_jac else lik.evaluate(theta, True)
        if opt.verbose:
            rel = decrease / max(abs(cost0), 1e-300)
            print(f"{label}iteration {it:3d}: cost {cost0: .6e}, rel. decrease {rel:.2e}, undamped step "
                  f"{moved_max:.2e} sigma ({keys[order[int(np.argmax(moved))]]}), lambda {lam:.1e}")
    else:
        if moved_max < 10.0 * opt.step_tol_sigma:
            # as where no step decreases the cost: within a tenth of a deviation of the minimum (a
            # predicted decrease of 0.005 at most, a likelihood ratio of 1.005), the iterations crawl
            # along a weakly determined direction (a delay near its bound, the realism level's slow
            # errors) without moving the estimate by anything its deviations resolve
            status = Status.CONVERGED_STEP
            message = (f"converged: at the iteration limit ({opt.max_iterations}) the undamped Gauss-Newton "
                       f"step is {moved_max:.1e} deviations at most (< {10.0 * opt.step_tol_sigma:g}), "
                       "within a tenth of a deviation of the minimum")
        else:
            message = (f"not converged: iteration limit ({opt.max_iterations}) reached; the undamped "
                       f"Gauss-Newton step is still {moved_max:.2g} deviations")
    sse, cnt = residual_sums(evals, nch)
    return _Iterated(theta, evals, sse, cnt, status, message, it, history, moved_max, poor)


def _staged_start(problem: Problem, theta: np.ndarray, free: np.ndarray, opt: SolverOptions
                  ) -> tuple[np.ndarray, list[str]]:
    """Run the stages of :func:`estimator.start.staged_plan` from ``theta``; returns the last
    stage's estimate and one line per stage."""
    notes = []
    for stage in staged_plan(problem, free):
        sub = replace(problem, channels=tuple(problem.channels[i] for i in stage.channels))
        model = Model(sub)
        try:
            ev = _evaluate(model, theta, True)
        except ModelEvaluationError as exc:
            notes.append(f"start stage {stage.name}: skipped ({exc})")
            continue
        st = Structure(sub, stage.free)
        # a stage frees only what its channels depend on; the rest waits for a later stage
        N = build_normal(st, ev, np.ones(len(sub.channels)))
        st = Structure(sub, stage.free & _has_data(N, st, opt.min_support_samples))
        if not st.free.any():
            continue
        it = _gauss_newton(model, theta, st, opt, ev, label=f"start ({stage.name}) ")
        theta = it.theta
        notes.append(f"start stage {stage.name}: {len(stage.channels)} channels, {int(st.free.sum())} "
                     f"free, {it.iterations} iterations, {it.status.name.lower()}")
        if opt.verbose:
            print(notes[-1])
    return theta, notes
