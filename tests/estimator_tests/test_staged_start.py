"""The staged start (estimator/start.py) ends a stage where its quadratic model turns poor.

A stage's premise is a nearly linear sub-problem. The tiny campaign (tests/_campaigns.py: pitch
doublets and 3211s, no sideslip excitation) leaves the vanes' sideslip gains ``f2`` to a curved
valley with the maneuvers' initial sideslip velocities: the flow stage's steps achieved a tenth of
the decrease their model predicted and crawled 0.03 per iteration towards the bound, to the
iteration limit (40 iterations, 300 model evaluations; the whole estimation crawled the same
valley again). It now ends at the first such step, and the estimation converges from there.
"""

from __future__ import annotations

import re
import warnings

import pytest

from estimator.gauss_newton import staged_start
from estimator.io import problem_from_dataset
from estimator.model import Model
from estimator.options import SolverOptions
from estimator.solver import estimate

#: each test flies the tiny campaign (once per session) and estimates for seconds: the full suite
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def problem(tiny_dataset):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return problem_from_dataset(tiny_dataset)


def test_the_flow_stage_ends_where_its_quadratic_model_turns_poor(problem):
    free = problem.parameters.free_mask
    opt = SolverOptions()
    theta, notes, _ = staged_start(problem, problem.parameters.values.copy(), free, opt, Model(problem))
    (flow,) = [n for n in notes if n.startswith("start stage flow")]
    assert "ended where its quadratic model turned poor" in flow, notes
    # (it crawled to the iteration limit, 40, before the rule)
    assert int(re.search(r"(\d+) iterations", flow).group(1)) < 15, flow


def test_the_estimation_from_it_converges(problem):
    res = estimate(problem, SolverOptions(colored=False, diagnose=False))
    assert res.status.converged, res.message
    (start,) = [f for f in res.findings if f.code == "start"]
    assert "ended where its quadratic model turned poor" in start.message
