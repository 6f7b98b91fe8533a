"""Figures of an estimation: time-history matches (paper Fig. 3) and residual cross-plots.

Each function returns a matplotlib Figure (Agg backend; nothing is shown) so callers choose where
it goes: a PNG file, an HTML report, a notebook.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from estimator.model import Model  # noqa: E402
from estimator.problem import Problem  # noqa: E402
from estimator.result import EstimationResult  # noqa: E402


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


def plot_time_history_match(
    histories: pd.DataFrame,
    channels: Sequence[str] | None = None,
    maneuvers: Sequence[str] | None = None,
    max_maneuvers: int = 18,
    title: str = "",
):
    """Measured vs model for several maneuvers laid end to end (paper Fig. 3).

    Parameters
    ----------
    histories : from :func:`time_histories`.
    channels : channels to show (default: all present).
    maneuvers : maneuvers to show (default: the first ``max_maneuvers``).
    """
    h = histories
    chans = list(channels) if channels else list(dict.fromkeys(h["channel"]))
    mans = list(maneuvers) if maneuvers else list(dict.fromkeys(h["maneuver"]))[:max_maneuvers]
    h = h[h["maneuver"].isin(mans) & h["channel"].isin(chans)]
    fig, axes = plt.subplots(len(chans), 1, figsize=(12, 1.6 * len(chans) + 0.8), sharex=True,
                             squeeze=False)
    # lay maneuvers end to end on a running time axis, as the paper's figure does
    offsets, t0 = {}, 0.0
    for mid in mans:
        span = h.loc[h["maneuver"] == mid, "t_s"]
        if span.empty:
            continue
        offsets[mid] = t0 - span.min()
        t0 += span.max() - span.min() + 2.0
    for ax, ch in zip(axes[:, 0], chans, strict=True):
        d = h[h["channel"] == ch]
        if d.empty:
            ax.set_visible(False)
            continue
        s = d["display_scale"].iloc[0]
        for mid, g in d.groupby("maneuver", sort=False):
            t = g["t_s"] + offsets.get(mid, 0.0)
            ax.plot(t, g["measured"] * s, color="0.55", lw=0.8)
            ax.plot(t, g["model"] * s, color="tab:red", lw=0.8)
        ax.set_ylabel(f"{ch}\n[{d['display_unit'].iloc[0]}]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(["measured", "model"], loc="upper right", fontsize=7, ncol=2)
    axes[-1, 0].set_xlabel("time, maneuvers end to end [s]")
    fig.suptitle(title or f"time-history match, {len(offsets)} maneuvers", fontsize=10)
    fig.tight_layout()
    return fig


def plot_residual_crossplot(histories: pd.DataFrame, channels: Sequence[str], title: str = ""):
    """Measurement minus model against the model output (paper Figs. 5, 7), with 3-sigma lines."""
    fig, axes = plt.subplots(1, len(channels), figsize=(4.2 * len(channels), 3.6), squeeze=False)
    for ax, ch in zip(axes[0], channels, strict=True):
        d = histories[histories["channel"] == ch]
        if d.empty:
            ax.set_visible(False)
            continue
        s = d["display_scale"].iloc[0]
        err = (d["measured"] - d["model"]) * s
        ax.plot(d["model"] * s, err, ".", ms=1.0, alpha=0.4, color="tab:blue")
        three = 3.0 * err.std()
        for y in (-three, three):
            ax.axhline(y, color="tab:red", lw=0.8, ls="--")
        unit = d["display_unit"].iloc[0]
        ax.set_xlabel(f"{ch} model [{unit}]", fontsize=8)
        ax.set_ylabel(f"measured - model [{unit}]", fontsize=8)
        ax.set_title(f"{ch}: 3 sigma = {three:.3f} {unit}", fontsize=9)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def save_standard_figures(problem: Problem, result: EstimationResult, directory,
                          record: Callable[[Path], object] | None = None) -> list[str]:
    """Write the time-history match and cross-plots of a result as PNG files; returns the paths.

    ``record`` is called with each file's path before it is written (e.g.
    :meth:`estimator.io.outdir.OutputFolder.record`, so the output folder lists what it holds).
    """
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    hist = time_histories(problem, result.values)
    paths = []
    fig = plot_time_history_match(hist, title=f"time-history match — {problem.source}")
    p = d / "time_history_match.png"
    if record is not None:
        record(p)
    fig.savefig(p, dpi=110)
    plt.close(fig)
    paths.append(str(p))
    flow = [c for c in dict.fromkeys(hist["channel"]) if c.startswith(("alpha_", "beta_"))]
    if flow:
        fig = plot_residual_crossplot(hist, flow, title="measurement minus model")
        p = d / "residual_crossplots.png"
        if record is not None:
            record(p)
        fig.savefig(p, dpi=110)
        plt.close(fig)
        paths.append(str(p))
    return paths
