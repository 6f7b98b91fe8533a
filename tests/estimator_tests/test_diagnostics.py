"""Fit-quality diagnostics (estimator.diagnostics): each detector on synthetic residuals with known
answers, and no false alarm on clean residuals.

The thresholds themselves were calibrated on fits of JSBSim data (good fits and injected faults);
these tests pin the detectors' behaviour on arrays whose answer is known exactly. Seeds are explicit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimator.diagnostics import (
    ChannelFit,
    Diagnosis,
    DiagnosticOptions,
    ManeuverInputs,
    diagnose,
    noise_floor,
)
from estimator.verdict import Severity

D2R = math.pi / 180.0
RATE_HZ = 40.0
#: Sampling deviation of the k = 3 difference floor of white noise, relative (module docstring):
#: sd(s_hat) / s = sqrt(sum_j rho_j^2 / (2 n)) with sum_j rho_j^2 = 2.31 for k = 3.
REL_SD_K3 = math.sqrt(1.155)


def sampling_tol(n: int, bias: float = 0.02) -> float:
    """5 sampling deviations of a floor from n samples, plus ``bias``: the floor is the larger of
    the spacing-1 and 2 estimates (+1.1 % measured on 400 replications), and edges get clipped."""
    return 5 * REL_SD_K3 / math.sqrt(n) + bias


def times(n: int, rate_hz: float = RATE_HZ) -> np.ndarray:
    return np.arange(n) / rate_hz


def doublet(t: np.ndarray, amp: float, t0: float = 5.0, width: float = 1.0,
            edge_s: float = 0.25) -> np.ndarray:
    """A pitch-doublet-like signal: +amp for ``width`` s then -amp, edges ~``edge_s`` long."""
    up = np.tanh((t - t0) / edge_s) - np.tanh((t - t0 - width) / edge_s)
    down = np.tanh((t - t0 - width) / edge_s) - np.tanh((t - t0 - 2 * width) / edge_s)
    return 0.5 * amp * (up - down)


def fit(maneuver: str, channel: str, t: np.ndarray, y: np.ndarray, z: np.ndarray, flow: bool | None = None,
        measured_t: np.ndarray | None = None, measured: np.ndarray | None = None, **kw) -> ChannelFit:
    flow = channel.startswith(("alpha", "beta")) if flow is None else flow
    deg = kw.pop("deg", channel not in ("tas", "h", "h_dgps"))
    return ChannelFit(maneuver, channel, flow, t, z, y, t if measured_t is None else measured_t,
                      z if measured is None else measured, unit="rad" if deg else "m",
                      display_scale=1 / D2R if deg else 1.0, display_unit="deg" if deg else "m", **kw)


def codes(d: Diagnosis, at_least: Severity = Severity.WARNING) -> list[str]:
    return [f.code for f in d.findings if f.severity >= at_least]


# ------------------------------------------------------------------------------------------------
# the noise floor
# ------------------------------------------------------------------------------------------------


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), sigma=st.floats(1e-4, 10.0), n=st.integers(800, 3000))
def test_floor_of_white_noise_within_its_sampling_error(seed, sigma, n):
    rng = np.random.default_rng(seed)
    t = times(n)
    x = 20 * sigma * doublet(t, 1.0) + sigma * rng.standard_normal(n)
    floor, q = noise_floor(t, x)
    assert abs(floor / sigma - 1.0) < sampling_tol(n), f"floor {floor / sigma:.4f} x sigma"
    assert q == 0.0


@pytest.mark.parametrize("source_hz", [64.0, 50.0, 25.0, 10.0])
def test_floor_of_noise_linearly_resampled_onto_the_common_base(source_hz):
    """Interpolation correlates neighbours: the floor must still be the std of the resampled noise."""
    rng = np.random.default_rng(7)
    t = times(1600)
    ts = np.arange(int((t[-1] + 1) * source_hz)) / source_hz
    z = np.interp(t, ts, 0.01 * rng.standard_normal(ts.size)) + 0.2 * np.sin(0.5 * t)
    e = z - 0.2 * np.sin(0.5 * t)
    floor, _ = noise_floor(t, z)
    # the resampled noise's own std, estimated from 1600 correlated samples: a few % (sd <= 3.7 %
    # over 400 replications at 10 Hz, where only 400 source samples exist)
    assert abs(floor / e.std() - 1.0) < 0.12, f"{source_hz} Hz: floor {floor / e.std():.3f} x the std"
    if source_hz <= 50.0:
        naive, _ = noise_floor(t, z, DiagnosticOptions(floor_max_spacing=1))
        assert naive < 0.97 * e.std(), "the trap is real: spacing-1 differences read low on resampled noise"


def test_floor_of_quantised_noisy_vane():
    """0.07 deg of noise quantised at 0.05 deg: the floor is sqrt(s^2 + q^2 / 12) (Sheppard)."""
    rng = np.random.default_rng(3)
    t = times(1600)
    q, s = 0.05 * D2R, 0.07 * D2R
    z = np.round((5 * D2R * doublet(t, 1.0) + s * rng.standard_normal(t.size)) / q) * q
    floor, quantum = noise_floor(t, z)
    assert abs(floor / math.sqrt(s**2 + q**2 / 12) - 1) < sampling_tol(1600)
    assert abs(quantum / q - 1) < 1e-6, "the quantisation step is the lattice of the differences"


def test_floor_of_quantisation_only_channel_is_q_over_sqrt12():
    t = times(1600)
    q = 0.05 * D2R
    z = np.round(2 * D2R * np.sin(t / 5) / q) * q  # no noise: the differences are mostly exactly 0
    floor, quantum = noise_floor(t, z)
    assert abs(quantum / q - 1) < 1e-6
    # the staircase's own differences add up to 20 % at larger spacings (1.18 measured here)
    assert 0.99 <= floor / (q / math.sqrt(12)) <= 1.25


def test_floor_ignores_a_sharp_maneuver():
    """A 10 deg pitch doublet with 0.1 s edges at 40 Hz: its own differences are not noise."""
    rng = np.random.default_rng(11)
    t = times(1600)
    s = 0.03 * D2R
    z = 10 * D2R * doublet(t, 1.0, edge_s=0.1) + 3 * D2R * doublet(t, 1.0, t0=20.0, edge_s=0.1)
    floor, _ = noise_floor(t, z + s * rng.standard_normal(t.size))
    assert abs(floor / s - 1) < sampling_tol(1600, 0.1), f"floor {floor / s:.3f} x sigma (edges clipped)"


def test_floor_of_own_rate_channel_does_not_difference_across_gaps():
    """DGPS height at 10 Hz, with a 5 s dropout across which the height changed by 80 m."""
    rng = np.random.default_rng(5)
    t = np.arange(400) / 10.0
    h = 6000 + 2.0 * t
    h[t >= 20] += 80.0
    keep = (t < 15) | (t >= 20)
    z = h + 0.3 * rng.standard_normal(t.size)
    floor, _ = noise_floor(t[keep], z[keep])
    assert abs(floor / 0.3 - 1) < sampling_tol(keep.sum())


def test_floor_of_a_slower_stream_held_on_the_common_base():
    """A 10 Hz stream written at 40 Hz by sample-and-hold: three repeats in four; its own samples."""
    rng = np.random.default_rng(21)
    e = 0.3 * rng.standard_normal(400)
    t = times(1600)
    x = np.repeat(6000 + 2.0 * t[::4] + e, 4)
    floor, q = noise_floor(t, x)
    assert q == 0.0 and abs(floor / e.std() - 1) < sampling_tol(400)


def test_constant_channel_has_zero_floor_and_no_ratio():
    t = times(800)
    d = diagnose([fit("m0", "theta", t, np.full(t.size, 0.1), np.full(t.size, 0.1))])
    row = d.table.iloc[0]
    assert row.noise_floor == 0.0 and math.isnan(row.ratio)
    assert codes(d) == [], "a constant channel whose model does not move is not stuck"


# ------------------------------------------------------------------------------------------------
# findings on one channel
# ------------------------------------------------------------------------------------------------


def clean_maneuver(man: str, rng: np.random.Generator, n: int = 1600) -> list[ChannelFit]:
    """The channels of a well-fitted maneuver: model outputs plus white noise, SI."""
    t = times(n)
    out = []
    for ch, y, s in (("phi", 20 * D2R * np.sin(t / 6), 0.03 * D2R),
                     ("theta", 3 * D2R + 4 * D2R * doublet(t, 1.0), 0.03 * D2R),
                     ("psi", 0.01 * t, 0.03 * D2R),
                     ("tas", 150 + 2 * np.sin(t / 8), 0.1),
                     ("h", 6000 + 30 * np.sin(t / 10), 1.3),
                     ("alpha_zl", 4 * D2R + 5 * D2R * doublet(t, 1.0), 0.05 * D2R),
                     ("alpha_zr", 4 * D2R + 5 * D2R * doublet(t, 1.0), 0.05 * D2R),
                     ("beta_zsp", 2 * D2R * np.sin(t / 4), 0.03 * D2R)):
        z = y + s * rng.standard_normal(n)
        out.append(fit(man, ch, t, y, z))
    return out


def test_stuck_and_dead_channels_are_named_with_their_time_range():
    rng = np.random.default_rng(1)
    fits = clean_maneuver("m0", rng)
    t = fits[5].t_s
    y = fits[5].y
    stuck = fit("m0", "alpha_zl", t, y, np.full(t.size, 5 * D2R))
    dead = fit("m0", "alpha_zr", t, y, np.zeros(t.size))
    partial_z = fits[7].z.copy()
    i0 = np.searchsorted(t, 15.0)
    partial_z[i0:] = partial_z[i0]
    partial = fit("m0", "beta_zsp", t, fits[7].y, partial_z)
    d = diagnose(fits[:5] + [stuck, dead, partial])
    got = {(f.code, f.channel): f for f in d.findings if f.severity == Severity.FAILURE}
    assert ("stuck_channel", "alpha_zl") in got and ("dead_channel", "alpha_zr") in got
    assert got[("stuck_channel", "alpha_zl")].t_s == (t[0], t[-1])
    f = got[("stuck_channel", "beta_zsp")]
    assert f.t_s == (t[i0], t[-1]) and "from t = 15.00" in f.message
    assert "5 deg" in got[("stuck_channel", "alpha_zl")].message, "the stuck value, in display units"
    assert d.table.set_index("channel").loc["alpha_zl", "stuck"]


def test_quantised_channel_steady_within_one_level_is_not_stuck():
    t = times(1600)
    q = 0.05 * D2R
    y = 3 * D2R + 0.2 * q * np.sin(t / 3)  # the model moves by less than a quantum
    z = np.round(y / q) * q
    z[:200] = np.round((y[:200] + 3 * q * np.sin(t[:200])) / q) * q  # elsewhere it moves: q is seen
    d = diagnose([fit("m0", "alpha_zl", t, y, z)])
    assert "stuck_channel" not in codes(d)


def test_spike_is_an_outlier_at_its_time_and_nothing_else():
    rng = np.random.default_rng(2)
    fits = clean_maneuver("m0", rng)
    f = fits[5]
    z = f.z.copy()
    z[400] += 30 * D2R
    z[900] += 18 * D2R  # a spike split over two samples by the resampling
    z[901] += 12 * D2R
    fits[5] = fit("m0", "alpha_zl", f.t_s, f.y, z)
    d = diagnose(fits)
    assert codes(d) == ["outlier"]
    (o,) = [x for x in d.findings if x.code == "outlier"]
    assert o.channel == "alpha_zl" and o.t_s == (f.t_s[400], f.t_s[900], f.t_s[901])
    assert np.array_equal(d.outliers[("m0", "alpha_zl")], f.t_s[[400, 900, 901]])
    assert "robust" in o.advice
    row = d.table.set_index("channel").loc["alpha_zl"]
    assert row.n_outliers == 3 and row.ratio < 1.2, "the ratio leaves the outliers out"


@pytest.mark.parametrize("channel, factor, words", [
    ("theta", 180 / math.pi, "degrees but declared as radians"),
    ("h", 1 / 0.3048, "feet but declared as metres"),
    ("beta_zsp", math.pi / 180, "radians but declared as degrees"),
])
def test_unit_error_is_named_from_the_slope(channel, factor, words):
    rng = np.random.default_rng(4)
    fits = {f.channel: f for f in clean_maneuver("m0", rng)}
    f = fits[channel]
    z = factor * f.z  # the noise scales too: the floor of z is factor x larger
    fits[channel] = fit("m0", channel, f.t_s, f.y, z)
    d = diagnose(list(fits.values()))
    (u,) = [x for x in d.findings if x.code == "unit_error"]
    assert u.channel == channel and u.severity == Severity.FAILURE and words in u.message
    assert abs(u.value / factor - 1) < 0.02
    assert d.findings[0] is u


def test_unit_error_of_a_flow_channel_absorbed_by_its_model_is_found_on_the_kinematic_angle():
    """A vane in degrees declared as radians, fitted by a model with a free scale: the residual is
    noise, but the measurement is 57.3 x the angle of attack of the reconstructed flight path."""
    rng = np.random.default_rng(6)
    t = times(1600)
    alpha = 4 * D2R + 5 * D2R * doublet(t, 1.0)
    z = 180 / math.pi * alpha + 0.05 * rng.standard_normal(t.size)
    y = 180 / math.pi * alpha  # the model's scale absorbed the factor
    states = np.zeros((t.size, 7))
    states[:, 0] = 150 * np.cos(alpha)
    states[:, 2] = 150 * np.sin(alpha)
    m = ManeuverInputs("m0", t, np.tile([0.0, 0.0, -9.8], (t.size, 1)), np.zeros((t.size, 3)) + 1e-4 *
                       rng.standard_normal((t.size, 3)), states)
    d = diagnose([fit("m0", "alpha_zl", t, y, z)], [m])
    (u,) = [x for x in d.findings if x.code == "unit_error"]
    assert "kinematic alpha" in u.message and "degrees but declared as radians" in u.message


def test_scale_error_not_matching_a_unit():
    rng = np.random.default_rng(8)
    fits = {f.channel: f for f in clean_maneuver("m0", rng)}
    f = fits["theta"]
    fits["theta"] = fit("m0", "theta", f.t_s, f.y, 1.5 * f.z)
    d = diagnose(list(fits.values()))
    (s,) = [x for x in d.findings if x.code == "scale_error"]
    assert s.channel == "theta" and abs(s.value - 1.5) < 0.02 and s.severity == Severity.FAILURE


@pytest.mark.parametrize("excess, code, severity", [
    (60.0, "misfit", Severity.FAILURE),  # 1.8 deg rms: beyond any working attitude reference (1.5)
    (30.0, "misfit", Severity.NOTE),     # 0.9 deg rms: what a small UAV's AHRS leaves
    (2.5, "misfit", Severity.NOTE), (1.3, None, None)])
def test_kinematic_misfit_against_the_floor(excess, code, severity):
    """theta's residual = its noise (0.03 deg) plus a smooth error, ``excess`` x the floor in all: a
    failure only where the misfit is gross, above ``misfit_ratio`` floors and the attitude limit
    (1.5 deg rms); a slow, coloured residual below it is said as a note (real recorded data)."""
    rng = np.random.default_rng(9)
    fits = {f.channel: f for f in clean_maneuver("m0", rng)}
    f = fits["theta"]
    s = 0.03 * D2R
    smooth = math.sqrt(excess**2 - 1) * s * math.sqrt(2) * np.sin(2 * np.pi * 0.2 * f.t_s)
    fits["theta"] = fit("m0", "theta", f.t_s, f.y, f.z + smooth)
    d = diagnose(list(fits.values()))
    ratio = d.table.set_index("channel").loc["theta", "ratio"]
    # the ratio is the excess, to the floor's sampling error (5 sd, 2 % for the max of two spacings)
    assert abs(ratio / excess - 1) < sampling_tol(1600)
    got = [(x.code, x.severity) for x in d.findings if x.channel == "theta"]
    assert got == ([] if code is None else [(code, severity)])


@pytest.mark.parametrize("excess, expect", [(3.0, ["noise_floor"]), (1.3, [])])
def test_flow_channel_above_its_floor_is_a_warning_only(excess, expect):
    rng = np.random.default_rng(10)
    fits = {f.channel: f for f in clean_maneuver("m0", rng)}
    f = fits["alpha_zl"]
    s = 0.05 * D2R
    smooth = math.sqrt(excess**2 - 1) * s * math.sqrt(2) * np.sin(2 * np.pi * 0.3 * f.t_s)
    fits["alpha_zl"] = fit("m0", "alpha_zl", f.t_s, f.y, f.z + smooth)
    d = diagnose(list(fits.values()))
    assert codes(d) == expect
    assert all(x.severity == Severity.WARNING for x in d.findings if x.code == "noise_floor")


def test_strongly_coloured_moderate_residual_is_info():
    rng = np.random.default_rng(12)
    fits = {f.channel: f for f in clean_maneuver("m0", rng)}
    f = fits["tas"]
    smooth = math.sqrt(1.7**2 - 1) * 0.1 * math.sqrt(2) * np.sin(2 * np.pi * 0.1 * f.t_s)
    fits["tas"] = fit("m0", "tas", f.t_s, f.y, f.z + smooth)
    d = diagnose(list(fits.values()))
    assert codes(d) == []
    assert [(x.code, x.channel) for x in d.findings] == [("coloured", "tas")]


# ------------------------------------------------------------------------------------------------
# turbulence: common-mode coloured flow residuals
# ------------------------------------------------------------------------------------------------


def gust(t: np.ndarray, rng: np.random.Generator, std: float) -> np.ndarray:
    """Band-limited (0.1-0.8 Hz) zero-mean random motion with standard deviation ``std``."""
    f = rng.uniform(0.1, 0.8, 12)
    g = np.sin(2 * np.pi * f[:, None] * t[None, :] + rng.uniform(0, 2 * np.pi, 12)[:, None]).sum(axis=0)
    g -= g.mean()
    return std * g / g.std()


def test_common_coloured_flow_residuals_are_turbulence():
    rng = np.random.default_rng(13)
    fits = clean_maneuver("m0", rng)
    t = fits[0].t_s
    w = gust(t, rng, 0.4 * D2R)  # vertical gust: every AOA sensor alike
    v = gust(t, rng, 0.3 * D2R)  # lateral gust: the sideslip sensors
    for i, g in ((5, w), (6, 1.1 * w), (7, v)):
        f = fits[i]
        fits[i] = fit("m0", f.channel, t, f.y, f.z + g)
    tas = fits[3]
    fits[3] = fit("m0", "tas", t, tas.y, tas.z + gust(t, rng, 0.8))  # longitudinal gust
    d = diagnose(fits)
    (turb,) = [x for x in d.findings if x.code == "turbulence"]
    # a failure: the output-error estimates and even the honest deviations are off in gusts
    assert turb.severity == Severity.FAILURE
    assert set(turb.channel.split(", ")) == {"alpha_zl", "alpha_zr", "tas"}
    assert "calm air" in turb.advice and "process noise" in turb.advice
    assert codes(d) == ["turbulence", "noise_floor"], "beta_zsp moves alone: structure, not common air motion"


def test_common_flow_residuals_with_misfitting_kinematics_are_not_turbulence():
    rng = np.random.default_rng(14)
    fits = clean_maneuver("m0", rng)
    t = fits[0].t_s
    w = gust(t, rng, 0.4 * D2R)
    for i in (5, 6):
        fits[i] = fit("m0", fits[i].channel, t, fits[i].y, fits[i].z + w)
    fits[1] = fit("m0", "theta", t, fits[1].y, fits[1].z + gust(t, rng, 2.0 * D2R))  # a wrong minimum
    d = diagnose(fits)
    assert "turbulence" not in codes(d) and "misfit" in codes(d)


# ------------------------------------------------------------------------------------------------
# the IMU inputs
# ------------------------------------------------------------------------------------------------


def inputs(man: str, rng: np.random.Generator, n: int = 1600, az: float = -9.8, gyro_zero: bool = False,
           pitch_deg: float = 5.0) -> ManeuverInputs:
    t = times(n)
    theta = 2 * D2R + pitch_deg * D2R * doublet(t, 1.0)
    acc = np.column_stack([0.1 * rng.standard_normal(n), 0.1 * rng.standard_normal(n),
                           az + 0.1 * rng.standard_normal(n)])
    om = np.zeros((n, 3)) if gyro_zero else np.column_stack(
        [1e-3 * rng.standard_normal(n), np.gradient(theta, t) + 1e-3 * rng.standard_normal(n),
         1e-3 * rng.standard_normal(n)])
    states = np.zeros((n, 7))
    states[:, 0] = 150.0
    states[:, 4] = theta
    eul = np.column_stack([np.zeros(n), theta, np.zeros(n)]) + 0.03 * D2R * rng.standard_normal((n, 3))
    return ManeuverInputs(man, t, acc, om, states, eul)


def test_dead_gyros_while_the_attitude_changes():
    rng = np.random.default_rng(15)
    d = diagnose([], [inputs("m0", rng, gyro_zero=True), inputs("m1", rng)])
    dead = [f for f in d.findings if f.code == "dead_input"]
    assert {f.channel for f in dead} == {"p_rps", "q_rps", "r_rps"}
    assert all(f.maneuver == "m0" and f.severity == Severity.FAILURE and f.t_s for f in dead)


def test_constant_gyro_in_steady_flight_is_not_dead():
    rng = np.random.default_rng(16)
    d = diagnose([], [inputs("m0", rng, gyro_zero=True, pitch_deg=0.0)])
    assert codes(d) == []


@pytest.mark.parametrize("az, code", [(+9.8, "accel_sign"), (-1.0, "unit_error"), (-9.8, None),
                                      (-30.0, None)])
def test_body_z_specific_force_sign_and_units(az, code):
    rng = np.random.default_rng(17)
    d = diagnose([], [inputs("m0", rng, az=az)])
    got = [(f.code, f.channel) for f in d.findings]
    assert got == ([] if code is None else [(code, "az_imu_mps2")])


# ------------------------------------------------------------------------------------------------
# ordering, attribution, table; no false alarm
# ------------------------------------------------------------------------------------------------


def test_the_data_fault_comes_first_and_its_consequences_say_so():
    rng = np.random.default_rng(18)
    fits = clean_maneuver("m0", rng)
    t = fits[0].t_s
    fits[5] = fit("m0", "alpha_zl", t, fits[5].y, np.full(t.size, 5 * D2R))
    fits[1] = fit("m0", "theta", t, fits[1].y, fits[1].z + 1 * D2R * np.sin(t / 5))  # dragged
    d = diagnose(fits)
    assert d.findings[0].code == "stuck_channel" and d.findings[0].channel == "alpha_zl"
    (mis,) = [f for f in d.findings if f.code == "misfit"]
    assert "consequence of the stuck channel of alpha_zl" in mis.message


def test_table_has_a_row_per_maneuver_and_channel_with_display_units():
    rng = np.random.default_rng(19)
    fits = clean_maneuver("m0", rng) + clean_maneuver("m1", rng)
    d = diagnose(fits)
    tab = d.to_pandas()
    assert len(tab) == len(fits) and not tab.duplicated(["maneuver", "channel"]).any()
    for col in ("noise_floor", "ratio", "rho1", "n_outliers", "slope", "stuck", "rms_display"):
        assert col in tab.columns
    row = tab.set_index(["maneuver", "channel"]).loc[("m1", "theta")]
    assert row.rms_display == pytest.approx(row.rms / D2R) and row.display_unit == "deg"


def test_no_false_alarm_on_clean_residuals_of_many_channels():
    """40 maneuvers x 8 channels of white-noise residuals, some resampled from 64 Hz, some quantised,
    an own-rate 10 Hz height: no warning, no failure, every ratio within its sampling error."""
    rng = np.random.default_rng(20)
    fits = []
    for k in range(40):
        fits += clean_maneuver(f"m{k}", rng)
        t = times(1600)
        ts = np.arange(int(41 * 64)) / 64.0
        y = 4 * D2R + 5 * D2R * doublet(t, 1.0, t0=8.0)
        z = y + np.interp(t, ts, 0.06 * D2R * rng.standard_normal(ts.size))
        fits.append(fit(f"m{k}", "alpha_zsp", t, y, z))
        q = 0.05 * D2R
        zq = np.round((y + 0.07 * D2R * rng.standard_normal(t.size)) / q) * q
        fits.append(fit(f"m{k}", "alpha_zb", t, y, zq))
        t10 = t[::4]
        h = 6000 + 30 * np.sin(t10 / 10)
        fits.append(fit(f"m{k}", "h_dgps", t10, h, h + 0.3 * rng.standard_normal(t10.size)))
    d = diagnose(fits)
    assert codes(d) == [], [f.text() for f in d.findings][:5]
    # the 10 Hz channel has 400 samples: 5 sampling deviations of it, plus the quantised vane's
    # Sheppard approximation and the max of two spacings (2 %)
    r = d.table.ratio.to_numpy()
    tol = sampling_tol(400)
    assert np.all(np.abs(r - 1) < tol), f"ratios {r.min():.3f}-{r.max():.3f}, tolerance {tol:.3f}"
    assert d.table.n_outliers.sum() == 0 and not d.table.stuck.any()
