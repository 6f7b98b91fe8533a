"""The estimation result: immutable, named, with units, deviations, a verdict and a message.

``EstimationResult.to_pandas()`` gives one row per parameter (SI and display units, and what the
estimator did with it: estimated, on a bound, held and why, or fixed); ``residuals_table()`` one
row per maneuver and channel; ``findings_table()`` the findings behind the verdict;
``diagnostics`` the fit-quality table; ``to_json`` / ``to_csv`` write them. A result is immutable:
its arrays are read-only copies, its mappings read-only views.

``status`` is the solver's (:class:`~estimator.verdict.Status`: positive = converged);
``verdict`` (:class:`~estimator.verdict.Verdict`) is what to act on: a converged fit can still be
a failure (a wrong minimum, a stuck vane).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType

import numpy as np
import pandas as pd

from estimator.parameters import ParameterSet
from estimator.problem import Problem
from estimator.verdict import Finding, Severity, Status, Verdict, findings_frame, judge, reasons

#: Short text of each solver status code (for tables that store the code).
STATUS_TEXT = {s.value: s.name.lower().replace("_", " ") for s in Status}
#: What the estimator did with a parameter (:attr:`EstimationResult.state`).
STATES = ("estimated", "on_bound", "held", "unidentifiable", "fixed", "not estimated")


@dataclass(frozen=True)
class Confounding:
    """Parameters the data cannot determine or separate: ``kind`` is "no_data", "undetermined",
    "unidentifiable" or "correlated"."""

    parameters: tuple[str, ...]
    kind: str
    detail: str


@dataclass(frozen=True)
class ResidualStats:
    """Residual ``z - y`` of one channel in one maneuver, SI units."""

    maneuver: str
    channel: str
    n: int
    mean: float
    std: float
    rms: float


@dataclass(frozen=True)
class EstimationResult:
    """Estimates of an output-error estimation.

    Attributes
    ----------
    parameters : the parameter set at the estimate (values SI, free/fixed, scopes, units).
    std_crb : (P,) Cramér-Rao standard deviations, SI (NaN for fixed or unidentifiable).
    std_colored : (P,) honest deviations, SI: corrected for coloured and cross-correlated residuals
        (Morelli-Klein, matrix form), never below the Cramér-Rao bound, plus the IMU noise's share.
    correlation_keys, correlation : Cramér-Rao correlation matrix of the estimated
        non-per-maneuver parameters.
    correlation_colored : the same parameters' correlations in the honest covariance (coloured
        residuals, IMU noise), NaN without it.
    R : channel -> residual variance (SI^2) at the estimate.
    residuals : per maneuver and channel residual statistics.
    iterations, cost_history, status, message, confounding, elapsed_s : how it went.
    g_mps2, source : the gravity used and where the problem came from.
    free_estimated : (P,) the parameters estimated (free and not held).
    state, state_reason : per parameter, one of :data:`STATES` and why (held: no data,
        undetermined, unidentifiable; on a bound: which).
    findings : what the fit-quality and identifiability checks found (the verdict's reasons).
    verdict : success, success with warnings, or failure.
    fit_quality : the fit-quality table of the diagnostics, one row per maneuver and channel (None if
        not run); read it through :attr:`diagnostics` (a copy).
    outliers : (maneuver, channel) -> times (s) of the residual outliers the diagnostics found.
    std_imu_noise : (P,) the share of ``std_colored`` that the IMU's noise, integrated as process
        noise, contributes (``std_colored^2 = max(Morelli-Klein, Cramér-Rao)^2 + std_imu_noise^2``).
    imu_noise_psd : aircraft -> (6,) the IMU white-noise densities used (accelerometers m^2/s^3,
        gyros rad^2/s), or None.
    """

    parameters: ParameterSet
    std_crb: np.ndarray
    std_colored: np.ndarray
    correlation_keys: tuple[str, ...]
    correlation: np.ndarray = field(repr=False)
    R: Mapping[str, float] = field(repr=False)
    residuals: tuple[ResidualStats, ...] = field(repr=False)
    iterations: int = 0
    cost_history: tuple[float, ...] = ()
    status: Status = Status.MODEL_ERROR
    message: str = ""
    confounding: tuple[Confounding, ...] = ()
    elapsed_s: float = 0.0
    g_mps2: float = 9.80665
    source: str = ""
    channel_display: dict[str, tuple[float, str]] = field(default_factory=dict, repr=False)
    free_estimated: np.ndarray | None = field(default=None, repr=False)
    correlation_colored: np.ndarray | None = field(default=None, repr=False)
    state: tuple[str, ...] = field(default=(), repr=False)
    state_reason: tuple[str, ...] = field(default=(), repr=False)
    findings: tuple[Finding, ...] = field(default=(), repr=False)
    verdict: Verdict = Verdict.FAILURE
    fit_quality: pd.DataFrame | None = field(default=None, repr=False)
    outliers: Mapping[tuple[str, str], np.ndarray] = field(default_factory=dict, repr=False)
    std_imu_noise: np.ndarray | None = field(default=None, repr=False)
    imu_noise_psd: Mapping[str, np.ndarray] | None = field(default=None, repr=False)

    @classmethod
    def build(cls, problem: Problem, values: np.ndarray, **kw) -> EstimationResult:
        """The result of an estimation of ``problem`` ending at ``values``; every array is copied
        and made read-only, every mapping wrapped read-only (the caller's own are untouched)."""
        def frozen(a):
            a = np.array(a, copy=True)
            a.setflags(write=False)
            return a

        for a in ("std_crb", "std_colored", "correlation", "std_imu_noise", "free_estimated",
                  "correlation_colored"):
            if kw.get(a) is not None:
                kw[a] = frozen(kw[a])
        kw["R"] = MappingProxyType(dict(kw.get("R", {})))
        kw["outliers"] = MappingProxyType({k: frozen(v) for k, v in dict(kw.get("outliers", {})).items()})
        if kw.get("imu_noise_psd") is not None:
            kw["imu_noise_psd"] = MappingProxyType({k: frozen(v) for k, v in kw["imu_noise_psd"].items()})
        if kw.get("fit_quality") is not None:
            kw["fit_quality"] = kw["fit_quality"].copy()
        return cls(
            parameters=problem.parameters.with_values(values), g_mps2=problem.g_mps2,
            source=problem.source,
            channel_display={c.name: (c.display_scale, c.display_unit) for c in problem.channels},
            **kw,
        )

    @property
    def diagnostics(self) -> pd.DataFrame | None:
        """The fit-quality table (a copy: the result stays as it was)."""
        return None if self.fit_quality is None else self.fit_quality.copy()

    @property
    def success(self) -> bool:
        """The verdict is a success (with or without warnings): see :attr:`verdict`."""
        return self.verdict.success

    @property
    def converged(self) -> bool:
        """The solver converged (which alone does not make a trustworthy result)."""
        return Status(self.status).converged

    @property
    def warnings(self) -> tuple[Finding, ...]:
        return tuple(f for f in self.findings if f.severity == Severity.WARNING)

    @property
    def failures(self) -> tuple[Finding, ...]:
        return tuple(f for f in self.findings if f.severity == Severity.FAILURE)

    def with_findings(self, more: tuple[Finding, ...], iterations: int = 0) -> EstimationResult:
        """A copy with more findings (the verdict judged again) and ``iterations`` more iterations."""
        findings = self.findings + tuple(more)
        return replace(self, findings=findings, verdict=judge(Status(self.status), findings),
                       iterations=self.iterations + iterations)

    @property
    def values(self) -> np.ndarray:
        return self.parameters.values

    def value(self, key: str) -> float:
        return self.parameters[key].value

    def std(self, key: str, colored: bool = False) -> float:
        i = self.parameters.index(key)
        return float((self.std_colored if colored else self.std_crb)[i])

    def covariance(self, keys: list[str] | tuple[str, ...], colored: bool = False) -> np.ndarray:
        """Covariance (SI) of some estimated global parameters, from their correlations and deviations.

        ``colored``: the honest covariance (coloured residuals and IMU noise: its own deviations
        and correlations) instead of the Cramér-Rao one. Parameters outside the correlation matrix
        (per-maneuver ones) are taken as uncorrelated with the others; a parameter without a
        deviation (held, unidentifiable) gives NaN, never a zero variance.
        """
        pos = {k: i for i, k in enumerate(self.correlation_keys)}
        corr = self.correlation
        if colored:
            corr = (self.correlation_colored if self.correlation_colored is not None
                    else np.full_like(self.correlation, np.nan))
        std = np.array([self.std(k, colored=colored) for k in keys])
        C = np.zeros((len(keys), len(keys)))
        for i, a in enumerate(keys):
            for j, b in enumerate(keys):
                rho = corr[pos[a], pos[b]] if a in pos and b in pos else float(i == j)
                C[i, j] = rho * std[i] * std[j]
        return C

    def to_pandas(self) -> pd.DataFrame:
        """One row per parameter, indexed by key: value and deviations (SI and display units),
        ``free`` (asked for by the problem), ``estimated`` (estimated here) and ``state`` /
        ``reason`` (estimated, on_bound, held, fixed: why)."""
        rows = []
        n = len(self.parameters)
        state = self.state or tuple("estimated" if p.free else "fixed" for p in self.parameters)
        reason = self.state_reason or ("",) * n
        est = (self.free_estimated if self.free_estimated is not None
               else np.array([p.free for p in self.parameters]))
        imu = self.std_imu_noise if self.std_imu_noise is not None else np.full(n, np.nan)
        for i, p in enumerate(self.parameters):
            s = p.display_scale
            rows.append({
                "key": p.key, "name": p.name, "instance": p.instance, "element": p.element,
                "kind": p.kind, "scope": p.scope, "free": p.free, "estimated": bool(est[i]),
                "state": state[i], "reason": reason[i], "unit": p.unit,
                "value": p.value, "std_crb": self.std_crb[i], "std_colored": self.std_colored[i],
                "display_unit": p.display_unit, "value_display": p.value * s,
                "std_crb_display": self.std_crb[i] * s, "std_colored_display": self.std_colored[i] * s,
                "std_imu_noise": imu[i], "std_imu_noise_display": imu[i] * s,
            })
        return pd.DataFrame(rows).set_index("key")

    def findings_table(self) -> pd.DataFrame:
        """The findings behind the verdict, most severe first."""
        return findings_frame(self.findings)

    def residuals_table(self) -> pd.DataFrame:
        df = pd.DataFrame([r.__dict__ for r in self.residuals])
        if len(df):
            scale = df["channel"].map(lambda c: self.channel_display.get(c, (1.0, ""))[0])
            df["display_unit"] = df["channel"].map(lambda c: self.channel_display.get(c, (1.0, ""))[1])
            for c in ("mean", "std", "rms"):
                df[f"{c}_display"] = df[c] * scale
        return df

    def correlation_frame(self) -> pd.DataFrame:
        return pd.DataFrame(self.correlation, index=self.correlation_keys, columns=self.correlation_keys)

    def summary(self, kinds: tuple[str, ...] = ("imu_bias", "time_delay", "bias", "scale", "table"),
                max_rows: int = 60, max_findings: int = 15) -> str:
        """A readable text summary: the verdict and its reasons first, then the estimates (free
        parameters of the given kinds, display units, with their state where not estimated)."""
        df = self.to_pandas()
        df = df[df["free"] & df["kind"].isin(kinds)]
        counts = pd.Series([s for s, f in zip(self.state or (), self.parameters.free_mask, strict=False)
                            if f]).value_counts()
        lines = [
            f"VERDICT: {self.verdict.name.replace('_', ' ')} — {self.verdict.text}",
            f"solver: {Status(self.status).name.lower()} after {self.iterations} iterations "
            f"({self.elapsed_s:.2f} s) — {self.message}",
            f"g = {self.g_mps2} m/s^2; {int(self.parameters.free_mask.sum())} free parameters"
            + (": " + ", ".join(f"{n} {s}" for s, n in counts.items()) if len(counts) else ""),
        ]
        shown = reasons(self.findings)
        if shown:
            lines.append(f"failures and warnings ({len(shown)}):")
            lines += [f"  {f.text()}" for f in shown[:max_findings]]
            if len(shown) > max_findings:
                lines.append(f"  ... {len(shown) - max_findings} more in findings.csv / result.json")
        info = [f for f in self.findings if f.severity == Severity.INFO]
        if info:
            lines.append(f"notes ({len(info)}):")
            lines += [f"  {f.message}" for f in info[:max_findings]]
        cols = ["value_display", "std_crb_display", "std_colored_display", "display_unit", "state"]
        show = df[cols]
        if len(show) > max_rows:
            lines.append(f"(first {max_rows} of {len(show)} parameters)")
            show = show.head(max_rows)
        lines.append(show.to_string(float_format=lambda v: f"{v: .5g}"))
        return "\n".join(lines)

    def to_json(self, path: str | Path) -> None:
        """Everything, with the verdict and its findings at the top. Strict JSON: a value that is
        not a finite number (a deviation of a held parameter) is ``null``."""
        def clean(v):
            if isinstance(v, Mapping):
                return {str(k): clean(x) for k, x in v.items()}
            if isinstance(v, (list, tuple, np.ndarray)):
                return [clean(x) for x in v]
            if isinstance(v, np.generic):
                v = v.item()
            if isinstance(v, float) and not np.isfinite(v):
                return None
            if v is None or isinstance(v, (str, int, float, bool)):
                return v
            return str(v)
        doc = {
            "verdict": self.verdict.name, "verdict_code": self.verdict.code,
            "verdict_text": self.verdict.text,
            "findings": [f.to_dict() for f in sorted(self.findings, key=lambda f: -int(f.severity))],
            "status": int(self.status), "status_text": STATUS_TEXT.get(int(self.status)),
            "message": self.message, "iterations": self.iterations, "elapsed_s": self.elapsed_s,
            "g_mps2": self.g_mps2, "source": self.source, "cost_history": list(self.cost_history),
            "R": dict(self.R),
            "imu_noise_psd": None if self.imu_noise_psd is None else dict(self.imu_noise_psd),
            "parameters": self.to_pandas().reset_index().to_dict(orient="records"),
            "confounding": [c.__dict__ for c in self.confounding],
            "correlation": {"keys": list(self.correlation_keys), "matrix": self.correlation},
            "correlation_colored": self.correlation_colored,
            "residuals": [r.__dict__ for r in self.residuals],
            "fit_quality": ([] if self.fit_quality is None else self.fit_quality.to_dict(orient="records")),
        }
        Path(path).write_text(json.dumps(clean(doc), indent=1, allow_nan=False))

    def to_csv(self, directory: str | Path, record: Callable[[Path], object] | None = None) -> None:
        """parameters.csv, residuals.csv, correlation.csv, findings.csv and fit_quality.csv.

        ``record`` is called with each file's path before it is written (e.g.
        :meth:`estimator.io.outdir.OutputFolder.record`, so the output folder lists what it holds).
        """
        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)

        def at(name: str) -> Path:
            if record is not None:
                record(d / name)
            return d / name

        self.to_pandas().to_csv(at("parameters.csv"))
        self.residuals_table().to_csv(at("residuals.csv"), index=False)
        self.correlation_frame().to_csv(at("correlation.csv"))
        self.findings_table().to_csv(at("findings.csv"), index=False)
        if self.fit_quality is not None:
            self.fit_quality.to_csv(at("fit_quality.csv"), index=False)
