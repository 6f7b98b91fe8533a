"""Flight logs behind a problem file's ``[[files]]``: MATLAB (v5, v7.3) and PX4 ULog files read
into streams, each on its own clock, and brought onto one time base (estimator/io/logs.py).

- The same flight written as Parquet, as a MATLAB v5 struct, as a MATLAB v7.3 (HDF5) struct and
  as a PX4 ULog topic (synth/export.py) reads into the same problem, bit for bit, and estimates to
  the same numbers.
- Streams on their own clocks: a slower stream is interpolated onto the base stamps (linear
  signals exactly), a declared clock offset moves it, an own-rate column keeps only its own
  samples, a dropout is left empty (never bridged), a quaternion gives its Euler angles.
- Real logs (``../shared/data``; skipped when absent): both PX4 sample logs list every stream with
  its rate and span, the small one's logger dropout included; the Thor UAV's MATLAB file is one
  50-Hz stream, and a problem file over it reads an airborne piece into a problem.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.io
from hypothesis import given, settings
from hypothesis import strategies as st

from campaigns.benchmarks.user_files import USER_COLUMNS, write_user_files
from campaigns.cli import main
from estimator.io import load_problem
from estimator.io.errors import DataError, DataWarning
from estimator.io.logs import euler_from_quaternion, log_frame, stream_table
from estimator.solver import SolverOptions, estimate
from synth.export import write_mat, write_ulog

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data"
THOR = SHARED / "umn-thor75" / "thor_flight75.mat"
PX4 = SHARED / "px4"
CHANNELS = ["phi", "theta", "psi", "tas", "h", "alpha_zl", "alpha_zr"]


# --------------------------------------------------------------------------------------------------
# one flight, four file formats


@pytest.fixture(scope="module")
def formats(tiny_dataset, tmp_path_factory) -> dict[str, Path]:
    """The tiny campaign as a user's files: one Parquet table; one MATLAB v5 and one v7.3 struct
    ``flight`` and one ULog topic ``flight`` (synth/export.py); a problem file each, alike but for
    the path and the columns' paths (``flight.AX``). The ULog's stamps are whole microseconds, so
    ``parquet_us`` is the Parquet table with its time quantised alike (the ULog's reference)."""
    root = tmp_path_factory.mktemp("logs")
    cols = {k: USER_COLUMNS[k] for k in ("ax", "ay", "az", "p", "q", "r", *CHANNELS)}
    problem = write_user_files(tiny_dataset, root / "csv", cols, CHANNELS, "tiny as a user's files")
    frame = pd.read_csv(root / "csv" / "flight.csv")
    t_us = np.round(frame["Time"].to_numpy() * 1e6).astype(np.int64)
    text = problem.read_text()
    in_log = re.sub(r'column = "([^"]+)"', r'column = "flight.\1"', text)
    out = {}
    for fmt, name in (("parquet", "flight.parquet"), ("parquet_us", "flight.parquet"),
                      ("mat5", "flight_v5.mat"), ("mat73", "flight_v73.mat"), ("ulog", "flight.ulg")):
        d = root / fmt
        d.mkdir()
        columns = {c: frame[c].to_numpy() for c in frame.columns}
        body = in_log
        if fmt.startswith("parquet"):
            if fmt == "parquet_us":
                columns["Time"] = t_us.astype(float) * 1e-6 + 0.0  # as the reader converts us
            pd.DataFrame(columns).to_parquet(d / name)
            body = text
        elif fmt == "ulog":
            del columns["Time"]
            write_ulog(d / name, {"flight": {"timestamp": t_us, **columns}})
            body = in_log.replace('t = { column = "flight.Time", unit = "s" }',
                                  't = { column = "flight.timestamp", unit = "us" }')
        else:
            write_mat(d / name, {"flight": columns}, version="5" if fmt == "mat5" else "7.3")
        (d / "problem.toml").write_text(body.replace('path = "flight.csv"', f'path = "{name}"'))
        out[fmt] = d / "problem.toml"
    return out


def _load(path: Path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_problem(path)


def test_matlab_v5_v73_and_ulog_read_into_the_parquet_problem_bit_for_bit(formats):
    for fmt, reference in (("mat5", "parquet"), ("mat73", "parquet"), ("ulog", "parquet_us")):
        ref = _load(formats[reference])
        p = _load(formats[fmt])
        assert [m.id for m in p.maneuvers] == [m.id for m in ref.maneuvers]
        for a, b in zip(p.maneuvers, ref.maneuvers, strict=True):
            assert np.array_equal(a.t_s, b.t_s), fmt
            assert np.array_equal(a.accel_imu_mps2, b.accel_imu_mps2), fmt
            assert np.array_equal(a.omega_rps, b.omega_rps), fmt
            assert a.measurements.keys() == b.measurements.keys(), fmt
            for k in b.measurements:
                assert np.array_equal(a.measurements[k], b.measurements[k], equal_nan=True), (fmt, k)


@pytest.mark.slow
def test_a_matlab_file_estimates_to_the_parquet_numbers(formats):
    opt = SolverOptions(max_iterations=4, colored=False, diagnose=False)
    ref = estimate(_load(formats["parquet"]), opt)
    res = estimate(_load(formats["mat73"]), opt)
    scale = np.maximum(np.abs(ref.parameters.values), 1e-12)
    assert np.max(np.abs(res.parameters.values - ref.parameters.values) / scale) <= 1e-9
    assert np.allclose(res.std_crb, ref.std_crb, rtol=1e-9, equal_nan=True)


INS_COLUMNS = ("PHI", "THETA", "PSI")


def _two_streams(tiny_dataset, root: Path, ins_time, keep=None, trim_s: float = 1.0) -> Path:
    """The tiny flight as a MATLAB file of two structs on their own clocks, ``dru`` (IMU, air data)
    and ``ins`` (attitude, stamped ``ins_time(Time)``, only its rows ``keep``), and a problem file
    over it giving phi, theta and psi one delay, tau_ins; each maneuver from ``trim_s`` in."""
    cols = {k: USER_COLUMNS[k] for k in ("ax", "ay", "az", "p", "q", "r", *CHANNELS)}
    problem = write_user_files(tiny_dataset, root / "csv", cols, CHANNELS, "two clocks")
    frame = pd.read_csv(root / "csv" / "flight.csv")
    keep = np.ones(len(frame), bool) if keep is None else keep(frame["Time"].to_numpy())
    stream_of = {c: "ins" if c in INS_COLUMNS else "dru" for c in frame.columns}
    body = re.sub(r'column = "([^"]+)"', lambda m: f'column = "{stream_of[m[1]]}.{m[1]}"',
                  problem.read_text())
    body = body.replace('path = "flight.csv"', 'path = "f.mat"')
    body = re.sub(r"t_start_s = ([0-9.]+)", lambda m: f"t_start_s = {float(m[1]) + trim_s:.6f}", body)
    body += "".join(f'\n[[channel]]\nname = "{a}"\nmodel = "{a}"\ndelay = "tau_ins"\nrecorder = "ins"\n'
                    'unit = "rad"\n' for a in ("phi", "theta", "psi"))
    body += '\n[parameter.tau_ins]\nunit = "s"\nkind = "time_delay"\nbounds = [-1.0, 1.5]\n'
    d = root / "mat"
    d.mkdir()
    write_mat(d / "f.mat", {
        "dru": {c: frame[c].to_numpy() for c in frame.columns if c not in INS_COLUMNS},
        "ins": {"Time": ins_time(frame["Time"].to_numpy())[keep],
                **{c: frame[c].to_numpy()[keep] for c in INS_COLUMNS}}})
    (d / "problem.toml").write_text(body)
    return d / "problem.toml"


@pytest.mark.slow
def test_a_streams_clock_offset_is_estimated_as_its_channels_common_delay(tiny_dataset, tmp_path):
    """The INS attitude on its own clock, 0.1 s and 1 s ahead of the IMU's (the issue's range):
    declared as one delay for the stream's channels (tau_ins), the estimate moves by the offset,
    within 3 of its honest deviations."""
    tau = {}
    for offset_s in (0.0, 0.1, 1.0):
        problem = _two_streams(tiny_dataset, tmp_path / f"offset{offset_s}", lambda t, o=offset_s: t + o)
        r = estimate(_load(problem), SolverOptions(max_iterations=200))
        assert r.converged, r.message
        tau[offset_s] = (r.value("tau_ins"), r.std("tau_ins", colored=True))
    for offset_s in (0.1, 1.0):
        shift, std = tau[offset_s][0] - tau[0.0][0], tau[offset_s][1]
        assert abs(shift - offset_s) < 3.0 * std, \
            f"tau_ins moved {shift:.5f} s for a {offset_s}-s offset (+- {std:.2g} s)"


def test_a_streams_dropout_or_end_inside_a_maneuver_is_named(tiny_dataset, tmp_path):
    first = pd.read_parquet(next((tiny_dataset / "maneuvers").glob("*.parquet")))["t_s"]
    t0 = 1000.0  # write_user_files puts the first maneuver's first sample there
    gap = lambda t: ~((t > t0 + 4.0) & (t < t0 + 5.0))  # noqa: E731 - one second of the INS lost
    with pytest.raises(DataError, match=r"phi \(column 'ins.PHI'\) has no value from t = 100\d.\d+ to "
                                        r"100\d.\d+ s: in a dropout of stream 'ins' \(no samples for 1 s\)"):
        _load(_two_streams(tiny_dataset, tmp_path / "gap", lambda t: t, keep=gap))
    # its stamps 0.5 s late and the maneuvers not trimmed: the first half second has no INS sample
    with pytest.raises(DataError, match=r"has no value from t = 1000.000 to .*before stream 'ins''s first"):
        _load(_two_streams(tiny_dataset, tmp_path / "late", lambda t: t + 0.5, trim_s=0.0))
    assert len(first) > 200  # the gap lies inside the first maneuver


# --------------------------------------------------------------------------------------------------
# streams on their own clocks


def _two_clocks(path: Path, gps_offset_s: float = 0.0, gap: tuple[float, float] | None = None) -> None:
    """A MATLAB file with an IMU struct at 50 Hz and a GPS struct at 5 Hz on its own clock
    (``gps_offset_s`` behind the IMU's), both carrying a linear ramp of time."""
    t_imu = np.arange(0.0, 20.0, 0.02)
    t_gps = np.arange(0.1, 20.0, 0.2)
    if gap is not None:
        t_gps = t_gps[(t_gps < gap[0]) | (t_gps > gap[1])]
    scipy.io.savemat(path, {
        "imu": {"time": t_imu, "ax": 3.0 * t_imu, "quat": np.tile([1.0, 0.0, 0.0, 0.0], (t_imu.size, 1))},
        "gps": {"time": t_gps - gps_offset_s, "vn": 2.0 * t_gps + 1.0}})


def _cols(**more) -> dict:
    return {"t": {"column": "imu.time", "unit": "s"}, **more}


def test_a_slower_stream_is_interpolated_onto_the_base_stamps(tmp_path):
    _two_clocks(tmp_path / "f.mat")
    df = log_frame(tmp_path / "f.mat", "mat", _cols(vn={"column": "gps.vn"}), "test")
    t = df["imu.time"].to_numpy()
    t_gps = np.arange(0.1, 20.0, 0.2)
    inside = (t >= t_gps[0]) & (t <= t_gps[-1])
    assert np.allclose(df["gps.vn"][inside], 2.0 * t[inside] + 1.0, rtol=0, atol=1e-12)
    assert df["gps.vn"][~inside].isna().all(), "outside the GPS's span there is no value to give"


def test_a_declared_clock_offset_brings_the_stream_onto_the_base_clock(tmp_path):
    _two_clocks(tmp_path / "f.mat", gps_offset_s=0.5)
    cols = _cols(vn={"column": "gps.vn"})
    off = log_frame(tmp_path / "f.mat", "mat", cols, "test")
    on = log_frame(tmp_path / "f.mat", "mat", cols, "test", offsets_s={"gps": 0.5})
    t = on["imu.time"].to_numpy()
    ok = on["gps.vn"].notna().to_numpy()
    assert np.allclose(on["gps.vn"][ok], 2.0 * t[ok] + 1.0, atol=1e-12)
    shifted = off["gps.vn"].notna().to_numpy()
    # its clock reads 0.5 s behind the IMU's: without the offset each value is taken for 0.5 s
    # earlier than it was measured, the ramp 1.0 too high
    assert np.allclose(off["gps.vn"][shifted] - (2.0 * t[shifted] + 1.0), 1.0, atol=1e-12)


def test_an_own_rate_column_keeps_only_its_own_samples(tmp_path):
    _two_clocks(tmp_path / "f.mat")
    df = log_frame(tmp_path / "f.mat", "mat", _cols(vn={"column": "gps.vn", "own_rate": True}), "test")
    got = df["gps.vn"].notna().to_numpy()
    assert got.sum() == 100, "each of the 100 GPS samples at one base sample"
    t = df["imu.time"].to_numpy()[got]
    assert np.allclose(df["gps.vn"][got], 2.0 * t + 1.0, atol=1e-9)


def test_a_dropout_is_left_empty_not_bridged(tmp_path):
    _two_clocks(tmp_path / "f.mat", gap=(8.0, 11.0))
    df = log_frame(tmp_path / "f.mat", "mat", _cols(vn={"column": "gps.vn"}), "test")
    t = df["imu.time"].to_numpy()
    empty = df["gps.vn"].isna().to_numpy()
    assert empty[(t > 7.95) & (t < 11.05)].all()
    assert not empty[(t > 1.0) & (t < 7.85)].any() and not empty[(t > 11.15) & (t < 19.8)].any()


def test_a_quaternion_gives_its_euler_angles(tmp_path):
    _two_clocks(tmp_path / "f.mat")
    df = log_frame(tmp_path / "f.mat", "mat", _cols(phi={"column": "imu.quat.roll"},
                                                     psi={"column": "imu.quat.yaw"}), "test")
    assert np.all(df["imu.quat.roll"] == 0.0) and np.all(df["imu.quat.yaw"] == 0.0)
    with pytest.raises(DataError, match=r"4 components.*quat\.roll, quat\.pitch or quat\.yaw"):
        log_frame(tmp_path / "f.mat", "mat", _cols(phi={"column": "imu.quat"}), "test")


def test_heading_through_180_deg_is_interpolated_unwrapped(tmp_path):
    t_fast, t_slow = np.arange(0.0, 10.0, 0.01), np.arange(0.0, 10.0, 0.02)
    yaw = np.pi - 0.5 + 0.1 * t_slow  # crosses +180 deg at t = 5 s
    q = np.column_stack([np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)])
    scipy.io.savemat(tmp_path / "f.mat", {"imu": {"time": t_fast, "ax": t_fast},
                                          "ins": {"time": t_slow, "q": q}})
    df = log_frame(tmp_path / "f.mat", "mat", _cols(psi={"column": "ins.q.yaw"}), "test")
    t = df["imu.time"].to_numpy()
    ok = t <= t_slow[-1]
    want = np.mod(np.pi - 0.5 + 0.1 * t[ok] + np.pi, 2 * np.pi) - np.pi
    assert np.allclose(df["ins.q.yaw"][ok], want, atol=1e-9)


def test_clock_and_rate_mistakes_are_named(tmp_path):
    _two_clocks(tmp_path / "f.mat")
    with pytest.raises(DataError, match="not slower than the base"):  # a 50-Hz stream as own-rate at 5 Hz
        log_frame(tmp_path / "f.mat", "mat", {"t": {"column": "gps.time"},
                                              "ax": {"column": "imu.ax", "own_rate": True}}, "test")
    with pytest.raises(DataError, match="time base's own stream 'imu'"):
        log_frame(tmp_path / "f.mat", "mat", _cols(vn={"column": "gps.vn"}), "test", offsets_s={"imu": 0.1})
    with pytest.raises(DataError, match="quat has 4 columns"):  # optional, but the index is wrong
        log_frame(tmp_path / "f.mat", "mat", _cols(w={"column": "imu.quat[4]", "optional": True}), "test")


@settings(max_examples=60, deadline=None)
@given(st.floats(-3.1, 3.1), st.floats(-1.5, 1.5), st.floats(-3.1, 3.1))
def test_euler_angles_of_a_quaternion_are_the_ones_it_was_built_from(roll, pitch, yaw):
    cr, sr = np.cos(roll / 2), np.sin(roll / 2)
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    q = np.array([[cr * cp * cy + sr * sp * sy], [sr * cp * cy - cr * sp * sy],
                  [cr * sp * cy + sr * cp * sy], [cr * cp * sy - sr * sp * cy]])  # ZYX, scalar first
    got = [float(a[0]) for a in euler_from_quaternion(q)]
    assert np.allclose(got, [roll, pitch, yaw], atol=1e-7)


def test_a_wrong_path_is_named_with_what_the_file_has(tmp_path):
    _two_clocks(tmp_path / "f.mat")
    with pytest.raises(DataError, match=r"no stream 'gsp'; did you mean 'gps'\?.*fpr streams"):
        log_frame(tmp_path / "f.mat", "mat", _cols(vn={"column": "gsp.vn"}), "test")
    with pytest.raises(DataError, match=r"stream 'gps' has no field 'vnn'; did you mean 'vn'\?"):
        log_frame(tmp_path / "f.mat", "mat", _cols(vn={"column": "gps.vnn"}), "test")
    df = log_frame(tmp_path / "f.mat", "mat", _cols(vn={"column": "gps.vnn", "optional": True}), "test")
    assert list(df.columns) == ["imu.time"], "an optional column a log lacks is simply absent"


# --------------------------------------------------------------------------------------------------
# real logs


needs_px4 = pytest.mark.skipif(not (PX4 / "sample.ulg").is_file(), reason="../shared/data/px4 absent")
needs_thor = pytest.mark.skipif(not THOR.is_file(), reason="../shared/data/umn-thor75 absent")


@needs_px4
@pytest.mark.parametrize("name", ["sample.ulg", "sample_log_small.ulg"])
def test_both_px4_sample_logs_list_every_stream_with_its_rate_and_span(name):
    table = stream_table(PX4 / name)
    assert table["stream"].is_unique and len(table) >= 15
    sc = table.set_index("stream").loc["sensor_combined"]
    assert sc["span_s"] > 6.0 and 150.0 < sc["rate_hz"] < 260.0, sc
    timed = table[table["samples"] > 1]
    # a rate for every stream whose stamps increase; the others are counted as bad stamps (some
    # topics of sample.ulg carry one stamp for all their samples)
    assert (timed["rate_hz"].notna() | (timed["bad_stamps"] == timed["samples"] - 1)).all()
    if name == "sample_log_small.ulg":
        # its logger lost 0.16 s of the fast topics at once: a dropout in each of them
        assert sc["dropouts"] == 1 and 0.15 < sc["longest_dropout_s"] < 0.17
        assert {"sensor_accel:1", "sensor_accel:2"} <= set(table["stream"]), "multi-instance topics"


@needs_px4
def test_a_ulog_reads_onto_the_imu_time_base_with_attitude_from_its_quaternion():
    cols = {"t": {"column": "sensor_combined.timestamp", "unit": "us"},
            "ax": {"column": "sensor_combined.accelerometer_m_s2[0]"},
            "phi": {"column": "vehicle_attitude.q.roll"}, "theta": {"column": "vehicle_attitude.q.pitch"},
            "tas": {"column": "airspeed.true_airspeed_m_s", "optional": True}}
    df = log_frame(PX4 / "sample_log_small.ulg", "ulog", cols, "test", time_factor_s=1e-6)
    assert len(df) == 1298  # sensor_combined's samples
    assert np.nanmax(np.abs(df["vehicle_attitude.q.roll"])) < np.pi
    # the attitude topic shares sensor_combined's stamps here: its values, not interpolated ones
    assert df["vehicle_attitude.q.pitch"].notna().mean() > 0.95


@needs_thor
def test_the_thor_flight_is_one_50_hz_stream():
    (row,) = stream_table(THOR).itertuples()
    assert row.stream == "flight_data" and row.time_field == "time" and row.samples == 34812
    assert abs(row.rate_hz - 50.0) < 0.01 and row.dropouts == 0


@needs_thor
def test_a_problem_file_reads_an_airborne_piece_of_the_thor_flight(tmp_path):
    (tmp_path / "thor.toml").write_text(f"""
model = "uav_example"
channels = ["phi", "theta", "psi", "tas", "h", "alpha_v", "beta_v"]
positions_checked = true
[sensors]
imu = [0.0, 0.0, 0.0]
aoa_vane = [0.5, 0.0, 0.0]
sideslip_vane = [0.5, 0.0, 0.0]
[aircraft.thor]
r_cg_body_m = [0.0, 0.0, 0.0]
[columns]
t = {{ column = "flight_data.time", unit = "s" }}
ax = {{ column = "flight_data.ax", unit = "m/s^2" }}
ay = {{ column = "flight_data.ay", unit = "m/s^2" }}
az = {{ column = "flight_data.az", unit = "m/s^2" }}
p = {{ column = "flight_data.p", unit = "rad/s" }}
q = {{ column = "flight_data.q", unit = "rad/s" }}
r = {{ column = "flight_data.r", unit = "rad/s" }}
phi = {{ column = "flight_data.phi", unit = "rad" }}
theta = {{ column = "flight_data.theta", unit = "rad" }}
psi = {{ column = "flight_data.psi", unit = "rad" }}
tas = {{ column = "flight_data.ias", unit = "m/s" }}
h = {{ column = "flight_data.h", unit = "m" }}
alpha_v = {{ column = "flight_data.aoa", unit = "rad" }}
beta_v = {{ column = "flight_data.aos", unit = "rad" }}
[[files]]
path = "{THOR}"
maneuvers = [{{ id = "leg1", t_start_s = 300.0, t_end_s = 330.0 }}]
""")
    try:
        p = _load(tmp_path / "thor.toml")
    except DataError as exc:  # the model set's ranges are a jet drone's: say so, then stop here
        pytest.fail(f"the Thor flight's problem file does not read: {exc}")
    (m,) = p.maneuvers
    assert m.t_s.size == 1500 and abs(m.t_s[-1] - m.t_s[0] - 29.98) < 0.001  # 50 Hz, stamps in float32
    assert set(m.measurements) >= {"phi", "theta", "tas", "alpha_v", "beta_v"}
    assert 10.0 < np.nanmedian(m.measurements["tas"]) < 25.0, "a small UAV's airspeed"


@needs_thor
def test_the_shipped_thor_example_reads_the_flight_from_its_matlab_file():
    # docs/examples/thor75.toml: the uav model set, columns as paths, the held 1-Hz GPS fitted at its fixes
    example = Path(__file__).resolve().parents[2] / "docs" / "examples" / "thor75.toml"
    p = _load(example)
    assert [m.id for m in p.maneuvers] == [f"s{k:02d}" for k in range(6)]
    for m in p.maneuvers:
        assert m.t_s.size == 2999 and set(m.measurements) >= {"vn", "ve", "vd", "tas", "alpha_v", "beta_v"}
        fixes = np.count_nonzero(np.isfinite(m.measurements["vn"]))
        assert 55 <= fixes <= 61, f"{m.id}: {fixes} GPS fixes in 60 s, at 1 Hz"


@needs_thor
def test_the_thor_probe_from_its_raw_pressures_reads_them_as_channels():
    # docs/examples/thor75_pressures.toml: the probe's pressures as channels of the file's own,
    # its dynamic pressure a data signal; the uav set's angle channels, without a column, left out
    example = Path(__file__).resolve().parents[2] / "docs" / "examples" / "thor75_pressures.toml"
    with pytest.warns(DataWarning, match=r"\['alpha_v', 'beta_v'\] of the model set have no data"):
        p = load_problem(example)
    assert {c.name for c in p.channels} >= {"pda", "pds"}
    assert not {"alpha_v", "beta_v"} & {c.name for c in p.channels}
    m = p.maneuvers[0]
    ratio = m.measurements["pda"] / m.signals["pd"]
    assert 0.0 < np.nanmedian(ratio) < 1.0, "the AOA pressure a fraction of the dynamic pressure"


def test_fpr_streams_prints_the_table(tmp_path, capsys):
    _two_clocks(tmp_path / "f.mat")
    assert main(["streams", str(tmp_path / "f.mat")]) == 0
    out = capsys.readouterr().out
    assert "gps" in out and "imu" in out and "rate_hz" in out
    assert re.search(r"gps\s+2\s+100\s+time", out), out
