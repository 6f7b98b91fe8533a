"""Implicit channel models (``zhat``, the channel's own modelled measurement, as a table argument).

The side probe's ``alpha_zsp = alpha_s + f3(zhat) + b_sa`` is solved for ``zhat`` by Newton's
method and, should that not settle, by fixed-point iteration. A table steeper than 1:1 between two
breakpoints has no attracting solution: the iterations cycle, and the model must say so at once
(a ModelEvaluationError naming the channel, which the solver takes as a step out of the model's
domain) instead of spending its whole iteration budget to say the same thing.
"""

from __future__ import annotations

import numpy as np
import pytest

import estimator.core.expressions as expressions
from campaigns.analytic_flight import Flight, truth_values
from estimator.io.modelset import load_model_set
from estimator.model import IMPLICIT_FIXED_POINT_ITERATIONS, IMPLICIT_ITERATIONS, Model, ModelEvaluationError

#: f3 at its breakpoints -8, 0, 8, 16, 24 deg (rad): a slope of 1.43 from -8 to 8 deg, where the
#: flight's alpha (2-6 deg) is, and of 2.9 beyond: steeper than 1:1 wherever the flight goes
STEEP = [-0.2, 0.0, 0.2, -0.2, 0.2]
#: the same shape, mirrored: a slope of -1.43 where the flight's alpha is, where the iteration
#: y -> F(y) overshoots but Newton converges in a few steps (the slope is constant there)
MIRRORED = [0.2, 0.0, -0.2, 0.2, -0.2]


@pytest.fixture(scope="module")
def side_probe():
    _, specs = load_model_set("tejas")
    problem = Flight(truth_values(np.random.default_rng(5)), specs).problem()
    values = np.array(problem.parameters.values, dtype=float)
    f3 = [i for i, k in enumerate(problem.parameters.keys) if str(k).startswith("f3[")]
    return Model(problem), values, f3


@pytest.fixture
def expression_calls(monkeypatch):
    """How many times a channel expression is evaluated (with or without derivatives)."""
    calls = [0]
    value, evaluate = expressions.Expression.value, expressions.Expression.evaluate

    def counted(fn):
        def wrapper(self, *args, **kwargs):
            calls[0] += 1
            return fn(self, *args, **kwargs)
        return wrapper

    monkeypatch.setattr(expressions.Expression, "value", counted(value))
    monkeypatch.setattr(expressions.Expression, "evaluate", counted(evaluate))
    return calls


def test_a_cycling_implicit_model_is_given_up_at_once(side_probe, expression_calls):
    model, values, f3 = side_probe
    steep = values.copy()
    steep[f3] = STEEP
    with pytest.raises(ModelEvaluationError, match=r"alpha_zsp.*does not converge"):
        model.evaluate_all(steep, jacobian=False)
    budget = IMPLICIT_ITERATIONS + IMPLICIT_FIXED_POINT_ITERATIONS
    # the cycle is recognised after 9 Newton and 31 fixed-point iterations (model.py's
    # IMPLICIT_STALLED_STEP): the other channels' few evaluations besides, far below the budget
    assert expression_calls[0] < budget / 4, (expression_calls[0], budget)


def test_implicit_models_that_settle_still_do(side_probe, expression_calls):
    model, values, f3 = side_probe
    ev = model.evaluate_all(values, jacobian=False)  # the truth: a gentle f3
    assert all(np.isfinite(ce.y).all() for ce in ev.channels)
    mirrored = values.copy()
    mirrored[f3] = MIRRORED
    expression_calls[0] = 0
    ev = model.evaluate_all(mirrored, jacobian=False)
    zsp = [ce for ce in ev.channels if model.problem.channels[ce.channel].name == "alpha_zsp"]
    assert zsp and np.isfinite(zsp[0].y).all()
    assert expression_calls[0] < 40, expression_calls[0]
