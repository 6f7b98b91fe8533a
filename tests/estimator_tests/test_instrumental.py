"""The time delays' feedback check (estimator.core.instrumental): the instrumental-variable step
against the likelihood's, on a regression whose regressor carries the current error or not."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from estimator.core.instrumental import instrument_sums, iv_difference
from estimator.filter_error import DelayCheck, feedback_findings, judge_delays, widen_for_feedback
from estimator.parameters import Parameter
from estimator.verdict import Severity

RTOL = 1e-10
#: the instruments' lags, samples (50-100 ms at 40 Hz, as the filter-error method's)
LAGS = np.array([2, 3, 4])


def _regression(rng: np.random.Generator, n: int, feedback: float):
    """``y = 0.5 x + e``: ``x`` a slow AR(1) signal plus ``feedback`` times the current error ``e``
    (the aircraft's answer to the gust the innovation carries); returns the kernel's inputs at
    theta = 0: ``nu = y``, ``J = d nu / d theta = -x``, and the second column an independent
    regressor (not instrumented)."""
    e = rng.standard_normal(n)
    s = np.zeros(n)
    w = rng.standard_normal(n)
    for i in range(1, n):
        s[i] = 0.95 * s[i - 1] + w[i]
    x = s + feedback * e
    u = rng.standard_normal(n)
    y = 0.5 * x + 0.2 * u + e
    return np.arange(n), -np.column_stack([x, u]), y


def _difference(rows, J, nu):
    sums = instrument_sums(rows, J, nu, np.array([True, False]), LAGS)
    return iv_difference([(np.arange(2), *sums)], np.arange(2), RTOL)[:2]


def test_without_feedback_the_difference_is_its_own_noise():
    """Regressor independent of the current error: both estimates consistent, the difference has
    the Hausman variance V_IV - V_ML: D / sd over 400 replications of mean 0 and standard deviation
    1 (within 0.1: 400 draws give a standard deviation of 1 within about 0.035 at 1 sigma)."""
    rng = np.random.default_rng(7)
    z = []
    for _ in range(400):
        D, V = _difference(*_regression(rng, 2000, 0.0))
        z.append(D[0] / np.sqrt(V[0]))
    z = np.asarray(z)
    assert abs(z.mean()) < 0.15, z.mean()
    assert abs(z.std() - 1.0) < 0.1, z.std()


def test_with_feedback_the_difference_measures_the_likelihoods_bias():
    """The regressor carries the current error (feedback 0.5): the least-squares (likelihood)
    estimate is biased by cov(x, e) / var(x); the difference D is minus that bias, within 4 of its
    own deviations averaged over 50 replications, and far beyond its noise in each."""
    rng = np.random.default_rng(11)
    D_all, bias_all, z = [], [], []
    for _ in range(50):
        rows, J, nu = _regression(rng, 4000, 0.5)
        D, V = _difference(rows, J, nu)
        ml = np.linalg.lstsq(-J, nu, rcond=None)[0][0]
        D_all.append(D[0])
        bias_all.append(ml - 0.5)
        z.append(abs(D[0]) / np.sqrt(V[0]))
    D_all, bias_all = np.asarray(D_all), np.asarray(bias_all)
    sd = D_all.std() / np.sqrt(D_all.size)
    assert abs(D_all.mean() + bias_all.mean()) < 4 * sd, (D_all.mean(), bias_all.mean(), sd)
    assert np.median(z) > 5, np.median(z)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2 ** 31 - 1), st.integers(20, 200))
def test_nothing_instrumented_gives_no_difference(seed, n):
    """With no column instrumented the instrument is the regressor itself: both steps are one."""
    rng = np.random.default_rng(seed)
    J, nu = rng.standard_normal((n, 3)), rng.standard_normal(n)
    sums = instrument_sums(np.arange(n), J, nu, np.zeros(3, dtype=bool), np.array([2]))
    np.testing.assert_allclose(sums[0], sums[3])
    np.testing.assert_allclose(sums[1], sums[4])
    D, V, _ = iv_difference([(np.arange(3), *sums)], np.arange(3), RTOL)
    np.testing.assert_allclose(D, 0.0, atol=1e-9 * np.abs(np.linalg.lstsq(J, nu, rcond=None)[0]).max())
    np.testing.assert_allclose(V, 0.0, atol=1e-12)


def test_a_missing_sample_leaves_the_instrument_zero_there():
    """Rows with a gap: the instrument at a sample whose lagged sample is absent is zero, not the
    row that happens to sit that many places earlier."""
    rows = np.array([0, 1, 2, 5, 6, 7])
    J = np.arange(1.0, 7.0)[:, None]
    ZJ, *_ = instrument_sums(rows, J, np.zeros(6), np.array([True]), np.array([1]))
    # Z = [0, 1, 2, 0, 4, 5] (samples 0 and 5 have no predecessor): Z.J = 2 + 6 + 20 + 30
    assert ZJ[0, 0] == 58.0


def test_eliminating_each_maneuvers_own_parameters_equals_the_whole_solve():
    """Three maneuvers, each with two parameters of its own and two of the three globals: the
    globals' difference and variance from the Schur complements equal the dense solve of the whole
    system (to rounding); the maneuvers' own parameters are NaN."""
    rng = np.random.default_rng(3)
    gpos = np.array([0, 1, 2, -1, -1, -1, -1, -1, -1])
    delay = np.array([True, False, False] + [False] * 6)
    P = gpos.size
    whole = [np.zeros((P, P)), np.zeros(P), np.zeros((P, P)), np.zeros((P, P)), np.zeros(P)]
    blocks = []
    for k, glob in enumerate(([0, 1], [0, 2], [0, 1, 2])):
        cols = np.array(glob + [3 + 2 * k, 4 + 2 * k])
        rows, J, nu = _regression(rng, 500, 0.3)
        J = np.column_stack([J, rng.standard_normal((500, cols.size - 2))])
        sums = instrument_sums(rows, J, nu, delay[cols], LAGS)
        blocks.append((cols, *sums))
        for a, x in zip(whole, sums, strict=True):
            if a.ndim == 2:
                a[np.ix_(cols, cols)] += x
            else:
                a[cols] += x
    D, V, V_ml = iv_difference(blocks, gpos, RTOL)
    ZJ, Zn, ZZ, JJ, Jn = whole
    Ai, Mi = np.linalg.inv(ZJ), np.linalg.inv(JJ)
    D_ref = -Ai @ Zn + Mi @ Jn
    V_ref = np.diag(Ai @ ZZ @ Ai.T) - np.diag(Mi)
    np.testing.assert_allclose(D[:3], D_ref[:3], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(V[:3], np.maximum(V_ref[:3], 0.0), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(V_ml[:3], np.diag(Mi)[:3], rtol=1e-9)
    assert np.isnan(D[3:]).all() and np.isnan(V[3:]).all()


def _judged(rows, J, nu):
    """The feedback check of the first column (its honest deviation the white-innovation one)."""
    sums = instrument_sums(rows, J, nu, np.array([True, False]), LAGS)
    D, V, V_ml = iv_difference([(np.arange(2), *sums)], np.arange(2), RTOL)
    checks = judge_delays(D, V, V_ml, np.array([True, False]), np.sqrt(V_ml))
    return checks, np.sqrt(V_ml[0])


def _fast_regression(rng: np.random.Generator, n: int, feedback: float):
    """As :func:`_regression`, but the regressor mostly white (its slow part small): the
    instrument, its value 2-4 samples earlier, is weak (the airspeed delay's regressor on JSBSim's
    turbulence, the aircraft's answer to the gusts)."""
    e, w, u = rng.standard_normal((3, n))
    s = np.zeros(n)
    for i in range(1, n):
        s[i] = 0.95 * s[i - 1] + 0.15 * rng.standard_normal()
    x = s + w + feedback * e
    return np.arange(n), -np.column_stack([x, 0.2 * u]), 0.5 * x + 0.2 * u + e


def test_a_strong_instrument_without_feedback_widens_at_the_tests_size():
    """No feedback, instrument strong: a widening is a false alarm of the two-sided FEEDBACK_Z
    test, about 4.6 % (2 sigma); over 400 replications within 1.5-7.7 % (binomial 3 sigma at
    4.6 %: 3.1 %)."""
    rng = np.random.default_rng(5)
    n_widened = 0
    for _ in range(400):
        checks, _ = _judged(*_regression(rng, 2000, 0.0))
        assert all(not c.weak for c in checks)
        n_widened += len(checks)
    assert 0.015 < n_widened / 400 < 0.077, n_widened / 400


def _weak_coverage(feedback: float, seed: int, n_rep: int) -> np.ndarray:
    """The likelihood's error in widened deviations over ``n_rep`` weak-instrument regressions."""
    rng = np.random.default_rng(seed)
    z = []
    for _ in range(n_rep):
        rows, J, nu = _fast_regression(rng, 2000, feedback)
        checks, sd = _judged(rows, J, nu)
        (c,) = checks
        assert c.weak and c.ratio > 3.0 and c.parameter == 0 and not c.differs
        assert np.isclose(c.std_after_s, np.hypot(sd * c.ratio, c.difference_s), rtol=1e-12)
        z.append(abs(np.linalg.lstsq(-J, nu, rcond=None)[0][0] - 0.5) / c.std_after_s)
    return np.asarray(z)


def test_a_weak_instrument_widens_to_what_it_supports():
    """Regressor mostly white: the instrumental estimate is several times less precise, and the
    deviation becomes what it supports and the difference together, sqrt((sd r)^2 + D^2). It then
    covers the likelihood's feedback bias. Strong feedback (0.5, the bias about 20 likelihood
    deviations): every one of 60 replications within 3 widened deviations, none within 3 of the
    likelihood's. Moderate feedback (0.2, the bias 2-3 instrumental deviations, where the
    difference alone is no reliable test): at least 90 % within 2 (nominal 95 % for a deviation
    that is right; the formula errs on the safe side of Anderson-Rubin's |D| + c sd_IV)."""
    z = _weak_coverage(0.5, 3, 60)
    assert np.all(z < 3.0), np.round(z, 1)
    rng = np.random.default_rng(3)
    z_before = []
    for _ in range(20):
        rows, J, nu = _fast_regression(rng, 2000, 0.5)
        _, sd = _judged(rows, J, nu)
        z_before.append(abs(np.linalg.lstsq(-J, nu, rcond=None)[0][0] - 0.5) / sd)
    assert np.min(z_before) > 3.0, np.round(z_before, 1)
    z = _weak_coverage(0.2, 4, 200)
    assert np.mean(z < 2.0) >= 0.9, np.mean(z < 2.0)


def test_a_difference_without_variance_is_not_judged():
    """The rank cut left the difference (or the likelihood) no variance: listed, not judged."""
    for V, V_ml in ((0.0, 1.0), (1.0, 0.0)):
        (c,) = judge_delays(np.array([0.0]), np.array([V]), np.array([V_ml]), np.array([True]),
                            np.array([2.0]))
        assert np.isnan(c.std_after_s) and not c.weak and not c.differs


def _delay(key: str) -> Parameter:
    return Parameter(key, key, "", None, "s", 0.0, True, "global", (-0.3, 0.3), "time_delay",
                     1000.0, "ms")


#: three delays and a bias: two strong instruments that differ (opposite signs), a weak one, and
#: a fourth parameter the check leaves alone; positions among the globals shuffled
_GPOS = np.array([2, 0, 3, 1])
_CHECKS = [DelayCheck(0, 0.002, 0.005, +0.004, 0.001, 1.5),
           DelayCheck(1, 0.001, 0.003, -0.003, 0.0005, 1.2),
           DelayCheck(2, 0.010, 0.700, +0.05, np.nan, 40.0)]


def test_the_widening_bookkeeping():
    """Each judged delay's deviation becomes its std_after and its variance grows by
    std_after^2 - std_before^2, the covariance staying symmetric and positive semi-definite: the
    strong ones' growth one rank-one term with the differences' signs (their bias common: the
    covariance between them grows by the product of their growths' roots, signed), the weak one's
    its own diagonal term (its correlations shrink by std_before / std_after); the inputs are not
    changed."""
    rng = np.random.default_rng(1)
    A = rng.standard_normal((4, 4))
    std = np.array([0.002, 0.001, 0.010, 0.03])
    M = A @ A.T + 4 * np.eye(4)  # positive definite, correlated
    corr = M / np.sqrt(np.outer(np.diag(M), np.diag(M)))
    cov = np.empty((4, 4))
    cov[np.ix_(_GPOS, _GPOS)] = corr * np.outer(std, std)
    std0, cov0 = std.copy(), cov.copy()
    s, c = widen_for_feedback(std, cov, _GPOS, _CHECKS)
    np.testing.assert_array_equal(std, std0)
    np.testing.assert_array_equal(cov, cov0)
    np.testing.assert_allclose(s, [0.005, 0.003, 0.700, 0.03])
    g = _GPOS
    np.testing.assert_allclose(np.sqrt(np.diag(c)[g]), s, rtol=1e-12)
    grow = np.sqrt([0.005 ** 2 - 0.002 ** 2, 0.003 ** 2 - 0.001 ** 2])
    np.testing.assert_allclose(c[g[0], g[1]], cov0[g[0], g[1]] - grow[0] * grow[1], rtol=1e-12)
    for i in (0, 1, 3):  # the weak delay's covariances with the others are unchanged
        assert c[g[2], g[i]] == cov0[g[2], g[i]]
    r_before = cov0[g[2], g[3]] / (0.010 * 0.03)
    np.testing.assert_allclose(c[g[2], g[3]] / (0.700 * 0.03), r_before * 0.010 / 0.700, rtol=1e-12)
    np.testing.assert_allclose(c, c.T)
    assert np.linalg.eigvalsh(cov0).min() > 0.0
    assert np.linalg.eigvalsh(c).min() > 0.0


def test_a_delay_not_judged_changes_nothing():
    std, cov = np.array([0.002, 0.03]), np.diag([0.002 ** 2, 0.03 ** 2])
    s, c = widen_for_feedback(std, cov, np.array([0, 1]),
                              [DelayCheck(0, 0.002, np.nan, 0.001, np.nan, np.nan)])
    np.testing.assert_array_equal(s, std)
    np.testing.assert_array_equal(c, cov)


def test_the_findings_of_a_mixed_check():
    """One check with every kind: a delay_feedback note naming exactly the strong delays that
    differ, with their deviations in the display unit and the difference's deviations; a
    delay_weak_instrument note naming the weak one, its ratio, and that its widened deviation
    exceeds its allowed range (0.7 s against 0.6); a note naming the one not judged. Nothing else.
    Notes: the widened honest deviations already say what they say."""
    ps = [_delay(k) for k in ("tau_a", "tau_b", "tau_tas", "tau_c")]
    checks = _CHECKS + [DelayCheck(3, 0.002, np.nan, 0.0, np.nan, np.nan)]
    out = feedback_findings(ps, checks)
    assert [(f.code, f.severity) for f in out] == [
        ("delay_feedback", Severity.NOTE), ("delay_weak_instrument", Severity.NOTE),
        ("delay_feedback", Severity.NOTE)]
    strong, weak, info = out
    assert strong.parameters == ("tau_a", "tau_b")
    assert "tau_a 2 -> 5 ms" in strong.message and "tau_b 1 -> 3 ms" in strong.message
    assert "4.0 deviations of the difference" in strong.message
    assert strong.value == 6.0  # the largest |D| / sd_D: tau_b's 3 / 0.5
    assert weak.parameters == ("tau_tas",)
    assert "tau_tas 10 -> 700 ms" in weak.message and "40.0 times less precise" in weak.message
    assert "not determined by this flight" in weak.message
    assert "not determined" not in strong.message
    assert weak.value == 40.0
    assert info.parameters == ("tau_c",) and "tau_c" in info.message
    assert feedback_findings(ps, []) == []
