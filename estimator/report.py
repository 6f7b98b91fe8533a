"""The calibration report: the paper's figures and Table 2 as one self-contained HTML file.

The renderer of the calibration workflow (SPEC §8; paper §4, Figs. 3-8, Table 2). It knows nothing
of the estimator, the synthesizer or JSBSim: it takes plain arrays and pandas DataFrames whose
schemas are documented per function, so it renders real flight data (where there is no truth) the
same way as a synthetic campaign (where optional truth columns add open "truth" markers).

Figures are built object-oriented on :class:`matplotlib.figure.Figure` and rendered through the Agg
canvas, so importing this module never changes the caller's pyplot backend and no figure is
registered with pyplot (nothing leaks when callers forget to close).

:func:`write_report` writes ``report.html`` (PNG figures embedded as base64 data URIs, inline CSS,
no external resource) and the CSV files beside it.
"""

from __future__ import annotations

import base64
import html
import io
import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import quote

import numpy as np
import pandas as pd

if TYPE_CHECKING:  # matplotlib is imported where a figure is drawn: a report without plots needs none
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "Banner",
    "CrossplotSampling",
    "ReportStyle",
    "Section",
    "accuracy_table_html",
    "figure_bias_vs_mach",
    "figure_crossplot",
    "figure_table_updates",
    "figure_time_history",
    "save_png",
    "time_history_maneuver",
    "write_report",
]

#: resolution of embedded and saved PNGs [dots per inch]; ~110 keeps 10-inch figures legible on
#: screen while a report with a dozen figures stays a few MB
DEFAULT_DPI = 110.0
#: crossplots draw at most this many points; the statistics always use all of them
DEFAULT_MAX_POINTS = 50_000
#: rows of a DataFrame shown in the HTML; the rest are in its CSV
DEFAULT_MAX_TABLE_ROWS = 60

_MEASURED_COLOR = "0.45"
_MODEL_COLOR = "tab:red"
_LIMIT_COLOR = "tab:red"


# --------------------------------------------------------------------------------------------------
# helpers


def _new_figure(width_in: float, height_in: float) -> Figure:
    """A Figure on the Agg canvas with constrained layout.

    Parameters
    ----------
    width_in, height_in : figure size [inch].
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _require_columns(frame: pd.DataFrame, columns: Sequence[str], what: str) -> None:
    """Raise a ValueError naming the missing columns of ``frame`` (described as ``what``)."""
    if not isinstance(frame, pd.DataFrame):
        raise TypeError(f"{what}: expected a pandas DataFrame, got {type(frame).__name__}")
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise ValueError(f"{what}: missing column(s) {missing}; present: {list(frame.columns)}")
    if frame.empty:
        raise ValueError(f"{what}: the frame has no rows")


def _has_values(frame: pd.DataFrame, column: str) -> bool:
    """True if ``column`` exists and holds at least one finite number."""
    return column in frame.columns and bool(np.isfinite(pd.to_numeric(frame[column], errors="coerce")).any())


def _style_axes(ax: Axes) -> None:
    ax.grid(alpha=0.3)
    ax.tick_params(labelsize=8)


def _dodge(k: int, n: int, width: float) -> float:
    """Offset of series ``k`` of ``n`` spread evenly over ``width`` centred on zero.

    Used to keep the error bars of series sharing x values from hiding each other; the spread is a
    small fraction of the x spacing, so values are still read at their breakpoint / Mach number.
    """
    return 0.0 if n <= 1 else (k / (n - 1) - 0.5) * width


def _min_spacing(values: np.ndarray) -> float:
    """Smallest positive difference between distinct sorted values (1.0 if there is none)."""
    u = np.unique(values[np.isfinite(values)])
    d = np.diff(u)
    return float(d.min()) if d.size else 1.0


# --------------------------------------------------------------------------------------------------
# figures


def figure_time_history(
    maneuver_id: str,
    t_s: np.ndarray,
    channels: Mapping[str, tuple[np.ndarray, np.ndarray, str]],
) -> Figure:
    """Measured against model output for one maneuver, one subplot per channel (paper Fig. 3).

    Parameters
    ----------
    maneuver_id : the maneuver's name, shown in the title.
    t_s : (N,) time [s].
    channels : ``label -> (measured, model, unit)``: two (N,) arrays on ``t_s`` in display units
        (``unit``, e.g. "deg", "m/s", "m"). NaN marks a missing sample: a channel recorded at its own,
        slower rate (e.g. a 10 Hz DGPS height on a 40 Hz base) is drawn through its samples.

    Returns
    -------
    The figure: one axes per channel, in the mapping's order, with a measured and a model line; the
    title of each axes gives the rms of measured minus model [unit].
    """
    t = np.asarray(t_s, dtype=float)
    if t.ndim != 1 or t.size == 0:
        raise ValueError(f"{maneuver_id}: t_s must be a non-empty 1-D array, got shape {t.shape}")
    if not channels:
        raise ValueError(f"{maneuver_id}: no channels to plot")
    fig = _new_figure(10.0, 1.55 * len(channels) + 0.9)
    axes = fig.subplots(len(channels), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (label, (measured, model, unit)) in zip(axes, channels.items(), strict=True):
        z = np.asarray(measured, dtype=float)
        y = np.asarray(model, dtype=float)
        if z.shape != t.shape or y.shape != t.shape:
            raise ValueError(
                f"{maneuver_id}, channel {label!r}: measured {z.shape} and model {y.shape} must have the "
                f"shape of t_s {t.shape}"
            )
        # connect the finite samples only: NaN would break the line into invisible single points for
        # a slow channel whose samples sit between NaNs on the common time base
        fz, fy = np.isfinite(z), np.isfinite(y)
        ax.plot(t[fz], z[fz], color=_MEASURED_COLOR, lw=1.0, label="measured")
        ax.plot(t[fy], y[fy], color=_MODEL_COLOR, lw=0.9, label="model")
        both = fz & fy
        if both.any():
            rms = float(np.sqrt(np.mean((z[both] - y[both]) ** 2)))
            ax.set_title(f"rms(measured - model) = {rms:.3g} {unit}", loc="right", fontsize=7.5)
        ax.set_ylabel(f"{label}\n[{unit}]", fontsize=8.5)
        _style_axes(ax)
    axes[0].legend(loc="upper left", fontsize=7.5, ncol=2, framealpha=0.8)
    axes[-1].set_xlabel("time [s]", fontsize=9)
    fig.suptitle(f"{maneuver_id}: time-history match, measured vs model", fontsize=10)
    return fig


def figure_wind_history(maneuver_id: str, t_s: np.ndarray, wind_ned_mps: np.ndarray,
                        std_ned_mps: np.ndarray, reference_ned_mps: np.ndarray | None = None,
                        reference_label: str = "truth") -> Figure:
    """The filter-error method's smoothed turbulent wind of one maneuver, north, east and down.

    Parameters
    ----------
    maneuver_id : the maneuver's name, shown in the title.
    t_s : (N,) time, s.
    wind_ned_mps : (N, 3) the smoothed wind (the departure from the maneuver's steady wind), NED, m/s.
    std_ned_mps : (N, 3) its smoothed standard deviations, m/s (a +- 1 sigma band).
    reference_ned_mps : (N, 3) a wind to compare with (the truth of a synthetic flight), on the same
        footing (the same mean removed), or None; each axis' title gives the rms difference.
    reference_label : its legend label.
    """
    t = np.asarray(t_s, dtype=float)
    w = np.asarray(wind_ned_mps, dtype=float)
    s = np.asarray(std_ned_mps, dtype=float)
    if w.shape != (t.size, 3) or s.shape != (t.size, 3):
        raise ValueError(f"{maneuver_id}: wind {w.shape} and std {s.shape} must be ({t.size}, 3)")
    fig = _new_figure(10.0, 5.2)
    axes = fig.subplots(3, 1, sharex=True, squeeze=False)[:, 0]
    for i, (ax, axis) in enumerate(zip(axes, ("north", "east", "down"), strict=True)):
        ax.fill_between(t, w[:, i] - s[:, i], w[:, i] + s[:, i], color=_MODEL_COLOR, alpha=0.2, lw=0)
        ax.plot(t, w[:, i], color=_MODEL_COLOR, lw=0.9, label="estimated (+- 1 sigma)")
        if reference_ned_mps is not None:
            r = np.asarray(reference_ned_mps, dtype=float)[:, i]
            ax.plot(t, r, color=_MEASURED_COLOR, lw=0.9, label=reference_label)
            rms = float(np.sqrt(np.mean((w[:, i] - r) ** 2)))
            ax.set_title(f"rms(estimated - {reference_label}) = {rms:.3g} m/s", loc="right",
                         fontsize=7.5)
        ax.set_ylabel(f"wind {axis}\n[m/s]", fontsize=8.5)
        _style_axes(ax)
    axes[0].legend(loc="upper left", fontsize=7.5, ncol=2, framealpha=0.8)
    axes[-1].set_xlabel("time [s]", fontsize=9)
    fig.suptitle(f"{maneuver_id}: turbulent wind, filter-error method", fontsize=10)
    return fig


#: Fig. 3 shows a maneuver of these kinds if there is one (the paper's is a pitch doublet). Maneuver
#: kinds are the flight-test programme's vocabulary (a dataset entry's ``kind``), not the aircraft's.
TIME_HISTORY_KINDS = ("pitch_doublet", "3211")


def time_history_maneuver(maneuvers: Sequence) -> str:
    """The id of the maneuver the time-history figure shows: the first whose ``meta["kind"]`` is one
    of :data:`TIME_HISTORY_KINDS`, else the first (``maneuvers``: objects with ``id`` and ``meta``)."""
    return next((m.id for m in maneuvers if m.meta.get("kind") in TIME_HISTORY_KINDS), maneuvers[0].id)


def figure_bias_vs_mach(bias: pd.DataFrame, reference_mach: float | None = None, *,
                        bias_label: str = "mean bias") -> Figure:
    """Mean vane bias (Tejas: ``(b_l + b_r)/2``) against Mach per aircraft, and the fleet mean (Fig. 4).

    The fleet mean per Mach (the unweighted mean over the aircraft at that Mach) is the update to the
    correction model; each aircraft's distance from it is its installation bias (SPEC §8).

    Parameters
    ----------
    bias : one row per aircraft and Mach bin, columns
        ``mach`` (float, [-]), ``aircraft`` (str), ``mean_bias_deg`` ((b_l + b_r)/2 [deg]),
        ``std_deg`` (its standard deviation [deg], drawn as +-1 sigma error bars; NaN: none), and
        optionally ``true_mean_bias_deg`` ([deg], drawn as open markers "truth").
    reference_mach : if given, a vertical line marks the Mach number at which the installation biases
        are fixed [-].
    bias_label : what the mean bias is, for the axis label and title (matplotlib mathtext allowed,
        e.g. ``"$(b_l + b_r)/2$"``).

    Returns
    -------
    The figure: one axes; one errorbar line per aircraft, the fleet mean as a thick black line.
    """
    _require_columns(bias, ["mach", "aircraft", "mean_bias_deg", "std_deg"], "bias vs Mach")
    b = bias.copy()
    b["aircraft"] = b["aircraft"].astype(str)
    aircraft = list(dict.fromkeys(b["aircraft"]))
    mach = b["mach"].to_numpy(dtype=float)
    width = 0.25 * _min_spacing(mach)
    from matplotlib import colormaps
    from matplotlib.lines import Line2D

    colors = colormaps["tab10"]
    with_truth = _has_values(b, "true_mean_bias_deg")

    fig = _new_figure(7.6, 4.4)
    ax = fig.subplots()
    for k, name in enumerate(aircraft):
        g = b[b["aircraft"] == name].sort_values("mach")
        x = g["mach"].to_numpy(dtype=float) + _dodge(k, len(aircraft), width)
        std = g["std_deg"].to_numpy(dtype=float)
        ax.errorbar(x, g["mean_bias_deg"].to_numpy(dtype=float),
                    yerr=np.where(np.isfinite(std), std, 0.0), color=colors(k % 10), marker="o", ms=5,
                    lw=1.1, capsize=2.5, label=name)
        if with_truth:
            ax.plot(x, g["true_mean_bias_deg"].to_numpy(dtype=float), ls="none", marker="o", ms=9,
                    mfc="none", mec=colors(k % 10), mew=1.2)
    fleet = b.groupby("mach", sort=True)["mean_bias_deg"].mean()
    ax.plot(fleet.index.to_numpy(dtype=float), fleet.to_numpy(dtype=float), color="black", lw=2.4,
            marker="D", ms=5, label="fleet mean (model update)", zorder=5)
    ax.axhline(0.0, color="0.6", lw=0.8)
    if reference_mach is not None:
        ax.axvline(reference_mach, color="0.35", lw=1.0, ls=":")
        ax.annotate(f"installation biases\nfixed at M = {reference_mach:g}", (reference_mach, 1.0),
                    xycoords=("data", "axes fraction"), xytext=(4, -4), textcoords="offset points",
                    va="top", fontsize=7.5, color="0.3")
    # aircraft first, then the fleet mean (get_legend_handles_labels lists lines before error bars)
    handles, labels = ax.get_legend_handles_labels()
    order = sorted(range(len(labels)), key=lambda i: labels[i] not in aircraft)
    handles, labels = [handles[i] for i in order], [labels[i] for i in order]
    if with_truth:
        handles.append(Line2D([], [], ls="none", marker="o", ms=9, mfc="none", mec="0.3", mew=1.2))
        labels.append("truth (open markers)")
    ax.legend(handles, labels, fontsize=8, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    ax.set_xlabel("Mach number [-]", fontsize=9)
    ax.set_ylabel(f"{bias_label} [deg]", fontsize=9)
    ax.set_title(f"mean vane bias {bias_label} per aircraft (error bars $\\pm 1\\sigma$)", fontsize=10)
    _style_axes(ax)
    return fig


@dataclass(frozen=True)
class CrossplotSampling:
    """What :func:`figure_crossplot` draws of a large cloud.

    Attributes
    ----------
    max_points : at most this many points are drawn, a deterministic random subsample (the raster
        stays small); the statistics in the figure use every finite point.
    bins : the abscissa's range is cut into this many equal bins; the mean +- 3 sigma of the error in
        each bin holding at least 20 points is drawn, which shows how the scatter grows with the
        angle where a cloud of 1e5 points saturates.
    """

    max_points: int = DEFAULT_MAX_POINTS
    bins: int = 20


def figure_crossplot(
    x_deg: np.ndarray,
    err_deg: np.ndarray,
    title: str,
    xlabel: str,
    ylabel: str,
    limit_deg: float | None = None,
    x_limit_deg: float | None = None,
    *,
    sampling: CrossplotSampling = CrossplotSampling(),  # noqa: B008 (frozen, so one shared default is safe)
) -> Figure:
    """Error against flow angle, the paper's cross-plots (Figs. 5 and 7).

    Parameters
    ----------
    x_deg : (N,) the abscissa, an angle [deg] (e.g. the model output, or the true angle).
    err_deg : (N,) the error [deg] (measurement - model, or calibrated - truth).
    title, xlabel, ylabel : texts of the axes (put the units in the labels).
    limit_deg : desired 3-sigma accuracy [deg]; drawn as +-limit lines.
    x_limit_deg : usable limit of the abscissa [deg] (e.g. the nose probe's AOA limit); a vertical line.
    sampling : the points drawn and the envelope's bins (:class:`CrossplotSampling`).

    Returns
    -------
    The figure: one axes, the scatter (rasterized) plus the bin envelope and limit lines.
    """
    max_points, bins = sampling.max_points, sampling.bins
    x = np.asarray(x_deg, dtype=float).ravel()
    e = np.asarray(err_deg, dtype=float).ravel()
    if x.shape != e.shape:
        raise ValueError(f"{title}: x_deg {x.shape} and err_deg {e.shape} differ in length")
    ok = np.isfinite(x) & np.isfinite(e)
    x, e = x[ok], e[ok]
    if x.size == 0:
        raise ValueError(f"{title}: no finite (x, error) pair to plot")
    n = x.size
    mean, three_sigma = float(e.mean()), 3.0 * float(e.std())

    fig = _new_figure(6.4, 4.4)
    ax = fig.subplots()
    shown = np.arange(n)
    if n > max_points:
        # a fixed seed: the same data give the same picture, and unlike a stride a random subsample
        # cannot alias with the maneuvers' periodic inputs
        shown = np.sort(np.random.default_rng(0).choice(n, size=max_points, replace=False))
    ax.scatter(x[shown], e[shown], s=2.0, marker=".", linewidths=0, alpha=0.35, color="tab:blue",
               rasterized=True, label=f"samples ({shown.size:,} of {n:,} shown)" if shown.size < n else
               f"samples ({n:,})")

    edges = np.linspace(x.min(), x.max(), bins + 1) if x.max() > x.min() else np.array([])
    if edges.size:
        idx = np.clip(np.digitize(x, edges) - 1, 0, bins - 1)
        count = np.bincount(idx, minlength=bins)
        s1 = np.bincount(idx, weights=e, minlength=bins)
        s2 = np.bincount(idx, weights=e * e, minlength=bins)
        full = count >= 20
        if full.any():
            m = s1[full] / count[full]
            sd = np.sqrt(np.maximum(s2[full] / count[full] - m * m, 0.0))
            xc = 0.5 * (edges[:-1] + edges[1:])[full]
            ax.plot(xc, m + 3.0 * sd, color="black", lw=1.0, label=r"mean $\pm 3\sigma$ per bin")
            ax.plot(xc, m - 3.0 * sd, color="black", lw=1.0)
    ax.axhline(0.0, color="0.5", lw=0.8)
    if limit_deg is not None:
        ax.axhline(limit_deg, color=_LIMIT_COLOR, lw=1.2, ls="--", label=f"desired $\\pm${limit_deg:g} deg")
        ax.axhline(-limit_deg, color=_LIMIT_COLOR, lw=1.2, ls="--")
    if x_limit_deg is not None:
        ax.axvline(x_limit_deg, color="tab:purple", lw=1.2, ls=":", label=f"usable limit {x_limit_deg:g} deg")
    ax.text(0.01, 0.98, f"n = {n:,}   mean = {mean:.3f} deg   3$\\sigma$ = {three_sigma:.3f} deg",
            transform=ax.transAxes, va="top", fontsize=8,
            bbox={"boxstyle": "round", "fc": "white", "ec": "0.7", "alpha": 0.9})
    # keep the limits in view even when the errors are far inside them
    if limit_deg is not None:
        lo, hi = ax.get_ylim()
        ax.set_ylim(min(lo, -1.25 * limit_deg), max(hi, 1.25 * limit_deg))
    ax.legend(fontsize=7.5, loc="lower left", markerscale=6, framealpha=0.85)
    ax.set_xlabel(xlabel, fontsize=9)
    ax.set_ylabel(ylabel, fontsize=9)
    ax.set_title(title, fontsize=10)
    _style_axes(ax)
    return fig


def figure_table_updates(updates: pd.DataFrame, *, max_columns: int = 3) -> Figure:
    """Correction-table updates against breakpoint, one line per Mach and gear (paper Figs. 6 and 8).

    Parameters
    ----------
    updates : one row per table, breakpoint, Mach bin and gear position, columns
        ``table`` (str, e.g. "f1"), ``breakpoint_deg`` (the table's argument at the breakpoint [deg]),
        ``mach`` (float [-]), ``gear`` ("up" or "down"), ``value`` (the update, display units),
        ``std`` (its standard deviation, display units; +-1 sigma error bars), ``unit`` (str, the
        display unit of value and std, one per table), and optionally ``truth`` (display units,
        drawn as open markers).
    max_columns : subplots per row [-].

    Returns
    -------
    The figure: one axes per table in order of appearance; Mach is the colour, gear down is dashed.
    """
    cols = ["table", "breakpoint_deg", "mach", "gear", "value", "std", "unit"]
    _require_columns(updates, cols, "table updates")
    u = updates.copy()
    u["table"] = u["table"].astype(str)
    u["gear"] = u["gear"].astype(str).str.lower()
    bad_gear = sorted(set(u["gear"]) - {"up", "down"})
    if bad_gear:
        raise ValueError(f"table updates: gear must be 'up' or 'down', got {bad_gear}")
    tables = list(dict.fromkeys(u["table"]))
    machs = np.sort(u["mach"].astype(float).unique())
    from matplotlib import colormaps
    from matplotlib.lines import Line2D

    # one colour per Mach shared by every subplot; the colormap's pale yellow end is left out
    cmap = colormaps["viridis"]
    color = {m: cmap(0.85 * k / max(len(machs) - 1, 1)) for k, m in enumerate(machs)}
    with_truth = _has_values(u, "truth")

    ncols = min(len(tables), max_columns)
    nrows = math.ceil(len(tables) / ncols)
    fig = _new_figure(4.4 * ncols + 1.6, 3.5 * nrows + 0.5)
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    for ax in axes[len(tables):]:
        ax.set_visible(False)
    for ax, name in zip(axes, tables, strict=False):
        g = u[u["table"] == name]
        units = list(dict.fromkeys(g["unit"].astype(str)))
        if len(units) != 1:
            raise ValueError(f"table updates: table {name!r} has several units {units}")
        series = list(g.groupby(["gear", "mach"], sort=True).groups)
        series.sort(key=lambda gm: (gm[0] != "up", gm[1]))
        width = 0.3 * _min_spacing(g["breakpoint_deg"].to_numpy(dtype=float))
        for k, (gear, mach) in enumerate(series):
            s = g[(g["gear"] == gear) & (g["mach"] == mach)].sort_values("breakpoint_deg")
            x = s["breakpoint_deg"].to_numpy(dtype=float) + _dodge(k, len(series), width)
            std = s["std"].to_numpy(dtype=float)
            down = gear == "down"
            ax.errorbar(x, s["value"].to_numpy(dtype=float), yerr=np.where(np.isfinite(std), std, 0.0),
                        color=color[mach], ls="--" if down else "-", marker="s" if down else "o", ms=4,
                        lw=1.2, capsize=2.0, label=f"M {mach:.2f}, gear {gear}")
            if with_truth:
                ax.plot(x, s["truth"].to_numpy(dtype=float), ls="none", marker="o", ms=8, mfc="none",
                        mec=color[mach], mew=1.0)
        ax.axhline(0.0, color="0.6", lw=0.8)
        ax.set_title(f"{name} update", fontsize=10)
        ax.set_xlabel("breakpoint [deg]", fontsize=9)
        ax.set_ylabel(f"{name} update [{units[0]}]", fontsize=9)
        _style_axes(ax)
    # one legend for the whole figure: every subplot uses the same Mach colours and line styles
    handles, labels = [], []
    for ax in axes[: len(tables)]:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    order = sorted(range(len(labels)), key=lambda i: (" down" in labels[i], labels[i]))
    handles, labels = [handles[i] for i in order], [labels[i] for i in order]
    if with_truth:
        handles.append(Line2D([], [], ls="none", marker="o", ms=8, mfc="none", mec="0.3"))
        labels.append("truth (open markers)")
    fig.legend(handles, labels, loc="outside right center", fontsize=7.5, frameon=False)
    fig.suptitle(r"correction-table updates (error bars $\pm 1\sigma$; gear down dashed)", fontsize=10)
    return fig


def save_png(fig: Figure, path: str | Path, dpi: float = DEFAULT_DPI, close: bool = False) -> Path:
    """Write ``fig`` as a PNG file.

    Parameters
    ----------
    fig : the figure.
    path : the file; its directory is created.
    dpi : resolution [dots per inch].
    close : close the figure afterwards (leave it open to embed it in a report too).

    Returns
    -------
    The path written.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_bytes(_png_bytes(fig, dpi))
    if close:
        _close(fig)
    return p


def _png_bytes(fig: Figure, dpi: float) -> bytes:
    buf = io.BytesIO()
    # metadata without the matplotlib version: the same figure gives the same bytes on any install
    fig.savefig(buf, format="png", dpi=dpi, metadata={"Software": None})
    return buf.getvalue()


def _close(fig: Figure) -> None:
    """Release a figure; one made through pyplot is also removed from pyplot's registry."""
    import matplotlib.pyplot as plt  # only here: the module itself never needs pyplot's state

    plt.close(fig)
    fig.clear()


# --------------------------------------------------------------------------------------------------
# tables


def accuracy_table_html(acc: pd.DataFrame, title: str) -> str:
    """The 3-sigma accuracy per sensor and Mach against the desired accuracy (paper Table 2), as HTML.

    Parameters
    ----------
    acc : one row per sensor and Mach bin, columns ``sensor`` (str, e.g. "vane AOA left"),
        ``channel`` (str), ``mach`` (float [-]), ``n`` (int, samples), ``three_sigma_deg`` (3 sigma of
        the error [deg]; NaN: not available), ``desired_deg`` (the desired 3-sigma accuracy [deg]),
        ``passed`` (bool), ``note`` (str, may be empty); optionally ``gear`` ("up"/"down": a
        gear-down bin gets its own column beside the gear-up one of the same Mach) and ``judged``
        (bool: False greys the cell and marks it "?", its note says why).

    title : the table's caption.

    Returns
    -------
    An HTML ``<table class="acc">``: rows are sensors in order of appearance, columns the Mach bins and
    "desired ±"; each cell holds 3 sigma [deg] with class ``pass`` or ``fail`` (``na`` if missing) and
    a tooltip with the channel, n and the note. Notes are listed under the table. The CSS is in
    :func:`write_report`'s page; put ``acc`` itself in a :class:`Section`'s ``csv`` to keep the long
    form.
    """
    cols = ["sensor", "channel", "mach", "n", "three_sigma_deg", "desired_deg", "passed", "note"]
    _require_columns(acc, cols, "accuracy table")
    a = acc.copy()
    a["sensor"] = a["sensor"].astype(str)
    a["mach"] = a["mach"].astype(float)
    a["gear"] = a["gear"].astype(str) if "gear" in a else "up"
    dup = a[a.duplicated(["sensor", "mach", "gear"], keep=False)]
    if not dup.empty:
        pairs = sorted(set(zip(dup["sensor"], dup["mach"], dup["gear"], strict=True)))
        raise ValueError(f"accuracy table: several rows for (sensor, Mach, gear) {pairs}")

    def label(mach: float, down: bool) -> str:
        return f"M {mach:.2f}" + (" gear down" if down else "")

    a["col"] = [label(m, g == "down") for m, g in zip(a["mach"], a["gear"], strict=True)]
    sensors = list(dict.fromkeys(a["sensor"]))
    machs = [label(m, d) for m, d in sorted(set(zip(a["mach"], a["gear"] == "down", strict=True)))]
    e = html.escape

    out = [f'<table class="acc">\n<caption>{e(title)}</caption>\n<thead><tr><th>sensor</th>'
           "<th>channel</th>"]
    out += [f"<th>{e(m).replace(' gear', '<br>gear')}</th>" for m in machs]
    out.append("<th>desired ±<br>[deg]</th></tr></thead>\n<tbody>\n")
    notes: list[str] = []
    for sensor in sensors:
        rows = a[a["sensor"] == sensor].set_index("col")
        channels = ", ".join(dict.fromkeys(rows["channel"].astype(str)))
        out.append(f"<tr><th>{e(sensor)}</th><td class=\"ch\">{e(channels)}</td>")
        for m in machs:
            if m not in rows.index:
                out.append('<td class="na">—</td>')
                continue
            r = rows.loc[m]
            value = float(r["three_sigma_deg"])
            note = "" if pd.isna(r["note"]) else str(r["note"])
            mark = ""
            if note:
                notes.append(f"{sensor}, {m}: {note}")
                mark = f"<sup>{len(notes)}</sup>"
            n = int(r["n"]) if pd.notna(r["n"]) else 0
            tip = f"{r['channel']}; n = {n:,}" + (f"; {note}" if note else "")
            if not np.isfinite(value) or pd.isna(r["passed"]):
                cls, text = "na", "—"
            elif not bool(r.get("judged", True)):
                cls, text = "na", f"{value:.2f}?"
            else:
                cls, text = ("pass" if bool(r["passed"]) else "fail"), f"{value:.2f}"
            out.append(f'<td class="{cls}" title="{e(tip)}">{text}{mark}</td>')
        desired = ", ".join(f"{d:g}" for d in dict.fromkeys(rows["desired_deg"].astype(float)))
        out.append(f'<td class="desired">{e(desired)}</td></tr>\n')
    out.append("</tbody>\n</table>\n")
    out.append('<p class="legend"><span class="pass">green</span>: 3&sigma; within the desired accuracy; '
               '<span class="fail">red</span>: exceeds it; ?: not judged (its note says why); — no data. '
               'Cells: 3&sigma; [deg].</p>\n')
    if notes:
        out.append('<ol class="notes">' + "".join(f"<li>{e(n)}</li>" for n in notes) + "</ol>\n")
    return "".join(out)


# --------------------------------------------------------------------------------------------------
# the report


@dataclass(frozen=True)
class Banner:
    """The verdict at the top of the report.

    Attributes
    ----------
    level : "success", "warning" or "failure" (its colour).
    headline : one line, e.g. "FAILURE: do not use these estimates".
    lines : the reasons, one per line (failures first).
    """

    level: str
    headline: str
    lines: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.level not in ("success", "warning", "failure"):
            raise ValueError(f"Banner.level must be success, warning or failure, got {self.level!r}")


@dataclass(frozen=True)
class Section:
    """One section of the report, rendered in this order: text, tables, figures, CSV links.

    Attributes
    ----------
    title : the section's heading (plain text).
    text : plain text; blank lines separate paragraphs, single newlines break lines (escaped).
    tables : ``(caption, table)``: a DataFrame (rendered, at most ``max_table_rows`` rows shown) or
        an already rendered HTML string (e.g. from :func:`accuracy_table_html`, inserted as is); an
        empty caption is left out.
    figures : ``(caption, figure)``: embedded as PNG, the figure is closed afterwards.
    csv : ``(file name, frame)``: written to ``out_dir/<file name>`` (a plain name ending in .csv) and
        linked; the index is written too unless it is a plain RangeIndex.
    """

    title: str
    text: str = ""
    tables: Sequence[tuple[str, pd.DataFrame | str]] = ()
    figures: Sequence[tuple[str, Figure]] = ()
    csv: Sequence[tuple[str, pd.DataFrame]] = ()


_CSS = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; color: #222;
       max-width: 1180px; margin: 0 auto; padding: 0 1.5em 3em; line-height: 1.45; }
header { border-bottom: 2px solid #345; margin-bottom: 1em; }
header h1 { margin-bottom: 0.2em; }
header p { color: #666; margin-top: 0; }
nav ol { columns: 2; }
h2 { border-bottom: 1px solid #ccc; padding-bottom: 0.2em; margin-top: 2em; }
figure { margin: 1em 0; }
figure img { max-width: 100%; height: auto; border: 1px solid #ddd; }
figcaption, caption, p.caption { font-size: 0.92em; color: #444; text-align: left; padding: 0.3em 0; }
table { border-collapse: collapse; margin: 0.6em 0; font-size: 0.88em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; }
thead th { background: #eef1f5; }
td { text-align: right; font-variant-numeric: tabular-nums; }
table.acc th { text-align: left; }
table.acc td.ch { text-align: left; color: #555; }
.pass { background: #c8ecc9; }
.fail { background: #f8c4c4; font-weight: bold; }
.na { background: #f1f1f1; color: #888; text-align: center; }
td.desired { background: #fafafa; font-weight: bold; }
p.legend span { padding: 0 0.3em; }
p.note, ol.notes { font-size: 0.88em; color: #555; }
ul.csv { font-size: 0.92em; }
.tablewrap { overflow-x: auto; }
div.verdict { border: 2px solid; border-radius: 4px; padding: 0.5em 1em; margin: 1em 0; }
div.verdict h2 { border: none; margin: 0.2em 0; }
div.verdict.success { border-color: #2e7d32; background: #e8f5e9; }
div.verdict.warning { border-color: #e6a100; background: #fff8e1; }
div.verdict.failure { border-color: #c62828; background: #ffebee; }
div.verdict li { font-size: 0.92em; }
"""


def _banner_html(banner: Banner | None, max_lines: int) -> str:
    if banner is None:
        return ""
    e = html.escape
    items = "".join(f"<li>{e(line)}</li>" for line in banner.lines[:max_lines])
    more = len(banner.lines) - max_lines
    if more > 0:
        items += f"<li>... and {more} more (all in findings.csv)</li>"
    return (f'<div class="verdict {banner.level}"><h2>{e(banner.headline)}</h2>'
            + (f"<ul>{items}</ul>" if items else "") + "</div>\n")


def _paragraphs(text: str) -> str:
    blocks = [b.strip("\n") for b in re.split(r"\n\s*\n", text) if b.strip()]
    return "".join(f"<p>{html.escape(b).replace(chr(10), '<br>')}</p>\n" for b in blocks)


def _check_csv_name(name: str) -> None:
    if Path(name).name != name or name in {"", ".", ".."} or not name.lower().endswith(".csv"):
        raise ValueError(f"CSV file name {name!r} must be a plain file name ending in .csv (no directory)")
    if name == "report.html":
        raise ValueError("CSV file name must not be report.html")


def _slug(text: str) -> str:
    s = re.sub(r"[^A-Za-z0-9]+", "-", text).strip("-").lower()
    return s[:40] or "table"


def _write_csv(frame: pd.DataFrame, path: Path) -> None:
    # a default RangeIndex carries nothing; any other index (e.g. a named one) is data and is kept
    keep_index = not isinstance(frame.index, pd.RangeIndex) or frame.index.name is not None
    frame.to_csv(path, index=keep_index)


def _frame_html(frame: pd.DataFrame, float_format: Callable[[float], str], max_rows: int) -> str:
    shown = frame.head(max_rows)
    keep_index = not isinstance(frame.index, pd.RangeIndex) or frame.index.name is not None
    return shown.to_html(float_format=float_format, index=keep_index, border=0, na_rep="—",
                         classes="data", escape=True)


@dataclass(frozen=True)
class ReportStyle:
    """How :func:`write_report` renders.

    Attributes
    ----------
    dpi : resolution of the embedded PNGs [dots per inch].
    float_format : formats floats in DataFrame tables.
    max_banner_lines : reasons shown in the banner (the rest are counted).
    """

    dpi: float = DEFAULT_DPI
    float_format: Callable[[float], str] = "{:.4g}".format
    max_banner_lines: int = 25


class _CsvFiles:
    """The report's CSV files, each written once (``record`` called with its path first)."""

    def __init__(self, out: Path, record: Callable[[Path], object] | None) -> None:
        self.out = out
        self.record = record
        self.written: dict[str, pd.DataFrame] = {}

    def put(self, name: str, frame: pd.DataFrame) -> None:
        """Write ``frame`` as ``name`` (a second, different frame under one name raises)."""
        _check_csv_name(name)
        if not isinstance(frame, pd.DataFrame):
            raise TypeError(f"CSV {name!r}: expected a DataFrame, got {type(frame).__name__}")
        written = self.written
        if name in written and written[name] is not frame and not written[name].equals(frame):
            # two sections claiming one file name would silently lose one of the frames
            raise ValueError(f"CSV file name {name!r} is used for two different frames")
        written[name] = frame
        if self.record is not None:
            self.record(self.out / name)
        _write_csv(frame, self.out / name)


def _table_html(i: int, j: int, sec: Section, csv_files: _CsvFiles, csv_names: list[str],
                style: ReportStyle, max_table_rows: int) -> str:
    """The ``j``-th table of section ``i``: its HTML, a long one's first rows pointing at the CSV
    holding all of them (written here when the section has none of the same frame)."""
    e = html.escape
    caption, table = sec.tables[j - 1]
    parts = ['<div class="tablewrap">\n']
    if caption:
        parts.append(f'<p class="caption">{e(caption)}</p>\n')
    if isinstance(table, str):
        # already rendered by the caller (e.g. accuracy_table_html): inserted as is
        parts.append(f"{table}</div>\n")
        return "".join(parts)
    if not isinstance(table, pd.DataFrame):
        raise TypeError(f"section {sec.title!r}, table {caption!r}: expected a DataFrame or an "
                        f"HTML string, got {type(table).__name__}")
    parts.append(f"{_frame_html(table, style.float_format, max_table_rows)}\n")
    if len(table) > max_table_rows:
        name = next((n for n, f in sec.csv if f is table), None)
        if name is None:
            name = f"s{i}-table{j}-{_slug(caption)}.csv"
            csv_files.put(name, table)
            csv_names.append(name)
        parts.append(f'<p class="note">first {max_table_rows} rows shown (all {len(table):,} rows '
                     f'in <a href="{quote(name)}">{e(name)}</a>)</p>\n')
    parts.append("</div>\n")
    return "".join(parts)


def _section_html(i: int, sec: Section, csv_files: _CsvFiles, style: ReportStyle, max_table_rows: int
                  ) -> str:
    """Section ``i``'s HTML (its CSV files written): text, tables, figures, the list of its CSVs."""
    e = html.escape
    anchor = f"s{i}"
    parts = [f'<section id="{anchor}">\n<h2>{i}. {e(sec.title)}</h2>\n']
    if sec.text:
        parts.append(_paragraphs(sec.text))
    # the section's CSV first, so a long table can point at the file holding the same frame
    csv_names: list[str] = []
    for name, frame in sec.csv:
        csv_files.put(name, frame)
        csv_names.append(name)
    for j in range(1, len(sec.tables) + 1):
        parts.append(_table_html(i, j, sec, csv_files, csv_names, style, max_table_rows))
    for caption, fig in sec.figures:
        data = base64.b64encode(_png_bytes(fig, style.dpi)).decode("ascii")
        _close(fig)
        parts.append(f'<figure><img src="data:image/png;base64,{data}" alt="{e(caption)}">'
                     f"<figcaption>{e(caption)}</figcaption></figure>\n")
    if csv_names:
        written = csv_files.written
        parts.append('<ul class="csv">' + "".join(
            f'<li><a href="{quote(n)}">{e(n)}</a> ({len(written[n]):,} rows)</li>' for n in csv_names)
            + "</ul>\n")
    parts.append("</section>\n")
    return "".join(parts)


def write_report(
    out_dir: str | Path,
    title: str,
    sections: Sequence[Section],
    *,
    max_table_rows: int = DEFAULT_MAX_TABLE_ROWS,
    banner: Banner | None = None,
    record: Callable[[Path], object] | None = None,
    style: ReportStyle = ReportStyle(),  # noqa: B008 (frozen, so one shared default is safe)
) -> Path:
    """Write the report: ``out_dir/report.html`` and the sections' CSV files.

    The HTML is one self-contained file (inline CSS, figures as base64 PNG data URIs, no external
    resource): a header with the title and the generation time (UTC), a table of contents and the
    sections in order. Every text is escaped. A DataFrame table longer than ``max_table_rows`` shows
    its first rows and a link to the CSV holding all of them (the section's own CSV of the same frame
    if there is one, else a CSV written for it).

    Parameters
    ----------
    out_dir : the directory, created if needed; existing files of the same names are replaced.
    title : the report's title.
    sections : the sections, in order.
    max_table_rows : rows of a DataFrame shown in the HTML.
    banner : the verdict, shown above everything else.
    record : called with each file's path before it is written (e.g.
        :meth:`estimator.io.outdir.OutputFolder.record`, so the output folder lists what it holds).
    style : the figures' resolution, the tables' float format and the banner's length
        (:class:`ReportStyle`).

    Returns
    -------
    The path of ``report.html``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    e = html.escape
    csv_files = _CsvFiles(out, record)
    body: list[str] = []
    toc: list[str] = []
    for i, sec in enumerate(sections, start=1):
        toc.append(f'<li><a href="#s{i}">{e(sec.title)}</a></li>')
        body.append(_section_html(i, sec, csv_files, style, max_table_rows))

    now = datetime.now(UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    page = (
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
        f"<title>{e(title)}</title>\n<style>{_CSS}</style>\n</head>\n<body>\n"
        f"<header><h1>{e(title)}</h1><p>generated {now}</p></header>\n"
        + _banner_html(banner, style.max_banner_lines)
        + f"<nav><h2>Contents</h2><ol>{''.join(toc)}</ol></nav>\n"
        + "".join(body)
        + "</body>\n</html>\n"
    )
    path = out / "report.html"
    if record is not None:
        record(path)
    path.write_text(page, encoding="utf-8")
    return path
