"""Figures of one estimation as PNG files, drawn by the report's figure family (:mod:`estimator.report`).

``fpr calibrate --single`` writes them: the time-history match of one maneuver (paper Fig. 3, as the
workflow report's) and a measurement-minus-model cross-plot per flow-angle channel (paper Fig. 5).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd

from estimator.model import Model
from estimator.problem import Problem
from estimator.report import figure_crossplot, figure_time_history, save_png, time_history_maneuver
from estimator.result import EstimationResult


def time_histories(problem: Problem, values: np.ndarray) -> pd.DataFrame:
    """Measured and modelled outputs of every channel and maneuver.

    Parameters
    ----------
    problem : the problem.
    values : (P,) parameter values (e.g. ``result.values``).

    Returns
    -------
    Long table: maneuver, channel, t_s, measured, model (SI units), and the channel's display
    scale and unit.
    """
    model = Model(problem)
    frames = []
    for k, m in enumerate(problem.maneuvers):
        ev = model.evaluate(values, k, jacobian=False)
        for b in ev.blocks:
            ch = problem.channels[b.channel]
            frames.append(pd.DataFrame({
                "maneuver": m.id, "channel": ch.name, "t_s": m.t_s[b.rows], "measured": b.z,
                "model": b.y, "display_scale": ch.display_scale, "display_unit": ch.display_unit,
            }))
    return pd.concat(frames, ignore_index=True)


def _time_history_channels(problem: Problem, hist: pd.DataFrame):
    """The shown maneuver, its time base and ``channel -> (measured, model, unit)`` on it (NaN where a
    channel has no sample: a time-shifted channel loses its edges, an own-rate one has its own)."""
    mid = time_history_maneuver(problem.maneuvers)
    t_all = next(m.t_s for m in problem.maneuvers if m.id == mid)
    h = hist[hist["maneuver"] == mid]
    chans = {}
    for name, g in h.groupby("channel", sort=False):
        idx = np.searchsorted(t_all, g["t_s"].to_numpy())
        z, y = np.full(t_all.shape, np.nan), np.full(t_all.shape, np.nan)
        s = float(g["display_scale"].iloc[0])
        z[idx], y[idx] = g["measured"].to_numpy() * s, g["model"].to_numpy() * s
        chans[name] = (z, y, str(g["display_unit"].iloc[0]))
    return mid, t_all, chans


def save_standard_figures(problem: Problem, result: EstimationResult, directory,
                          record: Callable[[Path], object] | None = None) -> list[str]:
    """Write the time-history match and the flow channels' cross-plots of a result; return the paths.

    ``time_history_match.png`` (one maneuver, a pitch doublet or 3211 if there is one) and
    ``residual_crossplot_<channel>.png`` for each channel that measures a flow angle. ``record`` is
    called with each file's path before it is written (e.g.
    :meth:`estimator.io.outdir.OutputFolder.record`, so the output folder lists what it holds).
    """
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    hist = time_histories(problem, result.values)
    figures = []
    mid, t, chans = _time_history_channels(problem, hist)
    if chans:
        figures.append(("time_history_match.png", figure_time_history(mid, t, chans)))
    for ch in problem.channels:
        g = hist[hist["channel"] == ch.name]
        if ch.measures is None or g.empty:
            continue
        s, unit = float(ch.display_scale), ch.display_unit
        figures.append((f"residual_crossplot_{ch.name}.png", figure_crossplot(
            g["model"].to_numpy() * s, (g["measured"] - g["model"]).to_numpy() * s,
            f"{ch.name}: measurement - model", f"model ({unit})", f"measurement - model ({unit})")))
    paths = []
    for name, fig in figures:
        p = d / name
        if record is not None:
            record(p)
        paths.append(str(save_png(fig, p, close=True)))
    return paths
