"""The INS measures the velocity of its own point, not of the CG (issue 13, must-show 3).

A JSBSim 3211 at Mach 0.5 (pitch rates to ~10 deg/s) is instrumented with every error off; the
velocity of the INS point is computed here, independently of ``synth``, from the truth columns
(earth-relative body velocity of the CG, body rates, Euler angles, CG position) and the INS position
of the airframe (the manifest's ``airframe.positions_body_m.ins``)::

    v_ins_ned = C_nb(phi, theta, psi) (v_cg + omega x (r_ins - r_cg))

and compared with the recorded ``vn_mps ve_mps vd_mps`` at their recorded delay
(``injected["time_shift_s.vn_mps"]``). The CG's velocity differs by omega x (r_ins - r_cg), about
q * 2.1 m = 0.37 m/s in this maneuver: the test fails for the CG point.
"""

from __future__ import annotations

import numpy as np
import pytest
from _synthetic_truth import dcm_body_to_ned

from aircraft_models import load_fleet
from synth.environment import Environment
from synth.errors import ErrorConfig
from synth.flight import fly_maneuver
from synth.instrument import instrument
from synth.maneuvers import ManeuverSpec

FLEET = load_fleet()
CONFIG = FLEET.configuration("PV1-NP")
R_INS_M = FLEET.airframe.position("ins")
INS_COLUMNS = ["vn_mps", "ve_mps", "vd_mps"]
#: the lever-arm effect the test must see: CG and INS velocities differ by more than this, m/s
LEVER_ARM_VISIBLE_MPS = 0.05


@pytest.fixture(scope="module")
def truth():
    spec = ManeuverSpec.from_dict({"kind": "3211", "mach": 0.5, "altitude_m": 6000.0,
                                   "duration_s": 12.0})
    return fly_maneuver(spec, FLEET.airframe, CONFIG.aircraft, Environment(planet="flat"))[0]


def ned_velocity_from_columns(df, point_m=None) -> np.ndarray:
    """(N, 3) NED velocity of the body point ``point_m`` (None: the CG) from the truth columns."""
    v = df[["true_u_mps", "true_v_mps", "true_w_mps"]].to_numpy()
    if point_m is not None:
        omega = df[["true_p_rps", "true_q_rps", "true_r_rps"]].to_numpy()
        lever = point_m - df[["true_r_cg_x_m", "true_r_cg_y_m", "true_r_cg_z_m"]].to_numpy()
        v = v + np.cross(omega, lever)
    c_nb = dcm_body_to_ned(df[["true_phi_rad", "true_theta_rad", "true_psi_rad"]].to_numpy())
    return np.einsum("nij,nj->ni", c_nb, v)


def shift_in_samples(shift_s: float, rate_hz: float) -> int:
    n = round(shift_s * rate_hz)
    assert abs(shift_s * rate_hz - n) < 1e-9, "the delay must be a whole number of common samples"
    return n


@pytest.mark.parametrize("ins_delay_s", [0.0, 0.025])
def test_ins_velocity_is_the_velocity_of_the_ins_point(truth, ins_delay_s):
    """Ideal recorders, INS latency 0 or 25 ms = 3 truth steps (120 Hz) = 1 common sample (40 Hz):
    every recorded sample is a truth sample, so no interpolation error, only float rounding
    (velocities of ~250 m/s, eps 2e-16: ~1e-13 m/s); 1e-9 m/s leaves room."""
    errors = ErrorConfig.none().with_values({"recorders.ins.delay_s": ins_delay_s})
    m = instrument(truth, FLEET.airframe, CONFIG, errors, common_rate_hz=40.0)
    df = m.data
    n = shift_in_samples(m.injected["time_shift_s.vn_mps"], 40.0)
    assert n == round(ins_delay_s * 40.0)
    recorded = df[INS_COLUMNS].to_numpy()[n:]
    ins_point = ned_velocity_from_columns(df, R_INS_M)[:len(df) - n]
    cg_point = ned_velocity_from_columns(df)[:len(df) - n]
    err = np.abs(recorded - ins_point).max(axis=0)
    assert np.all(err < 1e-9), f"INS velocity off the INS point's by {err} m/s (N, E, D)"
    lever_arm = np.abs(recorded - cg_point).max()
    assert lever_arm > LEVER_ARM_VISIBLE_MPS, (
        f"the CG point's velocity differs by {lever_arm:.3f} m/s only: the maneuver must "
        "make the lever arm visible")
    # the truth columns: the CG's velocity (unchanged meaning) and the INS point's
    true_ins = df[["true_vn_ins_mps", "true_ve_ins_mps", "true_vd_ins_mps"]].to_numpy()
    assert np.abs(true_ins - ned_velocity_from_columns(df, R_INS_M)).max() < 1e-9
    true_cg = df[["true_vn_mps", "true_ve_mps", "true_vd_mps"]].to_numpy()
    assert np.abs(true_cg - ned_velocity_from_columns(df)).max() < 1e-9


def test_ins_velocity_with_a_real_recorders_timing_within_the_interpolation_error(truth):
    """The typical INS recorder (50 Hz, clock 30 ms late) plus a 10 ms INS latency: the recorder
    samples the 120 Hz truth between its samples, the 50 Hz stream is resampled onto the 40 Hz
    common base, and the reference (at truth rate) is evaluated at the delayed time, all by linear
    interpolation, whose error is at most h^2 / 8 max|v''| for a step h. The bound is
    (2 h_truth^2 + h_ins^2) / 8 max|v''|, max|v''| from the reference's second differences
    (doubled: a sampled estimate of a maximum)."""
    errors = ErrorConfig.none().with_values({"recorders.ins.rate_hz": 50.0,
                                             "recorders.ins.clock_offset_s": 0.030,
                                             "recorders.ins.delay_s": 0.010})
    m = instrument(truth, FLEET.airframe, CONFIG, errors, common_rate_hz=40.0)
    df = m.data
    shift_s = m.injected["time_shift_s.vn_mps"]
    assert shift_s == pytest.approx(0.040)
    # the reference at the truth rate, from the truth the columns are sampled from
    t = truth.t_s
    c_nb = dcm_body_to_ned(truth.euler_rad)
    lever = R_INS_M - truth.r_cg_body_m
    ref = np.einsum("nij,nj->ni", c_nb, truth.v_body_mps + np.cross(truth.omega_body_rps, lever))
    cg = np.einsum("nij,nj->ni", c_nb, truth.v_body_mps)
    h_t = t[1] - t[0]
    v_dd_max = np.abs(np.diff(ref, 2, axis=0)).max(axis=0) / h_t**2
    bound = 2.0 * (2 * h_t**2 + (1 / 50.0) ** 2) / 8.0 * v_dd_max
    t_true = df["t_s"].to_numpy() - shift_s
    recorded = df[INS_COLUMNS].to_numpy()
    ins_point = np.stack([np.interp(t_true, t, ref[:, i]) for i in range(3)], axis=1)
    cg_point = np.stack([np.interp(t_true, t, cg[:, i]) for i in range(3)], axis=1)
    err = np.abs(recorded - ins_point).max(axis=0)
    assert np.all(err <= bound), f"INS velocity off the INS point's by {err} m/s, bound {bound}"
    lever_arm = np.abs(recorded - cg_point).max()
    assert lever_arm > LEVER_ARM_VISIBLE_MPS
    assert bound.max() < 0.1 * lever_arm, "the bound must tell the INS point from the CG"
