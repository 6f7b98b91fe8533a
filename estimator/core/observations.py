r"""Model signals for the observation equations, with their derivatives.

From the reconstructed states ``x = [u, v, w, phi, theta, psi, h]`` and the bias-corrected rates
``omega``, the air velocity at a sensor at ``r_s`` (body axes, from the CG) is the exact rigid-body
velocity (SPEC §3; the paper's Eq. 6 is its small-angle form)::

    V_s = V + omega x (r_s - r_cg)

and the angles a sensor can sense are::

    alpha_s = atan2(w_s, u_s)          angle of attack
    beta_s  = asin(v_s / |V_s|)        aerodynamic sideslip
    flank_s = atan2(v_s, u_s)          flank angle (what a sideslip vane senses)

At the CG (``r_s = r_cg``) these are ``alpha_t``, ``beta_t`` and ``tas_t = |V|``. The components
of ``V_s`` themselves (``u_s, v_s, w_s``) are what an inertial velocity at the sensor is, less the
steady wind (:mod:`estimator.problem`).

Each function returns the signal and its derivatives with respect to ``(u, v, w)`` and to
``omega`` (so the estimator can chain them to the state sensitivities and to the gyro biases).
"""

from __future__ import annotations

import numpy as np
from numba import njit

_KIND_CODE = {"alpha": 0, "beta": 1, "flank": 2, "tas": 3, "u": 4, "v": 5, "w": 6}


def flow_signal_batch(X: np.ndarray, omega: np.ndarray | None, r_cg: np.ndarray | None,
                      sensor: np.ndarray | None, kind: str, derivatives: bool,
                      dv_out: np.ndarray | None = None, b_out: np.ndarray | None = None):
    """:func:`angle_signal` of the velocity at a sensor, for concatenated maneuvers, in one pass.

    Parameters
    ----------
    X : (N, 7) states; omega : (N, 3) bias-corrected rates; r_cg : (N, 3) CG of each sample's
        maneuver; sensor : (3,) sensor position, or None for the CG (then ``omega``, ``r_cg`` unused).
    kind : "alpha", "beta", "flank", "tas", or "u", "v", "w" (a component of ``V_s`` itself).
    derivatives : also the derivatives.
    dv_out, b_out : (N, 3) arrays to write the derivatives into (else new ones).

    Returns
    -------
    value (N,), and if ``derivatives``: d value / d(u, v, w) (N, 3) and, for a sensor, the direct
    derivative with respect to the gyro biases (N, 3) (``V_s`` depends on
    ``omega = omega_m - d_omega``), else None. The same arithmetic as :func:`angle_signal` on
    ``V + omega x (r_s - r_cg)`` and the model's chain rule, operation for operation; the
    transcendental functions stay numpy's, so the values are those of the array code exactly.
    """
    n = X.shape[0]
    vs = np.empty((n, 3))
    has_sensor = sensor is not None
    if has_sensor:
        _sensor_velocity(X, omega, r_cg, np.asarray(sensor, dtype=float), vs)
    else:
        vs[:] = X[:, :3]
    u, v, w = vs[:, 0], vs[:, 1], vs[:, 2]
    if kind == "alpha":
        val = np.arctan2(w, u)
    elif kind == "beta":
        val = np.arcsin(v / np.sqrt(u * u + w * w + v * v))
    elif kind == "flank":
        val = np.arctan2(v, u)
    elif kind == "tas":
        val = np.sqrt(u * u + w * w + v * v)
    elif kind in ("u", "v", "w"):
        val = vs[:, "uvw".index(kind)].copy()
    else:
        raise ValueError(f"unknown flow signal {kind!r}; one of alpha, beta, flank, tas, u, v, w")
    if not derivatives:
        return val, None, None
    dv = np.empty((n, 3)) if dv_out is None else dv_out
    b = (np.empty((n, 3)) if b_out is None else b_out) if has_sensor else np.empty((0, 3))
    _flow_derivatives(vs, _KIND_CODE[kind], r_cg if has_sensor else np.empty((0, 3)),
                      np.asarray(sensor if has_sensor else np.zeros(3), dtype=float), dv, b)
    return val, dv, (b if has_sensor else None)


@njit(cache=True, nogil=True)
def _sensor_velocity(X, omega, r_cg, sensor, vs):
    # V + omega x r with r = sensor - r_cg, as np.cross computes it
    for i in range(X.shape[0]):
        r0 = sensor[0] - r_cg[i, 0]
        r1 = sensor[1] - r_cg[i, 1]
        r2 = sensor[2] - r_cg[i, 2]
        o0, o1, o2 = omega[i, 0], omega[i, 1], omega[i, 2]
        vs[i, 0] = X[i, 0] + (o1 * r2 - o2 * r1)
        vs[i, 1] = X[i, 1] + (o2 * r0 - o0 * r2)
        vs[i, 2] = X[i, 2] + (o0 * r1 - o1 * r0)


@njit(cache=True, nogil=True)
def _flow_derivatives(vs, kind, r_cg, sensor, dv, b):
    has_sensor = b.shape[0] > 0
    for i in range(vs.shape[0]):
        u, v, w = vs[i, 0], vs[i, 1], vs[i, 2]
        if kind == 0:
            uw2 = u * u + w * w
            d0, d1, d2 = -w / uw2, 0.0, u / uw2
        elif kind == 1:
            uw2 = u * u + w * w
            V2 = uw2 + v * v
            suw = np.sqrt(uw2)
            d0, d1, d2 = -v * u / (V2 * suw), suw / V2, -v * w / (V2 * suw)
        elif kind == 2:
            uv2 = u * u + v * v
            d0, d1, d2 = -v / uv2, u / uv2, 0.0
        elif kind == 3:
            V = np.sqrt(u * u + w * w + v * v)
            d0, d1, d2 = u / V, v / V, w / V
        else:  # a velocity component: 4, 5, 6 for u, v, w
            d0 = 1.0 if kind == 4 else 0.0
            d1 = 1.0 if kind == 5 else 0.0
            d2 = 1.0 if kind == 6 else 0.0
        dv[i, 0] = d0
        dv[i, 1] = d1
        dv[i, 2] = d2
        if has_sensor:
            # minus dv @ d(omega x r)/domega, r = sensor - r_cg
            x = sensor[0] - r_cg[i, 0]
            y = sensor[1] - r_cg[i, 1]
            z = sensor[2] - r_cg[i, 2]
            b[i, 0] = -(-z * d1 + y * d2)
            b[i, 1] = -(z * d0 - x * d2)
            b[i, 2] = -(-y * d0 + x * d1)
