"""Four bad inputs a user met on a 3-maneuver CSV are named, and good data are not refused.

The user's report (``fpr calibrate problem.toml`` and ``--single`` on one Mach bin of 3 maneuvers):

1. a CG in inches under a metre key (``r_cg_body_m = [13.0, 0.0, 5.1]`` for ``[0.33, 0, 0.13]``
   m): the fit converged, a time delay 17 deviations off, nothing said. Now refused at import
   (:mod:`estimator.io.positions`), naming the key, its line, inches and ``r_cg_body_in``;
2. a sideslip within +-0.7 deg in degrees declared as radians: a FAILURE on the channel's
   residual, no unit. Now a ``unit_error`` naming the channel, x 57.2958 and ``unit = "deg"``
   (the slope on the reconstructed kinematic sideslip, ``_unit_finding``);
3. gyro rates in rad/s declared as deg/s: a FAILURE on an Euler angle's misfit. Now refused at
   import (:mod:`estimator.io.consistency`), naming p, q, r, rad/s and ``unit = "rad/s"``;
4. one vane sample 25 deg off (below the import's spike check) that alone makes Table 2 miss:
   now the first warning the user reads (console and findings.csv), with its time, saying that
   it makes Table 2 miss and to rerun with ``--robust``.

And the checks refuse no good data: the corpus base (campaigns/faults_base.toml as a user's CSV),
layouts of real aircraft (a small UAV like UMN Thor, transports whose sensors sit in the nose far
from the CG) and real-flight-like attitude data (an AHRS's lag and noise, gyro bias, a heading
that wraps). The corpus (campaigns/benchmarks/bad_inputs.py) runs the same four on its base and
on a 3-maneuver variant; these are the fast checks. Flights: the corpus base and the same with
the rudder doublets at 0.2 (a few seconds each, flown once per session).
"""

from __future__ import annotations

import math
import re
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from campaigns.benchmarks.user_files import DEG, USER_COLUMNS, write_user_files
from campaigns.cli import main
from estimator.diagnostics import ChannelFit, ManeuverInputs, diagnose
from estimator.finding_groups import group_findings
from estimator.io import DataError, load_problem
from estimator.io.consistency import check_euler_rates
from estimator.io.errors import Where
from estimator.io.positions import Position, check_positions
from estimator.solver import estimate
from estimator.verdict import Finding, Severity, Verdict
from synth.campaign import resolve_campaign_path

D2R = math.pi / 180.0
CAMPAIGN = tomllib.loads(resolve_campaign_path("faults_base").read_text(encoding="utf-8"))
#: The base with the rudder doublets at 0.2: the sideslip within +-0.7 deg (the report's "within a
#: degree or so"), where the kinematic slope was once left untested (its sd 0.0043 rad < 0.005)
SMALL_BETA = {**CAMPAIGN, "flights": [CAMPAIGN["flights"][0],
                                      {**CAMPAIGN["flights"][1], "maneuver": {"rudder_norm": 0.2}}]}
CHANNELS = ["phi", "theta", "psi", "tas", "h", "alpha_zl", "alpha_zr", "alpha_zsp", "beta_zsp"]
COLUMNS = {k: USER_COLUMNS[k] for k in ("ax", "ay", "az", "p", "q", "r", *CHANNELS)}
#: Codes naming a fault of the data itself
DATA_FAULTS = {"stuck_channel", "dead_channel", "dead_input", "accel_sign", "unit_error"}
#: PV1's sensor positions (the corpus's [sensors]), m
PV1 = {"imu": (1.8, 0.1, 0.2), "vane_left": (6.2, -0.45, 0.25), "vane_right": (6.2, 0.45, 0.25),
       "side_probe_left": (6.6, -0.52, 0.05), "side_probe_right": (6.6, 0.52, 0.05)}


@pytest.fixture(scope="module")
def base(fly_once) -> Path:
    """The corpus base (the same dict and label as tests/campaigns_tests/test_faults.py's calm flight:
    flown once per session)."""
    camp = {**CAMPAIGN, "environment": {**CAMPAIGN["environment"], "turbulence": "none"}}
    return fly_once(camp, "test_faults (none)")


@pytest.fixture(scope="module")
def small_beta(fly_once) -> Path:
    return fly_once(SMALL_BETA, "test_bad_inputs_named (rudder 0.2)")


def user_files(ds: Path, dest: Path, wrong: dict[str, tuple[float, str]] | None = None) -> Path:
    """A user's CSV and problem file of a flown dataset; ``wrong``: channel -> (factor from SI as
    written, declared unit)."""
    cols = dict(COLUMNS)
    for name, (factor, unit) in (wrong or {}).items():
        csv, src, _, _, extra = cols[name]
        cols[name] = (csv, src, factor, unit, extra)
    return write_user_files(ds, dest, cols, CHANNELS, "bad inputs named")


def ranked(findings) -> list[Finding]:
    """Warnings and failures as the user reads them (most severe first, the order within kept),
    without the base's own crosswind warning."""
    out = sorted(findings, key=lambda f: -int(f.severity))
    return [f for f in out if f.severity >= Severity.WARNING and f.code != "crosswind_confounded"]


# ------------------------------------------------------------------------------------------------
# 1. the CG in inches


def _problem_file(tmp_path: Path, cg: str, extra: str = "") -> Path:
    """A problem file with PV1's sensors and the CG given; its data file does not exist (positions
    are checked before any data is read)."""
    sensors = "\n".join(f"{k} = [{', '.join(map(str, v))}]" for k, v in PV1.items())
    text = (f'title = "cg"\nmodel = "tejas"\n{extra}\n[sensors]\n{sensors}\n\n[aircraft.PV1]\n{cg}\n\n'
            '[columns]\nt = { column = "Time", unit = "s" }\n\n[[files]]\npath = "flight.csv"\n')
    path = tmp_path / "problem.toml"
    path.write_text(text)
    return path


def test_cg_in_inches_under_a_metre_key_is_refused_naming_key_line_and_unit(tmp_path):
    path = _problem_file(tmp_path, "r_cg_body_m = [13.0, 0.0, 5.1]")
    with pytest.raises(DataError) as e:
        load_problem(path)
    msg = str(e.value)
    line = 1 + path.read_text().splitlines().index("r_cg_body_m = [13.0, 0.0, 5.1]")
    # the file, the key and its line, what it is, the unit it probably is and the key to write it under
    for part in (f"problem.toml line {line}", "[aircraft.PV1] r_cg_body_m", "the CG of aircraft PV1",
                 "read as inches it is [0.33, 0, 0.13] m", "Write r_cg_body_in = [13, 0, 5.1]"):
        assert part in msg, (part, msg)


def test_the_same_cg_in_metres_or_under_the_inch_key_is_accepted(tmp_path):
    for cg in ("r_cg_body_m = [0.33, 0.0, 0.13]", "r_cg_body_in = [13.0, 0.0, 5.1]"):
        path = _problem_file(tmp_path, cg)
        with pytest.raises(DataError) as e:  # past the positions: the data file is missing
            load_problem(path)
        assert "no such data file" in str(e.value), (cg, "the positions must pass", str(e.value))


def _positions(sensors: dict, cg: tuple[float, float, float], unit: str = "m") -> list[Position]:
    out = [Position(f"sensor {k}", f"[sensors] {k}", k, "m", tuple(map(float, v)), False)
           for k, v in sensors.items()]
    return out + [Position("the CG", f"[aircraft.X] r_cg_body_{unit}", f"r_cg_body_{unit}", unit, cg, True)]


@pytest.mark.parametrize("sensors, cg, why", [
    (PV1, (0.302, 0.0, 0.091), "the corpus base's CG (0.04 m beside the sensors' cross-section)"),
    (PV1, (-2.0, 0.0, 0.5), "a CG 2 m aft of the IMU and 0.25 m below the vanes"),
    (PV1, (0.33 * 3.2808, 0.0, 0.13 * 3.2808), "a CG in feet under the metre key: 0.43 m low, not certain"),
    ({"imu": (0, 0, 0), "probe": (0.6, 0, 0)}, (0.0, 0.0, 0.0), "UMN Thor: IMU at the CG, a 0.6 m probe"),
    ({"iru": (-7, 0, 2), "vane_l": (-2, -1.8, 1.5), "vane_r": (-2, 1.8, 1.5)}, (-28.0, 0.0, 1.5),
     "a transport referenced to its nose: avionics-bay IMU and nose vanes, the CG 21 m aft of them"),
    ({"iru": (-7, 0, 0), "vane_l": (-2, -1.8, 0), "vane_r": (-2, 1.8, 0)}, (-28.0, 0.0, 0.0),
     "the same with every position on the centre line's height (its inch reading lands among them)"),
    ({"iru": (-3, 0, 1), "boom": (3, 0, 0.5)}, (-25.0, 0.0, 1.0), "a nose boom and a nose IMU, CG 22 m aft"),
])
def test_positions_of_real_layouts_pass(sensors, cg, why):
    try:
        check_positions(_positions(sensors, cg), "p.toml")
    except DataError as e:
        pytest.fail(f"good positions refused ({why}): {e}")


def test_a_sensor_in_inches_is_named_and_no_airframe_is_120_m():
    pos = _positions({**PV1, "vane_left": (244.1, -17.7, 9.8)}, (0.3, 0.0, 0.1))
    with pytest.raises(DataError, match=r"\[sensors\] vane_left = .* more than any aircraft measures.*"
                                        r"read as inches it is \[6\.2, -0\.45, 0\.249\] m"):
        check_positions(pos, "p.toml")
    # positions_checked skips the far-outside check (a layout the user vouches for), never the size
    check_positions(_positions(PV1, (13.0, 0.0, 5.1)), "p.toml", checked=True)
    with pytest.raises(DataError, match="more than any aircraft measures"):
        check_positions(_positions(PV1, (500.0, 0.0, 0.0)), "p.toml", checked=True)


# ------------------------------------------------------------------------------------------------
# 3. gyro rates in rad/s declared as deg/s


def test_rates_in_rad_s_declared_deg_s_are_refused_naming_the_rates_and_the_unit(base, tmp_path):
    path = user_files(base, tmp_path / "user", {c: (1.0, "deg/s") for c in ("p", "q", "r")})
    with pytest.raises(DataError) as e:
        load_problem(path)
    msg = str(e.value)
    for part in ("flight.csv, maneuver m0000 (t = ", "p (column 'P'), q (column 'Q'), r (column 'R')",
                 "look like rad/s", 'declare unit = "rad/s" for p, q and r'):
        assert part in msg, (part, msg)


def _flight_like(rng: np.random.Generator, n: int = 2400, rate_hz: float = 50.0):
    """A real-flight-like record (a small UAV's): a turn and pitch doublets, the gyros with noise
    and a bias, the AHRS attitude lagged by 0.1 s (a first-order filter) with 0.3-deg noise, the
    heading wrapped to +-180 deg. SI, rad."""
    t = np.arange(n) / rate_hz
    p = 0.3 * np.sin(2 * np.pi * t / 12.0) + 0.2 * (np.abs(t - 20) < 1.0)
    q = 0.15 * np.sign(np.sin(2 * np.pi * t / 6.0)) * (t % 15 < 6)
    r = 0.12 + 0.05 * np.sin(2 * np.pi * t / 9.0)
    phi, theta, psi = np.zeros(n), np.zeros(n), np.zeros(n)
    for k in range(1, n):  # Euler kinematics, forward Euler at 50 Hz
        dt = t[k] - t[k - 1]
        sp, cp, tt, ct = np.sin(phi[k - 1]), np.cos(phi[k - 1]), np.tan(theta[k - 1]), np.cos(theta[k - 1])
        phi[k] = phi[k - 1] + dt * (p[k - 1] + (q[k - 1] * sp + r[k - 1] * cp) * tt)
        theta[k] = theta[k - 1] + dt * (q[k - 1] * cp - r[k - 1] * sp)
        psi[k] = psi[k - 1] + dt * (q[k - 1] * sp + r[k - 1] * cp) / ct
    a = 1.0 - np.exp(-1.0 / (rate_hz * 0.1))

    def ahrs(x):
        y = np.empty_like(x)
        y[0] = x[0]
        for k in range(1, x.size):
            y[k] = y[k - 1] + a * (x[k] - y[k - 1])
        return y + 0.3 * D2R * rng.standard_normal(x.size)

    gyro = {k: v + 0.01 + 0.02 * rng.standard_normal(n) for k, v in (("p", p), ("q", q), ("r", r))}
    si = {**gyro, "phi": ahrs(phi), "theta": ahrs(theta), "psi": np.angle(np.exp(1j * ahrs(psi)))}
    return si, t


def test_euler_rate_check_passes_real_flight_like_data_and_names_rates_read_57_x_small():
    si, t = _flight_like(np.random.default_rng(3))
    units = {**dict.fromkeys("pqr", "deg/s"), **dict.fromkeys(("phi", "theta", "psi"), "deg")}
    labels = {k: k for k in units}
    check_euler_rates(si, t, units, labels, Where("uav.csv", "s00"))  # good data: no error
    small = {**si, **{k: si[k] / 57.2958 for k in "pqr"}}
    with pytest.raises(DataError, match=r'look like rad/s .*declare unit = "rad/s" for p, q and r'):
        check_euler_rates(small, t, units, labels, Where("uav.csv", "s00"))


# ------------------------------------------------------------------------------------------------
# 2. a small sideslip in degrees declared as radians


@pytest.mark.slow
def test_small_sideslip_in_degrees_declared_as_radians_is_a_unit_error(small_beta, tmp_path):
    path = user_files(small_beta, tmp_path / "user", {"beta_zsp": (DEG, "rad")})
    problem = load_problem(path)  # within +-0.7 "rad": the import's range check lets it pass
    res = estimate(problem)
    first = ranked(res.findings)[0]
    text = res.summary(max_findings=20)
    assert res.verdict == Verdict.FAILURE, text
    assert (first.code, first.channel, first.severity) == ("unit_error", "beta_zsp", Severity.FAILURE), text
    assert "recorded in degrees but declared as radians (x 57.2958)" in first.message, first.message
    assert 'unit = "deg" for beta_zsp under [columns]' in first.advice, first.advice
    wrong = [f for f in res.findings if f.code in DATA_FAULTS and f.channel != "beta_zsp"]
    assert not wrong, "a data fault blamed on a channel that is right: " + "; ".join(f.text() for f in wrong)


def _beta_fit(rng, t, beta, z_factor: float, y_factor: float, drag: float = 1.0) -> tuple[ChannelFit,
                                                                                           ManeuverInputs]:
    """A side-probe channel ``z = z_factor (beta + noise)`` whose model output ``y = y_factor *
    drag * beta`` (a free scale that absorbed part of a factor), and the states whose kinematic
    sideslip is ``beta``."""
    z = z_factor * (beta + 0.025 * D2R * rng.standard_normal(t.size))
    y = y_factor * drag * beta
    states = np.zeros((t.size, 7))
    states[:, 0] = 150.0
    states[:, 1] = 150.0 * np.tan(beta)
    m = ManeuverInputs("m1", t, np.tile([0.0, 0.0, -9.8], (t.size, 1)), np.zeros((t.size, 3)), states)
    f = ChannelFit("m1", "beta_zsp", True, t, z, y, t, z, display_scale=1 / D2R, display_unit="deg")
    return f, m


def test_the_kinematic_slope_names_a_small_sideslip_in_degrees_and_no_good_channel():
    """The slope on the kinematic sideslip with the sideslip's sd 0.0025 rad (under the 0.005 rad
    the scale test needs): 57.3 is named, a good channel (slope 1) or one dragged by a fault
    elsewhere (slopes of 0.5-2, seen with a TAS in knots) is not."""
    rng = np.random.default_rng(11)
    t = np.arange(1200) / 40.0
    beta = 0.35 * D2R * np.sin(2 * np.pi * t / 5.0) * (t > 5)  # +-0.35 deg: sd 0.0040 rad
    f, m = _beta_fit(rng, t, beta, 180 / math.pi, 0.5 * 180 / math.pi)  # the model absorbed half
    (u,) = [x for x in diagnose([f], [m]).findings if x.code == "unit_error"]
    assert "57.2958" in u.message and 'unit = "deg"' in u.advice, u.text()
    for drag in (1.0, 0.5, 2.0):
        f, m = _beta_fit(rng, t, beta, 1.0, 1.0, drag)
        d = diagnose([f], [m])
        assert not [x for x in d.findings if x.code == "unit_error"], (drag, [x.text() for x in d.findings])


# ------------------------------------------------------------------------------------------------
# 4. one vane sample that makes Table 2 miss


def test_a_spike_that_makes_table2_miss_is_said_first_with_its_time_and_robust(base, tmp_path, capsys):
    user = user_files(base, tmp_path / "user")
    df = pd.read_csv(user.parent / "flight.csv")
    i = int(np.searchsorted(df["Time"].to_numpy(), 1012.0))  # 12 s into the first maneuver (at 1000 s)
    df.loc[i, "AOA_L"] += 25.0
    df.to_csv(user.parent / "flight.csv", index=False)
    out = tmp_path / "res"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        code = main(["calibrate", str(user), "--single", "--out", str(out), "--no-plots"])
    text = capsys.readouterr().out
    assert code == 3, text  # success with warnings: one sample barely moves the estimates
    said = [ln.strip() for ln in text.splitlines() if re.match(r"\s+(WARNING|FAILURE): ", ln)]
    assert said and said[0].startswith("WARNING: alpha_zl in maneuver m0000: 1 outlier sample(s) at t = "
                                       "1012.000 s"), text
    assert "this sample alone makes alpha_zl miss its desired accuracy" in said[0], said[0]
    assert "(fpr calibrate --robust)" in said[0], said[0]
    top = pd.read_csv(out / "findings.csv").iloc[0]
    assert (top["code"], top["severity"], top["channel"]) == ("outlier", "WARNING", "alpha_zl"), top
    assert "Table 2" in top["message"] and "--robust" in top["advice"], top


def test_an_outlier_that_does_not_make_table2_miss_does_not_say_so():
    """One 3-deg sample in 3600 (3 sigma 0.18 deg with it, desired 0.5): an outlier, not the miss."""
    rng = np.random.default_rng(12)
    t = np.arange(3600) / 40.0
    y = 4 * D2R + 3 * D2R * np.sin(t / 3.0)
    z = y + 0.048 * D2R * rng.standard_normal(t.size)
    z[480] += 3.0 * D2R
    f = ChannelFit("m0", "alpha_zl", True, t, z, y, t, z, display_scale=1 / D2R, display_unit="deg",
                   desired_3sigma=0.5 * D2R)
    (o,) = [x for x in diagnose([f]).findings if x.code == "outlier"]
    assert "Table 2" not in o.message, o.message
    z[480] += 22.0 * D2R  # 25 deg: now it is the miss, and said first among the warnings
    f = ChannelFit("m0", "alpha_zl", True, t, z, y, t, z, display_scale=1 / D2R, display_unit="deg",
                   desired_3sigma=0.5 * D2R)
    (o,) = [x for x in diagnose([f]).findings if x.code == "outlier"]
    assert "this sample alone makes alpha_zl miss its desired accuracy" in o.message, o.message
    crosswind = Finding("crosswind_confounded", Severity.WARNING, "the sideslip offsets ...")
    groups = group_findings([crosswind, o])
    assert groups[0].code == "outlier", [g.code for g in groups]


# ------------------------------------------------------------------------------------------------
# good data


def test_the_corpus_base_is_not_refused_and_no_data_fault_is_named(base, tmp_path):
    res = estimate(load_problem(user_files(base, tmp_path / "user")))
    assert res.verdict != Verdict.FAILURE, res.summary()
    assert not [f for f in res.findings if f.code in DATA_FAULTS], res.summary()
