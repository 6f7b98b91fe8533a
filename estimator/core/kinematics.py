r"""Flight-path-reconstruction kinematics: state equations and their RK4 integration.

State equations (SPEC §3, paper Eq. 1 with the altitude typo corrected), flat non-rotating earth,
constant gravity g, body axes x forward / y right / z down. Inputs are the bias-corrected specific
force at the CG ``a = (Ax, Ay, Az)`` and the body rates ``omega = (p, q, r)``::

    u' = r v - q w - g sin(theta)                + Ax
    v' = p w - r u + g cos(theta) sin(phi)       + Ay
    w' = q u - p v + g cos(theta) cos(phi)       + Az
    phi'   = p + (q sin(phi) + r cos(phi)) tan(theta)
    theta' = q cos(phi) - r sin(phi)
    psi'   = (q sin(phi) + r cos(phi)) / cos(theta)
    h'     = u sin(theta) - v cos(theta) sin(phi) - w cos(theta) cos(phi)

The state vector is ``x = [u_mps, v_mps, w_mps, phi_rad, theta_rad, psi_rad, h_m]``.

Accelerometers away from the CG sense (SPEC §3)::

    a_imu = a_cg + omega' x r + omega x (omega x r),   r = r_imu - r_cg

so :func:`specific_force_at_cg` removes the lever arm, with ``omega'`` from smoothed numerical
differentiation of the measured rates.

The integrator is the classical fourth-order Runge-Kutta scheme on the measurement grid. RK4
needs the inputs at the half step, which sampled data do not have. The usual choice, the mean of
the two neighbouring samples (Jategaonkar 2006, §4.8), is only second-order accurate and limits
the whole scheme to second order; the default here is the four-point cubic midpoint
``(-y[k-1] + 9 y[k] + 9 y[k+1] - y[k+2]) / 16``, fourth-order accurate, so RK4 keeps its order on
sampled inputs (one-sided cubics at the two end intervals).
"""

from __future__ import annotations

import numpy as np
from scipy.signal import savgol_filter

STATE_NAMES = ("u_mps", "v_mps", "w_mps", "phi_rad", "theta_rad", "psi_rad", "h_m")


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


def midpoints(y: np.ndarray, method: str = "cubic") -> np.ndarray:
    """Values half-way between consecutive samples of a uniformly sampled signal.

    Parameters
    ----------
    y : (N, ...) samples.
    method : "cubic" — four-point ``(-y[k-1] + 9 y[k] + 9 y[k+1] - y[k+2]) / 16``, exact for cubic
        polynomials (one-sided four-point cubics in the first and last interval); "linear" —
        ``(y[k] + y[k+1]) / 2``.

    Returns
    -------
    (N-1, ...) midpoint values.
    """
    y = np.asarray(y, dtype=float)
    mid = 0.5 * (y[1:] + y[:-1])
    if method == "linear" or y.shape[0] < 4:
        return mid
    if method != "cubic":
        raise ValueError(f"midpoint method must be 'cubic' or 'linear', got {method!r}")
    mid[1:-1] = (-y[:-3] + 9.0 * y[1:-2] + 9.0 * y[2:-1] - y[3:]) / 16.0
    # one-sided cubics at the two end intervals keep the whole grid fourth-order accurate
    mid[0] = (5.0 * y[0] + 15.0 * y[1] - 5.0 * y[2] + y[3]) / 16.0
    mid[-1] = (y[-4] - 5.0 * y[-3] + 15.0 * y[-2] + 5.0 * y[-1]) / 16.0
    return mid


def smoothed_derivative(
    t_s: np.ndarray, y: np.ndarray, window_s: float = 0.25, polyorder: int = 2
) -> np.ndarray:
    """Derivative of a uniformly sampled signal by a Savitzky-Golay filter.

    Parameters
    ----------
    t_s : (N,) uniform sample times, s.
    y : (N, ...) signal.
    window_s : length of the local polynomial fit, s; longer is smoother.
    polyorder : order of the local polynomial.

    Returns
    -------
    (N, ...) dy/dt in the units of ``y`` per second.
    """
    dt = float(np.median(np.diff(t_s)))
    window = max(polyorder + 2, int(round(window_s / dt)) | 1)
    if window > len(t_s):
        window = len(t_s) if len(t_s) % 2 else len(t_s) - 1
    return savgol_filter(y, window, polyorder, deriv=1, delta=dt, axis=0, mode="interp")


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
