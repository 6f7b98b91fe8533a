"""Units of the data columns: name -> dimension and SI factor/offset.

``value_SI = value * factor + offset``. A problem file declares the unit of every column
(``ax = { column = "AX", unit = "g" }``); everything inside the estimator is SI and radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimator.io.errors import DataError, close_match


@dataclass(frozen=True)
class Unit:
    """A unit: its physical dimension and the conversion to the SI unit of that dimension."""

    name: str
    dimension: str
    factor: float
    offset: float = 0.0


_DEG = math.pi / 180.0
_FT = 0.3048
_TABLE = (
    Unit("s", "time", 1.0), Unit("ms", "time", 1e-3), Unit("us", "time", 1e-6),
    Unit("rad", "angle", 1.0), Unit("deg", "angle", _DEG), Unit("mrad", "angle", 1e-3),
    Unit("rad/s", "angular rate", 1.0), Unit("deg/s", "angular rate", _DEG),
    Unit("m/s^2", "acceleration", 1.0), Unit("g", "acceleration", 9.80665),
    Unit("ft/s^2", "acceleration", _FT),
    Unit("m/s", "speed", 1.0), Unit("kt", "speed", 1852.0 / 3600.0), Unit("ft/s", "speed", _FT),
    Unit("km/h", "speed", 1.0 / 3.6),
    Unit("m", "length", 1.0), Unit("ft", "length", _FT), Unit("in", "length", 0.0254),
    Unit("1", "dimensionless", 1.0), Unit("bool", "dimensionless", 1.0),
    Unit("Pa", "pressure", 1.0), Unit("hPa", "pressure", 100.0), Unit("kPa", "pressure", 1000.0),
    Unit("mbar", "pressure", 100.0), Unit("psf", "pressure", 47.88025898),
    Unit("K", "temperature", 1.0), Unit("degC", "temperature", 1.0, 273.15),
)
#: Unit name -> :class:`Unit`. ``bool`` (a 0/1 flag) is dimensionless.
UNITS: dict[str, Unit] = {u.name: u for u in _TABLE}
#: The SI unit of each dimension (what the estimator uses inside).
SI_UNITS: dict[str, str] = {u.dimension: u.name for u in reversed(_TABLE) if u.factor == 1.0 and not u.offset}
SI_UNITS["dimensionless"] = "1"


def get_unit(name: str, where: str) -> Unit:
    """Look up a unit by name.

    Raises
    ------
    DataError
        For an unknown name; the message lists the valid names by dimension.
    """
    if not isinstance(name, str) or name not in UNITS:
        key = str(name).strip().lower().replace(" ", "")
        meant = (_SPELLINGS.get(key) or {u.lower(): u for u in UNITS}.get(key)
                 or close_match(str(name), UNITS))
        raise DataError(f"{where}: unknown unit {name!r}" + (f" (did you mean {meant!r}?)" if meant else "")
                        + f"; set unit = one of the valid units: {valid_units_text()}")
    return UNITS[name]


#: Common spellings of the units, lower case and without blanks -> the unit's name here.
_SPELLINGS = {
    "sec": "s", "second": "s", "seconds": "s", "msec": "ms", "millisecond": "ms", "milliseconds": "ms",
    "µs": "us", "μs": "us", "usec": "us", "microsecond": "us", "microseconds": "us",
    "radian": "rad", "radians": "rad", "degree": "deg", "degrees": "deg", "°": "deg",
    "milliradian": "mrad", "milliradians": "mrad",
    "rad/sec": "rad/s", "rps": "rad/s", "deg/sec": "deg/s", "dps": "deg/s", "°/s": "deg/s",
    "m/s2": "m/s^2", "m/s/s": "m/s^2", "m/sec^2": "m/s^2", "ft/s2": "ft/s^2", "ft/sec^2": "ft/s^2",
    "knot": "kt", "knots": "kt", "kts": "kt", "kn": "kt", "kias": "kt", "ktas": "kt", "m/sec": "m/s",
    "mps": "m/s", "fps": "ft/s", "ft/sec": "ft/s", "kph": "km/h", "kmh": "km/h", "km/hr": "km/h",
    "meter": "m", "meters": "m", "metre": "m", "metres": "m", "feet": "ft", "foot": "ft",
    "inch": "in", "inches": "in", "-": "1", "none": "1", "": "1", "mach": "1", "flag": "bool",
    "pascal": "Pa", "pa": "Pa", "hpa": "hPa", "kpa": "kPa", "mb": "mbar", "millibar": "mbar",
    "lb/ft^2": "psf", "lbf/ft^2": "psf", "kelvin": "K", "k": "K", "c": "degC", "°c": "degC",
    "celsius": "degC", "degc": "degC",
}


def valid_units_text() -> str:
    """``"time: s, ms; angle: rad, deg, mrad; ..."``."""
    dims: dict[str, list[str]] = {}
    for u in _TABLE:
        dims.setdefault(u.dimension, []).append(u.name)
    return "; ".join(f"{d}: {', '.join(n)}" for d, n in dims.items())


def units_of(dimension: str) -> list[str]:
    """The unit names of one dimension, in table order."""
    return [u.name for u in _TABLE if u.dimension == dimension]


def to_si(values: np.ndarray, unit: str, where: str) -> np.ndarray:
    """Convert ``values`` given in ``unit`` to SI (float array, a new copy)."""
    u = get_unit(unit, where)
    return np.asarray(values, dtype=float) * u.factor + u.offset


def from_si(values_si: np.ndarray, unit: str, where: str) -> np.ndarray:
    """Inverse of :func:`to_si`."""
    u = get_unit(unit, where)
    return (np.asarray(values_si, dtype=float) - u.offset) / u.factor
