r"""Model signals for the observation equations, with their derivatives.

From the reconstructed states ``x = [u, v, w, phi, theta, psi, h]`` and the bias-corrected rates
``omega``, the air velocity at a sensor at ``r_s`` (body axes, from the CG) is the exact rigid-body
velocity (SPEC §3; the paper's Eq. 6 is its small-angle form)::

    V_s = V + omega x (r_s - r_cg)

and the angles a sensor can sense are::

    alpha_s = atan2(w_s, u_s)          angle of attack
    beta_s  = asin(v_s / |V_s|)        aerodynamic sideslip
    flank_s = atan2(v_s, u_s)          flank angle (what a sideslip vane senses)

At the CG (``r_s = r_cg``) these are ``alpha_t``, ``beta_t`` and ``tas_t = |V|``.

Each function returns the signal and its derivatives with respect to ``(u, v, w)`` and to
``omega`` (so the estimator can chain them to the state sensitivities and to the gyro biases).
"""

from __future__ import annotations

import numpy as np


def velocity_at_sensor(v_body_mps: np.ndarray, omega_rps: np.ndarray, r_from_cg_m: np.ndarray) -> np.ndarray:
    """``V_s = V + omega x r``: (N, 3) air velocity at the sensor, body axes, m/s."""
    return v_body_mps + np.cross(omega_rps, r_from_cg_m)


def domega_matrix(r_from_cg_m: np.ndarray) -> np.ndarray:
    """``d(omega x r)/d omega = -[r]x``: (3, 3), rows (u_s, v_s, w_s), columns (p, q, r)."""
    x, y, z = r_from_cg_m
    return np.array([[0.0, z, -y], [-z, 0.0, x], [y, -x, 0.0]])


def angle_signals(v_s_mps: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Flow angles and speed of a velocity, with derivatives with respect to its components.

    Parameters
    ----------
    v_s_mps : (N, 3) air velocity (u_s, v_s, w_s), body axes, m/s.

    Returns
    -------
    name -> (value (N,), d value / d(u_s, v_s, w_s) (N, 3)) for ``alpha``, ``beta``, ``flank``
    (rad) and ``tas`` (m/s).
    """
    return {kind: angle_signal(v_s_mps, kind) for kind in ("alpha", "beta", "flank", "tas")}


def angle_signal(v_s_mps: np.ndarray, kind: str) -> tuple[np.ndarray, np.ndarray]:
    """One of :func:`angle_signals` (``kind`` "alpha", "beta", "flank" or "tas"), computed alone."""
    u, v, w = v_s_mps[:, 0], v_s_mps[:, 1], v_s_mps[:, 2]
    if kind == "alpha":
        uw2 = u * u + w * w
        zero = np.zeros_like(u)
        return np.arctan2(w, u), np.stack([-w / uw2, zero, u / uw2], axis=1)
    if kind == "beta":
        uw2 = u * u + w * w
        V2 = uw2 + v * v
        V = np.sqrt(V2)
        suw = np.sqrt(uw2)
        return np.arcsin(v / V), np.stack([-v * u / (V2 * suw), suw / V2, -v * w / (V2 * suw)], axis=1)
    if kind == "flank":
        uv2 = u * u + v * v
        zero = np.zeros_like(u)
        return np.arctan2(v, u), np.stack([-v / uv2, u / uv2, zero], axis=1)
    if kind == "tas":
        V = np.sqrt(u * u + w * w + v * v)
        return V, v_s_mps / V[:, None]
    raise ValueError(f"unknown flow signal {kind!r}; one of alpha, beta, flank, tas")
