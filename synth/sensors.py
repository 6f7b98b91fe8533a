"""Sensor kinematics and transduction errors: IMU and INS lever arms, scale/noise/quantization.

Equations (SPEC §3, §6)
-----------------------
Specific force at an IMU at ``r_imu`` (body axes), rigid body, CG at ``r_cg``::

    f_imu = f_cg + omega_dot x r + omega x (omega x r),      r = r_imu - r_cg

(the CG's slow motion relative to the structure, fuel burn, contributes nothing measurable and is
ignored). Gyros sense omega itself. The INS outputs the velocity of its own point ``r_ins``: the
CG's body-axis earth-relative velocity carried to it by the rigid-body transport (the one the flow
at the sensors uses, :func:`synth.local_flow.air_velocity_at_sensor_body_mps`), then in NED with
the 3-2-1 Euler angles (psi, theta, phi)::

    v_ned = C_nb(phi, theta, psi) (v_body + omega x (r_ins - r_cg))

(omega is the inertial rate; on the rotating WGS84 earth the earth-relative rate differs by the
earth rate, 7.3e-5 rad/s, i.e. < 2e-4 m/s over these lever arms). Its Euler angles are the body's:
a rigid body has one attitude at every point.

Transduction of every measured sample::

    y = Q(s * x + b + sigma * n)         Q(z) = step * round(z / step)  (step 0: none)

with ``s`` = 1 + scale error, ``b`` a bias, ``n`` standard normal from a seeded generator.

Pure kernels: arrays in SI / radians, no I/O, no state.
"""

from __future__ import annotations

import numpy as np


def imu_specific_force_body_mps2(
    specific_force_cg_body_mps2: np.ndarray,
    omega_body_rps: np.ndarray,
    omega_dot_body_rps2: np.ndarray,
    r_imu_from_cg_body_m: np.ndarray,
) -> np.ndarray:
    """Specific force sensed at the IMU, body axes, m/s^2.

    Parameters
    ----------
    specific_force_cg_body_mps2 : (N, 3) specific force at the CG, body axes, m/s^2.
    omega_body_rps, omega_dot_body_rps2 : (N, 3) body rate, rad/s, and its derivative, rad/s^2.
    r_imu_from_cg_body_m : (N, 3) or (3,) IMU position minus CG position, body axes, m.
    """
    r = np.broadcast_to(np.asarray(r_imu_from_cg_body_m, dtype=float),
                        np.shape(specific_force_cg_body_mps2))
    return (specific_force_cg_body_mps2 + np.cross(omega_dot_body_rps2, r)
            + np.cross(omega_body_rps, np.cross(omega_body_rps, r)))


def dcm_body_to_ned(euler_rad: np.ndarray) -> np.ndarray:
    """(N, 3, 3) direction-cosine matrices C_nb (body -> NED) for 3-2-1 Euler angles (phi, theta, psi)."""
    phi, theta, psi = euler_rad[..., 0], euler_rad[..., 1], euler_rad[..., 2]
    cf, sf, ct, st, cp, sp = (np.cos(phi), np.sin(phi), np.cos(theta), np.sin(theta),
                              np.cos(psi), np.sin(psi))
    c = np.empty(np.shape(euler_rad)[:-1] + (3, 3))
    c[..., 0, 0] = ct * cp
    c[..., 0, 1] = sf * st * cp - cf * sp
    c[..., 0, 2] = cf * st * cp + sf * sp
    c[..., 1, 0] = ct * sp
    c[..., 1, 1] = sf * st * sp + cf * cp
    c[..., 1, 2] = cf * st * sp - sf * cp
    c[..., 2, 0] = -st
    c[..., 2, 1] = sf * ct
    c[..., 2, 2] = cf * ct
    return c


def ned_velocity_mps(v_body_mps: np.ndarray, euler_rad: np.ndarray) -> np.ndarray:
    """(N, 3) velocity in NED from body-axis velocity and Euler angles, m/s."""
    return np.einsum("nij,nj->ni", dcm_body_to_ned(euler_rad), v_body_mps)


def quantize(x: np.ndarray, step: float) -> np.ndarray:
    """Round to a multiple of ``step`` (returned unchanged when step == 0)."""
    if step == 0.0:
        return x
    return step * np.round(np.asarray(x) / step)


def transduce(
    x: np.ndarray,
    *,
    scale: float = 0.0,
    bias: float | np.ndarray = 0.0,
    noise_std: float | np.ndarray = 0.0,
    quant_step: float = 0.0,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """``Q((1 + scale) x + bias + noise_std * n)`` for samples ``x`` (any unit; module docstring).

    ``noise_std`` may be an array (per-sample std); ``rng`` is required when any std is > 0.
    """
    y = (1.0 + scale) * np.asarray(x, dtype=float) + bias
    if np.any(np.asarray(noise_std) > 0.0):
        if rng is None:
            raise ValueError("transduce: noise requested but no random generator given")
        y = y + noise_std * rng.standard_normal(np.shape(y))
    return quantize(y, quant_step)
