"""The realism level of the synthesizer (docs/realism.md): each source does what it says, each is
off by default, and one seed gives bit-identical data.

Instrumentation against the analytic, kinematically exact flight of tests/_synthetic_truth.py with
ideal recorders (every common sample on a truth sample), so that "exact" means float rounding; the
statistics of the Gauss-Markov processes on long records of the kernel itself, with tolerances of
four sampling standard deviations (quoted at each assertion); the vertical air motion on a short
JSBSim flight.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from _synthetic_truth import AnalyticFlight
from scipy.spatial.transform import Rotation

from aircraft_models import load_fleet
from synth.airdata_computer import impact_pressure_pa, mach_from_pressures, pressure_altitude_m
from synth.campaign import load_campaign
from synth.environment import Environment, VerticalAirMotion
from synth.errors import SEED_SOURCES, ErrorConfig, RealismErrors, Seeds, channel_rng
from synth.flight import FlightError, fly_maneuver
from synth.instrument import _RNG_INDEX, instrument
from synth.maneuvers import ManeuverSpec
from synth.processes import first_order_lag, gauss_markov, hold_fix_times_s, static_source_error_ratio
from synth.sortie import fly_sortie

FLEET = load_fleet()
AIRFRAME = FLEET.airframe
CFG = FLEET.configuration("PV1-NP")
TRUTH = AnalyticFlight().truth(duration_s=12.0)
DEG = math.pi / 180.0
TYPICAL_REALISM = RealismErrors.typical()
#: every realism source's switch (a magnitude: 0 = off), as a dotted ErrorConfig path
SWITCHES = ("ins_attitude_sigma_rad", "accel_scale", "gyro_scale", "accel_nonorthogonality_rad",
            "gyro_nonorthogonality_rad", "imu_mounting_rad", "static_error_c0",
            "static_error_c_alpha_per_rad", "static_error_c_mach2", "static_lag_s", "total_lag_s",
            "gnss_velocity_rate_hz")


def run(errors: ErrorConfig, **kw):
    return instrument(TRUTH, AIRFRAME, CFG, errors, **kw)


def only(**realism) -> ErrorConfig:
    """Every error off (ideal recorders) but the given realism values (SI names)."""
    return ErrorConfig.none().with_values({f"realism.{k}": v for k, v in realism.items()})


# ---------------------------------------------------------------- off by default, opt-in


def test_every_source_is_off_by_default_and_absent_from_the_stored_values():
    for cfg in (ErrorConfig(), ErrorConfig.none(), ErrorConfig.typical()):
        assert cfg.realism == RealismErrors()
        assert not (cfg.realism.ins_attitude or cfg.realism.imu_matrix_errors
                    or cfg.realism.static_source_error or cfg.realism.gnss_velocity)
        assert cfg.realism.static_lag_s == cfg.realism.total_lag_s == 0.0
        # the stored injected values are those written before the realism level existed
        assert not any(k.startswith("realism.") or k == "seeds.ins_attitude" for k in cfg.flat()), (
            "the injected values of a dataset without the realism level must not change")
        assert "realism" not in cfg.to_dict()
    assert Environment().vertical_air_motion is None
    assert "vertical_air_motion" not in Environment().to_dict()
    assert Environment.from_dict({"vertical_air_motion": False}) == Environment()
    # seeds: the new source is appended, the master seed's older ones unchanged
    assert SEED_SOURCES[-1] == "ins_attitude"
    old = np.random.SeedSequence(2026).generate_state(len(SEED_SOURCES) - 1)
    assert [getattr(Seeds.from_master(2026), s) for s in SEED_SOURCES[:-1]] == [int(v) for v in old]


def test_an_all_zero_realism_table_leaves_the_data_bit_identical():
    zeros = {k: ([0.0] * 3 if isinstance(v, tuple) else 0.0)
             for k, v in TYPICAL_REALISM.__dict__.items() if k in SWITCHES}
    a = run(ErrorConfig.typical(), maneuver_key=3)
    b = run(ErrorConfig.from_dict({"preset": "typical", "realism": zeros}), maneuver_key=3)
    pd.testing.assert_frame_equal(a.data, b.data, check_exact=True)
    assert a.injected == b.injected


def test_presets_and_the_dict_form():
    rw = ErrorConfig.real_world()
    assert rw.realism == TYPICAL_REALISM
    assert ErrorConfig.from_dict({"preset": "real_world"}).realism == TYPICAL_REALISM
    assert ErrorConfig.from_dict(rw.to_dict()) == rw
    cfg = ErrorConfig.from_dict({"realism": {"ins_attitude_sigma_deg": [0.1, 0.1, 0.2],
                                             "static_error_c_alpha_per_deg": 0.0014,
                                             "static_lag_ms": 300, "gnss_velocity_latency_ms": 60}})
    assert cfg.realism.ins_attitude_sigma_rad == pytest.approx((0.1 * DEG, 0.1 * DEG, 0.2 * DEG))
    assert cfg.realism.static_error_c_alpha_per_rad == pytest.approx(0.0014 / DEG)
    assert cfg.realism.static_lag_s == pytest.approx(0.3)
    assert cfg.realism.gnss_velocity_latency_s == pytest.approx(0.06)
    with pytest.raises(ValueError, match="did you mean 'static_lag_s'"):
        ErrorConfig.from_dict({"realism": {"static_lag": 0.3}})
    with pytest.raises(ValueError, match="ins_attitude_tau_s"):
        ErrorConfig.from_dict({"realism": {"ins_attitude_sigma_deg": [0.1, 0, 0],
                                           "ins_attitude_tau_s": [0, 30, 30]}})
    with pytest.raises(ValueError, match="static_lag_s"):
        ErrorConfig.from_dict({"realism": {"static_lag_s": -0.1}})
    # a Monte Carlo draw (with_values) keeps the realism level and its seed
    drawn = ErrorConfig.from_dict({"preset": "real_world"}, seed=9).with_values(
        {"imu.accel_bias_mps2": (0.1, 0.0, 0.0)})
    assert drawn.realism == TYPICAL_REALISM
    assert drawn.seeds == ErrorConfig.from_dict({}, seed=9).seeds


def test_the_shipped_campaign_is_the_realism_level():
    camp = load_campaign("realism")
    assert {j.configuration_id for j in camp.jobs} >= {"PV1-NP", "PT1-BOOM"}
    assert {j.maneuver["mach"] for j in camp.jobs} == {0.5, 0.7}
    assert {j.maneuver["kind"] for j in camp.jobs} == {"pitch_doublet", "3211", "windup_turn", "shss"}
    for job in camp.jobs:
        assert ErrorConfig.from_dict(job.errors, seed=camp.seed).realism == TYPICAL_REALISM
        env = Environment.from_dict(job.environment)
        assert env.vertical_air_motion == VerticalAirMotion(0.4, 30.0) and env.turbulence == "none"
    # each maneuver its own vertical motion: drawn from its own turbulence seed
    assert len({Environment.from_dict(j.environment).turbulence_seed for j in camp.jobs}) == len(camp.jobs)


# ---------------------------------------------------------------- 1. INS attitude from a filter


def test_gauss_markov_has_the_declared_sigma_and_correlation_time():
    """A long record (N = 200,000 at dt = tau / 10): its lag-1 autocorrelation phi = exp(-dt/tau)
    and variance. Sampling std of the estimates of an AR(1) record: rho1 sqrt((1 - phi^2) / N) =
    0.00095, variance sqrt(2 (1 + phi^2) / ((1 - phi^2) N)) = 1.0 % relative, tau (through
    -dt / ln rho1) 1.05 % relative; the tolerances are 4 of them."""
    sigma, tau, n = 0.7, 30.0, 200_000
    t = np.arange(n) * (tau / 10.0)
    x = gauss_markov(t, sigma, tau, np.random.default_rng(1))
    phi = math.exp(-0.1)
    rho1 = np.corrcoef(x[:-1], x[1:])[0, 1]
    assert abs(np.var(x) / sigma**2 - 1.0) < 0.04, f"variance {np.var(x):.4f} vs sigma^2 {sigma**2}"
    assert abs(rho1 - phi) < 4 * 0.00095, f"lag-1 autocorrelation {rho1:.4f} vs {phi:.4f}"
    tau_hat = -(tau / 10.0) / math.log(rho1)
    assert abs(tau_hat / tau - 1.0) < 0.042, f"correlation time {tau_hat:.2f} s vs {tau} s"
    # stationary from the start: the first sample over 4000 independent records has the declared
    # sigma (std of a sample variance sqrt(2 / 4000) = 2.2 %, 4 of them), whatever the spacing
    firsts = np.array([gauss_markov(np.array([0.0, 0.3, 1.0]), sigma, tau, np.random.default_rng([2, k]))[0]
                       for k in range(4000)])
    assert abs(np.var(firsts) / sigma**2 - 1.0) < 4 * math.sqrt(2 / 4000), np.var(firsts)
    # the uneven-spacing path agrees with the uniform one where both apply
    t_short = np.arange(50) * 0.5
    uneven = gauss_markov(np.append(t_short, 25.3), sigma, tau, np.random.default_rng(3))
    even = gauss_markov(t_short, sigma, tau, np.random.default_rng(3))
    np.testing.assert_allclose(uneven[:50], even, rtol=1e-12, atol=1e-15)


def test_ins_attitude_error_is_the_declared_process_on_the_ins_stamps():
    sigma = (0.1 * DEG, 0.15 * DEG, 0.2 * DEG)
    tau = (20.0, 30.0, 60.0)
    errors = only(ins_attitude_sigma_rad=sigma, ins_attitude_tau_s=tau)
    inst = run(errors, maneuver_key=5)
    df = inst.data
    means = []
    for i, c in enumerate(("phi_rad", "theta_rad", "psi_rad")):
        expected = gauss_markov(df["t_s"].to_numpy(), sigma[i], tau[i],
                                channel_rng(errors.seeds.ins_attitude, 5, _RNG_INDEX[c]))
        err = df[c].to_numpy() - df[f"true_{c}"].to_numpy()
        np.testing.assert_allclose(err, expected, rtol=0, atol=1e-12,
                                   err_msg=f"{c}: the INS attitude error is not its Gauss-Markov draw")
        means.append(float(np.mean(expected)))
    assert inst.injected["realism.ins_attitude_error_mean_rad"] == pytest.approx(means, abs=1e-15)
    assert inst.injected["realism.ins_attitude_sigma_rad"] == list(sigma)
    assert inst.injected["seeds.ins_attitude"] == errors.seeds.ins_attitude
    # another maneuver, another draw; the other channels untouched
    other = run(errors, maneuver_key=6).data
    assert not np.array_equal(other["phi_rad"], df["phi_rad"])
    base = run(ErrorConfig.none()).data
    for c in ("vn_mps", "q_rps", "h_baro_m", "alpha_zl_rad"):
        assert np.array_equal(base[c], df[c]), c


# ---------------------------------------------------------------- 2. IMU scale and misalignment


def test_imu_matrix_is_scale_times_nonorthogonality_times_mounting():
    r = RealismErrors(accel_scale=(1e-3, -2e-3, 3e-3), accel_nonorthogonality_rad=(4e-4, -5e-4, 6e-4),
                      imu_mounting_rad=(1e-3, -2e-3, 1.5e-3))
    m = r.imu_matrix("accel")
    # the mounting alone is the small rotation of the case: components in the case frame
    mount = RealismErrors(imu_mounting_rad=(1e-3, -2e-3, 1.5e-3)).imu_matrix("gyro")
    exact = Rotation.from_rotvec([1e-3, -2e-3, 1.5e-3]).inv().as_matrix()
    np.testing.assert_allclose(mount, exact, atol=5e-6)  # small-angle model: O(d^2) = 4e-6
    # a tilted y axis (towards x by m_yx) senses f_y + m_yx f_x; z: f_z + m_zx f_x + m_zy f_y
    n = RealismErrors(gyro_nonorthogonality_rad=(4e-4, -5e-4, 6e-4)).imu_matrix("gyro")
    np.testing.assert_allclose(n @ [1.0, 0.0, 0.0], [1.0, 4e-4, -5e-4], atol=1e-15)
    np.testing.assert_allclose(n @ [0.0, 1.0, 0.0], [0.0, 1.0, 6e-4], atol=1e-15)
    np.testing.assert_allclose(np.diag(RealismErrors(accel_scale=(1e-3, -2e-3, 3e-3)).imu_matrix("accel")),
                               [1.001, 0.998, 1.003], atol=1e-15)
    np.testing.assert_allclose(m, np.diag([1.001, 0.998, 1.003]) @ n @ exact, atol=5e-6)


def test_imu_channels_measure_the_matrix_times_the_truth():
    errors = ErrorConfig.with_only("realism.accel_scale").with_values({
        f"realism.{k}": getattr(TYPICAL_REALISM, k) for k in
        ("gyro_scale", "accel_nonorthogonality_rad", "gyro_nonorthogonality_rad", "imu_mounting_rad")})
    inst = run(errors)
    df = inst.data
    for triad, cols, true in (("accel", ("ax_imu_mps2", "ay_imu_mps2", "az_imu_mps2"),
                               ("true_ax_imu_mps2", "true_ay_imu_mps2", "true_az_imu_mps2")),
                              ("gyro", ("p_rps", "q_rps", "r_rps"),
                               ("true_p_rps", "true_q_rps", "true_r_rps"))):
        m = TYPICAL_REALISM.imu_matrix(triad)
        np.testing.assert_allclose(df[list(cols)].to_numpy(), df[list(true)].to_numpy() @ m.T,
                                   rtol=0, atol=1e-12, err_msg=f"{triad}: not (I + M) x")
        assert inst.injected[f"realism.{triad}_matrix"] == pytest.approx(m.ravel().tolist(), abs=0)
    # the attitude, velocities and air data are the INS's and the ADC's: untouched
    base = run(ErrorConfig.none()).data
    for c in ("phi_rad", "vn_mps", "tas_mps", "h_baro_m"):
        assert np.array_equal(base[c], df[c]), c


# ---------------------------------------------------------------- 3. static source and pneumatic lag


def test_static_source_error_changes_pressure_altitude_by_the_declared_function():
    c0, ca, cm = 0.004, 0.08, 0.012
    df = run(only(static_error_c0=c0, static_error_c_alpha_per_rad=ca, static_error_c_mach2=cm)).data
    alpha, mach, qc, ps = (df[c].to_numpy() for c in ("true_alpha_cg_rad", "true_mach", "true_qc_pa",
                                                         "true_p_static_pa"))
    dpp = qc * (c0 + ca * alpha + cm * mach**2)
    np.testing.assert_allclose(static_source_error_ratio(alpha, mach, c0, ca, cm) * qc, dpp, rtol=1e-15)
    # ps at the port, qc = pt - ps_port; h, Mach (and TAS) from them
    np.testing.assert_allclose(df["ps_pa"], ps + dpp, rtol=1e-12)
    np.testing.assert_allclose(df["qc_pa"], qc - dpp, rtol=1e-12)
    np.testing.assert_allclose(df["h_baro_m"], pressure_altitude_m(ps + dpp), rtol=0, atol=1e-8)
    np.testing.assert_allclose(df["mach"], mach_from_pressures(qc - dpp, ps + dpp), rtol=1e-12)
    # what the altimeter shows: -dPp / (rho g), to the curvature of the pressure law (< 0.1 %)
    dh = df["h_baro_m"] - df["true_h_pressure_m"]
    rho_g = df["true_rho_kgpm3"] * 9.80665
    np.testing.assert_allclose(dh, -dpp / rho_g, rtol=2e-3)
    assert (dpp / qc).min() > 0.007 and (dpp / qc).max() < 0.02  # 1-2 % of qc, as typical
    assert df["true_h_pressure_m"].equals(run(ErrorConfig.none()).data["true_h_pressure_m"])


def test_first_order_lag_is_exact_for_a_ramp_and_attenuates_a_sine():
    h, tau = 1 / 120, 0.3
    t = np.arange(0, 5, h)
    ramp = 200.0 * t  # from a line in equilibrium at u(0) = 0: y = r (t - tau (1 - exp(-t / tau)))
    np.testing.assert_allclose(first_order_lag(t, ramp, tau), 200.0 * (t - tau * (1 - np.exp(-t / tau))),
                               rtol=0, atol=1e-9)
    w = 2 * math.pi * 0.5
    y = first_order_lag(t, np.sin(w * t), tau)
    late = t > 10 * tau  # transient gone: amplitude 1 / sqrt(1 + (w tau)^2), phase -atan(w tau)
    steady = np.sin(w * t - math.atan(w * tau)) / math.hypot(1.0, w * tau)
    np.testing.assert_allclose(y[late], steady[late], atol=1e-4)  # O(h^2) of the linear pieces
    assert first_order_lag(t, ramp, 0.0) is not None and np.array_equal(first_order_lag(t, ramp, 0.0), ramp)


def test_pneumatic_lags_reach_pressure_altitude_mach_and_the_time_shifts():
    ts, tt = 0.3, 0.1
    inst = run(only(static_lag_s=ts, total_lag_s=tt))
    df = inst.data
    qc_true = impact_pressure_pa(TRUTH.mach, TRUTH.p_static_pa)  # at the truth rate
    ps_line = first_order_lag(TRUTH.t_s, TRUTH.p_static_pa, ts)
    pt_line = first_order_lag(TRUTH.t_s, TRUTH.p_static_pa + qc_true, tt)
    k = np.searchsorted(TRUTH.t_s, df["t_s"].to_numpy() - 1e-9)  # the common samples on the truth's
    np.testing.assert_allclose(df["ps_pa"], ps_line[k], rtol=1e-12)
    np.testing.assert_allclose(df["qc_pa"], (pt_line - ps_line)[k], rtol=1e-9)
    np.testing.assert_allclose(df["h_baro_m"], pressure_altitude_m(ps_line[k]), rtol=0, atol=1e-8)
    np.testing.assert_allclose(df["mach"], mach_from_pressures((pt_line - ps_line)[k], ps_line[k]),
                               rtol=1e-12)
    # the analytic flight climbs at up to 20 m/s: 0.3 s of static lag shows metres of height
    assert np.abs(df["h_baro_m"] - df["true_h_pressure_m"]).max() > 1.0
    assert inst.injected["time_shift_s.h_baro_m"] == pytest.approx(ts)
    assert inst.injected["time_shift_s.tas_mps"] == pytest.approx(tt)


# ---------------------------------------------------------------- 5. GNSS velocity held


def test_gnss_velocity_is_held_between_fixes_at_the_declared_rate():
    rate, latency = 5.0, 0.06
    inst = run(only(gnss_velocity_rate_hz=rate, gnss_velocity_latency_s=latency))
    df = inst.data
    t = df["t_s"].to_numpy()
    t_fix = hold_fix_times_s(t, rate, latency)
    assert np.all(t_fix <= t - latency + 1e-12) and np.all(t - latency - t_fix < 1 / rate)
    seen = t_fix >= t[0]  # (the first fix held is valid before the common base begins)
    assert seen.sum() >= len(t) - 40 / rate
    for c in ("vn_mps", "ve_mps", "vd_mps"):
        # every sample is the true INS-point velocity at its fix's time of validity
        np.testing.assert_allclose(df[c][seen], np.interp(t_fix[seen], t, df[f"true_{c[:2]}_ins_mps"]),
                                   rtol=0, atol=1e-9, err_msg=c)
        runs = np.diff(np.flatnonzero(np.diff(df[c].to_numpy()) != 0))
        assert np.all(runs == 40 / rate), f"{c}: a fix holds 8 samples of the 40 Hz base, got {set(runs)}"
    assert inst.injected["time_shift_s.vn_mps"] == pytest.approx(latency + 0.5 / rate)
    # with typical recorders (INS at 50 Hz) and noise: the fix's noise is held with it
    typ = instrument(TRUTH, AIRFRAME, CFG, ErrorConfig.typical().with_values(
        {"realism.gnss_velocity_rate_hz": rate}))
    vn = typ.streams["ins"]["vn_mps"].to_numpy()
    runs = np.diff(np.flatnonzero(np.diff(vn) != 0))
    assert np.all(runs == 10), f"50 Hz INS, 5 Hz fixes: runs of 10 samples, got {set(runs)}"
    assert len(np.unique(vn)) == pytest.approx(np.ptp(typ.streams["ins"]["t_s"].to_numpy()) * rate, abs=2)


# ---------------------------------------------------------------- every source alone; reproducible


@pytest.mark.parametrize("path", SWITCHES)
def test_each_source_alone_changes_the_measurements_never_the_truth(path):
    base = run(ErrorConfig.none()).data
    df = run(ErrorConfig.with_only(f"realism.{path}")).data
    common = np.intersect1d(df["t_s"], base["t_s"])
    a = base.set_index("t_s").loc[common]
    b = df.set_index("t_s").loc[common]
    changed = [c for c in a.columns if not np.array_equal(a[c].to_numpy(), b[c].to_numpy())]
    assert changed, f"realism.{path} changed nothing"
    assert not any(c.startswith("true_") for c in changed), f"realism.{path} changed the truth: {changed}"


def test_the_same_seed_gives_bit_identical_data():
    errors = ErrorConfig.from_dict({"preset": "real_world"}, seed=77)
    a, b = run(errors, maneuver_key=4), run(ErrorConfig.from_dict({"preset": "real_world"}, seed=77),
                                            maneuver_key=4)
    pd.testing.assert_frame_equal(a.data, b.data, check_exact=True)
    assert a.injected == b.injected
    c = run(ErrorConfig.from_dict({"preset": "real_world"}, seed=78), maneuver_key=4)
    assert not np.array_equal(a.data["theta_rad"], c.data["theta_rad"])


# ---------------------------------------------------------------- 4. slow vertical air motion


SHORT = ManeuverSpec.from_dict({"kind": "pitch_doublet", "mach": 0.5, "altitude_m": 6000.0,
                                "duration_s": 10.0})
AIRCRAFT = FLEET.aircraft["PV1"]


@pytest.fixture(scope="module")
def vertical_flights():
    env = Environment(wind_ned_mps=(6.0, -4.0, 0.0), turbulence_seed=11,
                      vertical_air_motion=VerticalAirMotion(sigma_mps=0.5, tau_s=30.0))
    fly = [fly_maneuver(SHORT, AIRFRAME, AIRCRAFT, e)[0]
           for e in (env, env, Environment(wind_ned_mps=(6.0, -4.0, 0.0), turbulence_seed=12,
                                           vertical_air_motion=env.vertical_air_motion),
                     Environment(wind_ned_mps=(6.0, -4.0, 0.0), turbulence_seed=11))]
    return env, fly


def test_vertical_air_motion_is_flown_and_in_the_truth_wind(vertical_flights):
    env, (a, again, other_seed, still) = vertical_flights
    w = env.vertical_wind_ned_mps(a.t_s)
    np.testing.assert_allclose(a.wind_ned_mps[:, 2], w[:, 2], rtol=0, atol=1e-12,
                               err_msg="the truth's vertical wind is the drawn history from the first sample")
    np.testing.assert_allclose(a.wind_ned_mps[:, :2], np.broadcast_to([6.0, -4.0], (len(a.t_s), 2)),
                               atol=1e-12)
    assert np.all(still.wind_ned_mps[:, 2] == 0.0)
    # the aircraft responds: it moves with the air mass (height) and sees it (angle of attack)
    assert np.abs(a.h_m - still.h_m).max() > 0.05
    assert np.abs(a.alpha_rad - still.alpha_rad).max() > 1e-5
    # but starts without a transient: restarted in the moving air at trim, its air-relative state
    # at entry is the still-air one (to 1 mm/s: 2 s of settling at another height), where a
    # start in still air would have had to absorb the vertical wind's first value, 0.1 m/s here
    assert abs(w[0, 2]) > 0.1
    np.testing.assert_allclose(a.v_air_body_mps[0], still.v_air_body_mps[0], atol=1e-3)
    # reproducible by seed, and another maneuver's seed draws another history
    for name in ("wind_ned_mps", "h_m", "alpha_rad", "v_body_mps"):
        assert np.array_equal(getattr(a, name), getattr(again, name)), name
    assert not np.array_equal(a.wind_ned_mps[:, 2], other_seed.wind_ned_mps[:, 2])
    assert a.meta["environment"]["vertical_air_motion"] == {"sigma_mps": 0.5, "tau_s": 30.0}


def test_vertical_air_motion_history_statistics_and_options():
    """The declared sigma and correlation time (the kernel's, checked above) through the
    environment's own draw: 400 maneuvers' first values (sampling std of the variance sqrt(2/400)
    = 7 %; 4 of them) and the same start whatever the record's length."""
    vam = VerticalAirMotion(sigma_mps=0.4, tau_s=30.0)
    firsts = np.array([vam.wind_down_mps(np.zeros(1), seed)[0] for seed in range(400)])
    assert abs(np.var(firsts) / 0.16 - 1.0) < 4 * math.sqrt(2 / 400), np.var(firsts)
    t = np.arange(0, 40, 1 / 120)
    long, short = vam.wind_down_mps(t, 5), vam.wind_down_mps(t[:10], 5)
    assert long[0] == short[0]
    env = Environment.from_dict({"vertical_air_motion": {"sigma_mps": 0.3, "tau_ms": 45000}})
    assert env.vertical_air_motion == VerticalAirMotion(0.3, 45.0)
    assert Environment.from_dict(env.to_dict()) == env
    assert Environment.from_dict({"vertical_air_motion": True}).vertical_air_motion == VerticalAirMotion()
    with pytest.raises(ValueError, match="sigma_mps"):
        Environment.from_dict({"vertical_air_motion": {"sigma_mps": 0.0}})
    with pytest.raises(ValueError, match="did you mean 'tau_s'"):
        Environment.from_dict({"vertical_air_motion": {"tau": 30}})


def test_a_sortie_refuses_the_vertical_air_motion():
    env = Environment(vertical_air_motion=VerticalAirMotion())
    with pytest.raises(FlightError, match="vertical air motion.*--sortie"):
        fly_sortie([SHORT], [(0, 1)], AIRFRAME, AIRCRAFT, env)
