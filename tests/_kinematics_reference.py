"""The plain-NumPy reference of the estimator's kinematics: the test oracle of the compiled kernel.

The state equations (:mod:`estimator.core.kinematics`'s docstring) written out line by line, their
RK4 integration one step at a time, and the lever-arm removal — slow and obvious, so that the
estimator's compiled integration (:mod:`estimator.core.sensitivity`) can be checked against them.
The package ships only the compiled kernel; these were in ``estimator/core/kinematics.py`` until
issue 12.
"""

from __future__ import annotations

import numpy as np

from estimator.core.kinematics import midpoints
from estimator.core.sensitivity import N_SENS, Inputs, integrate_many


def state_derivative(
    x: np.ndarray, accel_cg_body_mps2: np.ndarray, omega_body_rps: np.ndarray, g_mps2: float
) -> np.ndarray:
    """Right-hand side of the FPR state equations.

    Parameters
    ----------
    x : (..., 7) state [u, v, w (m/s, body), phi, theta, psi (rad), h (m)].
    accel_cg_body_mps2 : (..., 3) specific force at the CG, body axes, m/s^2.
    omega_body_rps : (..., 3) body rates p, q, r, rad/s.
    g_mps2 : gravity, m/s^2.

    Returns
    -------
    (..., 7) time derivative of ``x``.
    """
    u, v, w, phi, theta = x[..., 0], x[..., 1], x[..., 2], x[..., 3], x[..., 4]
    ax, ay, az = accel_cg_body_mps2[..., 0], accel_cg_body_mps2[..., 1], accel_cg_body_mps2[..., 2]
    p, q, r = omega_body_rps[..., 0], omega_body_rps[..., 1], omega_body_rps[..., 2]
    sphi, cphi = np.sin(phi), np.cos(phi)
    sth, cth = np.sin(theta), np.cos(theta)
    qs_rc = q * sphi + r * cphi
    return np.stack(
        [
            r * v - q * w - g_mps2 * sth + ax,
            p * w - r * u + g_mps2 * cth * sphi + ay,
            q * u - p * v + g_mps2 * cth * cphi + az,
            p + qs_rc * sth / cth,
            q * cphi - r * sphi,
            qs_rc / cth,
            u * sth - v * cth * sphi - w * cth * cphi,
        ],
        axis=-1,
    )


def integrate_rk4(
    t_s: np.ndarray,
    x0: np.ndarray,
    accel_cg_body_mps2: np.ndarray,
    omega_body_rps: np.ndarray,
    g_mps2: float,
    accel_mid_body_mps2: np.ndarray | None = None,
    omega_mid_body_rps: np.ndarray | None = None,
    midpoint: str = "cubic",
) -> np.ndarray:
    """Integrate the state equations with RK4 on the sample grid ``t_s``.

    Parameters
    ----------
    t_s : (N,) strictly increasing sample times, s (need not be uniform).
    x0 : (7,) state at ``t_s[0]``.
    accel_cg_body_mps2 : (N, 3) specific force at the CG, body axes, m/s^2, at ``t_s``.
    omega_body_rps : (N, 3) body rates, rad/s, at ``t_s``.
    g_mps2 : gravity, m/s^2.
    accel_mid_body_mps2, omega_mid_body_rps : (N-1, 3) inputs at the half steps, if known
        (analytic inputs, or a recorder faster than the grid). Default: interpolated as
        ``midpoint`` says.
    midpoint : "cubic" (four-point, fourth order; default) or "linear" (mean of the neighbours,
        which limits the global error to second order in the step for curved inputs).

    Returns
    -------
    (N, 7) state history.
    """
    t_s = np.asarray(t_s, dtype=float)
    n = t_s.size
    if accel_cg_body_mps2.shape != (n, 3) or omega_body_rps.shape != (n, 3):
        raise ValueError(
            f"inputs must be (N, 3) with N = len(t_s) = {n}; got accel {accel_cg_body_mps2.shape}, "
            f"omega {omega_body_rps.shape}"
        )
    x = np.empty((n, 7))
    x[0] = x0
    dt = np.diff(t_s)
    a_mid = (
        midpoints(accel_cg_body_mps2, midpoint) if accel_mid_body_mps2 is None else accel_mid_body_mps2
    )
    w_mid = midpoints(omega_body_rps, midpoint) if omega_mid_body_rps is None else omega_mid_body_rps
    f = state_derivative
    for k in range(n - 1):
        h = dt[k]
        xk = x[k]
        k1 = f(xk, accel_cg_body_mps2[k], omega_body_rps[k], g_mps2)
        k2 = f(xk + 0.5 * h * k1, a_mid[k], w_mid[k], g_mps2)
        k3 = f(xk + 0.5 * h * k2, a_mid[k], w_mid[k], g_mps2)
        k4 = f(xk + h * k3, accel_cg_body_mps2[k + 1], omega_body_rps[k + 1], g_mps2)
        x[k + 1] = xk + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return x


def specific_force_at_cg(
    accel_imu_body_mps2: np.ndarray,
    omega_body_rps: np.ndarray,
    omega_dot_body_rps2: np.ndarray,
    r_imu_from_cg_body_m: np.ndarray,
) -> np.ndarray:
    """Remove the accelerometer lever arm: ``a_cg = a_imu - omega' x r - omega x (omega x r)``.

    Parameters
    ----------
    accel_imu_body_mps2 : (N, 3) specific force sensed at the IMU, body axes, m/s^2.
    omega_body_rps : (N, 3) body rates, rad/s.
    omega_dot_body_rps2 : (N, 3) angular accelerations, rad/s^2.
    r_imu_from_cg_body_m : (3,) or (N, 3) IMU position minus CG position, body axes, m.

    Returns
    -------
    (N, 3) specific force at the CG, body axes, m/s^2.
    """
    r = np.broadcast_to(r_imu_from_cg_body_m, accel_imu_body_mps2.shape)
    return (
        accel_imu_body_mps2
        - np.cross(omega_dot_body_rps2, r)
        - np.cross(omega_body_rps, np.cross(omega_body_rps, r))
    )


def integrate_sensitivities(t_s, x0, a_m, om_m, omd, r_imu_cg, da, dw, g, midpoint="cubic",
                            lever_arm="differentiated"):
    """The compiled RK4 of the states and their sensitivities for one maneuver.

    Parameters
    ----------
    t_s : (N,) sample times, s.
    x0 : (7,) initial state.
    a_m : (N, 3) measured specific force at the IMU, body, m/s^2.
    om_m : (N, 3) measured body rates, rad/s.
    omd : (N, 3) angular acceleration (smoothed derivative of om_m), rad/s^2.
    r_imu_cg : (3,) IMU position minus CG position, body, m.
    da, dw : (3,) accelerometer (m/s^2) and gyro (rad/s) biases, subtracted from the measurements.
    g : gravity, m/s^2.
    midpoint, lever_arm : as :meth:`estimator.core.sensitivity.Inputs.concatenate`.

    Returns
    -------
    X : (N, 7) states; S : (N, 7, 13) sensitivities dX/d[x0, da, dw].
    """
    inputs = Inputs.concatenate([t_s], [a_m], [om_m], [omd], r_imu_cg, midpoint=midpoint, lever_arm=lever_arm)
    params = np.concatenate([np.asarray(x0, dtype=float), np.asarray(da, dtype=float),
                             np.asarray(dw, dtype=float)]).reshape(1, N_SENS)
    return integrate_many(inputs, params, float(g), sensitivities=True)
