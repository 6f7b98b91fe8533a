"""The filter-error method's noise relaxation (issue 14): the intensity search from the last value
by successive parabolas, the squared extrapolation of R's EM updates, and that both reach what the
plain searches and updates reach."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize_scalar

from estimator.filter_error import SIGMA_STEP, SIGMA_XTOL, _parabolic_minimum, _squarem_step


@settings(max_examples=300, deadline=None)
@given(m=st.floats(-3.0, 3.0), k=st.floats(0.3, 5.0), a=st.floats(0.1, 100.0), off=st.floats(-0.4, 0.4))
def test_parabolic_minimum_finds_an_asymmetric_minimum(m, k, a, off):
    """``a (exp(k (x - m)) - k (x - m))``: convex, asymmetric (like a log-likelihood in the log of
    an intensity: steep on one side, nearly linear on the other), its minimum at ``m``. From as
    far as the relaxation's narrow bracket reaches (ln 1.5 = 0.405) the search ends within
    SIGMA_XTOL of it (what Brent's bounded search promises) or gives up (the caller then runs
    Brent's); from within 0.1 it must not give up, and takes a handful of evaluations."""
    calls = []

    def f(x):
        calls.append(x)
        return a * (math.exp(k * (x - m)) - k * (x - m))

    x = _parabolic_minimum(f, m + off, -10.0, 10.0, SIGMA_STEP, SIGMA_XTOL)
    if abs(off) <= 0.1:
        assert x is not None, "a smooth convex function near the start: the parabolas must settle"
        assert len(calls) <= 8, calls
    assert x is None or abs(x - m) < SIGMA_XTOL, f"found {x}, the minimum is at {m}"


def test_parabolic_minimum_near_the_start_takes_four_evaluations():
    calls = []

    def f(x):
        calls.append(x)
        return math.cosh(2.0 * (x - 0.013))

    x = _parabolic_minimum(f, 0.0, -5.0, 5.0, SIGMA_STEP, SIGMA_XTOL)
    assert abs(x - 0.013) < 1e-4 and len(calls) <= 4


def test_parabolic_minimum_returns_the_bound_it_decreases_to():
    assert _parabolic_minimum(lambda x: -x, 0.0, -1.0, 1.0, 0.1, 1e-3) == 1.0
    assert _parabolic_minimum(lambda x: x, 0.0, -1.0, 1.0, 0.1, 1e-3) == -1.0
    assert _parabolic_minimum(lambda x: -((x - 0.01) ** 2), 0.0, -1.0, 1.0, 0.1, 1e-3) == -1.0


@settings(max_examples=100, deadline=None)
@given(rho=st.floats(0.0, 0.85), seed=st.integers(0, 2**31 - 1))
def test_squarem_takes_a_geometric_tail_in_one_step(rho, seed):
    """A fixed-point map converging linearly at one rate, ``x -> x* + rho (x - x*)``: one squared
    extrapolation from two of its iterates lands on ``x*`` (Varadhan & Roland 2008)."""
    rng = np.random.default_rng(seed)
    xs, x0 = rng.normal(size=5), rng.normal(size=5) * 3.0

    def F(x):
        return xs + rho * (x - xs)

    x1 = F(x0)
    x2 = F(x1)
    np.testing.assert_allclose(_squarem_step(x0, x1, x2), xs, atol=1e-9 * (1 + np.abs(x0 - xs).max()))


def test_squarem_is_clamped_and_never_steps_back():
    """A slow map (rho = 0.95: alpha would be -20) moves as far as the clamp allows, towards the
    fixed point, past x2; a converged one (x0 = x1 = x2) stays."""
    xs, x0 = np.zeros(3), np.ones(3)
    x1, x2 = 0.95 * x0, 0.95 ** 2 * x0
    x = _squarem_step(x0, x1, x2)
    assert np.all(x < x2) and np.all(x > xs)
    np.testing.assert_allclose(x, x0 * (1 + 2 * 8 * (-0.05) + 64 * 0.0025))  # alpha = -8
    np.testing.assert_array_equal(_squarem_step(x2, x2, x2), x2)


@pytest.fixture(scope="module")
def relaxed():
    from campaigns.analytic_flight import NOISE_SIGMA, Flight, truth_values
    from estimator.filter_error import FilterErrorLikelihood
    from estimator.io.modelset import load_model_set
    from estimator.model import Model

    specs = load_model_set("tejas")[1]
    fl = Flight(truth_values(np.random.default_rng(5)), specs, T=30.0, turbulence=(1.0, 533.4, 7))
    prob = fl.problem(noise=NOISE_SIGMA, rng=np.random.default_rng(3))
    lik = FilterErrorLikelihood(Model(prob))
    ev = lik.evaluate(prob.parameters.values, True)
    return lik, ev, lik.relax(ev, lik.stats(ev))


def test_the_intensity_search_from_the_last_value_is_brents(relaxed):
    """On a turbulent maneuver's likelihood, the search from a start 20 % off ends where Brent's
    bounded search of the whole range does, to SIGMA_XTOL in ln sigma."""
    lik, ev, noise = relaxed
    m = next(m for m in noise.maneuvers if noise.sigma_mps[m.k] > 0.0)
    e = lik._residuals(ev, m)
    s_brent = math.exp(minimize_scalar(lambda x: lik._nll(m, e, noise.R, math.exp(x)),
                                       bounds=(math.log(1e-3), math.log(15.0)), method="bounded",
                                       options={"xatol": 1e-6}).x)
    for start in (0.8 * s_brent, 1.2 * s_brent):
        s = lik._best_sigma(m, e, noise.R, start / 1.5, start * 1.5, start)
        assert abs(math.log(s / s_brent)) < SIGMA_XTOL, (start, s, s_brent)
    assert abs(math.log(noise.sigma_mps[m.k] / s_brent)) < 0.05, "the relaxation's own intensity"


def test_the_extrapolated_em_reaches_the_plain_em_fixed_point(relaxed):
    """R relaxed with the squared extrapolation is R's EM fixed point: one more plain EM update
    moves it by less than the relaxation's tolerance."""
    from estimator.filter_error import RELAX_TOL

    lik, ev, noise = relaxed
    R2 = lik._em_variances(ev, noise.maneuvers, noise.R, noise.sigma_mps)
    assert np.max(np.abs(R2 / noise.R - 1.0)) < RELAX_TOL
