"""Each thing said once, at the severity it deserves (SPEC §9): the kinds table, the grouping, the
console, and the severity rules that judge a residual by its effect.

Fast: hand-made findings and hand-made residuals (``tests/estimator_tests/test_diagnostics.py``'s
helpers), no flight.
"""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest
from test_diagnostics import D2R, clean_maneuver, fit, inputs

from estimator.diagnostics import ChannelFit, DiagnosticOptions, diagnose
from estimator.finding_groups import group_findings, verdict_text
from estimator.finding_kinds import KINDS, kinds_markdown
from estimator.verdict import Finding, Severity, Status, Verdict, judge

ROOT = Path(__file__).resolve().parents[2]


# ------------------------------------------------------------------------------------------------
# the kinds table
# ------------------------------------------------------------------------------------------------


def _emitted_codes() -> set[str]:
    """Every literal code a ``Finding(...)`` of the code base is made with, and the codes made from
    names (a stuck channel's, a ratio finding's, a failed status's)."""
    codes = set()
    for path in (*ROOT.joinpath("estimator").rglob("*.py"), *ROOT.joinpath("campaigns").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "Finding" and node.args:
                if isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str):
                    codes.add(node.args[0].value)
    dynamic = {"dead_channel", "stuck_channel", "misfit", "noise_floor",
               *(s.name.lower() for s in Status if not s.success)}
    return codes | dynamic


def test_every_code_the_estimator_emits_has_a_severity_in_the_table():
    missing = sorted(_emitted_codes() - set(KINDS))
    assert not missing, f"finding codes without a row in estimator.finding_kinds.KINDS: {missing}"
    for k in KINDS.values():
        assert k.severity in ("FAILURE", "WARNING", "NOTE", "rule"), k
        assert k.severity != "rule" or k.rule, f"{k.code}: a severity by rule needs its rule said"


def test_the_users_page_shows_the_table_as_it_is():
    page = ROOT.joinpath("docs", "verdict.md").read_text(encoding="utf-8")
    assert kinds_markdown() in page, "docs/verdict.md is out of date: paste kinds_markdown() into it"


def test_info_is_read_back_as_note():
    f = Finding.from_dict({"code": "held", "severity": "INFO", "message": "m"})
    assert f.severity is Severity.NOTE and Severity.INFO is Severity.NOTE
    assert Finding.from_dict(f.to_dict()) == f


# ------------------------------------------------------------------------------------------------
# groups
# ------------------------------------------------------------------------------------------------


def _residual(man: str, ratio: float, sev: Severity = Severity.NOTE, channel: str = "beta_znp",
              stage: str | None = None, code: str = "noise_floor") -> Finding:
    return Finding(code, sev, f"{channel} in maneuver {man}: residual", "act", channel=channel,
                   maneuver=man, t_s=(1.0, 9.0), value=ratio, stage=stage,
                   numbers={"ratio": ratio, "rms_deg": 0.03 * ratio, "rho1": 0.9})


def test_one_kind_on_one_channel_in_one_estimation_is_one_group_with_counts_and_ranges():
    findings = [_residual(f"m{k:02d}", 3.3 + 0.2 * k) for k in range(11)]
    findings += [_residual("m03", 2.5, channel="beta_zsp")]
    groups = group_findings(findings, 49)
    assert len(groups) == 2
    g = next(g for g in groups if g.channel == "beta_znp")
    assert len(g.members) == 11 and g.members[0].maneuver == "m10", "the worst first"
    assert "in 11 of 49 maneuvers" in g.headline, g.headline
    assert "3.3-5.3 x its noise floor" in g.headline, g.headline
    assert "the largest in m10 (t = 1.0-9.0 s)" in g.headline, g.headline


def test_each_estimation_is_its_own_group():
    findings = [_residual("m01", 3.0, stage="Mach 0.50 gear up"),
                _residual("m02", 3.0, stage="Mach 0.70 gear up")]
    assert len(group_findings(findings)) == 2


def test_a_group_has_its_worst_members_severity_and_names_them():
    findings = [_residual("m01", 3.0), _residual("m02", 5.0, Severity.WARNING), _residual("m03", 4.0)]
    (g,) = group_findings(findings, 10)
    assert g.severity == Severity.WARNING and g.members[0].maneuver == "m02"
    assert "[warning: 1 of them, m02; the others: 2 note(s)]" in g.headline, g.headline


def test_kinds_about_parameters_are_one_group_over_their_parameters():
    findings = [Finding("on_bound", Severity.WARNING, f"{p} is on its bound", "check", parameters=(p,),
                        value=1.0) for p in ("tau_bu", "f4[1]", "f5[0]")]
    (g,) = group_findings(findings)
    assert "and 2 more like it" in g.headline and "f4[1]" in g.headline and "f5[0]" in g.headline


def test_failures_then_warnings_then_notes_and_the_datas_faults_first():
    findings = [_residual("m01", 3.0, Severity.NOTE),
                _residual("m01", 40.0, Severity.FAILURE, channel="theta", code="misfit"),
                Finding("stuck_channel", Severity.FAILURE, "alpha_zl stuck", channel="alpha_zl",
                        maneuver="m01"),
                Finding("on_bound", Severity.WARNING, "k is on its bound", parameters=("k",))]
    order = [(g.severity, g.code) for g in group_findings(findings)]
    assert order == [(Severity.FAILURE, "stuck_channel"), (Severity.FAILURE, "misfit"),
                     (Severity.WARNING, "on_bound"), (Severity.NOTE, "noise_floor")]


def test_the_console_shows_every_failure_and_warning_then_notes_to_ten_lines():
    acting = [Finding("on_bound", Severity.WARNING, f"{p} on its bound", "widen", parameters=(p,))
              for p in ("a",)] + [Finding("stuck_channel", Severity.FAILURE, "stuck", channel=f"c{k}",
                                          maneuver="m1") for k in range(3)]
    notes = [_residual("m1", 3.0, channel=f"n{k}") for k in range(12)]
    text = verdict_text(judge(Status.CONVERGED_STEP, acting + notes), acting + notes, max_lines=10)
    lines = text.splitlines()
    assert lines[0].startswith("VERDICT: FAILURE")
    assert sum(ln.startswith("  FAILURE") for ln in lines) == 3
    assert sum(ln.startswith("  WARNING") for ln in lines) == 1
    assert len(lines) - 1 <= 10, "about ten finding lines"
    assert lines[-1] == "  ... 7 more note(s) in findings.csv", lines[-1]
    assert "widen" in text and "act" not in text.split("NOTE", 1)[1], "notes carry no advice"


def test_notes_alone_are_a_success():
    notes = [_residual("m1", 3.0)]
    assert judge(Status.CONVERGED_STEP, notes) == Verdict.SUCCESS


# ------------------------------------------------------------------------------------------------
# severities by effect
# ------------------------------------------------------------------------------------------------


def _flow(excess: float, desired_deg: float | None, seed: int = 10) -> list[ChannelFit]:
    """A clean maneuver whose left vane carries a smooth structure error: ``excess`` x its floor."""
    rng = np.random.default_rng(seed)
    fits = {f.channel: f for f in clean_maneuver("m0", rng)}
    f = fits["alpha_zl"]
    smooth = math.sqrt(excess**2 - 1) * 0.05 * D2R * math.sqrt(2) * np.sin(2 * np.pi * 0.3 * f.t_s)
    fits["alpha_zl"] = ChannelFit("m0", "alpha_zl", True, f.t_s, f.z + smooth, f.y, f.t_s, f.z + smooth,
                                  unit="rad", display_scale=1 / D2R, display_unit="deg",
                                  desired_3sigma=None if desired_deg is None else math.radians(desired_deg))
    return list(fits.values())


@pytest.mark.parametrize("desired_deg, severity", [
    (0.5, Severity.NOTE),      # 3 sigma = 3 x 0.15 deg = 0.45: within
    (0.3, Severity.WARNING),   # beyond
    (None, Severity.WARNING)])  # no stated accuracy: nothing says it is harmless
def test_a_flow_residual_is_judged_against_its_desired_accuracy(desired_deg, severity):
    d = diagnose(_flow(3.0, desired_deg))
    (f,) = [x for x in d.findings if x.channel == "alpha_zl"]
    assert f.code == "noise_floor" and f.severity == severity, f.text()
    if desired_deg is not None:
        assert f.numbers["desired_deg"] == pytest.approx(desired_deg), "the requirement said as given"
        assert f.numbers["scatter_three_sigma_deg"] == pytest.approx(0.45, rel=0.05), "3 x rms, 3 x 0.15 deg"


def test_a_low_alpha_channel_beyond_its_usable_range_is_a_note():
    """The nose probe's error grows above 12 deg of alpha (paper Fig. 7): its Table 2 is judged
    below that alpha, where it meets its accuracy; the excess above is said as a note."""
    rng = np.random.default_rng(3)
    n = 2400
    t = np.arange(n) / 40.0
    alpha = np.radians(2.0 + 14.0 * t / t[-1])  # a wind-up turn: 2 to 16 deg
    y = 0.5 * np.sin(t / 5) * D2R
    noise = 0.05 * D2R * rng.standard_normal(n)
    grow = np.where(alpha > np.radians(12.0), 0.6 * D2R * np.sin(2 * np.pi * 0.7 * t), 0.0)
    z = y + noise + grow
    f = ChannelFit("m0", "beta_znp", True, t, z, y, t, z, unit="rad", display_scale=1 / D2R,
                   display_unit="deg", desired_3sigma=math.radians(0.5), low_alpha_only=True)
    states = np.zeros((n, 7))
    states[:, 0] = 150.0 * np.cos(alpha)
    states[:, 2] = 150.0 * np.sin(alpha)
    m = inputs("m0", rng, n=n)
    m = type(m)("m0", t, m.accel_imu_mps2, m.omega_rps, states, m.euler_measured_rad)
    d = diagnose([f], [m], DiagnosticOptions(min_band_samples=100))
    (g,) = [x for x in d.findings if x.code == "noise_floor"]
    assert g.severity == Severity.NOTE and "usable range" in g.message, g.text()
    assert g.numbers["usable_alpha_deg"] == pytest.approx(12.0), (
        "the error grows above 12 deg: the last 2-deg band that passes ends there")
    assert g.numbers["scatter_three_sigma_below_deg"] < 0.5 < g.numbers["scatter_three_sigma_deg"], (
        "the excess lies above the usable range: within the accuracy below it, beyond it over all")


@pytest.mark.parametrize("spike_deg, severity", [(30.0, Severity.WARNING), (0.6, Severity.NOTE)])
def test_an_outlier_is_a_warning_where_it_matters(spike_deg, severity):
    """A 30-deg sample carries nearly all of the residual's sum of squares (and exceeds the
    accuracy); a 0.6-deg one, 12 floors, about 4 % of it (below 10 %) and within the accuracy."""
    fits = _flow(1.0001, 0.7, seed=4)
    i = next(k for k, f in enumerate(fits) if f.channel == "alpha_zl")
    f = fits[i]
    z = f.z.copy()
    z[800] += math.radians(spike_deg)
    fits[i] = ChannelFit("m0", "alpha_zl", True, f.t_s, z, f.y, f.t_s, z, unit="rad", display_scale=1 / D2R,
                         display_unit="deg", desired_3sigma=math.radians(0.7))
    d = diagnose(fits)
    (o,) = [x for x in d.findings if x.code == "outlier"]
    assert o.severity == severity and o.t_s == (f.t_s[800],), o.text()


@pytest.mark.parametrize("channel, unit, scale, amp, severity", [
    ("theta", "rad", D2R, 0.9, Severity.NOTE),      # 0.9 deg rms: a small UAV's AHRS
    ("theta", "rad", D2R, 2.0, Severity.FAILURE),   # beyond any working attitude reference (1.5)
    ("psi", "rad", D2R, 2.0, Severity.NOTE),        # a small UAV's heading
    ("psi", "rad", D2R, 3.0, Severity.FAILURE),     # beyond 2.5 deg
    ("tas", "m/s", 1.0, 1.5, Severity.NOTE),        # 1 % of 150 m/s: static-source error
    ("tas", "m/s", 1.0, 6.0, Severity.FAILURE),     # 4 %
    ("h", "m", 1.0, 20.0, Severity.NOTE),
    ("h", "m", 1.0, 80.0, Severity.FAILURE)])
def test_a_kinematic_misfit_fails_only_where_it_is_gross(channel, unit, scale, amp, severity):
    rng = np.random.default_rng(5)
    fits = {f.channel: f for f in clean_maneuver("m0", rng)}
    f = fits[channel]
    slow = amp * scale * math.sqrt(2) * np.sin(2 * np.pi * 0.05 * f.t_s)  # rms amp, slow and coloured
    fits[channel] = ChannelFit("m0", channel, False, f.t_s, f.z + slow, f.y, f.t_s, f.z + slow, unit=unit,
                               display_scale=1 / scale, display_unit="deg" if unit == "rad" else unit)
    d = diagnose(list(fits.values()))
    (g,) = [x for x in d.findings if x.channel == channel]
    assert (g.code, g.severity) == ("misfit", severity), g.text()
    if severity == Severity.NOTE:
        assert "real recorded data" in g.message and not g.advice


def test_a_kinematic_channel_recorded_with_its_sign_inverted_is_named():
    """The bank angle written with the wrong sign in every maneuver: its slope on the model output is
    -1 in each, the channel's median too (a unit or scale mistake is the channel's): named as a
    scale error whose sign is inverted, not as a misfit only."""
    rng = np.random.default_rng(8)
    fits = []
    for man in ("m0", "m1", "m2"):
        for f in clean_maneuver(man, rng):
            fits.append(fit(man, f.channel, f.t_s, f.y, -f.z) if f.channel == "phi" else f)
    d = diagnose(fits)
    named = [x for x in d.findings if x.channel == "phi" and x.code == "scale_error"]
    assert len(named) == 3 and all("sign is inverted" in x.message for x in named), [
        x.text() for x in d.findings if x.channel == "phi"]
