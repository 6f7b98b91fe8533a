"""The honest deviations do not depend on which worker thread finished first.

A problem of more than 20,000 samples evaluates its channels on two threads, which hand each
channel's Jacobian to the honest deviations as they finish (here a small problem is made to, the
threshold lowered). The IMU noise's middle sums those channels; summed in the order the threads
finished, its rounding (about 1e-9 of a deviation, enough to change the bytes of
``parameters.csv``) changed from run to run.
Here the deviations of one estimate are computed again, with the threads finishing in whatever
order they do, and must come out bit-identical.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "campaigns" / "benchmarks"))
from synthetic_fpr import synthetic_problem  # noqa: E402

import estimator.model as model  # noqa: E402
import estimator.uncertainty as uncertainty  # noqa: E402
from estimator.core.sensitivity import worker_threads  # noqa: E402
from estimator.solver import SolverOptions, estimate  # noqa: E402

pytestmark = pytest.mark.slow


@pytest.mark.skipif(worker_threads() < 2, reason="one core: the channels are evaluated in order")
def test_the_honest_deviations_are_bit_identical_however_the_threads_finish(monkeypatch):
    calls: list[tuple] = []
    honest_std = uncertainty.honest_std

    def kept(*args, **kwargs):
        calls.append((args, kwargs))
        return honest_std(*args, **kwargs)

    monkeypatch.setattr(uncertainty, "honest_std", kept)
    monkeypatch.setattr(model, "_THREADED_SAMPLES", 0)  # four maneuvers' channels on two threads
    problem = synthetic_problem(4, seed=1)
    estimate(problem, SolverOptions())
    (args, kwargs), = calls
    with threadpool_limits(limits=1, user_api="blas"):  # as estimate() computes them
        first = honest_std(*args, **kwargs)
        agains = [honest_std(*args, **kwargs) for _ in range(2)]
    for again in agains:
        for name, a, b in zip(("honest", "IMU noise's", "covariance"), first, again, strict=True):
            assert np.array_equal(a, b, equal_nan=True), (
                f"the {name} deviations moved by up to "
                f"{np.nanmax(np.abs(a - b) / np.abs(a)):.1e} of themselves between two computations")
