"""Every kind of finding the estimator reports, and the severity it deserves (SPEC §9).

One table, :data:`KINDS`: each finding code the estimator, its diagnostics and the workflow emit,
with its severity (the rule, where it depends on what the finding measured), what it means and how
a group of them is said. ``docs/verdict.md`` shows the same table (:func:`kinds_markdown` writes it;
``tests/estimator_tests/test_said_once.py`` checks the two agree and that every code the code base
emits is here).

The three severities (:class:`~estimator.verdict.Severity`): FAILURE — the estimates must not be
used; WARNING — the user should act, and the finding says what and where; NOTE — information, no
action.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

__all__ = ["KINDS", "Kind", "kind_of", "kinds_markdown"]


@dataclass(frozen=True)
class Kind:
    """One kind of finding.

    Attributes
    ----------
    code : the finding's code.
    severity : ``"FAILURE"``, ``"WARNING"`` or ``"NOTE"``, or ``"rule"`` where it depends on the
        finding (then ``rule`` says how).
    source : the module that emits it.
    means : what it means, in a few words.
    rule : how its severity is decided, where it varies.
    by_channel : a group is one channel's findings of this kind in one estimation (True), or every
        finding of this kind in it (False: kinds about parameters, or the maneuver as a whole).
    cause : a fault of the data itself: said before the findings it may cause.
    """

    code: str
    severity: str
    source: str
    means: str
    rule: str = ""
    by_channel: bool = True
    cause: bool = False


_D, _S, _I, _U, _F, _W = ("diagnostics", "solver", "identifiability", "uncertainty", "filter_error",
                          "workflow")

#: Every kind, in the order a group of each is said within one severity: the data's faults first
#: (they explain the rest), then the fit, then the parameters, then the method's own notes.
KINDS: Mapping[str, Kind] = MappingProxyType({k.code: k for k in (
    Kind("model_error", "FAILURE", _S, "the model cannot be evaluated at the parameter values",
         by_channel=False),
    Kind("undetermined", "FAILURE", _S, "no free parameter is determined by the data", by_channel=False),
    Kind("dead_input", "FAILURE", _D, "an IMU axis constant while the attitude changes", cause=True),
    Kind("accel_sign", "FAILURE", _D, "the body-z specific force has the wrong sign", cause=True),
    Kind("dead_channel", "FAILURE", _D, "a channel reads exactly 0 while its model moves", cause=True),
    Kind("stuck_channel", "FAILURE", _D, "a channel frozen while its model moves", cause=True),
    Kind("unit_error", "FAILURE", _D, "a channel recorded in another unit than declared", cause=True),
    Kind("outlier", "rule", _D, "single samples far outside the channel's noise",
         "WARNING where they carry more than 10 % of the channel's residual sum of squares in the "
         "maneuver or exceed its desired accuracy (they drag the fit and Table 2: rerun with --robust); "
         "NOTE otherwise", cause=True),
    Kind("bin_failed", "FAILURE", _W, "a Mach bin's estimation failed; it is left out of the calibration",
         by_channel=False),
    Kind("iteration_limit", "FAILURE", _S, "the iteration limit was reached", by_channel=False),
    Kind("stalled", "FAILURE", _S, "no step decreases the cost, yet the step is not negligible",
         by_channel=False),
    Kind("not_converged", "FAILURE", _S, "the iterations did not converge", by_channel=False),
    Kind("misfit", "rule", _D, "a kinematic channel (attitude, heading, airspeed, height) misfits",
         "FAILURE where gross: above 3 x its floor and beyond what real data show (attitude 1.5 deg, "
         "heading 2.5 deg, speed the larger of 3 % and 2 m/s, height 50 m rms), or with the maneuver's "
         "state-equation parameters (IMU biases, initial conditions) on a bound: a wrong minimum or a "
         "data fault; NOTE otherwise: a slow, coloured residual a few times the white-noise floor is "
         "what real recorded data look like (filtered INS attitude, baro lag and static-source error, "
         "IMU scale and misalignment, vertical air motion); the honest deviations take its colour in, "
         "not a systematic error the model set lacks"),
    Kind("scale_error", "FAILURE", _D, "a misfitting channel is a multiple of its model output, no unit"),
    Kind("turbulence", "rule", _D, "flow and airspeed residuals common to every sensor: air motion",
         "FAILURE under the output-error method (it models no process noise: the estimates are "
         "biased); NOTE under the filter-error method, whose wind states take it in",
         by_channel=False),
    Kind("not_invertible", "FAILURE", _S, "a calibration that cannot be applied (a flat or folded table)"),
    Kind("noise_floor", "rule", _D, "a flow channel's residual above its noise floor: model structure",
         "judged by its effect on Table 2's 3 sigma: NOTE where the channel meets its desired accuracy in "
         "the maneuver or over the estimation (below its usable alpha range for a low-alpha-only channel, "
         "paper Fig. 7); WARNING beyond it, or with no stated accuracy; FAILURE beyond it with the "
         "channel's own calibration parameters on a bound (the model cannot represent the sensor)"),
    Kind("accuracy_miss", "WARNING", _W, "a Table 2 cell beyond its desired accuracy"),
    Kind("accuracy_unjudged", "WARNING", _W,
         "a Table 2 cell whose calibration deviation lies along a parameter on or near its bound"),
    Kind("coloured", "NOTE", _D, "a slow, coloured residual: Cramér-Rao deviations optimistic",
         "NOTE: the honest (coloured-residual) deviations take it in"),
    Kind("no_floor", "NOTE", _D, "too few samples to judge a channel's residual"),
    Kind("unidentifiable", "WARNING", _I, "parameters the data cannot tell apart", by_channel=False),
    Kind("confounded", "WARNING", _I, "parameters confounded by the maneuvers flown", by_channel=False),
    Kind("crosswind_confounded", "WARNING", _I,
         "sideslip offsets confounded with the wind: the maneuvers turn no heading", by_channel=False),
    Kind("on_bound", "rule", _I, "an estimate on its bound", "WARNING; NOTE for a maneuver's nuisance "
         "parameter (its bound only keeps the fit in range) and for a table value beyond its low-alpha "
         "channel's usable alpha range (paper Fig. 7)", by_channel=False),
    Kind("near_bound", "rule", _S, "an estimate within two deviations of its bound",
         "WARNING; NOTE for a delay the feedback check widened (that note says it) and for a table value "
         "beyond its low-alpha channel's usable alpha range", by_channel=False),
    Kind("poor_model", "WARNING", _S, "the Gauss-Newton model is poor: some parameters barely determined",
         by_channel=False),
    Kind("imu_noise_unknown", "WARNING", _U, "the IMU noise could not be estimated for the deviations",
         by_channel=False),
    Kind("delay_feedback", "NOTE", _F, "filter error: time delays biased by the aircraft's answer to gusts",
         "NOTE: the delays are widened to cover it (their honest deviations say it), or not judged",
         by_channel=False),
    Kind("delay_weak_instrument", "NOTE", _F, "filter error: a delay's instrument is weak: widened",
         "NOTE: its honest deviation is widened to what the instrument supports", by_channel=False),
    Kind("gust_answer", "rule", _F, "filter error: innovations correlate with the IMU's answer to gusts",
         "NOTE where the feedback check widened every delay it names (the honest deviations take it "
         "in); WARNING otherwise (a delay not judged, no honest deviations)", by_channel=False),
    Kind("filter_error_partial", "NOTE", _F, "filter error: what its deviations do not cover",
         "NOTE: said on every filter-error estimation (a property of the method, not of the flight; "
         "Table 2 carries the sideslip offsets' honest uncertainty)", by_channel=False),
    Kind("held", "NOTE", _I, "parameters held at their start values (no data, or undetermined)",
         by_channel=False),
    Kind("unexcited", "NOTE", _W, "the gear-down maneuvers do not move what some channels measure: "
         "their gains, tables, delays (and sideslip offsets) held at the nearest gear-up estimate",
         by_channel=False),
    Kind("correlated", "NOTE", _I, "highly correlated estimates (their deviations say it)",
         by_channel=False),
    Kind("imu_noise", "NOTE", _U, "the IMU noise's share of the honest deviations", by_channel=False),
    Kind("excluded", "NOTE", _S, "outlier samples the robust option left out of the fit"),
    Kind("crawled", "NOTE", _S,
         "converged at the iteration limit, within a tenth of a deviation of the minimum", by_channel=False),
    Kind("starts", "NOTE", _S, "several starts were tried; the best kept", by_channel=False),
    Kind("start", "NOTE", _S, "how the start and the estimation went (staged start, screens)",
         by_channel=False),
)})


def kind_of(code: str) -> Kind:
    """The kind of ``code``; an unknown code (a user's own, a later version's) is a channel-wise
    kind of its own, said after the known ones."""
    return KINDS.get(code) or Kind(code, "rule", "?", "")


#: Display order of the kinds within one severity.
ORDER: Mapping[str, int] = MappingProxyType({c: i for i, c in enumerate(KINDS)})


def kinds_markdown() -> str:
    """The table of :data:`KINDS` as Markdown (``docs/verdict.md`` holds it)."""
    lines = ["| code | severity | what it means | when (where the severity varies) |",
             "|---|---|---|---|"]
    for k in KINDS.values():
        rule = k.rule.replace("|", "/") if k.rule else ""
        lines.append(f"| `{k.code}` | {k.severity} | {k.means} | {rule} |")
    return "\n".join(lines)
