"""Aircraft, fleet and sensor installations, as data.

The TOML files beside this module are the data; this module reads them into immutable
dataclasses and checks them. Positions are body axes (x forward, y right, z down), metres, from
the airframe's reference point; angles are stored in radians (the files say ``_deg``).

Example
-------
>>> from aircraft_models import load_fleet
>>> fleet = load_fleet()
>>> sorted(fleet.configurations)[:2]
['PT1-BOOM', 'PT1-NP']
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

import numpy as np

from aircraft_models.schema import Key, check

DATA_DIR = Path(__file__).resolve().parent

#: Sensors every configuration carries.
COMMON_SENSORS = ("vane_left", "vane_right", "side_probe_left", "side_probe_right")
#: What sits on the nose, by ``nose_sensor``.
NOSE_SENSORS = {
    "nose_probe": ("nose_probe",),
    "boom": ("boom_alpha_vane", "boom_beta_upper_vane", "boom_beta_lower_vane"),
}
ALL_SENSORS = COMMON_SENSORS + NOSE_SENSORS["nose_probe"] + NOSE_SENSORS["boom"]
#: Non-air-data installations whose position matters.
INERTIAL_UNITS = ("imu", "ins")

#: The keys of an airframe file (positions_body_m: installation name -> [x, y, z], m).
AIRFRAME_KEYS = ("name", "jsbsim_model", "reference_point", "positions_body_m")
#: The keys of a fleet file, of its [[aircraft]] and of its [[configuration]] entries.
FLEET_KEYS = ("airframe", "aircraft", "configuration")
AIRCRAFT_KEYS = {"id": Key(str, required=True), "fuel_kg": Key(float), "ballast_kg": Key(float),
                 "ballast_position_body_m": Key(list), "installation_bias_deg": Key(Mapping)}
CONFIGURATION_KEYS = {"id": Key(str, required=True), "aircraft": Key(), "nose_sensor": Key(str)}


def _vec3(value, where: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{where}: expected three finite numbers [x, y, z] in metres, got {value!r}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class Airframe:
    """The aircraft type: which JSBSim model flies it and where its sensors sit.

    Attributes
    ----------
    name : airframe name.
    jsbsim_model : JSBSim aircraft directory name (e.g. ``"f16"``).
    reference_point : name of the JSBSim ``<location>`` used as the body-axis origin.
    positions_body_m : installation name -> (3,) position, body axes, m, from the reference point.
    """

    name: str
    jsbsim_model: str
    reference_point: str
    positions_body_m: Mapping[str, np.ndarray]

    def position(self, name: str) -> np.ndarray:
        try:
            return self.positions_body_m[name]
        except KeyError:
            raise KeyError(
                f"airframe {self.name!r} has no installation {name!r}; "
                f"known: {sorted(self.positions_body_m)}"
            ) from None


@dataclass(frozen=True)
class Aircraft:
    """One tail number: its mass distribution and its sensors' installation biases.

    Attributes
    ----------
    id : tail identifier.
    fuel_kg : internal fuel at the start of every maneuver, kg (split equally left/right).
    ballast_kg : extra point mass (instrumentation, boom counterweight), kg.
    ballast_position_body_m : (3,) where the ballast sits, body axes, m.
    installation_bias_rad : sensor name -> installation bias, rad.
    """

    id: str
    fuel_kg: float
    ballast_kg: float
    ballast_position_body_m: np.ndarray
    installation_bias_rad: Mapping[str, float]


@dataclass(frozen=True)
class Configuration:
    """An aircraft with a given nose installation (nose probe or flight-test boom)."""

    id: str
    aircraft: Aircraft
    nose_sensor: str

    @property
    def sensors(self) -> tuple[str, ...]:
        """Flow-angle sensors fitted in this configuration."""
        return COMMON_SENSORS + NOSE_SENSORS[self.nose_sensor]


@dataclass(frozen=True)
class Fleet:
    airframe: Airframe
    aircraft: Mapping[str, Aircraft]
    configurations: Mapping[str, Configuration]
    source: str

    def configuration(self, config_id: str) -> Configuration:
        try:
            return self.configurations[config_id]
        except KeyError:
            raise KeyError(
                f"{self.source}: no configuration {config_id!r}; "
                f"known: {sorted(self.configurations)}"
            ) from None


def read_toml(path: Path) -> dict:
    """Parse a TOML file; errors name the file."""
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML: {exc}") from None


def is_bare_name(name_or_path: str | Path) -> bool:
    """A shipped-data name (``fleet_default``), not a path: no directory part, no suffix."""
    p = Path(name_or_path)
    return len(p.parts) == 1 and not p.suffix


def resolve_data_file(name_or_path: str | Path) -> Path:
    """A TOML path (which must exist), or the name of a file shipped in ``aircraft_models/``.

    A path is never silently replaced by a shipped file of the same name: a user's edited copy
    with a mistyped path must fail, not fall back to the original.
    """
    p = Path(name_or_path)
    shipped = sorted(q.stem for q in DATA_DIR.glob("*.toml"))
    if not is_bare_name(p):
        if p.is_file():
            return p
        raise FileNotFoundError(f"{name_or_path}: no such file (shipped models, by bare name: {shipped})")
    candidate = DATA_DIR / f"{p.name}.toml"
    if candidate.exists():
        return candidate
    raise FileNotFoundError(f"{name_or_path}: no model of that name is shipped in {DATA_DIR} "
                            f"(shipped: {shipped}); give a path to your own TOML file instead")


_resolve = resolve_data_file


def load_airframe(name_or_path: str | Path = "f16_testbed") -> Airframe:
    """Load an airframe definition (shipped name such as ``"f16_testbed"`` or a TOML path)."""
    path = _resolve(name_or_path)
    raw = read_toml(path)
    check(raw, AIRFRAME_KEYS, str(path))
    try:
        positions = {
            k: _vec3(v, f"{path}: positions_body_m.{k}") for k, v in raw["positions_body_m"].items()
        }
        frame = Airframe(
            name=raw["name"],
            jsbsim_model=raw["jsbsim_model"],
            reference_point=raw.get("reference_point", "VRP"),
            positions_body_m=MappingProxyType(positions),
        )
    except KeyError as exc:
        raise ValueError(f"{path}: missing key {exc}; see aircraft_models/f16_testbed.toml") from None
    missing = [s for s in ALL_SENSORS + INERTIAL_UNITS if s not in positions]
    if missing:
        raise ValueError(f"{path}: positions_body_m lacks {missing}; every installation needs x, y, z")
    return frame


def load_fleet(name_or_path: str | Path = "fleet_default") -> Fleet:
    """Load a fleet (shipped name such as ``"fleet_default"`` or a TOML path)."""
    path = _resolve(name_or_path)
    raw = read_toml(path)
    check(raw, FLEET_KEYS, str(path))
    airframe_name = raw.get("airframe", "f16-testbed").replace("-", "_")
    airframe = load_airframe(airframe_name)
    aircraft: dict[str, Aircraft] = {}
    for i, a in enumerate(raw.get("aircraft", [])):
        where = f"{path}: aircraft[{i}]"
        a = check(a, AIRCRAFT_KEYS, where)
        biases_deg = check(a.get("installation_bias_deg", {}), ALL_SENSORS, f"{where}.installation_bias_deg",
                           what="sensor")
        ac = Aircraft(
            id=a["id"],
            fuel_kg=float(a.get("fuel_kg", 1360.0)),
            ballast_kg=float(a.get("ballast_kg", 0.0)),
            ballast_position_body_m=_vec3(
                a.get("ballast_position_body_m", [0.0, 0.0, 0.0]), f"{where}.ballast_position"
            ),
            installation_bias_rad=MappingProxyType(
                {s: math.radians(float(biases_deg.get(s, 0.0))) for s in ALL_SENSORS}
            ),
        )
        if ac.id in aircraft:
            raise ValueError(f"{where}: duplicate aircraft id {ac.id!r}")
        aircraft[ac.id] = ac
    configurations: dict[str, Configuration] = {}
    for i, c in enumerate(raw.get("configuration", [])):
        where = f"{path}: configuration[{i}]"
        c = check(c, CONFIGURATION_KEYS, where)
        if c.get("aircraft") not in aircraft:
            raise ValueError(
                f"{where}: aircraft {c.get('aircraft')!r} is not in the fleet {sorted(aircraft)}"
            )
        nose = c.get("nose_sensor", "nose_probe")
        if nose not in NOSE_SENSORS:
            raise ValueError(f"{where}: nose_sensor must be one of {sorted(NOSE_SENSORS)}, got {nose!r}")
        cfg = Configuration(id=c["id"], aircraft=aircraft[c["aircraft"]], nose_sensor=nose)
        if cfg.id in configurations:
            raise ValueError(f"{where}: duplicate configuration id {cfg.id!r}")
        configurations[cfg.id] = cfg
    if not configurations:
        raise ValueError(f"{path}: a fleet needs at least one [[configuration]]")
    return Fleet(
        airframe=airframe,
        aircraft=MappingProxyType(aircraft),
        configurations=MappingProxyType(configurations),
        source=str(path),
    )
