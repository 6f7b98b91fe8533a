r"""Filter-error method for turbulent wind: Kalman-filter innovations of the output-error residuals.

**Why.** The output-error method fits the parameters ``theta`` to residuals ``e = z - y(theta)``
(per scalar observation: one channel at one sample) with their exact Jacobian ``J = dy/dtheta``.
In turbulence the air the flow sensors see moves relative to the ground by a random wind that no
parameter models: the residuals are coloured and the estimates biased. The filter-error method
(Maine & Iliff 1981; Jategaonkar, *Flight Vehicle System Identification*, 2006, ch. 5) carries the
turbulent wind as Gauss-Markov states and replaces the residuals by the innovations of a Kalman
filter on them.

**Measurement model, linearised.** A turbulent wind deviation ``s_k`` (NED, m/s, plus optional
states such as its integral) at sample ``k`` moves observation ``i`` (channel ``j`` at sample
``k``) by ``h_i . s_k`` (``h_i``: the channel's sensitivity to the wind, given)::

    e_i     = h_i . s_k + v_i,         v_i ~ N(0, r_i)     (independent scalar observations)
    s_{k+1} = Phi s_k + w_k,           w_k ~ N(0, Qd),     s_0 ~ N(0, P0)

**Gauss-Markov wind** (:func:`gauss_markov`). Each NED component is an independent first-order
Gauss-Markov (Ornstein-Uhlenbeck) process, frozen turbulence of scale ``L`` crossed at airspeed
``V`` (Taylor's hypothesis: correlation time ``T_c = L / V``)::

    dW/dt = -(V/L) W + sigma sqrt(2 V / L) eta,      eta: unit white noise
    E[W(t) W(t + tau)] = sigma^2 exp(-V |tau| / L)

This is the first-order Dryden form (MIL-F-8785C; MIL-HDBK-1797): its spectrum
``sigma^2 (2 L / pi) / (1 + (L Omega)^2)`` is Dryden's longitudinal one; using it for the lateral
and vertical components too replaces their second-order Dryden spectra by a first-order one of the
same variance and scale (the usual simplification for a filter state; Jategaonkar 2006, §5.2, §7).
Exact discretisation over ``dt`` (no Euler step; ``x = V dt / L``)::

    Phi = exp(-x),   Qd = sigma^2 (1 - Phi^2),   P0 = sigma^2   (stationary: Phi P0 Phi + Qd = P0)

With ``integrated_down`` a fourth state ``D = int W_d dt`` (m; the altitude error a vertical wind
causes) joins the down component. The pair ``(W_d, D)`` has ``A = [[-1/T_c, 0], [1, 0]]``, so::

    Phi_2 = [[exp(-x), 0], [T_c (1 - exp(-x)), 1]]
    Qd_2  = int_0^dt Phi_2(t) b b^T Phi_2(t)^T dt,   b = (sigma sqrt(2 / T_c), 0)
          = sigma^2 [[ (1 - E^2),    T_c (1 - E)^2 ],
                     [ T_c (1 - E)^2, 2 T_c^2 g(x) ]],   E = exp(-x),
    g(x)  = x - 2 (1 - E) + (1 - E^2) / 2 = x^3/3 - x^4/4 + ... = sum_{k>=3} (-1)^(k+1) (2^(k-1) - 2) x^k / k!

(``g`` by its series for small ``x``: the closed form cancels to ``x^3/3``). ``P0`` of ``D`` is 0:
the altitude error starts at zero at the maneuver start. Check: from a stationary ``W_d`` and
``D = 0``, ``Var D(dt) = T_c^2 (1 - E)^2 sigma^2 + Qd_2[1, 1] = 2 sigma^2 T_c^2 (x - 1 + E)``, the
variance of the integral of a stationary OU process over ``dt``.

**Dryden wind in body axes** (:func:`dryden_body`). MIL-F-8785C's Dryden turbulence (what JSBSim
generates with its Tustin-discretised model, turb-type 4, the synthesizer's default) has a
first-order longitudinal component ``u_g`` and second-order lateral and vertical ones ``v_g, w_g``
(body axes), each with the autocorrelation (``x = V tau / L``, ``tau`` the time lag)::

    R_u(tau) = sigma^2 exp(-x),        R_v(tau) = R_w(tau) = sigma^2 (1 - x / 2) exp(-x)

A lateral or vertical component is ``y = z_1 + sqrt(3) z_2`` of two states with, ``a = V / L``::

    d/dt [z_1, z_2] = a [[0, 1], [-1, -2]] [z_1, z_2] + [0, sigma sqrt(a)] eta

(the shaping filter ``sigma sqrt(L / V) (1 + sqrt(3) s L / V) / (1 + s L / V)^2``, its second
state scaled by ``L / V`` to m/s). Stationary: ``Var z_1 = Var z_2 = sigma^2 / 4``, uncorrelated,
so ``Var y = sigma^2``. Its ``A = -a I + N`` with ``N^2 = 0``, so exactly::

    Phi_2 = exp(-x) [[1 + x, x], [-x, 1 - x]],   x = V dt / L
    Qd_2  = P_inf - Phi_2 P_inf Phi_2^T,         P_inf = (sigma^2 / 4) I   (stationary)

Check: ``[1, sqrt(3)] Phi_2(tau) P_inf [1, sqrt(3)]^T = sigma^2 (1 - x / 2) exp(-x)``. The five
states ``(u, v_1, v_2, w_1, w_2)`` map to the body-axis wind by :data:`DRYDEN_OUTPUT`; a channel's
sensitivity to the states is its body-axis wind sensitivity times that map.

**Innovations** (:func:`innovations`). Kalman filter with zero prior mean; observations at one
sample are processed one after the other as scalars, each with its own gain (valid because the
measurement noise covariance is diagonal)::

    time update (per sample step):  x = Phi x,   P = Phi P Phi^T + Qd
    observation i:                  s_i = h_i^T P h_i + r_i,   nu_i = e_i - h_i . x
                                    K = P h_i / s_i,   x += K nu_i
                                    P = (I - K h_i^T) P (I - K h_i^T)^T + r_i K K^T   (Joseph)

and then ``P = (P + P^T) / 2``. The Joseph form is used because a rounding error in the gain
enters its ``P`` only to second order (the short form ``P - K h^T P`` takes it to first order and
can lose positive definiteness when a channel is much more precise than the wind's effect on it,
``r << h^T P h``: the update removes almost all of a direction's variance); with ``ns <= 4`` its
``O(ns^3)`` per observation is negligible beside the ``ns x m`` Jacobian update. Neither form is
exactly symmetric in floating point, hence the explicit symmetrisation (the time update computes
one triangle and mirrors it).

The gains do not depend on ``e``, so ``nu = L e`` with ``L`` unit lower-triangular; the
innovations are independent, ``Cov(nu) = diag(s)``, and ``C = Cov(e) = L^-1 diag(s) L^-T``. The
negative log-likelihood is therefore exactly the dense Gaussian one::

    -log p(e) = 0.5 sum_i (nu_i^2 / s_i + log(2 pi s_i)) = 0.5 (e^T C^-1 e + log det(2 pi C))

With ``de/dtheta = -J`` and the gains held fixed (the usual filter-error approximation: they
depend on the noise model, not on ``theta``), ``dnu/dtheta = -L J``, the same filter run on the
Jacobian's columns: a filtered-Jacobian state ``dx = dx/dtheta`` (``ns x m``) with::

    time update:   dx = Phi dx
    observation:   dnu_i = -J_i - h_i^T dx,   dx += K dnu_i          (rank-1)

**Gauss-Newton** (:func:`normal_equations`): ``H = sum dnu^T dnu / s``, ``g = -sum dnu^T nu / s``
(``g`` is the *negative* gradient of the cost), step ``delta = solve(H, g)``, ``theta += delta``.
For a linear model ``e = z - J theta`` one step is generalised least squares with the full
covariance ``C``: ``(J^T C^-1 J)^-1 J^T C^-1 z``.

**Smoother** (:func:`smooth`). Rauch, Tung & Striebel (1965) fixed-interval smoother, on the
filtered ``x_k|k, P_k|k`` and predicted ``x_k+1|k, P_k+1|k`` of every sample::

    G_k = P_k|k Phi^T P_k+1|k^-1
    x_k|N = x_k|k + G_k (x_k+1|N - x_k+1|k)
    P_k|N = P_k|k + G_k (P_k+1|N - P_k+1|k) G_k^T

i.e. ``E[s | e]`` and ``Cov(s | e)`` at every sample, given all observations.

**Left-out smoother** (:func:`smooth_left_out`). Each observation ``i`` belongs to a group
``g_i`` (a sensor); its prediction by the wind the *other* groups' observations give::

    p_i = h_i . E[s_k | e_j : g_j != g_i],      v_i = h_i^T Cov(s_k | e_j : g_j != g_i) h_i

one smoother run per group, on the observations of the others (the group's own are left out of
the measurement updates, not given a large ``r``: exactly, not nearly, independent of them). So
``e_i - p_i`` compares observation ``i`` with a wind it did not shape: an error of its own that
the other groups do not share stays in it, where ``e_i - h_i . E[s_k | e]`` would have it
partly absorbed by the wind (the smoother takes a step in one sensor for a gust).

**Cost.** The filter and smoother loops are compiled with numba (cached on disk). A maneuver of
3200 samples with 12 observations each and 150 Jacobian columns: :func:`innovations` ~25 ms,
:func:`normal_equations` ~30 ms (one-thread BLAS), :func:`smooth` ~10 ms (2-core machine, loaded).

Sources: Jategaonkar 2006, ch. 5 (filter-error method) and §7 (process noise, turbulence models);
Maine & Iliff, *Formulation and implementation of a practical algorithm for parameter estimation
with process and measurement noise*, SIAM J. Appl. Math. 41, 1981; Rauch, Tung & Striebel,
*Maximum likelihood estimates of linear dynamic systems*, AIAA J. 3, 1965; MIL-F-8785C (1980) and
MIL-HDBK-1797 (1997), Dryden turbulence.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit
from scipy.special import gammainc
from threadpoolctl import threadpool_limits


class WindModel(NamedTuple):
    """A wind-state model per sample, SI: ``Phi`` (ns, ns) state transition, ``Qd`` (ns, ns)
    process-noise covariance and ``P0`` (ns, ns) initial state covariance, prior mean zero (as
    :func:`gauss_markov` and :func:`dryden_body` give)."""

    Phi: np.ndarray
    Qd: np.ndarray
    P0: np.ndarray


#: Below this ``x = V dt / L`` the integrated state's ``g(x)`` is summed as its series (the closed
#: form loses ~1/x of its digits to cancellation; the series converges to rounding in 30 terms).
_SERIES_BELOW = 0.5
_SERIES_TERMS = 30


# ----------------------------------------------------------------------------------------------
# Gauss-Markov wind model
# ----------------------------------------------------------------------------------------------

def _positive_finite(name: str, value, shape_ok: tuple[int, ...], what: str) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.ndim > 1 or (a.ndim == 1 and a.shape[0] not in shape_ok):
        raise ValueError(f"{name} must be {what}; got shape {a.shape}")
    if not np.all(np.isfinite(a)) or np.any(a <= 0.0):
        raise ValueError(f"{name} must be positive and finite ({what}); got {value!r}. "
                         f"Give a value > 0 in SI units")
    return a


def _g_integrated(x: float) -> float:
    """``g(x) = x - 2 (1 - e^-x) + (1 - e^-2x) / 2``, accurate for small ``x`` (module docstring)."""
    if x >= _SERIES_BELOW:
        em = -math.expm1(-x)
        return x - 2.0 * em + 0.5 * em * (2.0 - em)
    total = 0.0
    term = 0.5 * x * x  # x^k / k! for k = 2
    for k in range(3, _SERIES_TERMS + 3):
        term *= x / k
        total += (1.0 if k % 2 else -1.0) * (2.0 ** (k - 1) - 2.0) * term
    return total


def gauss_markov(v_mps: float, L_m, sigma_mps, dt_s: float,
                 integrated_down: bool = False) -> WindModel:
    """Exact discretisation of three independent first-order Gauss-Markov wind components.

    Parameters
    ----------
    v_mps : true airspeed, m/s (turbulence scale crossed per second; Taylor's hypothesis).
    L_m : turbulence scale length, m: a scalar, or (3,) per NED axis (north, east, down).
    sigma_mps : stationary standard deviation of the wind, m/s: a scalar or (3,) per NED axis.
    dt_s : sample interval, s.
    integrated_down : add a 4th state, the integral of the down component (m), starting at zero.

    Returns
    -------
    Phi : (ns, ns) state transition over ``dt_s`` (ns = 3, or 4 with ``integrated_down``).
    Qd : (ns, ns) process-noise covariance per step, (m/s)^2 (m^2, m^2/s for the integral).
    P0 : (ns, ns) initial covariance: the stationary wind variance; 0 for the integral.
    """
    v = _positive_finite("v_mps", v_mps, (), "a scalar airspeed in m/s")
    dt = _positive_finite("dt_s", dt_s, (), "a scalar sample interval in s")
    L = np.broadcast_to(_positive_finite("L_m", L_m, (3,), "a scalar or a length-3 (N, E, D) scale in m"),
                        (3,))
    sig = np.broadcast_to(_positive_finite("sigma_mps", sigma_mps, (3,),
                                           "a scalar or a length-3 (N, E, D) standard deviation in m/s"),
                          (3,))
    x = float(v) * float(dt) / L
    em = -np.expm1(-x)  # 1 - Phi, accurate for small x
    phi = 1.0 - em
    ns = 4 if integrated_down else 3
    Phi = np.zeros((ns, ns))
    Qd = np.zeros((ns, ns))
    P0 = np.zeros((ns, ns))
    for a in range(3):
        Phi[a, a] = phi[a]
        Qd[a, a] = sig[a] ** 2 * em[a] * (2.0 - em[a])  # sigma^2 (1 - Phi^2)
        P0[a, a] = sig[a] ** 2
    if integrated_down:
        tc = L[2] / float(v)
        s2 = sig[2] ** 2
        Phi[3, 2] = tc * em[2]
        Phi[3, 3] = 1.0
        Qd[2, 3] = Qd[3, 2] = s2 * tc * em[2] ** 2
        Qd[3, 3] = 2.0 * s2 * tc * tc * _g_integrated(float(x[2]))
    return WindModel(Phi, Qd, P0)


#: The body-axis wind (u, v, w) from :func:`dryden_body`'s five states (u, v_1, v_2, w_1, w_2).
DRYDEN_OUTPUT = np.array([[1.0, 0.0, 0.0, 0.0, 0.0],
                          [0.0, 1.0, math.sqrt(3.0), 0.0, 0.0],
                          [0.0, 0.0, 0.0, 1.0, math.sqrt(3.0)]])


def dryden_body(v_mps: float, L_m: float, sigma_mps: float, dt_s: float
                ) -> WindModel:
    """Exact discretisation of MIL-F-8785C's Dryden turbulence in body axes (module docstring).

    Parameters
    ----------
    v_mps : true airspeed, m/s (turbulence scale crossed per second; Taylor's hypothesis).
    L_m : turbulence scale length, m (one for the three axes: MIL-F-8785C above 2000 ft).
    sigma_mps : standard deviation of each component, m/s (isotropic above 2000 ft).
    dt_s : sample interval, s.

    Returns
    -------
    Phi : (5, 5) state transition over ``dt_s``; states (u, v_1, v_2, w_1, w_2), m/s.
    Qd : (5, 5) process-noise covariance per step, (m/s)^2, positive definite.
    P0 : (5, 5) the stationary covariance (u: sigma^2; each second-order state sigma^2 / 4).
    """
    v = float(_positive_finite("v_mps", v_mps, (), "a scalar airspeed in m/s"))
    dt = float(_positive_finite("dt_s", dt_s, (), "a scalar sample interval in s"))
    L = float(_positive_finite("L_m", L_m, (), "a scalar scale length in m"))
    sig = float(_positive_finite("sigma_mps", sigma_mps, (), "a scalar standard deviation in m/s"))
    x = v * dt / L
    em = -math.expm1(-x)  # 1 - exp(-x), accurate for small x
    E = 1.0 - em
    Phi = np.zeros((5, 5))
    P0 = np.zeros((5, 5))
    Qd = np.zeros((5, 5))
    Phi[0, 0] = E
    P0[0, 0] = sig * sig
    Qd[0, 0] = sig * sig * em * (2.0 - em)  # sigma^2 (1 - E^2)
    q = 0.25 * sig * sig
    # P_inf - Phi_2 P_inf Phi_2^T with P_inf = q I, Phi_2 = E [[1 + x, x], [-x, 1 - x]], y = 2x:
    #   [0, 0]: q (1 - e^-y (1 + y + y^2/2)) = q P(3, y), the regularised lower incomplete gamma
    #           function (O(x^3) for small x: written as the difference, it cancels to noise)
    #   [1, 1]: q (1 - e^-y (1 - y + y^2/2)) = q (P(3, y) + 2 y e^-y)
    #   [0, 1]: -q E^2 (-x (1 + x) + x (1 - x)) = q e^-y y^2 / 2
    y = 2.0 * x
    p3 = float(gammainc(3.0, y))
    for i in (1, 3):
        Phi[i:i + 2, i:i + 2] = E * np.array([[1.0 + x, x], [-x, 1.0 - x]])
        P0[i, i] = P0[i + 1, i + 1] = q
        Qd[i, i] = q * p3
        Qd[i + 1, i + 1] = q * (p3 + 2.0 * y * E * E)
        Qd[i, i + 1] = Qd[i + 1, i] = 0.5 * q * E * E * y * y
    return WindModel(Phi, Qd, P0)


# ----------------------------------------------------------------------------------------------
# Compiled filter and smoother
# ----------------------------------------------------------------------------------------------

@njit(cache=True, nogil=True)
def _time_update(Phi, Qd, x, P, xt, T):
    """``x = Phi x``, ``P = Phi P Phi^T + Qd`` in place, ``P`` symmetrised."""
    ns = x.shape[0]
    for a in range(ns):
        acc = 0.0
        for c in range(ns):
            acc += Phi[a, c] * x[c]
        xt[a] = acc
    for a in range(ns):  # loops, not slice assignments: no shape-check message to compile
        x[a] = xt[a]
    for a in range(ns):  # T = Phi P
        for b in range(ns):
            acc = 0.0
            for c in range(ns):
                acc += Phi[a, c] * P[c, b]
            T[a, b] = acc
    for a in range(ns):  # P = T Phi^T + Qd: one triangle, mirrored (exactly symmetric)
        for b in range(a, ns):
            acc = Qd[a, b]
            for c in range(ns):
                acc += T[a, c] * Phi[b, c]
            P[a, b] = acc
            P[b, a] = acc


@njit(cache=True, nogil=True)
def _jacobian_time_update(Phi, dx, dxt):
    """``dx = Phi dx`` (ns x m) in place; zero entries of ``Phi`` (a diagonal wind model) skipped."""
    ns = dx.shape[0]
    m = dx.shape[1]
    dxt[:, :] = 0.0
    for a in range(ns):
        for c in range(ns):
            f = Phi[a, c]
            if f != 0.0:
                for j in range(m):
                    dxt[a, j] += f * dx[c, j]
    for a in range(ns):
        for j in range(m):
            dx[a, j] = dxt[a, j]


@njit(cache=True, nogil=True)
def _scalar_update(hrow, r, e, x, P, K, hP, T, Th):
    """One scalar observation: innovation and its variance; ``x``, ``P`` updated (Joseph, symmetrised),
    the gain left in ``K``."""
    ns = x.shape[0]
    pred = 0.0
    for a in range(ns):
        acc = 0.0
        for b in range(ns):
            acc += P[a, b] * hrow[b]
        hP[a] = acc
        pred += hrow[a] * x[a]
    s = r
    for a in range(ns):
        s += hrow[a] * hP[a]
    nu = e - pred
    for a in range(ns):
        K[a] = hP[a] / s
        x[a] += K[a] * nu
    # Joseph form: P = A P A^T + r K K^T with A = I - K h^T. T = A P, then T A^T = T - (T h) K^T
    for a in range(ns):
        for b in range(ns):
            T[a, b] = P[a, b] - K[a] * hP[b]
    for a in range(ns):
        acc = 0.0
        for c in range(ns):
            acc += T[a, c] * hrow[c]
        Th[a] = acc
    for a in range(ns):
        for b in range(ns):
            P[a, b] = T[a, b] - Th[a] * K[b] + r * K[a] * K[b]
    for a in range(ns):
        for b in range(a):
            P[a, b] = 0.5 * (P[a, b] + P[b, a])
            P[b, a] = P[a, b]
    return nu, s


@njit(cache=True, nogil=True)
def _filter(obs_sample, e, h, r, J, Phi, Qd, P0, nu, s, dnu):
    """Innovations, their variances and Jacobian (written into ``nu``, ``s``, ``dnu``); returns the
    negative log-likelihood."""
    n = e.shape[0]
    ns = Phi.shape[0]
    m = J.shape[1]
    x = np.zeros(ns)
    P = P0.copy()
    dx = np.zeros((ns, m))
    xt = np.zeros(ns)
    T = np.zeros((ns, ns))
    dxt = np.zeros((ns, m))
    K = np.zeros(ns)
    hP = np.zeros(ns)
    Th = np.zeros(ns)
    log2pi = math.log(2.0 * math.pi)
    nll = 0.0
    k = 0  # the sample x, P, dx are at
    for i in range(n):
        while k < obs_sample[i]:
            _time_update(Phi, Qd, x, P, xt, T)
            if m > 0:
                _jacobian_time_update(Phi, dx, dxt)
            k += 1
        nui, si = _scalar_update(h[i], r[i], e[i], x, P, K, hP, T, Th)
        nu[i] = nui
        s[i] = si
        nll += 0.5 * (nui * nui / si + math.log(si) + log2pi)
        if m > 0:
            # dnu = -J_i - h^T dx (the gains fixed), then dx += K dnu; row-wise, contiguous in m
            for j in range(m):
                dnu[i, j] = -J[i, j]
            for a in range(ns):
                ha = h[i, a]
                if ha != 0.0:
                    for j in range(m):
                        dnu[i, j] -= ha * dx[a, j]
            for a in range(ns):
                ka = K[a]
                if ka != 0.0:
                    for j in range(m):
                        dx[a, j] += ka * dnu[i, j]
    return nll


@njit(cache=True, nogil=True)
def _rts(obs_sample, e, h, r, Phi, Qd, P0, n_samples, xs, Ps):
    """Kalman filter over every sample, then the RTS backward pass (results in ``xs``, ``Ps``)."""
    n = e.shape[0]
    ns = Phi.shape[0]
    xp = np.zeros((n_samples, ns))  # predicted (prior) at each sample
    Pp = np.zeros((n_samples, ns, ns))
    x = np.zeros(ns)
    P = P0.copy()
    xt = np.zeros(ns)
    T = np.zeros((ns, ns))
    K = np.zeros(ns)
    hP = np.zeros(ns)
    Th = np.zeros(ns)
    i = 0
    for k in range(n_samples):
        if k > 0:
            _time_update(Phi, Qd, x, P, xt, T)
        # element by element: a whole-row assignment makes numba compile its shape-mismatch message
        # (about 3 s of every cold start) for copies whose shapes cannot mismatch
        _copy_state(x, P, xp, Pp, k)
        while i < n and obs_sample[i] == k:
            _scalar_update(h[i], r[i], e[i], x, P, K, hP, T, Th)
            i += 1
        _copy_state(x, P, xs, Ps, k)  # filtered, overwritten by the backward pass below
    # the backward pass in place, without allocations (one small solve per sample)
    dxk = np.zeros(ns)
    A = np.zeros((ns, ns))
    M = np.zeros((ns, ns))
    Gt = np.zeros((ns, ns))
    W = np.zeros((ns, ns))
    for k in range(n_samples - 2, -1, -1):
        # G^T = P_k+1|k^-1 Phi P_k|k  (P_k+1|k symmetric)
        for a in range(ns):
            for b in range(ns):
                acc = 0.0
                for c in range(ns):
                    acc += Phi[a, c] * Ps[k, c, b]
                A[a, b] = acc
                M[a, b] = Pp[k + 1, a, b]
        _solve_in_place(M, A, Gt)
        # x_k += G (x_k+1|N - x_k+1|k);  P_k += G (P_k+1|N - P_k+1|k) G^T
        for a in range(ns):
            dxk[a] = xs[k + 1, a] - xp[k + 1, a]
        for a in range(ns):
            acc = 0.0
            for b in range(ns):
                acc += Gt[b, a] * dxk[b]
            xs[k, a] += acc
        for a in range(ns):  # W = (P_k+1|N - P_k+1|k) G^T
            for b in range(ns):
                acc = 0.0
                for c in range(ns):
                    acc += (Ps[k + 1, a, c] - Pp[k + 1, a, c]) * Gt[c, b]
                W[a, b] = acc
        for a in range(ns):
            for b in range(a + 1):
                acc = 0.0
                for c in range(ns):
                    acc += Gt[c, a] * W[c, b]
                # symmetrised: the mean of (a, b) and (b, a) of P_k + G dP G^T
                acc2 = 0.0
                for c in range(ns):
                    acc2 += Gt[c, b] * W[c, a]
                v = 0.5 * (Ps[k, a, b] + Ps[k, b, a] + acc + acc2)
                Ps[k, a, b] = v
                Ps[k, b, a] = v


@njit(cache=True, nogil=True)
def _copy_state(x, P, xs, Ps, k):
    """``xs[k] = x``, ``Ps[k] = P``."""
    ns = x.shape[0]
    for a in range(ns):
        xs[k, a] = x[a]
        for b in range(ns):
            Ps[k, a, b] = P[a, b]


@njit(cache=True, nogil=True)
def _solve_in_place(M, B, X):
    """``X = M^-1 B`` for a small non-singular ``M`` (Gaussian elimination with partial pivoting;
    ``M`` and ``B`` are overwritten)."""
    n = M.shape[0]
    m = B.shape[1]
    for col in range(n):
        piv = col
        big = abs(M[col, col])
        for i in range(col + 1, n):
            if abs(M[i, col]) > big:
                big = abs(M[i, col])
                piv = i
        if piv != col:
            for j in range(n):
                M[col, j], M[piv, j] = M[piv, j], M[col, j]
            for j in range(m):
                B[col, j], B[piv, j] = B[piv, j], B[col, j]
        d = M[col, col]
        for i in range(col + 1, n):
            f = M[i, col] / d
            if f != 0.0:
                for j in range(col, n):
                    M[i, j] -= f * M[col, j]
                for j in range(m):
                    B[i, j] -= f * B[col, j]
    for i in range(n - 1, -1, -1):
        for j in range(m):
            acc = B[i, j]
            for c in range(i + 1, n):
                acc -= M[i, c] * X[c, j]
            X[i, j] = acc / M[i, i]


# ----------------------------------------------------------------------------------------------
# Public functions
# ----------------------------------------------------------------------------------------------

def _check_model(obs_sample, e, h, r, model: WindModel, n_samples):
    """Validated, contiguous float64 / int64 copies of the common inputs."""
    Phi, Qd, P0 = model
    obs = np.asarray(obs_sample)
    if obs.ndim != 1 or (obs.size and not np.issubdtype(obs.dtype, np.integer)):
        raise ValueError(f"obs_sample must be a 1-D integer array of sample indices; got dtype "
                         f"{obs.dtype}, shape {obs.shape}")
    obs = np.ascontiguousarray(obs, dtype=np.int64)
    n = obs.shape[0]
    if int(n_samples) != n_samples or n_samples < 0:
        raise ValueError(f"n_samples must be a non-negative integer; got {n_samples!r}")
    n_samples = int(n_samples)
    if n and (obs[0] < 0 or obs[-1] >= n_samples):
        raise ValueError(f"obs_sample must lie in 0..n_samples-1 = 0..{n_samples - 1}; got "
                         f"{obs.min()}..{obs.max()}")
    if n > 1 and np.any(np.diff(obs) < 0):
        raise ValueError("obs_sample must be non-decreasing (observations ordered by sample); "
                         "sort the observations by sample, e.g. with np.argsort(obs_sample, kind='stable')")
    e = np.ascontiguousarray(e, dtype=float)
    if e.shape != (n,):
        raise ValueError(f"e must have shape (n,) = ({n},) like obs_sample; got {e.shape}")
    Phi = np.ascontiguousarray(Phi, dtype=float)
    if Phi.ndim != 2 or Phi.shape[0] != Phi.shape[1] or Phi.shape[0] == 0:
        raise ValueError(f"Phi must be a square (ns, ns) state transition; got shape {Phi.shape}")
    ns = Phi.shape[0]
    h = np.ascontiguousarray(h, dtype=float)
    if h.shape != (n, ns):
        raise ValueError(f"h must have shape (n, ns) = ({n}, {ns}); got {h.shape}")
    r = np.ascontiguousarray(r, dtype=float)
    if r.shape != (n,):
        raise ValueError(f"r must have shape (n,) = ({n},); got {r.shape}")
    if not np.all(np.isfinite(r)) or np.any(r <= 0.0):
        raise ValueError("r (measurement noise variances) must be positive and finite; give each "
                         "observation its noise variance > 0")
    for name, a in (("e", e), ("h", h), ("Phi", Phi)):
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be finite (no NaN or inf)")
    mats = []
    for name, a in (("Qd", Qd), ("P0", P0)):
        a = np.ascontiguousarray(a, dtype=float)
        if a.shape != (ns, ns):
            raise ValueError(f"{name} must have shape (ns, ns) = ({ns}, {ns}) like Phi; got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be finite (no NaN or inf)")
        scale = max(float(np.max(np.abs(a))), np.finfo(float).tiny)
        if np.max(np.abs(a - a.T)) > 1e-12 * scale or np.any(np.diag(a) < 0.0):
            raise ValueError(f"{name} must be a symmetric covariance with a non-negative diagonal")
        mats.append(a)
    return obs, e, h, r, Phi, mats[0], mats[1], n_samples


def innovations(obs_sample: np.ndarray, e: np.ndarray, h: np.ndarray, r: np.ndarray, J: np.ndarray,
                model: WindModel, n_samples: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Kalman-filter innovations of the residuals, their variances and Jacobian, and the likelihood.

    Parameters
    ----------
    obs_sample : (n,) int, the sample index of each scalar observation, non-decreasing in
        ``0 .. n_samples - 1``; observations of one sample are processed in the given order.
    e : (n,) residuals ``z - y(theta)``, the channel's SI unit.
    h : (n, ns) sensitivity of each observation to the wind states (channel unit per state unit,
        e.g. rad per m/s).
    r : (n,) measurement-noise variances, > 0 (channel unit squared).
    J : (n, m) Jacobian rows ``dy/dtheta`` (m may be 0).
    model : :class:`WindModel` ``(Phi, Qd, P0)``, each (ns, ns): state transition per sample,
        process-noise covariance per sample and initial state covariance (e.g. from
        :func:`gauss_markov`); prior mean zero.
    n_samples : number of samples of the maneuver.

    Returns
    -------
    nu : (n,) innovations, channel unit.
    s : (n,) innovation variances.
    dnu : (n, m) ``d nu / d theta = -L J`` (gains fixed).
    nll : the negative log-likelihood ``0.5 sum(nu^2 / s + log(2 pi s))``.
    """
    obs, e, h, r, Phi, Qd, P0, n_samples = _check_model(obs_sample, e, h, r, model, n_samples)
    n = obs.shape[0]
    J = np.ascontiguousarray(J, dtype=float)
    if J.ndim != 2 or J.shape[0] != n:
        raise ValueError(f"J must have shape (n, m) = ({n}, m); got {J.shape}")
    if not np.all(np.isfinite(J)):
        raise ValueError("J must be finite (no NaN or inf)")
    nu = np.empty(n)
    s = np.empty(n)
    dnu = np.empty((n, J.shape[1]))
    nll = _filter(obs, e, h, r, J, Phi, Qd, P0, nu, s, dnu) if n else 0.0
    return nu, s, dnu, float(nll)


def normal_equations(nu: np.ndarray, s: np.ndarray, dnu: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Gauss-Newton normal equations of the filter-error cost.

    Parameters
    ----------
    nu, s, dnu : from :func:`innovations`: (n,), (n,), (n, m).

    Returns
    -------
    H : (m, m) ``sum dnu^T dnu / s`` (Gauss-Newton Hessian of the cost).
    g : (m,) ``-sum dnu^T nu / s``, the *negative* gradient: the step is ``theta += solve(H, g)``.
    cost : the negative log-likelihood ``0.5 sum(nu^2 / s + log(2 pi s))``.
    """
    nu = np.asarray(nu, dtype=float)
    s = np.asarray(s, dtype=float)
    dnu = np.asarray(dnu, dtype=float)
    if nu.ndim != 1 or s.shape != nu.shape or dnu.ndim != 2 or dnu.shape[0] != nu.shape[0]:
        raise ValueError(f"nu (n,), s (n,) and dnu (n, m) must agree; got {nu.shape}, {s.shape}, "
                         f"{dnu.shape}")
    if np.any(s <= 0.0):
        raise ValueError("s (innovation variances) must be positive")
    A = dnu * (1.0 / np.sqrt(s))[:, None]  # whitened rows: H = A^T A
    # one BLAS thread: on the project's two busy cores OpenBLAS's threads make this 40 times slower
    # (0.8 s against 0.02 s for 38400 x 150); a compiled Gram loop was 0.12 s
    with threadpool_limits(limits=1, user_api="blas"):
        H = A.T @ A
        g = -(dnu.T @ (nu / s))
    H = 0.5 * (H + H.T)
    cost = 0.5 * float(np.sum(nu * nu / s + np.log(2.0 * np.pi * s)))
    return H, g, cost


def smooth(obs_sample: np.ndarray, e: np.ndarray, h: np.ndarray, r: np.ndarray, model: WindModel,
           n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Rauch-Tung-Striebel fixed-interval smoother: the wind states given all the residuals.

    Parameters
    ----------
    obs_sample, e, h, r, model, n_samples : as :func:`innovations`. The predicted
        covariances ``Phi P Phi^T + Qd`` must be non-singular (true for a positive-definite ``Qd``,
        as :func:`gauss_markov` gives).

    Returns
    -------
    x_s : (n_samples, ns) smoothed state mean ``E[s_k | e]`` (state units, e.g. m/s NED).
    P_s : (n_samples, ns, ns) smoothed covariance ``Cov(s_k | e)``.

    Raises
    ------
    numpy.linalg.LinAlgError
        If a predicted covariance is singular.
    """
    obs, e, h, r, Phi, Qd, P0, n_samples = _check_model(obs_sample, e, h, r, model, n_samples)
    ns = Phi.shape[0]
    xs = np.zeros((n_samples, ns))
    Ps = np.zeros((n_samples, ns, ns))
    if n_samples:
        try:
            _rts(obs, e, h, r, Phi, Qd, P0, n_samples, xs, Ps)
        except ZeroDivisionError:
            # the backward pass solves with each predicted covariance: one was singular
            raise np.linalg.LinAlgError(
                "smooth: a predicted covariance Phi P Phi^T + Qd is singular; give a positive-definite "
                "Qd (gauss_markov's is)") from None
    return xs, Ps


def smooth_left_out(obs_sample: np.ndarray, e: np.ndarray, h: np.ndarray, r: np.ndarray,
                    group: np.ndarray, model: WindModel, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Each observation's prediction by the wind smoothed from the other groups' observations.

    Parameters
    ----------
    obs_sample, e, h, r, model, n_samples : as :func:`smooth` (``e`` the residuals, the
        channel's SI unit; ``h`` their sensitivity to the wind states, e.g. rad per m/s).
    group : (n,) int, each observation's group (e.g. its sensor): the observations of a group are
        left out of the smoother that predicts them.

    Returns
    -------
    p : (n,) ``h_i . E[s_k | e_j : group_j != group_i]``, the observation's response to that
        wind, the channel's unit (module docstring). 0 where ``h_i`` is zero (an observation that
        does not see the wind: its group's smoother is not run when all its rows are zero).
    v : (n,) its variance ``h_i^T Cov(s_k | e_j : group_j != group_i) h_i`` (channel unit squared).

    Raises
    ------
    ValueError
        Inputs of the wrong shape or values (as :func:`smooth`); ``group`` not one integer per
        observation.
    numpy.linalg.LinAlgError
        If a predicted covariance is singular (as :func:`smooth`).
    """
    obs, e, h, r, Phi, Qd, P0, n_samples = _check_model(obs_sample, e, h, r, model, n_samples)
    g = np.asarray(group)
    if g.shape != obs.shape or (g.size and not np.issubdtype(g.dtype, np.integer)):
        raise ValueError(f"group must be one integer per observation, shape ({obs.size},); got dtype "
                         f"{g.dtype}, shape {g.shape}")
    p = np.zeros(obs.size)
    v = np.zeros(obs.size)
    for k in np.unique(g):
        own = g == k
        if not np.any(h[own]):
            continue  # nothing of the group sees the wind: its prediction is zero
        other = ~own
        # the subset keeps the observations' order, so obs_sample stays non-decreasing
        xs, Ps = smooth(obs[other], e[other], h[other], r[other], WindModel(Phi, Qd, P0), n_samples)
        at, hk = obs[own], h[own]
        p[own] = np.einsum("ni,ni->n", hk, xs[at])
        v[own] = np.einsum("ni,nij,nj->n", hk, Ps[at], hk)
    return p, v
