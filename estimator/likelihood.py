"""The likelihoods an estimation maximises: the :class:`Likelihood` protocol and the output-error one.

The solver (:func:`estimator.solver.estimate`) chooses a likelihood once, by
:attr:`~estimator.options.SolverOptions.method`, and from then on only calls it:

- the five methods the Gauss-Newton iterations use (:func:`estimator.gauss_newton.gauss_newton`):
  ``evaluate`` (the model at a parameter vector, with or without the Jacobian), ``stats`` (what
  the cost needs of an evaluation), ``relax`` (the noise statistics at an iterate, held through
  its step), ``cost`` and ``normal`` (the normal equations);
- hooks around the iterations: ``before_iterations`` (what the method does first, and the
  likelihood to iterate with; given the caller's evaluation at the start where it has one),
  ``screen_normal`` (the information the identifiability screen at a solution judges by) and
  ``after_iterations`` (what it does once the iterations converged);
- at the estimate: ``at_estimate`` (its noise statistics, cost and normal equations, a
  :class:`Fit`), ``deviations``, ``findings`` (the method's own), ``predictions`` (what the
  fit-quality diagnostics judge the measurements against) and ``result_fields`` (what it adds to
  the result).

:class:`OutputErrorLikelihood` is the output-error cost (calm air; the hooks do nothing); the
filter-error method's is :class:`estimator.filter_error.FilterErrorLikelihood` (turbulence).
:func:`evaluate` is the model evaluation both use.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple, Protocol, runtime_checkable

import numpy as np

from estimator import uncertainty
from estimator.model import Evaluation, Model
from estimator.normal_equations import (
    NormalEquations,
    Structure,
    build_normal,
    channel_variances,
    ml_cost,
    residual_sums,
)

if TYPE_CHECKING:
    from estimator.options import SolverOptions
    from estimator.uncertainty import Covariance, Deviations
    from estimator.verdict import Finding, Status

__all__ = ["Fit", "Iterated", "Likelihood", "OutputErrorLikelihood", "Postlude", "Prelude", "evaluate"]


def evaluate(model: Model, theta: np.ndarray, jacobian: bool) -> Evaluation:
    """The model at ``theta`` (values and, with ``jacobian``, each block's normal-equation terms),
    its Jacobian not kept."""
    # the iterations need each block's normal-equation terms, not the Jacobian itself: fresh
    # memory for it each time costs more (page by page from the operating system) than
    # evaluating the last iterate once more for the Morelli-Klein deviations
    return model.evaluate_all(theta, jacobian=jacobian, keep_jacobian=False)


@dataclass
class Iterated:
    """What a Gauss-Newton run left (:func:`estimator.gauss_newton.gauss_newton`): the iterate, its
    evaluation and how it ended."""

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


class Prelude(NamedTuple):
    """What a likelihood's ``before_iterations`` leaves: the likelihood to iterate with (itself or
    another of its kind), where the iterations start, the evaluation there, and the iterations,
    costs and notes it spent on the way."""

    likelihood: Likelihood
    theta: np.ndarray
    evals: Evaluation
    iterations: int
    history: list[float]
    notes: list[str]


class Postlude(NamedTuple):
    """What a likelihood's ``after_iterations`` leaves: the likelihood at the estimate, the last
    iterations' outcome, and the iterations, costs and notes it added."""

    likelihood: Likelihood
    it: Iterated
    iterations: int
    history: list[float]
    notes: list[str]


@dataclass(frozen=True)
class Fit:
    """A likelihood at the estimate: what the deviations and the findings are computed from.

    Attributes
    ----------
    theta, st, evals : the estimate, its structure (free parameters, bounds) and the model there.
    noise : the likelihood's noise statistics (output error: ``R`` itself).
    R : (n_channels,) each channel's measurement-noise variance, SI squared.
    cost : the cost at the estimate.
    N : the normal equations (information matrix) at the estimate.
    """

    theta: np.ndarray
    st: Structure
    evals: Evaluation
    noise: object
    R: np.ndarray
    cost: float
    N: NormalEquations


@runtime_checkable
class Likelihood(Protocol):
    """What an estimation method offers the solver and the Gauss-Newton iterations (module
    docstring)."""

    model: Model

    # --- the iterations ----------------------------------------------------------------------
    def evaluate(self, theta: np.ndarray, jacobian: bool) -> Evaluation: ...

    def stats(self, ev: Evaluation): ...

    def relax(self, ev: Evaluation, stats): ...

    def cost(self, stats, noise) -> float: ...

    def normal(self, st: Structure, ev: Evaluation, noise) -> NormalEquations: ...

    # --- around them ---------------------------------------------------------------------------
    def before_iterations(self, theta: np.ndarray, st: Structure, opt: SolverOptions,
                          evals: Evaluation | None = None) -> Prelude: ...

    def screen_normal(self, st: Structure, ev: Evaluation
                      ) -> Callable[[Structure], NormalEquations] | None: ...

    def after_iterations(self, it: Iterated, st: Structure, opt: SolverOptions) -> Postlude: ...

    # --- at the estimate -----------------------------------------------------------------------
    def at_estimate(self, theta: np.ndarray, st: Structure, ev: Evaluation, it: Iterated,
                    opt: SolverOptions) -> Fit: ...

    def deviations(self, fit: Fit, cov: Covariance, opt: SolverOptions) -> Deviations: ...

    def findings(self, fit: Fit, dev: Deviations, opt: SolverOptions) -> list[Finding]: ...

    def predictions(self, ev: Evaluation, noise) -> list[np.ndarray] | None: ...

    def result_fields(self, fit: Fit) -> dict: ...


class OutputErrorLikelihood:
    """The output-error cost (module docstring of :mod:`estimator.solver`): residual sums per
    channel, ``R`` in closed form between the steps; nothing before or after the iterations, the
    Cramér-Rao and coloured-residual deviations of :func:`estimator.uncertainty.deviations`, no
    findings of its own, the measurements judged against the model output."""

    def __init__(self, model: Model):
        self.model = model
        self.n_channels = len(model.problem.channels)

    def evaluate(self, theta: np.ndarray, jacobian: bool) -> Evaluation:
        return evaluate(self.model, theta, jacobian)

    def stats(self, ev: Evaluation):
        return residual_sums(ev, self.n_channels)

    def relax(self, ev: Evaluation, stats):
        return channel_variances(*stats)

    def cost(self, stats, noise) -> float:
        return ml_cost(*stats, noise)

    def normal(self, st: Structure, ev: Evaluation, noise):
        return build_normal(st, ev, noise)

    def before_iterations(self, theta: np.ndarray, st: Structure, opt: SolverOptions,
                          evals: Evaluation | None = None) -> Prelude:
        """Nothing to do first: the iterations start at ``theta``, with ``evals`` (the model there
        with the Jacobian, as :meth:`evaluate` gives it) where the caller has it."""
        return Prelude(self, theta, self.evaluate(theta, True) if evals is None else evals, 0, [], [])

    def screen_normal(self, st: Structure, ev: Evaluation) -> None:
        return None  # the screen's own output-error normal equations

    def after_iterations(self, it: Iterated, st: Structure, opt: SolverOptions) -> Postlude:
        return Postlude(self, it, 0, [], [])

    def at_estimate(self, theta: np.ndarray, st: Structure, ev: Evaluation, it: Iterated,
                    opt: SolverOptions) -> Fit:
        R = channel_variances(it.sse, it.cnt)
        return Fit(theta, st, ev, R, R, ml_cost(it.sse, it.cnt, R), build_normal(st, ev, R))

    def deviations(self, fit: Fit, cov: Covariance, opt: SolverOptions) -> Deviations:
        return uncertainty.deviations(self.model, fit.theta, fit.N, fit.st, fit.R, cov, opt)

    def findings(self, fit: Fit, dev: Deviations, opt: SolverOptions) -> list[Finding]:
        return []

    def predictions(self, ev: Evaluation, noise) -> None:
        return None  # the model output itself

    def result_fields(self, fit: Fit) -> dict:
        return {}
