r"""Cross-correlation of a residual series with an input series, and its standard error.

Used to test a model's assumption that its innovations are independent of an input (the
filter-error method's wind states against the IMU's specific force, :mod:`estimator.filter_error`).

For a series ``x`` sampled at rows ``k_i`` of an input ``u`` on the full grid, the correlation at lag
``j`` (``u`` taken ``j`` samples after ``x``) over the ``n_j`` pairs in range::

    r_j = sum_i (x_i - xbar)(u_{k_i + j} - ubar) / sqrt(sum_i (x_i - xbar)^2 sum_i (u_{k_i + j} - ubar)^2)

If ``x`` and ``u`` are independent and stationary, Bartlett's formula (Bartlett, "On the
theoretical specification and sampling properties of autocorrelated time-series", JRSS Suppl. 8,
1946; Box, Jenkins & Reinsel, *Time Series Analysis*, 4th ed., 2008, §11.1.3) gives its variance::

    var(r_j) = (1 / n_j) sum_{l=-M..M} rho_x(l) rho_u(l)

with ``rho`` the autocorrelations, summed here to ``M`` lags (the input's correlation length after
:func:`high_pass`). For a white ``x`` (the innovations of a right model) this is ``1 / n_j``
whatever the input's colour; a coloured ``x`` widens it, so the test stays honest. Pure numerical
code, no I/O, no state.
"""

from __future__ import annotations

import numpy as np


def high_pass(u: np.ndarray, width: int) -> np.ndarray:
    """``u`` minus its centred moving mean over ``width`` samples (shrinking at the ends).

    Parameters
    ----------
    u : (n,) or (n, m) series on a uniform grid, any unit (per column).
    width : the moving mean's length, samples (odd or even; at least 1).

    Returns
    -------
    Same shape as ``u``: its part faster than about ``1 / (width dt)``.
    """
    if width < 1:
        raise ValueError(f"high_pass: width must be at least 1 sample, got {width}")
    u = np.asarray(u, dtype=float)
    n = u.shape[0]
    c = np.concatenate([np.zeros((1,) + u.shape[1:]), np.cumsum(u, axis=0)])
    half = width // 2
    lo = np.clip(np.arange(n) - half, 0, n)
    hi = np.clip(np.arange(n) - half + width, 0, n)
    count = (hi - lo).reshape((n,) + (1,) * (u.ndim - 1))
    return u - (c[hi] - c[lo]) / count


def _autocorrelation(full: np.ndarray, max_lag: int) -> np.ndarray:
    """Autocorrelation at lags 0..max_lag of a centred series with NaN gaps (pairs both finite)."""
    ok = np.isfinite(full)
    x = np.where(ok, full, 0.0)
    var = float(np.sum(x * x)) / max(int(ok.sum()), 1)
    if var <= 0.0:
        return np.zeros(max_lag + 1)
    # every lag at once: the series against its windows of max_lag + 1 samples (zero-padded)
    pad = np.zeros(max_lag)
    num = x @ np.lib.stride_tricks.sliding_window_view(np.concatenate([x, pad]), max_lag + 1)
    w = ok.astype(float)
    pairs = w @ np.lib.stride_tricks.sliding_window_view(np.concatenate([w, pad]), max_lag + 1)
    return np.where(pairs > 0, num / np.maximum(pairs, 1.0) / var, 0.0)


def lagged_correlation(x: np.ndarray, rows: np.ndarray, u: np.ndarray, lags: np.ndarray,
                       bartlett_lags: int) -> tuple[np.ndarray, np.ndarray]:
    """Correlation of ``x`` with ``u`` at each lag, and its standard error under independence.

    Parameters
    ----------
    x : (n,) the residual series (any unit), at rows ``rows`` of the grid.
    rows : (n,) its sample indices on the input's grid, increasing.
    u : (N,) the input on the full grid (any unit).
    lags : (L,) integer lags, samples: ``u`` taken that many samples after ``x`` (negative: before).
    bartlett_lags : ``M``, the lags summed in Bartlett's variance (module docstring).

    Returns
    -------
    r : (L,) correlations (NaN where fewer than 3 pairs, or a series is constant).
    se : (L,) their standard errors under independence (Bartlett).
    """
    x = np.asarray(x, dtype=float)
    rows = np.asarray(rows, dtype=np.int64)
    u = np.asarray(u, dtype=float)
    N = u.size
    full = np.full(N, np.nan)
    full[rows] = x - np.mean(x)
    M = int(max(0, min(bartlett_lags, N // 4)))
    rho_x = _autocorrelation(full, M)
    rho_u = _autocorrelation(u - np.mean(u), M)
    width = 1.0 + 2.0 * float(np.sum(rho_x[1:] * rho_u[1:]))
    r = np.full(len(lags), np.nan)
    se = np.full(len(lags), np.nan)
    for i, j in enumerate(np.asarray(lags, dtype=np.int64)):
        k = rows + j
        ok = (k >= 0) & (k < N)
        if ok.sum() < 3:
            continue
        a, b = x[ok] - np.mean(x[ok]), u[k[ok]] - np.mean(u[k[ok]])
        den = float(np.sqrt(np.sum(a * a) * np.sum(b * b)))
        if den > 0.0:
            r[i] = float(np.sum(a * b)) / den
            se[i] = float(np.sqrt(max(width, 1e-3) / ok.sum()))
    return r, se
