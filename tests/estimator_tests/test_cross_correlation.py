"""The innovation-input cross-correlation and its Bartlett standard error
(:mod:`estimator.core.cross_correlation`), the test behind the filter-error method's
``gust_answer`` finding."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimator.core.cross_correlation import high_pass, lagged_correlation


def _ar1(rng: np.random.Generator, n: int, a: float) -> np.ndarray:
    e = rng.standard_normal(n)
    x = np.empty(n)
    x[0] = e[0] / np.sqrt(1 - a * a)
    for i in range(1, n):
        x[i] = a * x[i - 1] + e[i]
    return x


@given(c=st.floats(-1e3, 1e3), slope=st.floats(-10, 10), width=st.integers(1, 41).filter(lambda w: w % 2))
@settings(max_examples=40, deadline=None)
def test_high_pass_removes_a_line_away_from_the_ends(c, slope, width):
    """A centred mean of odd length reproduces a straight line: nothing of it passes, except
    where the window shrinks at the ends."""
    u = c + slope * np.arange(200.0)
    out = high_pass(u, width)
    h = width // 2
    assert np.allclose(out[h:200 - h], 0.0, atol=1e-9 * (1 + abs(c) + 200 * abs(slope)))


def test_high_pass_keeps_the_fast_part_and_checks_its_width():
    t = np.arange(4000) * 0.025
    fast, slow = np.sin(2 * np.pi * 5.0 * t), 3.0 * np.sin(2 * np.pi * 0.05 * t)
    out = high_pass(fast + slow, 40)  # 1 s at 40 Hz: 5 Hz passes, 0.05 Hz does not
    inner = slice(100, -100)
    assert np.std(out[inner] - fast[inner]) < 0.03, "the slow part is removed to 1 % of its size"
    with pytest.raises(ValueError, match="at least 1 sample"):
        high_pass(fast, 0)


@pytest.mark.parametrize("a_x, a_u", [(0.0, 0.95), (0.5, 0.9)])
def test_standard_error_is_honest_for_independent_series(a_x, a_u):
    """Independent series: r / se is standard normal (400 replications: its deviation within
    +-10 %, about 3 sampling deviations of a deviation). For a coloured x against a coloured u the plain
    1 / sqrt(n) is too small (Bartlett's widening, here 1 + 2 sum 0.5^l 0.9^l = 2.8 in variance)."""
    rng = np.random.default_rng(11)
    n = 1500
    lags = np.array([0, 1, 2])
    z, naive = [], []
    for _ in range(400):
        x, u = _ar1(rng, n, a_x), _ar1(rng, n, a_u)
        rows = np.arange(n)
        r, se = lagged_correlation(x, rows, u, lags, 60)
        z.append(r[0] / se[0])
        naive.append(r[0] * np.sqrt(n))
    assert 0.9 < np.std(z) < 1.1, np.std(z)
    if a_x > 0:
        assert np.std(naive) > 1.4, "the plain 1/sqrt(n) would be too small"


def test_a_planted_correlation_is_found_at_its_lag():
    """x = white + c u (two samples later): the largest |r| is at lag 2, of the size the planted
    term gives, far beyond its standard error; rows with gaps (a channel at half rate) work."""
    rng = np.random.default_rng(3)
    N = 3000
    u = high_pass(_ar1(rng, N, 0.9), 40)
    rows = np.arange(0, N - 2, 2)
    c = 0.5 / np.std(u)
    x = rng.standard_normal(rows.size) + c * u[rows + 2]
    r, se = lagged_correlation(x, rows, u, np.arange(-3, 6), 40)
    assert int(np.nanargmax(np.abs(r))) == 5  # lag +2
    expect = 0.5 / np.sqrt(1.25)
    assert abs(r[5] - expect) < 4 * se[5], (r[5], expect, se[5])
    assert r[5] / se[5] > 10
