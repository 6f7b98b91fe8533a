"""Flow at each sensor: rigid-body kinematics and the local-flow truth model.

Equations (SPEC §2, §3, §6; paper Saraf & Kumaresan §2.2-2.3)
--------------------------------------------------------------
Rigid-body air velocity at a sensor at ``r_s`` (body axes, from the reference point), with the CG
at ``r_cg`` and ``V`` the air-relative velocity of the CG::

    V_s = V + omega x (r_s - r_cg)
    alpha_s = atan2(w_s, u_s)      beta_s = asin(v_s / |V_s|)      flank_s = atan2(v_s, u_s)

This is the exact form of the paper's small-angle kinematic correction (its Eq. 6).

Local-flow laws (this testbed's truth; parameters in ``aircraft_models/local_flow_truth.toml``,
the airdata computer's nominal "CFD/wind-tunnel" version in ``adc_baseline.toml``). With
``PG(M) = 1 / sqrt(1 - min(M, M_clamp)^2)`` the Prandtl-Glauert factor:

Upwash (vanes, side probes, boom alpha vane)::

    alpha_loc = A(M, g) + B(M, g) * alpha * (1 + c * alpha)
    A = a0 + a2 * M^2 + g * a_g            B = e0 + e_M * (PG(M) - 1) + g * e_g

with ``g`` the gear position (0 up, 1 down). For ``e0`` of 1.1-1.5 this is the fuselage upwash of
SPEC §6, nonlinear in alpha (``c``) and Mach (``e_M``); its inverse for given M, g is the root of a
quadratic (:meth:`UpwashLaw.free_alpha_rad`), which the ADC tabulates.

Vane sidewash coupling (antisymmetric: ``s_y = sign(y_sensor)``, left and right vanes opposite)::

    alpha_loc,vane += s_y * (k_b0 + k_b1 * alpha) * beta

Sidewash (side probes: aerodynamic beta; nose probe and boom beta vanes: flank angle)::

    x_loc = K(alpha, M) * x        K = k0 + k_a * alpha + k_M * (PG(M) - 1)

Side probes ("paper Fig. 1 law"; the figure is missing from the text, so a hemispherical head is
used). Each probe's ports Pa1, Pa2 lie in a plane through the probe axis canted by ``c`` from the
x-z plane, with unit normal ``n = (0, -s_y sin c, cos c)``; the probe senses the angle of the local
flow direction ``d(alpha_loc, beta_loc) = (cos a cos b, sin b, sin a cos b)`` in that plane,
``theta = atan2(d . n, d_x)``. On a hemisphere in potential flow ``Cp = 1 - 9/4 sin^2(eta)``; ports
at +-45 deg from the axis in that plane then read::

    Pa1 - Pa2 = qc * K_p(M) * sin(2 theta)        K_p = kp0 * (1 + kp2 * M^2),  kp0 = 9/4

(``kp2`` a compressibility correction; ``qc`` the impact pressure pt - ps). The nose probe's ports
Pb1, Pb2 lie in the x-y plane, so the same law holds with ``theta`` the local flank angle.

Nose-probe indeterminacy at high AOA (paper §4.2, Fig. 7: "appear as large noise, impossible to
model"): a deterministic but irregular function of (alpha, beta) added to the local flank angle::

    e(alpha, beta) = a_irr * max(0, alpha - alpha_on) * sqrt(2/n) * sum_k sin(w_k alpha + v_k beta + phi_k)

with wavenumbers ``w_k, v_k`` of thousands per radian (periods of a few tenths of a degree) and
phases drawn once from the irregularity seed (a property of the probe type, the same for the whole
fleet).

Every function here is a pure numerical kernel: arrays in SI / radians, no I/O, no state.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from aircraft_models import read_toml, resolve_data_file
from aircraft_models.schema import Key, check

# ------------------------------------------------------------------ rigid-body kinematics


def air_velocity_at_sensor_body_mps(
    v_air_cg_body_mps: np.ndarray,
    omega_body_rps: np.ndarray,
    r_sensor_body_m: np.ndarray,
    r_cg_body_m: np.ndarray,
) -> np.ndarray:
    """Air velocity at a point of the rigid airframe, ``V + omega x (r_s - r_cg)``.

    Parameters
    ----------
    v_air_cg_body_mps : (N, 3) air-relative velocity of the CG, body axes, m/s.
    omega_body_rps : (N, 3) angular rate p, q, r, body axes, rad/s.
    r_sensor_body_m : (3,) sensor position from the reference point, body axes, m.
    r_cg_body_m : (N, 3) or (3,) CG position from the reference point, body axes, m.

    Returns
    -------
    (N, 3) air velocity at the sensor, body axes, m/s.
    """
    lever_m = np.asarray(r_sensor_body_m, dtype=float) - np.asarray(r_cg_body_m, dtype=float)
    return np.asarray(v_air_cg_body_mps, dtype=float) + np.cross(omega_body_rps, lever_m)


def flow_angles_rad(v_body_mps: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(alpha, beta, flank) of body-axis velocities (N, 3): atan2(w,u), asin(v/|V|), atan2(v,u)."""
    u, v, w = v_body_mps[..., 0], v_body_mps[..., 1], v_body_mps[..., 2]
    speed = np.sqrt(u * u + v * v + w * w)
    return np.arctan2(w, u), np.arcsin(v / speed), np.arctan2(v, u)


def direction_from_angles(alpha_rad: np.ndarray, beta_rad: np.ndarray) -> np.ndarray:
    """Unit body-axis flow direction (..., 3) with angle of attack alpha and sideslip beta."""
    ca, sa, cb, sb = np.cos(alpha_rad), np.sin(alpha_rad), np.cos(beta_rad), np.sin(beta_rad)
    return np.stack([ca * cb, sb, sa * cb], axis=-1)


# ------------------------------------------------------------------ laws


def prandtl_glauert(mach: np.ndarray, mach_clamp: float) -> np.ndarray:
    """``1 / sqrt(1 - min(M, M_clamp)^2)`` (subsonic compressibility factor)."""
    m = np.minimum(np.abs(np.asarray(mach, dtype=float)), mach_clamp)
    return 1.0 / np.sqrt(1.0 - m * m)


@dataclass(frozen=True)
class UpwashLaw:
    """``alpha_loc = A + B alpha (1 + c alpha)``; A, B as in the module docstring.

    Attributes (SI)
    ---------------
    offset_rad (a0), offset_mach2_rad (a2), gain (e0), gain_mach (e_M),
    curvature_per_rad (c), gear_offset_rad (a_g), gear_gain (e_g).
    """

    offset_rad: float = 0.0
    offset_mach2_rad: float = 0.0
    gain: float = 1.0
    gain_mach: float = 0.0
    curvature_per_rad: float = 0.0
    gear_offset_rad: float = 0.0
    gear_gain: float = 0.0

    def coefficients(self, mach, gear, mach_clamp: float):
        """(A rad, B, C = B c per rad) for Mach ``mach`` and gear position ``gear``."""
        m = np.minimum(np.abs(np.asarray(mach, dtype=float)), mach_clamp)
        a = self.offset_rad + self.offset_mach2_rad * m * m + gear * self.gear_offset_rad
        b = self.gain + self.gain_mach * (prandtl_glauert(m, mach_clamp) - 1.0) + gear * self.gear_gain
        return a, b, b * self.curvature_per_rad

    def local_alpha_rad(self, alpha_rad, mach, gear, mach_clamp: float) -> np.ndarray:
        """Local angle of attack for free-stream ``alpha_rad`` (at the sensor), rad."""
        a, b, c = self.coefficients(mach, gear, mach_clamp)
        return a + b * alpha_rad + c * alpha_rad * alpha_rad

    def free_alpha_rad(self, alpha_local_rad, mach, gear, mach_clamp: float) -> np.ndarray:
        """Inverse of :meth:`local_alpha_rad`: the root ``alpha`` continuous with ``(x - A)/B``.

        ``alpha = 2 (x - A) / (B + sqrt(B^2 + 4 C (x - A)))`` (stable for C -> 0). Beyond the fold
        of the quadratic (local angle larger than the law can produce) the root is clamped at it.
        """
        a, b, c = self.coefficients(mach, gear, mach_clamp)
        dx = np.asarray(alpha_local_rad, dtype=float) - a
        disc = np.maximum(b * b + 4.0 * c * dx, 0.0)
        return 2.0 * dx / (b + np.sqrt(disc))


@dataclass(frozen=True)
class SidewashLaw:
    """Multiplicative sidewash ``K(alpha, M) = k0 + k_a alpha + k_M (PG(M) - 1)``."""

    gain: float = 1.0
    gain_per_rad: float = 0.0
    gain_mach: float = 0.0

    def factor(self, alpha_rad, mach, mach_clamp: float) -> np.ndarray:
        return (self.gain + self.gain_per_rad * np.asarray(alpha_rad, dtype=float)
                + self.gain_mach * (prandtl_glauert(mach, mach_clamp) - 1.0))


@dataclass(frozen=True)
class CouplingLaw:
    """Vane sidewash coupling coefficient ``k_b0 + k_b1 alpha`` (rad of alpha per rad of beta)."""

    coupling: float = 0.0
    coupling_per_rad: float = 0.0

    def value(self, alpha_rad) -> np.ndarray:
        return self.coupling + self.coupling_per_rad * np.asarray(alpha_rad, dtype=float)


@dataclass(frozen=True)
class PressureLaw:
    """Hemispherical-head law ``dp = qc K_p(M) sin(2 theta)``, ``K_p = kp0 (1 + kp2 M^2)``."""

    coefficient: float = 2.25
    mach2: float = 0.0

    def k(self, mach) -> np.ndarray:
        m = np.asarray(mach, dtype=float)
        return self.coefficient * (1.0 + self.mach2 * m * m)

    def dp_pa(self, theta_rad, qc_pa, mach) -> np.ndarray:
        """Differential pressure for port-plane angle ``theta_rad`` at impact pressure ``qc_pa``."""
        return qc_pa * self.k(mach) * np.sin(2.0 * np.asarray(theta_rad, dtype=float))

    def angle_rad(self, dp_pa, qc_pa, mach) -> np.ndarray:
        """Inverse: ``0.5 asin(dp / (qc K_p))``, the argument clipped to [-1, 1] (port saturation)."""
        ratio = np.asarray(dp_pa, dtype=float) / (np.asarray(qc_pa, dtype=float) * self.k(mach))
        return 0.5 * np.arcsin(np.clip(ratio, -1.0, 1.0))


@dataclass(frozen=True)
class IrregularityLaw:
    """Amplitude envelope and spectrum of the nose-probe high-AOA irregularity."""

    onset_rad: float = math.radians(8.0)
    amplitude_per_rad: float = 0.0
    n_terms: int = 12
    alpha_wavenumber_min_per_rad: float = 800.0
    alpha_wavenumber_max_per_rad: float = 3000.0
    beta_wavenumber_min_per_rad: float = 500.0
    beta_wavenumber_max_per_rad: float = 2000.0


def irregularity_rad(alpha_rad, beta_rad, law: IrregularityLaw | None, seed: int) -> np.ndarray:
    """The nose-probe irregular error e(alpha, beta), rad (module docstring). Zero if ``law`` is None.

    Deterministic: the wavenumbers and phases come from ``default_rng([seed])`` alone, so the same
    function applies to every maneuver and aircraft.
    """
    alpha_rad = np.asarray(alpha_rad, dtype=float)
    if law is None or law.amplitude_per_rad == 0.0:
        return np.zeros_like(alpha_rad)
    w, v, phi = _irregularity_spectrum(law, int(seed))
    arg = alpha_rad[..., None] * w + np.asarray(beta_rad, dtype=float)[..., None] * v + phi
    envelope = law.amplitude_per_rad * np.maximum(alpha_rad - law.onset_rad, 0.0)
    return envelope * math.sqrt(2.0 / law.n_terms) * np.sin(arg).sum(axis=-1)


@lru_cache(maxsize=32)
def _irregularity_spectrum(law: IrregularityLaw, seed: int):
    rng = np.random.default_rng([seed])
    w = rng.uniform(law.alpha_wavenumber_min_per_rad, law.alpha_wavenumber_max_per_rad, law.n_terms)
    v = rng.uniform(law.beta_wavenumber_min_per_rad, law.beta_wavenumber_max_per_rad, law.n_terms)
    v *= rng.choice([-1.0, 1.0], law.n_terms)
    phi = rng.uniform(0.0, 2.0 * math.pi, law.n_terms)
    return w, v, phi


# ------------------------------------------------------------------ the model


@dataclass(frozen=True)
class LocalFlowModel:
    """A complete local-flow model (truth or the ADC's nominal), plus the probe transduction.

    The transduction (``side_probe_port_cant_rad``, the pressure laws) is probe geometry, not local
    flow: :meth:`without_local_flow` keeps it and makes every local-flow law the identity.
    """

    name: str
    mach_clamp: float
    vane_upwash: UpwashLaw
    vane_coupling: CouplingLaw
    side_probe_upwash: UpwashLaw
    side_probe_sidewash: SidewashLaw
    side_probe_port_cant_rad: float
    side_probe_pressure: PressureLaw
    nose_probe_sidewash: SidewashLaw
    nose_probe_pressure: PressureLaw
    nose_probe_irregularity: IrregularityLaw | None = None
    boom_alpha_upwash: UpwashLaw = UpwashLaw()
    boom_beta_upper_sidewash: SidewashLaw = SidewashLaw()
    boom_beta_lower_sidewash: SidewashLaw = SidewashLaw()

    def without_local_flow(self) -> LocalFlowModel:
        """Same probes, free stream at every sensor (identity upwash/sidewash, no irregularity)."""
        return dataclasses.replace(
            self, name=f"{self.name} (local flow off)",
            vane_upwash=UpwashLaw(), vane_coupling=CouplingLaw(),
            side_probe_upwash=UpwashLaw(), side_probe_sidewash=SidewashLaw(),
            nose_probe_sidewash=SidewashLaw(), nose_probe_irregularity=None,
            boom_alpha_upwash=UpwashLaw(), boom_beta_upper_sidewash=SidewashLaw(),
            boom_beta_lower_sidewash=SidewashLaw(),
        )

    # --- per sensor type: free stream at the sensor -> the local angle it senses -------------
    def vane_local_alpha_rad(self, alpha_rad, beta_rad, mach, gear, side_sign) -> np.ndarray:
        """Local AOA at a fuselage-side vane; ``side_sign`` = sign(y) (-1 left, +1 right)."""
        return (self.vane_upwash.local_alpha_rad(alpha_rad, mach, gear, self.mach_clamp)
                + side_sign * self.vane_coupling.value(alpha_rad) * beta_rad)

    def side_probe_local_rad(self, alpha_rad, beta_rad, mach, gear):
        """(alpha_loc, beta_loc) at a side probe, rad."""
        alpha_loc = self.side_probe_upwash.local_alpha_rad(alpha_rad, mach, gear, self.mach_clamp)
        beta_loc = self.side_probe_sidewash.factor(alpha_rad, mach, self.mach_clamp) * beta_rad
        return alpha_loc, beta_loc

    def side_probe_port_angle_rad(self, alpha_loc_rad, beta_loc_rad, side_sign) -> np.ndarray:
        """Angle of the local flow in a side probe's canted port plane (hemispherical head), rad."""
        c = self.side_probe_port_cant_rad
        d = direction_from_angles(alpha_loc_rad, beta_loc_rad)
        normal = d[..., 2] * math.cos(c) - side_sign * d[..., 1] * math.sin(c)
        return np.arctan2(normal, d[..., 0])

    def nose_probe_local_flank_rad(self, alpha_rad, beta_rad, flank_rad, mach,
                                   irregularity_seed: int | None) -> np.ndarray:
        """Local flank angle in the nose probe's Pb port plane; irregularity added if seeded."""
        flank_loc = self.nose_probe_sidewash.factor(alpha_rad, mach, self.mach_clamp) * flank_rad
        if irregularity_seed is not None:
            flank_loc = flank_loc + irregularity_rad(alpha_rad, beta_rad,
                                                     self.nose_probe_irregularity, irregularity_seed)
        return flank_loc

    def boom_local_alpha_rad(self, alpha_rad, mach) -> np.ndarray:
        """Local AOA at the boom alpha vane (small upwash; the boom does not see the gear)."""
        return self.boom_alpha_upwash.local_alpha_rad(alpha_rad, mach, 0.0, self.mach_clamp)

    def boom_local_flank_rad(self, sensor: str, alpha_rad, flank_rad, mach) -> np.ndarray:
        """Local flank angle at a boom sideslip vane (``boom_beta_upper_vane``/``..._lower_vane``)."""
        law = {"boom_beta_upper_vane": self.boom_beta_upper_sidewash,
               "boom_beta_lower_vane": self.boom_beta_lower_sidewash}[sensor]
        return law.factor(alpha_rad, mach, self.mach_clamp) * flank_rad


# ------------------------------------------------------------------ loading from TOML

_D2R = math.pi / 180.0








def _law(cls, raw: dict | None, where: str):
    """Build a law dataclass from a TOML table whose keys may say ``_deg`` (converted to rad)."""
    if raw is None:
        raise ValueError(f"{where}: missing table")
    keys = {f.name: Key(unit="rad" if f.name.endswith("_rad") else None) for f in dataclasses.fields(cls)}
    return cls(**check(raw, keys, where))


#: the tables of a local-flow file and their keys ("": the top level; the laws' keys: :func:`_law`);
#: the boom's tables are read only for the truth
_TABLES = {
    "": ("name", "mach_clamp", "vane", "side_probe", "nose_probe", "boom_alpha_vane", "boom_beta_upper_vane",
         "boom_beta_lower_vane"),
    "vane": ("upwash", "coupling"),
    "side_probe": ("port_cant_deg", "upwash", "sidewash", "pressure"),
    "nose_probe": ("sidewash", "pressure", "irregularity"),
    "boom_alpha_vane": ("upwash",), "boom_beta_upper_vane": ("sidewash",),
    "boom_beta_lower_vane": ("sidewash",),
}


def _model_from_raw(raw: dict, path: Path, *, truth: bool) -> LocalFlowModel:
    def table(*keys):
        node = raw
        for k in keys:
            node = node.get(k) if isinstance(node, dict) else None
        return node

    where = str(path)
    check(raw, _TABLES[""], where)
    for name, keys in _TABLES.items():
        if name and name in raw:
            check(raw[name], keys, f"{where}: [{name}]")
    sp = table("side_probe") or {}
    irr = table("nose_probe", "irregularity")
    kwargs = dict(
        name=str(raw.get("name", path.stem)),
        mach_clamp=float(raw.get("mach_clamp", 0.95)),
        vane_upwash=_law(UpwashLaw, table("vane", "upwash"), f"{where}: [vane.upwash]"),
        vane_coupling=_law(CouplingLaw, table("vane", "coupling"), f"{where}: [vane.coupling]"),
        side_probe_upwash=_law(UpwashLaw, table("side_probe", "upwash"),
                               f"{where}: [side_probe.upwash]"),
        side_probe_sidewash=_law(SidewashLaw, table("side_probe", "sidewash"),
                                 f"{where}: [side_probe.sidewash]"),
        side_probe_port_cant_rad=float(sp.get("port_cant_deg", 35.0)) * _D2R,
        side_probe_pressure=_law(PressureLaw, table("side_probe", "pressure"),
                                 f"{where}: [side_probe.pressure]"),
        nose_probe_sidewash=_law(SidewashLaw, table("nose_probe", "sidewash"),
                                 f"{where}: [nose_probe.sidewash]"),
        nose_probe_pressure=_law(PressureLaw, table("nose_probe", "pressure"),
                                 f"{where}: [nose_probe.pressure]"),
        nose_probe_irregularity=(_law(IrregularityLaw, irr, f"{where}: [nose_probe.irregularity]")
                                 if irr is not None else None),
    )
    if truth:
        kwargs.update(
            boom_alpha_upwash=_law(UpwashLaw, table("boom_alpha_vane", "upwash"),
                                   f"{where}: [boom_alpha_vane.upwash]"),
            boom_beta_upper_sidewash=_law(SidewashLaw, table("boom_beta_upper_vane", "sidewash"),
                                          f"{where}: [boom_beta_upper_vane.sidewash]"),
            boom_beta_lower_sidewash=_law(SidewashLaw, table("boom_beta_lower_vane", "sidewash"),
                                          f"{where}: [boom_beta_lower_vane.sidewash]"),
        )
    model = LocalFlowModel(**kwargs)
    if not 0.0 < model.mach_clamp < 1.0:
        raise ValueError(f"{where}: mach_clamp must be in (0, 1), got {model.mach_clamp}")
    return model


@lru_cache(maxsize=8)
def load_local_flow_truth(name_or_path: str | Path = "local_flow_truth") -> LocalFlowModel:
    """The fleet's local-flow truth (``aircraft_models/local_flow_truth.toml`` or a TOML path)."""
    path = resolve_data_file(name_or_path)
    return _model_from_raw(read_toml(path), path, truth=True)


@dataclass(frozen=True)
class TableGrid:
    """Breakpoints of the ADC's correction tables: local/free alpha (rad) x Mach."""

    alpha_bp_rad: tuple[float, ...]
    mach_bp: tuple[float, ...]

    def __post_init__(self) -> None:
        for name in ("alpha_bp_rad", "mach_bp"):
            bp = np.asarray(getattr(self, name))
            if bp.ndim != 1 or len(bp) < 2 or np.any(np.diff(bp) <= 0):
                raise ValueError(f"TableGrid.{name}: need >= 2 strictly increasing breakpoints")


@lru_cache(maxsize=8)
def load_adc_baseline(name_or_path: str | Path = "adc_baseline") -> tuple[LocalFlowModel, TableGrid]:
    """The ADC's nominal ("CFD/wind-tunnel") model and its table breakpoints (``adc_baseline.toml``)."""
    path = resolve_data_file(name_or_path)
    raw = read_toml(path)
    tables = raw.pop("tables", None)
    if tables is None:
        raise ValueError(f"{path}: missing [tables] (alpha_min_deg, alpha_max_deg, alpha_step_deg, "
                         "mach_min, mach_max, mach_step)")
    try:
        n_a = round((tables["alpha_max_deg"] - tables["alpha_min_deg"]) / tables["alpha_step_deg"])
        n_m = round((tables["mach_max"] - tables["mach_min"]) / tables["mach_step"])
        alpha_bp = np.linspace(tables["alpha_min_deg"], tables["alpha_max_deg"], n_a + 1) * _D2R
        mach_bp = np.linspace(tables["mach_min"], tables["mach_max"], n_m + 1)
    except KeyError as exc:
        raise ValueError(f"{path}: [tables] lacks {exc}") from None
    grid = TableGrid(tuple(float(a) for a in alpha_bp), tuple(float(m) for m in mach_bp))
    return _model_from_raw(raw, path, truth=False), grid
