"""The estimation result: immutable, named, with units, deviations, a verdict and a message.

``EstimationResult.to_pandas()`` gives one row per parameter (SI and display units, and what the
estimator did with it: estimated, on a bound, held and why, or fixed); ``residuals_table()`` one
row per maneuver and channel; ``findings_table()`` the findings behind the verdict;
``diagnostics`` the fit-quality table; ``to_json`` / ``to_csv`` write them and
``EstimationResult.from_json`` reads ``result.json`` back. A result is immutable, however it was
made: its arrays are read-only copies, its mappings read-only views, its sequences tuples, its
fit-quality table a :class:`ReadOnlyTable` (``result.R["alpha_zl"] = 0`` raises ``TypeError``,
``result.std_crb[0] = 0`` ``ValueError``, ``result.status = ...`` ``FrozenInstanceError``).

``status`` is the solver's (:class:`~estimator.verdict.Status`: positive = converged);
``verdict`` (:class:`~estimator.verdict.Verdict`) is what to act on: a converged fit can still be
a failure (a wrong minimum, a stuck vane).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from types import MappingProxyType

import numpy as np
import pandas as pd

from estimator.finding_groups import FindingGroup, group_findings
from estimator.parameters import Parameter, ParameterSet, ParameterSpec
from estimator.problem import Problem
from estimator.verdict import Finding, Severity, Status, Verdict, findings_frame, judge

#: Short text of each solver status code (for tables that store the code).
STATUS_TEXT = {s.value: s.label for s in Status}
#: What the estimator did with a parameter (:attr:`EstimationResult.state`).
STATES = ("estimated", "on_bound", "held", "unidentifiable", "fixed", "not estimated")
#: What :meth:`EstimationResult.to_json` writes (``format``); :meth:`EstimationResult.from_json`
#: also reads the files written before it was named (everything but the exact parameter set).
JSON_FORMAT = "fpr-estimation-result/2"


def read_only(a, dtype=float) -> np.ndarray | None:
    """A read-only copy of ``a`` (None stays None; an array already read-only and owning its
    memory — one made here — is kept, so copying a result does not copy its matrices again)."""
    if a is None:
        return None
    if isinstance(a, np.ndarray) and not a.flags.writeable and a.base is None and a.flags.owndata:
        return a
    a = np.array(a, dtype=dtype, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class ReadOnlyTable:
    """A table that cannot be changed in place: named read-only columns (and index levels).

    ``to_pandas()`` gives a DataFrame (a new one each time, the caller's to change).

    Attributes
    ----------
    columns : the column names.
    data : one read-only array per column (its dtype kept).
    index_names, index : the index's level names and one read-only array per level; empty: the
        default index (0, 1, ...).
    columns_name : the name of the columns' axis (a pivot table's), if it has one.
    """

    columns: tuple[str, ...]
    data: tuple[np.ndarray, ...] = field(repr=False)
    index_names: tuple[str | None, ...] = ()
    index: tuple[np.ndarray, ...] = field(default=(), repr=False)
    columns_name: str | None = None

    @classmethod
    def of(cls, table: pd.DataFrame | ReadOnlyTable, keep_index: bool = False) -> ReadOnlyTable:
        """A read-only copy of ``table``; ``keep_index``: its index too, unless it is the default."""
        if isinstance(table, ReadOnlyTable):
            return table
        names, levels, axis = (), (), None
        ix = table.index
        if keep_index and not (isinstance(ix, pd.RangeIndex) and ix.start == 0 and ix.step == 1):
            names = tuple(None if n is None else str(n) for n in ix.names)
            levels = tuple(read_only(ix.get_level_values(i).to_numpy(copy=True), dtype=None)
                           for i in range(ix.nlevels))
        if keep_index and table.columns.name is not None:
            axis = str(table.columns.name)
        return cls(tuple(str(c) for c in table.columns),
                   tuple(read_only(table[c].to_numpy(copy=True), dtype=None) for c in table.columns),
                   names, levels, axis)

    def __len__(self) -> int:
        return len(self.data[0]) if self.data else (len(self.index[0]) if self.index else 0)

    def to_pandas(self) -> pd.DataFrame:
        index = None
        if len(self.index) == 1:
            index = pd.Index(np.array(self.index[0], copy=True), name=self.index_names[0])
        elif self.index:
            index = pd.MultiIndex.from_arrays([np.array(v, copy=True) for v in self.index],
                                              names=list(self.index_names))
        data = {c: np.array(v, copy=True) for c, v in zip(self.columns, self.data, strict=True)}
        frame = pd.DataFrame(data, columns=list(self.columns), index=index)
        frame.columns.name = self.columns_name
        return frame

    def to_dict(self) -> dict:
        """Plain JSON values, each column's dtype with it (:meth:`from_dict` reads it back; a
        number JSON cannot hold is ``null``: NaN in a float column, None in an object one)."""
        def col(a: np.ndarray) -> dict:
            return {"dtype": a.dtype.str if a.dtype != object else "object", "values": json_clean(a)}

        return {"columns": list(self.columns), "data": [col(a) for a in self.data],
                "index_names": list(self.index_names), "index": [col(a) for a in self.index],
                "columns_name": self.columns_name}

    @classmethod
    def from_dict(cls, d: Mapping) -> ReadOnlyTable:
        """The table :meth:`to_dict` gave."""
        def col(c: Mapping) -> np.ndarray:
            values = c["values"]
            if c["dtype"] == "object":
                a = np.empty(len(values), dtype=object)
                a[:] = values
                return a
            dtype = np.dtype(c["dtype"])
            if dtype.kind == "f":
                return np.array([_num(v) for v in values], dtype=dtype)
            return np.array(values, dtype=dtype)

        return cls(tuple(d["columns"]), tuple(read_only(col(c), dtype=None) for c in d["data"]),
                   tuple(d["index_names"]), tuple(read_only(col(c), dtype=None) for c in d["index"]),
                   d.get("columns_name"))


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
class WindModel:
    """The filter-error method's wind states at an estimate: with the result's values and ``R``,
    all it takes to run its Kalman filter and smoother again (Table 2's wind,
    :func:`estimator.workflow.stage_residuals`).

    Attributes
    ----------
    form : the wind states' form, ``WindOptions.form`` (:mod:`estimator.filter_error`):
        "gauss_markov" (three NED first-order Gauss-Markov components) or "dryden" (MIL-F-8785C's
        Dryden turbulence in body axes).
    scale_length_m : the Dryden scale length ``L``, m.
    sigma_mps : maneuver id -> its turbulence intensity, m/s, as the estimation left it; 0: no
        wind states there (calm, or not diagnosed turbulent).
    """

    form: str
    scale_length_m: float
    sigma_mps: Mapping[str, float]

    def __post_init__(self) -> None:
        object.__setattr__(self, "form", str(self.form))
        object.__setattr__(self, "scale_length_m", float(self.scale_length_m))
        object.__setattr__(self, "sigma_mps", MappingProxyType(
            {str(k): float(v) for k, v in dict(self.sigma_mps).items()}))

    def to_dict(self) -> dict:
        """Plain JSON values (:meth:`from_dict` reads them back exactly: floats keep their repr)."""
        return {"form": self.form, "scale_length_m": self.scale_length_m,
                "sigma_mps": dict(self.sigma_mps)}

    @classmethod
    def from_dict(cls, d: Mapping) -> WindModel:
        return cls(d["form"], d["scale_length_m"], d["sigma_mps"])


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
        not run), read-only (given as a DataFrame, stored as a :class:`ReadOnlyTable`); read it
        as a DataFrame through :attr:`diagnostics`.
    outliers : (maneuver, channel) -> times (s) of the residual outliers the diagnostics found.
    std_imu_noise : (P,) the share of ``std_colored`` that the IMU's noise, integrated as process
        noise, contributes (``std_colored^2 = max(Morelli-Klein, Cramér-Rao)^2 + std_imu_noise^2``).
    imu_noise_psd : aircraft -> (6,) the IMU white-noise densities used (accelerometers m^2/s^3,
        gyros rad^2/s), or None.
    wind : the filter-error method's smoothed turbulent wind per maneuver (:attr:`wind_history`);
        None for output error.
    wind_model : the filter-error method's wind states (their form, scale length and each
        maneuver's intensity, :class:`WindModel`), which with ``values`` and ``R`` rerun its
        filter; None for output error (and in a filter-error result read from a file written
        before it was kept).
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
    channel_display: Mapping[str, tuple[float, str]] = field(default_factory=dict, repr=False)
    free_estimated: np.ndarray | None = field(default=None, repr=False)
    correlation_colored: np.ndarray | None = field(default=None, repr=False)
    state: tuple[str, ...] = field(default=(), repr=False)
    state_reason: tuple[str, ...] = field(default=(), repr=False)
    findings: tuple[Finding, ...] = field(default=(), repr=False)
    verdict: Verdict = Verdict.FAILURE
    fit_quality: ReadOnlyTable | None = field(default=None, repr=False)
    outliers: Mapping[tuple[str, str], np.ndarray] = field(default_factory=dict, repr=False)
    std_imu_noise: np.ndarray | None = field(default=None, repr=False)
    imu_noise_psd: Mapping[str, np.ndarray] | None = field(default=None, repr=False)
    wind: ReadOnlyTable | None = field(default=None, repr=False)
    wind_model: WindModel | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        # every way of making a result (build, replace, the constructor, from_json) freezes it:
        # arrays read-only copies, mappings read-only views of copies, sequences tuples
        def put(name, value):
            object.__setattr__(self, name, value)

        put("status", Status(self.status))
        for a in ("std_crb", "std_colored", "correlation", "std_imu_noise", "correlation_colored"):
            put(a, read_only(getattr(self, a)))
        put("free_estimated", read_only(self.free_estimated, dtype=bool))
        for a in ("correlation_keys", "residuals", "confounding", "state", "state_reason", "findings"):
            put(a, tuple(getattr(self, a)))
        put("cost_history", tuple(float(c) for c in self.cost_history))
        put("R", MappingProxyType({str(k): float(v) for k, v in dict(self.R).items()}))
        put("channel_display", MappingProxyType(
            {str(k): (float(v[0]), str(v[1])) for k, v in dict(self.channel_display).items()}))
        put("outliers", MappingProxyType({tuple(k): read_only(v) for k, v in dict(self.outliers).items()}))
        if self.imu_noise_psd is not None:
            psd = {k: read_only(v) for k, v in dict(self.imu_noise_psd).items()}
            put("imu_noise_psd", MappingProxyType(psd))
        if self.fit_quality is not None:
            put("fit_quality", ReadOnlyTable.of(self.fit_quality))
        if self.wind is not None:
            put("wind", ReadOnlyTable.of(self.wind))
        if isinstance(self.wind_model, Mapping):
            put("wind_model", WindModel.from_dict(self.wind_model))

    @classmethod
    def build(cls, problem: Problem, values: np.ndarray, **kw) -> EstimationResult:
        """The result of an estimation of ``problem`` ending at ``values`` (the caller's arrays
        and mappings are copied, never frozen in place)."""
        return cls(
            parameters=problem.parameters.with_values(values), g_mps2=problem.g_mps2,
            source=problem.source,
            channel_display={c.name: (c.display_scale, c.display_unit) for c in problem.channels},
            **kw,
        )

    @property
    def wind_history(self) -> pd.DataFrame | None:
        """The filter-error method's smoothed turbulent wind per maneuver (a new DataFrame each
        time): ``maneuver``, ``t_s`` (the maneuver's time base, s), ``wind_{n,e,d}_mps`` (NED, m/s,
        the departure from the maneuver's steady wind, which its free initial velocities absorb)
        and their smoothed deviations ``std_{n,e,d}_mps``; None for output error."""
        return None if self.wind is None else self.wind.to_pandas()

    @property
    def diagnostics(self) -> pd.DataFrame | None:
        """The fit-quality table (a new DataFrame each time: the result stays as it was)."""
        return None if self.fit_quality is None else self.fit_quality.to_pandas()

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

    def finding_groups(self) -> tuple[FindingGroup, ...]:
        """The findings said once: one group per kind and channel, most important first
        (:func:`estimator.finding_groups.group_findings`)."""
        return group_findings(self.findings, len({r.maneuver for r in self.residuals}) or None)

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
        groups = self.finding_groups()
        acting = [g for g in groups if g.severity >= Severity.WARNING]
        notes = [g for g in groups if g.severity < Severity.WARNING]
        if acting:
            lines.append(f"failures and warnings ({len(acting)}; every finding in findings.csv):")
            lines += [f"  {g.text()}" for g in acting[:max_findings]]
            if len(acting) > max_findings:
                lines.append(f"  ... {len(acting) - max_findings} more in findings.csv / result.json")
        if notes:
            lines.append(f"notes ({len(notes)}):")
            lines += [f"  {g.headline}" for g in notes[:max_findings]]
            if len(notes) > max_findings:
                lines.append(f"  ... {len(notes) - max_findings} more in findings.csv / result.json")
        cols = ["value_display", "std_crb_display", "std_colored_display", "display_unit", "state"]
        show = df[cols]
        if len(show) > max_rows:
            lines.append(f"(first {max_rows} of {len(show)} parameters)")
            show = show.head(max_rows)
        lines.append(show.to_string(float_format=lambda v: f"{v: .5g}"))
        return "\n".join(lines)

    def to_json(self, path: str | Path) -> None:
        """Everything, with the verdict and its findings at the top; :meth:`from_json` reads it
        back. Strict JSON: a value that is not a finite number (a deviation of a held parameter)
        is ``null`` (an infinite bound too: ``[null, null]`` is unbounded)."""
        Path(path).write_text(json.dumps(self.to_dict(), indent=1, allow_nan=False))

    def to_dict(self) -> dict:
        """What :meth:`to_json` writes, as plain JSON values (:meth:`from_dict` reads it back)."""
        records = self.to_pandas().reset_index().to_dict(orient="records")
        for row, p in zip(records, self.parameters, strict=True):
            row["element"] = p.element  # an int, not the float of a column that also holds None
            row["bounds"] = list(p.bounds)
            row["display_scale"] = p.display_scale
        doc = {
            "verdict": self.verdict.name, "verdict_code": self.verdict.code,
            "verdict_text": self.verdict.text,
            # most severe first; "index" is the finding's place in the result (the data's findings
            # before the parameters' within a severity), which from_json restores
            "findings": [{**f.to_dict(), "index": i} for i, f in
                         sorted(enumerate(self.findings), key=lambda x: -int(x[1].severity))],
            "status": int(self.status), "status_text": STATUS_TEXT.get(int(self.status)),
            "message": self.message, "iterations": self.iterations, "elapsed_s": self.elapsed_s,
            "g_mps2": self.g_mps2, "source": self.source, "cost_history": list(self.cost_history),
            "R": dict(self.R),
            "imu_noise_psd": None if self.imu_noise_psd is None else dict(self.imu_noise_psd),
            "parameters": records,
            "confounding": [c.__dict__ for c in self.confounding],
            "correlation": {"keys": list(self.correlation_keys), "matrix": self.correlation},
            "correlation_colored": self.correlation_colored,
            "residuals": [r.__dict__ for r in self.residuals],
            "fit_quality": ([] if self.fit_quality is None else self.diagnostics.to_dict(orient="records")),
            # what from_json needs beyond the tables above to give back this very result
            "format": JSON_FORMAT,
            "fit_quality_columns": None if self.fit_quality is None else list(self.fit_quality.columns),
            "wind": None if self.wind is None else {"columns": list(self.wind.columns),
                                                    "rows": self.wind_history.to_dict(orient="list")},
            "wind_model": None if self.wind_model is None else self.wind_model.to_dict(),
            "state": list(self.state), "state_reason": list(self.state_reason),
            "free_estimated": self.free_estimated, "std_imu_noise": self.std_imu_noise,
            "channel_display": {k: list(v) for k, v in self.channel_display.items()},
            "outliers": [{"maneuver": m, "channel": c, "t_s": t} for (m, c), t in self.outliers.items()],
            "parameter_specs": [{f.name: getattr(sp, f.name) for f in fields(sp)}
                                for sp in self.parameters.specs.values()],
        }
        return json_clean(doc)

    @classmethod
    def from_json(cls, path: str | Path) -> EstimationResult:
        """The result that :meth:`to_json` wrote to ``path``.

        Values, deviations, correlations, the verdict, its findings, the status, each parameter's
        state and reason, residuals, the fit-quality table and the outliers come back as they
        were, except that a number JSON cannot hold (NaN, infinity) comes back as NaN (infinite
        bounds come back infinite). A file written before the format was named (no ``format``
        key) reads too, without what it lacks: the parameter families (``parameters.specs``
        empty), bounds (none), the outliers and the channels' display units.

        Raises
        ------
        ValueError
            The file is not JSON, or not an estimation result (naming what is missing).
        """
        path = Path(path)
        try:
            doc = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}: not JSON ({exc}); expected a result.json written by "
                             f"EstimationResult.to_json (fpr calibrate --single)") from None
        return cls.from_dict(doc, str(path))

    @classmethod
    def from_dict(cls, doc: Mapping, where: str = "the result") -> EstimationResult:
        """The result of :meth:`to_dict`'s document ``doc`` (as :meth:`from_json`; ``where`` names
        it in messages)."""
        path = where
        need = ("status", "verdict", "parameters", "correlation", "residuals")
        missing = [k for k in need if not isinstance(doc, dict) or k not in doc]
        if missing:
            raise ValueError(f"{path}: not an estimation result (no {', '.join(missing)}); expected a "
                             f"result.json written by EstimationResult.to_json (fpr calibrate --single)")
        fmt = doc.get("format")
        if fmt is not None and fmt != JSON_FORMAT:
            raise ValueError(f"{path}: format {fmt!r}, this version reads {JSON_FORMAT!r}; read it "
                             f"with the version that wrote it")
        try:
            return cls._from_doc(doc, exact=fmt is not None)
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{path}: not a readable estimation result "
                             f"({type(exc).__name__}: {exc})") from None

    @classmethod
    def _from_doc(cls, doc: Mapping, exact: bool) -> EstimationResult:
        rows = doc["parameters"]
        params, display = [], {}
        for r in rows:
            value = _num(r["value"])
            if exact:
                scale = float(r["display_scale"])
            else:  # older files: the display scale from a number shown both ways, or the units
                pairs = [(value, r.get("value_display")), (r.get("std_crb"), r.get("std_crb_display")),
                         (r.get("std_colored"), r.get("std_colored_display"))]
                units = 180.0 / math.pi if (r["unit"].startswith("rad")
                                            and r["display_unit"].startswith("deg")) else 1.0
                scale = next((_num(b) / _num(a) for a, b in pairs
                              if a not in (None, 0) and b is not None), units)
            params.append(Parameter(
                key=r["key"], name=r["name"], instance=r["instance"] or "",
                element=None if r["element"] is None else int(r["element"]), unit=r["unit"],
                value=value, free=bool(r["free"]), scope=r["scope"],
                bounds=_bounds(r.get("bounds")), kind=r["kind"], display_scale=scale,
                display_unit=r["display_unit"]))
        specs = {d["name"]: _spec(d) for d in doc.get("parameter_specs", ())}
        n = len(rows)
        col = {k: np.array([_num(r[k]) for r in rows], dtype=float).reshape(n)
               for k in ("std_crb", "std_colored", "std_imu_noise")}
        if exact:
            state, reason = tuple(doc["state"]), tuple(doc["state_reason"])
            free_est = doc["free_estimated"]
            std_imu = None if doc["std_imu_noise"] is None else _array(doc["std_imu_noise"])
            display = {k: (float(v[0]), str(v[1])) for k, v in doc["channel_display"].items()}
            outliers = {(o["maneuver"], o["channel"]): _array(o["t_s"]) for o in doc["outliers"]}
        else:
            state, reason = tuple(r["state"] for r in rows), tuple(r["reason"] or "" for r in rows)
            free_est = [bool(r["estimated"]) for r in rows]
            std_imu = None if np.all(np.isnan(col["std_imu_noise"])) else col["std_imu_noise"]
            outliers = {}
        fq_cols = doc.get("fit_quality_columns")
        fq_rows = doc.get("fit_quality") or []
        if fq_cols is None and fq_rows:
            fq_cols = list(fq_rows[0])
        fit_quality = None if fq_cols is None else _frame(fq_rows, fq_cols)
        wd = doc.get("wind")
        wind = None if wd is None else pd.DataFrame({c: wd["rows"][c] for c in wd["columns"]})
        wm = doc.get("wind_model")  # None too in a file written before it was kept
        corr = doc["correlation"]
        keys = tuple(corr["keys"])
        psd = doc.get("imu_noise_psd")
        return cls(
            parameters=ParameterSet(tuple(params), specs),
            std_crb=col["std_crb"], std_colored=col["std_colored"], correlation_keys=keys,
            correlation=_array(corr["matrix"]).reshape(len(keys), len(keys)),
            R={k: _num(v) for k, v in doc["R"].items()},
            residuals=tuple(ResidualStats(maneuver=r["maneuver"], channel=r["channel"], n=int(r["n"]),
                                          mean=_num(r["mean"]), std=_num(r["std"]), rms=_num(r["rms"]))
                            for r in doc["residuals"]),
            iterations=int(doc["iterations"]), cost_history=tuple(_num(c) for c in doc["cost_history"]),
            status=Status(int(doc["status"])), message=doc["message"],
            confounding=tuple(Confounding(tuple(c["parameters"]), c["kind"], c["detail"])
                              for c in doc["confounding"]),
            elapsed_s=float(doc["elapsed_s"]), g_mps2=float(doc["g_mps2"]), source=doc["source"],
            channel_display=display,
            free_estimated=None if free_est is None else np.array(free_est, dtype=bool),
            correlation_colored=(None if doc.get("correlation_colored") is None
                                 else _array(doc["correlation_colored"]).reshape(len(keys), len(keys))),
            state=state, state_reason=reason,
            findings=tuple(Finding.from_dict(f) for f in
                           sorted(doc["findings"], key=lambda f: f.get("index", 0))),
            verdict=Verdict[doc["verdict"]], fit_quality=fit_quality, outliers=outliers,
            std_imu_noise=std_imu,
            imu_noise_psd=None if psd is None else {k: _array(v) for k, v in psd.items()},
            wind=wind, wind_model=None if wm is None else WindModel.from_dict(wm),
        )

    def to_csv(self, directory: str | Path, record: Callable[[Path], object] | None = None) -> None:
        """parameters.csv, residuals.csv, correlation.csv, findings.csv, fit_quality.csv and (filter
        error) wind.csv.

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
            self.diagnostics.to_csv(at("fit_quality.csv"), index=False)
        if self.wind is not None:
            self.wind_history.to_csv(at("wind.csv"), index=False)


# ------------------------------------------------------------------------------ JSON helpers
def json_clean(v):
    """Plain JSON values: mappings with string keys, lists, finite numbers or None."""
    if isinstance(v, Mapping):
        return {str(k): json_clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple, np.ndarray)):
        return [json_clean(x) for x in v]
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not np.isfinite(v):
        return None
    if v is None or isinstance(v, (str, int, float, bool)):
        return v
    return str(v)


def _num(v) -> float:
    """A JSON number back as a float (``null``: NaN)."""
    return math.nan if v is None else float(v)


def _array(v) -> np.ndarray:
    """A JSON list (of lists) of numbers back as a float array (``null``: NaN)."""
    return np.array(v, dtype=float)


def _bounds(v) -> tuple[float, float]:
    """``[low, high]`` back (``null``: unbounded on that side; absent: unbounded)."""
    lo, hi = v if v is not None else (None, None)
    return (-math.inf if lo is None else float(lo), math.inf if hi is None else float(hi))


def _spec(d: Mapping) -> ParameterSpec:
    """A parameter family as :meth:`EstimationResult.to_json` wrote it."""
    d = dict(d)
    d["bounds"] = _bounds(d.get("bounds"))
    if d.get("breakpoints") is not None:
        d["breakpoints"] = tuple(d["breakpoints"])
    d["fixed_elements"] = tuple(d.get("fixed_elements", ()))
    return ParameterSpec(**d)


def _frame(rows: Sequence[Mapping], columns: Sequence[str]) -> pd.DataFrame:
    """Records back as a table: a column of numbers and nulls is a float column (NaN)."""
    df = pd.DataFrame.from_records(list(rows), columns=list(columns))
    for c in df.columns:
        vals = df[c].tolist()
        if all(v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)) for v in vals) and any(
                v is None for v in vals):
            df[c] = np.array([_num(v) for v in vals], dtype=float)
    return df
