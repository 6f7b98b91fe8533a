"""Planning study (c), its figure: one panel per factor, each sensor group's accuracy against the
level."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from campaigns.studies.tolerance.config import DESIRED_3SIGMA_DEG, SENSOR_GROUPS, Factor
from synth.errors import ErrorConfig


def _typical_flow_delay_ms() -> float:
    """The mean of the typical preset's flow-sensor delays, ms (where "typical" is plotted)."""
    return float(np.mean([1e3 * e.delay_s for e in ErrorConfig.typical().sensors.values()]))


def _panel(ax, f: Factor, rows: pd.DataFrame, variant: bool = False) -> None:
    """Draw one factor's accuracies into ``ax`` (a variant: hollow markers, dashed)."""
    labels = list(rows["level"])
    if f.numeric:
        x = np.array([_typical_flow_delay_ms() if v == "typical" else float(v) for v in labels])
    else:
        x = np.arange(len(labels), dtype=float)
    span = float(np.ptp(x)) if len(x) > 1 else 1.0
    for j, g in enumerate(SENSOR_GROUPS):
        col = f"acc_{g}"
        if col not in rows or not np.isfinite(rows[col].to_numpy(dtype=float)).any():
            continue
        y = rows[col].to_numpy(dtype=float)
        top = rows[f"acc_max_{g}"].to_numpy(dtype=float)
        ax.errorbar(x + (j - 2.5) * 0.006 * span, y, yerr=[np.zeros_like(y), np.maximum(top - y, 0.0)],
                    marker="os^vDP"[j], ms=5, capsize=2, lw=1.2, color=f"C{j}",
                    mfc="none" if variant else f"C{j}",
                    ls="--" if variant else ("-" if g in DESIRED_3SIGMA_DEG else ":"),
                    label=None if variant else g)
    for xi, (_, r) in zip(x, rows.iterrows(), strict=True):
        n_ok, n_failed = int(r.get("n_ok", 0) or 0), int(r.get("n_failed", 0) or 0)
        if n_failed:
            ax.annotate(f"{n_failed}/{n_ok + n_failed} failed" + (" (started at mean)" if variant else ""),
                        (xi, 0.97 if not variant else 0.90), xycoords=("data", "axes fraction"),
                        ha="center", va="top", fontsize=7, color="C3")
        if r["level"] == "typical":
            ax.annotate("typical", (xi, 0.06), xycoords=("data", "axes fraction"), ha="center", fontsize=7)
    if not f.numeric:
        ax.set_xticks(x, labels)


def plot(df: pd.DataFrame, factors: Sequence[Factor], path: Path, replications: int) -> Path:
    """One panel per factor: each sensor group's accuracy (median over the replications, bar to
    the worst) against the level, the desired accuracies as dashed lines; a variant factor (IMU
    biases started at their mean) is drawn in its factor's panel with hollow markers; the last
    panel holds the legend."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import FormatStrFormatter, LogLocator

    shown = [f for f in factors if f.variant_of is None]
    ncol = 3
    nrow = math.ceil((len(shown) + 1) / ncol)
    fig = Figure(figsize=(5.0 * ncol, 4.0 * nrow), layout="constrained")
    FigureCanvasAgg(fig)
    handles: list = []
    for i, f in enumerate(shown):
        ax = fig.add_subplot(nrow, ncol, i + 1)
        _panel(ax, f, df[df["factor"] == f.name])
        title = f.title
        for v in factors:
            if v.variant_of == f.name and (df["factor"] == v.name).any():
                _panel(ax, v, df[df["factor"] == v.name], variant=True)
                title += f"\nhollow, dashed: {v.title.split(', ', 1)[-1]}"
        for req in sorted(set(DESIRED_3SIGMA_DEG.values())):
            ax.axhline(req, color="k", ls="--", lw=0.8)
        ax.set_yscale("log")
        ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.yaxis.set_minor_locator(LogLocator(base=10.0, subs=(2.0, 5.0)))
        ax.yaxis.set_minor_formatter(FormatStrFormatter("%g"))
        ax.tick_params(axis="y", which="minor", labelsize=7)
        ax.set_xlabel(f.title)
        ax.set_ylabel("|mean| + 3 sigma vs truth, deg")
        ax.set_title(title, fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        if len(ax.get_legend_handles_labels()[0]) > len(handles):
            handles = list(zip(*ax.get_legend_handles_labels(), strict=True))
    leg = fig.add_subplot(nrow, ncol, len(shown) + 1)
    leg.axis("off")
    if handles:
        leg.legend([h for h, _ in handles], [lb for _, lb in handles], loc="upper left", fontsize=9,
                   title="calibrated channel (worst of a pair)")
    desired = "\n".join(f"  {g}: {v:g} deg" for g, v in DESIRED_3SIGMA_DEG.items())
    leg.text(0.0, 0.35, f"dashed lines: the desired 3-sigma accuracy\n{desired}\n"
             "dotted: the boom (no stated requirement)\n"
             "red: estimations that failed (no accuracy from them)", fontsize=9, va="top",
             transform=leg.transAxes)
    fig.suptitle("Planning study (c): calibrated-channel accuracy against the truth, median of "
                 f"{replications} replications (bar to the worst)", fontsize=11)
    fig.savefig(path, dpi=100)
    return path
