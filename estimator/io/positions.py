"""Positions that cannot be points of one airframe: a CG or sensor in the wrong unit.

Every position of a problem file (``[sensors]``, each ``r_cg_body_*``) is a point of one rigid
airframe, in metres from its reference point unless its key says ``_in`` or ``_ft``. A CG written
in inches under a metre key (``r_cg_body_m = [13.0, 0.0, 5.1]`` for ``[0.33, 0.0, 0.13]`` m) does
not crash anything: the state equations integrate the IMU point's velocity, so the fit converges
and the residuals stay small, but the flow angles at the CG that the calibration tables are
functions of are moved by ``omega x (12.7 m)`` and the fit absorbs that into the tables and time
delays (17 deviations off in a user's report). Only the input can tell; two checks, each on the
positions alone:

- **no airframe is that large** (:data:`MAX_AIRFRAME_M`): two positions of one aircraft further
  apart than the largest aircraft flown are impossible, whatever they are;
- **far outside the airframe the others span, and where they are in inches or feet**: a position
  given in metres that lies beyond the cross-section (y, z) the other positions span by more than
  :data:`FAR_FACTOR` times its extent (:func:`outside`), at least :data:`MIN_OFFSET_M` from each
  of them, and that lands among them when read as inches (/ 39.37) or feet (/ 3.281) is that unit
  under a metre key. Across the airframe, not along it: a large aircraft whose sensors are
  clustered in its nose (a transport's nose boom and avionics-bay IMU) has its CG 20 m aft of them,
  and that CG read in inches lands near them too; but its CG lies within its fuselage's height and
  width of them, as every CG does of the sensors on its fuselage. Neither condition alone is
  enough; where a layout still meets both with the metres right, ``positions_checked = true`` at
  the top of the problem file skips this check (never the first).

A CG is judged against the sensors (the IMU, the air-data sensors: they are on the airframe), a
sensor against the other sensors and the CGs. Fewer than two distinct other positions span no
airframe: only the first check applies.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from aircraft_models.schema import SUFFIXES
from estimator.io.errors import DataError

#: m; no two points of one aircraft are further apart: the longest aircraft flown (An-225) is
#: 84 m long, the widest (Scaled Composites Stratolaunch) spans 117 m.
MAX_AIRFRAME_M = 120.0
#: A position further beyond the cross-section (y, z) of the others' box than this many times the
#: box's extent along the same axes (plus the margin below) is outside the airframe they span: the
#: CG lies inside the fuselage (or the wing root) the IMU and the air-data sensors are mounted on,
#: within its height and width of them, and the sensors' own spread across it (vanes on both
#: sides, an IMU below the floor, a probe on the centre line) plus the margin is about that size,
#: not half of it (PV1: 1.0 m wide, 0.2 m high plus 1 m margin; its CG 0.04 m inside).
FAR_FACTOR = 2.0
#: A reading in inches or feet lands "among the others" if it is within this many times their
#: extent of their box: where a CG (between the nose sensors and the tail, near the IMU) sits.
NEAR_FACTOR = 0.5
#: m; the far check needs the position at least this far from every other: a small UAV's sensors
#: and CG are all within a few metres (UMN Thor: 0.6 m), where the factors above mean little.
MIN_OFFSET_M = 3.0
#: The margin added to the box's extent along each axis, as a fraction of the others' largest
#: distance apart (at least :data:`MARGIN_MIN_M`): an airframe's cross-section, so that sensors
#: that line up on one axis (a fuselage's centre line) still span a body around it.
MARGIN_FRACTION = 0.2
MARGIN_MIN_M = 0.1
#: The other length units a position is written in, and their metres (the ``_in``/``_ft`` keys).
LENGTH_UNITS = {suffix.lstrip("_"): f for suffix, f in SUFFIXES["m"]}
_CG_STEM = "r_cg_body"


@dataclass(frozen=True)
class Position:
    """One position of a problem file, as written.

    Attributes
    ----------
    what : what it is ("the CG of aircraft PV1", "sensor imu").
    where : the table and key (``[aircraft.PV1] r_cg_body_m``).
    key : the key as written (``r_cg_body_m``, ``imu``).
    unit : the unit its key declares: ``"m"``, ``"in"`` or ``"ft"``.
    written : the three values as written.
    cg : a CG (judged against the sensors), else a sensor.
    line : its 1-based line in the problem file, where found (None: not located).
    """

    what: str
    where: str
    key: str
    unit: str
    written: tuple[float, float, float]
    cg: bool
    line: int | None = None

    @property
    def value_m(self) -> np.ndarray:
        """The position in metres, body axes from the reference point."""
        return np.asarray(self.written, dtype=float) * LENGTH_UNITS[self.unit]


def _split(key: str) -> tuple[str, str]:
    """(name, unit) of a position key: ``imu_ft`` -> ("imu", "ft"), ``imu`` -> ("imu", "m")."""
    for suffix, _ in SUFFIXES["m"]:
        if key.endswith(suffix):
            return key[: -len(suffix)], suffix.lstrip("_")
    return key, "m"


def _numbers(v) -> tuple[float, float, float] | None:
    if (isinstance(v, list) and len(v) == 3
            and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
        return float(v[0]), float(v[1]), float(v[2])
    return None  # the readers name a malformed position themselves


def _line(lines: Sequence[str], header: str | None, key: str) -> int | None:
    """The line of ``key = ...`` in the table whose header matches ``header`` (None: anywhere)."""
    inside = header is None
    for i, text in enumerate(lines):
        stripped = text.strip()
        if stripped.startswith("["):
            inside = header is not None and re.fullmatch(header, stripped.split("#")[0].strip()) is not None
            continue
        if inside and re.match(rf"\s*{re.escape(key)}\s*=", text):
            return i + 1
    return None


def positions_of(raw: Mapping, text: str = "") -> list[Position]:
    """Every position a problem file's tables give (``[sensors]``, ``[aircraft.X]``, ``[[files]]``
    entries and their maneuvers), in the order written; ``text``: the file's text, to locate lines."""
    lines = text.splitlines()
    out: list[Position] = []
    sensors = raw.get("sensors", {})
    if isinstance(sensors, Mapping):
        for key, v in sensors.items():
            xyz = _numbers(v)
            if xyz is not None:
                name, unit = _split(key)
                out.append(Position(f"sensor {name}", f"[sensors] {key}", key, unit, xyz, False,
                                    _line(lines, r"\[\s*sensors\s*\]", key)))
    aircraft = raw.get("aircraft", {})
    for ac, table in (aircraft.items() if isinstance(aircraft, Mapping) else ()):
        for key, v in (table.items() if isinstance(table, Mapping) else ()):
            xyz = _numbers(v)
            if xyz is not None and _split(key)[0] == _CG_STEM:
                header = rf"\[\s*aircraft\.{re.escape(str(ac))}\s*\]"
                out.append(Position(f"the CG of aircraft {ac}", f"[aircraft.{ac}] {key}", key, _split(key)[1],
                                    xyz, True, _line(lines, header, key)))
    files = raw.get("files", [])
    for i, entry in enumerate(files if isinstance(files, list) else ()):
        if not isinstance(entry, Mapping):
            continue
        name = entry.get("path", f"#{i + 1}")
        mans = entry.get("maneuvers", [])
        for j, table in [(None, entry), *enumerate(mans if isinstance(mans, list) else ())]:
            for key, v in (table.items() if isinstance(table, Mapping) else ()):
                xyz = _numbers(v)
                if xyz is None or _split(key)[0] != _CG_STEM:
                    continue
                man = "" if j is None else f" maneuvers[{j}] ({table.get('id', '?')})"
                where = f"[[files]] {name}{man}"
                out.append(Position(f"the CG of {where.removeprefix('[[files]] ')}", f"{where} {key}", key,
                                    _split(key)[1], xyz, True))
    return out


def outside(p: np.ndarray, others: np.ndarray, axes: Sequence[int] = (0, 1, 2)) -> float:
    """How far ``p`` lies beyond the box of ``others`` ((k, 3), m), in units of the box's extent
    along each axis plus a margin (:data:`MARGIN_FRACTION` of the others' largest distance apart,
    at least :data:`MARGIN_MIN_M`): 0 inside the box, 1 one extent beyond it; over the body
    ``axes`` given (0 x, 1 y, 2 z).

    Axis by axis, because an airframe is long and flat: a CG 1.3 m below sensors that all sit
    within 0.2 m of one height is further outside than one 1.5 m behind sensors 5 m apart.
    """
    lo, hi = others.min(axis=0), others.max(axis=0)
    spread = max(float(np.max(np.linalg.norm(others[:, None, :] - others[None, :, :], axis=2))), 0.0)
    scale = (hi - lo) + max(MARGIN_FRACTION * spread, MARGIN_MIN_M)
    excess = np.maximum(0.0, np.maximum(lo - p, p - hi))
    return float(np.linalg.norm((excess / scale)[list(axes)]))


def _fmt(v: Sequence[float]) -> str:
    return "[" + ", ".join(f"{x:.3g}" for x in v) + "]"


def _box_text(others: np.ndarray) -> str:
    lo, hi = others.min(axis=0), others.max(axis=0)
    return ", ".join(f"{a} {lo[k]:.3g} to {hi[k]:.3g}" for k, a in enumerate("xyz")) + " m"


def _reading(p: Position, others: np.ndarray) -> tuple[str, np.ndarray, float] | None:
    """The other length unit in which ``p`` lands among ``others`` (the closest such), or None."""
    best = None
    for unit, f in LENGTH_UNITS.items():
        if unit == p.unit or f >= LENGTH_UNITS[p.unit]:
            continue  # a mistake that made the number larger: read in a smaller unit
        v = np.asarray(p.written) * f
        s = outside(v, others)
        if s <= NEAR_FACTOR and (best is None or s < best[2]):
            best = (unit, v, s)
    return best


def check_positions(positions: Sequence[Position], source: str, checked: bool = False) -> None:
    """Raise :class:`DataError` for a position that cannot be a point of the airframe the others
    span (module docstring): the first CG, then the first sensor.

    Parameters
    ----------
    positions : every position of the problem file (:func:`positions_of`), sensors from a dataset too.
    source : the problem file, for messages.
    checked : ``positions_checked = true``: the far-outside check is skipped (not the size check).
    """
    sensors = [p for p in positions if not p.cg]
    cgs = [p for p in positions if p.cg]
    for p in (*cgs, *sensors):
        pool = sensors if p.cg else [*sensors, *cgs]
        pool = [q for q in pool if q is not p]
        if not pool:
            continue
        v = p.value_m
        others_a = np.unique(np.asarray([q.value_m for q in pool]), axis=0)
        dist = np.linalg.norm(others_a - v, axis=1)
        nearest = min(pool, key=lambda q: float(np.linalg.norm(q.value_m - v)))
        where = f"{source}" + (f" line {p.line}" if p.line else "") + f": {p.where} = {_fmt(p.written)}"
        # the size check on the distance from the others' median: one wrong position is far from
        # all the others, which are not far from each other
        too_big = float(np.linalg.norm(v - np.median(others_a, axis=0))) > MAX_AIRFRAME_M
        # outside the cross-section (y, z) the others span: along x, a large aircraft's CG can lie
        # far behind sensors clustered in its nose; across, it lies within its fuselage
        far = (not checked and p.unit == "m" and len(others_a) >= 2 and float(dist.min()) > MIN_OFFSET_M
               and outside(v, others_a, (1, 2)) > FAR_FACTOR)
        if not (too_big or far):
            continue
        reading = _reading(p, others_a) if len(others_a) >= 2 else None
        if far and reading is None and not too_big:
            continue  # far, but no unit makes it fit: a large aircraft's layout, not certainly wrong
        stem = _split(p.key)[0]
        if too_big:
            d = float(np.linalg.norm(v - np.median(others_a, axis=0)))
            what = (f"puts {p.what} {d:.4g} m from the other positions (their median), more than any "
                    f"aircraft measures ({MAX_AIRFRAME_M:.0f} m)")
        else:
            what = (f"puts {p.what} {float(dist.min()):.3g} m from the nearest position ({nearest.what}), "
                    f"far outside the airframe the {'sensor positions' if p.cg else 'other positions'} span "
                    f"({_box_text(others_a)})")
        if reading is not None:
            unit, vm, _ = reading
            name = {"in": "inches", "ft": "feet", "m": "metres"}[unit]
            fix = (f"read as {name} it is {_fmt(vm)} m, among them: the values look like {name}. Write "
                   f"{stem}_{unit} = {_fmt(p.written)} (the key's suffix gives the unit: _m, _in or _ft), or "
                   f"convert them to metres under {p.key}")
        else:
            fix = f"check the value and its unit (write {stem}_in or {stem}_ft for inches or feet)"
        escape = ("" if too_big else "; if the metres are right (a large aircraft whose sensors are "
                  "clustered far from this point), set positions_checked = true at the top of the "
                  "problem file")
        raise DataError(f"{where} {what}; {fix}{escape}")


__all__ = ["FAR_FACTOR", "LENGTH_UNITS", "MAX_AIRFRAME_M", "MIN_OFFSET_M", "NEAR_FACTOR", "Position",
           "check_positions", "outside", "positions_of"]
