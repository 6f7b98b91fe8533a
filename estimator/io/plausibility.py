"""Gross unit checks: values that cannot be right in the declared unit.

A unit mistake (degrees declared as radians, g declared as m/s^2, feet declared as metres) does
not crash anything: the estimator would converge to nonsense. These checks catch the mistakes
that leave values far outside what an aircraft can do, name the channel and the observed range,
and suggest the unit in which the values would be plausible. They cannot catch every mistake:
values plausible in both units (an airspeed of 150 read as kt or m/s; small angles in degrees
declared as radians) pass. Two cross-checks add to them: true airspeed / Mach must be a speed of
sound (:func:`check_tas_against_mach`), and the Euler angles must change as the body rates say
(:mod:`estimator.io.consistency`; the heading, which may be unwrapped, is checked only that way).

=====================  ===============================  =========================================
quantity (channels)    statistic                        plausible (SI)
=====================  ===============================  =========================================
time step (t)          median step                      1e-4 to 2 s
flow angle (alpha_*,   max abs                          <= 1.6 rad (92 deg)
beta_*), theta
bank angle (phi)       max abs                          <= pi (+0.05) rad
other angles but psi   max abs                           <= 2 pi (+0.05) rad
body rate (p, q, r)    max abs                          <= 6 rad/s (344 deg/s)
IMU acceleration       mean of the norm of (ax, ay, az) 0.4 g to 4 g (1 g in steady flight);
                                                        every sample's norm <= 15 g
true airspeed (tas)    median                           15 to 700 m/s; every sample 0 to 1000 m/s
altitude (h)           median                           -500 to 25 000 m; every sample -1000 to
                                                        30 000 m
gear flag (gear)       min, max                         0 to 1
Mach (mach)            median                           0 to 5; every sample 0 to 5
=====================  ===============================  =========================================

These are a fighter's and an airliner's ranges. An aircraft outside them (a 12 m/s UAV) declares
its own under ``[plausible]`` in its model set or problem file (:func:`parse_ranges`): the range of
the statistic, replacing the built-in one (:func:`declared`).

Samples out of range that jump away from the rest (:func:`spikes`: one sample or a burst whose
signed value jumps from the in-range samples either side by far more than the signal's own
steps) are spikes. A unit is judged only by the bulk of the data (:func:`_bulk`: without its
1 % most extreme samples, and at least without the most extreme one): when the bulk is
plausible in the declared unit, the out-of-range samples, spikes or not, are named with their
times and rows, and no unit is ever suggested, so that one 95-deg or 1000-deg sample in a
column of degrees never reads as "set unit = mrad". A unit is suggested only when the bulk
itself is implausible.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from estimator.io.errors import DataError, Where, at_row, close_match
from estimator.io.units import UNITS, from_si, get_unit, to_si, units_of


class SpikeError(DataError):
    """A few samples far outside the plausible range (:func:`check_plausible`): not a unit error."""


@dataclass(frozen=True)
class Check:
    """A plausible interval of one statistic of a channel's SI values.

    Attributes
    ----------
    what : the quantity, for messages ("an angle").
    statistic : "maxabs", "median", "mean_norm" or "minmax".
    low, high : plausible interval of the statistic, SI.
    typical : a typical value to rank unit suggestions by closeness (None: rank by ``prefer``).
    prefer : unit suggestions in order of preference.
    sample_low, sample_high : for the statistics of the bulk ("median", "mean_norm"): the range
        every single sample (the norm for "mean_norm") must stay in, SI (None: not checked).
        "maxabs" and "minmax" check every sample against ``low``/``high`` themselves.
    """

    what: str
    statistic: str
    low: float
    high: float
    typical: float | None = None
    prefer: tuple[str, ...] = ()
    sample_low: float | None = None
    sample_high: float | None = None


_G = 9.80665
_FLOW = Check("a flow angle", "maxabs", 0.0, 1.6, prefer=("deg", "mrad"))
_CHECKS: dict[str, Check] = {
    "t": Check("a sample time step", "median_step", 1e-4, 2.0, typical=0.025, prefer=("s", "ms")),
    "theta": Check("a pitch angle", "maxabs", 0.0, 1.6, prefer=("deg", "mrad")),
    "phi": Check("a bank angle", "maxabs", 0.0, math.pi + 0.05, prefer=("deg", "mrad")),
    "p": Check("a body rate", "maxabs", 0.0, 6.0, prefer=("deg/s",)),
    "q": Check("a body rate", "maxabs", 0.0, 6.0, prefer=("deg/s",)),
    "r": Check("a body rate", "maxabs", 0.0, 6.0, prefer=("deg/s",)),
    "accel": Check("a specific force in flight", "mean_norm", 0.4 * _G, 4.0 * _G, typical=_G,
                   sample_low=0.0, sample_high=15.0 * _G),
    "tas": Check("a true airspeed", "median", 15.0, 700.0, typical=150.0, sample_low=0.0, sample_high=1000.0),
    "h": Check("a pressure altitude", "median", -500.0, 25000.0, typical=5000.0, sample_low=-1000.0,
               sample_high=30000.0),
    "gear": Check("a gear-down flag", "minmax", 0.0, 1.0),
    "mach": Check("a Mach number", "median", 0.0, 5.0, sample_low=0.0, sample_high=5.0),
}
_BY_DIMENSION: dict[str, Check] = {
    "angle": Check("an angle", "maxabs", 0.0, 2 * math.pi + 0.05, prefer=("deg", "mrad")),
    "angular rate": Check("an angular rate", "maxabs", 0.0, 6.0, prefer=("deg/s",)),
}


#: Declared ranges (``[plausible]``): canonical name -> (low, high) in SI and the unit's dimension.
Ranges = Mapping[str, tuple[float, float, str]]
#: Names a range cannot be declared for: the time base is checked by its step, the specific force
#: as a whole (declare ``accel``: the magnitude of (ax, ay, az)).
_NOT_RANGED = {"t": "the time base is checked by its sampling step, not a range",
               "ax": "declare accel (the specific force's magnitude) instead",
               "ay": "declare accel (the specific force's magnitude) instead",
               "az": "declare accel (the specific force's magnitude) instead"}


def parse_ranges(table: object, where: str, names: Sequence[str] | None = None
                 ) -> dict[str, tuple[float, float, str]]:
    """A ``[plausible]`` table (model set or problem file): ``NAME = { range = [low, high],
    unit = "..." }`` -> name -> (low, high) in SI and the unit's dimension. The range replaces the
    built-in plausible interval of the column's statistic (the median of an airspeed, height or
    Mach; the largest |value| of an angle or rate, which takes max(|low|, |high|)) for an aircraft
    outside the fighter-to-airliner ranges of :data:`_CHECKS` (a 12 m/s UAV).

    ``names``: the names a range may be declared for (the problem's columns and ``accel``);
    None: not checked."""
    if not isinstance(table, Mapping):
        raise DataError(f"{where}: [plausible] must be a table of NAME = {{ range = [low, high], "
                        "unit = ... }")
    out = {}
    for name, spec in table.items():
        w = f"{where}: [plausible] {name}"
        if name in _NOT_RANGED:
            raise DataError(f"{w}: no range for {name}: {_NOT_RANGED[name]}")
        if names is not None and name not in names:
            near = close_match(str(name), list(names))
            mean = f"; did you mean {near!r}?" if near else ""
            raise DataError(f"{w}: {name!r} is no column of the problem{mean}; ranges can be declared "
                            f"for: {sorted(names)}")
        if not isinstance(spec, Mapping) or set(spec) != {"range", "unit"}:
            raise DataError(f"{w}: must be {{ range = [low, high], unit = \"...\" }}, e.g. tas = {{ range = "
                            "[8.0, 40.0], unit = \"m/s\" }}, got " + repr(spec))
        r = spec["range"]
        if (not isinstance(r, list) or len(r) != 2 or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in r)
                or not r[0] < r[1]):
            raise DataError(f"{w}: range = {r!r} must be [low, high], finite, with low < high")
        unit = get_unit(str(spec["unit"]), w)
        lo, hi = to_si(np.asarray(r, dtype=float), unit.name, w)
        out[str(name)] = (float(lo), float(hi), unit.dimension)
    return out


#: A run of exact zeros at most this long, between neighbours of one sign, close to each other and
#: further from zero than :data:`ZERO_JUMP` times the column's median step, is a dropout written
#: as zero (:func:`check_zero_dropouts`).
ZERO_RUN_MAX = 5
ZERO_JUMP = 20.0
#: The quantities a dropout written as zero is looked for in (flags and Mach are left alone).
ZERO_DIMENSIONS = ("angle", "angular rate", "acceleration", "speed", "length", "pressure")


def check_zero_dropouts(values: np.ndarray, unit: str, t_s: np.ndarray, rows: np.ndarray, where: Where,
                        label: str) -> None:
    """Raise :class:`DataError` for a dropout written as zero: a run of at most
    :data:`ZERO_RUN_MAX` samples that are exactly 0 between samples far from 0 (a sample-and-hold
    that lost its input, a logger's empty value: 0 m/s for one sample of a 17 m/s airspeed),
    whatever the column is named: continuous across the zeros (the samples either side of one
    sign, closer to each other than a fifth of their distance from 0) and far from 0 there
    (:data:`ZERO_JUMP` times the column's median step). A signal crossing 0 changes sign."""
    v = np.asarray(values, dtype=float)
    if UNITS[unit].dimension not in ZERO_DIMENSIONS or v.size < 3:
        return
    zero = v == 0.0
    if not zero.any() or zero.all():
        return
    steps = np.abs(np.diff(v[~zero & np.isfinite(v)]))
    jump = ZERO_JUMP * float(np.median(steps)) if steps.size else 0.0
    edges = np.flatnonzero(np.diff(np.r_[0, zero.astype(np.int8), 0]))
    for a, b in zip(edges[::2], edges[1::2], strict=True):  # v[a:b] == 0
        if b - a > ZERO_RUN_MAX or a == 0 or b == v.size:
            continue
        # continuous through it and far from 0 on both sides, of one sign: a signal crossing 0
        # (a rate through a doublet) changes sign there, however steep its step
        before, after = v[a - 1], v[b]
        far = min(abs(before), abs(after))
        if before * after > 0.0 and far > max(jump, 5.0 * abs(before - after)) and jump > 0.0:
            raise DataError(
                f"{where}: {label} is exactly 0 {at_row(t_s[a], int(rows[a]))} ({b - a} sample(s)) between "
                f"{v[a - 1]:.6g} and {v[b]:.6g} {unit}: a dropout written as zero (a sample-and-hold that "
                "lost its input, a logger's empty value), not a measurement; blank those samples in the file "
                "or trim the maneuver's t_start_s/t_end_s around them")


def declared(check: Check | None, name: str, lo: float, hi: float) -> Check:
    """``check`` with a declared plausible range of its statistic, SI; every sample's range
    widened to hold it. A largest-|value| check takes max(|lo|, |hi|); a name without a built-in
    check gets one on its median."""
    if check is None:
        return Check(f"{name} (its declared range)", "median", lo, hi, sample_low=lo, sample_high=hi)
    if check.statistic == "maxabs":
        return dataclasses.replace(check, high=max(abs(lo), abs(hi)))
    return dataclasses.replace(
        check, low=lo, high=hi,
        sample_low=None if check.sample_low is None else min(check.sample_low, lo),
        sample_high=None if check.sample_high is None else max(check.sample_high, hi))


def check_for(name: str, dimension: str) -> Check | None:
    """The check of a canonical column name (``alpha_*``/``beta_*`` are flow angles), or None."""
    if name in _CHECKS:
        return _CHECKS[name]
    if name == "psi":  # may be unwrapped over several turns: see estimator.io.consistency
        return None
    if dimension == "angle" and (name.startswith("alpha") or name.startswith("beta")):
        return _FLOW
    return _BY_DIMENSION.get(dimension)


def _statistic(check: Check, v: np.ndarray, t_s: np.ndarray) -> tuple[float, int]:
    """Statistic value and the sample index it is attributed to."""
    if check.statistic == "maxabs":
        i = int(np.argmax(np.abs(v)))
        return float(abs(v[i])), i
    if check.statistic == "median":
        return float(np.median(v)), int(np.argmin(np.abs(v - np.median(v))))
    if check.statistic == "median_step":
        return float(np.median(np.diff(t_s))), 0
    if check.statistic == "mean_norm":
        norm = np.linalg.norm(np.atleast_2d(v.T).T.reshape(len(t_s), -1), axis=1)
        return float(np.mean(norm)), int(np.argmax(norm))
    lo, hi = float(np.min(v)), float(np.max(v))
    return (lo if lo < check.low else hi), int(np.argmin(v) if lo < check.low else np.argmax(v))


def _ok(check: Check, v: np.ndarray, t_s: np.ndarray) -> bool:
    if check.statistic == "minmax":
        return bool(np.min(v) >= check.low - 1e-9 and np.max(v) <= check.high + 1e-9)
    s, _ = _statistic(check, v, t_s)
    return check.low <= s <= check.high


def _bulk(check: Check, v: np.ndarray) -> np.ndarray:
    """The values a unit is judged by: for the per-sample statistics ("maxabs", "minmax"),
    without the 1 % most extreme samples, and at least without the single most extreme one
    (each end for "minmax"). A few samples out of range, whether or not the jump test of
    :func:`spikes` sees them, must not choose the unit, nor hide that the unit is right."""
    if check.statistic not in ("maxabs", "minmax") or v.size < 3:
        return v
    if check.statistic == "maxabs":
        k = max(1, v.size // 100)
        return v[np.sort(np.argsort(np.abs(v), kind="stable")[: v.size - k])]
    k = max(1, v.size // 200)
    order = np.argsort(v, kind="stable")
    return v[np.sort(order[k: v.size - k])] if v.size > 2 * k else v


def suggest_units(check: Check, raw: np.ndarray, declared: str, t_s_of: Callable) -> list[str]:
    """Units of the declared dimension in which the bulk of the raw values (:func:`_bulk`) would
    pass ``check``, best first."""
    dim = UNITS[declared].dimension
    ok = []
    raw = _bulk(check, raw)
    for u in units_of(dim):
        if u == declared or u == "bool":
            continue
        v = to_si(raw, u, u)
        if _ok(check, v, t_s_of(v)):
            ok.append(u)
    if check.typical is not None:
        def _key(u):
            v = to_si(raw, u, u)
            return abs(math.log(max(_statistic(check, v, t_s_of(v))[0], 1e-300) / check.typical))

        return sorted(ok, key=_key)
    return sorted(ok, key=lambda u: check.prefer.index(u) if u in check.prefer else len(check.prefer))


#: More spikes than this fraction of a maneuver's samples suggest a wrong or corrupted column.
SPIKE_MAX_FRACTION = 0.01


def _per_sample(check: Check, v: np.ndarray) -> tuple[np.ndarray, float, float] | None:
    """The per-sample quantity, its plausible range, or None if the check has none."""
    if check.statistic == "maxabs":
        return np.abs(v), -math.inf, check.high
    if check.statistic == "minmax":
        return v, check.low, check.high
    if check.sample_low is None and check.sample_high is None:
        return None
    x = np.linalg.norm(v, axis=1) if v.ndim == 2 else v
    lo = -math.inf if check.sample_low is None else check.sample_low
    return x, lo, math.inf if check.sample_high is None else check.sample_high


def spikes(x: np.ndarray, out: np.ndarray, jump: float) -> np.ndarray:
    """Mask of the out-of-range samples that are spikes: runs of consecutive out-of-range samples
    (one or a burst) whose signed value jumps by more than ``jump`` away from the in-range sample
    on each side they have. A whole signal in the wrong unit, or one that drifts out of range,
    stays near its neighbours where it crosses the limit and has no such jumps."""
    result = np.zeros(out.shape, dtype=bool)
    if not out.any() or out.all():
        return result
    edges = np.flatnonzero(np.diff(np.r_[0, out.astype(np.int8), 0]))
    for a, b in zip(edges[::2], edges[1::2], strict=True):  # out[a:b] is one run
        sides = [(a, a - 1)] if a > 0 else []
        sides += [(b - 1, b)] if b < out.size else []
        if all(abs(x[i] - x[j]) > jump for i, j in sides):
            result[a:b] = True
    return result


#: A spike jumps by more than this many times the signal's own large steps (:func:`jump_threshold`).
SPIKE_STEP_FACTOR = 5.0


def jump_threshold(check: Check, x: np.ndarray, out: np.ndarray) -> float:
    """The jump that makes an out-of-range run a spike (:func:`spikes`), SI.

    ``SPIKE_STEP_FACTOR`` times the 99th percentile of the signal's steps between in-range
    samples (its own fast motion, noise and quantization: a signal crossing the limit smoothly
    steps no further than that), and at least a floor, so that a signal that hardly moves does
    not make every crossing a spike: a tenth of a "maxabs" check's limit (0.16 rad = 9 deg for a
    flow angle) or of a "minmax" check's span, a hundredth of the per-sample span of the others.
    """
    if check.statistic == "maxabs":
        floor = check.high / 10.0
    elif check.statistic == "minmax":
        floor = (check.high - check.low) / 10.0
    else:
        lo = check.sample_low if check.sample_low is not None else check.low
        hi = check.sample_high if check.sample_high is not None else check.high
        floor = (hi - lo) / 100.0
    inside = ~out[1:] & ~out[:-1]
    steps = np.abs(np.diff(x))[inside]
    steps = steps[np.isfinite(steps)]
    return max(floor, SPIKE_STEP_FACTOR * float(np.quantile(steps, 0.99))) if steps.size else floor


def _scalar(v: np.ndarray) -> np.ndarray:
    """Per-sample values as messages show them: the magnitude of an (N, 3) vector."""
    return np.linalg.norm(v, axis=1) if v.ndim == 2 else v


def _samples_text(values: np.ndarray, unit: str, t_s: np.ndarray, rows: np.ndarray, idx: np.ndarray,
                  limit: int = 5) -> str:
    """The samples ``idx``, a run of consecutive ones as one item: ``"200 deg from t = 1530.000 to
    1531.975 s (data rows 400 to 479, 80 samples)"``."""
    runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1) if idx.size else []
    parts = []
    for r in runs[:limit]:
        i, j = int(r[0]), int(r[-1])
        if r.size == 1:
            parts.append(f"{values[i]:.6g} {unit} {at_row(t_s[i], int(rows[i]))}")
        else:
            lo, hi = float(np.min(values[r])), float(np.max(values[r]))
            val = f"{lo:.6g} {unit}" if lo == hi else f"{lo:.6g} to {hi:.6g} {unit}"
            parts.append(f"{val} from t = {t_s[i]:.3f} to {t_s[j]:.3f} s (data rows {int(rows[i])} to "
                         f"{int(rows[j])}, {r.size} samples)")
    rest = sum(r.size for r in runs[limit:])
    return "; ".join(parts) + (f"; ... ({rest} more sample(s), the last at t = {t_s[idx[-1]]:.3f} s)"
                               if rest else "")


def check_plausible(name: str, label: str, values_si: np.ndarray, unit: str, t_s: np.ndarray,
                    rows: np.ndarray, where: Where, ranges: Ranges | None = None) -> None:
    """Raise :class:`DataError` if ``values_si`` cannot be right in the declared ``unit``.

    A few samples far outside the plausible range that jump away from their neighbours are
    spikes (:func:`spikes`): named with their times, and never taken for a unit mistake (a unit
    is suggested only from the rest of the data).

    Parameters
    ----------
    name : canonical column name (``phi``, ``alpha_zl``, ``t``) or ``"accel"`` for (ax, ay, az).
    label : how the message names the channel and its source column.
    values_si : (N,) values after conversion, or (N, 3) for ``"accel"``.
    unit : the declared unit.
    t_s : (N,) sample times, s (for ``"t"``: the times themselves, SI).
    rows : (N,) data rows of the samples in the file.
    where : file, maneuver and time range.
    ranges : declared plausible ranges (``[plausible]``, :func:`parse_ranges`), SI.
    """
    check = check_for(name, UNITS[unit].dimension)
    declared_here = bool(ranges) and name in ranges
    if declared_here:
        lo, hi, dim = ranges[name]
        if dim != UNITS[unit].dimension:
            raise DataError(f"{where}: {label}: the range declared for it under [plausible] is in "
                            f"{dim} units, the column in {unit!r} ({UNITS[unit].dimension}): give the "
                            "range in a unit of the column's quantity")
        check = declared(check, name, lo, hi)
    if check is None or values_si.size == 0:
        return
    raw_all = from_si(values_si, unit, label)
    spike = out = np.zeros(len(t_s), dtype=bool)
    per = _per_sample(check, values_si)
    if per is not None and name != "t":
        x, lo, hi = per
        out = (x < lo - 1e-9) | (x > hi + 1e-9)
        # jumps on the signed values: -95 deg next to +15 deg is a jump of 110 deg, not 80
        signed = values_si if check.statistic == "maxabs" else x
        spike = spikes(signed, out, jump_threshold(check, signed, out))
    keep = ~spike  # spikes are never part of the statistics a unit is judged by
    v, tk, rk, raw = values_si[keep], t_s[keep], rows[keep], raw_all[keep]
    if v.size and _ok(check, v, tk):
        if spike.any():
            _raise_spikes(check, label, unit, _Recorded(raw_all, t_s, rows), raw, np.flatnonzero(spike),
                          where)
        if per is not None and name != "t":
            x, lo, hi = _per_sample(check, v)
            bad = np.flatnonzero((x < lo - 1e-9) | (x > hi + 1e-9))
            if bad.size:
                raise DataError(
                    f"{where}: {label} has {bad.size} sample(s) outside what {check.what} can be "
                    f"({lo:.4g} to {hi:.4g} in SI, declared unit {unit!r}): "
                    f"{_samples_text(_scalar(raw), unit, tk, rk, bad)}; "
                    "check that the column is the right one, and replace those samples in the file or "
                    "exclude them with the maneuver's t_start_s/t_end_s"
                )
        return
    if out.any() and v.size and _ok(check, to_si(_bulk(check, raw), unit, label), tk):
        # the bulk is plausible in the declared unit: a few samples out of range (spikes that
        # jump less than the threshold, or a short excursion) are the problem, never the unit
        _raise_spikes(check, label, unit, _Recorded(raw_all, t_s, rows), raw_all[~out], np.flatnonzero(out),
                      where, spikes_only=False)
    stat, i = _statistic(check, v, tk)
    raw_stat, _ = _statistic(check, raw, from_si(tk, unit, label) if name == "t" else tk)
    t_of = (lambda q: q) if name == "t" else (lambda q: tk)
    cands = suggest_units(check, raw, unit, t_of)
    stat_text = {
        "maxabs": "largest |value|", "median": "median", "median_step": "median time step",
        "mean_norm": "mean magnitude", "minmax": "value",
    }[check.statistic]
    place = f" {at_row(tk[i], int(rk[i]))}" if check.statistic in ("maxabs", "minmax") else ""
    si_text = "" if UNITS[unit].factor == 1.0 and not UNITS[unit].offset else f" (= {stat:.6g} in SI)"
    lo, hi = check.low, check.high
    hint = (f"the values look like {cands[0]}: set unit = \"{cands[0]}\" for it under [columns]"
            if cands else "check that the column is the right one and that its unit is declared correctly")
    if declared_here:
        hint = ("it is outside the range declared for it under [plausible]: check the data and the "
                "declared range (and the unit of each)")
    elif check.statistic in ("median", "maxabs", "mean_norm") and name != "t":
        # an aircraft outside the built-in ranges (a slow UAV, an agile one rolling at 400 deg/s)
        hint += (f"; if your aircraft really flies there, declare the range under [plausible] "
                 f"({name} = {{ range = [low, high], unit = \"{unit}\" }}, in the problem file or the "
                 "model set)")
    n_spikes = int(spike.sum())
    also = (f" ({n_spikes} spike(s) beyond that left aside: "
            f"{_samples_text(_scalar(raw_all), unit, t_s, rows, np.flatnonzero(spike), 3)})"
            if n_spikes else "")
    raise DataError(
        f"{where}: {label} is declared in {unit!r} but its {stat_text} is {raw_stat:.6g} {unit}"
        f"{place}{si_text}{also}, which cannot be {check.what} (plausible: {lo:.4g} to "
        f"{hi:.4g} in SI); {hint}"
    )


class _Recorded(NamedTuple):
    """A channel's samples as recorded: ``raw`` values in the declared unit ((N,) or (N, 3)), times
    ``t_s`` (N,) and data rows ``rows`` (N,) in the file."""

    raw: np.ndarray
    t_s: np.ndarray
    rows: np.ndarray


def _raise_spikes(check: Check, label: str, unit: str, recorded: _Recorded, raw_rest: np.ndarray,
                  idx: np.ndarray, where: Where, spikes_only: bool = True) -> None:
    """Raise :class:`SpikeError` naming the samples ``idx`` of ``recorded`` (spikes, or with
    ``spikes_only`` False, out-of-range samples some of which may not jump) and the fix;
    ``raw_rest`` is the rest of the channel, plausible in the declared unit."""
    raw_all, t_s, rows = recorded
    shown, rest, what = _scalar(raw_all), _scalar(raw_rest), "magnitude" if raw_all.ndim == 2 else "value"
    rest_text = (f"median {what} {np.median(rest):.4g} {unit}" if check.statistic in ("median", "mean_norm")
                 else f"values {np.min(rest):.4g} to {np.max(rest):.4g} {unit}")
    many = idx.size > SPIKE_MAX_FRACTION * len(t_s)
    kind = ("spike(s), sample(s) that jump far outside" if spikes_only
            else "sample(s) (spikes or a short excursion) outside")
    raise SpikeError(
        f"{where}: {label} has {idx.size} {kind} what "
        f"{check.what} can be: {_samples_text(shown, unit, t_s, rows, idx)}. The rest of it is "
        f"plausible in {unit!r} ({rest_text}), so the unit is not the problem"
        + (f"; that is {100 * idx.size / len(t_s):.1f} % of the samples, more than a few spikes: check "
           "that the column is the right one and was recorded properly. " if many else ". ")
        + "Replace the sample(s) in the file (e.g. by interpolating between their neighbours), or "
        "exclude them from the maneuver with t_start_s/t_end_s (split the maneuver around them)"
    )


#: Speed of sound, m/s, from -70 degC to +45 degC: true airspeed / Mach must fall in here.
SPEED_OF_SOUND_MPS = (260.0, 360.0)


def check_tas_against_mach(tas_si: np.ndarray, mach: np.ndarray, unit: str, label: str,
                           where: Where) -> None:
    """True airspeed over Mach is the speed of sound: a cross-check of the airspeed unit.

    Used where Mach is recorded and above 0.1 (below, the ratio is too noisy to say anything).
    """
    ok = mach > 0.1
    if not np.any(ok):
        return
    a = float(np.median(tas_si[ok] / mach[ok]))
    lo, hi = SPEED_OF_SOUND_MPS
    if lo <= a <= hi:
        return
    raw = from_si(tas_si, unit, label)
    cands = [u for u in units_of("speed") if u != unit
             and lo <= float(np.median(to_si(raw[ok], u, u) / mach[ok])) <= hi]
    hint = (f"the values look like {cands[0]}: set unit = \"{cands[0]}\" for it under [columns]" if cands
            else "check the column and its declared unit, and the Mach column")
    raise DataError(
        f"{where}: {label} is declared in {unit!r}, but true airspeed / Mach has a median of "
        f"{a:.4g} m/s, which is not a speed of sound ({lo:.0f} to {hi:.0f} m/s); {hint}"
    )
