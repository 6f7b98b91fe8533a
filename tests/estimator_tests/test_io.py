"""The flight-data import: problem files, units, datasets, and a clear error for every bad input."""

from __future__ import annotations

import math
import subprocess
import sys
import textwrap
import warnings

import numpy as np
import pandas as pd
import pytest
from _problem_files import (
    DEG,
    ENG_UNITS,
    FT,
    KT,
    SENSORS,
    SI_COLUMNS,
    G,
    flight_frame,
    one_range,
    raises,
    si_problem,
    write_problem,
)

from estimator.io import (
    DataError,
    DataWarning,
    initial_condition_starts,
    load_problem,
    load_truth,
    problem_from_dataset,
)
from synth.dataset import prepare_directory, write_maneuver, write_manifest


# ---------------------------------------------------------------------------------- round trips
def test_csv_with_header_round_trip(tmp_path):
    frame = flight_frame()
    prob = load_problem(si_problem(tmp_path, frame))
    (m,) = prob.maneuvers
    assert m.id == "flight" and m.aircraft == "PV1" and m.configuration == "PV1"
    np.testing.assert_allclose(m.t_s, frame["time"])
    np.testing.assert_allclose(m.accel_imu_mps2, frame[["ax", "ay", "az"]].to_numpy())
    np.testing.assert_allclose(m.omega_rps, frame[["p", "q", "r"]].to_numpy())
    for c in ("phi", "theta", "psi", "tas", "h", "alpha_zl", "alpha_zr"):
        np.testing.assert_allclose(m.measurements[c], frame[c], err_msg=c)
    assert set(m.signals) == {"gear", "mach"}
    np.testing.assert_allclose(m.r_cg_body_m, [0.33, 0.0, 0.13])
    np.testing.assert_allclose(prob.sensors["vane_right"], [6.20, 0.45, 0.25], atol=1e-6)  # from inches
    np.testing.assert_allclose(prob.sensors["side_probe"], [6.60, 0.0, 0.05])
    np.testing.assert_allclose(prob.imu_position_body_m, [1.80, 0.10, 0.20])
    assert [c.name for c in prob.channels] == ["phi", "theta", "psi", "tas", "h", "alpha_zl", "alpha_zr"]
    # parameters of channels that are not used are not in the problem
    assert "b_sa[PV1]" not in prob.parameters and "b_l[PV1]" in prob.parameters
    assert prob.g_mps2 == G


def test_whitespace_without_header_by_index(tmp_path):
    frame = flight_frame()
    order = list(frame.columns)
    np.savetxt(tmp_path / "flight.dat", frame.to_numpy(), fmt="%.12g")
    cols = "\n".join(
        f'{canon} = {{ column = {order.index(src)}, unit = "{unit}" }}'
        for canon, src, unit in [("t", "time", "s"), ("ax", "ax", "m/s^2"), ("ay", "ay", "m/s^2"),
                                 ("az", "az", "m/s^2"), ("p", "p", "rad/s"), ("q", "q", "rad/s"),
                                 ("r", "r", "rad/s"), ("phi", "phi", "rad"), ("theta", "theta", "rad"),
                                 ("psi", "psi", "rad"), ("tas", "tas", "m/s"), ("h", "h", "m"),
                                 ("alpha_zl", "alpha_zl", "rad")])
    path = write_problem(tmp_path,
                         f'{SENSORS}[columns]\n{cols}\n[[files]]\npath = "flight.dat"\nheader = false\n')
    with pytest.warns(DataWarning, match="alpha_zr"):  # tejas channels without data are left out
        prob = load_problem(path)
    (m,) = prob.maneuvers
    np.testing.assert_allclose(m.t_s, frame["time"])
    np.testing.assert_allclose(m.measurements["alpha_zl"], frame["alpha_zl"], rtol=1e-11)
    np.testing.assert_allclose(m.omega_rps[:, 1], frame["q"], rtol=1e-10, atol=1e-14)
    assert "alpha_zr" not in {c.name for c in prob.channels}


def test_parquet_and_time_ranges(tmp_path):
    frame = flight_frame(duration_s=100.0, t0_s=0.0)
    frame.to_parquet(tmp_path / "flight.parquet")
    files = ('[[files]]\npath = "flight.parquet"\naircraft = "PV1"\nconfiguration = "PV1-NP"\n'
             'maneuvers = [{ id = "pd1", t_start_s = 10.0, t_end_s = 45.0 },\n'
             '  { id = "wut1", t_start_s = 50.0, t_end_s = 90.0, configuration = "PV1-GD",'
             ' r_cg_body_m = [0.35, 0.0, 0.13] }]\n')
    with pytest.warns(DataWarning, match="alpha_zsp"):
        prob = load_problem(write_problem(tmp_path, f"{SENSORS}{SI_COLUMNS}{files}"))
    pd1, wut1 = prob.maneuvers
    assert (pd1.id, wut1.id) == ("pd1", "wut1")
    assert pd1.t_s[0] == pytest.approx(10.0) and pd1.t_s[-1] == pytest.approx(45.0)
    assert pd1.n == 35 * 40 + 1 and wut1.n == 40 * 40 + 1
    sel = (frame["time"] >= 50.0 - 1e-9) & (frame["time"] <= 90.0 + 1e-9)
    np.testing.assert_allclose(wut1.measurements["alpha_zl"], frame.loc[sel, "alpha_zl"])
    assert (pd1.configuration, wut1.configuration) == ("PV1-NP", "PV1-GD")
    np.testing.assert_allclose(wut1.r_cg_body_m, [0.35, 0.0, 0.13])
    np.testing.assert_allclose(pd1.r_cg_body_m, [0.33, 0.0, 0.13])
    assert pd1.meta["t_start_s"] == 10.0 and pd1.meta["file"].endswith("flight.parquet")


def test_two_files_two_aircraft_per_file_columns(tmp_path):
    """Per-file column names; a sensor one aircraft lacks; its bias is held for that aircraft."""
    a = flight_frame(seed=1)
    b = flight_frame(seed=2).rename(columns={"alpha_zl": "AOA_L"}).drop(columns=["alpha_zr"])
    b["gear"] = 1.0
    a.to_csv(tmp_path / "pv1.csv", index=False)
    b.to_csv(tmp_path / "pt1.csv", index=False)
    cols = SI_COLUMNS.replace('alpha_zr = { column = "alpha_zr", unit = "rad" }',
                              'alpha_zr = { column = "alpha_zr", unit = "rad", optional = true }')
    files = ('[aircraft.PT1]\nr_cg_body_m = [0.30, 0.0, 0.12]\n'
             '[[files]]\npath = "pv1.csv"\naircraft = "PV1"\n'
             '[[files]]\npath = "pt1.csv"\naircraft = "PT1"\n'
             'columns = { alpha_zl = { column = "AOA_L", unit = "rad" } }\n')
    prob = load_problem(write_problem(tmp_path, f'channels = ["theta", "alpha_zl", "alpha_zr"]\n'
                                                f"{SENSORS}{cols}{files}"))
    pv1, pt1 = prob.maneuvers
    assert (pv1.id, pt1.id) == ("pv1", "pt1")
    np.testing.assert_allclose(pt1.measurements["alpha_zl"], b["AOA_L"])
    assert "alpha_zr" not in pt1.measurements
    np.testing.assert_allclose(pt1.r_cg_body_m, [0.30, 0.0, 0.12])
    ps = prob.parameters
    assert ps["b_r[PV1]"].free and not ps["b_r[PT1]"].free  # PT1 has no right vane data
    assert ps["b_l[PT1]"].free
    assert pt1.meta["gear_down"] and not pv1.meta["gear_down"]
    assert pv1.meta["mach_mean"] == pytest.approx(a["mach"].mean())


def test_whitespace_with_header_and_preamble(tmp_path):
    frame = flight_frame()
    text = "FLIGHT 421 DRU export\nrecorded 2024-05-01\n" + frame.to_string(index=False)
    (tmp_path / "flight.log").write_text(text)
    files = '[[files]]\npath = "flight.log"\nskip_rows = 2\n'
    path = si_problem(tmp_path, files=files)
    raises(path, "flight.log", "cannot tell the format", 'format = "csv"')
    path.write_text(path.read_text().replace("skip_rows = 2", 'skip_rows = 2\nformat = "whitespace"'))
    m = load_problem(path).maneuvers[0]
    np.testing.assert_allclose(m.measurements["tas"], frame["tas"], rtol=1e-5)
    assert m.n == len(frame)


def test_engineering_units_give_the_si_maneuver(tmp_path):
    frame = flight_frame()
    si = load_problem(si_problem(tmp_path / "", frame)).maneuvers[0]
    eng = frame.copy()
    for c, (_, f) in ENG_UNITS.items():
        eng[c] = frame[c] / f
    eng.to_csv(tmp_path / "eng.csv", index=False)
    cols = "[columns]\n" + "\n".join(
        f'{"t" if c == "time" else c} = {{ column = "{c}", unit = "{u}" }}'
        for c, (u, _) in ENG_UNITS.items())
    path = write_problem(tmp_path, f'{SENSORS}{cols}\n[[files]]\npath = "eng.csv"\n', "eng.toml")
    with pytest.warns(DataWarning):
        m = load_problem(path).maneuvers[0]
    np.testing.assert_allclose(m.t_s, si.t_s)
    np.testing.assert_allclose(m.accel_imu_mps2, si.accel_imu_mps2, rtol=1e-12)
    np.testing.assert_allclose(m.omega_rps, si.omega_rps, rtol=1e-12, atol=1e-15)
    for c in si.measurements:
        np.testing.assert_allclose(m.measurements[c], si.measurements[c], rtol=1e-12, err_msg=c)


def test_model_can_be_constructed(tmp_path):
    from estimator.model import Model

    prob = load_problem(si_problem(tmp_path))
    model = Model(prob)
    assert len(model.state_columns(0)) == 13
    # every free parameter belongs to a family some channel or the state equations use
    names = {p.name for p in prob.parameters if p.free}
    assert {"u0", "dax", "b_l", "b_r", "f1", "tau_alpha_zl"} <= names


def test_lever_arm_formulation_from_the_problem_file(tmp_path):
    from estimator.model import Model

    assert load_problem(si_problem(tmp_path)).lever_arm == "imu_point"
    prob = load_problem(si_problem(tmp_path, extra='lever_arm = "differentiated"\n'))
    assert prob.lever_arm == "differentiated" and Model(prob).lever_arm == "differentiated"
    assert Model(prob, lever_arm="imu_point").lever_arm == "imu_point"
    raises(si_problem(tmp_path, extra='lever_arm = "cg"\n'), "lever_arm", "'imu_point'", "'differentiated'")


def test_initial_conditions_from_the_first_samples(tmp_path):
    frame = flight_frame()
    prob = load_problem(si_problem(tmp_path, frame))
    ps = prob.parameters
    k = 5
    tas, alpha = frame["tas"][:k].mean(), frame["alpha_zl"][:k].mean()
    assert ps["u0[flight]"].value == pytest.approx(tas * math.cos(alpha))
    assert ps["w0[flight]"].value == pytest.approx(tas * math.sin(alpha))
    assert ps["v0[flight]"].value == pytest.approx(0.0)
    assert ps["theta0[flight]"].value == pytest.approx(frame["theta"][:k].mean())
    assert ps["psi0[flight]"].value == pytest.approx(frame["psi"][:k].mean())
    assert ps["h0[flight]"].value == pytest.approx(frame["h"][:k].mean())
    assert not ps["h0[flight]"].free and ps["u0[flight]"].free
    starts = initial_condition_starts(prob.maneuvers[0], n_avg=1)
    assert starts["phi0"] == pytest.approx(frame["phi"][0])


def test_parameter_overrides_merge_and_user_start_values_win(tmp_path):
    extra = ""
    body = ('[parameter.b_l]\nfree = false\nvalue_deg = 0.5\n'
            '[parameter.u0]\nvalues = { flight = 151.0 }\n'
            '[parameter.tau_alpha_zl]\nbounds = [-0.1, 0.1]\n')
    path = si_problem(tmp_path, files='[[files]]\npath = "flight.csv"\n' + body, extra=extra)
    ps = load_problem(path).parameters
    assert not ps["b_l[PV1]"].free and ps["b_l[PV1]"].value == pytest.approx(0.5 * DEG)
    assert ps["b_l[PV1]"].kind == "bias" and ps["b_l[PV1]"].scope == "aircraft"  # kept from the model set
    assert ps["u0[flight]"].value == 151.0
    assert ps["tau_alpha_zl"].bounds == (-0.1, 0.1)


def test_psi_wrap_is_unwrapped(tmp_path):
    frame = flight_frame()
    frame["psi"] = np.angle(np.exp(1j * (3.0 + 0.01 * (frame["time"] - 100.0))))  # crosses +-pi
    m = load_problem(si_problem(tmp_path, frame)).maneuvers[0]
    assert np.max(np.abs(np.diff(m.measurements["psi"]))) < 0.01


# ------------------------------------------------------------------------------------ datasets
def write_dataset(directory, n_maneuvers=3, with_boom=False):
    """A tiny dataset written by synth/dataset.py's own writers (manifest.json + maneuvers/*.parquet)."""
    prepare_directory(directory)
    entries = []
    for i in range(n_maneuvers):
        f = flight_frame(duration_s=10.0, t0_s=0.0, seed=i)
        mach = 0.4 + 0.1 * i
        tas = f["tas"] / 150.0 * 300.0 * mach
        df = pd.DataFrame({
            "t_s": f["time"], "ax_imu_mps2": f["ax"], "ay_imu_mps2": f["ay"], "az_imu_mps2": f["az"],
            "p_rps": f["p"], "q_rps": f["q"], "r_rps": f["r"], "phi_rad": f["phi"],
            "theta_rad": f["theta"], "psi_rad": f["psi"], "vn_mps": tas, "tas_mps": tas,
            "h_baro_m": f["h"], "mach": tas / 300.0, "gear_down": np.zeros(len(f), bool),
            "alpha_zl_rad": f["alpha_zl"], "alpha_zr_rad": f["alpha_zr"],
            "alpha_zsp_rad": f["alpha_zl"], "beta_zsp_rad": 0.01 * f["phi"],
            **({"alpha_zb_rad": f["alpha_zl"]} if with_boom and i == 0
               else {"beta_znp_rad": 0.01 * f["phi"]}),
            "true_alpha_cg_rad": f["alpha_zl"] - 0.01, "true_tas_mps": f["tas"] + 1.0,
        })
        entry = {"id": f"m{i:04d}", "file": f"maneuvers/m{i:04d}.parquet", "kind": "pitch_doublet",
                 "configuration": "PV1-NP" if i < 2 else "PT1-NP", "aircraft": "PV1" if i < 2 else "PT1",
                 "mach_mean": mach, "gear_down": False, "r_cg_body_m_mean": [0.33, 0.0, 0.13 + 0.01 * i],
                 "injected": {"imu.accel_bias_mps2": [0.1, 0.0, -0.05]}}
        write_maneuver(directory / entry["file"], df, entry)
        entries.append(entry)
    positions = {"imu": [1.8, 0.1, 0.2], "vane_left": [6.2, -0.45, 0.25], "vane_right": [6.2, 0.45, 0.25],
                 "side_probe_left": [6.6, -0.52, 0.05], "side_probe_right": [6.6, 0.52, 0.05],
                 "nose_probe": [8.3, 0.0, 0.22], "boom_alpha_vane": [9.4, 0.0, 0.22]}
    manifest = {"format": "fpr-dataset", "format_version": 1, "maneuvers": entries,
                "airframe": {"positions_body_m": positions}}
    write_manifest(directory, manifest)
    return directory


def test_dataset_through_a_problem_file(tmp_path):
    write_dataset(tmp_path / "ds")
    path = write_problem(
        tmp_path, '[data]\ndataset = "ds"\nselect = { mach_min = 0.45, aircraft = ["PV1", "PT1"] }\n')
    with pytest.warns(DataWarning, match="alpha_zb"):  # no boom in this dataset
        prob = load_problem(path)
    assert [m.id for m in prob.maneuvers] == ["m0001", "m0002"]
    m1, m2 = prob.maneuvers
    assert (m2.aircraft, m2.configuration) == ("PT1", "PT1-NP")
    np.testing.assert_allclose(m2.r_cg_body_m, [0.33, 0.0, 0.15])
    assert set(m1.measurements) == {"phi", "theta", "psi", "tas", "h", "alpha_zl", "alpha_zr",
                                    "alpha_zsp", "beta_zsp", "beta_znp"}
    assert set(m1.signals) == {"gear", "mach"}
    assert not any(k.startswith("true") for k in (*m1.measurements, *m1.signals))
    np.testing.assert_allclose(prob.sensors["side_probe"], [6.6, 0.0, 0.05])
    assert m1.meta["injected"]["imu.accel_bias_mps2"] == [0.1, 0.0, -0.05]
    truth = load_truth(prob, "m0002")
    assert list(truth.columns) == ["t_s", "true_alpha_cg_rad", "true_tas_mps"]
    np.testing.assert_allclose(truth["t_s"], m2.t_s)
    pd.testing.assert_frame_equal(truth, load_truth(tmp_path / "ds", "m0002"))


def test_problem_from_dataset_api_and_instances_without_data(tmp_path):
    write_dataset(tmp_path / "ds", with_boom=True)
    with pytest.warns(DataWarning, match="beta_zbu"):
        prob = problem_from_dataset(tmp_path / "ds", select={"kind": "pitch_doublet"},
                                    overrides={"b_r": {"free": False}})
    ps = prob.parameters
    assert [m.id for m in prob.maneuvers] == ["m0000", "m0001", "m0002"]
    assert "b_ba[PV1]" in ps and ps["b_ba[PV1]"].free   # PV1's m0000 has the boom vane
    assert not ps["b_ba[PT1]"].free                      # PT1 never flew the boom: nothing to fit
    assert not ps["b_r[PV1]"].free
    from estimator.model import Model

    Model(prob)


def test_dataset_selection_errors(tmp_path):
    write_dataset(tmp_path / "ds")
    with pytest.raises(DataError, match="kind.*matches nothing.*pitch_doublet"):
        problem_from_dataset(tmp_path / "ds", select={"kind": ["shss"]})
    with pytest.raises(DataError, match="leaves no maneuvers"):
        problem_from_dataset(tmp_path / "ds", select={"mach_min": 0.9})
    with pytest.raises(DataError, match="unknown select key 'speed'"):
        problem_from_dataset(tmp_path / "ds", select={"speed": 1})
    with pytest.raises(DataError, match="came from .* not from an fpr dataset"):
        load_truth(load_problem(si_problem(tmp_path)), "flight")


# ----------------------------------------------------------------------------- bad input errors
def test_nan_inside_a_maneuver(tmp_path):
    frame = flight_frame()
    frame.loc[400, "alpha_zl"] = np.nan
    raises(si_problem(tmp_path, frame), "flight.csv", "maneuver flight", "alpha_zl (column 'alpha_zl')",
           "t = 110.000 s", "data row 400", "missing value")


def test_nan_outside_the_maneuver_range_is_fine(tmp_path):
    frame = flight_frame()
    frame.loc[10, "alpha_zl"] = np.nan
    prob = load_problem(si_problem(tmp_path, frame, files=one_range("a", 101.0, 150.0)))
    assert prob.maneuvers[0].t_s[0] == pytest.approx(101.0)


def test_non_numeric_cell(tmp_path):
    frame = flight_frame().astype({"tas": object})
    frame.loc[123, "tas"] = "N/A?"
    raises(si_problem(tmp_path, frame), "flight.csv", "tas (column 'tas')", "non-numeric value 'N/A?'",
           "t = 103.075 s")


def test_gap(tmp_path):
    frame = flight_frame().drop(index=range(800, 804))
    raises(si_problem(tmp_path, frame), "flight.csv", "maneuver flight", "gap", "t = 119.975 s",
           "120.100 s", "split the maneuver")


@pytest.mark.parametrize("kind", ["duplicate", "backwards"])
def test_time_not_increasing(tmp_path, kind):
    frame = flight_frame()
    if kind == "duplicate":
        frame.loc[500, "time"] = frame.loc[499, "time"]
        raises(si_problem(tmp_path, frame), "flight.csv", "t (column 'time')", "duplicated", "t = 112.475 s",
               "data row 500", "sort the file")
    else:
        frame.loc[500, "time"] = 50.0
        raises(si_problem(tmp_path, frame), "flight.csv", "goes back to 50", "data row 500")


def test_missing_column_lists_what_the_file_has(tmp_path):
    frame = flight_frame().drop(columns=["alpha_zr"])
    raises(si_problem(tmp_path, frame), "flight.csv", "no column 'alpha_zr'", "alpha_zr", "'alpha_zl'",
           "'gear'")


def test_optional_column_may_be_missing(tmp_path):
    frame = flight_frame().drop(columns=["alpha_zr"])
    frame.to_csv(tmp_path / "flight.csv", index=False)
    cols = SI_COLUMNS.replace('alpha_zr = { column = "alpha_zr", unit = "rad" }',
                              'alpha_zr = { column = "alpha_zr", unit = "rad", optional = true }')
    path = write_problem(tmp_path,
                         f'channels = ["phi", "alpha_zl"]\n{SENSORS}{cols}[[files]]\npath = "flight.csv"\n')
    prob = load_problem(path)
    assert [c.name for c in prob.channels] == ["phi", "alpha_zl"]
    assert "alpha_zr" not in prob.maneuvers[0].measurements


def test_missing_required_input(tmp_path):
    path = si_problem(tmp_path)
    path.write_text(path.read_text().replace('q = { column = "q", unit = "rad/s" }\n', ""))
    raises(path, "flight.csv", "'q'", "required input", "[columns]")


def test_listed_channel_without_data(tmp_path):
    path = si_problem(tmp_path)
    path.write_text(path.read_text().replace('"alpha_zr"]', '"alpha_zr", "beta_znp"]'))
    raises(path, "problem.toml", "beta_znp", "no maneuver has data")


def test_unknown_channel_and_unknown_unit(tmp_path):
    path = si_problem(tmp_path)
    path.write_text(path.read_text().replace('"alpha_zr"]', '"alpha_zz"]'))
    raises(path, "alpha_zz", "not in the model set", "alpha_zl")
    path = si_problem(tmp_path)
    path.write_text(path.read_text().replace('unit = "m/s" }', 'unit = "knots" }'))
    raises(path, "tas (column 'tas')", "unknown unit 'knots'", "kt", "km/h")
    path = si_problem(tmp_path)
    path.write_text(path.read_text().replace('unit = "m/s" }', 'unit = "rad" }'))
    raises(path, "tas (column 'tas')", "'rad' (angle)", "speed", "'kt'")


@pytest.mark.parametrize("column, unit, factor, suggestion, fragment", [
    ("phi", "rad", 1 / DEG, "deg", "largest |value|"),
    ("alpha_zl", "rad", 1 / DEG, "deg", "largest |value|"),
    ("q", "rad/s", 1 / DEG, "deg/s", "largest |value|"),
    ("h", "m", 1 / FT, "ft", "median"),
    ("tas", "m/s", 1 / KT, "kt", "Mach"),
])
def test_implausible_units(tmp_path, column, unit, factor, suggestion, fragment):
    frame = flight_frame()
    frame[column] = frame[column] * factor
    if column == "q":
        frame[column] *= 10.0  # 0.8 rad/s in deg/s: 46 (an 0.08 rad/s peak would look fine)
    if column == "h":
        frame[column] += 4000.0 / FT  # 10 000 m in ft is not an altitude in m; 6000 m in ft would be
    msg = raises(si_problem(tmp_path, frame), "flight.csv", f"{column} (column '{column}')",
                 f"declared in '{unit}'", fragment, f'set unit = "{suggestion}"', "maneuver flight")
    if fragment == "largest |value|":
        assert " at t = " in msg and "data row" in msg


def test_acceleration_in_g_declared_as_mps2_and_vice_versa(tmp_path):
    frame = flight_frame()
    for c in ("ax", "ay", "az"):
        frame[c] = frame[c] / G
    raises(si_problem(tmp_path, frame), "flight.csv", "IMU specific force", "ax (column 'ax')",
           "mean magnitude", 'set unit = "g"')
    frame = flight_frame()
    path = si_problem(tmp_path, frame)
    path.write_text(path.read_text().replace('unit = "m/s^2"', 'unit = "g"'))
    raises(path, "IMU specific force", "declared in 'g'", 'set unit = "m/s^2"')


def test_clean_data_pass_the_euler_rate_check():
    from estimator.io.consistency import euler_slopes

    f = flight_frame()
    slopes = euler_slopes({c: f[c].to_numpy() for c in ("p", "q", "r", "phi", "theta", "psi")},
                          f["time"].to_numpy())
    assert set(slopes) == {"phi", "theta"}  # psi: 0.002 rad/s is too little to tell
    assert all(abs(v - 1.0) < 0.02 for v in slopes.values()), slopes


def test_small_angle_in_deg_declared_rad(tmp_path):
    """1.1 deg of pitch read as 1.1 rad passes the range check; the Euler kinematics catch it."""
    frame = flight_frame(theta_amp_rad=0.02, theta_w_rps=2.0)
    frame["theta"] = (frame["theta"] - 0.06) / DEG
    raises(si_problem(tmp_path, frame), "flight.csv", "maneuver flight", "Euler angles disagree",
           "theta (column 'theta')", "changes 57", "declared in 'rad' but looks like deg")


def test_rates_in_deg_per_s_declared_rad_per_s(tmp_path):
    frame = flight_frame(phi_amp_rad=0.05, theta_amp_rad=0.02, theta_w_rps=1.5)
    for c in ("p", "q", "r"):
        frame[c] = frame[c] / DEG
    assert frame[["p", "q", "r"]].abs().max().max() < 6.0  # the range check cannot see it
    raises(si_problem(tmp_path, frame), "flight.csv", "Euler angles disagree", "p (column 'p')",
           "body rates are likely in the wrong unit", "look like deg/s")


def test_time_in_ms_declared_as_s(tmp_path):
    frame = flight_frame()
    frame["time"] *= 1000.0
    raises(si_problem(tmp_path, frame), "flight.csv", "t (column 'time')", "median time step",
           'set unit = "ms"')


def test_range_outside_the_file(tmp_path):
    raises(si_problem(tmp_path, files=one_range("late", 140.0, 200.0)), "flight.csv", "maneuver late",
           "140.000 to 200.000 s",
           "outside the file's time span", "100.000 to 160.000 s")


def test_short_maneuver(tmp_path):
    raises(si_problem(tmp_path, files=one_range("blip", 110.0, 113.0)), "flight.csv", "maneuver blip",
           "t = 110.000 to 113.000 s",
           "too short", "13 free per-maneuver parameters", "121 samples")


def test_non_uniform_sampling_needs_resample_hz(tmp_path):
    frame = flight_frame()
    rng = np.random.default_rng(1)
    frame["time"] = frame["time"] + rng.uniform(-0.005, 0.005, len(frame))  # 20 % of a step: no grid
    frame["psi"] = 1.0 + 0.002 * (frame["time"] - 100.0)
    raises(si_problem(tmp_path, frame), "flight.csv", "maneuver flight", "non-uniform sampling",
           "resample_hz = 40")
    prob = load_problem(si_problem(tmp_path, frame, extra="resample_hz = 40.0\n"))
    m = prob.maneuvers[0]
    np.testing.assert_allclose(np.diff(m.t_s), 1 / 40.0, rtol=1e-9)
    # linear interpolation of a linear signal (psi) is exact
    np.testing.assert_allclose(m.measurements["psi"], 1.0 + 0.002 * (m.t_s - 100.0), atol=1e-12)


def test_resample_hz_per_file_and_downsampling_warning(tmp_path):
    files = '[[files]]\npath = "flight.csv"\nresample_hz = 10.0\n'
    with pytest.warns(DataWarning, match="anti-aliasing"):
        m = load_problem(si_problem(tmp_path, files=files)).maneuvers[0]
    assert m.dt_s == pytest.approx(0.1)


def test_duplicate_ids_and_missing_sensor(tmp_path):
    files = ('[[files]]\npath = "flight.csv"\nmaneuvers = [{ id = "a", t_start_s = 100.0, t_end_s = 120.0 },'
             ' { id = "a", t_start_s = 130.0, t_end_s = 150.0 }]\n')
    raises(si_problem(tmp_path, files=files), "maneuver id 'a' is used twice")
    path = si_problem(tmp_path)
    path.write_text(path.read_text().replace("vane_left = [6.20, -0.45, 0.25]\n", ""))
    raises(path, "problem.toml", "alpha_zl", "vane_left", "[sensors]")


def test_unknown_keys_and_missing_data_file(tmp_path):
    path = si_problem(tmp_path)
    path.write_text(path.read_text().replace('aircraft = "PV1"', 'aircraft = "PV1"\nheadr = true'))
    raises(path, "[[files]]", "unknown key 'headr'", "did you mean 'header'")
    path = si_problem(tmp_path)
    path.write_text(path.read_text().replace('path = "flight.csv"', 'path = "nope.csv"'))
    raises(path, "nope.csv", "no such data file")


def test_data_signal_used_by_a_model_must_exist(tmp_path):
    chan = ('[[channel]]\nname = "alpha_zl"\nsensor = "vane_left"\nmodel = "alpha_s + k_gear * gear + b_l"\n'
            '[parameter.k_gear]\nunit = "rad"\n')
    path = si_problem(tmp_path, files='[[files]]\npath = "flight.csv"\n' + chan)
    prob = load_problem(path)
    assert "k_gear" in prob.parameters
    path.write_text(path.read_text().replace('gear = { column = "gear", unit = "1" }\n', ""))
    raises(path, "flight.csv", "maneuver flight", "channel alpha_zl", "'gear'", "[columns]")


def test_unused_user_parameter_warns(tmp_path):
    path = si_problem(tmp_path, files='[[files]]\npath = "flight.csv"\n[parameter.b_n]\nfree = false\n')
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        prob = load_problem(path)
    assert any(issubclass(w.category, DataWarning) and "b_n" in str(w.message) for w in caught)
    assert "b_n[PV1]" not in prob.parameters


# ---------------------------------------------------------------------------------- documentation
def test_documented_problem_file_example_works(tmp_path):
    """The schema example of estimator.io's docstring (copied into the README) loads as documented."""
    import estimator.io

    doc = estimator.io.__doc__
    block = doc.split("from the aircraft's reference point::\n")[1].split("\nInstead of")[0]
    (tmp_path / "problem.toml").write_text(textwrap.dedent(block))
    f = flight_frame(duration_s=400.0, t0_s=0.0)
    eng = pd.DataFrame({
        "Time": f["time"], "AX": f["ax"] / G, "AY": f["ay"] / G, "AZ": f["az"] / G,
        "P": f["p"] / DEG, "Q": f["q"] / DEG, "R": f["r"] / DEG, "SPARE": 0.0,
        "PHI": f["phi"] / DEG, "THETA": f["theta"] / DEG, "PSI": np.mod(f["psi"] / DEG, 360.0),
        "TAS": f["tas"] / KT, "HP": f["h"] / FT, "AOA_R": f["alpha_zr"] / DEG, "GEAR": f["gear"],
        "MACH": f["mach"], "AOA_L": f["alpha_zl"] / DEG,
        # a GPS height at a quarter of the file's rate, empty between its samples (own_rate)
        "GPS_ALT": np.where(np.arange(len(f)) % 4 == 0, f["h"] / FT, np.nan),
    })
    eng.to_csv(tmp_path / "flight421.csv", index=False)
    with pytest.warns(DataWarning, match="b_5h"):  # declared for the example channel, which is not listed
        prob = load_problem(tmp_path / "problem.toml")
    pd1, wut1 = prob.maneuvers
    assert (pd1.id, wut1.id, pd1.aircraft, pd1.configuration) == ("pd1", "wut1", "PV1", "PV1-NP")
    assert pd1.t_s[0] == pytest.approx(120.0) and wut1.t_s[-1] == pytest.approx(340.0)
    sel = (f["time"] >= 120.0 - 1e-9) & (f["time"] <= 155.0 + 1e-9)
    np.testing.assert_allclose(pd1.measurements["alpha_zl"], f.loc[sel, "alpha_zl"], rtol=1e-9)
    gps = pd1.measurements["h_dgps"]
    assert np.array_equal(np.isfinite(gps), (np.flatnonzero(sel) % 4) == 0)
    np.testing.assert_allclose(gps[np.isfinite(gps)], f.loc[sel, "h"].to_numpy()[np.isfinite(gps)],
                               rtol=1e-9)
    np.testing.assert_allclose(pd1.measurements["tas"], f.loc[sel, "tas"], rtol=1e-9)
    assert prob.parameters["u0[pd1]"].value == 152.0
    assert prob.parameters["b_l[PV1]"].bounds == pytest.approx((-3 * DEG, 3 * DEG))
    # the GPS height left out of the fitted channels: its empty cells are no error, it is not read
    text = (tmp_path / "problem.toml").read_text()
    (tmp_path / "problem.toml").write_text(text.replace('"h", "h_dgps", "alpha_zl"', '"h", "alpha_zl"'))
    with pytest.warns(DataWarning, match="b_5h"):
        pd1, _ = load_problem(tmp_path / "problem.toml").maneuvers
    assert "h_dgps" not in pd1.measurements and "h_dgps" not in pd1.signals
    # the same GPS height held between its samples (each repeated for 4 rows, no empty cells), as
    # a recorder writing everything at one rate does: the same samples, fitted at the same rows
    (tmp_path / "problem.toml").write_text(text)
    eng["GPS_ALT"] = eng["GPS_ALT"].ffill()
    eng.to_csv(tmp_path / "flight421.csv", index=False)
    with pytest.warns(DataWarning, match="b_5h"):
        held, _ = load_problem(tmp_path / "problem.toml").maneuvers
    assert np.array_equal(held.measurements["h_dgps"], gps, equal_nan=True)


def test_only_a_held_own_rate_column_is_cut_to_its_changes():
    from estimator.io.assemble import held_samples

    held = np.repeat(np.arange(10.0), 5)
    held[-1] = np.nan  # an empty last row does not hide the hold
    assert np.flatnonzero(np.isfinite(held_samples(held))).tolist() == list(range(0, 50, 5))
    sparse = np.where(np.arange(40) % 4 == 0, np.arange(40.0), np.nan)  # empty between its samples
    assert np.array_equal(held_samples(sparse), sparse, equal_nan=True)
    rng = np.random.default_rng(3)
    quantised = np.round(np.cumsum(rng.normal(0, 0.3, 400)))  # full rate, repeats now and then
    assert np.array_equal(held_samples(quantised), quantised)


def test_estimator_io_imports_neither_synth_nor_jsbsim():
    code = ("import sys, estimator.io, estimator.problem; "
            "print([m for m in sys.modules if m.split('.')[0] in ('synth', 'jsbsim')])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
