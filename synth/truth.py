"""The true flight history of one maneuver, as JSBSim flew it.

This is the contract between the flight half of ``synth`` (JSBSim, controllers, maneuvers) and the
instrumentation half (sensors, error injection, recorders). Everything is SI, radians, body axes
x forward / y right / z down with the origin at the aircraft reference point (SPEC §2), sampled at
the simulation rate. The conversion from JSBSim's English units and structural frame happens once,
in :mod:`synth.jsbsim_io`; nothing here knows about feet or inches.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np


@dataclass(frozen=True)
class TruthTrajectory:
    """True state history of one flown maneuver at the simulation rate.

    Attributes
    ----------
    t_s : (N,) time since the start of the recorded maneuver, s.
    v_body_mps : (N, 3) velocity of the CG relative to the earth, body axes, m/s (u, v, w).
    v_air_body_mps : (N, 3) velocity of the CG relative to the air mass, body axes, m/s.
    wind_ned_mps : (N, 3) total wind (steady + turbulence + gust) at the aircraft, NED, m/s.
    omega_body_rps : (N, 3) inertial angular rate p, q, r, body axes, rad/s (what gyros sense).
    omega_dot_body_rps2 : (N, 3) time derivative of ``omega_body_rps``, rad/s^2.
    specific_force_cg_body_mps2 : (N, 3) non-gravitational force / mass at the CG, body axes,
        m/s^2 (what an ideal accelerometer at the CG senses; includes no gravity).
    euler_rad : (N, 3) roll, pitch, heading (phi, theta, psi) of the body relative to local NED.
    h_m : (N,) geometric altitude above mean sea level, m.
    alpha_rad, beta_rad : (N,) JSBSim's free-stream angle of attack atan2(w, u) and aerodynamic
        sideslip asin(v / V), at the CG, rad.
    tas_mps : (N,) true airspeed at the CG, m/s.
    mach : (N,) free-stream Mach number.
    p_static_pa : (N,) free-stream static pressure, Pa.
    t_static_k : (N,) free-stream static temperature, K.
    rho_kgpm3 : (N,) free-stream density, kg/m^3.
    qbar_pa : (N,) dynamic pressure 0.5 rho V^2, Pa.
    gear_pos_norm : (N,) landing-gear position, 0 up, 1 down.
    r_cg_body_m : (N, 3) CG position relative to the reference point, body axes, m (moves with fuel).
    mass_kg : (N,) aircraft mass, kg.
    g_mps2 : (N,) magnitude of gravity at the aircraft, m/s^2.
    controls : name -> (N,) array of control-surface and throttle positions (rad or normalized, as
        named), for plots and for checking what the controller did.
    planet : "flat" (flat, non-rotating, constant g) or "wgs84" (JSBSim's rotating ellipsoid).
    meta : free-form facts about the run (trim result, seeds, maneuver parameters).
    """

    t_s: np.ndarray
    v_body_mps: np.ndarray
    v_air_body_mps: np.ndarray
    wind_ned_mps: np.ndarray
    omega_body_rps: np.ndarray
    omega_dot_body_rps2: np.ndarray
    specific_force_cg_body_mps2: np.ndarray
    euler_rad: np.ndarray
    h_m: np.ndarray
    alpha_rad: np.ndarray
    beta_rad: np.ndarray
    tas_mps: np.ndarray
    mach: np.ndarray
    p_static_pa: np.ndarray
    t_static_k: np.ndarray
    rho_kgpm3: np.ndarray
    qbar_pa: np.ndarray
    gear_pos_norm: np.ndarray
    r_cg_body_m: np.ndarray
    mass_kg: np.ndarray
    g_mps2: np.ndarray
    controls: dict[str, np.ndarray] = field(default_factory=dict)
    planet: str = "flat"
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.t_s)
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, np.ndarray) and value.shape[0] != n:
                raise ValueError(
                    f"TruthTrajectory.{f.name} has {value.shape[0]} samples but t_s has {n}; "
                    "every signal must be sampled on the same simulation time base"
                )
        if self.planet not in ("flat", "wgs84"):
            raise ValueError(f"planet must be 'flat' or 'wgs84', got {self.planet!r}")

    @property
    def n_samples(self) -> int:
        return len(self.t_s)

    @property
    def dt_s(self) -> float:
        """Simulation time step, s."""
        return float(self.t_s[1] - self.t_s[0])

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0])
