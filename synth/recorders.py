"""Recorders (DRU, INS, DGPS) and the preprocessing onto one common time base.

Timing model (SPEC §2, §6; paper §3)
------------------------------------
A recorder with rate ``f``, latency ``d`` and clock offset ``o`` stamps its samples at
``t_k = k / f`` on its own clock (which reads true time + ``o``). A channel with extra lag ``tau``
(sensor or channel delay) recorded at stamp ``t_k`` holds the signal at true time::

    t_true = t_k - o - d - tau            y_k = y(t_true)   (linear interpolation of the truth)

so a delay lags (``y(t - tau)``, tau > 0) and a clock offset shifts every channel of its recorder.
An ideal recorder (rate ``None``) samples exactly on the common time base. Preprocessing, as the
paper's extraction tool: every stream is resampled by its own stamps (linear interpolation;
zero-order hold for discrete flags) onto ``t_c = j / f_c``, over the overlap of all streams.
The analyst's time axis is the stamps; the truth is given at true time = ``t_c``.

Pure kernels: arrays in seconds, no I/O, no state.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import CubicHermiteSpline

#: Tolerance on sample-time comparisons, s (far below any sample period).
TIME_EPS_S = 1e-9


def sample_at(t_truth_s: np.ndarray, y: np.ndarray, t_query_s: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``y`` ((N,) or (N, k), sampled at ``t_truth_s``) at ``t_query_s``."""
    y = np.asarray(y, dtype=float)
    if y.ndim == 1:
        return np.interp(t_query_s, t_truth_s, y)
    return np.stack([np.interp(t_query_s, t_truth_s, y[:, j]) for j in range(y.shape[1])], axis=1)


def average_at(t_truth_s: np.ndarray, y: np.ndarray, t_query_s: np.ndarray,
               window_s: float) -> np.ndarray:
    """Mean of ``y`` over ``[t - window, t]`` at each query time (what a strapdown IMU outputs).

    A strapdown IMU reports the velocity and angle increments of each sample interval, i.e. the
    mean specific force and rate over it, not a point sample: point-sampling a signal with
    content above the sample rate aliases it, which the flight-path integration would then see
    as a velocity error. The mean lags the signal by half the window (its group delay).
    """
    y = np.asarray(y, dtype=float)
    dt = np.diff(t_truth_s).reshape((-1,) + (1,) * (y.ndim - 1))
    cum = np.concatenate([np.zeros((1,) + y.shape[1:]),
                          np.cumsum(0.5 * (y[1:] + y[:-1]) * dt, axis=0)])
    # the running integral's derivative is y itself: Hermite interpolation between truth samples
    # keeps the window ends accurate to the trapezoidal rule's order
    spline = CubicHermiteSpline(t_truth_s, cum, y, axis=0)
    lo = spline(t_query_s - window_s)
    hi = spline(t_query_s)
    return (hi - lo) / window_s


def allowed_stamp_interval_s(t_first_s: float, t_last_s: float, clock_offset_s: float,
                             lags_s: np.ndarray) -> tuple[float, float]:
    """Stamps at which every channel (lags ``lags_s`` = latency + channel delays) has truth."""
    lags = np.asarray(lags_s, dtype=float)
    return (t_first_s + clock_offset_s + float(lags.max()),
            t_last_s + clock_offset_s + float(lags.min()))


def grid_in_interval_s(lo_s: float, hi_s: float, rate_hz: float) -> np.ndarray:
    """Sample times ``k / rate`` within ``[lo, hi]`` (to :data:`TIME_EPS_S`)."""
    k0 = math.ceil(lo_s * rate_hz - TIME_EPS_S * rate_hz)
    k1 = math.floor(hi_s * rate_hz + TIME_EPS_S * rate_hz)
    return np.arange(k0, k1 + 1) / rate_hz


def resample_linear(stamps_s: np.ndarray, values: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """Resample a stream onto ``t_s`` by linear interpolation in its stamps."""
    return sample_at(stamps_s, values, t_s)


def resample_hold(stamps_s: np.ndarray, values: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """Resample a discrete stream onto ``t_s``: the latest sample stamped at or before each time."""
    idx = np.searchsorted(stamps_s, np.asarray(t_s) + TIME_EPS_S, side="right") - 1
    return np.asarray(values)[np.clip(idx, 0, len(stamps_s) - 1)]
