"""Kernels of the realism level: slow random errors, pneumatic lag, static-source error, hold.

Equations
---------
First-order Gauss-Markov process (exact discretization at the sample times ``t_k``; Gelb,
*Applied Optimal Estimation*, MIT Press 1974, §3.8; Maybeck, *Stochastic Models, Estimation and
Control* vol. 1, 1979, §4.9)::

    dx/dt = -x / tau + w,     E[x^2] = sigma^2,     E[x(t) x(t + s)] = sigma^2 exp(-|s| / tau)
    x_0 = sigma n_0,          x_k = a_k x_{k-1} + sigma sqrt(1 - a_k^2) n_k,
    a_k = exp(-(t_k - t_{k-1}) / tau)

started in its stationary distribution, ``n_k`` standard normal from a seeded generator.

First-order pneumatic lag of a pressure line (Gracey, *Measurement of Aircraft Speed and
Altitude*, NASA RP-1046, 1980, ch. 11: laminar flow in the tube, ``lambda = 128 mu L V / (pi d^4 p)``)::

    tau dy/dt = u - y             y(t_0) = u(t_0)  (the line has equilibrated at the trim)

discretized exactly for an input linear between samples (first-order hold, "ramp invariant")::

    y_k = a y_{k-1} + b0 u_k + b1 u_{k-1},   a = exp(-h / tau),
    b0 = 1 - (tau / h)(1 - a),               b1 = (tau / h)(1 - a) - a

Static-source position error (Gracey ch. 5-6; USAF Test Pilot School, *Pitot-Statics and the
Standard Atmosphere*, ch. 2, "position error": ``dPp / qc`` a function of Mach and of the lift
coefficient, i.e. of alpha at a given Mach)::

    ps_port = ps + dPp,    dPp / qc = c0 + c_alpha alpha + c_mach2 M^2

Sample-and-hold of a slower source with latency (GNSS velocity on the INS stream): at query time
``t`` the value is that of the latest fix ``t_f = j / f`` with ``t_f + latency <= t``.

Pure kernels: arrays in SI / radians, no I/O, no state.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter

from synth.recorders import TIME_EPS_S


def _uniform_step_s(t_s: np.ndarray) -> float | None:
    """The sample interval of ``t_s`` if it is uniform (to 1e-9 relative), else None."""
    d = np.diff(t_s)
    if d.size == 0:
        return None
    h = float(np.mean(d))
    return h if np.all(np.abs(d - h) <= 1e-9 * max(h, 1.0)) else None


def gauss_markov(t_s: np.ndarray, sigma: float, tau_s: float, rng: np.random.Generator) -> np.ndarray:
    """A stationary first-order Gauss-Markov process sampled at ``t_s`` (module docstring).

    Parameters
    ----------
    t_s : (N,) strictly increasing sample times, s.
    sigma : its standard deviation (any unit; 0 gives zeros and draws nothing).
    tau_s : its correlation time, s (> 0).
    rng : the seeded generator; exactly N standard normals are drawn from it.

    Returns
    -------
    (N,) samples, in the unit of ``sigma``. The first sample depends on the first draw alone, so a
    longer record of the same generator starts with the same value.
    """
    t = np.asarray(t_s, dtype=float)
    if sigma == 0.0:
        return np.zeros(t.shape)
    if not (math.isfinite(tau_s) and tau_s > 0.0) or not (math.isfinite(sigma) and sigma > 0.0):
        raise ValueError(f"gauss_markov: sigma = {sigma!r} must be >= 0 and tau_s = {tau_s!r} > 0")
    n = rng.standard_normal(t.shape)
    x = np.empty(t.shape)
    if t.size == 0:
        return x
    x[0] = sigma * n[0]
    h = _uniform_step_s(t)
    if h is not None:
        a = math.exp(-h / tau_s)
        c = sigma * math.sqrt(1.0 - a * a)
        x[1:] = lfilter([c], [1.0, -a], n[1:], zi=[a * x[0]])[0]
        return x
    a = np.exp(-np.diff(t) / tau_s)
    c = sigma * np.sqrt(1.0 - a * a)
    for k in range(1, t.size):
        x[k] = a[k - 1] * x[k - 1] + c[k - 1] * n[k]
    return x


def first_order_lag(t_s: np.ndarray, u: np.ndarray, tau_s: float) -> np.ndarray:
    """The output of a first-order lag ``tau y' = u - y`` for input samples ``u`` (module docstring).

    Parameters
    ----------
    t_s : (N,) uniform sample times, s.
    u : (N,) input samples (any unit).
    tau_s : lag time constant, s (0: the input is returned unchanged).

    Returns
    -------
    (N,) the lagged signal, starting in equilibrium with the first input sample.
    """
    u = np.asarray(u, dtype=float)
    if tau_s == 0.0:
        return u
    if not (math.isfinite(tau_s) and tau_s > 0.0):
        raise ValueError(f"first_order_lag: tau_s = {tau_s!r} must be >= 0")
    h = _uniform_step_s(np.asarray(t_s, dtype=float))
    if h is None:
        raise ValueError("first_order_lag: the samples must be uniform in time")
    a = math.exp(-h / tau_s)
    b0 = 1.0 - (tau_s / h) * (1.0 - a)
    b1 = (tau_s / h) * (1.0 - a) - a
    # the steady state y = u (b0 + b1 = 1 - a): zi so that a constant input stays constant
    zi = [(1.0 - b0) * u[0]]
    return lfilter([b0, b1], [1.0, -a], u, zi=zi)[0]


def static_source_error_ratio(alpha_rad: np.ndarray, mach: np.ndarray, c0: float,
                              c_alpha_per_rad: float, c_mach2: float) -> np.ndarray:
    """The static-source position error ``dPp / qc = c0 + c_alpha alpha + c_mach2 M^2`` (1).

    Parameters
    ----------
    alpha_rad : free-stream angle of attack, rad.
    mach : free-stream Mach number.
    c0, c_alpha_per_rad, c_mach2 : the installation's coefficients (1, 1/rad, 1).
    """
    m = np.asarray(mach, dtype=float)
    return c0 + c_alpha_per_rad * np.asarray(alpha_rad, dtype=float) + c_mach2 * m * m


def hold_fix_times_s(t_query_s: np.ndarray, rate_hz: float, latency_s: float) -> np.ndarray:
    """The time of validity of the fix held at each query time, s.

    Fixes are valid at ``j / rate_hz`` (receiver time = true time) and reach the recorder
    ``latency_s`` later; each query time holds the latest fix that has arrived.
    """
    if not (math.isfinite(rate_hz) and rate_hz > 0.0) or not (math.isfinite(latency_s) and latency_s >= 0):
        raise ValueError(f"hold_fix_times_s: rate_hz = {rate_hz!r} must be > 0 and latency_s = "
                         f"{latency_s!r} >= 0")
    j = np.floor((np.asarray(t_query_s, dtype=float) - latency_s) * rate_hz + TIME_EPS_S * rate_hz)
    return j / rate_hz
