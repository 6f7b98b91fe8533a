"""The verdict of an estimation: what an engineer can act on, and why.

A converged solver is not a trustworthy result: a wrong minimum converges too, and so does a fit
to a stuck vane. The verdict joins the solver's :class:`Status` (did the iteration reach a
minimum?) with the findings of the fit-quality diagnostics (does the minimum explain the data?)
and of the identifiability checks (is every estimate determined by the data?):

=======================  ======  ===========================================================
verdict                  code    when
=======================  ======  ===========================================================
SUCCESS                   1      converged, and no finding is a warning or a failure (notes allowed)
SUCCESS_WITH_WARNINGS     2      converged, at least one warning, no failure
FAILURE                  -1      not converged, or at least one failure
=======================  ======  ===========================================================

Codes follow scipy's convention: positive is success. Each :class:`Finding` names what it found,
where (channel, maneuver, times), how large, and what to do.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType

import pandas as pd


class Status(enum.IntEnum):
    """How the Gauss-Newton iteration ended; each member carries its message (``.message``).

    scipy's rule: a positive status is a success (the iteration converged), zero or negative is
    not (``ITERATION_LIMIT`` is 0, as scipy's "maximum number of evaluations"); ``.success`` says
    which. The integer values are written to files (``result.json``, the Monte Carlo
    replications, the studies' tables) and never change meaning. The result's message adds the
    numbers to the member's.

    >>> Status.CONVERGED_DECREASE.success, Status.STALLED.success
    (True, False)
    >>> Status(-2).message
    'not converged: no step decreases the cost, yet the Gauss-Newton step is not negligible'
    """

    CONVERGED_STEP = 1, "converged: the undamped Gauss-Newton step is negligible against every deviation"
    CONVERGED_DECREASE = 2, "converged: the Gauss-Newton model predicts a negligible further cost decrease"
    ITERATION_LIMIT = 0, "not converged: iteration limit reached"
    STALLED = -2, "not converged: no step decreases the cost, yet the Gauss-Newton step is not negligible"
    MODEL_ERROR = -3, "failed: the model cannot be evaluated at these parameter values"
    UNDETERMINED = -4, "failed: no free parameter is determined by the data"

    message: str

    def __new__(cls, value: int, message: str):
        obj = int.__new__(cls, value)
        obj._value_ = value
        obj.message = message
        return obj

    @property
    def success(self) -> bool:
        """The iteration converged (the status is positive)."""
        return self.value > 0

    @property
    def converged(self) -> bool:
        """The same as :attr:`success` (the solver's own word for it)."""
        return self.success

    @property
    def label(self) -> str:
        """The member's name in words (``"converged step"``), for tables that store the code."""
        return self.name.lower().replace("_", " ")


class Severity(enum.IntEnum):
    """How much a finding weighs (SPEC §9: said once, at the severity it deserves).

    ``FAILURE``: the estimates must not be used (no convergence, a wrong minimum, a data fault, a
    turbulent fit under a method that cannot take it). ``WARNING``: the user should act (what and
    where the finding says). ``NOTE``: information, no action (a channel the model set has but the
    data lack, the nose probe's usable alpha range, coloured residuals already in the honest
    deviations). ``INFO`` is the old name of ``NOTE`` (an alias: files written before read back).

    >>> Severity["INFO"] is Severity.NOTE, Severity.NOTE.name
    (True, 'NOTE')
    """

    NOTE = 0
    WARNING = 1
    FAILURE = 2
    INFO = 0  # the alias of NOTE


class Verdict(enum.Enum):
    """The overall judgement (``.code`` follows scipy's convention, ``.text`` says what it means)."""

    SUCCESS = 1, "success: converged, and the fit explains the data"
    SUCCESS_WITH_WARNINGS = 2, "success with warnings: read each warning before using the estimates"
    FAILURE = -1, "failure: do not use these estimates"

    def __init__(self, code: int, text: str):
        self.code = code
        self.text = text

    @property
    def message(self) -> str:
        """What the verdict means (the same as ``.text``; :class:`Status` names it so too)."""
        return self.text

    @property
    def success(self) -> bool:
        return self.code > 0

    @property
    def rank(self) -> int:
        """0 for the best verdict (success), 2 for the worst (failure): for choosing between runs."""
        return {1: 0, 2: 1, -1: 2}[self.code]


@dataclass(frozen=True)
class Finding:
    """One thing the checks found.

    Attributes
    ----------
    code : what kind of finding, a short identifier (``"stuck_channel"``, ``"outlier"``,
        ``"misfit"``, ``"turbulence"``, ``"unit_error"``, ``"held"``, ``"on_bound"``, ...; every
        kind and its severity: :data:`estimator.finding_kinds.KINDS`).
    severity : NOTE, WARNING or FAILURE.
    message : what was found, with its numbers and where, as a full sentence.
    advice : what to do about it.
    channel : the channel (or IMU input, e.g. ``"az_imu"``) concerned, or None.
    maneuver : the maneuver id, or None (all / not maneuver-specific).
    t_s : the times concerned, s (an outlier's samples; a time range as ``(start, end)``).
    parameters : parameter keys concerned.
    value : the finding's key number (a ratio, a count, a slope), for tables.
    stage : the estimation of a workflow it comes from (``"Mach 0.50 gear up, biases free"``), or
        None (a single estimation, or the workflow itself).
    numbers : its other numbers by name (``ratio``, ``rms``, ``rho1``, ``three_sigma_deg``, ...;
        display units where the name says so), from which a group of findings states its ranges.
    """

    code: str
    severity: Severity
    message: str
    advice: str = ""
    channel: str | None = None
    maneuver: str | None = None
    t_s: tuple[float, ...] = ()
    parameters: tuple[str, ...] = ()
    value: float | None = None
    stage: str | None = None
    numbers: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        # frozen all the way down: whatever sequences the caller passed become tuples
        object.__setattr__(self, "severity", Severity(self.severity))
        object.__setattr__(self, "t_s", tuple(float(t) for t in self.t_s))
        object.__setattr__(self, "parameters", tuple(self.parameters))
        # a number that is not finite (not computed) says nothing: left out, so that a finding read
        # back from JSON equals the one written
        object.__setattr__(self, "numbers", MappingProxyType({str(k): float(v) for k, v in
                                                              dict(self.numbers).items()
                                                              if math.isfinite(float(v))}))

    def __hash__(self) -> int:  # the numbers' mapping is not hashable itself
        return hash((self.code, self.severity, self.message, self.channel, self.maneuver, self.stage))

    def text(self) -> str:
        """One line: severity, stage, message and advice."""
        where = f"{self.stage}: " if self.stage else ""
        out = f"{self.severity.name.lower()}: {where}{self.message}"
        return out + (f" — {self.advice}" if self.advice else "")

    def to_dict(self) -> dict:
        return {"code": self.code, "severity": self.severity.name, "stage": self.stage,
                "channel": self.channel, "maneuver": self.maneuver, "t_s": list(self.t_s),
                "parameters": list(self.parameters), "value": self.value, "message": self.message,
                "advice": self.advice,
                "numbers": dict(self.numbers)}

    @classmethod
    def from_dict(cls, d: dict) -> Finding:
        """The finding :meth:`to_dict` gave (severity by name, ``INFO`` read as NOTE; a ``null``
        value is None)."""
        return cls(code=d["code"], severity=Severity[d["severity"]], message=d["message"],
                   advice=d.get("advice", ""), channel=d.get("channel"), maneuver=d.get("maneuver"),
                   t_s=tuple(d.get("t_s", ())), parameters=tuple(d.get("parameters", ())),
                   value=None if d.get("value") is None else float(d["value"]), stage=d.get("stage"),
                   numbers={k: float(v) for k, v in (d.get("numbers") or {}).items() if v is not None})


def judge(status: Status, findings: Iterable[Finding]) -> Verdict:
    """The verdict of a solver status and the findings (module docstring)."""
    worst = max((f.severity for f in findings), default=Severity.NOTE)
    if not status.converged or worst >= Severity.FAILURE:
        return Verdict.FAILURE
    if worst >= Severity.WARNING:
        return Verdict.SUCCESS_WITH_WARNINGS
    return Verdict.SUCCESS


def findings_frame(findings: Sequence[Finding]) -> pd.DataFrame:
    """One row per finding, most severe first (columns of :meth:`Finding.to_dict`; ``numbers`` as
    ``name=value`` pairs)."""
    cols = ["code", "severity", "stage", "channel", "maneuver", "t_s", "parameters", "value", "message",
            "advice", "numbers"]
    rows = []
    for f in sorted(findings, key=lambda f: -int(f.severity)):
        d = f.to_dict()
        d["numbers"] = "; ".join(f"{k}={v:.6g}" for k, v in f.numbers.items())
        rows.append(d)
    return pd.DataFrame(rows, columns=cols)


def reasons(findings: Iterable[Finding]) -> list[Finding]:
    """The warnings and failures, most severe first (the order within a severity kept: the data's
    findings before the parameters')."""
    return sorted((f for f in findings if f.severity >= Severity.WARNING), key=lambda f: -int(f.severity))
