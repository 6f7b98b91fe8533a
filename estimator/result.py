"""The estimation result: immutable, named, with units, deviations, status and message.

``EstimationResult.to_pandas()`` gives one row per parameter (SI and display units);
``residuals_table()`` one row per maneuver and channel; ``to_json`` / ``to_csv`` write them.
Status: 1 converged, 0 iteration limit, 2 no further decrease possible, -1 failed.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from estimator.parameters import ParameterSet
from estimator.problem import Problem

STATUS_TEXT = {1: "converged", 0: "iteration limit", 2: "stalled", -1: "failed"}


@dataclass(frozen=True)
class Confounding:
    """Parameters the data cannot separate: ``kind`` is "unidentifiable" or "correlated"."""

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
    std_colored : (P,) deviations corrected for coloured residuals (Morelli-Klein), SI.
    correlation_keys, correlation : correlation matrix of the free non-per-maneuver parameters.
    R : channel -> residual variance (SI^2) at the estimate.
    residuals : per maneuver and channel residual statistics.
    iterations, cost_history, status, message, confounding, elapsed_s : how it went.
    g_mps2, source : the gravity used and where the problem came from.
    """

    parameters: ParameterSet
    std_crb: np.ndarray
    std_colored: np.ndarray
    correlation_keys: tuple[str, ...]
    correlation: np.ndarray = field(repr=False)
    R: dict[str, float] = field(repr=False)
    residuals: tuple[ResidualStats, ...] = field(repr=False)
    iterations: int = 0
    cost_history: tuple[float, ...] = ()
    status: int = -1
    message: str = ""
    confounding: tuple[Confounding, ...] = ()
    elapsed_s: float = 0.0
    g_mps2: float = 9.80665
    source: str = ""
    channel_display: dict[str, tuple[float, str]] = field(default_factory=dict, repr=False)
    free_estimated: np.ndarray | None = field(default=None, repr=False)

    @classmethod
    def build(cls, problem: Problem, values: np.ndarray, **kw) -> EstimationResult:
        for a in ("std_crb", "std_colored", "correlation"):
            kw[a] = np.asarray(kw[a])
            kw[a].setflags(write=False)
        return cls(
            parameters=problem.parameters.with_values(values), g_mps2=problem.g_mps2,
            source=problem.source,
            channel_display={c.name: (c.display_scale, c.display_unit) for c in problem.channels},
            **kw,
        )

    @property
    def success(self) -> bool:
        return self.status == 1

    @property
    def values(self) -> np.ndarray:
        return self.parameters.values

    def value(self, key: str) -> float:
        return self.parameters[key].value

    def std(self, key: str, colored: bool = False) -> float:
        i = self.parameters.index(key)
        return float((self.std_colored if colored else self.std_crb)[i])

    def to_pandas(self) -> pd.DataFrame:
        """One row per parameter, indexed by key."""
        rows = []
        for i, p in enumerate(self.parameters):
            s = p.display_scale
            rows.append({
                "key": p.key, "name": p.name, "instance": p.instance, "element": p.element,
                "kind": p.kind, "scope": p.scope, "free": p.free, "unit": p.unit,
                "value": p.value, "std_crb": self.std_crb[i], "std_colored": self.std_colored[i],
                "display_unit": p.display_unit, "value_display": p.value * s,
                "std_crb_display": self.std_crb[i] * s, "std_colored_display": self.std_colored[i] * s,
            })
        return pd.DataFrame(rows).set_index("key")

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
                max_rows: int = 60) -> str:
        """A readable text summary (free parameters of the given kinds, in display units)."""
        df = self.to_pandas()
        df = df[df["free"] & df["kind"].isin(kinds)]
        lines = [
            f"status: {STATUS_TEXT.get(self.status, self.status)} after {self.iterations} iterations "
            f"({self.elapsed_s:.2f} s) — {self.message}",
            f"g = {self.g_mps2} m/s^2; {int(self.parameters.free_mask.sum())} free parameters",
        ]
        if self.confounding:
            lines.append(f"confounding ({len(self.confounding)}):")
            lines += [f"  {c.kind}: {', '.join(c.parameters)} — {c.detail}" for c in self.confounding[:10]]
        show = df[["value_display", "std_crb_display", "std_colored_display", "display_unit"]]
        if len(show) > max_rows:
            lines.append(f"(first {max_rows} of {len(show)} parameters)")
            show = show.head(max_rows)
        lines.append(show.to_string(float_format=lambda v: f"{v: .5g}"))
        return "\n".join(lines)

    def to_json(self, path: str | Path) -> None:
        def clean(v):
            if isinstance(v, float) and not np.isfinite(v):
                return None
            return v
        doc = {
            "status": self.status, "status_text": STATUS_TEXT.get(self.status), "message": self.message,
            "iterations": self.iterations, "elapsed_s": self.elapsed_s, "g_mps2": self.g_mps2,
            "source": self.source, "cost_history": list(self.cost_history),
            "R": self.R,
            "parameters": [
                {k: clean(v) for k, v in row.items()}
                for row in self.to_pandas().reset_index().to_dict(orient="records")
            ],
            "confounding": [c.__dict__ for c in self.confounding],
            "correlation": {
                "keys": list(self.correlation_keys),
                "matrix": np.where(np.isfinite(self.correlation), self.correlation, 0.0).tolist(),
            },
            "residuals": [r.__dict__ for r in self.residuals],
        }
        text = json.dumps(doc, indent=1, default=lambda o: o.item() if hasattr(o, "item") else str(o))
        Path(path).write_text(text)

    def to_csv(self, directory: str | Path) -> None:
        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        self.to_pandas().to_csv(d / "parameters.csv")
        self.residuals_table().to_csv(d / "residuals.csv", index=False)
        self.correlation_frame().to_csv(d / "correlation.csv")
