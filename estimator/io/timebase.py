"""Time-base checks: monotonic time, time ranges, NaNs, gaps, uniform sampling, resampling.

The estimator integrates the state equations sample by sample on a uniform grid, so a
maneuver's data must be finite, gap-free and uniformly sampled. Nothing is repaired silently:
non-uniform sampling is resampled only when the problem file asks for it (``resample_hz``), and
time stamps that fit a uniform grid but for a recorder's clock resolution or jitter, or but for
their rounding when written (all multiples of 0.01 s, say), are taken as that grid's samples with
a warning that says so.
"""

from __future__ import annotations

import math

import numpy as np

from estimator.io.errors import DataError, Where, at_row, warn
from estimator.io.units import UNITS

#: A time step larger than this times the median step is a gap (lost samples): an error.
GAP_FACTOR = 1.5
#: Sampling is uniform if every step is within this fraction of the median step.
JITTER_FRACTION = 0.01
#: Otherwise, stamps within this fraction of a step of a uniform grid are that grid's samples
#: (a recorder's clock resolution or jitter), taken as such with a warning.
STAMP_TOLERANCE = 0.1
#: Sampling rates recorders use, Hz: the nominal rate is one of these when the stamps fit it.
COMMON_RATES_HZ = (1.0, 2.0, 4.0, 5.0, 8.0, 10.0, 12.5, 16.0, 20.0, 25.0, 32.0, 40.0, 50.0, 60.0, 64.0,
                   80.0, 100.0, 120.0, 125.0, 128.0, 200.0, 250.0, 256.0, 400.0, 500.0, 512.0, 1000.0,
                   1024.0)


#: Ticks time stamps may be rounded to, s, coarsest first: decimal places, and binary clock ticks.
_TICKS_S = tuple(sorted({10.0 ** -d for d in range(7)} | {2.0 ** -m for m in range(1, 21)}, reverse=True))


def stamp_resolution(t_s: np.ndarray) -> float | None:
    """The coarsest tick every stamp is a whole multiple of (0.01 s for time written with 2
    decimals, 1/1024 s for a clock counting 1024 ticks a second), s; None if none of
    :data:`_TICKS_S` fits (stamps written at full precision)."""
    t = np.asarray(t_s, dtype=float)
    t = t[np.isfinite(t)]
    if t.size < 2:
        return None
    eps = 8.0 * np.finfo(float).eps * float(np.max(np.abs(t)))  # the stamps' own float error, s
    for tick in _TICKS_S:
        if eps > 1e-3 * tick:
            break  # finer ticks cannot be told from the float error
        q = t / tick
        if np.max(np.abs(q - np.round(q))) * tick <= 1e-3 * tick + eps:
            return tick
    return None


def _tick_text(tick_s: float) -> str:
    """``"0.01 s"``, ``"1/1024 s"``."""
    d = round(-math.log10(tick_s))
    if abs(tick_s - 10.0 ** -d) < 1e-12 * tick_s:
        return f"{tick_s:.{max(d, 0)}f} s"
    return f"1/{round(1.0 / tick_s)} s"


def check_time(t_s: np.ndarray, rows: np.ndarray, where: Where, label: str) -> None:
    """Time must be finite and strictly increasing over the whole file (range selection needs it)."""
    bad = np.flatnonzero(~np.isfinite(t_s))
    if bad.size:
        i = int(bad[0])
        raise DataError(
            f"{where}: time column {label} has {bad.size} missing/non-numeric value(s), the first in "
            f"data row {int(rows[i])}" + (f" after t = {t_s[i - 1]:.3f} s" if i > 0 else "")
            + "; remove those rows or fill in their time stamps"
        )
    dt = np.diff(t_s)
    back = np.flatnonzero(dt <= 0)
    if back.size:
        i = int(back[0])
        kind = "is duplicated" if dt[i] == 0 else f"goes back to {t_s[i + 1]:.6g} s"
        tick = stamp_resolution(t_s)
        up = dt[dt > 0]
        if dt[i] == 0 and tick is not None and up.size and float(np.median(up)) <= 1.01 * tick:
            # time rounded as coarsely as it advances (40 Hz written to 0.1 s): samples share
            # stamps, and dropping the "duplicated" rows would lose data
            share = int(np.max(np.unique(t_s, return_counts=True)[1]))
            raise DataError(
                f"{where}: time column {label} {kind} {at_row(t_s[i], int(rows[i + 1]))} "
                f"({back.size} repeated stamp(s) in the file, up to {share} samples share one): the "
                f"time is rounded to {_tick_text(tick)}, no finer than the sampling; export the "
                "time with more decimals (the recorder's full resolution)"
            )
        raise DataError(
            f"{where}: time column {label} {kind} {at_row(t_s[i], int(rows[i + 1]))} "
            f"({back.size} such step(s) in the file); time must increase strictly: sort the file by "
            "time and drop duplicated rows, or, if the recorder restarted its clock, split the "
            "file at the restart"
        )


def select_range(t_s: np.ndarray, t_start_s: float | None, t_end_s: float | None,
                 where: Where, label: str = "t", unit: str = "s") -> np.ndarray:
    """Indices of the samples with ``t_start_s <= t <= t_end_s`` (None: the file's start/end).

    ``label`` and ``unit`` name the time column and its declared unit in messages: a range that
    would fit if the time were in another unit says so.
    """
    step = float(np.median(np.diff(t_s))) if len(t_s) > 1 else 0.0
    t0 = t_s[0] if t_start_s is None else float(t_start_s)
    t1 = t_s[-1] if t_end_s is None else float(t_end_s)
    if not t1 > t0:
        raise DataError(f"{where}: t_end_s = {t1:.3f} s is not after t_start_s = {t0:.3f} s; fix the range")
    tol = 0.5 * step
    if t0 < t_s[0] - tol or t1 > t_s[-1] + tol:
        hint = ""
        for other, factor in (("ms", 1e-3), ("s", 1.0)):
            scale = factor / UNITS[unit].factor  # the time in SI if declared in `other`
            if other != unit and t_s[0] * scale - tol * scale <= t0 and t1 <= t_s[-1] * scale + tol * scale:
                hint = (f"; the range fits if the time column {label}, declared in {unit!r}, is in "
                        f"{other!r}: if it is, set unit = \"{other}\" for t under [columns]")
        if not hint and t1 > t_s[-1] + tol and t0 < t_s[-1]:
            hint = (f"; the file ends inside the range, after {t_s.size} rows: if it was cut short, "
                    "copy it whole again")
        raise DataError(
            f"{where}: the requested range is outside the file's time span t = {t_s[0]:.3f} to "
            f"{t_s[-1]:.3f} s (time column {label}){hint}; {'otherwise ' if hint else ''}fix "
            "t_start_s/t_end_s (they are in the file's time base, in seconds)"
        )
    idx = np.flatnonzero((t_s >= t0 - 1e-9 * max(1.0, abs(t0))) & (t_s <= t1 + 1e-9 * max(1.0, abs(t1))))
    if idx.size < 2:
        raise DataError(f"{where}: fewer than 2 samples in t = {t0:.3f} to {t1:.3f} s; widen the range")
    return idx


def check_finite(values: np.ndarray, not_numeric: np.ndarray, raw_text, t_s: np.ndarray,
                 rows: np.ndarray, where: Where, label: str) -> None:
    """Every value of a used column must be a finite number inside the maneuver."""
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size == 0:
        return
    i = int(bad[0])
    what = (f"a non-numeric value {raw_text[i]!r}" if not_numeric[i] else
            "a missing value (NaN/empty)" if np.isnan(values[i]) else f"an infinite value {values[i]}")
    raise DataError(
        f"{where}: {label} has {what} {at_row(t_s[i], int(rows[i]))} ({bad.size} bad sample(s) in "
        f"the maneuver, the last at t = {t_s[bad[-1]]:.3f} s); trim the maneuver's t_start_s/t_end_s "
        "to exclude them, split the maneuver around them, or fix the data"
    )


def _rate_text(rate_hz: float) -> str:
    return f"{rate_hz:.6g}" if abs(rate_hz - round(rate_hz, 3)) < 1e-9 else f"{rate_hz:.4f}"


def grid_deviation(t_s: np.ndarray, rate_hz: float) -> tuple[float, float]:
    """The uniform grid ``t0 + k / rate_hz`` closest to the stamps (least largest deviation):
    its origin ``t0`` and the largest ``|t_k - (t0 + k / rate_hz)|``, s."""
    r = t_s - np.arange(t_s.size) / rate_hz
    lo, hi = float(np.min(r)), float(np.max(r))
    return 0.5 * (lo + hi), 0.5 * (hi - lo)


def _fits(dev_s: float, rate_hz: float, tol_s: float) -> bool:
    """Do stamps off a ``rate_hz`` grid by up to ``dev_s`` fit it: within :data:`STAMP_TOLERANCE`
    of a step, or within ``tol_s`` (half the tick the stamps were rounded to)?"""
    return dev_s <= max(STAMP_TOLERANCE / rate_hz, tol_s)


def nominal_rate(t_s: np.ndarray, tol_s: float = 0.0) -> tuple[float, bool]:
    """The sampling rate the stamps were meant to have, Hz, and whether it is a round one.

    The mean rate (span / (n - 1), which quantized or jittered stamps do not bias, unlike the
    median step) is taken as the nearest of :data:`COMMON_RATES_HZ`, or the nearest whole or half
    hertz, when that one's uniform grid fits every stamp within :data:`STAMP_TOLERANCE` of a step
    (or within ``tol_s``, half the tick rounded stamps are multiples of); else the least-squares
    rate if its grid fits (a drifting clock; False); else, for a suggestion, a round rate within
    1 % of the mean rate, or the mean rate (False).
    """
    n = t_s.size
    mean_hz = (n - 1) / float(t_s[-1] - t_s[0])
    cands = [min(COMMON_RATES_HZ, key=lambda f: abs(math.log(f / mean_hz))), round(mean_hz),
             round(2.0 * mean_hz) / 2.0]
    for f in cands:
        if f > 0 and abs(f / mean_hz - 1.0) < 0.02 and _fits(grid_deviation(t_s, f)[1], f, tol_s):
            return float(f), True
    k = np.arange(n) - 0.5 * (n - 1)
    fit_hz = float(np.sum(k * k) / np.sum(k * (t_s - np.mean(t_s))))  # least-squares step, inverted
    if _fits(grid_deviation(t_s, fit_hz)[1], fit_hz, tol_s):
        return fit_hz, False  # a uniform grid, but not at a round rate (a drifting clock)
    # nothing fits a grid (non-uniform data): still a round rate to suggest if one is close
    for f in cands:
        if f > 0 and abs(f / mean_hz - 1.0) < 0.01:
            return float(f), True
    return mean_hz, False


def check_sampling(t_s: np.ndarray, rows: np.ndarray, where: Where, resample_hz: float | None,
                   label: str = "t") -> np.ndarray:
    """Reject gaps; accept recorder stamps that fit a uniform grid; reject other non-uniform
    sampling unless it is to be resampled.

    ``label`` names the time column in messages.

    Returns
    -------
    The maneuver's sample times: ``t_s`` itself when uniform or to be resampled; the uniform grid
    the stamps fit (:func:`nominal_rate`, with a :class:`DataWarning` saying so) when their steps
    vary by more than :data:`JITTER_FRACTION` but no stamp is more than :data:`STAMP_TOLERANCE` of
    a step off that grid (a recorder's clock resolution or jitter: 1 ms stamps at 64 Hz, a 50 Hz
    recorder counting 1/1024 s ticks), or, for stamps rounded to a tick (:func:`stamp_resolution`:
    40 Hz written to 0.01 s), no more than half that tick off it. Stamps that stray further are
    an error: it names ``resample_hz``, or, when half the tick alone is more than
    :data:`STAMP_TOLERANCE` of a step, says to export the time with more decimals.
    """
    dt = np.diff(t_s)
    step = float(np.median(dt))
    tick = stamp_resolution(t_s)
    # a step of stamps rounded to a tick is off by up to a tick (80 Hz rounded to 0.01 s: steps
    # of 10 and 20 ms, median 10 ms): that is no gap. Their median step is off by up to a tick
    # too (40 Hz rounded to 0.01 s: steps of 20 and 30 ms), their mean step is not
    usual = min(step, float(t_s[-1] - t_s[0]) / (t_s.size - 1))
    gaps = np.flatnonzero(dt > GAP_FACTOR * usual + (tick or 0.0) + 1e-9 * max(1.0, abs(float(t_s[-1]))))
    if gaps.size:
        i = int(gaps[0])
        raise DataError(
            f"{where}: gap in the data (time column {label}): no samples between t = {t_s[i]:.3f} s "
            f"and {t_s[i + 1]:.3f} s "
            f"(data rows {int(rows[i])} to {int(rows[i + 1])}, a step of {dt[i]:.4g} s against the "
            f"usual {usual:.4g} s; {gaps.size} gap(s) in the maneuver); lost samples cannot be "
            "reconstructed: split the maneuver into ranges on either side of the gap"
        )
    jitter = np.abs(dt - step)
    j = int(np.argmax(jitter))
    if resample_hz is not None or jitter[j] <= JITTER_FRACTION * step:
        return t_s
    # stamps rounded to `tick` are up to half a tick off the times they stand for; the float
    # error of the stamps themselves is added so that an exact half tick still fits
    half_tick = 0.0 if tick is None else 0.5 * tick + 64.0 * np.finfo(float).eps * float(np.max(np.abs(t_s)))
    rate, round_rate = nominal_rate(t_s, half_tick)
    t0, dev = grid_deviation(t_s, rate)
    name = f"nominal {_rate_text(rate)} Hz" if round_rate else f"uniform {_rate_text(rate)} Hz"
    if dev <= STAMP_TOLERANCE / rate:
        warn(f"{where}: time stamps of {label} jitter by up to {1e3 * dev:.3g} ms "
             f"({100 * dev * rate:.1f} % of a step) "
             f"around a {name} grid (a recorder's clock resolution or jitter): taken as {name} samples, "
             f"t = {t0:.4f} s + k / {_rate_text(rate)} Hz. If the samples were really taken at their "
             f"stamped times, set resample_hz = {_rate_text(rate)} to interpolate them onto that grid "
             "instead")
        return t0 + np.arange(t_s.size) / rate
    if tick is not None and dev <= half_tick:
        # Every stamp is within half its rounding tick of the grid: the stamps say nothing against
        # a uniform grid, and the grid is the best estimate of the sample times there is (exact if
        # the recorder was uniform). Interpolating from the stamps instead (resample_hz) would
        # move the data by up to half a tick, a fifth of a step at 40 Hz rounded to 0.01 s, which
        # biases the time delays. This holds while the tick is finer than the step (else stamps
        # repeat and check_time refuses them): e.g. 64 Hz rounded to 0.01 s (steps of 15.6 ms,
        # stamps up to 5 ms = 32 % of a step off) is taken as 64 Hz too, and the warning says
        # that jitter below half a tick cannot be seen, and how to check (more decimals).
        warn(f"{where}: time stamps of {label} are rounded to {_tick_text(tick)} (they stray up to "
             f"{1e3 * dev:.3g} ms, "
             f"{100 * dev * rate:.0f} % of a step, from a {name} grid, within the rounding): taken as a "
             f"{name} grid, t = {t0:.4f} s + k / {_rate_text(rate)} Hz. Jitter under "
             f"{1e3 * half_tick:.3g} ms cannot be seen in such stamps: if the recorder's sampling was "
             "not uniform, export the time with more decimals")
        return t0 + np.arange(t_s.size) / rate
    k = int(np.argmax(np.abs(t_s - t0 - np.arange(t_s.size) / rate)))
    head = (f"{where}: non-uniform sampling (time column {label}): the step "
            f"{at_row(t_s[j], int(rows[j]))} is "
            f"{dt[j]:.6g} s against the median {step:.6g} s, and the stamps stray up to {1e3 * dev:.3g} ms "
            f"from a uniform {_rate_text(rate)} Hz grid (at t = {t_s[k]:.3f} s; more than "
            f"{100 * STAMP_TOLERANCE:.0f} % of a step")
    if tick is not None and half_tick > STAMP_TOLERANCE / rate:
        # interpolating from stamps that are themselves up to half a tick off would misplace the
        # samples by more than the stamp tolerance: resample_hz is not the fix, more decimals are
        raise DataError(
            f"{head}, and more than the rounding explains); the time is rounded to {_tick_text(tick)}, "
            f"so each stamp may be {1e3 * half_tick:.3g} ms ({100 * half_tick * rate:.0f} % of a step) "
            "off the time the sample was taken: export the time with more decimals (the recorder's "
            "full resolution); if the stamps then still stray, add "
            f"resample_hz = {_rate_text(rate)} under this [[files]] entry to interpolate the data onto "
            "a uniform grid"
        )
    raise DataError(
        f"{head}); the estimator needs a uniform time base. Add "
        f"resample_hz = {_rate_text(rate)} under this [[files]] entry (or at the top level) to "
        "interpolate the data linearly onto a uniform grid, or resample it yourself"
    )


def resample(t_s: np.ndarray, columns: dict[str, np.ndarray], rate_hz: float,
             where: Where) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Linear interpolation of every column onto ``t_s[0] + k / rate_hz`` within the data's span."""
    if not rate_hz > 0:
        raise DataError(f"{where}: resample_hz = {rate_hz} must be positive")
    n = int(np.floor((t_s[-1] - t_s[0]) * rate_hz + 1e-9)) + 1
    t_new = t_s[0] + np.arange(n) / rate_hz
    return t_new, {k: np.interp(t_new, t_s, v) for k, v in columns.items()}
