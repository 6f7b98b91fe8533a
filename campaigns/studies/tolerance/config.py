"""Planning study (c), its configuration: the requirements, the swept factors and their levels, the
base scenario, and the study's points (one Monte Carlo scenario per factor and level)."""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from campaigns.montecarlo import parse_scenario
from campaigns.studies.common import set_imu_bias, typical_imu_biases_deg
from synth.errors import PROBE_SENSORS, VANE_SENSORS

#: desired 3-sigma accuracy per requirement group, deg (paper Table 2)
DESIRED_3SIGMA_DEG: Mapping[str, float] = {
    "vane AOA": 0.5, "side-probe AOA": 1.0, "side-probe AOSS": 1.0, "nose-probe AOSS": 0.5,
}
#: requirement group -> calibrated channels (the group's accuracy is its worst channel's); the
#: boom has no stated requirement and is shown for information
SENSOR_GROUPS: Mapping[str, tuple[str, ...]] = {
    "vane AOA": ("alpha_zl", "alpha_zr"),
    "side-probe AOA": ("alpha_zsp",),
    "side-probe AOSS": ("beta_zsp",),
    "nose-probe AOSS": ("beta_znp",),
    "boom AOA": ("alpha_zb",),
    "boom AOSS": ("beta_zbu", "beta_zbl"),
}
#: short column titles of the groups in the text table
SHORT_TITLE = {"vane AOA": "vane_a", "side-probe AOA": "sp_a", "side-probe AOSS": "sp_b",
          "nose-probe AOSS": "np_b", "boom AOA": "boom_a", "boom AOSS": "boom_b"}
#: a steady wind blows towards this heading (the air mass moves towards it), deg from north
WIND_TOWARDS_DEG = 120.0
Level = float | str
#: the study's code (its uncommitted changes count in the code version of its header)
STUDY_CODE = Path(__file__).parent


# ---------------------------------------------------------------------------- the factors


def _set_imu_bias_started(raw: dict, scale: Level) -> None:
    """IMU biases as :func:`~campaigns.studies.common.set_imu_bias`, and the estimator's start values
    of the per-maneuver biases at their mean (the per-maneuver spread remains to be found); ``None``:
    no change."""
    if scale is None:
        return
    set_imu_bias(raw, scale)
    s = float(scale)
    accel_mps2, gyro_deg_s = typical_imu_biases_deg()
    params = raw["estimator"].setdefault("parameters", {})
    for name, v in zip(("dax", "day", "daz"), accel_mps2, strict=True):
        params[name] = {**params.get(name, {}), "value": s * v}
    for name, v in zip(("dp", "dq", "dr"), gyro_deg_s, strict=True):
        params[name] = {**params.get(name, {}), "value_deg": s * v}


def _set_flow_delay(raw: dict, delay_ms: Level) -> None:
    if delay_ms == "typical":
        return
    sensors = raw["errors"].setdefault("sensors", {})
    for name in (*VANE_SENSORS, *PROBE_SENSORS):
        sensors.setdefault(name, {})["delay_ms"] = float(delay_ms)


def _set_ins_delay(raw: dict, delay_ms: Level) -> None:
    recorders = raw["errors"].setdefault("recorders", {})
    recorders.setdefault("ins", {})["delay_ms"] = float(delay_ms)


def _set_wind(raw: dict, wind_mps: Level) -> None:
    w, a = float(wind_mps), math.radians(WIND_TOWARDS_DEG)
    raw["environment"]["wind_ned_mps"] = [w * math.cos(a), w * math.sin(a), 0.0]


def _set_turbulence(raw: dict, level: Level) -> None:
    raw["environment"]["turbulence"] = str(level)


@dataclass(frozen=True)
class Factor:
    """One swept factor.

    Attributes
    ----------
    name : short name (point directories, CSV).
    title : what is swept, with its unit (plot panel, table).
    levels : the swept levels (numbers, or names such as ``"light"``; ``"typical"`` = the preset's
        own per-sensor values, not plotted).
    base_level : the level of the base scenario (every other factor's runs use it).
    apply : sets a level in a scenario mapping, in place.
    swept : (label, parameter families, display unit) whose estimate-minus-truth error is reported.
    variant_of : the factor this one repeats with another estimator set-up (its conclusion is
        added to that factor's).
    """

    name: str
    title: str
    levels: tuple[Level, ...]
    base_level: Level
    apply: Callable[[dict, Level], None]
    swept: tuple[tuple[str, tuple[str, ...], str], ...] = ()
    variant_of: str | None = None

    def label(self, level: Level) -> str:
        """The level as written in tables and directory names."""
        return f"{level:g}" if isinstance(level, int | float) else str(level)

    @property
    def numeric(self) -> bool:
        """Levels are numbers (plotted on a numeric axis; ``"typical"`` left out)."""
        return all(isinstance(lv, int | float) for lv in self.levels if lv != "typical")


def make_factors(imu_scales: Sequence[float], imu_started_scales: Sequence[float],
                 flow_delays_ms: Sequence[Level], ins_delays_ms: Sequence[float],
                 winds_mps: Sequence[float], turbulence: Sequence[str]) -> tuple[Factor, ...]:
    """The six factors with the given levels (the base levels: 1, -, typical, 0, 0, none)."""
    imu = (("accel", ("dax", "day", "daz"), "m/s^2"), ("gyro", ("dp", "dq", "dr"), "deg/s"))
    return (
        Factor("imu_bias", "IMU biases (x typical)", tuple(imu_scales), 1.0, set_imu_bias, imu),
        Factor("imu_started", "IMU biases (x typical), started at their mean", tuple(imu_started_scales),
               None, _set_imu_bias_started, imu, variant_of="imu_bias"),
        Factor("flow_delay", "flow-sensor delay (ms)", tuple(flow_delays_ms), "typical", _set_flow_delay,
               (("tau", ("tau_alpha_zl", "tau_alpha_zr", "tau_sp", "tau_np", "tau_ba", "tau_bu",
                         "tau_bl"), "ms"),)),
        Factor("ins_delay", "INS latency (ms)", tuple(ins_delays_ms), 0.0, _set_ins_delay,
               (("tau", ("tau_phi", "tau_theta", "tau_psi"), "ms"),)),
        Factor("wind", "steady wind (m/s)", tuple(winds_mps), 0.0, _set_wind),
        Factor("turbulence", "turbulence (MIL-F-8785C)", tuple(turbulence), "none", _set_turbulence),
    )


# ---------------------------------------------------------------------------- the scenarios

#: the base scenario (a Monte Carlo scenario mapping, see campaigns/montecarlo/scenario.py): two
#: configurations (PV1 with the nose probe, PT1 with the boom) x Mach 0.6 x five maneuver kinds,
#: typical errors, the model-representable local-flow truth and ADC baseline (as mc_20maneuvers:
#: any loss of accuracy is then caused by the swept factor, not by a model that cannot fit)
FULL_BASE: Mapping[str, Any] = {
    "name": "tolerance",
    "description": "planning study (c): tolerance to IMU biases, delays, wind and turbulence",
    "seed": 2031,
    "replications": 10,
    "fleet": "fleet_default",
    "local_flow_truth": "local_flow_linear",
    "adc_baseline": "adc_baseline_linear",
    "common_rate_hz": 40.0,
    "environment": {"planet": "flat", "wind_ned_mps": [0.0, 0.0, 0.0], "turbulence": "none"},
    "errors": {"preset": "typical", "nose_probe_irregularity": False},
    "flights": [
        {"configurations": ["PV1-NP", "PT1-BOOM"], "mach": [0.6], "altitude_m": 6000.0,
         "maneuvers": ["pitch_doublet", "3211", "roller_coaster", "pullup_rudder_doublets"]},
        {"configurations": ["PV1-NP", "PT1-BOOM"], "mach": [0.6], "altitude_m": 6000.0,
         "maneuvers": ["windup_turn"], "maneuver": {"alpha_max_rad": 0.2094, "nz_max": 4.5}},
    ],
    "draw": {"turbulence": "redraw", "errors": {}},
    "estimator": {"model": "tejas", "max_iterations": 40, "colored": True,
                  "parameters": {"h0": {"free": True}}},
}

#: a smoke-test scenario: one configuration, two 20 s maneuvers, the vane channels only, the vane
#: tables held (about a second per replication)
TINY_BASE: Mapping[str, Any] = {
    **FULL_BASE,
    "name": "tolerance_tiny",
    "flights": [{"configurations": ["PV1-NP"], "mach": [0.6], "maneuvers": ["pitch_doublet", "3211"],
                 "maneuver": {"duration_s": 20.0}}],
    # no sideslip channel: v0 and the lateral accelerometer bias would enter the outputs only to
    # second order (through TAS), a degenerate problem; they are held (at the data's start, 0)
    "estimator": {"channels": ["phi", "theta", "psi", "tas", "h", "h_dgps", "alpha_zl", "alpha_zr"],
                  "max_iterations": 100, "parameters": {"f1": {"free": False}, "f2": {"free": False},
                                                        "v0": {"free": False}, "day": {"free": False}}},
}


@dataclass(frozen=True)
class StudyConfig:
    """A study: base scenario, factors and their levels, N."""

    base: Mapping[str, Any]
    factors: tuple[Factor, ...]
    replications: int


FULL = StudyConfig(FULL_BASE, make_factors(
    imu_scales=(0.0, 1.0, 1.5, 2.0, 3.0, 10.0), imu_started_scales=(3.0, 10.0),
    flow_delays_ms=("typical", 200.0, 300.0, 400.0), ins_delays_ms=(0.0, 100.0, 200.0, 300.0),
    winds_mps=(0.0, 10.0, 20.0), turbulence=("none", "light", "moderate")), replications=8)
TINY = StudyConfig(TINY_BASE, make_factors(
    imu_scales=(1.0, 3.0), imu_started_scales=(3.0,), flow_delays_ms=("typical", 100.0),
    ins_delays_ms=(0.0, 100.0), winds_mps=(0.0, 10.0), turbulence=("none", "light")), replications=1)
#: The turbulence rows again, estimated by the filter-error method (the wind as states;
#: estimator/filter_error.py): calm, light and moderate, 8 replications each, on the full base
#: The model set adds the INS ground velocities (estimator/models/tejas_ins.toml): the
#: accelerometer biases are then measured, not told by the flow sensors the wind also moves
FILTER_ERROR_BASE: Mapping[str, Any] = {
    **FULL_BASE, "name": "tolerance_filter_error",
    "estimator": {**FULL_BASE["estimator"], "model": "tejas_ins", "solver": {"method": "filter_error"}}}
FILTER_ERROR = StudyConfig(FILTER_ERROR_BASE, tuple(
    f for f in make_factors(imu_scales=(1.0,), imu_started_scales=(), flow_delays_ms=("typical",),
                            ins_delays_ms=(0.0,), winds_mps=(0.0,), turbulence=("none", "light", "moderate"))
    if f.name == "turbulence"), replications=8)
SIZES = {"full": FULL, "tiny": TINY, "filter_error": FILTER_ERROR}


@dataclass(frozen=True)
class Point:
    """One (factor, level) of the study and the Monte Carlo run that answers it."""

    factor: Factor
    level: Level
    raw: dict
    directory: Path


def base_scenario(config: StudyConfig) -> dict:
    """The base scenario mapping: every factor at its base level."""
    raw = copy.deepcopy(dict(config.base))
    for f in config.factors:
        f.apply(raw, f.base_level)
    return raw


def study_points(config: StudyConfig, out_dir: Path) -> list[Point]:
    """Every (factor, level) with its scenario; points with the same scenario (each factor's base
    level is the base scenario) share one run directory."""
    base = base_scenario(config)
    seen: dict[str, Path] = {}
    points = []
    for f in config.factors:
        for level in f.levels:
            raw = copy.deepcopy(base)
            f.apply(raw, level)
            raw["name"] = f"{config.base['name']}_{f.name}_{f.label(level)}"
            key = parse_scenario({**raw, "name": ""}, source="tolerance").hash
            directory = seen.setdefault(key, Path(out_dir) / "points" / f"{f.name}_{f.label(level)}")
            if directory.name != f"{f.name}_{f.label(level)}":
                raw["name"] = f"{config.base['name']}_{directory.name}"  # the shared run's name
            points.append(Point(f, level, raw, directory))
    return points

