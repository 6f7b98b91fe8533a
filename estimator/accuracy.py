r"""Table 2's numbers: the 3-sigma accuracy of a channel and its usable alpha range (paper §4, Fig. 7).

``three_sigma(e) = 3 sqrt(mean(e^2))``: 3 x the rms about zero, so that a mean offset is an error
too (the paper's Table 2 states the desired accuracy as +-3 sigma). A channel whose error grows with
the angle of attack (the nose probe's sideslip, paper Fig. 7) is usable up to the highest alpha to
which every alpha band, from the lowest, keeps its 3 sigma within the desired accuracy
(:func:`alpha_limit`). Pure functions of SI-or-display arrays as their parameters say; the workflow
(Table 2) and the fit-quality diagnostics (is a residual beyond the usable range?) share them.

**Table 2 is the accuracy of the calibrated channel**, not the scatter of its residual alone. The
residual ``e = z - y(theta_hat)`` cannot see an error of the calibration itself: an offset
estimated 0.1 deg off moves the model output and the reconstructed flow alike and leaves ``e``
unchanged, while the channel's true error grows by 0.1 deg. So Table 2 adds the calibration's own
uncertainty, propagated to the channel at each sample (:func:`calibration_variance`)::

    three_sigma = 3 sqrt(mean(e^2) + mean(s_cal^2)),      s_cal^2(t) = J_c(t) C J_c(t)^T

``J_c(t)`` the sensitivity of the channel's model output to its own calibration parameters
(biases, scale factors, tables, time delay) at sample ``t``, ``C`` their covariance (the
estimation's honest one). With no calibration uncertainty (``s_cal = 0``) it is the scatter of the
residual, to the bit. Under the filter-error method the residual is taken against the model plus
the turbulent wind smoothed from the other sensors, an estimate whose own error the residual holds
and the sensor does not: its variance ``s_w^2`` is taken out first,
``3 sqrt(max(mean(e^2) - mean(s_w^2), 0) + mean(s_cal^2))``.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

__all__ = ["alpha_limit", "calibration_variance", "three_sigma"]


def three_sigma(e: np.ndarray, calibration_var: np.ndarray | None = None,
                wind_var: np.ndarray | None = None) -> float:
    """3 x the rms about zero (a mean offset is an error too), with the calibration's own variance.

    ``3 sqrt(mean(e^2) + mean(s_cal^2))`` (module docstring); with ``wind_var``,
    ``3 sqrt(max(mean(e^2) - mean(s_w^2), 0) + mean(s_cal^2))``.

    Parameters
    ----------
    e : (n,) error samples (measurement minus model), any unit.
    calibration_var : (n,) the calibration's own variance ``s_cal^2`` at the same samples
        (:func:`calibration_variance`), ``e``'s unit squared; None: the scatter of ``e`` alone
        (a channel without calibration uncertainty gives the same number to the bit).
    wind_var : (n,) filter-error method: the variance ``s_w^2`` of the turbulent wind's response
        that ``e`` was corrected by (the wind smoothed from the other sensors), ``e``'s unit
        squared. ``e`` holds that estimate's own error and the sensor does not: it is taken out of
        the residual's mean square (never below zero). None: nothing taken out.

    Returns
    -------
    3 sigma in ``e``'s unit; NaN without samples.
    """
    if not e.size:
        return math.nan
    ms = np.mean(np.square(e))
    for name, var in (("calibration_var", calibration_var), ("wind_var", wind_var)):
        if var is not None and np.shape(var) != np.shape(e):
            raise ValueError(f"three_sigma: {name} has shape {np.shape(var)}, the errors "
                             f"{np.shape(e)}: give one variance per error sample")
    if wind_var is not None:
        ms = max(ms - np.mean(wind_var), 0.0)
    if calibration_var is not None:
        # adding an exact 0.0 leaves the mean square as it was: no calibration term, the old value
        ms = ms + np.mean(calibration_var)
    return float(3.0 * np.sqrt(ms))


def calibration_variance(J: np.ndarray, C: np.ndarray) -> np.ndarray:
    r"""The calibration's own variance of a channel's model output at each sample.

    ``s_cal^2(t) = J_c(t) C J_c(t)^T``: the first-order propagation of the calibration parameters'
    estimation error to the channel (module docstring). The residual cannot show this part of the
    channel's error (the measurement minus model is blind to an error of the model's own
    parameters that the fit shares out consistently), so Table 2 adds it.

    Parameters
    ----------
    J : (n, m) ``J_c``: the derivative of the channel's model output at each of ``n`` samples with
        respect to its ``m`` calibration parameters, the channel's SI unit per parameter SI unit
        (rad/rad for a bias, rad per unit for a scale factor, rad/s for a time delay).
    C : (m, m) the covariance of those parameters' estimates, SI squared (symmetric, positive
        semi-definite; zero rows and columns for a parameter held without a deviation).

    Returns
    -------
    (n,) ``s_cal^2``, the channel's SI unit squared, never negative (round-off of a semi-definite
    ``C`` clipped to 0).

    Raises
    ------
    ValueError
        The shapes do not agree.
    """
    J = np.asarray(J, dtype=float)
    C = np.asarray(C, dtype=float)
    if J.ndim != 2 or C.shape != (J.shape[1], J.shape[1]):
        raise ValueError(f"calibration_variance: J must be (n, m) and C (m, m), got {J.shape} and {C.shape}")
    # row-wise J C J^T without forming the (n, n) matrix
    return np.maximum(np.einsum("ij,ij->i", J @ C, J), 0.0)


def alpha_limit(alpha_deg: np.ndarray, err_deg: np.ndarray, desired_deg: float, band_deg: float,
                min_samples: int, calibration_var_deg2: np.ndarray | None = None,
                wind_var_deg2: np.ndarray | None = None) -> tuple[pd.DataFrame, float | None]:
    """3 sigma of an error in alpha bands and the highest alpha up to which every band passes.

    ``calibration_var_deg2``: (n,) the calibration's own variance at the samples, deg^2
    (:func:`three_sigma`: each band's 3 sigma is Table 2's, the residual's scatter and the
    calibration's uncertainty); None: the scatter of ``err_deg`` alone. ``wind_var_deg2``: the
    filter-error wind response's variance taken out of it (:func:`three_sigma`).

    Returns
    -------
    (bands, limit): bands has alpha_lo_deg, alpha_hi_deg, n, three_sigma_deg, passed; limit is the
    upper edge of the last passing band counted from the lowest (None without judged bands).
    """
    if alpha_deg.size == 0:
        return pd.DataFrame(columns=["alpha_lo_deg", "alpha_hi_deg", "n", "three_sigma_deg", "passed"]), None
    edges = np.arange(math.floor(alpha_deg.min() / band_deg) * band_deg,
                      alpha_deg.max() + band_deg, band_deg)
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        sel = (alpha_deg >= lo) & (alpha_deg < hi)
        n = int(sel.sum())
        s = three_sigma(err_deg[sel], None if calibration_var_deg2 is None else calibration_var_deg2[sel],
                        None if wind_var_deg2 is None else wind_var_deg2[sel])
        rows.append({"alpha_lo_deg": float(lo), "alpha_hi_deg": float(hi), "n": n, "three_sigma_deg": s,
                     "passed": bool(n >= min_samples and s <= desired_deg) if n >= min_samples else None})
    bands = pd.DataFrame(rows)
    limit = None
    for r in bands.itertuples():
        if r.passed is None:
            continue
        if not r.passed:
            break
        limit = r.alpha_hi_deg
    return bands, limit


