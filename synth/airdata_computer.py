"""The airdata computer (ADC): pressure airdata and the baseline flow-angle corrections of paper Eq. 2.

Equations
---------
Pressure airdata (subsonic, ISA; gamma = 1.4, R = 287.05287 J/(kg K))::

    qc = pt - ps = ps ((1 + 0.2 M^2)^3.5 - 1)           M = sqrt(5 ((qc/ps + 1)^(2/7) - 1))
    Ts = Tt / (1 + 0.2 M^2)                             TAS = M sqrt(gamma R Ts)
    h_p = (T0 / L) (1 - (ps/p0)^(R L / g0))             (troposphere; above 11 km isothermal)

Baseline corrections (paper Eq. 2), generated as *tables* on breakpoint grids (alpha x Mach, one
per gear position) from the inverse of the ADC's nominal local-flow model
(``aircraft_models/adc_baseline.toml``; laws in :mod:`synth.local_flow`) and bilinearly
interpolated, as an ADC does::

    alpha_z{l,r} = f_v(alpha_{l,r}m, M, gear)                 table: nominal upwash inverse
    theta_{l,r}  = 0.5 asin(dp_{l,r} / (qc K_p(M)))           probe law, per probe
    (alpha_loc, beta_loc) from (theta_l, theta_r)             exact port-plane geometry:
        tan a = (tan th_l + tan th_r) / (2 cos c)     v/u = (tan th_l - tan th_r) / (2 sin c)
        tan b = (v/u) cos a
    alpha_zsp = T_a(alpha_loc, M, gear)                       table: nominal upwash inverse
    beta_zsp  = T_b(alpha_loc, M, gear) * beta_loc            table: 1 / nominal sidewash gain
    flank_np  = 0.5 asin(dp_np / (qc K_p(M)))
    alpha_adc = (alpha_d + alpha_x) / 2 = (alpha_zl + alpha_zr) / 2
    beta_znp  = atan(tan(T_np(alpha_adc, M) * flank_np) cos alpha_adc)   T_np = 1 / nominal gain

Tables extrapolate linearly in alpha beyond the breakpoints (so an identity table stays exact) and
clamp Mach to the breakpoint range. The vane coupling with sideslip is not corrected (f_v has no
beta input): it is what the estimator's f2 table models.

Pure kernels: arrays in SI / radians, no I/O, no state (tables are built once and cached).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from synth.local_flow import LocalFlowModel, TableGrid

GAMMA = 1.4
R_AIR_JPKGK = 287.05287
G0_MPS2 = 9.80665
ISA_T0_K = 288.15
ISA_P0_PA = 101325.0
ISA_LAPSE_KPM = 0.0065
ISA_TROPOPAUSE_M = 11000.0
_ISA_EXP = G0_MPS2 / (R_AIR_JPKGK * ISA_LAPSE_KPM)
ISA_T11_K = ISA_T0_K - ISA_LAPSE_KPM * ISA_TROPOPAUSE_M
ISA_P11_PA = ISA_P0_PA * (ISA_T11_K / ISA_T0_K) ** _ISA_EXP


# ------------------------------------------------------------------ pressure airdata


def impact_pressure_pa(mach: np.ndarray, p_static_pa: np.ndarray) -> np.ndarray:
    """Subsonic impact pressure qc = pt - ps from Mach and static pressure, Pa."""
    m = np.asarray(mach, dtype=float)
    return np.asarray(p_static_pa, dtype=float) * ((1.0 + 0.2 * m * m) ** 3.5 - 1.0)


def mach_from_pressures(qc_pa: np.ndarray, p_static_pa: np.ndarray) -> np.ndarray:
    """Subsonic Mach from impact and static pressure (inverse of :func:`impact_pressure_pa`)."""
    ratio = np.maximum(np.asarray(qc_pa, dtype=float) / np.asarray(p_static_pa, dtype=float), 0.0)
    return np.sqrt(5.0 * ((ratio + 1.0) ** (2.0 / 7.0) - 1.0))


def total_temperature_k(t_static_k: np.ndarray, mach: np.ndarray) -> np.ndarray:
    """Total (stagnation) temperature, recovery factor 1, K."""
    m = np.asarray(mach, dtype=float)
    return np.asarray(t_static_k, dtype=float) * (1.0 + 0.2 * m * m)


def tas_from_mach_mps(mach: np.ndarray, t_total_k: np.ndarray) -> np.ndarray:
    """True airspeed from Mach and total temperature, m/s."""
    m = np.asarray(mach, dtype=float)
    t_static_k = np.asarray(t_total_k, dtype=float) / (1.0 + 0.2 * m * m)
    return m * np.sqrt(GAMMA * R_AIR_JPKGK * t_static_k)


def pressure_altitude_m(p_static_pa: np.ndarray) -> np.ndarray:
    """ISA pressure altitude from static pressure (troposphere and lower stratosphere), m."""
    p = np.asarray(p_static_pa, dtype=float)
    tropo = ISA_T0_K / ISA_LAPSE_KPM * (1.0 - (p / ISA_P0_PA) ** (1.0 / _ISA_EXP))
    strato = ISA_TROPOPAUSE_M + R_AIR_JPKGK * ISA_T11_K / G0_MPS2 * np.log(ISA_P11_PA / p)
    return np.where(p >= ISA_P11_PA, tropo, strato)


# ------------------------------------------------------------------ tables


@dataclass(frozen=True, eq=False)
class BreakpointTable:
    """A 2-D table ``values[i, j]`` at ``(x_bp[i], y_bp[j])``, bilinear interpolation.

    Linear extrapolation in x beyond the breakpoints; y clamped to its range.
    """

    name: str
    x_bp: np.ndarray
    y_bp: np.ndarray
    values: np.ndarray

    def __call__(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        y = np.clip(np.asarray(y, dtype=float), self.y_bp[0], self.y_bp[-1])
        ix = np.clip(np.searchsorted(self.x_bp, x, side="right") - 1, 0, len(self.x_bp) - 2)
        iy = np.clip(np.searchsorted(self.y_bp, y, side="right") - 1, 0, len(self.y_bp) - 2)
        x0, x1 = self.x_bp[ix], self.x_bp[ix + 1]
        y0, y1 = self.y_bp[iy], self.y_bp[iy + 1]
        tx = (x - x0) / (x1 - x0)
        ty = (y - y0) / (y1 - y0)
        v = self.values
        lo = v[ix, iy] * (1.0 - tx) + v[ix + 1, iy] * tx
        hi = v[ix, iy + 1] * (1.0 - tx) + v[ix + 1, iy + 1] * tx
        return lo * (1.0 - ty) + hi * ty


def _gear_mix(up: BreakpointTable, down: BreakpointTable, x, y, gear_down) -> np.ndarray:
    g = np.asarray(gear_down, dtype=float)
    return up(x, y) * (1.0 - g) + down(x, y) * g


# ------------------------------------------------------------------ the computer


@dataclass(frozen=True, eq=False)
class AirdataComputer:
    """Baseline flow-angle corrections of paper Eq. 2, as tables built from a nominal model.

    Build with :func:`build_airdata_computer`. Inputs are the ADC's *measured* values (raw sensor
    angles or pressures, measured Mach, gear-down flag 0/1).
    """

    nominal: LocalFlowModel
    grid: TableGrid
    f_v_up: BreakpointTable
    f_v_down: BreakpointTable
    sp_alpha_up: BreakpointTable
    sp_alpha_down: BreakpointTable
    sp_beta_gain_up: BreakpointTable
    sp_beta_gain_down: BreakpointTable
    np_flank_gain: BreakpointTable

    def f_v(self, alpha_m_rad, mach, gear_down) -> np.ndarray:
        """Vane baseline: measured local vane angle -> free-stream AOA, rad."""
        return _gear_mix(self.f_v_up, self.f_v_down, alpha_m_rad, mach, gear_down)

    def side_probe_angle_rad(self, dp_pa, qc_pa, mach) -> np.ndarray:
        """Local angle in a side probe's port plane from Pa1 - Pa2 (paper Fig. 1 law), rad."""
        return self.nominal.side_probe_pressure.angle_rad(dp_pa, qc_pa, mach)

    def side_probe_local_rad(self, alpha_lsp_rad, alpha_rsp_rad):
        """(alpha_loc, beta_loc) from the two port-plane angles, exact geometry, rad."""
        c = self.nominal.side_probe_port_cant_rad
        tl, tr = np.tan(alpha_lsp_rad), np.tan(alpha_rsp_rad)
        alpha_loc = np.arctan((tl + tr) / (2.0 * math.cos(c)))
        v_over_u = (tl - tr) / (2.0 * math.sin(c))
        return alpha_loc, np.arctan(v_over_u * np.cos(alpha_loc))

    def f_sp(self, alpha_lsp_rad, alpha_rsp_rad, mach, gear_down):
        """Side-probe baseline: (alpha_lsp, alpha_rsp, M) -> (alpha_zsp, beta_zsp), rad."""
        alpha_loc, beta_loc = self.side_probe_local_rad(alpha_lsp_rad, alpha_rsp_rad)
        alpha = _gear_mix(self.sp_alpha_up, self.sp_alpha_down, alpha_loc, mach, gear_down)
        gain = _gear_mix(self.sp_beta_gain_up, self.sp_beta_gain_down, alpha_loc, mach, gear_down)
        return alpha, gain * beta_loc

    def nose_probe_flank_rad(self, dp_pa, qc_pa, mach) -> np.ndarray:
        """Local flank angle in the nose probe's Pb port plane from Pb1 - Pb2, rad."""
        return self.nominal.nose_probe_pressure.angle_rad(dp_pa, qc_pa, mach)

    def f_np(self, flank_np_rad, alpha_d_rad, alpha_x_rad, mach) -> np.ndarray:
        """Nose-probe baseline: (local flank, alpha_d, alpha_x, M_m) -> beta_znp, rad."""
        alpha_adc = 0.5 * (np.asarray(alpha_d_rad) + np.asarray(alpha_x_rad))
        flank = self.np_flank_gain(alpha_adc, mach) * flank_np_rad
        return np.arctan(np.tan(flank) * np.cos(alpha_adc))


@lru_cache(maxsize=16)
def build_airdata_computer(nominal: LocalFlowModel, grid: TableGrid) -> AirdataComputer:
    """Generate the ADC's tables on ``grid`` as the inverse of the ``nominal`` local-flow model.

    Table values at the breakpoints are exact (analytic inverse of the quadratic upwash law), so
    the only table error is interpolation between breakpoints.
    """
    a_bp = np.asarray(grid.alpha_bp_rad, dtype=float)
    m_bp = np.asarray(grid.mach_bp, dtype=float)
    a_grid, m_grid = np.meshgrid(a_bp, m_bp, indexing="ij")
    clamp = nominal.mach_clamp
    tables = {}
    for gear, tag in ((0.0, "up"), (1.0, "down")):
        tables[f"f_v_{tag}"] = BreakpointTable(
            f"f_v gear {tag}", a_bp, m_bp,
            nominal.vane_upwash.free_alpha_rad(a_grid, m_grid, gear, clamp))
        alpha_free = nominal.side_probe_upwash.free_alpha_rad(a_grid, m_grid, gear, clamp)
        tables[f"sp_alpha_{tag}"] = BreakpointTable(f"f_sp alpha gear {tag}", a_bp, m_bp,
                                                    alpha_free)
        gain = nominal.side_probe_sidewash.factor(alpha_free, m_grid, clamp)
        tables[f"sp_beta_gain_{tag}"] = BreakpointTable(f"f_sp beta gain gear {tag}", a_bp, m_bp,
                                                        1.0 / gain)
    tables["np_flank_gain"] = BreakpointTable(
        "f_np flank gain", a_bp, m_bp, 1.0 / nominal.nose_probe_sidewash.factor(a_grid, m_grid, clamp))
    for t in tables.values():
        if not np.all(np.isfinite(t.values)):
            raise ValueError(f"ADC table {t.name!r} from model {nominal.name!r} is not finite on its "
                             "grid: check the model's gains (a sidewash gain crosses zero?)")
        t.values.setflags(write=False)
    return AirdataComputer(nominal=nominal, grid=grid, **tables)
