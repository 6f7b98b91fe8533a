"""Faults injected into good flight data are named by the verdict (issue 10, must-show 2).

One small, good dataset is flown once: PV1-NP at Mach 0.5, a pitch doublet (m0000) and a pull-up
with rudder doublets (m0001; rudder 0.4 keeps the sideslip within about +-1.3 deg, so that
sideslip written in degrees but declared as radians passes the import's 1.6 rad range check),
typical errors, a steady wind, calm air, and the linear local-flow truth and airdata-computer
baseline, which the model set represents exactly: the base fit is a success whose one warning is
that its maneuvers turn no heading, so that only the airspeed's changes tell the sideslip offsets
from the steady crosswind (``crosswind_confounded``: true of these maneuvers; asserted first, on
both routes in, and nothing else). Every fault below is judged by its own findings beyond that one
(:data:`BASE_WARNINGS`), which the ranking the tests read leaves out.
The same maneuvers are flown once more in light turbulence.

Each fault is injected into a copy, the way a user meets it:

- data faults (a stuck vane, a dead channel, a single-sample spike, a sign-flipped accelerometer,
  dead gyros) in the copied dataset's Parquet files (manifest entry kept), read with
  ``problem_from_dataset``: the fault is in the recorded data, and everything derived from the
  data at import (start values of the initial conditions, the import checks) sees it;
- unit mistakes (sideslip in degrees declared as radians, pressure altitude in feet declared as
  metres, a flow angle in radians declared as degrees) in a user CSV + problem file read with
  ``load_problem``, because the problem file is where a user declares units. Each passes the
  import's checks (asserted), so the verdict is what catches it.

For each fault: the verdict is never a clean success (which the base's own warning already makes
true: the checks that decide are the next ones); it has the severity the fault deserves; the
first warning-or-failure finding beyond the base's own in the order the user reads them (``summary()``,
``findings.csv``: most severe first) has the fault's code and names its channel, maneuver and
time; and no data-fault finding (stuck, dead, dead input, accelerometer sign, unit error) names a
channel or maneuver that was not faulted. Turbulence is the exception to "first": parameters the
unmodelled air motion pushes onto their bounds are listed before it (see its test).

The fits take 0.5-2 s each but two: the flipped accelerometer, and the dead gyros in the rudder
doublets (an expected failure: estimate() raises there, see its test), drive the staged start
into a damped crawl (~8 s each).
"""

from __future__ import annotations

import re
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from campaigns.benchmarks.user_files import DEG, FT, USER_COLUMNS, write_user_files
from campaigns.cli import EXIT_STATUS, main
from estimator.io import load_problem, problem_from_dataset
from estimator.solver import SolverOptions, estimate
from estimator.verdict import Finding, Severity, Verdict
from synth.campaign import resolve_campaign_path
from synth.dataset import copy_with_edits, load_dataset

#: The shipped campaign campaigns/faults_base.toml, which the bad-input corpus
#: (campaigns/benchmarks/bad_inputs.py) flies too: the nose probe's irregularity and high-AOA noise
#: are off there (model-structure errors of the linear pair, which the verdict warns about): the
#: base must be a success with no warning but its own (BASE_WARNINGS).
CAMPAIGN = tomllib.loads(resolve_campaign_path("faults_base").read_text(encoding="utf-8"))
DOUBLET, RUDDER = "m0000", "m0001"

#: Codes of findings that name a fault in the data itself (estimator/diagnostics.py, "Order and
#: attribution"); their consequences (misfit, scale_error, noise_floor, ...) may appear anywhere.
DATA_FAULTS = {"stuck_channel", "dead_channel", "dead_input", "accel_sign", "unit_error"}

#: every test here flies (the module's two flights) or estimates for a second or more
pytestmark = pytest.mark.slow


# ----------------------------------------------------------------------------------------------
# data and helpers


@pytest.fixture(scope="module")
def flights(fly_once):
    """The calm base dataset and the same maneuvers in light turbulence (shared: faults go into copies)."""
    out = {}
    for turbulence in ("none", "light"):
        camp = {**CAMPAIGN, "environment": {**CAMPAIGN["environment"], "turbulence": turbulence}}
        out[turbulence] = fly_once(camp, f"test_faults ({turbulence})")
    return out


@pytest.fixture(scope="module")
def base(flights) -> Path:
    return flights["none"]


def _problem(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # channels without data (the boom's) are left out: a DataWarning
        return problem_from_dataset(path)


@pytest.fixture(scope="module")
def clean(base):
    return estimate(_problem(base))


def _faulted_copy(base: Path, dest: Path, edits) -> Path:
    """A copy of the dataset with ``edits[maneuver id](DataFrame) -> DataFrame`` applied."""
    return copy_with_edits(base, dest, edits)


def _times(base: Path, mid: str) -> np.ndarray:
    return load_dataset(base).load(mid)["t_s"].to_numpy()


#: The base's own warning: its pitch doublet and rudder doublets turn no heading, so the sideslip
#: offsets are told from the steady crosswind only through the airspeed's changes (true of the
#: maneuvers, whatever the data's faults)
BASE_WARNINGS = frozenset({"crosswind_confounded"})


def _ranked(result) -> list[Finding]:
    """Warnings and failures in the order the user reads them (summary(), findings.csv), without
    the base's own (:data:`BASE_WARNINGS`)."""
    ranked = sorted(result.findings, key=lambda f: -int(f.severity))
    return [f for f in ranked if f.severity >= Severity.WARNING and f.code not in BASE_WARNINGS]


def _assert_base(result) -> None:
    """A success whose only warnings are the base's own, each naming the sideslip offsets."""
    text = result.summary(max_findings=40)
    assert result.verdict == Verdict.SUCCESS_WITH_WARNINGS, text
    assert not _ranked(result), text
    own = [f for f in result.findings if f.code in BASE_WARNINGS]
    # the side probe's offset, and the nose probe's where the data have it (not in the user file)
    assert len(own) == 1 and "b_sb[PV1]" in own[0].parameters, text
    assert set(own[0].parameters) <= {"b_sb[PV1]", "b_n[PV1]"}, text


def _first(result) -> Finding:
    ranked = _ranked(result)
    assert ranked, f"no warning or failure at all:\n{result.summary()}"
    return ranked[0]


def _assert_named(result, code: str, severity: Severity, channel: str, maneuver: str | None,
                  faulted: set[tuple[str, str | None]]) -> Finding:
    """The verdict is not a clean success, the first finding is the fault, and no data-fault finding
    points anywhere but at the faulted (channel, maneuver) pairs (maneuver None: any)."""
    text = result.summary(max_findings=40)
    assert result.verdict != Verdict.SUCCESS, text
    if severity == Severity.FAILURE:
        assert result.verdict == Verdict.FAILURE, text
    first = _first(result)
    assert (first.code, first.channel) == (code, channel), text
    if maneuver is not None:
        assert first.maneuver == maneuver, text
    assert first.severity >= severity, text
    wrong = [f for f in result.findings if f.code in DATA_FAULTS
             and (f.channel, f.maneuver) not in faulted and (f.channel, None) not in faulted]
    assert not wrong, "data faults attributed to what was not faulted:\n" + "\n".join(f.text() for f in wrong)
    return first


# ----------------------------------------------------------------------------------------------
# the base


def test_the_base_is_a_success_with_only_its_own_warning(clean):
    # no other warning: every fault below is then the cause of what its findings say
    _assert_base(clean)


# ----------------------------------------------------------------------------------------------
# data faults in the recorded data


@pytest.fixture(scope="module")
def stuck(base, tmp_path_factory):
    """alpha_zl freezes in the pitch doublet 15 s in and stays frozen to the end."""
    t = _times(base, DOUBLET)
    i = int(np.searchsorted(t, t[0] + 15.0))

    def edit(df):
        v = df["alpha_zl_rad"].to_numpy().copy()
        v[i:] = v[i]
        return df.assign(alpha_zl_rad=v)

    path = _faulted_copy(base, tmp_path_factory.mktemp("stuck") / "ds", {DOUBLET: edit})
    return path, (t[i], t[-1]), estimate(_problem(path))


def test_stuck_vane(stuck):
    _, (t0, t1), res = stuck
    f = _assert_named(res, "stuck_channel", Severity.FAILURE, "alpha_zl", DOUBLET, {("alpha_zl", DOUBLET)})
    # the stuck range: from the sample it froze at to the end, to within half a sample (25 ms)
    assert len(f.t_s) == 2 and f.t_s == pytest.approx((t0, t1), abs=0.0126), f.message
    assert "stuck" in f.message and "alpha_zl" in f.message and DOUBLET in f.message


def test_dead_channel(base, tmp_path_factory):
    """The side probe's sideslip reads exactly 0 through the rudder doublets (where it moves)."""
    t = _times(base, RUDDER)
    path = _faulted_copy(base, tmp_path_factory.mktemp("dead") / "ds",
                         {RUDDER: lambda df: df.assign(beta_zsp_rad=0.0)})
    res = estimate(_problem(path))
    f = _assert_named(res, "dead_channel", Severity.FAILURE, "beta_zsp", RUDDER, {("beta_zsp", RUDDER)})
    assert f.t_s == pytest.approx((t[0], t[-1]), abs=0.0126), f.message  # the whole maneuver
    assert "dead" in f.message


SPIKE_DEG = 30.0


@pytest.fixture(scope="module")
def spiked(base, tmp_path_factory):
    """One sample of alpha_zl in the pitch doublet 30 deg off, 12 s in (amid the doublet's
    excitation, not at an edge of the maneuver)."""
    t = _times(base, DOUBLET)
    i = int(np.searchsorted(t, t[0] + 12.0))

    def edit(df):
        v = df["alpha_zl_rad"].to_numpy().copy()
        v[i] += SPIKE_DEG / DEG
        return df.assign(alpha_zl_rad=v)

    path = _faulted_copy(base, tmp_path_factory.mktemp("spike") / "ds", {DOUBLET: edit})
    problem = _problem(path)
    return t[i], float(np.median(np.diff(t))), problem, estimate(problem)


def test_single_sample_spike(spiked):
    t_spike, dt, _, res = spiked
    # a warning, not a failure: one bad sample barely moves the fit (the robust option removes it)
    f = _assert_named(res, "outlier", Severity.WARNING, "alpha_zl", DOUBLET, set())
    assert res.verdict == Verdict.SUCCESS_WITH_WARNINGS, res.summary()
    assert len(f.t_s) == 1 and abs(f.t_s[0] - t_spike) <= 0.5 * dt, (f.t_s, t_spike)
    assert f.value == 1, f.message  # one sample
    # its size is reported: the residual of that sample, the spike plus the noise and fit error
    # there (hundredths of a degree)
    largest = re.search(r"the largest ([0-9.]+) deg", f.message)
    assert largest and abs(float(largest.group(1)) - SPIKE_DEG) < 0.5, f.message


def test_robust_option_excludes_the_spike(spiked, clean):
    t_spike, dt, problem, res = spiked
    robust = estimate(problem, SolverOptions(robust=True))
    # nothing left to warn about once the sample is out but the base's own warning
    _assert_base(robust)
    excluded = [f for f in robust.findings if f.code == "excluded"]
    assert len(excluded) == 1, robust.summary()
    f = excluded[0]
    assert (f.channel, f.maneuver) == ("alpha_zl", DOUBLET)
    assert len(f.t_s) == 1 and abs(f.t_s[0] - t_spike) <= 0.5 * dt, f.t_s
    # the outlier warning is gone with the sample
    assert not [g for g in robust.findings if g.code == "outlier"], robust.summary()
    key, sigma = "b_l[PV1]", clean.std("b_l[PV1]")
    moved = abs(res.value(key) - clean.value(key))
    back = abs(robust.value(key) - clean.value(key))
    # the spike moved the left vane's bias visibly (2.4 clean Cramér-Rao deviations here); without
    # that, "moves back" below would prove nothing
    assert moved > 1.5 * sigma, (moved / sigma, "the spike must move b_l for this test to mean anything")
    # ... and the robust fit, the same data less that one sample, moves it back: within 3 deviations
    # of the clean fit as the issue asks, and in fact within half of one (one sample of 2384 has
    # no leverage to move it further)
    assert back < 3.0 * sigma and back < 0.5 * sigma, (back / sigma, moved / sigma)


@pytest.mark.parametrize("maneuver", [DOUBLET, RUDDER])
def test_sign_flipped_accelerometer(base, tmp_path_factory, maneuver):
    """The body-z accelerometer recorded with the wrong sign in one maneuver. The fault drags the
    shared parameters and with them the other maneuver's fit; no data fault may be blamed there (a
    slope of the altitude there was once read as "m/s declared as knots": the unit conversions
    offered are now those of the channel's own quantity)."""
    path = _faulted_copy(base, tmp_path_factory.mktemp(f"azflip_{maneuver}") / "ds",
                         {maneuver: lambda df: df.assign(az_imu_mps2=-df["az_imu_mps2"])})
    res = estimate(_problem(path))
    f = _assert_named(res, "accel_sign", Severity.FAILURE, "az_imu_mps2", maneuver,
                      {("az_imu_mps2", maneuver)})
    assert "sign is flipped" in f.message, f.message


def _dead_gyros(df):
    return df.assign(p_rps=0.0, q_rps=0.0, r_rps=0.0)


@pytest.mark.parametrize("maneuver", [
    DOUBLET,
    # the rudder doublets: the staged start leaves f3 at its +-0.2 bounds, and putting the parameters
    # the identifiability screen holds back at their start values would make the side-probe table
    # steeper than 1:1, where the implicit alpha_zsp model does not converge (estimate() used to
    # raise there): they stay where the estimation left them, and the verdict still names the gyros
    RUDDER,
])
def test_zero_gyros(base, tmp_path_factory, maneuver):
    t = _times(base, maneuver)
    path = _faulted_copy(base, tmp_path_factory.mktemp(f"gyro0_{maneuver}") / "ds", {maneuver: _dead_gyros})
    res = estimate(_problem(path))
    faulted = {(c, maneuver) for c in ("p_rps", "q_rps", "r_rps")}
    _assert_named(res, "dead_input", Severity.FAILURE, "p_rps", maneuver, faulted)
    dead = {f.channel: f for f in res.findings if f.code == "dead_input"}
    assert set(dead) == {"p_rps", "q_rps", "r_rps"}, res.summary()  # all three, each by name
    for f in dead.values():
        assert f.severity == Severity.FAILURE and f.maneuver == maneuver
        assert f.t_s == pytest.approx((t[0], t[-1]), abs=0.0126), f.message  # the whole maneuver


def test_light_turbulence(flights):
    """The calibration maneuvers flown in light turbulence: each maneuver is reported, once, as
    turbulence (the output-error method models no air motion), not as a sensor fault."""
    res = estimate(_problem(flights["light"]))
    text = res.summary(max_findings=40)
    assert res.verdict != Verdict.SUCCESS, text
    turb = {f.maneuver: f for f in res.findings if f.code == "turbulence"}
    assert set(turb) == {DOUBLET, RUDDER}, text
    for f in turb.values():
        assert f.severity >= Severity.WARNING
        # every air-relative channel moves alike: all flow channels and the airspeed are named
        named = {c.strip() for c in (f.channel or "").split(",")}
        assert {"alpha_zl", "alpha_zr", "alpha_zsp", "beta_zsp", "beta_znp", "tas"} <= named, f.channel
    # not mistaken for a sensor fault, and nothing worse than the turbulence itself
    assert not [f for f in res.findings if f.code in DATA_FAULTS], text
    assert max(f.severity for f in res.findings) <= max(f.severity for f in turb.values()), text
    # the first warning a user reads (summary(), findings.csv) is the turbulence, before the tables
    # the air motion pushes onto their bounds (f4, k_spr: the identifiability checks' warnings)
    assert _ranked(res)[0].code == "turbulence", text


# ----------------------------------------------------------------------------------------------
# unit mistakes in a user's problem file

#: The user's columns and channels (bad_inputs.py's without the DGPS height, Mach and gear)
USER_CHANNELS = ["phi", "theta", "psi", "tas", "h", "alpha_zl", "alpha_zr", "alpha_zsp", "beta_zsp"]
USER_FILE_COLUMNS = {k: USER_COLUMNS[k] for k in ("ax", "ay", "az", "p", "q", "r", *USER_CHANNELS)}


def _write_user_files(ds_dir: Path, out: Path, wrong: tuple[str, float, str] | None = None) -> Path:
    """One CSV of both maneuvers in engineering units, and its problem file
    (:func:`campaigns.benchmarks.user_files.write_user_files`). ``wrong = (channel, factor,
    declared)``: that channel is written as ``SI value * factor`` and declared in unit ``declared``."""
    cols = dict(USER_FILE_COLUMNS)
    if wrong is not None:
        name, factor, declared = wrong
        csv, src, _, _, extra = cols[name]
        cols[name] = (csv, src, factor, declared, extra)
    return write_user_files(ds_dir, out, cols, USER_CHANNELS, "fault injection: units")


def test_the_base_user_file_is_a_success_with_only_its_own_warning(base, tmp_path):
    _assert_base(estimate(load_problem(_write_user_files(base, tmp_path / "user"))))


@pytest.mark.parametrize("wrong, phrase, maneuver", [
    # sideslip within +-1.3 deg written in degrees, declared rad: below the 1.6 rad range check.
    # Only the rudder doublets move the sideslip enough to tell (the doublet's varies by 0.2 deg)
    (("beta_zsp", DEG, "rad"), "recorded in degrees but declared as radians", RUDDER),
    # pressure altitude 6000 m written in feet (19 700), declared m: inside the -500..25 000 m check
    (("h", FT, "m"), "recorded in feet but declared as metres", None),
    # side-probe AOA written in radians, declared deg: a few hundredths of a degree pass any range check
    (("alpha_zsp", 1.0, "deg"), "recorded in radians but declared as degrees", None),
], ids=["beta_deg_declared_rad", "h_ft_declared_m", "alpha_rad_declared_deg"])
def test_unit_mistake_in_the_problem_file(base, tmp_path, wrong, phrase, maneuver):
    problem = load_problem(_write_user_files(base, tmp_path / "user", wrong))  # the import lets it pass
    res = estimate(problem)
    channel = wrong[0]
    # the whole file is in the wrong unit: a unit error may be named in any maneuver, on that channel only
    f = _assert_named(res, "unit_error", Severity.FAILURE, channel, maneuver, {(channel, None)})
    assert f.maneuver in {m.id for m in problem.maneuvers}
    assert phrase in f.message, f.message


# ----------------------------------------------------------------------------------------------
# the command line


def test_cli_exit_status_and_findings_name_the_stuck_vane(stuck, tmp_path, capsys):
    path, _, _ = stuck
    out = tmp_path / "res"
    code = main(["calibrate", str(path), "--single", "--out", str(out), "--no-plots"])
    text = capsys.readouterr().out
    assert code == EXIT_STATUS["FAILURE"] == 1, text
    assert f"alpha_zl in maneuver {DOUBLET} is stuck" in text, text
    assert "VERDICT: FAILURE" in text
    findings = pd.read_csv(out / "findings.csv")
    top = findings.iloc[0]
    assert (top["code"], top["severity"], top["channel"], top["maneuver"]) == (
        "stuck_channel", "FAILURE", "alpha_zl", DOUBLET), findings.head().to_string()
