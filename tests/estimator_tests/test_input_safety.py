"""Real files come in without surprises (issue 11): headers, recorder time stamps, slow channels,
spikes, name typos, a problem without Mach, and --help that points only at what exists.

Each test builds its files in tmp_path with the helpers of test_io.py.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from _problem_files import (
    DEG,
    SENSORS,
    SI_COLUMNS,
    flight_frame,
    one_range,
    raises,
    si_problem,
    write_problem,
)

from estimator.io import DataWarning, load_problem

ORDER = list(flight_frame().columns)


def index_columns(names=("time", "ax", "ay", "az", "p", "q", "r", "phi", "theta", "psi", "tas", "h",
                         "alpha_zl")) -> str:
    """[columns] by 0-based index into a file written in flight_frame's column order."""
    units = {"time": "s", "ax": "m/s^2", "ay": "m/s^2", "az": "m/s^2", "p": "rad/s", "q": "rad/s",
             "r": "rad/s", "tas": "m/s", "h": "m"}
    return "[columns]\n" + "\n".join(
        f'{"t" if c == "time" else c} = {{ column = {ORDER.index(c)}, unit = "{units.get(c, "rad")}" }}'
        for c in names) + "\n"


def load_quietly(path):
    """load_problem, and the DataWarnings it gave (text)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DataWarning)
        prob = load_problem(path)
    return prob, [str(w.message) for w in caught if issubclass(w.category, DataWarning)]


# ----------------------------------------------------------------------------------- a. headers
@pytest.mark.parametrize("fmt", ["csv", "whitespace"])
def test_headerless_file_read_with_default_header_keeps_its_first_row(tmp_path, fmt):
    """Columns by index, header = true by default, a file without a header: the first line is
    data (it parses as numbers), read as such and said so; no row is lost."""
    frame = flight_frame()
    name = "flight.csv" if fmt == "csv" else "flight.dat"
    frame.to_csv(tmp_path / name, index=False, header=False, sep="," if fmt == "csv" else " ")
    path = write_problem(tmp_path, f'channels = ["theta", "alpha_zl"]\n{SENSORS}{index_columns()}'
                                   f'[[files]]\npath = "{name}"\n')
    prob, warned = load_quietly(path)
    (m,) = prob.maneuvers
    assert m.n == len(frame)
    assert m.t_s[0] == pytest.approx(frame["time"].iloc[0])
    np.testing.assert_allclose(m.measurements["alpha_zl"], frame["alpha_zl"], rtol=1e-12)
    assert any(name in w and "header = false" in w and "numbers" in w for w in warned), warned


def test_headerless_file_with_columns_by_name_is_an_error_naming_the_fix(tmp_path):
    frame = flight_frame()
    frame.to_csv(tmp_path / "flight.csv", index=False, header=False)
    path = si_problem(tmp_path, frame)
    frame.to_csv(tmp_path / "flight.csv", index=False, header=False)  # si_problem wrote a header
    msg = raises(path, "flight.csv", "first line", "numbers", "header = false", "0-based column index")
    assert "cannot read" not in msg


def test_file_with_a_header_read_with_header_false_is_an_error_naming_the_fix(tmp_path):
    frame = flight_frame()
    frame.to_csv(tmp_path / "flight.csv", index=False)
    path = write_problem(tmp_path, f'channels = ["theta", "alpha_zl"]\n{SENSORS}{index_columns()}'
                                   '[[files]]\npath = "flight.csv"\nheader = false\n')
    raises(path, "flight.csv", "first line", "column names", "header = true")


def test_text_in_another_encoding_names_the_encoding_key(tmp_path):
    frame = flight_frame().rename(columns={"phi": "phi°"})
    frame.to_csv(tmp_path / "flight.csv", index=False, encoding="latin-1")
    path = si_problem(tmp_path, frame)
    frame.to_csv(tmp_path / "flight.csv", index=False, encoding="latin-1")
    path.write_text(path.read_text().replace('column = "phi"', 'column = "phi°"'))
    raises(path, "flight.csv", "UTF-8", 'encoding = "latin-1"')
    text = path.read_text().replace('path = "flight.csv"', 'path = "flight.csv"\nencoding = "latin-1"')
    path.write_text(text)
    m = load_problem(path).maneuvers[0]
    np.testing.assert_allclose(m.measurements["phi"], frame["phi°"])


def test_header_must_be_a_boolean(tmp_path):
    path = si_problem(tmp_path, files='[[files]]\npath = "flight.csv"\nheader = "false"\n')
    raises(path, "flight.csv", "header = 'false'", "true or false")


def test_two_columns_of_the_mapped_name_are_an_error(tmp_path):
    frame = flight_frame()
    frame["alpha_zl_counts"] = (frame["alpha_zl"] * 1e4).round()
    path = si_problem(tmp_path, frame)
    text = (tmp_path / "flight.csv").read_text().replace("alpha_zl_counts", "alpha_zl", 1)
    (tmp_path / "flight.csv").write_text(text)
    raises(path, "flight.csv", "2 columns are named 'alpha_zl'", "[12, 16]", "column = 12")


def test_title_lines_without_skip_rows_name_skip_rows(tmp_path):
    frame = flight_frame()
    path = si_problem(tmp_path, frame)
    title = "FLIGHT 421\nexported 2024-05-01\nDRU 3\n"
    (tmp_path / "flight.csv").write_text(title + frame.to_csv(index=False))
    raises(path, "flight.csv", "skip_rows = 3")


def test_units_row_under_the_header_is_named(tmp_path):
    frame = flight_frame()
    path = si_problem(tmp_path, frame)
    lines = frame.to_csv(index=False).splitlines(keepends=True)
    units = ",".join(["s", "m/s^2", "m/s^2", "m/s^2", *["rad/s"] * 3, *["rad"] * 3, "m/s", "m", "rad", "rad",
                      "1", "1"]) + "\n"
    (tmp_path / "flight.csv").write_text(lines[0] + units + "".join(lines[1:]))
    raises(path, "flight.csv", "line after the header", "units row", "Remove that line")


def test_european_export_names_delimiter_and_decimal(tmp_path):
    frame = flight_frame()
    path = si_problem(tmp_path, frame)
    frame.to_csv(tmp_path / "flight.csv", index=False, sep=";", decimal=",")
    raises(path, "flight.csv", 'delimiter = ";"', 'decimal = ","')
    path.write_text(path.read_text().replace('path = "flight.csv"', 'path = "flight.csv"\ndelimiter = ";"'))
    raises(path, "flight.csv", "time", "decimal comma", 'decimal = ","')
    path.write_text(path.read_text().replace('delimiter = ";"', 'delimiter = ";"\ndecimal = ","'))
    m = load_problem(path).maneuvers[0]
    np.testing.assert_allclose(m.measurements["alpha_zl"], frame["alpha_zl"])


def test_empty_file_folder_and_misspelt_path(tmp_path):
    path = si_problem(tmp_path)
    (tmp_path / "flight.csv").write_text("")
    raises(path, "flight.csv", "empty (0 bytes)")
    (tmp_path / "flight.csv").unlink()
    (tmp_path / "flight.csv").mkdir()
    raises(path, "flight.csv", "is a directory", "give the file's path")
    (tmp_path / "flight.csv").rmdir()
    flight_frame().to_csv(tmp_path / "flight421.csv", index=False)
    path.write_text(path.read_text().replace('path = "flight.csv"', 'path = "flight42.csv"'))
    raises(path, "flight42.csv", "no such data file", "did you mean 'flight421.csv'")


def test_unit_spellings_get_the_unit_meant(tmp_path):
    path = si_problem(tmp_path)
    path.write_text(path.read_text().replace('unit = "m/s" }', 'unit = "knots" }'))
    raises(path, "tas (column 'tas')", "unknown unit 'knots'", "did you mean 'kt'", "set unit")


def test_time_in_seconds_declared_ms_says_so(tmp_path):
    path = si_problem(tmp_path, files=one_range("pd1", 110.0, 140.0))
    path.write_text(path.read_text().replace('t = { column = "time", unit = "s" }',
                                             't = { column = "time", unit = "ms" }'))
    raises(path, "flight.csv", "maneuver pd1", "t (column 'time')", "declared in 'ms'", 'set unit = "s"')


# --------------------------------------------------------------------------- b. recorder clocks
def _stamped(frame, t_written):
    """The frame (sampled uniformly) with its time column written as a recorder would."""
    out = frame.copy()
    out["time"] = t_written
    return out


def _check_taken_as_nominal(tmp_path, frame, t_written, rate_hz, fragment):
    prob, warned = load_quietly(si_problem(tmp_path, _stamped(frame, t_written)))
    (m,) = prob.maneuvers
    assert m.n == len(frame)  # every sample kept, none interpolated away
    np.testing.assert_allclose(np.diff(m.t_s), 1.0 / rate_hz, rtol=1e-9)
    np.testing.assert_allclose(m.measurements["alpha_zl"], frame["alpha_zl"])
    assert abs(m.t_s[0] - t_written[0]) < 0.2 / rate_hz
    hit = [w for w in warned if "flight.csv" in w and fragment in w]
    assert hit, warned
    return hit[0]


def test_50hz_recorder_on_a_1024hz_clock_is_taken_as_50hz(tmp_path):
    """Stamps counted in 1/1024 s ticks: steps of 19.5 and 20.5 ms, median 19.5 ms (51.2 Hz)."""
    frame = flight_frame(duration_s=40.0)
    frame["time"] = 100.0 + np.arange(len(frame)) / 50.0
    t = np.floor(frame["time"].to_numpy() * 1024.0) / 1024.0
    msg = _check_taken_as_nominal(tmp_path, frame, t, 50.0, "nominal 50 Hz")
    assert "ms" in msg and "51.2" not in msg


def test_40hz_recorder_with_clock_jitter_written_in_ms_is_taken_as_40hz(tmp_path):
    frame = flight_frame()
    rng = np.random.default_rng(11)
    t = np.round(frame["time"].to_numpy() + rng.normal(0.0, 3e-4, len(frame)), 3)
    assert np.max(np.abs(np.diff(t) - 0.025)) > 0.01 * 0.025  # refused on the old 1 % rule
    _check_taken_as_nominal(tmp_path, frame, t, 40.0, "nominal 40 Hz")


def test_64hz_written_with_3_decimals_is_taken_as_64hz(tmp_path):
    frame = flight_frame(duration_s=30.0)
    frame["time"] = 100.0 + np.arange(len(frame)) / 64.0
    _check_taken_as_nominal(tmp_path, frame, np.round(frame["time"].to_numpy(), 3), 64.0,
                            "nominal 64 Hz")


@pytest.mark.parametrize("rate_hz", [40.0, 64.0, 80.0])
def test_time_rounded_to_2_decimals_is_taken_as_its_nominal_grid(tmp_path, rate_hz):
    """Time written to 0.01 s: at 40 Hz the stamps are up to 5 ms (20 % of a step) off the grid,
    at 64 Hz 32 %, at 80 Hz 40 % (steps of 10 and 20 ms, no gap). Every stamp is within half the
    rounding of the grid, so the grid is taken (exactly, not interpolated from the stamps), and
    the warning says the stamps were rounded."""
    frame = flight_frame(duration_s=30.0)
    exact = 100.0 + np.arange(len(frame)) / rate_hz
    frame["time"] = exact
    msg = _check_taken_as_nominal(tmp_path, frame, np.round(exact, 2), rate_hz, "rounded to 0.01 s")
    assert f"nominal {rate_hz:g} Hz grid" in msg and "more decimals" in msg
    assert "resample_hz" not in msg
    prob, _ = load_quietly(tmp_path / "problem.toml")
    np.testing.assert_allclose(prob.maneuvers[0].t_s, exact, rtol=0, atol=1e-9)


def test_jittered_time_rounded_to_2_decimals_says_to_export_more_decimals(tmp_path):
    """40 Hz stamps with 1.5 ms of jitter, written to 0.01 s: they stray beyond the rounding, but
    interpolating from stamps that may be 5 ms off (resample_hz) is no fix: more decimals are."""
    frame = flight_frame()
    rng = np.random.default_rng(3)
    t = np.round(frame["time"].to_numpy() + rng.normal(0.0, 1.5e-3, len(frame)), 2)
    assert np.all(np.diff(t) > 0)
    msg = raises(si_problem(tmp_path, _stamped(frame, t)), "flight.csv", "maneuver flight",
                 "rounded to 0.01 s", "export the time with more decimals")
    assert not msg.split("; ")[-1].startswith("Add resample_hz"), msg


def test_time_rounded_coarser_than_the_step_says_so_not_drop_rows(tmp_path):
    """40 Hz written to 0.1 s: four samples share each stamp. Dropping duplicated rows would lose
    three samples in four: the message names the rounding and more decimals."""
    frame = flight_frame()
    msg = raises(si_problem(tmp_path, _stamped(frame, np.round(frame["time"].to_numpy(), 1))), "flight.csv",
                 "rounded to 0.1 s", "more decimals")
    assert "drop duplicated rows" not in msg


def test_non_uniform_sampling_suggests_the_nominal_rate_not_the_median_step(tmp_path):
    """Steps of 22 ms (60 %) and 29.5 ms (40 %): the median says 45 Hz, the data average 40 Hz."""
    frame = flight_frame()
    rng = np.random.default_rng(5)
    steps = np.where(rng.random(len(frame) - 1) < 0.6, 0.022, 0.0295)
    t = 100.0 + np.concatenate([[0.0], np.cumsum(steps)])
    t = 100.0 + (t - 100.0) * (0.025 * (len(frame) - 1)) / (t[-1] - 100.0)  # a mean step of 25 ms
    frame = _stamped(frame, t)
    frame["psi"] = 1.0 + 0.002 * (frame["time"] - 100.0)
    msg = raises(si_problem(tmp_path, frame), "flight.csv", "maneuver flight", "non-uniform sampling",
                 "resample_hz = 40")
    assert "resample_hz = 45" not in msg


# ----------------------------------------------------------------------- c. a slower channel
GPS_COLUMNS = SI_COLUMNS + 'h_dgps = { column = "gps", unit = "m" }\n'


def test_undeclared_slow_channel_error_names_own_rate(tmp_path):
    frame = flight_frame()
    frame["gps"] = np.where(np.arange(len(frame)) % 4 == 0, frame["h"], np.nan)
    frame.to_csv(tmp_path / "flight.csv", index=False)
    path = write_problem(tmp_path, f'channels = ["theta", "h", "h_dgps"]\n{SENSORS}{GPS_COLUMNS}'
                                   '[[files]]\npath = "flight.csv"\n')
    msg = raises(path, "flight.csv", "h_dgps (column 'gps')", "every 4th row", "10 Hz",
                 "own_rate = true")
    assert "trim" not in msg
    # following the advice works
    path.write_text(path.read_text().replace('unit = "m" }\n[[', 'unit = "m", own_rate = true }\n[['))
    m = load_problem(path).maneuvers[0]
    assert np.count_nonzero(np.isfinite(m.measurements["h_dgps"])) == (len(frame) + 3) // 4


def test_slow_required_input_says_to_resample_it(tmp_path):
    """own_rate is not for the IMU: the message says so and what to do instead."""
    frame = flight_frame()
    frame.loc[frame.index % 2 == 1, "q"] = np.nan
    msg = raises(si_problem(tmp_path, frame), "flight.csv", "q (column 'q')", "every 2nd row",
                 "resample")
    assert "own_rate = true" not in msg.replace("own_rate = true is for", "")


def test_slow_channel_written_by_repeating_its_values_is_named(tmp_path):
    frame = flight_frame()
    held = frame["h"].to_numpy()[(np.arange(len(frame)) // 4) * 4]
    frame["gps"] = held
    frame.to_csv(tmp_path / "flight.csv", index=False)
    path = write_problem(tmp_path, f'channels = ["theta", "h", "h_dgps"]\n{SENSORS}{GPS_COLUMNS}'
                                   '[[files]]\npath = "flight.csv"\n')
    _, warned = load_quietly(path)
    assert any("h_dgps (column 'gps')" in w and "4 rows" in w and "own_rate = true" in w
               for w in warned), warned


# ------------------------------------------------------------------------------------- d. spikes
def test_one_sample_spike_is_named_as_a_spike_not_a_unit_error(tmp_path):
    frame = flight_frame()
    frame["alpha_zl"] = frame["alpha_zl"] / DEG
    frame.loc[400, "alpha_zl"] = 1000.0
    path = si_problem(tmp_path, frame)
    path.write_text(path.read_text().replace('alpha_zl = { column = "alpha_zl", unit = "rad" }',
                                             'alpha_zl = { column = "alpha_zl", unit = "deg" }'))
    msg = raises(path, "flight.csv", "maneuver flight", "alpha_zl (column 'alpha_zl')", "spike",
                 "1000", "t = 110.000 s", "data row 400")
    assert "mrad" not in msg and "set unit" not in msg


def test_a_few_spikes_are_listed_with_their_times(tmp_path):
    frame = flight_frame()
    for i, v in ((100, 9.0), (900, -12.0), (1500, 40.0)):
        frame.loc[i, "q"] = v  # rad/s: far beyond what an aircraft does
    msg = raises(si_problem(tmp_path, frame), "flight.csv", "q (column 'q')", "3 spike",
                 "t = 102.500 s", "t = 122.500 s", "t = 137.500 s")
    assert "set unit" not in msg


def test_a_burst_of_bad_samples_is_named_whole(tmp_path):
    frame = flight_frame()
    frame.loc[50:60, "tas"] = 5000.0  # m/s, 11 samples
    raises(si_problem(tmp_path, frame), "flight.csv", "tas (column 'tas')", "11 spike(s)",
           "5000 m/s from t = 101.250 to 101.500 s (data rows 50 to 60, 11 samples)", "median value 150")


def test_a_stuck_value_burst_is_one_item(tmp_path):
    frame = flight_frame()
    frame["alpha_zl"] = frame["alpha_zl"] / DEG
    frame.loc[400:479, "alpha_zl"] = 200.0  # a failed synchro, 2 s
    path = si_problem(tmp_path, frame)
    path.write_text(path.read_text().replace('alpha_zl = { column = "alpha_zl", unit = "rad" }',
                                             'alpha_zl = { column = "alpha_zl", unit = "deg" }'))
    msg = raises(path, "flight.csv", "80 spike(s)", "200 deg from t = 110.000 to 111.975 s",
                 "data rows 400 to 479, 80 samples", "more than a few")
    assert "set unit" not in msg


def test_imu_spike_is_caught(tmp_path):
    frame = flight_frame()
    frame.loc[700, "az"] = -1000.0 * 9.80665
    raises(si_problem(tmp_path, frame), "flight.csv", "az (column 'az')", "spike", "t = 117.500 s")


def _deg_problem(tmp_path, frame):
    """flight_frame's alpha_zl written in degrees and declared so."""
    path = si_problem(tmp_path, frame)
    path.write_text(path.read_text().replace('alpha_zl = { column = "alpha_zl", unit = "rad" }',
                                             'alpha_zl = { column = "alpha_zl", unit = "deg" }'))
    return path


@pytest.mark.parametrize("spike_deg, neighbour_deg", [(95.0, None), (100.0, 15.0), (-95.0, 15.0)])
def test_a_moderate_spike_is_a_spike_not_a_unit_error(tmp_path, spike_deg, neighbour_deg):
    """One sample just beyond what a flow angle can be (1.6 rad = 92 deg) in a column of degrees
    (2 to 6 deg): named with its time and row, no unit suggested (mrad would be wrong)."""
    frame = flight_frame()
    frame["alpha_zl"] = frame["alpha_zl"] / DEG
    if neighbour_deg is not None:
        frame.loc[[399, 401], "alpha_zl"] = neighbour_deg
    frame.loc[400, "alpha_zl"] = spike_deg
    msg = raises(_deg_problem(tmp_path, frame), "flight.csv", "maneuver flight",
                 "alpha_zl (column 'alpha_zl')", "spike",
                 f"{spike_deg:g} deg at t = 110.000 s (data row 400)",
                 "the unit is not the problem")
    assert "mrad" not in msg and "set unit" not in msg, msg


def test_a_short_excursion_out_of_range_is_named_not_taken_for_a_unit_error(tmp_path):
    """A smooth excursion to 100 deg (no jump a spike test sees) in 5 of 2401 samples: the bulk is
    plausible in deg, so the samples are named and no unit is suggested."""
    frame = flight_frame()
    frame["alpha_zl"] = frame["alpha_zl"] / DEG
    ramp = np.r_[np.linspace(5.0, 100.0, 30), np.linspace(100.0, 5.0, 30)]
    frame.loc[400:459, "alpha_zl"] = ramp
    msg = raises(_deg_problem(tmp_path, frame), "flight.csv", "alpha_zl (column 'alpha_zl')",
                 "outside what a flow angle can be", "data rows", "the unit is not the problem")
    assert "mrad" not in msg and "set unit" not in msg, msg


@pytest.mark.parametrize("scale, declared, suggestion", [(1.0 / DEG, "rad", "deg"), (1000.0, "deg", "mrad")])
def test_a_real_unit_error_with_a_spike_still_gets_the_unit_advice(tmp_path, scale, declared, suggestion):
    """A whole column in the wrong unit (degrees declared rad; mrad declared deg, a quarter of its
    samples beyond 92 "deg") keeps its unit advice, a 95-unit spike on top or not."""
    frame = flight_frame()
    frame["alpha_zl"] = frame["alpha_zl"] * scale
    frame.loc[400, "alpha_zl"] = -95.0
    path = si_problem(tmp_path, frame)
    path.write_text(path.read_text().replace('alpha_zl = { column = "alpha_zl", unit = "rad" }',
                                             f'alpha_zl = {{ column = "alpha_zl", unit = "{declared}" }}'))
    raises(path, "flight.csv", "alpha_zl (column 'alpha_zl')", f'set unit = "{suggestion}"')


def test_a_real_unit_error_still_gets_the_unit_advice(tmp_path):
    frame = flight_frame()
    frame["alpha_zl"] = frame["alpha_zl"] / DEG
    frame.loc[400, "alpha_zl"] = 1000.0  # and a spike on top
    raises(si_problem(tmp_path, frame), "flight.csv", "alpha_zl (column 'alpha_zl')", 'set unit = "deg"')


# -------------------------------------------------------------------------------------- e. typos
def test_canonical_name_typo_is_an_error_with_the_close_match(tmp_path):
    path = si_problem(tmp_path)
    path.write_text(path.read_text().replace('alpha_zl = { column', 'alpha_lz = { column'))
    raises(path, "problem.toml", "[columns]", "'alpha_lz'", "did you mean 'alpha_zl'", "beta_zsp")


def test_per_file_canonical_name_typo_is_an_error(tmp_path):
    files = '[[files]]\npath = "flight.csv"\ncolumns = { alpah_zr = { column = "alpha_zr", unit = "rad" } }\n'
    raises(si_problem(tmp_path, files=files), "flight.csv", "'alpah_zr'", "did you mean 'alpha_zr'")


def test_a_missing_column_is_never_matched_to_another_channels_column(tmp_path):
    # alpha_zr's column is gone: the nearest name left is alpha_zl's column, which following the
    # advice would feed the right vane with the left vane's data
    path = si_problem(tmp_path, frame=flight_frame().drop(columns=["alpha_zr"]))
    msg = raises(path, "flight.csv", "no column 'alpha_zr'", "alpha_zr")
    assert "did you mean 'alpha_zl'" not in msg, msg


def test_a_column_name_differing_in_case_is_offered(tmp_path):
    path = si_problem(tmp_path, frame=flight_frame().rename(columns={"alpha_zr": "ALPHA_ZR"}))
    raises(path, "no column 'alpha_zr'", "did you mean 'ALPHA_ZR'")


def test_unknown_key_suggests_the_close_match(tmp_path):
    path = si_problem(tmp_path)
    path.write_text(path.read_text().replace('aircraft = "PV1"\n', 'aircraft = "PV1"\nheadr = true\n'))
    raises(path, "[[files]]", "'headr'", "did you mean 'header'")
    path = si_problem(tmp_path)
    path.write_text(path.read_text().replace('unit = "rad" }', 'unit = "rad", own_rat = true }', 1))
    raises(path, "[columns]", "'own_rat'", "did you mean 'own_rate'")


def test_sensor_typo_is_named(tmp_path):
    path = si_problem(tmp_path)
    path.write_text(path.read_text().replace("vane_left = [", "vane_lft = ["))
    raises(path, "vane_left", "[sensors]", "'vane_lft'", "misspelling")


def test_parameter_typo_is_an_error_with_the_close_match(tmp_path):
    path = si_problem(tmp_path, files='[[files]]\npath = "flight.csv"\n[parameter.b_lx]\nfree = false\n')
    raises(path, "[parameter.b_lx]", "did you mean 'b_l'")


# ------------------------------------------------------------------------------- f. no Mach
def _fake_problem(mach_means):
    mans = [SimpleNamespace(id=f"m{i}", aircraft="A", configuration="A",
                            meta={} if mm is None else {"mach_mean": mm, "mach_min": mm - 0.01,
                                                        "mach_max": mm + 0.01})
            for i, mm in enumerate(mach_means)]
    return SimpleNamespace(maneuvers=mans, source="my_flight.toml")


def test_workflow_without_mach_says_so_and_names_single():
    from estimator.workflow import run_workflow

    with pytest.raises(ValueError) as info:
        run_workflow(_fake_problem([None] * 5))
    msg = str(info.value)
    for frag in ("my_flight.toml", "no Mach signal", "mach = { column", "--single"):
        assert frag in msg, msg
    assert "nothing to calibrate" not in msg


def test_workflow_with_too_small_bins_names_them_and_single():
    from estimator.workflow import run_workflow

    with pytest.raises(ValueError) as info:
        run_workflow(_fake_problem([0.5, 0.5, 0.7, None]))
    msg = str(info.value)
    for frag in ("Mach 0.50", "2 maneuver", "Mach 0.70", "1 maneuver", "--single", "no Mach signal"):
        assert frag in msg, msg


def test_fpr_calibrate_on_data_without_mach_names_single(tmp_path, capsys):
    from campaigns.cli import main

    path = si_problem(tmp_path)
    path.write_text(path.read_text().replace('mach = { column = "mach", unit = "1" }\n', ""))
    assert main(["calibrate", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "no Mach signal" in err and "--single" in err and "mach" in err


# ------------------------------------------------------------------------------------- h. --help
def test_calibrate_help_points_only_at_what_exists():
    from campaigns.cli import CALIBRATE_EPILOG, build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    cal = sub.choices["calibrate"]
    options = {s for a in cal._actions for s in a.option_strings}
    for flag in re.findall(r"(?<![\w-])--[a-z][a-z-]*\*?", CALIBRATE_EPILOG):
        assert flag in options, f"{flag} in `fpr calibrate --help` is not an option"
    root = Path(__file__).resolve().parents[2]
    refs = re.findall(r'(README\.md|docs/[\w-]+\.md)\s+section\s+"([^"]+)"', CALIBRATE_EPILOG)
    assert refs, "the help names the user guide's section on problem files"
    for doc, section in refs:
        headings = [h.strip() for h in re.findall(r"^#+ (.*)$", (root / doc).read_text(), flags=re.M)]
        assert any(h.startswith(section) for h in headings), f"no section {section!r} in {doc}"
    for path in re.findall(r"\b((?:estimator|campaigns|synth)/[\w/]+\.py)\b", CALIBRATE_EPILOG):
        assert (Path(__file__).resolve().parents[2] / path).is_file(), path
