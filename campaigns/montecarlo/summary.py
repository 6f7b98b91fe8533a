"""Summary of a Monte Carlo run: bias, RMSE and scatter against the Cramér-Rao bounds; accuracies.

Which replications count. The statistics are taken over the replications whose estimator verdict
is a success (with or without warnings); those with a failure verdict, or that raised, are
counted per verdict and left out. Within them, a parameter counts only in the replications that
*estimated* it (a finite Cramér-Rao deviation): one the estimator held at its start value (no data,
undetermined) has no deviation to judge it by, and its start-minus-truth is no estimation error,
so every statistic of a parameter — bias, RMSE, scatter, mean deviations, z-scores — is taken over
the same replications, and ``n_not_estimated`` says how many were left out.

Per parameter (display units): the bias (mean of estimate - truth), the RMSE, the Monte Carlo
scatter (standard deviation of estimate - truth: the truth itself may be drawn), the mean
Cramér-Rao and coloured-residual deviations the estimator reported, and their ratios — 1 when the
reported error bars are honest, above 1 when they are optimistic. Per-maneuver parameters (initial
conditions, IMU biases) are also pooled per family through their z-scores (the standard deviation
of z is the same ratio). Per parameter kind (imu_bias, time_delay, bias, scale, table,
initial_condition): the fraction of estimates within 3 reported deviations (Cramér-Rao and
coloured) of their truth, the z-score standard deviations and median |z|. Per channel, the
distribution over replications of the 3-sigma accuracy — :func:`estimator.workflow.three_sigma`,
3 x the rms about zero, computed by the replication — of the residuals (their scatter: Table 2's
``scatter_three_sigma_deg``, without the calibration's own uncertainty that Table 2 adds and that
the calibrated rows measure) and of the calibrated channel against the true flow angle. The time
a replication took comes from the run's ``timings.csv`` (kept apart from the replication files,
which stay bit-identical).

The files. :func:`write_summary` writes :data:`SUMMARY_FILES` into the run folder (or another
folder) and records them, with their sizes and SHA-256, in :data:`SUMMARY_LISTING` there
(:func:`estimator.io.outdir.prepare_files`): a later summary replaces exactly those files, and a
file of one of those names that the summary did not write, or that changed since (a user's notes
in ``summary.txt``), is never replaced — the summary is refused, naming it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from estimator.io.outdir import check_files, prepare_files

from .replication import VERDICT_NAMES, ReplicationResult
from .runner import (
    STATE_FILE,
    finished_replications,
    read_replication,
    read_state,
    replication_file,
    with_timings,
)

#: the parameter kinds of the calibration proper (shown one by one in the text summary)
CALIBRATION_KINDS = ("time_delay", "bias", "scale", "table")
#: kinds of per-maneuver parameters, shown pooled per family
POOLED_KINDS = ("imu_bias", "initial_condition")
#: the order of the per-kind table (kinds not listed follow, alphabetically)
KIND_ORDER = ("imu_bias", "time_delay", "bias", "scale", "table", "initial_condition")
#: a reported deviation "covers" an error within this many deviations
COVERAGE_SIGMAS = 3.0
#: the files :func:`write_summary` writes (summary.png only when a replication succeeded)
SUMMARY_FILES = ("summary.txt", "summary_parameters.csv", "summary_families.csv",
                 "summary_channels.csv", "summary.png")
#: the listing of the summary files written (names, sizes, SHA-256), beside them
SUMMARY_LISTING = ".fpr-summary.json"


@dataclass(frozen=True)
class MonteCarloSummary:
    """The summary tables of a Monte Carlo run (see the module docstring).

    Attributes
    ----------
    name : the scenario.
    n_ok, n_failed : replications summarised (verdict success, with or without warnings) and
        failed ones (failure verdict, or raised), left out of the statistics.
    parameters : one row per parameter key, over the replications that estimated it: kind, unit,
        n, n_not_estimated (summarised replications that held it or lacked it), truth_mean, bias,
        rmse, mc_std, crb_mean, colored_mean, ratio_crb (= mc_std / crb_mean), ratio_colored,
        z_mean, z_std, within_3sigma (fraction of |z_crb| < 3), bias_t (bias / its standard error).
    families : per parameter family (``dax``, ``u0``, ``f1``, ...): instances, n, bias, rmse,
        crb_rms, z_std_crb, z_std_colored, within_3sigma.
    channels : per channel and kind ("residual", "calibrated"): unit, n, median_3sigma,
        p90_3sigma, max_3sigma (3-sigma = 3 x rms about zero), median_mean.
    failures : replication, status, verdict, message (first line).
    z : the per-replication rows of estimated parameters (replication, name, family, kind, error,
        z_crb, z_colored), for plots.
    kinds : per parameter kind (:func:`kind_table`): parameters, n, within_3crb, within_3colored,
        z_std_crb, z_std_colored, median_abs_z_crb, median_abs_z_colored.
    verdicts : per verdict (success, success with warnings, failure, none): replications, and
        whether they are in the statistics.
    findings : per (severity, code) of the estimator's warnings and failures: the replications
        that had it and how often.
    elapsed_s : wall time of each replication that has one (from the run's ``timings.csv``), s.
    """

    name: str
    n_ok: int
    n_failed: int
    parameters: pd.DataFrame
    families: pd.DataFrame
    channels: pd.DataFrame
    failures: pd.DataFrame
    z: pd.DataFrame = field(repr=False)
    kinds: pd.DataFrame = field(default_factory=pd.DataFrame)
    verdicts: pd.DataFrame = field(default_factory=pd.DataFrame)
    findings: pd.DataFrame = field(default_factory=pd.DataFrame)
    elapsed_s: tuple[float, ...] = ()

    @property
    def n_failure_verdict(self) -> int:
        """Replications left out of the statistics because the estimator's verdict was failure."""
        v = self.verdicts
        return int(v.loc["failure", "replications"]) if len(v) and "failure" in v.index else 0

    def to_pandas(self) -> pd.DataFrame:
        """The per-parameter table, indexed by parameter key."""
        return self.parameters

    def text(self, kinds: tuple[str, ...] = CALIBRATION_KINDS, max_rows: int = 80) -> str:
        """A readable summary: verdicts, the per-kind table, calibration parameters one by one,
        per-maneuver families pooled, channel accuracies, the estimator's findings, failures."""
        fmt = {"float_format": lambda v: f"{v: .4g}"}
        lines = [f"Monte Carlo {self.name}: {self.n_ok + self.n_failed} replications, {self.n_ok} "
                 f"summarised (verdict success, with or without warnings), {self.n_failed} failed"]
        if len(self.verdicts):
            counts = ", ".join(f"{int(r.replications)} {v}" for v, r in self.verdicts.iterrows())
            lines.append(f"verdicts: {counts}; {self.n_failure_verdict} left out of the statistics "
                         "because their verdict was failure"
                         + (f", {self.n_failed - self.n_failure_verdict} because they failed otherwise "
                            "(raised, or no verdict)" if self.n_failed > self.n_failure_verdict else ""))
        if self.elapsed_s:
            t = np.asarray(self.elapsed_s)
            lines.append(f"time per replication in its worker (timings.csv, {t.size} replications): median "
                         f"{np.median(t):.2f} s (10-90 %: {np.percentile(t, 10):.2f}-"
                         f"{np.percentile(t, 90):.2f} s)")
        if len(self.kinds):
            lines += ["", f"per parameter kind, estimates within {COVERAGE_SIGMAS:g} reported deviations of "
                      "their truth (Cramer-Rao, coloured-residual), z-score std and median |z|:",
                      self.kinds.to_string(**fmt)]
        p = self.parameters[self.parameters["kind"].isin(kinds)]
        if len(p):
            cols = ["kind", "unit", "n", "n_not_estimated", "truth_mean", "bias", "rmse", "mc_std",
                    "crb_mean", "colored_mean", "ratio_crb", "ratio_colored", "within_3sigma"]
            shown = p[cols].head(max_rows)
            lines += ["", "parameters (display units), over the replications that estimated each: bias "
                      "and RMSE of estimate - truth, Monte Carlo scatter, mean Cramer-Rao and coloured "
                      "deviations, scatter / mean deviation, fraction within 3 CRB sigmas"
                      + (f" (first {max_rows} of {len(p)})" if len(p) > max_rows else ""),
                      shown.to_string(**fmt)]
        f = self.families[self.families["kind"].isin(POOLED_KINDS)]
        if len(f):
            lines += ["", "per-maneuver parameters pooled per family (z_std = scatter / deviation):",
                      f.to_string(**fmt)]
        if len(self.channels):
            lines += ["", "channels: 3-sigma (3 x rms about zero) over the replications (residual = "
                      "measurement - model, the scatter of the paper's Table 2; calibrated = calibrated "
                      "channel - true flow angle):", self.channels.to_string(**fmt)]
        if len(self.findings):
            lines += ["", "the estimator's warnings and failures (replications that had each):",
                      self.findings.head(30).to_string(index=False)]
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
    """Fraction of the finite z-scores with |z| < 3 (NaN without any)."""
    z = _finite(z)
    return float(np.mean(np.abs(z) < COVERAGE_SIGMAS)) if z.size else np.nan


def _median_abs(z) -> float:
    z = _finite(z)
    return float(np.median(np.abs(z))) if z.size else np.nan


def estimated_rows(rows: pd.DataFrame) -> pd.Series:
    """Which parameter rows were estimated: a finite error and a finite, positive Cramér-Rao
    deviation (a held parameter has none, a fixed one is not in the table)."""
    crb = pd.to_numeric(rows["std_crb"], errors="coerce").to_numpy(dtype=float)
    err = pd.to_numeric(rows["error"], errors="coerce").to_numpy(dtype=float)
    return pd.Series(np.isfinite(err) & np.isfinite(crb) & (crb > 0), index=rows.index)


def _parameter_table(rows: pd.DataFrame, n_replications: int | None = None) -> pd.DataFrame:
    """Per parameter, over the replications that estimated it (``rows`` holds estimated rows
    only); ``n_replications`` (the replications summarised) gives n_not_estimated."""
    out = []
    for key, g in rows.groupby("name", sort=False):
        e = g["error"].to_numpy(dtype=float)
        n = len(g)
        bias, mc_std = _mean(e), _std(e)
        crb_mean, col_mean = _mean(g["std_crb"]), _mean(g["std_colored"])
        out.append({
            "parameter": key, "family": g["family"].iloc[0], "kind": g["kind"].iloc[0],
            "unit": g["unit"].iloc[0], "n": n,
            "n_not_estimated": (n_replications - n) if n_replications is not None else 0,
            "truth_mean": _mean(g["truth"]), "bias": bias,
            "rmse": _rms(e), "mc_std": mc_std, "crb_mean": crb_mean, "colored_mean": col_mean,
            "ratio_crb": mc_std / crb_mean, "ratio_colored": mc_std / col_mean,
            "z_mean": _mean(g["z_crb"]), "z_std": _std(g["z_crb"]), "within_3sigma": _within3(g["z_crb"]),
            # the bias in units of its own standard error: |bias_t| > 3 is a bias the run resolves
            "bias_t": bias / (mc_std / np.sqrt(n)) if n > 1 and mc_std > 0 else np.nan,
        })
    cols = ["parameter", "family", "kind", "unit", "n", "n_not_estimated", "truth_mean", "bias", "rmse",
            "mc_std", "crb_mean", "colored_mean", "ratio_crb", "ratio_colored", "z_mean", "z_std",
            "within_3sigma", "bias_t"]
    return pd.DataFrame(out, columns=cols).set_index("parameter")


def kind_table(rows: pd.DataFrame) -> pd.DataFrame:
    """Per parameter kind, how honest the reported deviations are.

    Parameters
    ----------
    rows : per-replication parameter rows (columns name, kind, error, std_crb, z_crb, z_colored);
        rows that were not estimated (:func:`estimated_rows`) are left out.

    Returns
    -------
    Indexed by kind (:data:`KIND_ORDER` first): parameters (distinct keys), n (estimates),
    within_3crb and within_3colored (fraction of |z| < 3 with the Cramér-Rao and the
    coloured-residual deviation; 0.9973 for honest Gaussian deviations), z_std_crb and
    z_std_colored (sample std of z: the scatter / reported deviation ratio, 1 when honest),
    median_abs_z_crb and median_abs_z_colored (0.674 when honest; robust to a few wild
    replications). Dimensionless.
    """
    cols = ["kind", "parameters", "n", "within_3crb", "within_3colored", "z_std_crb", "z_std_colored",
            "median_abs_z_crb", "median_abs_z_colored"]
    if not len(rows):
        return pd.DataFrame(columns=cols).set_index("kind")
    rows = rows[estimated_rows(rows)]
    present = sorted(set(rows["kind"]), key=lambda k: (KIND_ORDER.index(k) if k in KIND_ORDER
                                                       else len(KIND_ORDER), k))
    out = []
    for kind in present:
        g = rows[rows["kind"] == kind]
        zc, zk = g["z_crb"].to_numpy(dtype=float), g["z_colored"].to_numpy(dtype=float)
        out.append({"kind": kind, "parameters": g["name"].nunique(), "n": len(g),
                    "within_3crb": _within3(zc), "within_3colored": _within3(zk),
                    "z_std_crb": _std(zc), "z_std_colored": _std(zk),
                    "median_abs_z_crb": _median_abs(zc), "median_abs_z_colored": _median_abs(zk)})
    return pd.DataFrame(out, columns=cols).set_index("kind")


def _verdict_label(r: ReplicationResult) -> str:
    if r.verdict_code is not None:
        return VERDICT_NAMES.get(r.verdict_code, str(r.verdict_code))
    return "not recorded" if r.ok else "none (raised, or no verdict recorded)"


def verdict_table(results: list[ReplicationResult]) -> pd.DataFrame:
    """Replications per verdict (success, success with warnings, failure; none when the
    replication raised or its file predates verdicts) and whether they are in the statistics."""
    order = [*VERDICT_NAMES.values(), "not recorded", "none (raised, or no verdict recorded)"]
    counts: dict[str, list[int]] = {}
    for r in results:
        c = counts.setdefault(_verdict_label(r), [0, 0])
        c[0] += 1
        c[1] += int(r.ok)
    rows = [{"verdict": v, "replications": counts[v][0], "in_statistics": counts[v][1]}
            for v in sorted(counts, key=lambda v: order.index(v) if v in order else len(order))]
    return pd.DataFrame(rows, columns=["verdict", "replications", "in_statistics"]).set_index("verdict")


def findings_table(results: list[ReplicationResult]) -> pd.DataFrame:
    """Per (severity, code) of the estimator's warning and failure findings: the replications that
    had it, how many findings in all, and the first message seen."""
    seen: dict[tuple[str, str], dict] = {}
    for r in results:
        codes = set()
        for severity, code, message in r.findings:
            d = seen.setdefault((severity, code), {"severity": severity, "code": code, "replications": 0,
                                                   "findings": 0, "example": message.splitlines()[0][:160]
                                                   if message else ""})
            d["findings"] += 1
            codes.add((severity, code))
        for k in codes:
            seen[k]["replications"] += 1
    cols = ["severity", "code", "replications", "findings", "example"]
    df = pd.DataFrame(list(seen.values()), columns=cols)
    return df.sort_values(["severity", "replications", "code"], ascending=[True, False, True],
                          key=lambda c: c.map({"failure": 0, "warning": 1}) if c.name == "severity" else c,
                          ignore_index=True)


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
    if not len(rows):
        rows = pd.DataFrame(columns=["name", "kind", "unit", "three_sigma", "mean"])
    for (name, kind), g in rows.groupby(["name", "kind"], sort=True):
        s = g["three_sigma"].to_numpy()
        out.append({"channel": name, "kind": kind, "unit": g["unit"].iloc[0], "n": len(g),
                    "median_3sigma": float(np.median(s)), "p90_3sigma": float(np.percentile(s, 90)),
                    "max_3sigma": float(np.max(s)), "median_mean": float(np.median(g["mean"]))})
    cols = ["channel", "kind", "unit", "n", "median_3sigma", "p90_3sigma", "max_3sigma", "median_mean"]
    return pd.DataFrame(out, columns=cols).set_index(["channel", "kind"])


def summarize_results(results: list[ReplicationResult], name: str = "") -> MonteCarloSummary:
    """Summarise replication results (finished and failed).

    Parameters
    ----------
    results : the replications; those not ``ok`` (a failure verdict, or raised) are counted and
        left out of the statistics.
    name : the scenario's name, for the text.
    """
    ok = [r for r in results if r.ok]
    failed = [r for r in results if not r.ok]
    params = pd.concat([r.parameters.assign(replication=r.index) for r in ok], ignore_index=True) \
        if ok else pd.DataFrame(columns=["replication", "name", "family", "kind", "unit", "error",
                                         "truth", "std_crb", "std_colored", "z_crb", "z_colored"])
    # one set of replications per parameter for every statistic: those that estimated it
    params = params[estimated_rows(params)] if len(params) else params
    chans = pd.concat([r.channels.assign(replication=r.index) for r in ok], ignore_index=True) \
        if ok else pd.DataFrame(columns=["name", "kind", "unit", "three_sigma", "mean"])
    failures = pd.DataFrame([{"replication": r.index, "status": r.status, "verdict": _verdict_label(r),
                              "message": (r.message.splitlines() or [""])[0]} for r in failed],
                            columns=["replication", "status", "verdict", "message"])
    return MonteCarloSummary(
        name=name, n_ok=len(ok), n_failed=len(failed), parameters=_parameter_table(params, len(ok)),
        families=_family_table(params), channels=_channel_table(chans), failures=failures,
        z=params[["replication", "name", "family", "kind", "error", "z_crb", "z_colored"]].copy(),
        kinds=kind_table(params), verdicts=verdict_table(results), findings=findings_table(results),
        elapsed_s=tuple(float(r.elapsed_s) for r in results if r.elapsed_s > 0))


def load_results(out_dir: str | Path, replications: int | None = None) -> list[ReplicationResult]:
    """Every replication file of a run (of 0..N-1 when ``replications`` is given), in index order.

    A failure record is read whole (:meth:`ReplicationResult.from_meta`: its verdict and findings
    too). Each result's ``elapsed_s`` comes from the run's ``timings.csv`` (0 without a line)."""
    out_dir = Path(out_dir)
    # the run's scenario: a replication file of another run copied in is not read as this run's
    # (a folder of replication files alone, without montecarlo.json, is read as it is)
    expected = read_state(out_dir).get("scenario_hash") if (out_dir / STATE_FILE).exists() else None
    have = finished_replications(out_dir)
    keys = sorted(k for k in have if replications is None or k < replications)
    out = []
    for k in keys:
        path = replication_file(out_dir, k, failed=have[k] == "failed")
        try:
            if have[k] == "failed":
                r = ReplicationResult.from_meta(json.loads(path.read_text(encoding="utf-8")))
            else:
                r = read_replication(path)
        except (ValueError, KeyError, TypeError, UnicodeDecodeError, OSError) as exc:
            if str(path) in str(exc):  # read_replication's own message names the file already
                raise
            raise ValueError(f"{path}: not a replication file `fpr montecarlo` wrote ({exc}); move it "
                             "out of the run folder") from None
        if (expected is not None and r.scenario_hash != expected) or r.index != k:
            raise ValueError(f"{path}: replication {r.index} of scenario hash {r.scenario_hash[:12]}, "
                             f"not replication {k} of this run ({str(expected)[:12]}); move it out of "
                             "the run folder")
        out.append(r)
    return with_timings(out_dir, out)


def summarize(out_dir: str | Path, replications: int | None = None) -> MonteCarloSummary:
    """Summarise the run in ``out_dir`` (every replication file, or those of 0..N-1)."""
    state = read_state(Path(out_dir))
    return summarize_results(load_results(out_dir, replications), name=str(state.get("name", "")))


def check_summary_files(directory: str | Path, *, tool: str = "fpr montecarlo-summary",
                        advice: str = "") -> None:
    """Raise the refusal :func:`write_summary` would give for ``directory``, writing nothing (for a
    run that summarises at its end: it stops before the work instead)."""
    check_files(directory, SUMMARY_FILES, listing_name=SUMMARY_LISTING, tool=tool, advice=advice)


def write_summary(out_dir: str | Path, directory: str | Path | None = None, *,
                  replications: int | None = None, all_kinds: bool = False,
                  tool: str = "fpr montecarlo-summary", advice: str = "") -> tuple[str, list[Path]]:
    """Summarise the run in ``out_dir`` and write :data:`SUMMARY_FILES` into ``directory``.

    Parameters
    ----------
    out_dir : the run folder.
    directory : where the files go (default: ``out_dir``); created when missing.
    replications : summarise replications 0..N-1 only (default: every file present).
    all_kinds : list every parameter in the text (initial conditions, IMU biases too).
    tool, advice : who writes, and what else the user can do, said in a refusal.

    Returns
    -------
    The summary's text and the files written.

    Raises
    ------
    estimator.io.outdir.OutputFolderError
        A file of one of :data:`SUMMARY_FILES` in ``directory`` was not written by a summary, or
        changed since (named; nothing is written). Earlier summary files, unchanged, are replaced.
    """
    directory = Path(out_dir if directory is None else directory)
    # checked before the (possibly long) reading of every replication file
    check_summary_files(directory, tool=tool, advice=advice)
    summary = summarize(out_dir, replications)
    kinds = (*CALIBRATION_KINDS, *POOLED_KINDS) if all_kinds else CALIBRATION_KINDS
    text = summary.text(kinds=kinds, max_rows=100000 if all_kinds else 80)
    with prepare_files(directory, SUMMARY_FILES, listing_name=SUMMARY_LISTING, tool=tool,
                       advice=advice) as folder:
        def record(name: str) -> Path:
            return folder.record(directory / name)

        record("summary.txt").write_text(text + "\n")
        summary.parameters.to_csv(record("summary_parameters.csv"))
        summary.families.to_csv(record("summary_families.csv"))
        summary.channels.to_csv(record("summary_channels.csv"))
        if summary.n_ok:
            summary.plot(record("summary.png"))
    return text, [p for p in folder.recorded if p.exists()]
