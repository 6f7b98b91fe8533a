"""From raw tables (file units, canonical column names) to checked SI :class:`ManeuverData`.

Both import paths meet here: a problem file's ``[[files]]`` and an ``fpr fly`` dataset are read
into :class:`SourceTable` objects and cut into maneuvers by :class:`ManeuverRequest` objects;
:func:`build_maneuver` applies every data check of :mod:`estimator.io`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from estimator.io.consistency import check_euler_rates
from estimator.io.errors import DataError, Where, warn
from estimator.io.plausibility import (
    Ranges,
    SpikeError,
    check_plausible,
    check_tas_against_mach,
    check_zero_dropouts,
)
from estimator.io.timebase import check_finite, check_sampling, check_time, resample, select_range
from estimator.io.units import UNITS, get_unit, to_si
from estimator.problem import ManeuverData

#: Inputs every maneuver needs: time, IMU specific force (at the IMU, body axes) and body rates.
REQUIRED = ("t", "ax", "ay", "az", "p", "q", "r")
#: Dimension of the canonical names the estimator itself knows.
DIMENSIONS: dict[str, str] = {
    "t": "time", "ax": "acceleration", "ay": "acceleration", "az": "acceleration",
    "p": "angular rate", "q": "angular rate", "r": "angular rate",
    "phi": "angle", "theta": "angle", "psi": "angle", "tas": "speed", "h": "length",
    "gear": "dimensionless", "mach": "dimensionless",
}


@dataclass
class SourceTable:
    """One data file mapped to canonical names, values still in the file's units.

    Attributes
    ----------
    path : the file.
    values : canonical name -> (N,) float values (NaN where missing or not a number).
    not_numeric : canonical name -> (N,) mask of cells that held text.
    raw_text : canonical name -> (N,) original cells, kept only for columns with text cells.
    units : canonical name -> declared unit.
    labels : canonical name -> how messages name it (``"channel ax (column 'AX')"``).
    rows : (N,) data row of each sample (0-based after the header).
    own_rate : canonical names recorded at their own, slower rate: empty (NaN) between their
        samples, fitted only where they have one (``own_rate = true`` in ``[columns]``).
    holes : canonical name -> where a log's stream has no samples (s, the time base's clock; what
        it is), for naming the dropout behind a missing value (:func:`estimator.io.logs.stream_holes`).
    """

    path: Path
    values: dict[str, np.ndarray]
    units: dict[str, str]
    labels: dict[str, str]
    not_numeric: dict[str, np.ndarray] = field(default_factory=dict)
    raw_text: dict[str, np.ndarray] = field(default_factory=dict)
    rows: np.ndarray | None = None
    own_rate: frozenset[str] = frozenset()
    holes: Mapping[str, list[tuple[float, float, str]]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        missing = [c for c in REQUIRED if c not in self.values]
        if missing:
            raise DataError(
                f"{self.path}: no data for the required input(s) {missing}; every maneuver needs "
                "t (time), ax, ay, az (IMU specific force) and p, q, r (IMU body rates): map them "
                "under [columns]"
            )
        n = len(self.values["t"])
        if self.rows is None:
            self.rows = np.arange(n)
        t = to_si(self.values["t"], self.units["t"], f"{self.path}: {self.labels['t']}")
        check_time(t, self.rows, Where(str(self.path)), self.labels["t"])
        self.t_s = t


@dataclass(frozen=True)
class ManeuverRequest:
    """A maneuver to cut out of a :class:`SourceTable`.

    Attributes
    ----------
    id : maneuver id.
    t_start_s, t_end_s : time range in the file's time base, s (None: start/end of the file).
    aircraft, configuration : ids for aircraft- and configuration-scoped parameters.
    r_cg_body_m : (3,) CG position, body axes, m.
    resample_hz : resample onto a uniform grid at this rate (None: the data must be uniform).
    plausible : declared plausible ranges, SI, with their dimension (``[plausible]``:
        :func:`estimator.io.plausibility.parse_ranges`).
    meta : carried into :attr:`ManeuverData.meta`, where ``mach_mean``, ``mach_min``,
        ``mach_max`` and ``gear_down`` are added from the data if absent.
    """

    id: str
    t_start_s: float | None
    t_end_s: float | None
    aircraft: str
    configuration: str
    r_cg_body_m: np.ndarray
    resample_hz: float | None = None
    meta: Mapping = field(default_factory=dict)
    plausible: Ranges = field(default_factory=dict)


def check_dimensions(table: SourceTable, expected: Mapping[str, str]) -> None:
    """Each column's declared unit must be of the dimension its canonical name needs."""
    for name, unit in table.units.items():
        u = get_unit(unit, f"{table.path}: {table.labels[name]}")
        dim = expected.get(name, DIMENSIONS.get(name))
        if dim is not None and u.dimension != dim:
            raise DataError(
                f"{table.path}: {table.labels[name]} is declared in {unit!r} ({u.dimension}) but "
                f"{name} is {'an' if dim[0] in 'aeiou' else 'a'} {dim}; declare one of "
                f"{[x for x, v in UNITS.items() if v.dimension == dim]}"
            )


def build_maneuver(table: SourceTable, req: ManeuverRequest, channel_columns: set[str]) -> ManeuverData:
    """Cut one maneuver out of a table, check it, convert it to SI.

    Parameters
    ----------
    table : the file's data.
    req : which time range and which aircraft.
    channel_columns : canonical names that are channel measurements (the rest, other than the
        required inputs, become :attr:`ManeuverData.signals`).
    """
    where = Where(str(table.path), req.id, None if req.t_start_s is None and req.t_end_s is None else (
        req.t_start_s if req.t_start_s is not None else float(table.t_s[0]),
        req.t_end_s if req.t_end_s is not None else float(table.t_s[-1])))
    idx = select_range(table.t_s, req.t_start_s, req.t_end_s, where, table.labels["t"], table.units["t"])
    t_s = table.t_s[idx]
    rows = table.rows[idx]
    own = table.own_rate & set(table.values)
    bad_own = own & (set(REQUIRED) | {"phi", "theta", "psi"})
    if bad_own:
        raise DataError(
            f"{where}: {sorted(bad_own)} cannot be own_rate columns: the IMU inputs and Euler angles "
            "are needed at every sample; resample them onto the time base first "
            "(own_rate is for slow measured channels such as a GPS height)")
    # an own-rate column no fitted channel measures (a GPS height left out of `channels`) is not
    # a data signal a model could read at every sample: it is not imported
    values = {k: v for k, v in table.values.items() if not (k in own and k not in channel_columns)}
    own &= channel_columns
    present = {}
    for name, v in values.items():
        vi = v[idx]
        not_num = table.not_numeric.get(name, np.zeros(len(v), bool))[idx]
        # an own-rate column's empty cells are not samples; text and infinities still are bad
        keep = ~np.isnan(vi) | not_num if name in own else np.ones(vi.size, bool)
        if name in own and np.count_nonzero(keep) < 2:
            raise DataError(f"{where}: {table.labels[name]} (own_rate) has fewer than 2 samples in the "
                            "maneuver; widen the time range or leave the channel out")
        if name not in own and not not_num.any():
            _check_slower(name, vi, t_s, where, table.labels[name], name in channel_columns)
        if name not in own and name in table.holes:
            _check_holes(vi, t_s, table.holes[name], where, table.labels[name])
        if name != "t" and not not_num.any():
            check_zero_dropouts(vi[keep], table.units[name], t_s[keep], rows[keep], where, table.labels[name])
        check_finite(vi[keep], not_num[keep],
                     table.raw_text[name][idx][keep] if name in table.raw_text else None, t_s[keep],
                     rows[keep], where, table.labels[name])
        present[name] = keep
    for name in sorted((channel_columns & set(values)) - own):
        _warn_held(values[name][idx], t_s, where, table.labels[name])
    t_s = check_sampling(t_s, rows, where, req.resample_hz, table.labels["t"])
    si = {name: to_si(v[idx], table.units[name], table.labels[name])
          for name, v in values.items() if name != "t"}
    check_plausible("t", table.labels["t"], t_s, table.units["t"], t_s, rows, where)
    for name, v in si.items():
        if name not in ("ax", "ay", "az"):
            k = present[name]
            check_plausible(name, table.labels[name], v[k], table.units[name], t_s[k], rows[k], where,
                            req.plausible)
    _check_accel(table, si, t_s, rows, where, req.plausible)
    if "tas" in si and "mach" in si and "tas" not in own:
        check_tas_against_mach(si["tas"], si["mach"], table.units["tas"], table.labels["tas"], where)
    check_euler_rates(si, t_s, table.units, table.labels, where)
    if req.resample_hz is not None:
        step = float(np.median(np.diff(t_s)))
        if req.resample_hz * step < 0.5:
            warn(f"{where}: resampling from {1 / step:.4g} Hz down to {req.resample_hz:.4g} Hz by linear "
                 "interpolation without an anti-aliasing filter; filter the data first if it is noisy")
        if "psi" in si:  # unwrap first: interpolating across a +-180 deg wrap invents headings
            si["psi"] = np.unwrap(si["psi"])
        t_old = t_s
        t_s, si = resample(t_s, {k: v for k, v in si.items() if k not in own}, float(req.resample_hz),
                           where)
        for name in own:
            si[name] = _own_rate_on_grid(t_old, to_si(table.values[name][idx], table.units[name],
                                                      table.labels[name]), t_s, table.labels[name], where)
    if "psi" in si:  # heading wraps at +-180 deg or 0/360 deg; the reconstruction does not
        si["psi"] = np.unwrap(si["psi"])
    ids = set(REQUIRED)
    meta = dict(req.meta)  # the same summary keys as an fpr manifest entry, for Mach binning
    if "mach" in si:
        for key, fn in (("mach_mean", np.mean), ("mach_min", np.min), ("mach_max", np.max)):
            meta.setdefault(key, float(fn(si["mach"])))
    if "gear" in si:
        meta.setdefault("gear_down", bool(np.mean(si["gear"]) >= 0.5))
    return ManeuverData(
        id=req.id, t_s=t_s,
        accel_imu_mps2=np.column_stack([si["ax"], si["ay"], si["az"]]),
        omega_rps=np.column_stack([si["p"], si["q"], si["r"]]),
        measurements={k: v for k, v in si.items() if k in channel_columns},
        signals={k: v for k, v in si.items() if k not in channel_columns and k not in ids},
        r_cg_body_m=np.asarray(req.r_cg_body_m, dtype=float),
        aircraft=req.aircraft, configuration=req.configuration,
        source=f"{table.path}, maneuver {req.id} (t = {t_s[0]:.3f} to {t_s[-1]:.3f} s)",
        meta=meta,
    )


def regular_period(present: np.ndarray) -> int | None:
    """``k >= 2`` if the rows flagged in ``present`` are (nearly: 90 % of the intervals) every
    ``k``-th row, as a slower channel's samples in a faster file; else None."""
    rows = np.flatnonzero(present)
    if rows.size < 3 or rows.size == present.size:
        return None
    d = np.diff(rows)
    k = int(np.median(d))
    return k if k >= 2 and np.mean(d == k) >= 0.9 else None


def _check_holes(v: np.ndarray, t_s: np.ndarray, holes: list[tuple[float, float, str]], where: Where,
                 label: str) -> None:
    """A missing value where the column's log stream has no samples: name the dropout (or the
    stream's end) and its times, rather than a bare missing value."""
    missing = np.isnan(v)
    for lo, hi, what in holes:
        inside = missing & (t_s > lo) & (t_s < hi)
        if inside.any():
            t0, t1 = float(t_s[inside][0]), float(t_s[inside][-1])
            raise DataError(f"{where}: {label} has no value from t = {t0:.3f} to {t1:.3f} s: {what}; trim "
                            "the maneuver's t_start_s/t_end_s to exclude it, or split the maneuver around it")


def _ordinal(k: int) -> str:
    return f"{k}{'th' if 10 <= k % 100 <= 20 else {1: 'st', 2: 'nd', 3: 'rd'}.get(k % 10, 'th')}"


def _check_slower(name: str, v: np.ndarray, t_s: np.ndarray, where: Where, label: str,
                  is_channel: bool) -> None:
    """Empty cells at a regular interval are a slower channel's, not lost data: say what to do."""
    if not np.isnan(v).any():
        return
    k = regular_period(np.isfinite(v))
    if k is None:
        return
    rate = 1.0 / float(np.median(np.diff(t_s)))
    what = (f"{where}: {label} has values only on every {_ordinal(k)} row ({rate / k:.3g} Hz in a "
            f"{rate:.3g} Hz file) and is empty between them: recorded at a slower rate")
    if name in REQUIRED or name in ("phi", "theta", "psi"):
        raise DataError(f"{what}. {name} is needed at every sample (own_rate = true is for slow measured "
                        "channels such as a GPS height): resample it onto the file's time base (interpolate "
                        "it in the file), or resample the whole file to its rate")
    if is_channel:
        raise DataError(f"{what}. Mark it own_rate = true under [columns] ({name} = {{ column = ..., "
                        "unit = ..., own_rate = true }): it is then fitted at its own samples only")
    raise DataError(f"{what}. If it is a measured channel, mark it own_rate = true under [columns]; a data "
                    f"signal the channel models read at every sample ({name}) must be filled in between "
                    "(hold or interpolate it in the file)")


def hold_starts(v: np.ndarray) -> np.ndarray:
    """Rows whose value differs from the row before (the first finite row counts; NaN rows never
    do): where each sample of a held column arrived."""
    return np.isfinite(v) & ~(v == np.r_[np.nan, v[:-1]])


def held_samples(v: np.ndarray) -> np.ndarray:
    """An own-rate column written at the file's rate by holding each sample (a 1-Hz GPS velocity
    repeated at 50 Hz): kept only where its value changes, the rows its samples arrived at, so that
    it is fitted at its own samples. Held means its changes come every k >= 2 of its filled rows
    (:func:`regular_period`); any other column (empty between its samples, or a full-rate one
    whose values merely repeat now and then, as a quantised height does) is returned as it is."""
    finite = np.isfinite(v)
    starts = hold_starts(v)
    if regular_period(starts[finite]) is None:
        return v
    return np.where(starts, v, np.nan)


def _warn_held(v: np.ndarray, t_s: np.ndarray, where: Where, label: str) -> None:
    """A slower channel written at the file's rate by repeating each sample: it is fitted as a
    staircase, late by up to a slow period; say so (it is not wrong enough to refuse)."""
    starts = hold_starts(v)
    k = regular_period(starts)
    if k is None or np.count_nonzero(starts) < 10:
        return
    rate = 1.0 / float(np.median(np.diff(t_s)))
    warn(f"{where}: {label} holds each value for {k} rows ({rate / k:.3g} Hz in a {rate:.3g} Hz file): a "
         f"slower channel written by repeating its samples, which delays it by up to "
         f"{1e3 * (k - 1) / rate:.0f} ms. Mark it own_rate = true under [columns]: it is then fitted at "
         "its own samples only (the rows where its value changes)")


def _own_rate_on_grid(t_s: np.ndarray, v: np.ndarray, t_new_s: np.ndarray, label: str,
                      where: Where) -> np.ndarray:
    """An own-rate column on a resampled grid: each sample moves to the grid time it falls on
    (within 1 % of a step); interpolating between samples would low-pass the channel."""
    k = np.flatnonzero(np.isfinite(v))
    step = float(t_new_s[1] - t_new_s[0])
    j = np.rint((t_s[k] - t_new_s[0]) / step).astype(np.int64)
    off = np.abs(t_s[k] - t_new_s[0] - j * step)
    if np.any(off > 0.01 * step):
        i = int(k[np.argmax(off)])
        raise DataError(
            f"{where}: {label} (own_rate) has a sample at t = {t_s[i]:.4f} s that is not a time of "
            f"the resampled grid (step {step:.4g} s from t = {t_new_s[0]:.4f} s); choose a "
            "resample_hz that is a multiple of the channel's rate, or resample the file yourself")
    out = np.full(t_new_s.shape, np.nan)
    inside = (j >= 0) & (j < t_new_s.size)
    out[j[inside]] = v[k[inside]]
    return out


def _check_accel(table: SourceTable, si: Mapping[str, np.ndarray], t_s, rows, where: Where,
                 ranges: Ranges) -> None:
    units = [table.units[c] for c in ("ax", "ay", "az")]
    acc = np.column_stack([si["ax"], si["ay"], si["az"]])
    label = "the IMU specific force (" + ", ".join(table.labels[c] for c in ("ax", "ay", "az")) + ")"
    if len(set(units)) == 1:
        check_plausible("accel", label, acc, units[0], t_s, rows, where, ranges)
        return
    try:
        check_plausible("accel", label, acc, "m/s^2", t_s, rows, where, ranges)
    except SpikeError:
        raise
    except DataError:
        mean_g = float(np.mean(np.linalg.norm(acc, axis=1))) / 9.80665
        raise DataError(
            f"{where}: {label} has a mean magnitude of {mean_g:.3g} g after conversion from the "
            f"declared units {units}; in flight it stays near 1 g (0.4 to 4 g on average). Check "
            "the units of ax, ay, az under [columns]"
        ) from None
