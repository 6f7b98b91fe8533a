"""The likelihoods the Gauss-Newton iterations minimise (:mod:`estimator.gauss_newton`).

:class:`OutputErrorLikelihood` is the output-error cost (calm air); the filter-error method's
(:class:`estimator.filter_error.FilterErrorLikelihood`, turbulence) offers the iterations the same
five methods. :func:`evaluate` is the model evaluation both use.
"""

from __future__ import annotations

import numpy as np

from estimator.model import Evaluation, Model
from estimator.normal_equations import Structure, build_normal, channel_variances, ml_cost, residual_sums

__all__ = ["OutputErrorLikelihood", "evaluate"]


def evaluate(model: Model, theta: np.ndarray, jacobian: bool) -> Evaluation:
    """The model at ``theta`` (values and, with ``jacobian``, each block's normal-equation terms),
    its Jacobian not kept."""
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
        return evaluate(self.model, theta, jacobian)

    def stats(self, ev: Evaluation):
        return residual_sums(ev, self.n_channels)

    def relax(self, ev: Evaluation, stats):
        return channel_variances(*stats)

    def cost(self, stats, noise) -> float:
        return ml_cost(*stats, noise)

    def normal(self, st: Structure, ev: Evaluation, noise):
        return build_normal(st, ev, noise)
