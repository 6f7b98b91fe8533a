"""A round that reaches the iteration limit is screened for identifiability, like a converged one:
what the screen there holds (and the pre-iteration screen left free) is held and the estimation
iterates again; otherwise the iteration limit stays a failure (estimator/solver.py).

The case of issue 13's follow-up was a gear-down stage crawling along v0 while a sideslip gain
f5(alpha) * (beta + b_n) of pitch-only maneuvers lost its argument (covered end to end by
tests/campaigns_tests/test_workflow_recovery.py). Here the same path, fast, on the analytic flight
of test_estimator (exact model, white noise): from zero IMU biases and delays the first trajectory
is wrong and puts two table breakpoints inside the reconstructed alpha range that the solution
leaves outside it (no data there); with three iterations per round the first round ends at the
limit, the screen there holds the two, and the estimation reaches the very minimum that forty
iterations reach. With one iteration per round every round ends at the limit: a failure.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_identifiability import NOISE  # the analytic flight's channel noise

from campaigns.analytic_flight import Flight
from campaigns.analytic_flight import truth_values as _truth_values
from estimator.io.modelset import load_model_set
from estimator.solver import SolverOptions, estimate
from estimator.verdict import Status


@pytest.fixture(scope="module")
def problem():
    _, specs = load_model_set("tejas")
    flight = Flight(_truth_values(np.random.default_rng(5)), specs)
    return flight.problem(start=lambda ps: {p.key: 0.0 for p in ps if p.kind in ("imu_bias", "time_delay")},
                          noise=NOISE, rng=np.random.default_rng(3))


def _run(problem, max_iterations):
    return estimate(problem, SolverOptions(max_iterations=max_iterations, start="given", diagnose=False))


def test_a_round_at_the_iteration_limit_is_screened_and_estimated_again(problem):
    ref = _run(problem, 40)
    assert ref.converged and ref.iterations < 10, ref.message
    short = _run(problem, 3)
    notes = " ".join(f.message for f in short.findings if f.code == "start")
    assert "round 1 reached the iteration limit" in notes and "f1[1], f3[0]" in notes, notes
    assert short.converged, short.message
    # the same minimum, and the two held at the solution too (no samples there)
    assert abs(short.cost_history[-1] - ref.cost_history[-1]) < 1e-3
    np.testing.assert_allclose(short.values, ref.values, rtol=0, atol=1e-9)
    df = short.to_pandas()
    assert not df.loc[["f1[1]", "f3[0]"], "estimated"].any()


def test_the_iteration_limit_stays_a_failure_when_the_screen_holds_nothing_new(problem):
    res = _run(problem, 1)
    assert res.status == Status.ITERATION_LIMIT and not res.success, res.message
