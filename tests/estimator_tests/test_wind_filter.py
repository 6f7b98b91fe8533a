"""Filter-error kernel for turbulent wind: the Kalman filter and RTS smoother against the dense Gaussian.

The reference is the joint distribution of all observations built directly from the state-space
model (no recursion): ``C = Hbig Pbig Hbig^T + R`` with ``Cov(s_j, s_i) = Phi^(j-i) P_i`` for
``j >= i``. The filter's likelihood, its innovation Jacobian, one Gauss-Newton step and the
smoother must all reproduce what that dense matrix says.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimator.core.wind_filter import (
    DRYDEN_OUTPUT,
    WindModel,
    dryden_body,
    gauss_markov,
    innovations,
    normal_equations,
    smooth,
)

# ----------------------------------------------------------------------------------------------
# the dense reference
# ----------------------------------------------------------------------------------------------


def dense_covariance(obs_sample, h, r, Phi, Qd, P0, n_samples):
    """``(C, Pbig, Hbig)``: the joint covariance of the observations, of the states at every sample,
    and the observation matrix, built from the state-space model without any filter recursion."""
    ns = Phi.shape[0]
    P = [P0]
    for _ in range(1, n_samples):
        P.append(Phi @ P[-1] @ Phi.T + Qd)
    Pbig = np.zeros((n_samples * ns, n_samples * ns))
    for i in range(n_samples):
        F = np.eye(ns)  # Phi^(j-i)
        for j in range(i, n_samples):
            block = F @ P[i]  # Cov(s_j, s_i)
            Pbig[j * ns:(j + 1) * ns, i * ns:(i + 1) * ns] = block
            Pbig[i * ns:(i + 1) * ns, j * ns:(j + 1) * ns] = block.T
            F = Phi @ F
    n = len(obs_sample)
    Hbig = np.zeros((n, n_samples * ns))
    for k, (smp, hrow) in enumerate(zip(obs_sample, h, strict=True)):
        Hbig[k, smp * ns:(smp + 1) * ns] = hrow
    C = Hbig @ Pbig @ Hbig.T + np.diag(r)
    return C, Pbig, Hbig


def dense_nll(e, C):
    sign, logdet = np.linalg.slogdet(2.0 * np.pi * C)
    assert sign > 0, "the joint covariance of the observations must be positive definite"
    return 0.5 * (e @ np.linalg.solve(C, e) + logdet)


def random_problem(seed, n_samples=40, integrated_down=False, m=3, general_phi=False):
    """A small random problem: 0-3 observations per sample (gaps included), wind states from
    :func:`gauss_markov` (or a random stable non-diagonal ``Phi``), random sensitivities."""
    rng = np.random.default_rng(seed)
    Phi, Qd, P0 = gauss_markov(rng.uniform(60, 200), rng.uniform(50, 400, 3), rng.uniform(0.5, 3, 3),
                               rng.uniform(0.05, 0.5), integrated_down=integrated_down)
    ns = Phi.shape[0]
    if general_phi:  # coupled, non-symmetric transition, generic Qd, P0: nothing diagonal to lean on
        A = rng.normal(size=(ns, ns))
        Phi = 0.9 * A / np.max(np.abs(np.linalg.eigvals(A)))
        B = rng.normal(size=(ns, ns))
        Qd = 0.3 * B @ B.T + 0.01 * np.eye(ns)
        B = rng.normal(size=(ns, ns))
        P0 = B @ B.T
    counts = rng.integers(0, 4, n_samples)
    obs_sample = np.repeat(np.arange(n_samples), counts)
    n = obs_sample.size
    h = rng.normal(size=(n, ns)) * 0.1
    if integrated_down:
        h[:, 3] *= 0.2  # an altitude channel sees the integral
    r = rng.uniform(0.01, 0.2, n) ** 2
    e = rng.normal(size=n) * 0.3
    J = rng.normal(size=(n, m))
    return obs_sample, e, h, r, J, Phi, Qd, P0, n_samples


PROBLEMS = [(1, False, False), (2, True, False), (3, False, True), (4, True, True)]


# ----------------------------------------------------------------------------------------------
# likelihood, innovations, Gauss-Newton
# ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed, integrated, general", PROBLEMS)
def test_likelihood_equals_dense_gaussian(seed, integrated, general):
    obs, e, h, r, J, Phi, Qd, P0, N = random_problem(seed, integrated_down=integrated, general_phi=general)
    assert np.any(np.bincount(obs, minlength=N) == 0) and np.any(np.bincount(obs, minlength=N) > 1), \
        "the problem must have gaps and several observations per sample to exercise both paths"
    nu, s, dnu, nll = innovations(obs, e, h, r, J, WindModel(Phi, Qd, P0), N)
    C, _, _ = dense_covariance(obs, h, r, Phi, Qd, P0, N)
    ref = dense_nll(e, C)
    assert nll == pytest.approx(ref, rel=1e-10), \
        "the prediction-error decomposition is exact: the filter's -log p(e) must equal the dense one"
    # the innovations whiten e: nu = L e, C = L^-1 diag(s) L^-T; so sum log s = log det C as well
    assert np.sum(np.log(s)) == pytest.approx(np.linalg.slogdet(C)[1], rel=1e-10), \
        "the innovation variances must factor det C (L is unit lower-triangular)"
    assert normal_equations(nu, s, dnu)[2] == pytest.approx(nll, rel=1e-14), \
        "normal_equations' cost is the same negative log-likelihood"


@pytest.mark.parametrize("seed, integrated, general", PROBLEMS)
def test_innovations_whiten_the_dense_covariance(seed, integrated, general):
    # nu = L e for every e, so L C L^T = diag(s): run the filter on the columns of I via J
    obs, e, h, r, _, Phi, Qd, P0, N = random_problem(seed, integrated_down=integrated, general_phi=general)
    n = e.size
    _, s, dnu, _ = innovations(obs, e, h, r, -np.eye(n), WindModel(Phi, Qd, P0), N)  # dnu = -L(-I) = L
    C, _, _ = dense_covariance(obs, h, r, Phi, Qd, P0, N)
    L = dnu
    assert np.allclose(np.triu(L, 1), 0.0) and np.allclose(np.diag(L), 1.0), \
        "the innovation filter must be causal with unit diagonal (nu_i = e_i - prediction from the past)"
    np.testing.assert_allclose(L @ C @ L.T, np.diag(s), atol=1e-11 * np.max(s),
                               err_msg="the innovations must be uncorrelated with variances s")


@pytest.mark.parametrize("seed, integrated, general", PROBLEMS)
def test_innovation_jacobian_is_exact_for_the_linear_map(seed, integrated, general):
    obs, e, h, r, J, Phi, Qd, P0, N = random_problem(seed, integrated_down=integrated, general_phi=general)
    nu0, _, dnu, _ = innovations(obs, e, h, r, J, WindModel(Phi, Qd, P0), N)
    rng = np.random.default_rng(seed + 100)
    for _ in range(3):
        d = rng.normal(size=J.shape[1])
        nu1, *_ = innovations(obs, e - J @ d, h, r, J, WindModel(Phi, Qd, P0), N)
        np.testing.assert_allclose(nu1, nu0 + dnu @ d, rtol=0, atol=1e-12 * (1 + np.max(np.abs(nu1))),
                                   err_msg="nu is linear in e with e-independent gains: "
                                           "nu(e - J d) = nu(e) + dnu d exactly")


def test_innovation_jacobian_against_central_differences():
    # a nonlinear model y(theta): the Jacobian J = dy/dtheta at theta0, residuals e = z - y(theta)
    obs, z, h, r, _, Phi, Qd, P0, N = random_problem(5, integrated_down=True)
    n = z.size
    rng = np.random.default_rng(55)
    A = rng.normal(size=(n, 3))
    c = rng.normal(size=n)

    def y(theta):
        return np.sin(A @ theta + c) + 0.1 * (A @ theta) ** 2

    def jac(theta):
        u = A @ theta
        return (np.cos(u + c) + 0.2 * u)[:, None] * A

    theta0 = np.array([0.3, -0.2, 0.5])
    _, _, dnu, _ = innovations(obs, z - y(theta0), h, r, jac(theta0), WindModel(Phi, Qd, P0), N)
    step = 1e-5
    fd = np.empty_like(dnu)
    for j in range(3):
        dt = np.zeros(3)
        dt[j] = step
        nup, *_ = innovations(obs, z - y(theta0 + dt), h, r, jac(theta0), WindModel(Phi, Qd, P0), N)
        num, *_ = innovations(obs, z - y(theta0 - dt), h, r, jac(theta0), WindModel(Phi, Qd, P0), N)
        fd[:, j] = (nup - num) / (2 * step)
    # central differences: truncation ~ step^2 |y'''| |A|^3 / 6, ~1e-10 here; rounding ~1e-16/1e-5
    np.testing.assert_allclose(dnu, fd, rtol=0, atol=1e-8 * np.max(np.abs(dnu)),
                               err_msg="dnu/dtheta must be -L J, the derivative of the innovations")


def test_gauss_newton_step_is_generalised_least_squares():
    obs, z, h, r, J, Phi, Qd, P0, N = random_problem(6, integrated_down=True, m=4)
    theta0 = np.zeros(J.shape[1])
    nu, s, dnu, _ = innovations(obs, z - J @ theta0, h, r, J, WindModel(Phi, Qd, P0), N)
    H, g, _ = normal_equations(nu, s, dnu)
    step = np.linalg.solve(H, g)
    C, _, _ = dense_covariance(obs, h, r, Phi, Qd, P0, N)
    Ci_J = np.linalg.solve(C, J)
    gls = np.linalg.solve(J.T @ Ci_J, Ci_J.T @ z)
    np.testing.assert_allclose(theta0 + step, gls, rtol=1e-9, atol=1e-12,
                               err_msg="L^T diag(1/s) L = C^-1, so one step from the filter's normal "
                                       "equations must be the GLS estimate with the full covariance")
    # and the step lands at the minimum: the gradient there vanishes
    nu2, s2, dnu2, _ = innovations(obs, z - J @ (theta0 + step), h, r, J, WindModel(Phi, Qd, P0), N)
    g2 = normal_equations(nu2, s2, dnu2)[1]
    assert np.max(np.abs(g2)) < 1e-9 * np.max(np.abs(g)), \
        "for a linear model the cost is quadratic: after the Gauss-Newton step its gradient is zero"


def test_m_zero_and_no_observations():
    obs, e, h, r, _, Phi, Qd, P0, N = random_problem(7)
    nu, s, dnu, nll = innovations(obs, e, h, r, np.zeros((e.size, 0)), WindModel(Phi, Qd, P0), N)
    assert dnu.shape == (e.size, 0) and np.isfinite(nll), "m = 0 (no parameters) must be allowed"
    H, g, cost = normal_equations(nu, s, dnu)
    assert H.shape == (0, 0) and g.shape == (0,) and cost == pytest.approx(nll, rel=1e-14), \
        "the normal equations of no parameters are empty, the cost is still the likelihood"
    empty = np.zeros(0, dtype=np.int64)
    nu, s, dnu, nll = innovations(empty, np.zeros(0), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 2)),
                                  WindModel(Phi, Qd, P0), 5)
    assert nu.size == 0 and nll == 0.0, "no observations: an empty likelihood (zero)"
    xs, Ps = smooth(empty, np.zeros(0), np.zeros((0, 3)), np.zeros(0), WindModel(Phi, Qd, P0), 5)
    np.testing.assert_allclose(Ps, np.broadcast_to(P0, (5, 3, 3)), rtol=1e-12,
                               err_msg="no observations: the smoothed covariance is the (stationary) prior")


# ----------------------------------------------------------------------------------------------
# smoother
# ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed, integrated, general", PROBLEMS)
def test_smoother_equals_dense_posterior(seed, integrated, general):
    obs, e, h, r, _, Phi, Qd, P0, N = random_problem(seed, integrated_down=integrated, general_phi=general)
    xs, Ps = smooth(obs, e, h, r, WindModel(Phi, Qd, P0), N)
    C, Pbig, Hbig = dense_covariance(obs, h, r, Phi, Qd, P0, N)
    PHt = Pbig @ Hbig.T
    mean = PHt @ np.linalg.solve(C, e)
    cov = Pbig - PHt @ np.linalg.solve(C, PHt.T)
    ns = Phi.shape[0]
    np.testing.assert_allclose(xs.ravel(), mean, rtol=0, atol=1e-9 * np.max(np.abs(mean)),
                               err_msg="the RTS mean must be E[s_k | all e] at every sample")
    for k in range(N):
        blk = cov[k * ns:(k + 1) * ns, k * ns:(k + 1) * ns]
        np.testing.assert_allclose(Ps[k], blk, rtol=0, atol=1e-9 * np.max(np.abs(np.diag(blk))),
                                   err_msg=f"the RTS covariance must be Cov(s_k | all e) at sample {k}")
        assert np.allclose(Ps[k], Ps[k].T, rtol=0, atol=0), "smoothed covariances are symmetrised"


# ----------------------------------------------------------------------------------------------
# Gauss-Markov discretisation
# ----------------------------------------------------------------------------------------------


def test_wind_axes_are_stationary_with_exponential_autocorrelation():
    v, L, sig, dt = 120.0, np.array([300.0, 200.0, 80.0]), np.array([1.5, 1.2, 0.9]), 0.025
    Phi, Qd, P0 = gauss_markov(v, L, sig, dt)
    np.testing.assert_allclose(Phi @ P0 @ Phi.T + Qd, P0, rtol=1e-14,
                               err_msg="P0 must be the stationary covariance: Phi P0 Phi^T + Qd = P0")
    np.testing.assert_allclose(np.diag(P0), sig**2, rtol=1e-15, err_msg="stationary std is sigma")
    for k in (1, 7, 40, 400):
        tau = k * dt
        cov = np.linalg.matrix_power(Phi, k) @ P0  # Cov(W(t + tau), W(t))
        np.testing.assert_allclose(np.diag(cov) / sig**2, np.exp(-v * tau / L), rtol=1e-12,
                                   err_msg="the autocorrelation must be exp(-V tau / L) (Taylor hypothesis)")
    Phi_s, Qd_s, P0_s = gauss_markov(v, 250.0, 1.1, dt)
    np.testing.assert_allclose(np.diag(P0_s), 1.21, rtol=1e-15, err_msg="a scalar sigma applies to all axes")
    np.testing.assert_allclose(np.diag(Phi_s), np.exp(-v * dt / 250.0), rtol=1e-15,
                               err_msg="a scalar L applies to all axes")


@pytest.mark.parametrize("x", [1e-5, 1e-3, 0.02, 0.3, 3.0])
def test_dryden_body_axes_have_the_milspec_autocorrelations(x):
    """MIL-F-8785C's Dryden form: the longitudinal component exp(-V tau / L), the lateral and
    vertical (1 - V tau / 2L) exp(-V tau / L), each of variance sigma^2, uncorrelated with each
    other; P0 stationary, Qd positive definite, for short and long steps alike."""
    v, L, sig = 150.0, 533.4, 1.3
    dt = x * L / v
    Phi, Qd, P0 = dryden_body(v, L, sig, dt)
    np.testing.assert_allclose(Phi @ P0 @ Phi.T + Qd, P0, rtol=0, atol=1e-14 * sig**2,
                               err_msg="P0 must be the stationary covariance")
    assert np.linalg.eigvalsh(Qd).min() > 0.0, "Qd positive definite (the smoother needs it)"
    for k in (0, 1, 5, 40):
        xi = v * k * dt / L
        cov = DRYDEN_OUTPUT @ np.linalg.matrix_power(Phi, k) @ P0 @ DRYDEN_OUTPUT.T
        want = sig**2 * np.array([np.exp(-xi), (1 - xi / 2) * np.exp(-xi), (1 - xi / 2) * np.exp(-xi)])
        np.testing.assert_allclose(np.diag(cov), want, rtol=1e-10, atol=1e-13,
                                   err_msg=f"autocorrelations at V tau / L = {xi:g}")
        np.testing.assert_allclose(cov - np.diag(np.diag(cov)), 0.0, atol=1e-15,
                                   err_msg="the three components are independent")


@pytest.mark.parametrize("x", [1e-7, 1e-5, 3e-3, 0.3, 3.0])
def test_dryden_process_noise_against_van_loan(x):
    """The closed-form Qd of the second-order pairs equals Van Loan's integral of the continuous
    model d/dt z = (V/L) [[0, 1], [-1, -2]] z + [0, sigma sqrt(V/L)] eta, to rounding, from steps
    where its first element is O(x^3) (a difference of O(x) terms would keep ~x^2 of its digits)
    to long ones."""
    from scipy.linalg import expm

    v, L, sig = 180.0, 533.4, 0.9
    dt = x * L / v
    a = v / L
    A = a * np.array([[0.0, 1.0], [-1.0, -2.0]])
    Qc = np.array([[0.0, 0.0], [0.0, sig**2 * a]])
    M = expm(np.block([[-A, Qc], [np.zeros((2, 2)), A.T]]) * dt)
    Phi2 = M[2:, 2:].T
    Qd2 = Phi2 @ M[:2, 2:]
    Phi, Qd, _ = dryden_body(v, L, sig, dt)
    for i in (1, 3):
        np.testing.assert_allclose(Phi[i:i + 2, i:i + 2], Phi2, rtol=1e-12)
        np.testing.assert_allclose(Qd[i:i + 2, i:i + 2], Qd2, rtol=1e-9, atol=1e-18)


@pytest.mark.parametrize("x", [1e-4, 3e-3, 0.02, 0.3, 0.49, 0.51, 2.0, 20.0])
def test_integrated_down_state_matches_the_integral_of_an_ou_process(x):
    # From a stationary W_d and D = 0: D(t) = int_0^t W_d, whose variance for an OU process of
    # correlation time Tc (autocovariance sigma^2 exp(-|u|/Tc)) is
    #   Var = int_0^t int_0^t sigma^2 exp(-|a-b|/Tc) = 2 sigma^2 int_0^t (t-u) exp(-u/Tc) du
    #       = 2 sigma^2 Tc^2 (t/Tc - 1 + exp(-t/Tc)),
    # and Cov(W_d(t), D(t)) = int_0^t sigma^2 exp(-(t-u)/Tc) du = sigma^2 Tc (1 - exp(-t/Tc)).
    # Checked after 1 and after 25 steps (the composition of the exact steps is exact too).
    v, L, sig = 100.0, 150.0, 1.3
    tc = L / v
    dt = x * tc
    Phi, Qd, P0 = gauss_markov(v, L, sig, dt, integrated_down=True)
    assert Phi.shape == (4, 4) and P0[3, 3] == 0.0 and P0[2, 3] == 0.0, \
        "the integral is a 4th state that starts at zero"
    P = P0.copy()
    for k in range(1, 26):
        P = Phi @ P @ Phi.T + Qd
        if k in (1, 25):
            t = k * dt
            var = 2 * sig**2 * tc**2 * (t / tc - 1 + np.exp(-t / tc))
            cov = sig**2 * tc * -np.expm1(-t / tc)
            # the closed form of var itself cancels for small t/Tc: use its series there
            if t / tc < 1e-2:
                u = t / tc
                var = 2 * sig**2 * tc**2 * (u**2 / 2 - u**3 / 6 + u**4 / 24 - u**5 / 120)
            assert P[3, 3] == pytest.approx(var, rel=1e-11), \
                f"Var of the integrated wind after {k} steps must be the OU integral's (x = {x})"
            assert P[2, 3] == pytest.approx(cov, rel=1e-11), \
                f"Cov(W_d, D) after {k} steps must be sigma^2 Tc (1 - exp(-t/Tc)) (x = {x})"
            assert P[2, 2] == pytest.approx(sig**2, rel=1e-12), "W_d stays stationary"
    assert np.all(np.linalg.eigvalsh(Qd[2:, 2:]) > 0), "the exact 2x2 process noise is positive definite"


def test_integrated_down_process_noise_against_van_loan():
    # an independent route to the exact Qd: Van Loan's matrix exponential of [[-A, B B^T], [0, A^T]]
    from scipy.linalg import expm
    v, L, sig, dt = 90.0, 60.0, 2.0, 0.2
    Phi, Qd, _ = gauss_markov(v, L, sig, dt, integrated_down=True)
    a = v / L
    A = np.array([[-a, 0.0], [1.0, 0.0]])
    BBt = np.array([[2 * a * sig**2, 0.0], [0.0, 0.0]])
    M = expm(np.block([[-A, BBt], [np.zeros((2, 2)), A.T]]) * dt)
    Phi_vl = M[2:, 2:].T
    Qd_vl = Phi_vl @ M[:2, 2:]
    np.testing.assert_allclose(Phi[2:, 2:], Phi_vl, rtol=1e-12, err_msg="transition of (W_d, D)")
    np.testing.assert_allclose(Qd[2:, 2:], Qd_vl, rtol=1e-10, err_msg="exact process noise of (W_d, D)")


# ----------------------------------------------------------------------------------------------
# invariants (Hypothesis)
# ----------------------------------------------------------------------------------------------


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), integrated=st.booleans())
def test_likelihood_independent_of_order_within_a_sample(seed, integrated):
    obs, e, h, r, J, Phi, Qd, P0, N = random_problem(seed, n_samples=15, integrated_down=integrated)
    rng = np.random.default_rng(seed)
    perm = np.concatenate([rng.permutation(np.flatnonzero(obs == k)) for k in range(N)]).astype(np.int64)
    nll = innovations(obs, e, h, r, J, WindModel(Phi, Qd, P0), N)[3]
    nll_p = innovations(obs[perm], e[perm], h[perm], r[perm], J[perm], WindModel(Phi, Qd, P0), N)[3]
    assert nll_p == pytest.approx(nll, rel=1e-11), \
        "the joint density of one sample's observations does not depend on the processing order"


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_no_wind_sensitivity_leaves_the_residuals(seed):
    obs, e, h, r, J, Phi, Qd, P0, N = random_problem(seed, n_samples=12)
    nu, s, dnu, nll = innovations(obs, e, np.zeros_like(h), r, J, WindModel(Phi, Qd, P0), N)
    np.testing.assert_array_equal(nu, e, err_msg="h = 0: nothing to predict, the innovations are e")
    np.testing.assert_array_equal(s, r, err_msg="h = 0: the innovation variance is the noise variance")
    np.testing.assert_array_equal(dnu, -J, err_msg="h = 0: dnu = -J (plain output error)")
    assert nll == pytest.approx(0.5 * np.sum(e**2 / r + np.log(2 * np.pi * r)), rel=1e-13), \
        "h = 0: the output-error likelihood"


# ----------------------------------------------------------------------------------------------
# input validation
# ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kwargs, name", [
    (dict(v_mps=-1.0), "v_mps"),
    (dict(v_mps=np.nan), "v_mps"),
    (dict(L_m=0.0), "L_m"),
    (dict(L_m=[100.0, 200.0]), "L_m"),
    (dict(sigma_mps=[1.0, -1.0, 1.0]), "sigma_mps"),
    (dict(sigma_mps=np.inf), "sigma_mps"),
    (dict(dt_s=0.0), "dt_s"),
])
def test_gauss_markov_validation_names_the_argument(kwargs, name):
    args = dict(v_mps=100.0, L_m=200.0, sigma_mps=1.0, dt_s=0.025) | kwargs
    with pytest.raises(ValueError, match=name):
        gauss_markov(**args)


def test_filter_validation_names_the_argument():
    obs, e, h, r, J, Phi, Qd, P0, N = random_problem(8, n_samples=10)
    model = WindModel(Phi, Qd, P0)
    good = dict(obs_sample=obs, e=e, h=h, r=r, J=J, model=model, n_samples=N)
    bad = [
        ("obs_sample", obs[::-1].copy()),
        ("obs_sample", obs.astype(float)),
        ("n_samples", int(obs.max())),
        ("e", e[:-1]),
        ("h", h[:, :2]),
        ("r", np.where(np.arange(r.size) == 0, 0.0, r)),
        ("J", J[:-1]),
        ("Phi", model._replace(Phi=Phi[:2])),
        ("Qd", model._replace(Qd=Qd + np.triu(np.ones_like(Qd), 1))),
        ("P0", model._replace(P0=P0[:2, :2])),
    ]
    for name, value in bad:
        key = "model" if name in WindModel._fields else name
        with pytest.raises(ValueError, match=name):
            innovations(**(good | {key: value}))
    smooth_good = {k: v for k, v in good.items() if k != "J"}
    with pytest.raises(ValueError, match="r"):
        smooth(**(smooth_good | {"r": -r}))


def test_a_singular_predicted_covariance_is_a_linear_algebra_error():
    """No process noise and no prior: the smoother's backward pass meets a singular predicted
    covariance and says so (a LinAlgError the solver turns into a verdict), not a division by zero."""
    obs = np.repeat(np.arange(10), 2)
    with pytest.raises(np.linalg.LinAlgError, match="singular"):
        smooth(obs, np.zeros(20), np.ones((20, 3)), np.ones(20),
               WindModel(np.eye(3), np.zeros((3, 3)), np.zeros((3, 3))), 10)
