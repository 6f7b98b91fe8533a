r"""RK4 integration of the FPR state equations together with their forward sensitivities.

States ``x = [u, v, w, phi, theta, psi, h]`` obey ``x' = f(x, a, omega)`` (SPEC §3, see
:mod:`estimator.core.kinematics`) with the bias- and lever-arm-corrected inputs::

    omega = omega_m - d_omega
    a     = a_m - d_a - omega_dot x r - omega x (omega x r),      r = r_imu - r_cg

The sensitivities ``S = dx/dp`` with respect to ``p = [x0 (7), d_a (3), d_omega (3)]`` obey the
variational equations (Jategaonkar 2006, §4.6)::

    S' = A S + F,   A = df/dx,   S(0) = [I_7 | 0 | 0]
    F[:, 7:10]  = -df/da
    F[:, 10:13] = df/da L - df/domega,   L = d(omega x (omega x r))/domega
                                           = (omega.r) I + omega r^T - 2 r omega^T

That is the SPEC's formulation (``lever_arm="differentiated"``), whose angular acceleration comes
from smoothed numerical differentiation of the rates and is only as good as that. The exact
alternative (``lever_arm="imu_point"``) integrates the velocity of the IMU point instead: with
``V_imu = V_cg + omega x r`` the lever-arm terms cancel identically, ::

    V_imu' = a_m - d_a + g_body - omega x V_imu

i.e. the same equations with zero lever arm and no angular acceleration. The attitude is the rigid
body's; the altitude stays the CG's, integrated with the CG's velocity ``V_imu - omega x r``::

    h' = (V_imu - omega x r) . n,   n = (sin theta, -cos theta sin phi, -cos theta cos phi)

so that ``dh'/d d_omega = r x n`` joins the forcing. The initial conditions ``x0[:3]`` remain the
CG's velocity: ``V_imu(0) = x0[:3] + omega(0) x r``, whence ``S(0)[:3, 10:13] = [r]x``. The kernels
take both lever arms — ``r_acc`` of the accelerations, ``r_h`` of the altitude and the initial
velocity — one of them zero, so either formulation is the same branch-free arithmetic (the
differentiated one bit-identical to a kernel without ``r_h``).

Both are stepped with the same classical RK4 scheme as the states (inputs at the half step from
:func:`estimator.core.kinematics.midpoints`, four-point cubic by default), so ``S`` is the exact
derivative of the discrete solution: Gauss-Newton sees the gradient of the cost it minimises.
Compiled with numba (cached on disk): the per-sample loop is the estimator's hot path. All
maneuvers of a problem are integrated in one compiled call (:func:`integrate_many`, inputs
concatenated once in :class:`Inputs`), with or without the sensitivities: the solver's trial
steps need only the states, which cost about a tenth.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple

import numpy as np
from numba import njit

from estimator.core.kinematics import midpoints

#: Lever-arm formulations (see the module docstring); the first is the estimator's default.
LEVER_ARMS = ("imu_point", "differentiated")
#: The parameters of the sensitivities ``S = dX/dp``, in their order: x0 (7), accelerometer
#: biases (3), gyro biases (3).
SENS_NAMES = ("u0", "v0", "w0", "phi0", "theta0", "psi0", "h0",
              "dax", "day", "daz", "dp", "dq", "dr")
N_SENS = len(SENS_NAMES)


@njit(cache=True, fastmath=False)
def _rhs(x, S, a_m, om_m, omd, r, rh, da, dw, g, xd, Sd):
    # r: lever arm of the accelerations (zero for the IMU point); rh: of the altitude's velocity
    # the states' derivative is _rhs_states' (one implementation: states with or without S agree)
    _rhs_states(x, a_m, om_m, omd, r, rh, da, dw, g, xd)
    # what the sensitivity part needs of the same quantities
    p, q, rr, odr, sph, cph, sth, cth, tth, qs_rc, qc_rs = _rates_and_angles(x, om_m, r, dw)
    u, v, w = x[0], x[1], x[2]
    # the CG's velocity V - om x rh (rh = 0: the state is the CG's velocity)
    uc = u - (q * rh[2] - rr * rh[1])
    vc = v - (rr * rh[0] - p * rh[2])
    wc = w - (p * rh[1] - q * rh[0])
    n0, n1, n2 = sth, -cth * sph, -cth * cph

    # S' = A S + F with A = df/dx written out by its non-zeros (psi and h never feed back)
    gc, gs = g * cth, g * sth
    a33 = qc_rs * tth
    a34 = qs_rc / (cth * cth)
    a53 = qc_rs / cth
    a54 = qs_rc * sth / (cth * cth)
    a63 = -vc * cth * cph + wc * cth * sph
    a64 = uc * cth + vc * sth * sph + wc * sth * cph
    for j in range(N_SENS):
        s0, s1, s2, s3, s4 = S[0, j], S[1, j], S[2, j], S[3, j], S[4, j]
        Sd[0, j] = rr * s1 - q * s2 - gc * s4
        Sd[1, j] = -rr * s0 + p * s2 + gc * cph * s3 - gs * sph * s4
        Sd[2, j] = q * s0 - p * s1 - gc * sph * s3 - gs * cph * s4
        Sd[3, j] = a33 * s3 + a34 * s4
        Sd[4, j] = -qs_rc * s3
        Sd[5, j] = a53 * s3 + a54 * s4
        Sd[6, j] = sth * s0 - cth * sph * s1 - cth * cph * s2 + a63 * s3 + a64 * s4
    # accelerometer biases: -df/da
    Sd[0, 7] -= 1.0
    Sd[1, 8] -= 1.0
    Sd[2, 9] -= 1.0
    # gyro biases: df/da L - df/domega, L = (om.r) I + om r^T - 2 r om^T
    om0, om1, om2 = p, q, rr
    for i in range(3):
        omi = om0 if i == 0 else (om1 if i == 1 else om2)
        Sd[i, 10] += (odr if i == 0 else 0.0) + omi * r[0] - 2.0 * r[i] * om0
        Sd[i, 11] += (odr if i == 1 else 0.0) + omi * r[1] - 2.0 * r[i] * om1
        Sd[i, 12] += (odr if i == 2 else 0.0) + omi * r[2] - 2.0 * r[i] * om2
    # - df/domega
    Sd[0, 11] += w
    Sd[0, 12] -= v
    Sd[1, 10] -= w
    Sd[1, 12] += u
    Sd[2, 10] += v
    Sd[2, 11] -= u
    Sd[3, 10] -= 1.0
    Sd[3, 11] -= sph * tth
    Sd[3, 12] -= cph * tth
    Sd[4, 11] -= cph
    Sd[4, 12] += sph
    Sd[5, 11] -= sph / cth
    Sd[5, 12] -= cph / cth
    # altitude: h' = (V - om x rh) . n = V . n - om . (rh x n), so dh'/d(d_omega) = rh x n
    Sd[6, 10] += rh[1] * n2 - rh[2] * n1
    Sd[6, 11] += rh[2] * n0 - rh[0] * n2
    Sd[6, 12] += rh[0] * n1 - rh[1] * n0


class ImuSamples(NamedTuple):
    """(N, 3) each: specific force at the IMU ``a`` (m/s^2), rates ``om`` (rad/s) and angular
    accelerations ``omd`` (rad/s^2)."""

    a: np.ndarray
    om: np.ndarray
    omd: np.ndarray


class Inputs:
    """The measured IMU inputs of many maneuvers, concatenated, with their half-step values.

    They never change during an estimation, so the midpoints are interpolated once.

    Parameters
    ----------
    seg : (K+1,) sample offsets: maneuver k is samples ``seg[k]:seg[k+1]``.
    t_s : (N,) sample times, s (each maneuver's own time base).
    measured : the measured specific force at the IMU, rates, angular accelerations (attributes
        ``a_m, om_m, omd``).
    half_steps : their half-step values (attributes ``a_mid, om_mid, omd_mid``): row ``i`` holds the
        midpoint between samples ``i`` and ``i + 1`` of the same maneuver (the last row of a
        maneuver is unused).
    r_imu_cg : (K, 3) IMU position minus CG position of each maneuver, body, m.
    lever_arm : the formulation, one of :data:`LEVER_ARMS`.
    """

    def __init__(self, seg, t_s, measured: ImuSamples, half_steps: ImuSamples, r_imu_cg,
                 lever_arm="differentiated"):
        if lever_arm not in LEVER_ARMS:
            raise ValueError(f"lever_arm must be one of {LEVER_ARMS}, got {lever_arm!r}")
        self.seg, self.t_s, self.r_imu_cg = seg, t_s, r_imu_cg
        self.a_m, self.om_m, self.omd = measured
        self.a_mid, self.om_mid, self.omd_mid = half_steps
        self.lever_arm = lever_arm
        # the kernels' two lever arms: of the accelerations, and of the altitude's velocity
        zero = np.zeros_like(r_imu_cg)
        imu = lever_arm == "imu_point"
        self.r_acc = zero if imu else r_imu_cg
        self.r_h = r_imu_cg if imu else zero

    @classmethod
    def concatenate(cls, t_s, a_m, om_m, omd, r_imu_cg, midpoint="cubic", lever_arm="differentiated"):
        """From per-maneuver lists of arrays (``t_s[k]`` (N_k,), ``a_m[k]`` (N_k, 3), ...)."""
        f64 = np.float64
        seg = np.concatenate([[0], np.cumsum([len(t) for t in t_s])]).astype(np.int64)

        def cat(parts):
            return np.ascontiguousarray(np.concatenate(parts), dtype=f64)

        mids = [cat([_padded_midpoints(np.asarray(v, dtype=f64), midpoint) for v in parts])
                for parts in (a_m, om_m, omd)]
        return cls(seg, cat(t_s), ImuSamples(cat(a_m), cat(om_m), cat(omd)), ImuSamples(*mids),
                   np.ascontiguousarray(np.reshape(r_imu_cg, (-1, 3)), dtype=f64), lever_arm=lever_arm)


def _padded_midpoints(v, midpoint):
    """``midpoints`` with a zero row appended so that row i is the midpoint after sample i."""
    return np.ascontiguousarray(np.vstack([midpoints(v, midpoint), np.zeros((1, 3))]))


def integrate_many(inputs: Inputs, params: np.ndarray, g: float, sensitivities: bool = True,
                   out_S: np.ndarray | None = None):
    """RK4 of the states (and their sensitivities) of many maneuvers in one compiled call.

    Parameters
    ----------
    inputs : the concatenated IMU data (:class:`Inputs`).
    params : (K, 13) per maneuver ``[x0 (7), da (3), dw (3)]``.
    g : gravity, m/s^2.
    sensitivities : also integrate ``S = dX/dparams``; without them (trial steps of the solver)
        the states cost about a tenth.
    out_S : (N, 7, 13) array to write the sensitivities into (overwritten). A caller that
        integrates repeatedly passes the same one: a fresh array this large comes from the
        operating system page by page, which can cost more than the integration.

    Returns
    -------
    X : (N, 7) states (with ``inputs.lever_arm == "imu_point"``, ``X[:, :3]`` is the IMU point's
    velocity); S : (N, 7, 13) sensitivities (``out_S`` if given), or None.
    """
    params = np.ascontiguousarray(params, dtype=np.float64)
    n = inputs.t_s.shape[0]
    X = np.empty((n, 7))
    if sensitivities:
        if out_S is None:
            out_S = np.empty((n, 7, N_SENS))
        elif out_S.shape != (n, 7, N_SENS) or not out_S.flags.c_contiguous:
            raise ValueError(f"out_S must be a C-contiguous ({n}, 7, {N_SENS}) array")
    K = inputs.seg.size - 1
    # maneuvers are independent: two halves (by samples) on two threads when there are two
    # cores (the kernels release the GIL; the second half is done before this returns)
    parts = [(0, K)]
    if worker_threads() > 1 and K > 1:
        half = int(np.searchsorted(inputs.seg, inputs.seg[-1] / 2))
        half = min(max(half, 1), K - 1)
        parts = [(0, half), (half, K)]

    def run(part):
        a, b = part
        args = (inputs.seg[a:b + 1], inputs.t_s, params[a:b], inputs.a_m, inputs.om_m, inputs.omd,
                inputs.a_mid, inputs.om_mid, inputs.omd_mid, inputs.r_acc[a:b], inputs.r_h[a:b],
                float(g), X)
        if sensitivities:
            _integrate_many(*args, out_S)
        else:
            _integrate_states_many(*args)

    if len(parts) == 1:
        run(parts[0])
    else:
        # the second half on the helper thread, the first here; each writes its own rows
        second = _helper_thread().submit(run, parts[1])
        try:
            run(parts[0])
        finally:  # never return (or raise) while the helper still writes into X and out_S
            second.result()
    return X, (out_S if sensitivities else None)


_HELPER: tuple[int, ThreadPoolExecutor] | None = None
_HELPER_LOCK = threading.Lock()


def _helper_thread() -> ThreadPoolExecutor:
    """One thread kept for :func:`integrate_many`'s second half: an estimation integrates a
    thousand times and more, and starting a thread each time cost about a sixth of a small
    problem's estimation. Made anew in a forked child (the parent's thread is not there)."""
    global _HELPER
    with _HELPER_LOCK:
        if _HELPER is None or _HELPER[0] != os.getpid():
            _HELPER = (os.getpid(), ThreadPoolExecutor(1, thread_name_prefix="fpr-rk4"))
        return _HELPER[1]


def worker_threads() -> int:
    """Worker threads for the estimator's compiled kernels: the cores, at most two (the work is
    split in two halves; more threads would mostly share memory bandwidth)."""
    return min(2, os.cpu_count() or 1)


@njit(cache=True, nogil=True)
def _initial_velocity(x, om_m, dw, rh):
    # the IMU point's velocity from the CG's (x[:3] on entry): V + om x rh (rh = 0: unchanged)
    p = om_m[0] - dw[0]
    q = om_m[1] - dw[1]
    rr = om_m[2] - dw[2]
    x[0] += q * rh[2] - rr * rh[1]
    x[1] += rr * rh[0] - p * rh[2]
    x[2] += p * rh[1] - q * rh[0]


@njit(cache=True, nogil=True)
def _maneuver_start(m, seg, params, om_m, r_acc, r_h, X):
    # maneuver m's first row X[seg[m]] (its initial states, the velocity moved to the IMU point)
    # and what its integration holds constant: lever arms, accelerometer and gyro biases, first row
    da = params[m, 7:10]
    dw = params[m, 10:13]
    b = seg[m]
    for i in range(7):  # a loop, not a slice assignment: no shape-check message to compile
        X[b, i] = params[m, i]
    _initial_velocity(X[b], om_m[b], dw, r_h[m])
    return r_acc[m], r_h[m], da, dw, b


@njit(cache=True, nogil=True)
def _integrate_many(seg, t_s, params, a_m, om_m, omd, a_mid, om_mid, omd_mid, r_acc, r_h, g, X, S):
    # maneuver m is samples seg[m]:seg[m+1] of the full arrays (seg may be a slice of offsets)
    k1x = np.empty(7)
    k2x = np.empty(7)
    k3x = np.empty(7)
    k4x = np.empty(7)
    k1s = np.empty((7, N_SENS))
    k2s = np.empty((7, N_SENS))
    k3s = np.empty((7, N_SENS))
    k4s = np.empty((7, N_SENS))
    xs = np.empty(7)
    Ss = np.empty((7, N_SENS))
    for m in range(seg.shape[0] - 1):
        r, rh, da, dw, b = _maneuver_start(m, seg, params, om_m, r_acc, r_h, X)
        S[b] = 0.0
        for i in range(7):
            S[b, i, i] = 1.0
        # d(om x rh)/d(d_omega) = [rh]x (om = om_m - d_omega)
        S[b, 0, 11] = -rh[2]
        S[b, 0, 12] = rh[1]
        S[b, 1, 10] = rh[2]
        S[b, 1, 12] = -rh[0]
        S[b, 2, 10] = -rh[1]
        S[b, 2, 11] = rh[0]
        for k in range(b, seg[m + 1] - 1):
            h = t_s[k + 1] - t_s[k]
            xk = X[k]
            Sk = S[k]
            _rhs(xk, Sk, a_m[k], om_m[k], omd[k], r, rh, da, dw, g, k1x, k1s)
            for i in range(7):
                xs[i] = xk[i] + 0.5 * h * k1x[i]
                for j in range(N_SENS):
                    Ss[i, j] = Sk[i, j] + 0.5 * h * k1s[i, j]
            _rhs(xs, Ss, a_mid[k], om_mid[k], omd_mid[k], r, rh, da, dw, g, k2x, k2s)
            for i in range(7):
                xs[i] = xk[i] + 0.5 * h * k2x[i]
                for j in range(N_SENS):
                    Ss[i, j] = Sk[i, j] + 0.5 * h * k2s[i, j]
            _rhs(xs, Ss, a_mid[k], om_mid[k], omd_mid[k], r, rh, da, dw, g, k3x, k3s)
            for i in range(7):
                xs[i] = xk[i] + h * k3x[i]
                for j in range(N_SENS):
                    Ss[i, j] = Sk[i, j] + h * k3s[i, j]
            _rhs(xs, Ss, a_m[k + 1], om_m[k + 1], omd[k + 1], r, rh, da, dw, g, k4x, k4s)
            h6 = h / 6.0
            for i in range(7):
                X[k + 1, i] = xk[i] + h6 * (k1x[i] + 2.0 * k2x[i] + 2.0 * k3x[i] + k4x[i])
                for j in range(N_SENS):
                    S[k + 1, i, j] = Sk[i, j] + h6 * (k1s[i, j] + 2.0 * k2s[i, j] + 2.0 * k3s[i, j]
                                                      + k4s[i, j])


@njit(cache=True, inline="always")
def _rates_and_angles(x, om_m, r, dw):
    # the body rates (gyro bias removed), om . r, and the Euler-angle terms of the state equations:
    # one computation for the states' right-hand side and the sensitivities' (_rhs); inlined by
    # numba (a call per right-hand side costs the states-only integration ~20 %)
    p = om_m[0] - dw[0]
    q = om_m[1] - dw[1]
    rr = om_m[2] - dw[2]
    odr = p * r[0] + q * r[1] + rr * r[2]
    phi, th = x[3], x[4]
    sph, cph = np.sin(phi), np.cos(phi)
    sth, cth = np.sin(th), np.cos(th)
    tth = sth / cth
    return p, q, rr, odr, sph, cph, sth, cth, tth, q * sph + rr * cph, q * cph - rr * sph


@njit(cache=True)
def _rhs_states(x, a_m, om_m, omd, r, rh, da, dw, g, xd):
    # the states' right-hand side; _rhs adds the sensitivities to it
    p, q, rr, odr, sph, cph, sth, cth, tth, qs_rc, qc_rs = _rates_and_angles(x, om_m, r, dw)
    oo = p * p + q * q + rr * rr
    ax = a_m[0] - da[0] - (omd[1] * r[2] - omd[2] * r[1]) - (p * odr - r[0] * oo)
    ay = a_m[1] - da[1] - (omd[2] * r[0] - omd[0] * r[2]) - (q * odr - r[1] * oo)
    az = a_m[2] - da[2] - (omd[0] * r[1] - omd[1] * r[0]) - (rr * odr - r[2] * oo)
    u, v, w = x[0], x[1], x[2]
    xd[0] = rr * v - q * w - g * sth + ax
    xd[1] = p * w - rr * u + g * cth * sph + ay
    xd[2] = q * u - p * v + g * cth * cph + az
    xd[3] = p + qs_rc * tth
    xd[4] = qc_rs
    xd[5] = qs_rc / cth
    u = u - (q * rh[2] - rr * rh[1])
    v = v - (rr * rh[0] - p * rh[2])
    w = w - (p * rh[1] - q * rh[0])
    xd[6] = u * sth - v * cth * sph - w * cth * cph


@njit(cache=True, nogil=True)
def _integrate_states_many(seg, t_s, params, a_m, om_m, omd, a_mid, om_mid, omd_mid, r_acc, r_h, g, X):
    k1x = np.empty(7)
    k2x = np.empty(7)
    k3x = np.empty(7)
    k4x = np.empty(7)
    xs = np.empty(7)
    for m in range(seg.shape[0] - 1):
        r, rh, da, dw, b = _maneuver_start(m, seg, params, om_m, r_acc, r_h, X)
        for k in range(b, seg[m + 1] - 1):
            h = t_s[k + 1] - t_s[k]
            xk = X[k]
            _rhs_states(xk, a_m[k], om_m[k], omd[k], r, rh, da, dw, g, k1x)
            for i in range(7):
                xs[i] = xk[i] + 0.5 * h * k1x[i]
            _rhs_states(xs, a_mid[k], om_mid[k], omd_mid[k], r, rh, da, dw, g, k2x)
            for i in range(7):
                xs[i] = xk[i] + 0.5 * h * k2x[i]
            _rhs_states(xs, a_mid[k], om_mid[k], omd_mid[k], r, rh, da, dw, g, k3x)
            for i in range(7):
                xs[i] = xk[i] + h * k3x[i]
            _rhs_states(xs, a_m[k + 1], om_m[k + 1], omd[k + 1], r, rh, da, dw, g, k4x)
            h6 = h / 6.0
            for i in range(7):
                X[k + 1, i] = xk[i] + h6 * (k1x[i] + 2.0 * k2x[i] + 2.0 * k3x[i] + k4x[i])
