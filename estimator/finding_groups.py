"""Each thing said once: findings of one kind on one channel in one estimation become one group.

A fit of 49 maneuvers whose nose probe cannot follow the flow above 12 deg of alpha gives one
finding per maneuver; the user needs one line: the channel, what, how often, the range of its
numbers, the worst maneuver and time, what to do. :func:`group_findings` makes those groups (the
individual findings stay in ``findings.csv`` and ``result.json``); :func:`verdict_text` is what the
console shows: the verdict, every FAILURE and WARNING group (most important first), then as many
NOTEs as fit in about ten lines, and where the rest are.

Which findings form a group (:data:`estimator.finding_kinds.KINDS`, ``by_channel``): one kind, one
estimation (the finding's ``stage``) and, for the kinds about a channel, one channel; a channel's
residual above its floor is one kind, coloured (1.2-2 floors) or above 2 (misfit, structure). A group has
the severity of its most severe member, said first; where its members differ (a flow channel's
residual beyond its accuracy in 3 maneuvers, within it in 8), the headline names the severe ones.
Within a severity, groups are said in the kinds' order (the data's faults first: they explain the
rest), then by how many findings they hold.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass

import pandas as pd

from estimator.finding_kinds import ORDER, kind_of
from estimator.verdict import Finding, Severity, Verdict

__all__ = ["FindingGroup", "group_findings", "groups_frame", "verdict_text"]

#: A note's line on the console and in the report's banner is cut to this many characters (notes are
#: information; the whole of each is in finding_groups.csv and the report's findings table)
NOTE_CHARS = 240
#: The display unit a number's name ends in (``rms_deg``, ``rms_mps``) and how it is written.
_UNITS = {"deg": "deg", "m": "m", "mps": "m/s", "ms": "ms", "s": "s", "pa": "Pa", "mps2": "m/s^2",
          "degps": "deg/s"}


@dataclass(frozen=True)
class FindingGroup:
    """Findings of one kind, estimation and (for channel kinds) channel, said once.

    Attributes
    ----------
    code, stage, channel : what the members share (``channel`` None for a kind grouped over
        channels, e.g. the parameters on their bounds).
    severity : the most severe member's.
    members : the findings, the worst first.
    headline : one line with the counts, the ranges of their numbers and the worst maneuver and time.
    advice : what to do (the worst member's).
    n_maneuvers : maneuvers of the estimation, where known (for "in 11 of 49 maneuvers").
    """

    code: str
    severity: Severity
    stage: str | None
    channel: str | None
    members: tuple[Finding, ...]
    headline: str
    advice: str
    n_maneuvers: int | None = None

    @property
    def maneuvers(self) -> tuple[str, ...]:
        """The members' maneuvers, each once, in the members' order."""
        return tuple(dict.fromkeys(f.maneuver for f in self.members if f.maneuver))

    def text(self, advice: bool | None = None, note_chars: int | None = None) -> str:
        """One line: severity, estimation, headline and (failures and warnings) advice; a note cut
        to ``note_chars`` characters at a word (the whole in ``finding_groups.csv``), None: whole."""
        where = f"{self.stage}: " if self.stage else ""
        out = f"{self.severity.name}: {where}{self.headline}"
        with_advice = self.severity >= Severity.WARNING if advice is None else advice
        out += f" — {self.advice}" if with_advice and self.advice else ""
        if note_chars is not None and self.severity < Severity.WARNING and len(out) > note_chars:
            out = out[:note_chars].rsplit(" ", 1)[0] + " …"
        return out

    def to_dict(self) -> dict:
        return {"code": self.code, "severity": self.severity.name, "stage": self.stage,
                "channel": self.channel, "count": len(self.members), "maneuvers": list(self.maneuvers),
                "headline": self.headline, "advice": self.advice}


def _sort_key(g: FindingGroup) -> tuple:
    return (-int(g.severity), ORDER.get(g.code, len(ORDER)), -len(g.members))


def group_findings(findings: Iterable[Finding],
                   n_maneuvers: Mapping[str | None, int] | int | None = None) -> tuple[FindingGroup, ...]:
    """The findings as groups, most important first (module docstring).

    Parameters
    ----------
    findings : any findings (of one estimation, or of a workflow's stages: their ``stage`` differs).
    n_maneuvers : the maneuvers of each estimation (by stage; an int for every stage), for the
        groups' "k of n maneuvers"; None: counts only.
    """
    buckets: dict[tuple, list[Finding]] = {}
    for f in findings:
        kind = kind_of(f.code)
        key = (f.stage, _FAMILY.get(f.code, f.code), f.channel if kind.by_channel else None)
        buckets.setdefault(key, []).append(f)
    out = []
    for (stage, _, channel), members in buckets.items():
        n = n_maneuvers.get(stage) if isinstance(n_maneuvers, Mapping) else n_maneuvers
        members = sorted(members, key=_worst_key, reverse=True)
        code = members[0].code
        head = _headline(code, members, n)
        sev = members[0].severity
        if any(f.severity != sev for f in members):  # the severe ones said apart, with where
            severe = [f for f in members if f.severity == sev]
            lower = sorted({f.severity for f in members if f.severity != sev}, reverse=True)
            rest = ", ".join(f"{sum(f.severity == s for f in members)} {s.name.lower()}(s)" for s in lower)
            head += f" [{sev.name.lower()}: {len(severe)} of them, {_names(severe)}; the others: {rest}]"
        out.append(FindingGroup(code, sev, stage, channel, tuple(members), head, members[0].advice, n))
    return tuple(sorted(out, key=_sort_key))


#: Codes said as one group on a channel: a residual above its floor is one thing, whether the
#: diagnostics call it coloured (1.2-2 floors) or a misfit / structure error (above 2 floors)
_FAMILY = {"misfit": "residual", "noise_floor": "residual", "coloured": "residual"}


def _worst_key(f: Finding) -> tuple[int, float]:
    """The most severe first, then the largest value."""
    return int(f.severity), float("-inf") if f.value is None else abs(float(f.value))


def _names(members: Sequence[Finding], most: int = 6) -> str:
    """The members' maneuvers (or parameters, or channels), the first ``most`` of them."""
    names = list(dict.fromkeys(f.maneuver or ", ".join(f.parameters[:2]) or f.channel or "" for f in members))
    names = [x for x in names if x]
    return ", ".join(names[:most]) + (" ..." if len(names) > most else "")


# ------------------------------------------------------------------------------------------------
# headlines


def _span(values: Sequence[float], fmt: str = ".3g") -> str:
    lo, hi = min(values), max(values)
    a, b = format(lo, fmt), format(hi, fmt)
    return a if a == b else f"{a}-{b}"


def _unit_of(name: str) -> str:
    suffix = name.rsplit("_", 1)[-1]
    return _UNITS.get(suffix, "")


def _numbers(members: Sequence[Finding], name: str) -> list[float]:
    return [f.numbers[name] for f in members if name in f.numbers]


def _count(members: Sequence[Finding], n: int | None) -> str:
    k = len({f.maneuver for f in members if f.maneuver})
    if k == 0:
        return ""
    if k == 1 and n in (None, 1):
        return f"in maneuver {members[0].maneuver}"
    return f"in {k} of {n} maneuvers" if n else f"in {k} maneuvers"


def _at(f: Finding) -> str:
    if not f.t_s:
        return ""
    if len(f.t_s) == 2:
        return f" (t = {f.t_s[0]:.1f}-{f.t_s[1]:.1f} s)"
    return f" (t = {f.t_s[0]:.2f} s)"


def _residual(members: Sequence[Finding], n: int | None) -> str:
    """misfit, noise_floor, coloured: the residual's size, ratio and colour, how often, where worst,
    and why its severity (within the desired accuracy, beyond the usable alpha range)."""
    worst = members[0]
    rms_name = next((k for k in worst.numbers if k.startswith("rms_")), None)
    parts = []
    if rms_name:
        parts.append(f"residual {_span(_numbers(members, rms_name))} {_unit_of(rms_name)} rms".rstrip())
    if _numbers(members, "ratio"):
        parts.append(f"{_span(_numbers(members, 'ratio'), '.2g')} x its noise floor")
    if _numbers(members, "rho1"):
        parts.append(f"lag-1 autocorrelation {_span(_numbers(members, 'rho1'), '.2f')}")
    head = f"{worst.channel}: " + ", ".join(parts) + f" {_count(members, n)}"
    head += f"; the largest in {worst.maneuver}{_at(worst)}" if len(members) > 1 else _at(worst)
    pooled = _numbers(members, "pooled_scatter_three_sigma_deg")
    if pooled:
        des = members[0].numbers.get("desired_deg", float("nan"))
        lim = members[0].numbers.get("usable_alpha_deg")
        own = _numbers(members, "scatter_three_sigma_below_deg" if lim is not None
                       else "scatter_three_sigma_deg")
        below = f" below alpha {lim:.0f} deg (its usable range, paper Fig. 7)" if lim is not None else ""
        head += (f"; 3 sigma of the residual{below} {_span(own, '.2g')} deg per maneuver, "
                 f"{_span(pooled, '.2g')} deg over all, against its desired {des:.2g} deg")
        beyond = _numbers(members, "alpha_from_deg")
        if lim is not None and beyond:
            head += f"; the excess above alpha {_span(beyond, '.0f')} deg"
    return head


def _outlier(members: Sequence[Finding], n: int | None) -> str:
    worst = members[0]
    total = int(sum(f.value or 0 for f in members))
    name = next((k for k in worst.numbers if k.startswith("largest_abs_")), "")
    big = _numbers(members, name) if name else []
    unit = _unit_of(name) if name else ""
    size = f", up to {max(big):.3g} {unit}".rstrip() if big else ""
    return (f"{worst.channel}: {total} outlier sample(s){size} {_count(members, n)}; the largest in "
            f"{worst.maneuver}{_at(worst)}") if len(members) > 1 else worst.message


def _turbulence(members: Sequence[Finding], n: int | None) -> str:
    if len(members) == 1:
        return members[0].message
    chans = sorted({c.strip() for f in members for c in (f.channel or "").split(",") if c.strip()})
    ratio = _numbers(members, "ratio")
    return (f"turbulence or other unmodelled air motion {_count(members, n)}: the flow-angle"
            + (f" residuals {_span(ratio, '.2g')} x their noise floors," if ratio else "")
            + f" coloured and common to the sensors ({', '.join(chans)}) while the inertial channels fit; "
            f"the strongest in {members[0].maneuver}")


def _listed(members: Sequence[Finding], n: int | None) -> str:
    """Any other kind: the worst finding said whole, the others named."""
    worst = members[0]
    if len(members) == 1:
        return worst.message
    others = []
    for f in members[1:]:
        name = (", ".join(f.parameters[:3]) if f.parameters and not f.maneuver else
                f.maneuver or f.channel or "")
        if name:
            others.append(name)
    names = "; ".join(dict.fromkeys(others))
    count = _count(members, n)
    return (f"{worst.message} — and {len(members) - 1} more like it"
            + (f" ({count})" if count else "") + (f": {names}" if names else ""))


_HEADLINES: dict[str, Callable[[Sequence[Finding], int | None], str]] = {
    "misfit": _residual, "noise_floor": _residual, "coloured": _residual, "outlier": _outlier,
    "turbulence": _turbulence,
}


def _headline(code: str, members: Sequence[Finding], n: int | None) -> str:
    text = _HEADLINES.get(code, _listed)(members, n)
    return re.sub(r"\s+", " ", text).strip()


# ------------------------------------------------------------------------------------------------
# what the console and the files show


def groups_frame(groups: Sequence[FindingGroup]) -> pd.DataFrame:
    """One row per group (:meth:`FindingGroup.to_dict`), in the order said."""
    cols = ["severity", "code", "stage", "channel", "count", "maneuvers", "headline", "advice"]
    return pd.DataFrame([g.to_dict() for g in groups], columns=cols)


def verdict_text(verdict: Verdict, findings: Iterable[Finding] | Sequence[FindingGroup],
                 max_lines: int = 10, n_maneuvers: Mapping[str | None, int] | int | None = None,
                 where: str = "findings.csv") -> str:
    """``VERDICT: NAME — text``, then every FAILURE and WARNING group, then as many NOTE groups as
    fit in ``max_lines`` finding lines, and where the rest are."""
    items = list(findings)
    groups = (tuple(items) if items and isinstance(items[0], FindingGroup)
              else group_findings(items, n_maneuvers))
    lines = [f"VERDICT: {verdict.name.replace('_', ' ')} — {verdict.text}"]
    acting = [g for g in groups if g.severity >= Severity.WARNING]
    notes = [g for g in groups if g.severity < Severity.WARNING]
    lines += [f"  {g.text()}" for g in acting]
    room = max(max_lines - len(acting), 0)
    shown = notes[:room] if len(notes) <= room else notes[:max(room - 1, 0)]
    lines += [f"  {g.text(note_chars=NOTE_CHARS)}" for g in shown]
    rest = len(notes) - len(shown)
    if rest:
        lines.append(f"  ... {rest} more note(s) in {where}")
    return "\n".join(lines)
