"""The instrumentation half of synth: sensors, local flow, airdata computer, recorders, errors.

All against analytic, kinematically exact flight histories (tests/_synthetic_truth.py), no JSBSim.
The truth is sampled at 120 Hz from t = 0 and the default common time base is 40 Hz, so with ideal
recorders every common sample falls on a truth sample and interpolation adds no error: what remains
is float rounding (~1e-16 relative), which is why "exact" below means 1e-12 rad / 1e-9 m/s^2.
"""

from __future__ import annotations

import dataclasses
import math
from types import MappingProxyType

import numpy as np
import pandas as pd
import pytest
from _synthetic_truth import AnalyticFlight
from hypothesis import given, settings
from hypothesis import strategies as st

from aircraft_models import ALL_SENSORS, load_fleet
from synth.airdata_computer import build_airdata_computer
from synth.errors import ErrorConfig
from synth.instrument import CHANNEL_TRUTH, channel_response, instrument
from synth.local_flow import (
    UpwashLaw,
    air_velocity_at_sensor_body_mps,
    flow_angles_rad,
    load_adc_baseline,
    load_local_flow_truth,
)

FLEET = load_fleet()
AIRFRAME = FLEET.airframe
CFG_NP = FLEET.configuration("PV1-NP")
CFG_BOOM = FLEET.configuration("PT1-BOOM")
FLIGHT = AnalyticFlight()
TRUTH = FLIGHT.truth(duration_s=20.0)
DEG = math.pi / 180.0
EXACT_RAD = 1e-12  # float rounding of angles of O(1) rad through a few operations
TRUTH_MODEL = load_local_flow_truth()
NOMINAL, GRID = load_adc_baseline()


def run(errors: ErrorConfig, cfg=CFG_NP, truth=TRUTH, **kw) -> pd.DataFrame:
    return instrument(truth, AIRFRAME, cfg, errors, **kw).data


def analytic_sensor_flow(t: np.ndarray, sensor_position_m) -> np.ndarray:
    """V + omega x (r_s - r_cg), written out component by component (independent of synth)."""
    v = FLIGHT.v_air(t)
    p, q, r = FLIGHT.omega(t).T
    d = np.asarray(sensor_position_m) - FLIGHT.r_cg(t)
    return np.stack([v[:, 0] + q * d[:, 2] - r * d[:, 1],
                     v[:, 1] + r * d[:, 0] - p * d[:, 2],
                     v[:, 2] + p * d[:, 1] - q * d[:, 0]], axis=1)


def angles(v: np.ndarray):
    return (np.arctan2(v[:, 2], v[:, 0]), np.arcsin(v[:, 1] / np.linalg.norm(v, axis=1)),
            np.arctan2(v[:, 1], v[:, 0]))


NONE = run(ErrorConfig.none())
NONE_BOOM = run(ErrorConfig.none(), CFG_BOOM)


# ---------------------------------------------------------------- (a) every error zero


@pytest.mark.parametrize("cfg", [CFG_NP, CFG_BOOM], ids=lambda c: c.id)
def test_zero_errors_vane_and_boom_channels_are_the_true_angle_at_the_sensor(cfg):
    df = NONE if cfg is CFG_NP else NONE_BOOM
    t = df["t_s"].to_numpy()
    expected = {
        "alpha_zl_rad": angles(analytic_sensor_flow(t, AIRFRAME.position("vane_left")))[0],
        "alpha_zr_rad": angles(analytic_sensor_flow(t, AIRFRAME.position("vane_right")))[0],
    }
    if cfg.nose_sensor == "boom":
        expected["alpha_zb_rad"] = angles(analytic_sensor_flow(
            t, AIRFRAME.position("boom_alpha_vane")))[0]
        expected["beta_zbu_rad"] = angles(analytic_sensor_flow(
            t, AIRFRAME.position("boom_beta_upper_vane")))[2]  # a sideslip vane senses the flank
        expected["beta_zbl_rad"] = angles(analytic_sensor_flow(
            t, AIRFRAME.position("boom_beta_lower_vane")))[2]
        assert "beta_znp_rad" not in df, "the boom replaces the nose probe"
    else:
        assert not {"alpha_zb_rad", "beta_zbu_rad", "beta_zbl_rad"} & set(df)
    for ch, want in expected.items():
        err = np.abs(df[ch].to_numpy() - want).max()
        assert err < EXACT_RAD, f"{ch} differs from the exact angle at its sensor by {err:.2e} rad"
        assert np.abs(df[ch] - df[CHANNEL_TRUTH[ch]]).max() < EXACT_RAD


def test_zero_errors_side_probe_pair_equals_truth_at_mean_position_to_second_order():
    """The ADC combines two port-plane angles measured at y = +-Y; the truth is taken at their
    mean position. With eta = |omega| Y / u, eps = r Y / u, delta = p Y / u, T_w = tan(alpha),
    T_v = v/u at the mean position, the exact combination is (derivation in the report)
        tan(alpha_rec) = (T_w + eps (delta - T_v tan c)) / (1 - eps^2)
        (v/u)_rec      = (T_v - (delta + eps T_w) / tan c) / (1 - eps^2)
    so alpha is exact to second order (eta^2, eta*beta), while beta has a FIRST-order roll term
    -Y (p + r tan(alpha)) / (u tan c): a roll rate makes the two probes see opposite local alpha,
    which a canted port pair reads as sideslip. It is checked to second order."""
    df = NONE
    t = df["t_s"].to_numpy()
    half_y = AIRFRAME.position("side_probe_right")[1]
    r_mean = 0.5 * (AIRFRAME.position("side_probe_left") + AIRFRAME.position("side_probe_right"))
    v = analytic_sensor_flow(t, r_mean)
    alpha, beta, _ = angles(v)
    p, q, r = FLIGHT.omega(t).T
    u = v[:, 0]
    eta = np.linalg.norm(FLIGHT.omega(t), axis=1) * half_y / u
    t_w, t_v = v[:, 2] / u, v[:, 1] / u
    tan_c = math.tan(TRUTH_MODEL.side_probe_port_cant_rad)
    assert np.abs(df["true_alpha_sp_rad"] - alpha).max() < EXACT_RAD
    bound_alpha = 1.05 * eta * (eta + np.abs(t_v) * tan_c + 2 * eta * np.abs(t_w))
    err_alpha = np.abs(df["alpha_zsp_rad"].to_numpy() - alpha)
    assert np.all(err_alpha <= bound_alpha + EXACT_RAD), (err_alpha - bound_alpha).max()
    first_order = -np.cos(alpha) * np.cos(beta) ** 2 * half_y * (p + r * t_w) / (u * tan_c)
    # second-order remainder: the alpha error through cos(alpha) (R1), the curvature of atan
    # (R2) and the 1 / (1 - eps^2) factor (R3); factor 2 for the neglected higher orders
    tan_beta = np.tan(beta)
    r1 = np.abs(t_v) * eta * (eta + np.abs(t_v) * tan_c)
    r2 = np.abs(tan_beta) * (eta * (1 + np.abs(t_w)) / tan_c) ** 2
    r3 = 2 * eta**2 * (np.abs(t_v) + eta * (1 + np.abs(t_w)) / tan_c)
    bound_beta = 2.0 * (r1 + r2 + r3)
    err_beta = df["beta_zsp_rad"].to_numpy() - beta
    assert np.abs(first_order).max() > 10 * bound_beta.max(), "the check must see the roll term"
    assert np.all(np.abs(err_beta - first_order) <= bound_beta + EXACT_RAD), (
        np.abs(err_beta - first_order) - bound_beta).max()


def test_zero_errors_nose_probe_is_exact_up_to_the_vane_alpha_it_uses():
    """f_np converts the flank angle to sideslip, tan(beta) = tan(flank) cos(alpha), with the vanes'
    alpha (alpha_d, alpha_x at the vanes, not at the nose): |d beta / d alpha| <= |tan flank sin
    alpha|, so the error is bounded by that times the kinematic alpha difference."""
    df = NONE
    t = df["t_s"].to_numpy()
    alpha, beta, flank = angles(analytic_sensor_flow(t, AIRFRAME.position("nose_probe")))
    alpha_vanes = 0.5 * (df["true_alpha_vane_left_rad"] + df["true_alpha_vane_right_rad"])
    bound = 1.01 * np.abs(np.tan(flank)) * np.abs(alpha_vanes - alpha).to_numpy()
    err = np.abs(df["beta_znp_rad"].to_numpy() - beta)
    assert np.all(err <= bound + EXACT_RAD), (err - bound).max()
    assert np.abs(df["true_beta_nose_probe_rad"] - beta).max() < EXACT_RAD


def test_zero_errors_inertial_and_airdata_channels_are_the_truth():
    df = NONE
    t = df["t_s"].to_numpy()
    omega = FLIGHT.omega(t)
    omega_dot = AnalyticFlight.derivative(FLIGHT.omega, t)
    lever = AIRFRAME.position("imu") - FLIGHT.r_cg(t)
    a_imu = df[["ax_imu_mps2", "ay_imu_mps2", "az_imu_mps2"]].to_numpy()
    a_cg = a_imu - np.cross(omega_dot, lever) - np.cross(omega, np.cross(omega, lever))
    # omega_dot of the fixture and of the test: the same 5-point stencil, rounding ~1e-10 rad/s^2
    assert np.abs(a_cg - FLIGHT.specific_force_cg(t)).max() < 1e-8
    lever_arm = np.abs(a_imu - FLIGHT.specific_force_cg(t)).max()
    assert lever_arm > 1e-3, "the IMU is off the CG: the lever arm must be visible"
    assert np.abs(df[["p_rps", "q_rps", "r_rps"]].to_numpy() - omega).max() < EXACT_RAD
    assert np.abs(df[["phi_rad", "theta_rad", "psi_rad"]].to_numpy() - FLIGHT.euler(t)).max() \
        < EXACT_RAD
    # TAS: qc -> Mach -> TAS round trip through (1 + 0.2 M^2)^3.5, relative rounding ~1e-14
    tas = np.linalg.norm(FLIGHT.v_air(t), axis=1)
    assert np.abs(df["tas_mps"] - tas).max() < 1e-9
    # the fixture's atmosphere is the ISA at the geometric height: pressure altitude = height
    assert np.abs(df["h_baro_m"] - df["true_h_m"]).max() < 1e-6
    assert np.abs(df["h_dgps_m"] - df["true_h_m"]).max() < 1e-9
    ned = df[["vn_mps", "ve_mps", "vd_mps"]].to_numpy()
    from _synthetic_truth import dcm_body_to_ned
    # the INS measures the velocity of its own point: v_cg + omega x (r_ins - r_cg), in NED
    c_nb = dcm_body_to_ned(FLIGHT.euler(t))
    v_ins = FLIGHT.v_body(t) + np.cross(omega, AIRFRAME.position("ins") - FLIGHT.r_cg(t))
    want = np.einsum("nij,nj->ni", c_nb, v_ins)
    assert np.abs(ned - want).max() < 1e-9
    assert np.abs(df[["true_vn_ins_mps", "true_ve_ins_mps", "true_vd_ins_mps"]].to_numpy()
                  - want).max() < 1e-9
    cg = np.einsum("nij,nj->ni", c_nb, FLIGHT.v_body(t))
    assert np.abs(df[["true_vn_mps", "true_ve_mps", "true_vd_mps"]].to_numpy() - cg).max() < 1e-9
    assert np.abs(ned - cg).max() > 1e-3, "the INS is off the CG: the lever arm must be visible"
    assert not df["gear_down"].any()


# ---------------------------------------------------------------- (b) one error at a time


def changed_columns(a: pd.DataFrame, b: pd.DataFrame) -> set[str]:
    """Columns that differ; a clean channel (true_clean_X) may change only together with X."""
    assert list(a.columns) == list(b.columns)
    assert np.array_equal(a["t_s"], b["t_s"])
    changed = {c for c in a.columns if not np.array_equal(a[c].to_numpy(), b[c].to_numpy(), equal_nan=True)}
    clean = {c for c in changed if c.startswith("true_clean_")}
    for c in clean:
        assert c.removeprefix("true_clean_") in changed, f"{c} changed but its channel did not"
    return changed - clean


def with_bias(sensor: str, bias_rad: float):
    """PV1-NP with one installation bias; every other sensor perfectly mounted."""
    biases = {s: (bias_rad if s == sensor else 0.0) for s in ALL_SENSORS}
    ac = dataclasses.replace(CFG_NP.aircraft, installation_bias_rad=MappingProxyType(biases))
    return dataclasses.replace(CFG_NP, aircraft=ac)


def test_vane_installation_bias_shifts_its_raw_angle_exactly_and_the_corrected_one_by_f_v():
    base_errors = ErrorConfig.none().with_values({"local_flow": True, "baseline_mismatch": True})
    base = run(base_errors)
    biased = run(dataclasses.replace(base_errors, installation_biases=True),
                 with_bias("vane_left", 0.3 * DEG))
    assert changed_columns(base, biased) == {"alpha_lm_rad", "alpha_zl_rad", "beta_znp_rad"}, (
        "a left-vane bias moves alpha_lm, its correction alpha_zl, and beta_znp (f_np uses the "
        "vane alpha) - nothing else")
    assert np.abs(biased["alpha_lm_rad"] - base["alpha_lm_rad"] - 0.3 * DEG).max() < EXACT_RAD
    adc = build_airdata_computer(NOMINAL, GRID)
    want = adc.f_v(base["alpha_lm_rad"] + 0.3 * DEG, base["mach"], 0.0) - base["alpha_zl_rad"]
    assert np.abs(biased["alpha_zl_rad"] - base["alpha_zl_rad"] - want).max() < EXACT_RAD
    slope = want / (0.3 * DEG)  # f_v' ~ 1 / upwash gain of the nominal model
    assert np.all((slope > 1 / 1.5) & (slope < 1 / 1.1)), slope.describe()


def test_installation_biases_switch_applies_the_fleet_values():
    df = run(ErrorConfig.none().with_values({"installation_biases": True}))
    inj = instrument(TRUTH, AIRFRAME, CFG_NP, ErrorConfig.none().with_values(
        {"installation_biases": True})).injected
    for s in CFG_NP.sensors:
        assert inj[f"{s}.installation_bias_rad"] == CFG_NP.aircraft.installation_bias_rad[s]
    assert np.abs(df["alpha_rm_rad"] - NONE["alpha_rm_rad"]
                  - CFG_NP.aircraft.installation_bias_rad["vane_right"]).max() < EXACT_RAD


@pytest.mark.parametrize("axis, column", [(0, "ax_imu_mps2"), (1, "ay_imu_mps2"),
                                          (2, "az_imu_mps2")])
def test_accelerometer_bias_shifts_only_its_axis(axis, column):
    bias = [0.0, 0.0, 0.0]
    bias[axis] = 0.15
    df = run(ErrorConfig.with_only("imu.accel_bias_mps2", bias))
    assert changed_columns(NONE, df) == {column}
    assert np.abs(df[column] - NONE[column] - 0.15).max() < 1e-12


def test_gyro_bias_shifts_only_its_axis():
    df = run(ErrorConfig.with_only("imu.gyro_bias_rps", [0.0, 0.004, 0.0]))
    assert changed_columns(NONE, df) == {"q_rps"}
    assert np.abs(df["q_rps"] - NONE["q_rps"] - 0.004).max() < EXACT_RAD


def linear_interp_bound(f, t_query, h_s: float) -> float:
    """|linear interpolation on a grid of step h - f| <= h^2 / 8 max |f''| (f'' by differences)."""
    d2 = np.abs(np.gradient(np.gradient(f(t_query), t_query), t_query))
    return h_s**2 / 8.0 * 1.5 * d2.max()  # 1.5: the difference estimate of max|f''| on a grid


def test_sensor_delay_reproduces_the_lagged_signal():
    tau = 0.075
    df = run(ErrorConfig.with_only("sensors.vane_right.delay_s", tau))
    t = df["t_s"].to_numpy()
    assert t[0] >= tau - 1e-9, "the common time base starts where the lagged stream has truth"

    def alpha_vane_right(tq):
        return angles(analytic_sensor_flow(tq, AIRFRAME.position("vane_right")))[0]

    want = alpha_vane_right(t - tau)
    bound = linear_interp_bound(alpha_vane_right, t, TRUTH.dt_s)
    err = np.abs(df["alpha_rm_rad"].to_numpy() - want)
    assert err.max() <= bound, f"y(t - tau) missed by {err.max():.2e} > {bound:.2e} rad"
    assert np.abs(df["alpha_zr_rad"].to_numpy() - want).max() <= bound
    # every other channel is the undelayed one at the same times
    same = NONE.set_index("t_s").loc[t].reset_index()
    assert changed_columns(same, df) == {"alpha_rm_rad", "alpha_zr_rad", "beta_znp_rad"}


def test_channel_delay_on_one_ins_channel():
    tau = 0.12
    df = run(ErrorConfig.with_only("channel_delays_s.theta_rad", tau))
    t = df["t_s"].to_numpy()
    want = np.interp(t - tau, TRUTH.t_s, TRUTH.euler_rad[:, 1])
    assert np.abs(df["theta_rad"] - want).max() < EXACT_RAD
    same = NONE.set_index("t_s").loc[t].reset_index()
    assert changed_columns(same, df) == {"theta_rad"}


@pytest.mark.parametrize("recorder, columns", [
    ("ins", ("phi_rad", "theta_rad", "psi_rad", "vn_mps", "ve_mps", "vd_mps")),
    ("dgps", ("h_dgps_m",)),
])
def test_recorder_clock_offset_shifts_all_of_its_channels(recorder, columns):
    offset = 0.05
    df = run(ErrorConfig.with_only(f"recorders.{recorder}.clock_offset_s", offset))
    t = df["t_s"].to_numpy()
    same = NONE.set_index("t_s").loc[t].reset_index()
    assert changed_columns(same, df) == set(columns)
    # the sample stamped t was taken at true time t - offset
    for c in columns:
        lagged = np.interp(t - offset, NONE["t_s"], NONE[c])
        assert np.abs(df[c] - lagged).max() < 1e-9, c


def test_dru_latency_lags_every_dru_channel():
    df = run(ErrorConfig.with_only("recorders.dru.delay_s", 0.025))
    t = df["t_s"].to_numpy()
    same = NONE.set_index("t_s").loc[t].reset_index()
    changed = changed_columns(same, df)
    assert {"alpha_zl_rad", "ax_imu_mps2", "q_rps", "tas_mps", "beta_znp_rad"} <= changed
    assert not changed & {"phi_rad", "vn_mps", "h_dgps_m"} and not any(
        c.startswith("true_") for c in changed)
    want = np.interp(t - 0.025, TRUTH.t_s, TRUTH.omega_body_rps[:, 1])
    assert np.abs(df["q_rps"] - want).max() < EXACT_RAD


def test_vane_noise_has_the_set_std_and_touches_only_its_channels():
    sigma = 0.07 * DEG
    df = run(ErrorConfig.with_only("sensors.vane_left.noise_rad", sigma))
    noise = (df["alpha_lm_rad"] - NONE["alpha_lm_rad"]).to_numpy()
    n = len(noise)
    # sample std of n Gaussian draws: relative standard error 1/sqrt(2(n-1)); 5 of them
    assert abs(noise.std(ddof=1) / sigma - 1) < 5 / math.sqrt(2 * (n - 1))
    assert abs(noise.mean()) < 5 * sigma / math.sqrt(n)
    assert changed_columns(NONE, df) == {"alpha_lm_rad", "alpha_zl_rad", "beta_znp_rad"}


def test_probe_pressure_noise_has_the_set_std_in_pascal():
    sigma_pa = 20.0
    df = run(ErrorConfig.with_only("sensors.side_probe_left.noise_pa", sigma_pa))
    noise = (df["dp_alpha_lsp_pa"] - NONE["dp_alpha_lsp_pa"]).to_numpy()
    assert abs(noise.std(ddof=1) / sigma_pa - 1) < 5 / math.sqrt(2 * (len(noise) - 1))
    assert changed_columns(NONE, df) == {"dp_alpha_lsp_pa", "alpha_lsp_rad", "alpha_zsp_rad",
                                         "beta_zsp_rad"}
    # the angle noise is the pressure noise over d(dp)/d(theta) = 2 qc K cos(2 theta)
    k = TRUTH_MODEL.side_probe_pressure.k(NONE["mach"])
    slope = 2 * NONE["qc_pa"] * k * np.cos(2 * NONE["alpha_lsp_rad"])
    angle_noise = (df["alpha_lsp_rad"] - NONE["alpha_lsp_rad"]).to_numpy()
    assert np.allclose(angle_noise, noise / slope, rtol=1e-3, atol=1e-9)


def test_noise_through_a_real_recorder_rate_and_resampling():
    """DRU at 64 Hz, common base 40 Hz: the stream carries the set std; linear resampling with
    weights w, 1-w of two independent samples leaves std * sqrt(mean(w^2 + (1-w)^2))."""
    sigma = 0.01
    errors = ErrorConfig.with_only("imu.accel_noise_mps2", sigma).with_values(
        {"recorders.dru.rate_hz": 64.0})
    clean = instrument(TRUTH, AIRFRAME, CFG_NP, ErrorConfig.none().with_values(
        {"recorders.dru.rate_hz": 64.0}))
    noisy = instrument(TRUTH, AIRFRAME, CFG_NP, errors)
    s_noise = (noisy.streams["dru"]["az_imu_mps2"] - clean.streams["dru"]["az_imu_mps2"]).to_numpy()
    assert np.allclose(np.diff(noisy.streams["dru"]["t_s"]), 1 / 64)
    assert abs(s_noise.std(ddof=1) / sigma - 1) < 5 / math.sqrt(2 * (len(s_noise) - 1))
    t = noisy.data["t_s"].to_numpy()
    w = (t * 64.0) % 1.0
    shrink = math.sqrt(np.mean(w**2 + (1 - w) ** 2))
    c_noise = (noisy.data["az_imu_mps2"] - clean.data["az_imu_mps2"]).to_numpy()
    # resampled values are correlated in groups; 8 standard errors of the effective sample
    assert abs(c_noise.std(ddof=1) / (sigma * shrink) - 1) < 8 / math.sqrt(2 * len(c_noise))
    assert shrink < 0.95, "64 Hz to 40 Hz must interpolate between samples"


def test_quantization_step():
    step = 0.05 * DEG
    df = run(ErrorConfig.with_only("sensors.vane_right.quant_rad", step))
    x = df["alpha_rm_rad"].to_numpy() / step
    assert np.abs(x - np.round(x)).max() < 1e-9, "every sample is a multiple of the step"
    assert np.abs(df["alpha_rm_rad"] - NONE["alpha_rm_rad"]).max() <= step / 2 + EXACT_RAD
    assert len(np.unique(np.round(x))) > 20


def test_scale_factor_of_a_boom_vane():
    df = run(ErrorConfig.with_only("sensors.boom_beta_lower_vane.scale", 0.02), CFG_BOOM)
    assert changed_columns(NONE_BOOM, df) == {"beta_zbl_rad"}
    assert np.abs(df["beta_zbl_rad"] - 1.02 * NONE_BOOM["beta_zbl_rad"]).max() < EXACT_RAD


def test_local_flow_alone_moves_only_flow_channels_and_local_truth():
    df = run(ErrorConfig.with_only("local_flow", True))
    changed = changed_columns(NONE, df)
    assert {"alpha_lm_rad", "alpha_rm_rad", "dp_alpha_lsp_pa", "dp_beta_np_pa"} <= changed
    allowed = {"alpha_lm_rad", "alpha_rm_rad", "alpha_lsp_rad", "alpha_rsp_rad",
               "dp_alpha_lsp_pa", "dp_alpha_rsp_pa", "dp_beta_np_pa", "flank_np_rad",
               "alpha_zl_rad", "alpha_zr_rad", "alpha_zsp_rad", "beta_zsp_rad", "beta_znp_rad"}
    assert changed - allowed == {c for c in changed if c.startswith(("true_local_",
                                                                     "true_port_angle_"))}
    # local alpha at the vanes is 1.1-1.5 x free stream (SPEC §6) where alpha is not tiny
    a = df["true_alpha_vane_left_rad"].to_numpy()
    ratio = df["true_local_alpha_vane_left_rad"].to_numpy()[a > 3 * DEG] / a[a > 3 * DEG]
    assert ratio.min() > 1.1 and ratio.max() < 1.5
    # mismatch off: the ADC inverts the truth, leaving the uncorrected sidewash coupling
    # s_y (k_b0 + k_b1 alpha) beta through f_v' ~ 1/gain, plus table interpolation
    k = TRUTH_MODEL.vane_coupling.value(df["true_alpha_vane_left_rad"])
    coupling = -k * df["true_beta_vane_left_rad"] / TRUTH_MODEL.vane_upwash.gain
    resid = df["alpha_zl_rad"] - df["true_alpha_vane_left_rad"] - coupling
    assert np.abs(resid).max() < 0.15 * np.abs(coupling).max() + 2e-5


def test_baseline_mismatch_alone_is_the_nominal_tables_on_free_stream():
    df = run(ErrorConfig.with_only("baseline_mismatch", True))
    adc = build_airdata_computer(NOMINAL, GRID)
    want = adc.f_v(df["true_alpha_vane_left_rad"], df["mach"], 0.0)
    assert np.abs(df["alpha_zl_rad"] - want).max() < EXACT_RAD
    assert np.abs(df["alpha_lm_rad"] - NONE["alpha_lm_rad"]).max() == 0.0


def test_nose_probe_irregularity_grows_with_alpha_and_looks_like_noise():
    law = TRUTH_MODEL.nose_probe_irregularity
    flight = AnalyticFlight(w0_mps=40.0)  # alpha ~ 15 deg, well above the onset
    truth = flight.truth(duration_s=20.0)
    base = run(ErrorConfig.none(), truth=truth)
    df = run(ErrorConfig.with_only("nose_probe_irregularity", True), truth=truth)
    err = (df["beta_znp_rad"] - base["beta_znp_rad"]).to_numpy()
    alpha = df["true_alpha_nose_probe_rad"].to_numpy()
    envelope = law.amplitude_per_rad * np.maximum(alpha - law.onset_rad, 0.0) * math.sqrt(
        2 * law.n_terms)
    assert np.all(np.abs(err) <= 1.2 * envelope + 1e-12)
    assert np.std(err) > 0.1 * DEG, "the irregularity must be visible at high alpha"
    # irregular: its lag-1 correlation at 40 Hz is far from that of a smooth signal
    r1 = np.corrcoef(err[:-1], err[1:])[0, 1]
    assert r1 < 0.9
    assert changed_columns(base, df) == {"dp_beta_np_pa", "flank_np_rad", "beta_znp_rad",
                                         "true_local_flank_nose_probe_rad"}
    low_truth = AnalyticFlight(w0_mps=4.0).truth(duration_s=5.0)  # alpha below 6 deg
    low = run(ErrorConfig.with_only("nose_probe_irregularity", True), truth=low_truth)
    assert low["true_alpha_nose_probe_rad"].max() < law.onset_rad
    assert np.array_equal(low["beta_znp_rad"], run(ErrorConfig.none(), truth=low_truth)[
        "beta_znp_rad"]), "no effect below the onset"


def test_gear_down_increment_and_adc_gear_tables():
    truth = AnalyticFlight(gear=1.0).truth(duration_s=5.0)
    up = AnalyticFlight(gear=0.0).truth(duration_s=5.0)
    errors = ErrorConfig.none().with_values({"local_flow": True})
    down_df, up_df = run(errors, truth=truth), run(errors, truth=up)
    assert down_df["gear_down"].all()
    d_local = down_df["true_local_alpha_vane_left_rad"] - up_df["true_local_alpha_vane_left_rad"]
    law = TRUTH_MODEL.vane_upwash
    a = up_df["true_alpha_vane_left_rad"]
    want = law.gear_offset_rad + law.gear_gain * a * (1 + law.curvature_per_rad * a)
    assert np.abs(d_local - want).max() < EXACT_RAD
    # the ADC reads the gear flag and uses its gear-down table (whose inversion of the truth is
    # the property test below)
    adc = build_airdata_computer(TRUTH_MODEL, GRID)
    for df, table in ((up_df, adc.f_v_up), (down_df, adc.f_v_down)):
        want = table(df["alpha_lm_rad"], df["mach"])
        assert np.abs(df["alpha_zl_rad"] - want).max() < EXACT_RAD


# ---------------------------------------------------------------- (c) seeds


def test_same_seeds_bit_identical_different_seeds_differ():
    e = ErrorConfig.typical()
    a = instrument(TRUTH, AIRFRAME, CFG_NP, e, maneuver_key=3)
    b = instrument(TRUTH, AIRFRAME, CFG_NP, e, maneuver_key=3)
    pd.testing.assert_frame_equal(a.data, b.data, check_exact=True)
    assert a.injected == b.injected
    other_key = run(e, maneuver_key=4)
    other_seed = run(ErrorConfig.from_dict({"preset": "typical"}, seed=99), maneuver_key=3)
    for other in (other_key, other_seed):
        for c in ("alpha_lm_rad", "ax_imu_mps2", "phi_rad", "h_dgps_m", "dp_alpha_lsp_pa"):
            assert not np.array_equal(a.data[c], other[c]), c
        assert np.array_equal(a.data["true_alpha_cg_rad"], other["true_alpha_cg_rad"])
    # one source's seed changes only that source's channels
    only_vane = run(e.with_values({"seeds.vane_noise": 12345}), maneuver_key=3)
    changed = changed_columns(a.data, only_vane)
    assert changed == {"alpha_lm_rad", "alpha_rm_rad", "alpha_zl_rad", "alpha_zr_rad",
                       "beta_znp_rad"}


# ---------------------------------------------------------------- (d) properties


finite = st.floats(-1.0, 1.0)


@settings(max_examples=200, deadline=None)
@given(st.tuples(st.floats(30, 300), st.floats(-40, 40), st.floats(-60, 60)),
       st.tuples(finite, finite, finite),
       st.tuples(st.floats(-10, 15), st.floats(-3, 3), st.floats(-2, 2)),
       st.tuples(st.floats(-1, 1), st.floats(-0.1, 0.1), st.floats(-0.5, 0.5)))
def test_flow_angle_at_sensor_matches_the_written_out_formula(v, omega, r_s, r_cg):
    v, omega, r_s, r_cg = (np.array(x, dtype=float) for x in (v, omega, r_s, r_cg))
    got = flow_angles_rad(air_velocity_at_sensor_body_mps(v[None], omega[None], r_s, r_cg[None]))
    p, q, r = omega
    dx, dy, dz = r_s - r_cg
    u_s, v_s, w_s = v[0] + q * dz - r * dy, v[1] + r * dx - p * dz, v[2] + p * dy - q * dx
    speed = math.sqrt(u_s**2 + v_s**2 + w_s**2)
    want = (math.atan2(w_s, u_s), math.asin(v_s / speed), math.atan2(v_s, u_s))
    for g, w in zip(got, want, strict=True):
        assert abs(float(g[0]) - w) < 1e-12


@settings(max_examples=200, deadline=None)
@given(st.floats(-15, 40), st.floats(-20, 20), st.floats(10, 60))
def test_side_probe_geometry_inverts_exactly(alpha_deg, beta_deg, cant_deg):
    model = dataclasses.replace(TRUTH_MODEL, side_probe_port_cant_rad=cant_deg * DEG)
    adc = build_airdata_computer(model, GRID)
    a, b = np.array([alpha_deg * DEG]), np.array([beta_deg * DEG])
    th_l = model.side_probe_port_angle_rad(a, b, -1.0)
    th_r = model.side_probe_port_angle_rad(a, b, 1.0)
    a2, b2 = adc.side_probe_local_rad(th_l, th_r)
    assert abs(a2[0] - a[0]) < 1e-12 and abs(b2[0] - b[0]) < 1e-12


@settings(max_examples=200, deadline=None)
@given(st.floats(0.9, 1.6), st.floats(-0.4, 0.4), st.floats(-0.01, 0.01), st.floats(0, 0.2),
       st.floats(-20, 40), st.floats(0.0, 0.94), st.sampled_from([0.0, 1.0]))
def test_upwash_law_inverse_is_exact(gain, curvature, offset, gain_mach, alpha_deg, mach, gear):
    law = UpwashLaw(offset_rad=offset, gain=gain, gain_mach=gain_mach, curvature_per_rad=curvature,
                    gear_offset_rad=0.01, gear_gain=0.05)
    alpha = alpha_deg * DEG
    # stay on the monotonic branch: d alpha_loc / d alpha = B (1 + 2 c alpha) > 0
    if 1 + 2 * curvature * alpha <= 0.05:
        return
    local = law.local_alpha_rad(alpha, mach, gear, 0.95)
    assert abs(law.free_alpha_rad(local, mach, gear, 0.95) - alpha) < 1e-12


def bilinear_bound(f, x, y, xbp, ybp) -> float:
    """Bilinear interpolation error on the cell containing (x, y): h_x^2/8 max|f_xx| +
    h_y^2/8 max|f_yy|, the maxima sampled on a 9 x 9 sub-grid of the cell by second differences
    (1.25 margin for the sampling of the maximum)."""
    i = int(np.clip(np.searchsorted(xbp, x, side="right") - 1, 0, len(xbp) - 2))
    j = int(np.clip(np.searchsorted(ybp, y, side="right") - 1, 0, len(ybp) - 2))
    hx, hy = xbp[i + 1] - xbp[i], ybp[j + 1] - ybp[j]
    xs = np.linspace(xbp[i], xbp[i + 1], 9)[:, None]
    ys = np.linspace(ybp[j], ybp[j + 1], 9)[None, :]
    dx, dy = hx / 50, hy / 50
    fxx = (f(xs + dx, ys) - 2 * f(xs, ys) + f(xs - dx, ys)) / dx**2
    fyy = (f(xs, ys + dy) - 2 * f(xs, ys) + f(xs, ys - dy)) / dy**2
    return 1.25 * (hx**2 / 8 * np.abs(fxx).max() + hy**2 / 8 * np.abs(fyy).max())


@settings(max_examples=100, deadline=None)
@given(st.floats(-10, 40), st.floats(0.1, 0.93), st.sampled_from([0.0, 1.0]))
def test_adc_without_mismatch_inverts_the_vane_truth_within_table_error(alpha_deg, mach, gear):
    alpha = alpha_deg * DEG
    got = channel_response("alpha_zl_rad", alpha, 0.0, mach, gear, local_flow=True,
                           baseline_mismatch=False)
    law, clamp = TRUTH_MODEL.vane_upwash, TRUTH_MODEL.mach_clamp
    local = law.local_alpha_rad(alpha, mach, gear, clamp)
    bound = bilinear_bound(lambda a, m: law.free_alpha_rad(a, m, gear, clamp), local, mach,
                           np.asarray(GRID.alpha_bp_rad), np.asarray(GRID.mach_bp))
    assert abs(float(got) - alpha) <= bound + 1e-15, (float(got) - alpha, bound)


@settings(max_examples=100, deadline=None)
@given(st.floats(-10, 35), st.floats(-12, 12), st.floats(0.1, 0.93))
def test_adc_without_mismatch_inverts_the_side_probe_truth_within_table_error(alpha_deg, beta_deg,
                                                                               mach):
    alpha, beta = alpha_deg * DEG, beta_deg * DEG
    kw = dict(local_flow=True, baseline_mismatch=False)
    a_sp = channel_response("alpha_zsp_rad", alpha, beta, mach, **kw)
    b_sp = channel_response("beta_zsp_rad", alpha, beta, mach, **kw)
    m = TRUTH_MODEL
    up, side, clamp = m.side_probe_upwash, m.side_probe_sidewash, m.mach_clamp
    a_loc, b_loc = m.side_probe_local_rad(alpha, beta, mach, 0.0)
    xbp, ybp = np.asarray(GRID.alpha_bp_rad), np.asarray(GRID.mach_bp)

    def alpha_free(a, mm):
        return up.free_alpha_rad(a, mm, 0.0, clamp)

    def beta_gain(a, mm):
        return 1.0 / side.factor(alpha_free(a, mm), mm, clamp)

    bound_a = bilinear_bound(alpha_free, a_loc, mach, xbp, ybp)
    bound_b = abs(b_loc) * bilinear_bound(beta_gain, a_loc, mach, xbp, ybp)
    assert abs(float(a_sp) - alpha) <= bound_a + 1e-14
    assert abs(float(b_sp) - beta) <= bound_b + 1e-14


@settings(max_examples=50, deadline=None)
@given(st.floats(-5, 20), st.floats(-8, 8), st.floats(0.2, 0.9))
def test_without_local_flow_and_mismatch_every_channel_response_is_the_identity(a_deg, b_deg, mach):
    alpha, beta = a_deg * DEG, b_deg * DEG
    flank = math.atan2(math.sin(beta), math.cos(beta) * math.cos(alpha))
    want = {"alpha_zl_rad": alpha, "alpha_zr_rad": alpha, "alpha_zsp_rad": alpha,
            "beta_zsp_rad": beta, "beta_znp_rad": beta, "alpha_zb_rad": alpha,
            "beta_zbu_rad": flank, "beta_zbl_rad": flank}
    for ch, w in want.items():
        got = channel_response(ch, alpha, beta, mach, local_flow=False, baseline_mismatch=False)
        assert abs(float(got) - w) < 1e-12, ch


# ---------------------------------------------------------------- ErrorConfig, data contract


def test_error_config_dict_round_trip_units_and_unknown_keys():
    cfg = ErrorConfig.from_dict({
        "preset": "typical",
        "imu": {"gyro_bias_deg_s": [0.1, 0.2, 0.3]},
        "sensors": {"vane_left": {"noise_deg": 0.1, "delay_ms": 40}},
        "recorders": {"ins": {"clock_offset_ms": 25}},
        "channel_delays_ms": {"psi_rad": 30},
        "seeds": {"imu_noise": 7},
    }, seed=5)
    assert cfg.imu.gyro_bias_rps == pytest.approx((0.1 * DEG, 0.2 * DEG, 0.3 * DEG), abs=1e-15)
    assert cfg.sensors["vane_left"].noise_rad == pytest.approx(0.1 * DEG)
    assert cfg.sensors["vane_left"].delay_s == pytest.approx(0.040)
    assert cfg.recorders["ins"].clock_offset_s == pytest.approx(0.025)
    assert cfg.channel_delays_s["psi_rad"] == pytest.approx(0.030)
    assert cfg.seeds.imu_noise == 7 and cfg.seeds.vane_noise != ErrorConfig().seeds.vane_noise
    assert ErrorConfig.from_dict(cfg.to_dict()) == cfg
    assert ErrorConfig.from_dict({}) == ErrorConfig.none()
    with pytest.raises(ValueError, match="valid:.*accel_bias_mps2"):
        ErrorConfig.from_dict({"imu": {"accel_bias": [0, 0, 0]}})
    with pytest.raises(ValueError, match="valid:.*baseline_mismatch"):
        ErrorConfig.from_dict({"local_flo": True})
    with pytest.raises(ValueError, match="side_probe_left.*noise_pa"):
        ErrorConfig.from_dict({"sensors": {"side_probe_left": {"noise_deg": 0.1}}})
    with pytest.raises(ValueError, match="vane_lefty"):
        ErrorConfig.from_dict({"sensors": {"vane_lefty": {}}})
    with pytest.raises(ValueError, match="alpha_zl_rad.*sensors"):
        ErrorConfig.from_dict({"channel_delays_s": {"alpha_zl_rad": 0.1}})


def test_injected_values_and_units_are_complete():
    inst = instrument(TRUTH, AIRFRAME, CFG_NP, ErrorConfig.typical(), maneuver_key=2)
    inj = inst.injected
    assert inj["imu.accel_bias_mps2"] == [0.10, -0.08, 0.15]
    assert inj["dru.delay_s"] == 0.020 and inj["dru.rate_hz"] == 64.0
    assert inj["vane_left.installation_bias_rad"] == CFG_NP.aircraft.installation_bias_rad["vane_left"]
    assert isinstance(inj["seeds.imu_noise"], int) and inj["maneuver_key"] == 2.0
    # total lag of alpha_lm against the truth: DRU latency + vane delay (no DRU clock offset)
    assert inj["time_shift_s.alpha_lm_rad"] == pytest.approx(0.020 + 0.030)
    assert inj["time_shift_s.phi_rad"] == pytest.approx(0.030 + 0.010)
    for v in inj.values():
        assert isinstance(v, (int, float, list)), v
    df = inst.data
    assert set(inst.channel_units) == set(df.columns)
    assert inst.channel_units["q_rps"] == "rad/s" and inst.channel_units["dp_beta_np_pa"] == "Pa"
    assert np.allclose(np.diff(df["t_s"]) * 40.0, 1.0)
    # the 10 Hz DGPS stream's stamps are 40 Hz times: it stays at its own samples, every 4th row
    assert inst.own_rate_columns == ("h_dgps_m",)
    dgps = df["h_dgps_m"].to_numpy()
    assert np.all(np.diff(np.flatnonzero(np.isfinite(dgps))) == 4)
    assert not df.drop(columns="h_dgps_m").isna().any().any()
    for col in CHANNEL_TRUTH.values():
        if "boom" not in col:
            assert col in df


def test_bad_input_names_what_and_when():
    fast = dataclasses.replace(TRUTH, mach=np.where(TRUTH.t_s > 3.0, 1.05, TRUTH.mach))
    with pytest.raises(ValueError, match=r"t = 3\.0"):
        instrument(fast, AIRFRAME, CFG_NP, ErrorConfig.none())
    short = FLIGHT.truth(duration_s=0.1)
    with pytest.raises(ValueError, match="recorder dru at 64.0 Hz"):
        instrument(short, AIRFRAME, CFG_NP, ErrorConfig.typical())


def _leaf_paths(d: dict, prefix: str = "") -> list[tuple[str, object]]:
    out = []
    for k, v in d.items():
        if isinstance(v, dict):
            out += _leaf_paths(v, f"{prefix}{k}.")
        else:
            out.append((f"{prefix}{k}", v))
    return out


TYPICAL_NONZERO = [(p, v) for p, v in _leaf_paths(ErrorConfig.typical().to_dict())
                   if not p.startswith("seeds.") and v is not False and np.any(np.asarray(v) != 0)
                   and not p.endswith("high_alpha_onset_rad")]  # a parameter of the noise above


@pytest.mark.parametrize("path, value", TYPICAL_NONZERO, ids=[p for p, _ in TYPICAL_NONZERO])
def test_every_typical_error_alone_changes_the_data(path, value):
    """No dead configuration: each typical error switched on alone leaves a trace in the data."""
    cfg = CFG_BOOM if "boom" in path else CFG_NP
    base = NONE_BOOM if cfg is CFG_BOOM else NONE
    df = run(ErrorConfig.with_only(path), cfg)
    common = np.intersect1d(df["t_s"], base["t_s"])
    a = base.set_index("t_s").loc[common]
    b = df.set_index("t_s").loc[common]
    changed = [c for c in a.columns if not np.array_equal(a[c].to_numpy(), b[c].to_numpy())]
    assert changed or len(df) != len(base), f"{path} = {value} changed nothing"
    # the clean channels carry the deterministic errors by design; the truth of the flight does not
    assert not any(c.startswith("true_") and "local" not in c and "port" not in c
                   and not c.startswith("true_clean_") for c in changed), (
        f"{path} must not change the truth: {changed}")


def test_the_documented_toml_example_parses():
    import inspect
    import textwrap
    import tomllib

    import synth.errors

    doc = inspect.getdoc(synth.errors)
    block = doc.split("Dict / TOML form")[1].split("::", 1)[1].split("``from_dict(d, seed=S)``")[0]
    cfg = ErrorConfig.from_dict(tomllib.loads(textwrap.dedent(block)))
    assert cfg.imu.gyro_bias_rps[1] == pytest.approx(-0.3 * DEG)
    assert cfg.recorders["dru"].rate_hz == 64.0 and cfg.channel_delays_s["phi_rad"] == 0.040


def test_clean_channels_equal_the_measurement_without_noise_and_delay():
    """true_clean_X is X with every deterministic error but no noise, quantization or delay."""
    errors = ErrorConfig.typical()
    quiet = errors.with_values({
        **{f"sensors.{s}.{k}": 0.0 for s in ALL_SENSORS
           for k in (("noise_rad", "quant_rad", "delay_s") if "probe" not in s
                     else ("noise_pa", "quant_pa", "delay_s"))},
        "sensors.nose_probe.high_alpha_noise_rad_per_rad": 0.0,
        "airdata.qc_noise_pa": 0.0, "airdata.ps_noise_pa": 0.0, "airdata.tt_noise_k": 0.0,
        "airdata.qc_quant_pa": 0.0, "airdata.ps_quant_pa": 0.0, "airdata.delay_s": 0.0,
        "recorders.dru.delay_s": 0.0,
        "recorders.dru.clock_offset_s": 0.0,
    })
    # the irregularity varies over 1e-3 rad of alpha: linear interpolation cannot follow it
    quiet = dataclasses.replace(quiet, nose_probe_irregularity=False)
    df = run(quiet, CFG_NP)
    for c in ("alpha_zl_rad", "alpha_zr_rad", "alpha_zsp_rad", "beta_zsp_rad", "beta_znp_rad"):
        err = np.abs(df[c] - df[f"true_clean_{c}"]).max()
        # both paths run the same ADC; the measured one on the DRU's 64 Hz samples resampled
        # linearly to the common base, the clean one at the truth rate: they agree to the linear
        # interpolation error (dt^2 / 8) |y''| with dt = 1/64 s and |y''| < ~1 rad/s^2 here
        assert err < (1 / 64) ** 2 / 8 * 1.0, f"{c}: measured without noise differs by {err:.2e}"
    noisy = run(errors, CFG_NP)
    assert np.abs(noisy["alpha_zl_rad"] - noisy["true_clean_alpha_zl_rad"]).std() > 0.0


def test_imu_interval_mean_is_the_strapdown_output():
    """average_at gives the exact interval mean (velocity increment / interval) of a sinusoid."""
    from synth.recorders import average_at

    t = np.arange(0.0, 5.0, 1 / 120)
    w = 7.0
    y = np.sin(w * t)
    tq = np.arange(0.5, 4.5, 1 / 64)
    T = 1 / 64
    exact = (np.cos(w * (tq - T)) - np.cos(w * tq)) / (w * T)
    # trapezoidal integration at 120 Hz: error ~ dt^2 w^2 / 12 relative -> ~3e-4 of the amplitude
    assert np.abs(average_at(t, y, tq, T) - exact).max() < 1e-3
    # the mean lags the signal by half its window (group delay): it matches y at t - T/2 closely
    assert np.abs(average_at(t, y, tq, T) - np.sin(w * (tq - T / 2))).max() < 2e-3


def test_imu_time_shift_includes_half_its_sample_interval():
    errors = ErrorConfig.none().with_values({"recorders.dru.rate_hz": 64.0})
    inst = instrument(FLIGHT.truth(), AIRFRAME, CFG_NP, errors)
    assert inst.injected["time_shift_s.ax_imu_mps2"] == pytest.approx(0.5 / 64.0)
    assert inst.injected["time_shift_s.alpha_zl_rad"] == pytest.approx(0.0)
