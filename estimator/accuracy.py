"""Table 2's numbers: the 3-sigma accuracy of a channel and its usable alpha range (paper §4, Fig. 7).

``three_sigma(e) = 3 sqrt(mean(e^2))``: 3 x the rms about zero, so that a mean offset is an error
too (the paper's Table 2 states the desired accuracy as +-3 sigma). A channel whose error grows with
the angle of attack (the nose probe's sideslip, paper Fig. 7) is usable up to the highest alpha to
which every alpha band, from the lowest, keeps its 3 sigma within the desired accuracy
(:func:`alpha_limit`). Pure functions of SI-or-display arrays as their parameters say; the workflow
(Table 2) and the fit-quality diagnostics (is a residual beyond the usable range?) share them.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

__all__ = ["alpha_limit", "three_sigma"]


def three_sigma(e: np.ndarray) -> float:
    """3 x the rms about zero (a mean offset is an error too)."""
    return float(3.0 * np.sqrt(np.mean(np.square(e)))) if e.size else math.nan


def alpha_limit(alpha_deg: np.ndarray, err_deg: np.ndarray, desired_deg: float, band_deg: float,
                min_samples: int) -> tuple[pd.DataFrame, float | None]:
    """3 sigma of an error in alpha bands and the highest alpha up to which every band passes.

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
        s = three_sigma(err_deg[sel])
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


