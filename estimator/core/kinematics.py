r"""Flight-path-reconstruction kinematics: the state equations, and the input helpers of their RK4
integration (half-step values, smoothed angular accelerations).

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

The estimator removes the lever arm with ``omega'`` from smoothed numerical differentiation of
the measured rates (:func:`smoothed_derivative`, ``lever_arm = "differentiated"``) or, exactly,
integrates the IMU point's velocity instead (``"imu_point"``): :mod:`estimator.core.sensitivity`
integrates these equations and their sensitivities, compiled.
The plain-NumPy reference of the equations and of RK4, against which the tests check that kernel,
is a test helper (``tests/_kinematics_reference.py``), not part of the package.

The integrator is the classical fourth-order Runge-Kutta scheme on the measurement grid. RK4
needs the inputs at the half step, which sampled data do not have. The usual choice, the mean of
the two neighbouring samples (Jategaonkar 2006, §4.8), is only second-order accurate and limits
the whole scheme to second order; the default here is the four-point cubic midpoint
``(-y[k-1] + 9 y[k] + 9 y[k+1] - y[k+2]) / 16``, fourth-order accurate, so RK4 keeps its order on
sampled inputs (one-sided cubics at the two end intervals).
"""

from __future__ import annotations

import numpy as np


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
    # imported here: scipy.signal takes about a second to import and only the differentiated
    # lever arm needs it, while every process that reads a problem file imports this module
    from scipy.signal import savgol_filter

    return savgol_filter(y, window, polyorder, deriv=1, delta=dt, axis=0, mode="interp")


def rotation_ned_to_body(euler_rad: np.ndarray) -> np.ndarray:
    """``C_bn`` (N, 3, 3) from Euler angles (N, 3) (phi, theta, psi; 3-2-1), rad."""
    ph, th, ps = euler_rad[:, 0], euler_rad[:, 1], euler_rad[:, 2]
    cph, sph, cth, sth, cps, sps = np.cos(ph), np.sin(ph), np.cos(th), np.sin(th), np.cos(ps), np.sin(ps)
    C = np.empty((euler_rad.shape[0], 3, 3))
    C[:, 0, 0] = cth * cps
    C[:, 0, 1] = cth * sps
    C[:, 0, 2] = -sth
    C[:, 1, 0] = sph * sth * cps - cph * sps
    C[:, 1, 1] = sph * sth * sps + cph * cps
    C[:, 1, 2] = sph * cth
    C[:, 2, 0] = cph * sth * cps + sph * sps
    C[:, 2, 1] = cph * sth * sps - sph * cps
    C[:, 2, 2] = cph * cth
    return C
