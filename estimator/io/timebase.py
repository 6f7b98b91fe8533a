"""Time-base checks: monotonic time, time ranges, NaNs, gaps, uniform sampling, resampling.

The estimator integrates the state equations sample by sample on a uniform grid, so a
maneuver's data must be finite, gap-free and uniformly sampled. Nothing is repaired silently:
non-uniform sampling is resampled only when the problem file asks for it (``resample_hz``).
"""

from __future__ import annotations

import numpy as np

from estimator.io.errors import DataError, Where, at_row

#: A time step larger than this times the median step is a gap (lost samples): an error.
GAP_FACTOR = 1.5
#: Sampling is uniform if every step is within this fraction of the median step.
JITTER_FRACTION = 0.01


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
        raise DataError(
            f"{where}: time column {label} {kind} {at_row(t_s[i], int(rows[i + 1]))} "
            f"({back.size} such step(s) in the file); time must increase strictly: sort the file by "
            "time and drop duplicated rows, or, if the recorder restarted its clock, split the "
            "file at the restart"
        )


def select_range(t_s: np.ndarray, t_start_s: float | None, t_end_s: float | None,
                 where: Where) -> np.ndarray:
    """Indices of the samples with ``t_start_s <= t <= t_end_s`` (None: the file's start/end)."""
    step = float(np.median(np.diff(t_s))) if len(t_s) > 1 else 0.0
    t0 = t_s[0] if t_start_s is None else float(t_start_s)
    t1 = t_s[-1] if t_end_s is None else float(t_end_s)
    if not t1 > t0:
        raise DataError(f"{where}: t_end_s = {t1:.3f} s is not after t_start_s = {t0:.3f} s; fix the range")
    tol = 0.5 * step
    if t0 < t_s[0] - tol or t1 > t_s[-1] + tol:
        raise DataError(
            f"{where}: the requested range is outside the file's time span t = {t_s[0]:.3f} to "
            f"{t_s[-1]:.3f} s; fix t_start_s/t_end_s (are they in the "
            "file's time base, in seconds?)"
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


def check_sampling(t_s: np.ndarray, rows: np.ndarray, where: Where, resample_hz: float | None) -> None:
    """Reject gaps; reject non-uniform sampling unless it is to be resampled."""
    dt = np.diff(t_s)
    step = float(np.median(dt))
    gaps = np.flatnonzero(dt > GAP_FACTOR * step)
    if gaps.size:
        i = int(gaps[0])
        raise DataError(
            f"{where}: gap in the data: no samples between t = {t_s[i]:.3f} s and {t_s[i + 1]:.3f} s "
            f"(data rows {int(rows[i])} to {int(rows[i + 1])}, a step of {dt[i]:.4g} s against the "
            f"median {step:.4g} s; {gaps.size} gap(s) in the maneuver); lost samples cannot be "
            "reconstructed: split the maneuver into ranges on either side of the gap"
        )
    if resample_hz is None:
        jitter = np.abs(dt - step)
        j = int(np.argmax(jitter))
        if jitter[j] > JITTER_FRACTION * step:
            raise DataError(
                f"{where}: non-uniform sampling: the step {at_row(t_s[j], int(rows[j]))} is "
                f"{dt[j]:.6g} s against the median {step:.6g} s (more than "
                f"{100 * JITTER_FRACTION:.0f} % off); the estimator needs a uniform time base. Add "
                f"resample_hz = {1.0 / step:.3g} under this [[files]] entry (or at the top level) to "
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
