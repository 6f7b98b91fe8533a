"""The one schema helper of every TOML format (aircraft_models/schema.py) and the formats using it.

Each format keeps raising its own exception type; a misspelt key is named with its place, its close
match and the valid keys.
"""

from __future__ import annotations

import ast
import math
import sys
from pathlib import Path

import pytest
from _problem_files import SENSORS, raises, si_problem

import estimator.io.errors
from aircraft_models import DATA_DIR, load_airframe, load_fleet
from aircraft_models.schema import Key, check, close_match, did_you_mean, field_keys, unknown
from campaigns.montecarlo.scenario import ScenarioError, load_scenario, parse_scenario
from estimator.calibration import CalibrationOptions
from estimator.io import DataError, load_problem
from estimator.io.fprdataset import select_entries
from estimator.io.modelset import parse_model_set, parse_parameter
from synth.campaign import CampaignError, parse_campaign
from synth.environment import Environment
from synth.errors import ErrorConfig
from synth.instrument import channel_response
from synth.local_flow import load_local_flow_truth
from synth.maneuvers import ManeuverSpec

DEG = math.pi / 180.0


class FormatError(ValueError):
    """A format's own exception type."""


# ------------------------------------------------------------------------------------- the helper


def test_unknown_key_names_the_place_the_key_its_close_match_and_the_valid_keys():
    with pytest.raises(FormatError) as info:
        check({"id": "PV1", "fuel_kgs": 1.0}, ("id", "fuel_kg", "ballast_kg"), "fleet.toml: aircraft[0]",
              FormatError)
    assert str(info.value) == ("fleet.toml: aircraft[0]: unknown key 'fuel_kgs' (did you mean 'fuel_kg'?); "
                               "valid: id, fuel_kg, ballast_kg")


def test_unknown_key_without_a_close_match_lists_the_valid_keys_only():
    with pytest.raises(ValueError) as info:
        check({"zzz": 1}, ("id", "fuel_kg"), "f.toml")
    assert str(info.value) == "f.toml: unknown key 'zzz'; valid: id, fuel_kg"
    assert did_you_mean("zzz", ("id", "fuel_kg")) == "" and close_match("zzz", ("id",)) is None


def test_several_unknown_keys_are_named_together_each_with_its_match():
    err = unknown(["fuel_kgs", "zzz"], ("id", "fuel_kg"), "f.toml", FormatError)
    assert isinstance(err, FormatError)
    assert str(err) == "f.toml: unknown keys 'fuel_kgs' (did you mean 'fuel_kg'?), 'zzz'; valid: id, fuel_kg"


@pytest.mark.parametrize("value, expected, got", [
    ("1.5", "a number", "str"), (True, "a number", "bool"), ([1], "a number", "list"),
])
def test_a_value_of_the_wrong_type_names_the_key_what_is_expected_and_what_was_given(value, expected, got):
    with pytest.raises(FormatError) as info:
        check({"fuel_kg": value}, {"fuel_kg": Key(float)}, "f.toml", FormatError)
    msg = str(info.value)
    assert msg.startswith(f"f.toml: fuel_kg = {value!r} must be {expected}"), msg
    assert msg.endswith(f"got {got}"), msg


def test_types_whole_numbers_are_numbers_and_booleans_are_not():
    keys = {"n": Key(float), "flag": Key(bool), "name": Key(str), "t": Key(dict)}
    assert check({"n": 3, "flag": False, "name": "x", "t": {}}, keys, "f") == {
        "n": 3, "flag": False, "name": "x", "t": {}}
    with pytest.raises(ValueError, match="flag = 1 must be true or false, got int"):
        check({"flag": 1}, keys, "f")


def test_required_keys_and_defaults():
    keys = {"id": Key(str, required=True), "fuel_kg": Key(float, default=1360.0), "note": Key()}
    assert check({"id": "PV1"}, keys, "f") == {"id": "PV1", "fuel_kg": 1360.0}
    with pytest.raises(FormatError, match="f: missing key 'id'"):
        check({"fuel_kg": 1.0}, keys, "f", FormatError)
    with pytest.raises(FormatError, match=r"f: must be a table of keys \(id, fuel_kg, note\), got \[1\]"):
        check([1], keys, "f", FormatError)


def test_unit_suffixes_are_converted_to_si_under_the_declared_name():
    keys = {"value": Key(unit="rad"), "noise_rad": Key(unit="rad"), "r_cg_body_m": Key(unit="m"),
            "delay_s": Key(unit="s"), "rate_rps": Key(unit="rad/s"), "gain_rad_per_rad": Key(unit="rad/rad")}
    got = check({"value_deg": {"a": 2.0, "b": [1, 3]}, "noise_deg": 0.5, "r_cg_body_in": [10, 0.0, -12.0],
                 "delay_ms": 40, "rate_deg_s": 3.0, "gain_deg_per_deg": 0.9}, keys, "f")
    assert got == {"value": {"a": 2.0 * DEG, "b": [1 * DEG, 3 * DEG]}, "noise_rad": 0.5 * DEG,
                   "r_cg_body_m": [10 * 0.0254, 0.0, -12.0 * 0.0254], "delay_s": 40 * 1e-3,
                   "rate_rps": 3.0 * DEG, "gain_rad_per_rad": 0.9}
    assert check({"r_cg_body_ft": [1.0, 2.0, 3.0]}, keys, "f")["r_cg_body_m"] == [0.3048, 0.6096, 3 * 0.3048]
    # the SI spelling passes unchanged, whatever it holds
    same = {"value": "breakpoints", "noise_rad": 7}
    assert check(same, keys, "f") == same
    # no spelling the declaration does not make: a bare name takes no _rad, a unit-less key no suffix
    with pytest.raises(ValueError, match="unknown key 'value_rad'"):
        check({"value_rad": 1.0}, keys, "f")
    with pytest.raises(ValueError, match="unknown key 'id_deg'"):
        check({"id_deg": 1.0}, {"id": Key()}, "f")


def test_a_key_in_two_units_and_a_suffixed_key_that_is_no_number_are_errors():
    keys = {"value": Key(unit="rad")}
    with pytest.raises(FormatError, match=r"f: value given twice \(as value and value_deg\); keep one"):
        check({"value": 0.1, "value_deg": 5.0}, keys, "f", FormatError)
    with pytest.raises(FormatError, match=r"f: value_deg = 'x' must be a number"):
        check({"value_deg": [1.0, "x"]}, keys, "f", FormatError)
    with pytest.raises(FormatError, match=r"f: value_deg = True must be a number"):
        check({"value_deg": True}, keys, "f", FormatError)
    # a close match among the unit spellings too
    with pytest.raises(ValueError, match="did you mean 'value_deg'"):
        check({"value_dg": 1.0}, keys, "f")


def test_one_close_match_and_a_schema_of_the_standard_library_only():
    assert estimator.io.errors.close_match is close_match
    assert close_match("alpha_lz", ["alpha_zr", "alpha_zl"]) == "alpha_zl"
    source = Path(sys.modules[check.__module__].__file__).read_text(encoding="utf-8")
    tops = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            tops |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            tops.add((node.module or "").split(".")[0])
    assert tops <= set(sys.stdlib_module_names) | {"__future__"}, tops


# ---------------------------------------------------------------------------- every format, a typo


def test_problem_file_typo_gives_the_close_match(tmp_path):
    path = si_problem(tmp_path, extra="resample_Hz = 40.0\n")
    raises(path, str(path), "unknown key 'resample_Hz'", "did you mean 'resample_hz'", "valid: title")
    path = si_problem(tmp_path, files='[[files]]\npath = "flight.csv"\naircraft = "PV1"\n'
                      'maneuvers = [{ id = "a", t_strat_s = 1.0 }]\n')
    raises(path, "[[files]] flight.csv maneuvers[0]", "'t_strat_s'", "did you mean 't_start_s'")


def test_problem_file_cg_in_inches_is_the_cg_in_metres(tmp_path):
    metres = load_problem(si_problem(tmp_path)).maneuvers[0].r_cg_body_m
    inches = SENSORS.replace("r_cg_body_m = [0.33, 0.0, 0.13]", "r_cg_body_in = [12.992126, 0.0, 5.118110]")
    (tmp_path / "in").mkdir()
    path = si_problem(tmp_path / "in")
    path.write_text(path.read_text().replace(SENSORS, inches))
    assert load_problem(path).maneuvers[0].r_cg_body_m == pytest.approx(metres, abs=1e-7)
    path.write_text(path.read_text().replace("[aircraft.PV1]\n", "[aircraft.PV1]\nr_cg_body_m = [0, 0, 0]\n"))
    raises(path, "[aircraft.PV1]", "r_cg_body_m given twice", "keep one")


def test_model_set_typo_gives_the_close_match():
    with pytest.raises(ValueError, match=r"m\.toml: unknown key 'chanel' \(did you mean 'channel'\?\)"):
        parse_model_set({"chanel": []}, "m.toml")
    with pytest.raises(ValueError, match=r"parameter\.b: unknown key 'bounds_dg' "
                                         r"\(did you mean 'bounds_deg'\?\)"):
        parse_parameter("b", {"bounds_dg": [-1, 1]}, "m.toml: parameter.b")
    spec = parse_parameter("b", {"value_deg": 1.5, "bounds_deg": [-2, 2], "unit": "rad"}, "p")
    assert spec.value == 1.5 * DEG and spec.bounds == (-2 * DEG, 2 * DEG)


def test_dataset_select_and_calibration_option_typos_give_the_close_match():
    with pytest.raises(DataError, match=r"ds: unknown select key 'knd' "
                                        r"\(did you mean 'kind'\?\); valid: kind"):
        select_entries({"maneuvers": []}, {"knd": "shss"}, "ds")
    with pytest.raises(ValueError, match=r"unknown calibration option 'max_iteration' "
                                         r"\(did you mean 'max_iterations'\?\); valid: "):
        CalibrationOptions.from_mapping({"max_iteration": 3})


def test_campaign_file_typo_gives_the_close_match():
    raw = {"name": "x", "seed": 1, "flights": [{"mach": [0.5], "maneuvers": ["pitch_doublet"]}]}
    with pytest.raises(CampaignError, match=r"c\.toml: unknown key 'sead' \(did you mean 'seed'\?\)"):
        parse_campaign({**raw, "sead": 2}, source="c.toml")
    with pytest.raises(CampaignError, match=r"flights\[0\]: unknown key 'altitude' "
                                            r"\(did you mean 'altitude_m'\?\)"):
        parse_campaign({**raw, "flights": [{"mach": [0.5], "altitude": 5000.0}]}, source="c.toml")
    with pytest.raises(CampaignError, match=r"unknown maneuver 'pitch_dublet' "
                                            r"\(did you mean 'pitch_doublet'\?\)"):
        parse_campaign({**raw, "flights": [{"mach": [0.5], "maneuvers": ["pitch_dublet"]}]}, source="c.toml")


def test_errors_block_typo_gives_the_close_match():
    with pytest.raises(ValueError, match=r"errors: unknown key 'local_flo' \(did you mean 'local_flow'\?\)"):
        ErrorConfig.from_dict({"local_flo": True})
    with pytest.raises(ValueError, match=r"errors\.imu: unknown key 'acel_bias_mps2' "
                                         r"\(did you mean 'accel_bias_mps2'\?\)"):
        ErrorConfig.from_dict({"imu": {"acel_bias_mps2": [0, 0, 0]}})
    with pytest.raises(ValueError, match=r"errors\.sensors: unknown sensor 'vane_lefty' "
                                         r"\(did you mean 'vane_left'"):
        ErrorConfig.from_dict({"sensors": {"vane_lefty": {}}})
    with pytest.raises(ValueError, match="errors: local_flow = 1 must be true or false"):
        ErrorConfig.from_dict({"local_flow": 1})
    # the edge units, as before: _deg, _deg_s, _ms, _deg_per_deg (and a quoted number still read)
    cfg = ErrorConfig.from_dict({"sensors": {"vane_left": {"noise_deg": "0.1", "delay_ms": 40}}})
    assert cfg.sensors["vane_left"].noise_rad == float("0.1") * DEG
    assert cfg.sensors["vane_left"].delay_s == 40 * 1e-3


def test_scenario_typo_gives_the_close_match():
    raw = load_scenario("mc_20maneuvers").raw
    with pytest.raises(ScenarioError, match=r"\[draw\]: unknown key 'turbulance' "
                                            r"\(did you mean 'turbulence'\?\)"):
        parse_scenario({**raw, "draw": {"turbulance": "frozen"}}, source="s.toml")
    with pytest.raises(ScenarioError, match=r"\[estimator\]: unknown key 'chanels' "
                                            r"\(did you mean 'channels'\?\)"):
        parse_scenario({**raw, "estimator": {"chanels": ["alpha_zl"]}}, source="s.toml")
    draw = {"errors": {"imu.accel_bias_mps2": {"dist": "normal", "std": 0.1, "scop": "aircraft"}}}
    with pytest.raises(ScenarioError, match=r"imu\.accel_bias_mps2: unknown key 'scop' "
                                            r"\(did you mean 'scope'\?\)"):
        parse_scenario({**raw, "draw": draw}, source="s.toml")


@pytest.mark.parametrize("shipped, old, new, load, message", [
    ("fleet_default", "fuel_kg = 1200.0", "fuel_kgs = 1200.0", load_fleet,
     r"aircraft\[1\]: unknown key 'fuel_kgs' \(did you mean 'fuel_kg'\?\)"),
    ("fleet_default", "vane_right = -0.37", "vane_rigth = -0.37", load_fleet,
     r"aircraft\[1\]\.installation_bias_deg: unknown sensor 'vane_rigth' \(did you mean 'vane_right'\?\)"),
    ("fleet_default", "nose_sensor =", "nose_sensr =", load_fleet,
     r"configuration\[0\]: unknown key 'nose_sensr' \(did you mean 'nose_sensor'\?\)"),
    ("fleet_default", "fuel_kg = 1200.0", 'fuel_kg = "1200"', load_fleet,
     r"aircraft\[1\]: fuel_kg = '1200' must be a number"),
    ("f16_testbed", "jsbsim_model =", "jsbsim_modle =", load_airframe,
     r"f16_testbed\.toml: unknown key 'jsbsim_modle' \(did you mean 'jsbsim_model'\?\)"),
    ("local_flow_truth", "[side_probe]\nport_cant_deg", "[side_probe]\nport_cnt_deg", load_local_flow_truth,
     r"\[side_probe\]: unknown key 'port_cnt_deg' \(did you mean 'port_cant_deg'\?\)"),
    ("local_flow_truth", "[vane.upwash]\noffset_deg", "[vane.upwash]\noffset_dg", load_local_flow_truth,
     r"\[vane\.upwash\]: unknown key 'offset_dg' \(did you mean 'offset_deg'\?\)"),
])
def test_a_typo_in_a_fleet_airframe_or_local_flow_file_gives_the_close_match(
        tmp_path, shipped, old, new, load, message):
    text = (DATA_DIR / f"{shipped}.toml").read_text()
    assert old in text
    path = tmp_path / f"{shipped}.toml"
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(ValueError, match=message):
        load(path)


def test_field_keys_declares_a_dataclass_table_with_the_units_asked_for():
    from dataclasses import dataclass

    @dataclass
    class Spec:
        kind: str
        heading_rad: float = 0.0
        duration_s: float = 1.0

    keys = field_keys(Spec, required=("kind",), units=("rad",))
    assert list(keys) == ["kind", "heading_rad", "duration_s"]
    assert keys["kind"].required and not keys["heading_rad"].required
    # only the units asked for: duration_ms is no new spelling
    assert check({"kind": "x", "heading_deg": 90}, keys, "s") == {"kind": "x", "heading_rad": math.pi / 2}
    with pytest.raises(ValueError, match="unknown key 'duration_ms'"):
        check({"kind": "x", "duration_ms": 5}, keys, "s")


# ---------------------------------------- the environment, maneuver and channel names of the testbed

CAMPAIGN = {"name": "x", "seed": 1, "flights": [{"mach": [0.5], "maneuvers": ["shss"]}]}


@pytest.mark.parametrize("change, message", [
    ({"environment": {"turbulance": "light"}},
     r"c\.toml: maneuver 0 .*environment: unknown key 'turbulance' \(did you mean 'turbulence'\?\); "
     r"valid: planet, wind_ned_mps, turbulence, turbulence_seed, gust, latitude_rad, latitude_deg, "),
    ({"environment": {"wind_kts": 20}},
     r"unknown key 'wind_kts' .*; the wind is wind_ned_mps = \[north, east, down\] in m/s"),
    ({"environment": {"gust": {"amplitude_mp": 3.0}}},
     r"environment\.gust: unknown key 'amplitude_mp' \(did you mean 'amplitude_mps'\?\); "
     r"valid: amplitude_mps, direction_ned, start_s, duration_s"),
    ({"environment": {"gust": {"start_s": 3.0}}}, r"environment\.gust: missing key 'amplitude_mps'"),
    ({"environment": {"latitude_deg": 45.0, "latitude_rad": 0.5}},
     r"environment: latitude_rad given twice \(as latitude_deg and latitude_rad\)"),
    ({"flights": [{"mach": [0.5], "maneuvers": ["shss"], "maneuver": {"beta_dg": 4.0}}]},
     r"maneuver: unknown key 'beta_dg' \(did you mean 'beta_deg'\?\)"),
    ({"flights": [{"mach": [0.5], "maneuvers": ["shss"], "maneuver": {"segmnt_s": 40.0}}]},
     r"maneuver: unknown key 'segmnt_s' \(did you mean 'segment_s'\?\)"),
    ({"errors": {"aircraft": {"PV33": {}}}},
     r"c\.toml: \[errors\.aircraft\]: unknown aircraft id 'PV33' \(did you mean 'PV3'\?\); "
     r"valid: PT1, PT2, PV1, PV2, PV3$"),
])
def test_a_typo_in_a_campaign_environment_gust_or_maneuver_table_gives_the_close_match(change, message):
    with pytest.raises(CampaignError, match=message):
        parse_campaign({**CAMPAIGN, **change}, source="c.toml")


def test_maneuver_and_environment_degrees_are_read_as_before():
    spec = ManeuverSpec.from_dict({"kind": "shss", "mach": 0.6, "altitude_m": 5000, "beta_deg": -4,
                                   "heading_deg": 90})
    # a float, bit-identical to math.radians (what the hand-written check returned)
    assert type(spec.beta_rad) is float and spec.beta_rad == math.radians(-4.0)
    assert spec.heading_rad == math.radians(90.0)
    assert ManeuverSpec.from_dict(spec.to_dict()) == spec
    with pytest.raises(ValueError, match="maneuver: heading_rad given twice"):
        ManeuverSpec.from_dict({**spec.to_dict(), "heading_deg": 90})
    with pytest.raises(ValueError, match=r"unknown key 'altitude_ft' \(did you mean 'altitude_m'\?\).*"
                                         r"; the altitude is altitude_m, in metres"):
        ManeuverSpec.from_dict({"kind": "shss", "mach": 0.6, "altitude_ft": 5000})
    with pytest.raises(ValueError, match="maneuver: missing key 'mach'"):
        ManeuverSpec.from_dict({"kind": "shss", "altitude_m": 5000})
    with pytest.raises(ValueError, match="maneuver: missing key 'kind'; kind is one of pitch_doublet, "):
        ManeuverSpec.from_dict({"mach": 0.6, "altitude_m": 5000})
    with pytest.raises(TypeError, match="maneuver must be a table"):
        ManeuverSpec.from_dict([("kind", "shss")])
    env = Environment.from_dict({"latitude_deg": 45, "longitude_deg": -7.5})
    assert type(env.latitude_rad) is float and env.latitude_rad == math.radians(45.0)
    assert env.longitude_rad == math.radians(-7.5)
    with pytest.raises(TypeError, match="environment must be a table"):
        Environment.from_dict("calm")


def test_channel_response_typo_gives_the_close_match():
    with pytest.raises(ValueError, match=r"channel_response: unknown channel 'alpha_lz_rad' "
                                         r"\(did you mean 'alpha_zl_rad'\?\); valid: alpha_zl_rad, "):
        channel_response("alpha_lz_rad", 0.0, 0.0, 0.5)
