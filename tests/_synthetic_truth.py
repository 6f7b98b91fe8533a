"""Analytic, kinematically exact flight histories for the instrumentation tests (no JSBSim).

Euler angles, body velocity and CG position are prescribed smooth functions of time. The body
rates follow exactly from the Euler kinematics, the specific force from the velocity equation on a
flat non-rotating earth, ``f = v_dot + omega x v - C_bn g_ned``; time derivatives of the analytic
rates and velocities use a 5-point stencil on the analytic functions (error ~1e-11). The
atmosphere is the ISA at the geometric height, so pressure altitude equals height.
"""

from __future__ import annotations

import numpy as np

from synth.truth import TruthTrajectory

G_MPS2 = 9.80665
R_AIR = 287.05287
GAMMA = 1.4


def isa(h_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ISA troposphere (T K, p Pa) at geometric = geopotential height h (flat earth, const g)."""
    t_k = 288.15 - 0.0065 * h_m
    return t_k, 101325.0 * (t_k / 288.15) ** (G_MPS2 / (R_AIR * 0.0065))


def dcm_body_to_ned(euler: np.ndarray) -> np.ndarray:
    phi, th, psi = euler[:, 0], euler[:, 1], euler[:, 2]
    cf, sf, ct, st, cp, sp = np.cos(phi), np.sin(phi), np.cos(th), np.sin(th), np.cos(psi), np.sin(psi)
    return np.stack([
        np.stack([ct * cp, sf * st * cp - cf * sp, cf * st * cp + sf * sp], -1),
        np.stack([ct * sp, sf * st * sp + cf * cp, cf * st * sp - sf * cp], -1),
        np.stack([-st, sf * ct, cf * ct], -1)], -2)


class AnalyticFlight:
    """A smooth maneuver; ``scale`` multiplies every oscillation amplitude."""

    def __init__(self, scale: float = 1.0, wind_ned_mps=(5.0, -3.0, 0.5), h0_m: float = 6000.0,
                 u0_mps: float = 150.0, w0_mps: float = 14.0, gear: float = 0.0):
        self.k = scale
        self.wind = np.asarray(wind_ned_mps, dtype=float)
        self.h0, self.u0, self.w0, self.gear = h0_m, u0_mps, w0_mps, gear

    def euler(self, t):
        k = self.k
        return np.stack([0.4 * k * np.sin(0.5 * t), 0.05 + 0.12 * k * np.sin(0.7 * t + 0.3),
                         1.0 + 0.05 * t + 0.1 * k * np.sin(0.4 * t)], -1)

    def euler_dot(self, t):
        k = self.k
        return np.stack([0.2 * k * np.cos(0.5 * t), 0.084 * k * np.cos(0.7 * t + 0.3),
                         0.05 + 0.04 * k * np.cos(0.4 * t)], -1)

    def omega(self, t):
        e, ed = self.euler(t), self.euler_dot(t)
        phi, th = e[:, 0], e[:, 1]
        return np.stack([ed[:, 0] - ed[:, 2] * np.sin(th),
                         ed[:, 1] * np.cos(phi) + ed[:, 2] * np.cos(th) * np.sin(phi),
                         -ed[:, 1] * np.sin(phi) + ed[:, 2] * np.cos(th) * np.cos(phi)], -1)

    def v_body(self, t):
        k = self.k
        return np.stack([self.u0 + 5.0 * k * np.sin(0.3 * t), 6.0 * k * np.sin(0.9 * t + 0.2),
                         self.w0 + 9.0 * k * np.sin(0.6 * t)], -1)

    def r_cg(self, t):
        return np.stack([0.33 - 0.0005 * t, 0.002 * np.sin(0.1 * t), 0.13 + 0.0 * t], -1)

    @staticmethod
    def derivative(f, t, h=1e-3):
        return (f(t - 2 * h) - 8 * f(t - h) + 8 * f(t + h) - f(t + 2 * h)) / (12 * h)

    def v_air(self, t):
        c_bn = np.transpose(dcm_body_to_ned(self.euler(t)), (0, 2, 1))
        return self.v_body(t) - c_bn @ self.wind

    def specific_force_cg(self, t):
        c_bn = np.transpose(dcm_body_to_ned(self.euler(t)), (0, 2, 1))
        v = self.v_body(t)
        g_body = c_bn @ np.array([0.0, 0.0, G_MPS2])
        return self.derivative(self.v_body, t) + np.cross(self.omega(t), v) - g_body

    def truth(self, duration_s: float = 40.0, rate_hz: float = 120.0) -> TruthTrajectory:
        t = np.arange(int(round(duration_s * rate_hz)) + 1) / rate_hz
        euler = self.euler(t)
        v_body = self.v_body(t)
        v_ned = np.einsum("nij,nj->ni", dcm_body_to_ned(euler), v_body)
        climb = -v_ned[:, 2]
        h = self.h0 + np.concatenate([[0.0], np.cumsum(0.5 * (climb[1:] + climb[:-1]) * np.diff(t))])
        t_k, p_pa = isa(h)
        v_air = self.v_air(t)
        tas = np.linalg.norm(v_air, axis=1)
        rho = p_pa / (R_AIR * t_k)
        n = len(t)
        return TruthTrajectory(
            t_s=t, v_body_mps=v_body, v_air_body_mps=v_air,
            wind_ned_mps=np.tile(self.wind, (n, 1)), omega_body_rps=self.omega(t),
            omega_dot_body_rps2=self.derivative(self.omega, t),
            specific_force_cg_body_mps2=self.specific_force_cg(t), euler_rad=euler, h_m=h,
            alpha_rad=np.arctan2(v_air[:, 2], v_air[:, 0]), beta_rad=np.arcsin(v_air[:, 1] / tas),
            tas_mps=tas, mach=tas / np.sqrt(GAMMA * R_AIR * t_k), p_static_pa=p_pa,
            t_static_k=t_k, rho_kgpm3=rho, qbar_pa=0.5 * rho * tas**2,
            gear_pos_norm=np.full(n, float(self.gear)), r_cg_body_m=self.r_cg(t),
            mass_kg=9000.0 - 0.5 * t, g_mps2=np.full(n, G_MPS2), planet="flat",
            meta={"source": "tests/_synthetic_truth.py"},
        )
