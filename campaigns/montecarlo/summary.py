"""Summary of a Monte Carlo run: bias, RMSE and scatter against the Cramér-Rao bounds; accuracies.

Per parameter, over the converged replications (display units): the bias (mean of estimate -
truth), the RMSE, the Monte Carlo scatter (standard deviation of estimate - truth: the truth
itself may be drawn), the mean Cramér-Rao and coloured-residual deviations the estimator reported,
and their ratios — 1 when the reported error bars are honest, above 1 when they are optimistic.
Per-maneuver parameters (initial conditions, IMU biases) are also pooled per family through their
z-scores (the standard deviation of z is the same ratio). Per channel, the distribution over
replications of the 3-sigma of the residuals (the paper's Table 2) and of the calibrated channel
against the true flow angle.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .replication import ReplicationResult
from .runner import finished_replications, read_replication, read_state, replication_file

#: the parameter kinds of the calibration proper (shown one by one in the text summary)
CALIBRATION_KINDS = ("time_delay", "bias", "scale", "table")
#: kinds of per-maneuver parameters, shown pooled per family
POOLED_KINDS = ("imu_bias", "initial_condition")


@dataclass(frozen=True)
class MonteCarloSummary:
    """The summary tables of a Monte Carlo run (see the module docstring).

    Attributes
    ----------
    name : the scenario.
    n_ok, n_failed : converged and failed replications summarised.
    parameters : one row per parameter key: kind, unit, n, truth_mean, bias, rmse, mc_std,
        crb_mean, colored_mean, ratio_crb (= mc_std / crb_mean), ratio_colored, z_mean, z_std,
        within_3sigma (fraction of |z_crb| < 3), bias_t (bias / its standard error).
    families : per parameter family (``dax``, ``u0``, ``f1``, ...): instances, n, bias, rmse,
        crb_rms, z_std_crb, z_std_colored, within_3sigma.
    channels : per channel and kind ("residual", "calibrated"): unit, n, median_3sigma,
        p90_3sigma, max_3sigma, median_mean.
    failures : replication, status, message (first line).
    z : the per-replication rows (replication, name, family, kind, error, z_crb, z_colored), for plots.
    """

    name: str
    n_ok: int
    n_failed: int
    parameters: pd.DataFrame
    families: pd.DataFrame
    channels: pd.DataFrame
    failures: pd.DataFrame
    z: pd.DataFrame = field(repr=False)

    def to_pandas(self) -> pd.DataFrame:
        """The per-parameter table, indexed by parameter key."""
        return self.parameters

    def text(self, kinds: tuple[str, ...] = CALIBRATION_KINDS, max_rows: int = 80) -> str:
        """A readable summary: calibration parameters one by one, per-maneuver families pooled,
        channel accuracies, failures."""
        fmt = {"float_format": lambda v: f"{v: .4g}"}
        lines = [f"Monte Carlo {self.name}: {self.n_ok + self.n_failed} replications, {self.n_ok} "
                 f"converged, {self.n_failed} failed"]
        p = self.parameters[self.parameters["kind"].isin(kinds)]
        if len(p):
            cols = ["kind", "unit", "n", "truth_mean", "bias", "rmse", "mc_std", "crb_mean",
                    "colored_mean", "ratio_crb", "ratio_colored", "within_3sigma"]
            shown = p[cols].head(max_rows)
            lines += ["", "parameters (display units): bias and RMSE of estimate - truth, Monte Carlo "
                      "scatter, mean Cramer-Rao and coloured deviations, scatter / mean deviation, "
                      "fraction within 3 CRB sigmas" + (f" (first {max_rows} of {len(p)})"
                                                         if len(p) > max_rows else ""),
                      shown.to_string(**fmt)]
        f = self.families[self.families["kind"].isin(POOLED_KINDS)]
        if len(f):
            lines += ["", "per-maneuver parameters pooled per family (z_std = scatter / deviation):",
                      f.to_string(**fmt)]
        if len(self.channels):
            lines += ["", "channels: 3-sigma over the replications (residual = measurement - model, "
                      "the paper's Table 2; calibrated = calibrated channel - true flow angle):",
                      self.channels.to_string(**fmt)]
        if len(self.failures):
            lines += ["", f"failed replications ({len(self.failures)}):",
                      self.failures.head(20).to_string(index=False)]
        return "\n".join(lines)

    def plot(self, path: str | Path, kinds: tuple[str, ...] = (*CALIBRATION_KINDS, "imu_bias")) -> Path:
        """Scatter / CRB ratios per calibration parameter and z-score histograms per kind (PNG)."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        p = self.parameters[self.parameters["kind"].isin(CALIBRATION_KINDS)]
        kinds = tuple(k for k in kinds if (self.z["kind"] == k).any())
        fig = Figure(figsize=(max(8.0, 0.22 * len(p) + 2.0), 8.0), layout="constrained")
        FigureCanvasAgg(fig)
        grid = fig.add_gridspec(2, max(1, len(kinds)))
        ax = fig.add_subplot(grid[0, :])
        x = np.arange(len(p))
        ax.axhline(1.0, color="0.5", lw=1)
        ax.plot(x, p["ratio_crb"], "o", label="scatter / mean Cramér-Rao std")
        ax.plot(x, p["ratio_colored"], "s", mfc="none", label="scatter / mean coloured-residual std")
        ax.set_xticks(x, p.index, rotation=90, fontsize=7)
        ax.set_ylabel("ratio")
        ax.set_title(f"{self.name}: Monte Carlo scatter against the reported deviations "
                     f"({self.n_ok} replications)")
        ax.legend(loc="upper left", fontsize=8)
        zz = np.linspace(-4, 4, 161)
        for i, kind in enumerate(kinds):
            a = fig.add_subplot(grid[1, i])
            z = self.z.loc[self.z["kind"] == kind, "z_crb"].to_numpy()
            z = z[np.isfinite(z)]
            a.hist(np.clip(z, -6, 6), bins=np.linspace(-6, 6, 49), density=True, color="C0", alpha=0.7)
            a.plot(zz, np.exp(-0.5 * zz**2) / np.sqrt(2 * np.pi), color="k", lw=1)
            a.set_title(f"{kind}: std(z) {np.std(z, ddof=1) if z.size > 1 else np.nan:.2f}", fontsize=9)
            a.set_xlabel("z (Cramér-Rao), clipped to ±6")
        path = Path(path)
        fig.savefig(path, dpi=110)
        return path


def _finite(a) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    return a[np.isfinite(a)]


def _mean(a) -> float:
    a = _finite(a)
    return float(a.mean()) if a.size else np.nan


def _std(a) -> float:
    """Sample standard deviation of the finite values (NaN below two)."""
    a = _finite(a)
    return float(a.std(ddof=1)) if a.size > 1 else np.nan


def _rms(a) -> float:
    a = _finite(a)
    return float(np.sqrt(np.mean(a * a))) if a.size else np.nan


def _within3(z) -> float:
    z = _finite(z)
    return float(np.mean(np.abs(z) < 3.0)) if z.size else np.nan


def _parameter_table(rows: pd.DataFrame) -> pd.DataFrame:
    out = []
    for key, g in rows.groupby("name", sort=False):
        e = g["error"].to_numpy(dtype=float)
        n = int(np.isfinite(e).sum())
        bias, mc_std = _mean(e), _std(e)
        crb_mean, col_mean = _mean(g["std_crb"]), _mean(g["std_colored"])
        out.append({
            "parameter": key, "family": g["family"].iloc[0], "kind": g["kind"].iloc[0],
            "unit": g["unit"].iloc[0], "n": n, "truth_mean": _mean(g["truth"]), "bias": bias,
            "rmse": _rms(e), "mc_std": mc_std, "crb_mean": crb_mean, "colored_mean": col_mean,
            "ratio_crb": mc_std / crb_mean, "ratio_colored": mc_std / col_mean,
            "z_mean": _mean(g["z_crb"]), "z_std": _std(g["z_crb"]), "within_3sigma": _within3(g["z_crb"]),
            # the bias in units of its own standard error: |bias_t| > 3 is a bias the run resolves
            "bias_t": bias / (mc_std / np.sqrt(n)) if n > 1 and mc_std > 0 else np.nan,
        })
    cols = ["parameter", "family", "kind", "unit", "n", "truth_mean", "bias", "rmse", "mc_std", "crb_mean",
            "colored_mean", "ratio_crb", "ratio_colored", "z_mean", "z_std", "within_3sigma", "bias_t"]
    return pd.DataFrame(out, columns=cols).set_index("parameter")


def _family_table(rows: pd.DataFrame) -> pd.DataFrame:
    out = []
    for (fam, kind), g in rows.groupby(["family", "kind"], sort=False):
        e = g["error"].to_numpy(dtype=float)
        out.append({"family": fam, "kind": kind, "unit": g["unit"].iloc[0], "instances": g["name"].nunique(),
                    "n": int(np.isfinite(e).sum()), "bias": _mean(e), "rmse": _rms(e),
                    "crb_rms": _rms(g["std_crb"]), "z_std_crb": _std(g["z_crb"]),
                    "z_std_colored": _std(g["z_colored"]), "within_3sigma": _within3(g["z_crb"])})
    cols = ["family", "kind", "unit", "instances", "n", "bias", "rmse", "crb_rms", "z_std_crb",
            "z_std_colored", "within_3sigma"]
    return pd.DataFrame(out, columns=cols).set_index("family")


def _channel_table(rows: pd.DataFrame) -> pd.DataFrame:
    out = []
    for (name, kind), g in rows.groupby(["name", "kind"], sort=True):
        s = g["three_sigma"].to_numpy()
        out.append({"channel": name, "kind": kind, "unit": g["unit"].iloc[0], "n": len(g),
                    "median_3sigma": float(np.median(s)), "p90_3sigma": float(np.percentile(s, 90)),
                    "max_3sigma": float(np.max(s)), "median_mean": float(np.median(g["mean"]))})
    cols = ["channel", "kind", "unit", "n", "median_3sigma", "p90_3sigma", "max_3sigma", "median_mean"]
    return pd.DataFrame(out, columns=cols).set_index(["channel", "kind"])


def summarize_results(results: list[ReplicationResult], name: str = "") -> MonteCarloSummary:
    """Summarise replication results (finished and failed)."""
    ok = [r for r in results if r.ok]
    failed = [r for r in results if not r.ok]
    params = pd.concat([r.parameters.assign(replication=r.index) for r in ok], ignore_index=True) \
        if ok else pd.DataFrame(columns=["replication", "name", "family", "kind", "unit", "error",
                                         "truth", "std_crb", "std_colored", "z_crb", "z_colored"])
    chans = pd.concat([r.channels.assign(replication=r.index) for r in ok], ignore_index=True) \
        if ok else pd.DataFrame(columns=["name", "kind", "unit", "three_sigma", "mean"])
    failures = pd.DataFrame([{"replication": r.index, "status": r.status,
                              "message": (r.message.splitlines() or [""])[0]} for r in failed],
                            columns=["replication", "status", "message"])
    return MonteCarloSummary(
        name=name, n_ok=len(ok), n_failed=len(failed), parameters=_parameter_table(params),
        families=_family_table(params), channels=_channel_table(chans), failures=failures,
        z=params[["replication", "name", "family", "kind", "error", "z_crb", "z_colored"]].copy())


def load_results(out_dir: str | Path, replications: int | None = None) -> list[ReplicationResult]:
    """Every replication file of a run (of 0..N-1 when ``replications`` is given), in index order."""
    out_dir = Path(out_dir)
    have = finished_replications(out_dir)
    keys = sorted(k for k in have if replications is None or k < replications)
    return [read_replication(replication_file(out_dir, k, failed=have[k] == "failed")) for k in keys]


def summarize(out_dir: str | Path, replications: int | None = None) -> MonteCarloSummary:
    """Summarise the run in ``out_dir`` (every replication file, or those of 0..N-1)."""
    state = read_state(Path(out_dir))
    return summarize_results(load_results(out_dir, replications), name=str(state.get("name", "")))
