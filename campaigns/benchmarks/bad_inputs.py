"""Bad-input corpus: what a user sees when their own flight-data files are wrong.

    python campaigns/benchmarks/bad_inputs.py [--out DIR] [--only NAME ...] [--write FILE]

A small, good input is made once, the way an engineer brings one: a problem file (TOML) and a
CSV of flight data in engineering units (deg, kt, ft, g, deg/s; a 10 Hz GPS height among the
40 Hz channels, declared ``own_rate``), two maneuvers at Mach 0.5 flown by the testbed (``synth``;
the shipped campaign ``campaigns/faults_base.toml``, a pitch doublet and a pull-up with rudder
doublets, also the base of tests/campaigns_tests/test_faults.py; its calibration is a success
whose one warning is that these maneuvers turn no heading, ``crosswind_confounded``). The
dataset and the base files are cached in ``--out`` (default ``fpr-out/bad_inputs``).

Each case copies the base and changes one thing (a unit, the time base, the header, the
encoding, a spike, a stuck channel, a typo, a range, a truncated file, ...), then runs it as the
user would: ``fpr calibrate problem.toml --single --out RESULTS --no-plots``
(:func:`campaigns.cli.main` in this process, its output captured). Each case declares what it
expects:

- ``accept``: good data in another guise (jittered time stamps, a byte-order mark, CRLF, a time
  offset, ...): the calibration estimates (biases, scale factors, tables and delays of aircraft,
  configuration or global scope; the IMU biases) must agree with the base case's within 3
  deviations (the larger of the base's Cramér-Rao and coloured-residual deviation), the verdict
  must not be a failure and no finding may call the data faulty;
- ``reject``: the input layer must stop it with exit status 2 and a message naming the file,
  the channel or column (where one applies), the time or row (where one applies) and a fix (an
  imperative such as set, use, give, remove, trim, or a close match: "did you mean ...?");
- ``flag``: faulty data the estimator (not the reader) must catch: the verdict must be FAILURE or
  SUCCESS WITH WARNINGS, its first finding must name the channel, and no data-fault finding may
  name a channel that was not touched (the Mach-bin workflow's "bin failed", said first, quotes
  its estimation's failures: it must name the channel, and the fault's own finding come next).

A case may allow more than one (``reject|flag``: caught either way). The outcome class printed
per case is ``clear error`` (a rejection that passes the checks above), ``correct result`` (a
result judged correct above) or ``anything else`` (a traceback, a silent success, a vague
message, a wrong channel named, wrong advice, or estimates that moved); the reason is given.
A case may also require a specific fix in the message (``own_rate``, ``skip_rows = 3``,
``--single``, ...) or forbid wrong advice (``mrad`` for a spike). The base itself must be a
correct result: verdict SUCCESS or SUCCESS WITH WARNINGS and every compared estimate within 4
deviations of the testbed's truth.

A few cases run on a variant base instead (``Case.base``, :data:`VARIANTS`): ``three``, a flight
whose small sideslip and single Mach bin hide a wrong input best (a sideslip in degrees declared
rad stays a plausible angle): the same campaign with a third maneuver at Mach 0.5 (a 3211) and
the rudder doublets at 0.2 (the sideslip within +-0.7 deg), ``[workflow] max_mach_variation =
0.1`` in its problem file so that the three maneuvers make one Mach bin, run with the Mach-bin
workflow (``fpr calibrate problem.toml``, no ``--single``: its results have no result.json, so a
flag is judged on its findings.csv and printed verdict). A variant base must itself be good data:
a verdict that is no failure, no data-fault finding.

The script exits 1 if any case is "anything else". A full run takes about a minute on 2
cores. ``--out`` must be empty or a folder this script made (it holds a ``.bad_inputs`` marker):
its ``base/`` and ``cases/`` (and the variants' ``base_NAME/``) are replaced on every run.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import platform
import re
import shutil
import sys
import time
import traceback
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from aircraft_models.schema import unknown
from campaigns.benchmarks.user_files import DEG, G0, KT, USER_COLUMNS, CsvLayout, write_user_files
from campaigns.benchmarks.user_files import column_line as user_column_line

# ----------------------------------------------------------------------------------------------
# the base input

#: The good flights: the shipped campaign campaigns/faults_base.toml (the base of
#: tests/campaigns_tests/test_faults.py too), PV1-NP at Mach 0.5, a pitch doublet and a pull-up with rudder
#: doublets, typical sensor
#: errors, steady wind, calm air, the linear local-flow truth the model set represents exactly.
CAMPAIGN = "faults_base"
DOUBLET, RUDDER = "m0000", "m0001"
DATA = "flight421.csv"
#: Marks a working folder as this script's: only such a folder has its base/ and cases/ replaced.
MARKER = ".bad_inputs"
PROBLEM = "problem.toml"
#: The third maneuver of the ``three`` variant base (:data:`VARIANTS`).
THIRD = "m0002"
#: Recorder time of the first sample of each maneuver in the CSV (not 0: a real recorder's clock).
T_FIRST_S = {DOUBLET: 1520.0, RUDDER: 1700.0, THIRD: 1880.0}

#: The user's columns: canonical name -> (CSV column, dataset column, factor from SI to the written
#: unit, unit, extra spec)
COLUMNS = USER_COLUMNS
CHANNELS = ["phi", "theta", "psi", "tas", "h", "h_dgps", "alpha_zl", "alpha_zr", "alpha_zsp", "beta_zsp"]
FLOAT_FORMAT = "%.6f"

#: Finding codes that name a fault in the data itself (estimator/diagnostics.py).
DATA_FAULTS = {"stuck_channel", "dead_channel", "dead_input", "accel_sign", "unit_error"}
#: Parameter kinds compared between a case and the base: the calibration the user takes home
#: (biases, scale factors, tables, delays, except per-maneuver nuisance offsets such as a GPS
#: height datum) and the IMU biases.
COMPARED_KINDS = ("imu_bias", "time_delay", "bias", "scale", "table")


def compared(p: dict) -> bool:
    """Is parameter ``p`` (a result.json row) one of the compared estimates?"""
    return bool(p["estimated"]) and p["kind"] in COMPARED_KINDS and (
        p["kind"] == "imu_bias" or p["scope"] != "maneuver")


@dataclass(frozen=True)
class Variant:
    """A base other than the corpus's own: the base campaign changed, and how its cases run.

    Attributes
    ----------
    what : one line for the table.
    rudder_norm : the rudder doublets' amplitude (the base's 0.4: sideslip within +-1.3 deg).
    third : a third maneuver kind flown at the same Mach and altitude, or "".
    tail : appended to the problem file.
    single : run with ``--single`` (else the Mach-bin workflow).
    """

    what: str
    rudder_norm: float = 0.4
    third: str = ""
    tail: str = ""
    single: bool = True


#: The bases: ``base`` the corpus's own; ``three`` the user's report of four bad inputs not named
#: (a 3-maneuver CSV, one Mach bin, small sideslip): module docstring.
VARIANTS = {
    "base": Variant("faults_base: pitch doublet + rudder doublets, --single"),
    "three": Variant("faults_base + a 3211 at Mach 0.5, rudder 0.2 (sideslip within 0.7 deg), one Mach bin, "
                     "Mach-bin workflow", rudder_norm=0.2, third="3211",
                     tail="\n[workflow]\nmax_mach_variation = 0.1  # the rudder doublets vary by 0.09: the "
                          "three maneuvers make one bin\n", single=False),
}


def _dataset_dir(root: Path, variant: str) -> Path:
    v = VARIANTS[variant]
    return root / "dataset" if variant == "base" else root / f"dataset_{variant}_r{v.rudder_norm:g}_{v.third}"


def fly_base(root: Path, variant: str = "base") -> Path:
    """The synthetic dataset of a base (flown once, cached in ``root/dataset``, a variant's in
    ``root/dataset_NAME_...``, named after what it changes)."""
    import tomllib

    from synth.campaign import fly_campaign, load_campaign, parse_campaign, resolve_campaign_path

    ds = _dataset_dir(root, variant)
    if not (ds / "manifest.json").is_file():
        if ds.exists():
            shutil.rmtree(ds)  # an incomplete earlier attempt, in our own cache folder
        if variant == "base":
            camp = load_campaign(CAMPAIGN)
        else:
            v = VARIANTS[variant]
            raw = tomllib.loads(resolve_campaign_path(CAMPAIGN).read_text(encoding="utf-8"))
            flights = [dict(f) for f in raw["flights"]]
            flights[1]["maneuver"] = {**flights[1].get("maneuver", {}), "rudder_norm": v.rudder_norm}
            if v.third:
                flights.append({**flights[0], "maneuvers": [v.third]})
            camp = parse_campaign({**raw, "name": f"{raw['name']}_{variant}", "flights": flights},
                                  source=f"{CAMPAIGN} ({variant} variant of bad_inputs.py)")
        res = fly_campaign(camp, ds, workers=1)
        if not res.ok:
            raise SystemExit(f"flying the {variant} dataset failed: {res.failures}")
    return ds


def write_base(ds_dir: Path, dest: Path, variant: str = "base") -> None:
    """The user's files: one CSV of every maneuver in engineering units and its problem file."""
    write_user_files(ds_dir, dest, COLUMNS, CHANNELS, "PV1 vane calibration, flight 421",
                     tail=VARIANTS[variant].tail,
                     layout=CsvLayout(name=DATA, float_format=FLOAT_FORMAT, t_first_s=T_FIRST_S,
                                      time_format=".3f", configuration="PV1-NP"))


# ----------------------------------------------------------------------------------------------
# editing a copy


def read(d: Path, name: str = DATA) -> pd.DataFrame:
    return pd.read_csv(d / name)


def write(d: Path, df: pd.DataFrame, name: str = DATA, **kw) -> None:
    df.to_csv(d / name, index=False, float_format=FLOAT_FORMAT, **kw)


def edit_text(path: Path, old: str, new: str, count: int = 1) -> None:
    """Replace ``old`` by ``new`` in a text file; the corpus is wrong if ``old`` is not there."""
    text = path.read_text()
    if old not in text:
        raise AssertionError(f"corpus bug: {old!r} not in {path.name}")
    path.write_text(text.replace(old, new, count))


def edit_problem(d: Path, old: str, new: str) -> None:
    edit_text(d / PROBLEM, old, new)


def column_line(name: str) -> str:
    return user_column_line(name, COLUMNS[name])


def set_unit(d: Path, name: str, unit: str) -> None:
    c, _, _, u, x = COLUMNS[name]
    edit_problem(d, column_line(name), f'{name} = {{ column = "{c}", unit = "{unit}"{x} }}')


def map_ranges(d: Path, f: Callable[[float], float]) -> None:
    """Apply ``f`` to every t_start_s / t_end_s of the problem file."""
    path = d / PROBLEM
    text = path.read_text()
    new = re.sub(r"(t_(?:start|end)_s = )([-0-9.e+]+)",
                 lambda m: f"{m.group(1)}{f(float(m.group(2))):.6f}", text)
    if new == text:
        raise AssertionError("corpus bug: no time ranges in the problem file")
    path.write_text(new)


def rows_of(df: pd.DataFrame, mid: str) -> np.ndarray:
    """Row indices of a maneuver in the base CSV."""
    t = df["Time"].to_numpy()
    t0 = T_FIRST_S[mid]
    return np.flatnonzero((t >= t0 - 1e-9) & (t < t0 + 60.0))


def row_at(df: pd.DataFrame, mid: str, seconds_in: float) -> int:
    r = rows_of(df, mid)
    return int(r[np.searchsorted(df["Time"].to_numpy()[r], T_FIRST_S[mid] + seconds_in)])


# ----------------------------------------------------------------------------------------------
# the cases


@dataclass
class Case:
    """One bad input and what must come of it.

    Attributes
    ----------
    name, category : shown in the table.
    expect : allowed outcomes, ``accept``, ``reject`` or ``flag`` joined by ``|``.
    edit : ``edit(case_dir)`` changes the copy of the base.
    file : the file a rejection must name (default the data file), or a tuple of files one of
        which it must name.
    names : a rejection must name one of these (channel or column); a flag's first finding must
        name one of them; empty: no channel applies.
    when : a rejection must say where: ``"time"`` (``t =`` or ``row``), ``"line"`` (a numbered
        line of the problem file), ``"row"`` (``t =``, a row or a line of the data file) or ``""``
        (nothing to locate).
    fix : a regular expression the rejection must also match (a specific fix, e.g. ``own_rate``).
    forbid : a regular expression no message may match (wrong advice).
    says : a regular expression the output of an accepted case must match (what was adjusted is
        reported, e.g. the nominal rate of jittered time stamps).
    same_samples : an accepted case must have the base's maneuvers and number of samples (no
        row lost or added).
    argv : extra command-line arguments; ``single=False`` runs the Mach-bin workflow instead.
    judge : a custom judge ``judge(run) -> (class, reason) or None`` tried first.
    base : the base the case copies (:data:`VARIANTS`); a variant's cases run as the variant says
        (``single``). A flag's ``fix`` must match its first finding's message or advice.
    """

    name: str
    category: str
    expect: str
    edit: Callable[[Path], None]
    doc: str = ""
    file: str | tuple[str, ...] = DATA
    names: tuple[str, ...] = ()
    when: str = "time"
    fix: str = ""
    forbid: str = ""
    says: str = ""
    same_samples: bool = True
    single: bool = True
    judge: Callable | None = None
    problem: str = PROBLEM
    base: str = "base"


CASES: list[Case] = []


def case(category: str, expect: str, **kw):
    """Register ``fn(d)`` as a case named after the function."""
    def deco(fn):
        CASES.append(Case(name=fn.__name__, category=category, expect=expect, edit=fn,
                          doc=(fn.__doc__ or "").strip(), **kw))
        return fn
    return deco


# --- units -------------------------------------------------------------------------------------

@case("units", "reject|flag", names=("alpha_zl", "AOA_L"), fix=r"\bdeg\b")
def aoa_deg_declared_rad(d):
    """Left vane AOA written in degrees, declared rad."""
    set_unit(d, "alpha_zl", "rad")


@case("units", "reject|flag", names=("alpha_zsp", "AOA_SP"))
def aoa_rad_declared_deg(d):
    """Side-probe AOA written in radians, declared deg (a few hundredths of a degree)."""
    df = read(d)
    df["AOA_SP"] = df["AOA_SP"] / DEG
    write(d, df)


#: What a flagged sideslip in degrees declared as radians must say: the factor and the unit to declare.
BETA_UNIT_FIX = r'57\.29.*unit = "deg"'


@case("units", "reject|flag", names=("beta_zsp", "AOSS_SP"), fix=BETA_UNIT_FIX)
def beta_deg_declared_rad(d):
    """Side-probe sideslip (within +-1.3 deg) written in degrees, declared rad."""
    set_unit(d, "beta_zsp", "rad")


@case("units", "reject|flag", names=("h", "HP"))
def altitude_ft_declared_m(d):
    """Pressure altitude written in feet (19 700), declared m."""
    set_unit(d, "h", "m")


@case("units", "reject|flag", names=("tas", "TAS"), fix=r"\bkt\b|knot")
def tas_kt_declared_mps(d):
    """True airspeed written in knots, declared m/s."""
    set_unit(d, "tas", "m/s")


@case("units", "reject|flag", names=("tas", "TAS"), fix=r"m/s")
def tas_mps_declared_kt(d):
    """True airspeed written in m/s, declared kt."""
    df = read(d)
    df["TAS"] = df["TAS"] / KT
    write(d, df)


@case("units", "reject", names=("ax", "ay", "az", "AX", "AY", "AZ"), fix=r"\bg\b")
def accel_g_declared_mps2(d):
    """Accelerometers written in g, declared m/s^2 (all three)."""
    for c in ("ax", "ay", "az"):
        set_unit(d, c, "m/s^2")


@case("units", "reject", names=("ax", "ay", "az", "AX", "AY", "AZ"), fix=r"m/s\^2|m/s2")
def accel_mps2_declared_g(d):
    """Accelerometers written in m/s^2, declared g."""
    df = read(d)
    for c in ("AX", "AY", "AZ"):
        df[c] = df[c] * G0
    write(d, df)


@case("units", "reject|flag", names=("p", "q", "r", "P", "Q", "R"), fix=r"deg/s")
def rates_deg_declared_rad(d):
    """Body rates written in deg/s, declared rad/s."""
    for c in ("p", "q", "r"):
        set_unit(d, c, "rad/s")


@case("units", "reject|flag", names=("psi", "PSI"))
def heading_deg_declared_mrad(d):
    """Heading written in degrees, declared mrad."""
    set_unit(d, "psi", "mrad")


@case("units", "reject|flag", names=("theta", "THETA"), fix=r"\bdeg\b")
def pitch_deg_declared_rad(d):
    """Pitch attitude written in degrees, declared rad (a few degrees: below 1.6 "rad")."""
    set_unit(d, "theta", "rad")


@case("units", "reject", file=(PROBLEM, DATA), names=("alpha_zl",), when="")
def unknown_unit_string(d):
    """unit = "degrees" (not a unit the tool knows)."""
    set_unit(d, "alpha_zl", "degrees")


@case("units", "reject", file=(PROBLEM, DATA), names=("theta",), when="")
def unit_of_wrong_dimension(d):
    """Pitch attitude declared in m/s."""
    set_unit(d, "theta", "m/s")


# --- time base ---------------------------------------------------------------------------------

@case("time base", "reject", names=("Time",), fix=r"\bms\b")
def time_ms_declared_s(d):
    """Time written in milliseconds (ranges in the problem file in ms too), declared s."""
    df = read(d)
    df["Time"] = df["Time"] * 1000.0
    write(d, df)
    map_ranges(d, lambda v: v * 1000.0)


@case("time base", "reject", names=("Time",), fix=r"\bs\b|second")
def time_s_declared_ms(d):
    """Time in seconds declared ms (ranges given in seconds)."""
    edit_problem(d, 't = { column = "Time", unit = "s" }', 't = { column = "Time", unit = "ms" }')


@case("time base", "reject", names=("Time",))
def time_not_monotonic(d):
    """Two rows swapped inside the pitch doublet."""
    df = read(d)
    i = row_at(df, DOUBLET, 10.0)
    df.iloc[[i, i + 1]] = df.iloc[[i + 1, i]].to_numpy()
    write(d, df)


@case("time base", "reject", names=("Time",))
def time_duplicate_stamps(d):
    """One row written twice (the recorder's buffer repeated it)."""
    df = read(d)
    i = row_at(df, DOUBLET, 10.0)
    write(d, pd.concat([df.iloc[: i + 1], df.iloc[i:]]))


@case("time base", "reject", names=("Time",))
def time_recorder_restart(d):
    """The recorder's clock restarts at 0 between the two maneuvers (ranges of the second in the
    new time base)."""
    df = read(d)
    r = rows_of(df, RUDDER)
    df.loc[r, "Time"] = df.loc[r, "Time"] - T_FIRST_S[RUDDER]
    write(d, df)
    edit_problem(d, f"t_start_s = {T_FIRST_S[RUDDER]:.3f}", "t_start_s = 0.000")
    text = (d / PROBLEM).read_text()
    end = re.findall(r"t_end_s = ([0-9.]+)", text)[-1]
    edit_problem(d, f"t_end_s = {end}", f"t_end_s = {float(end) - T_FIRST_S[RUDDER]:.3f}")


@case("time base", "reject")
def time_gap(d):
    """2 s of rows lost inside the pitch doublet."""
    df = read(d)
    i = row_at(df, DOUBLET, 10.0)
    write(d, df.drop(index=df.index[i: i + 80]))


def _jittered(df: pd.DataFrame, rate_hz: float, seed: int, jitter: float = 0.01,
              decimals: int = 3) -> pd.DataFrame:
    """The data on a recorder's clock at ``rate_hz``: the time stamp of each sample jitters by
    ``jitter`` (~1 %) of the step and is written with ``decimals`` decimals (milliseconds), the
    values interpolated onto the jittered times."""
    rng = np.random.default_rng(seed)
    parts = []
    for mid in (DOUBLET, RUDDER):
        m = df.iloc[rows_of(df, mid)]
        t = m["Time"].to_numpy()
        n = int(np.floor((t[-1] - t[0]) * rate_hz)) + 1
        tj = t[0] + np.arange(n) / rate_hz + rng.normal(0.0, jitter / rate_hz, n)
        # the first and last stamps on the nominal grid: the problem's ranges end there
        tj = np.clip(np.round(tj, decimals), t[0], t[-1])
        tj[0], tj[-1] = t[0], round(t[0] + (n - 1) / rate_hz, decimals)
        out = {"Time": tj}
        for c in m.columns[1:]:
            v = m[c].to_numpy()
            ok = np.isfinite(v)
            if c == "GPS_ALT":  # own rate: 10 Hz, in the recorder row nearest each GPS sample,
                col = np.full(n, np.nan)  # its value interpolated to that row's time
                rows = np.unique(np.abs(tj[None, :] - t[ok][:, None]).argmin(axis=1))
                col[rows] = np.interp(tj[rows], t[ok], v[ok])
                out[c] = col
            else:
                out[c] = np.interp(tj, t[ok], v[ok])
        parts.append(pd.DataFrame(out))
    return pd.concat(parts)


def _write_jittered(d: Path, rate_hz: float, seed: int, jitter: float = 0.01, decimals: int = 3) -> None:
    df = _jittered(read(d), rate_hz, seed, jitter, decimals)
    write(d, df)
    _ends_at_last_stamps(d, df)


def _ends_at_last_stamps(d: Path, df: pd.DataFrame) -> None:
    """Each maneuver's t_end_s at its last time stamp in ``df``."""
    t = df["Time"].to_numpy()
    ends = iter([t[t < T_FIRST_S[RUDDER]][-1], t[-1]])
    text = re.sub(r"t_end_s = [0-9.]+", lambda m: f"t_end_s = {next(ends):.3f}", (d / PROBLEM).read_text())
    (d / PROBLEM).write_text(text)


@case("time base", "accept", says=r"nominal 40 Hz")
def time_jitter_40hz(d):
    """Time stamps of a 40 Hz recorder: ~1 % jitter, written to the millisecond."""
    _write_jittered(d, 40.0, seed=1)


@case("time base", "accept", says=r"nominal 50 Hz", same_samples=False)
def time_jitter_50hz(d):
    """The same flight recorded at 50 Hz with ~1 % jitter, written to the millisecond (the
    ranges end at the last 50 Hz sample)."""
    _write_jittered(d, 50.0, seed=2)


@case("time base", "accept", says=r"rounded to 0\.01 s.*nominal 40 Hz grid")
def time_rounded_2_decimals_40hz(d):
    """The 40 Hz time written to 0.01 s (1520.00, 1520.02, 1520.05, ...): stamps up to 5 ms (20 %
    of a step) off the grid, within half the rounding; the grid is taken."""
    df = read(d)
    df["Time"] = np.round(df["Time"].to_numpy(), 2)
    write(d, df)
    _ends_at_last_stamps(d, df)


# 64 Hz written to 0.01 s: steps of 15.6 ms, stamps up to 5 ms (32 % of a step) off the 64 Hz grid.
# Accepted on the grid: every stamp is within half the rounding of it, so the stamps hold no
# evidence against a uniform 64 Hz recorder and the grid is the best estimate of the sample times
# there is (exact if the recorder was uniform); refusing would leave the user only resample_hz,
# which interpolates from stamps up to 5 ms off (worse for the delays), or a re-export. The
# warning says that jitter under 5 ms cannot be seen in such stamps and how to check.
@case("time base", "accept", says=r"rounded to 0\.01 s.*nominal 64 Hz grid", same_samples=False)
def time_rounded_2_decimals_64hz(d):
    """The same flight recorded at 64 Hz, time written to 0.01 s (steps of 10 and 20 ms)."""
    _write_jittered(d, 64.0, seed=3, jitter=0.0, decimals=2)


@case("time base", "reject", names=("Time",), fix=r"more decimals")
def time_rounded_2_decimals_jittered(d):
    """A 40 Hz recorder with 1.5 ms (6 %) of clock jitter, time written to 0.01 s: the stamps
    stray beyond the rounding, and interpolating from stamps up to 5 ms off is no fix."""
    _write_jittered(d, 40.0, seed=4, jitter=0.06, decimals=2)


@case("time base", "reject", names=("Time",), fix=r"more decimals")
def time_rounded_1_decimal_40hz(d):
    """The 40 Hz time written to 0.1 s: about four samples share each stamp."""
    df = read(d)
    df["Time"] = np.round(df["Time"].to_numpy(), 1)
    write(d, df)


@case("time base", "reject", names=("h_dgps", "GPS_ALT"), fix=r"own_rate")
def slow_channel_undeclared(d):
    """The 10 Hz GPS height without own_rate = true."""
    edit_problem(d, ', own_rate = true', '')


@case("time base", "accept")
def time_offset_gps_week(d):
    """Time stamps in GPS seconds of the week (345 600 s and more), ranges likewise."""
    df = read(d)
    df["Time"] = df["Time"] + 345600.0
    write(d, df)
    map_ranges(d, lambda v: v + 345600.0)


@case("time base", "accept")
def time_starts_at_zero(d):
    """The file's time starts at 0 (ranges likewise)."""
    df = read(d)
    df["Time"] = df["Time"] - T_FIRST_S[DOUBLET]
    write(d, df)
    map_ranges(d, lambda v: v - T_FIRST_S[DOUBLET])


@case("time base", "reject", names=("Time",))
def time_all_nan(d):
    """The time column is empty (the export left it out)."""
    df = read(d)
    df["Time"] = np.nan
    write(d, df)


@case("time base", "accept")
def nan_rows_between_maneuvers(d):
    """Rows of empty cells (but a time stamp) between the two maneuvers: outside every range."""
    df = read(d)
    t_end = df["Time"].to_numpy()[rows_of(df, DOUBLET)[-1]]
    gap = pd.DataFrame({"Time": t_end + 10.0 + np.arange(40) * 0.025})
    write(d, pd.concat([df.iloc[rows_of(df, DOUBLET)], gap, df.iloc[rows_of(df, RUDDER)]]))


# --- headers -----------------------------------------------------------------------------------

@case("headers", "reject", when="", fix=r"header = false")
def headerless_file_columns_by_name(d):
    """The file has no header line; the problem maps the columns by name, header = true (default)."""
    write(d, read(d), header=False)


@case("headers", "reject|accept", when="", fix=r"header = false", says=r"first data row")
def headerless_file_header_true(d):
    """The file has no header line; the problem maps by index but keeps header = true (default):
    the first line must be data, not lost (accepted: the estimates must be the base's, and the
    output must say the first line was read as data)."""
    df = read(d)
    names = ["Time", *[c for c, *_ in COLUMNS.values()]]
    write(d, df, header=False)
    text = (d / PROBLEM).read_text()
    for i, c in enumerate(names):
        text = text.replace(f'column = "{c}"', f"column = {i}")
    (d / PROBLEM).write_text(text)


@case("headers", "reject|accept", names=("Time",), when="")
def header_line_header_false(d):
    """The file has a header line; the problem says header = false and maps by index."""
    names = ["Time", *[c for c, *_ in COLUMNS.values()]]
    text = (d / PROBLEM).read_text()
    for i, c in enumerate(names):
        text = text.replace(f'column = "{c}"', f"column = {i}")
    (d / PROBLEM).write_text(text.replace('aircraft = "PV1"\nconfiguration',
                                          'aircraft = "PV1"\nheader = false\nconfiguration'))


@case("headers", "reject", names=("AOA_L",), when="")
def duplicate_column_names(d):
    """Two columns named AOA_L (the second, a raw vane angle in counts, appended at the end)."""
    df = read(d)
    df["AOA_L_RAW"] = (df["AOA_L"] * 100.0).round()
    write(d, df)
    edit_text(d / DATA, "AOA_L_RAW", "AOA_L")


@case("headers", "accept")
def trailing_blank_header_cells(d):
    """Every line ends with two empty cells (a spreadsheet export), header cells blank too."""
    lines = (d / DATA).read_text().splitlines()
    (d / DATA).write_text("\n".join(line + ",," for line in lines) + "\n")


@case("headers", "reject|accept", when="", fix=r"skip_rows = 3")
def title_block_without_skip_rows(d):
    """Three title lines before the header, skip_rows not given."""
    text = (d / DATA).read_text()
    (d / DATA).write_text("Flight 421 PV1\nrecorder DAS-2 export 2024-05-14\n\n" + text)


@case("headers", "reject|accept", when="row")
def units_row_under_header(d):
    """A second header line with the units (s, g, g, ...) under the names."""
    lines = (d / DATA).read_text().splitlines()
    units = ["s", *[u for _, _, _, u, _ in COLUMNS.values()]]
    (d / DATA).write_text("\n".join([lines[0], ",".join(units), *lines[1:]]) + "\n")


@case("headers", "accept")
def blanks_around_header_names(d):
    """Header names padded with blanks (" AX ")."""
    lines = (d / DATA).read_text().splitlines()
    lines[0] = ",".join(f" {c} " for c in lines[0].split(","))
    (d / DATA).write_text("\n".join(lines) + "\n")


@case("headers", "reject", names=("AOA_L", "aoa_l"), when="", forbid=r"did you mean 'AOA_R'")
def header_case_differs(d):
    """The file's header says aoa_l where the problem maps AOA_L (a close match offered must be
    aoa_l, not AOA_R: that is the right vane, mapped to alpha_zr)."""
    edit_text(d / DATA, "AOA_L", "aoa_l")


# --- encodings ---------------------------------------------------------------------------------

@case("encodings", "accept")
def utf8_bom(d):
    """A UTF-8 byte-order mark before the header (Excel's "CSV UTF-8")."""
    (d / DATA).write_bytes(b"\xef\xbb\xbf" + (d / DATA).read_bytes())


@case("encodings", "reject|accept", when="", fix=r"(?i)utf-?8|encoding|latin")
def latin1_degree_sign_in_header(d):
    """Header "AOA_L [°]" written in Latin-1; the problem file (UTF-8) maps that name."""
    text = (d / DATA).read_text().replace("AOA_L,", "AOA_L [°],", 1)
    (d / DATA).write_bytes(text.encode("latin-1"))
    edit_problem(d, 'column = "AOA_L"', 'column = "AOA_L [°]"')


@case("encodings", "reject|accept", when="", fix=r"(?i)utf-?8|utf-?16|encoding")
def utf16_file(d):
    """The whole file in UTF-16 (with its byte-order mark), as some Windows tools save it."""
    (d / DATA).write_bytes((d / DATA).read_text().encode("utf-16"))


@case("encodings", "accept")
def crlf_line_ends(d):
    """Windows line ends."""
    (d / DATA).write_bytes((d / DATA).read_bytes().replace(b"\n", b"\r\n"))


@case("encodings", "reject", when="", fix=r"delimiter = [\"'];")
def semicolon_delimiter_undeclared(d):
    """A European export: ';' between fields and ',' as decimal mark, no delimiter declared."""
    df = read(d)
    df.to_csv(d / DATA, index=False, sep=";", decimal=",", float_format=FLOAT_FORMAT)


@case("encodings", "reject|accept", names=("Time",), fix=r"(?i)decimal")
def decimal_comma_delimiter_declared(d):
    """The same European export with delimiter = ";" declared: the decimal commas remain."""
    df = read(d)
    df.to_csv(d / DATA, index=False, sep=";", decimal=",", float_format=FLOAT_FORMAT)
    edit_problem(d, 'aircraft = "PV1"\nconfiguration', 'aircraft = "PV1"\ndelimiter = ";"\nconfiguration')


# --- spikes, stuck and dead channels, missing values -------------------------------------------

@case("spikes", "reject|flag", names=("alpha_zl", "AOA_L"), forbid=r"mrad")
def spike_1000deg(d):
    """One sample of the left vane 1000 deg off, 12 s into the pitch doublet."""
    df = read(d)
    df.loc[row_at(df, DOUBLET, 12.0), "AOA_L"] += 1000.0
    write(d, df)


@case("spikes", "reject|flag", names=("alpha_zl", "AOA_L"), forbid=r"mrad|set unit")
def spike_95deg(d):
    """One sample of the left vane reads 95 deg (the rest 1 to 10 deg), 10 s into the pitch
    doublet: just beyond a flow angle's 92 deg, a jump smaller than 92 deg (not a unit error)."""
    df = read(d)
    df.loc[row_at(df, DOUBLET, 10.0), "AOA_L"] = 95.0
    write(d, df)


@case("spikes", "reject|flag", names=("alpha_zl", "AOA_L"), forbid=r"mrad|set unit")
def spike_100deg_next_to_15deg(d):
    """One left-vane sample of 100 deg between two of 15 deg, 10 s into the pitch doublet."""
    df = read(d)
    i = row_at(df, DOUBLET, 10.0)
    df.loc[[i - 1, i + 1], "AOA_L"] = 15.0
    df.loc[i, "AOA_L"] = 100.0
    write(d, df)


@case("spikes", "reject|flag", names=("alpha_zl", "AOA_L"), forbid=r"mrad|set unit")
def spike_minus95deg_next_to_15deg(d):
    """One left-vane sample of -95 deg between two of +15 deg (|value| jumps by 80 deg only, the
    signed value by 110 deg), 10 s into the pitch doublet."""
    df = read(d)
    i = row_at(df, DOUBLET, 10.0)
    df.loc[[i - 1, i + 1], "AOA_L"] = 15.0
    df.loc[i, "AOA_L"] = -95.0
    write(d, df)


@case("spikes", "reject|flag", names=("alpha_zl", "AOA_L"))
def spike_30deg(d):
    """One sample of the left vane 30 deg off, 12 s into the pitch doublet."""
    df = read(d)
    df.loc[row_at(df, DOUBLET, 12.0), "AOA_L"] += 30.0
    write(d, df)


@case("spikes", "reject|flag", names=("tas", "TAS"), forbid=r"unit =")
def tas_dropout_to_zero(d):
    """One true-airspeed sample reads 0 (a data-bus dropout) in the rudder doublets."""
    df = read(d)
    df.loc[row_at(df, RUDDER, 8.0), "TAS"] = 0.0
    write(d, df)


@case("stuck", "reject|flag", names=("alpha_zl", "AOA_L"))
def stuck_vane(d):
    """The left vane freezes 15 s into the pitch doublet and stays frozen."""
    df = read(d)
    r = rows_of(df, DOUBLET)
    i = row_at(df, DOUBLET, 15.0)
    df.loc[i: r[-1], "AOA_L"] = df.loc[i, "AOA_L"]
    write(d, df)


@case("stuck", "reject|flag", names=("beta_zsp", "AOSS_SP"))
def dead_sideslip(d):
    """The side probe's sideslip reads exactly 0 through the rudder doublets."""
    df = read(d)
    df.loc[rows_of(df, RUDDER), "AOSS_SP"] = 0.0
    write(d, df)


@case("missing values", "reject", names=("alpha_zr", "AOA_R"))
def nan_run_in_maneuver(d):
    """Twenty empty cells of the right vane inside the pitch doublet."""
    df = read(d)
    i = row_at(df, DOUBLET, 10.0)
    df.loc[i: i + 19, "AOA_R"] = np.nan
    write(d, df)


@case("missing values", "reject", names=("theta", "THETA"))
def text_in_a_cell(d):
    """A cell reads "N/A" in the pitch attitude column."""
    df = read(d)
    df["THETA"] = df["THETA"].map(lambda v: f"{v:.6f}").astype(object)
    df.loc[row_at(df, RUDDER, 5.0), "THETA"] = "N/A"
    write(d, df)


@case("missing values", "reject", names=("gear", "GEAR"))
def gear_as_text(d):
    """The gear column written as UP / DOWN."""
    df = read(d)
    df["GEAR"] = np.where(df["GEAR"] > 0.5, "DOWN", "UP")
    write(d, df)


# --- typos in names and keys -------------------------------------------------------------------

@case("typos", "reject", file=PROBLEM, names=("alpha_lz",), when="", fix=r"alpha_zl")
def canonical_name_typo(d):
    """[columns] alpha_lz (for alpha_zl)."""
    edit_problem(d, column_line("alpha_zl"), column_line("alpha_zl").replace("alpha_zl", "alpha_lz", 1))


@case("typos", "reject", names=("AOA_LL",), when="", fix=r"AOA_L\b")
def column_name_typo(d):
    """column = "AOA_LL" (the file has AOA_L)."""
    edit_problem(d, 'column = "AOA_L"', 'column = "AOA_LL"')


@case("typos", "reject", file=PROBLEM, names=("resample_Hz",), when="")
def unknown_top_level_key(d):
    """resample_Hz = 40.0 (for resample_hz)."""
    edit_problem(d, 'model = "tejas"', 'model = "tejas"\nresample_Hz = 40.0')


@case("typos", "reject", file=PROBLEM, names=("skiprows",), when="", fix=r"skip_rows")
def unknown_file_key(d):
    """skiprows = 0 in the [[files]] entry (for skip_rows)."""
    edit_problem(d, 'aircraft = "PV1"\nconfiguration', 'aircraft = "PV1"\nskiprows = 0\nconfiguration')


@case("typos", "reject", file=PROBLEM, names=("units",), when="", fix=r"\bunit\b")
def unknown_column_key(d):
    """units = "deg" (for unit) in one column's table."""
    edit_problem(d, column_line("alpha_zr"), column_line("alpha_zr").replace("unit =", "units ="))


@case("typos", "reject", file=PROBLEM, names=("alpha_zrr",), when="", fix=r"alpha_zr\b")
def unknown_channel_in_list(d):
    """channels = [..., "alpha_zrr"] (for alpha_zr)."""
    edit_problem(d, '"alpha_zr",', '"alpha_zrr",')


@case("typos", "reject", file=(PROBLEM, DATA), names=("q",), when="")
def required_input_not_mapped(d):
    """The pitch rate q is not in [columns]."""
    edit_problem(d, column_line("q") + "\n", "")


@case("typos", "reject", names=("AOA_R", "alpha_zr"), when="", forbid=r"did you mean 'AOA_L'")
def column_missing_from_file(d):
    """The file lacks the right vane's column the problem maps (a close match offered must not be
    AOA_L: that is the left vane, mapped to alpha_zl)."""
    write(d, read(d).drop(columns=["AOA_R"]))


@case("typos", "reject", file=PROBLEM, names=("vane_left",), when="")
def sensor_position_missing(d):
    """[sensors] lacks vane_left (its channel alpha_zl is fitted)."""
    text = (d / PROBLEM).read_text()
    (d / PROBLEM).write_text(re.sub(r"\nvane_left = \[[^\]]*\]", "", text, count=1))


@case("typos", "reject", file=PROBLEM, names=("m0000",), when="")
def duplicate_maneuver_id(d):
    """Both maneuvers called m0000."""
    edit_problem(d, f'id = "{RUDDER}"', f'id = "{DOUBLET}"')


# --- ranges ------------------------------------------------------------------------------------

@case("ranges", "reject|flag", names=("alpha_zl", "AOA_L"), forbid=r"mrad")
def alpha_200deg(d):
    """The left vane reads 200 deg for 2 s inside the pitch doublet (a failed synchro)."""
    df = read(d)
    i = row_at(df, DOUBLET, 10.0)
    df.loc[i: i + 79, "AOA_L"] = 200.0
    write(d, df)


@case("ranges", "reject", names=("tas", "TAS"))
def negative_tas(d):
    """True airspeed written with a minus sign (whole file)."""
    df = read(d)
    df["TAS"] = -df["TAS"]
    write(d, df)


@case("ranges", "reject|flag", names=("h", "HP"))
def altitude_fill_value(d):
    """Pressure altitude 1e6 for 1 s in the rudder doublets (the recorder's fill value)."""
    df = read(d)
    i = row_at(df, RUDDER, 5.0)
    df.loc[i: i + 39, "HP"] = 1.0e6
    write(d, df)


@case("ranges", "reject", names=("h", "HP"))
def altitude_1e6_m(d):
    """Pressure altitude 1e6 m throughout (declared m)."""
    df = read(d)
    df["HP"] = 1.0e6
    write(d, df)
    set_unit(d, "h", "m")


@case("ranges", "reject", file=PROBLEM, names=("g_mps2",), when="")
def gravity_in_ft_per_s2(d):
    """g_mps2 = 32.174 (gravity in ft/s^2)."""
    edit_problem(d, 'model = "tejas"', 'model = "tejas"\ng_mps2 = 32.174')


@case("ranges", "reject", names=(RUDDER,))
def range_outside_the_file(d):
    """The rudder doublets' t_end_s 60 s beyond the end of the file."""
    text = (d / PROBLEM).read_text()
    end = re.findall(r"t_end_s = ([0-9.]+)", text)[-1]
    edit_problem(d, f"t_end_s = {end}", f"t_end_s = {float(end) + 60.0:.3f}")


@case("ranges", "reject", names=(DOUBLET,))
def maneuver_too_short(d):
    """The pitch doublet's range cut to 3 s."""
    a = T_FIRST_S[DOUBLET]
    text = (d / PROBLEM).read_text()
    end = re.findall(r"t_end_s = ([0-9.]+)", text)[0]
    edit_problem(d, f"t_end_s = {end}", f"t_end_s = {a + 3.0:.3f}")


# --- truncated and missing files ---------------------------------------------------------------

@case("truncated", "reject", names=tuple(c for c, *_ in COLUMNS.values()))
def last_line_cut_mid_number(d):
    """The copy stopped mid-number in the last line (no newline at the end)."""
    text = (d / DATA).read_text()
    last = text.rstrip("\n").rsplit("\n", 1)[1]
    cut = len(text.rstrip("\n")) - len(last) + last.index(",", len(last) // 2) + 3
    (d / DATA).write_text(text[:cut])


@case("truncated", "reject", names=(DOUBLET, RUDDER))
def file_cut_to_three_rows(d):
    """Only the header and the first three rows arrived."""
    lines = (d / DATA).read_text().splitlines()
    (d / DATA).write_text("\n".join(lines[:4]) + "\n")


@case("truncated", "reject", when="", fix=r"(?i)\bempty\b|\b0 bytes")
def empty_file(d):
    """The data file is empty (0 bytes)."""
    (d / DATA).write_bytes(b"")


@case("truncated", "reject", when="")
def header_only(d):
    """The data file holds its header line only."""
    (d / DATA).write_text((d / DATA).read_text().splitlines()[0] + "\n")


@case("truncated", "reject", when="", fix=r"path")
def data_file_missing(d):
    """The data file is not there."""
    (d / DATA).unlink()


@case("truncated", "reject", file=PROBLEM, when="line")
def toml_syntax_error(d):
    """An unterminated string in the problem file."""
    edit_problem(d, 'title = "PV1 vane calibration, flight 421"', 'title = "PV1 vane calibration, flight 421')


@case("truncated", "reject", file="flights", when="", fix=r"(?i)director")
def data_path_is_a_directory(d):
    """path = the folder the data file is in, not the file."""
    (d / "flights").mkdir()
    shutil.move(d / DATA, d / "flights" / DATA)
    edit_problem(d, f'path = "{DATA}"', 'path = "flights"')


@case("truncated", "reject", file="flight421.log", when="", fix=r"format")
def unknown_extension(d):
    """The data file is flight421.log (a CSV with another extension)."""
    shutil.move(d / DATA, d / "flight421.log")
    edit_problem(d, f'path = "{DATA}"', 'path = "flight421.log"')


def _no_mach_judge(run: Run) -> tuple[str, str] | None:
    """Without Mach the workflow must say so and name --single, or run the single estimation."""
    text = run.stdout + run.stderr
    says = re.search(r"(?i)mach", text) and "--single" in text
    if run.status == 2:
        return None  # judged as a rejection (fix: --single)
    if run.status in (0, 3) and says:
        return "correct result", "the single estimation ran; the output says Mach is not mapped"
    return "anything else", f"exit {run.status} without naming Mach and --single"


@case("workflow", "reject|accept", file=PROBLEM, names=("mach", "Mach"), when="", fix=r"--single",
      single=False, judge=_no_mach_judge)
def workflow_without_mach(d):
    """The file has no Mach column (not mapped); `fpr calibrate problem.toml` without --single."""
    edit_problem(d, column_line("mach") + "\n", "")
    write(d, read(d).drop(columns=["MACH"]))


# --- the user's report: four bad inputs not named (a 3-maneuver CSV, both ways) ---------------
# Each on the corpus's base (--single) and on the ``three`` variant (Mach-bin workflow).


def _cg_in_inches(d: Path) -> None:
    """The CG written in inches under the metre key (as a user wrote [13.0, 0.0, 5.1] for
    [0.33, 0.0, 0.13] m)."""
    def inches(m: re.Match) -> str:
        v = [round(float(x) / 0.0254, 1) for x in m.group(1).split(",")]
        return f"r_cg_body_m = [{', '.join(f'{x:.1f}' for x in v)}]"

    path = d / PROBLEM
    text, n = re.subn(r"r_cg_body_m = \[([^\]]*)\]", inches, path.read_text(), count=1)
    if n != 1:
        raise AssertionError("corpus bug: no r_cg_body_m in the problem file")
    path.write_text(text)


def _rates_rad_declared_deg(d: Path) -> None:
    """The body rates written in rad/s, declared deg/s (read 57 x too small)."""
    df = read(d)
    for c in ("P", "Q", "R"):
        df[c] = df[c] / DEG
    write(d, df)


def _spike_25deg(d: Path) -> None:
    """One left-vane sample 25 deg off, 12 s into the pitch doublet: below the import's spike check,
    and alone it makes the vane's Table 2 accuracy miss (3 sigma 1.3 deg against 0.5 deg)."""
    df = read(d)
    df.loc[row_at(df, DOUBLET, 12.0), "AOA_L"] += 25.0
    write(d, df)


#: The CG case's message: the key, the unit it probably is, the key to write it under.
_CG = dict(file=PROBLEM, names=("r_cg_body_m",), when="line", fix=r"inches.*r_cg_body_in = \[")
_RATES = dict(names=("p", "q", "r", "P", "Q", "R"), fix=r'look like rad/s.*unit = "rad/s"')
#: The spike's first finding: the outlier, its time, that it makes Table 2 miss, --robust.
_SPIKE = dict(names=("alpha_zl", "AOA_L"), fix=r"t = 1532\.000 s.*Table 2.*--robust", forbid=r"mrad|set unit")
for _base, _suffix in (("base", ""), ("three", "_3man")):
    CASES += [
        Case(f"cg_inches_under_metre_key{_suffix}", "positions", "reject", _cg_in_inches,
             _cg_in_inches.__doc__.strip(), base=_base, **_CG),
        Case(f"rates_rad_declared_deg{_suffix}", "units", "reject", _rates_rad_declared_deg,
             _rates_rad_declared_deg.__doc__.strip(), base=_base, **_RATES),
        Case(f"spike_25deg_table2{_suffix}", "spikes", "flag", _spike_25deg, _spike_25deg.__doc__.strip(),
             base=_base, **_SPIKE),
    ]
# the sideslip on the base is beta_deg_declared_rad (+-1.3 deg); on the variant it is within +-0.7 deg
CASES.append(Case("beta_small_deg_declared_rad_3man", "units", "flag", beta_deg_declared_rad,
                  "Side-probe sideslip within +-0.7 deg written in degrees, declared rad (3 maneuvers).",
                  names=("beta_zsp", "AOSS_SP"), fix=BETA_UNIT_FIX, base="three"))


# ----------------------------------------------------------------------------------------------
# running and judging


@dataclass
class Run:
    """What the user saw."""

    status: int | None  # None: an exception escaped main()
    stdout: str
    stderr: str
    out: Path
    seconds: float
    result: dict | None = None
    error: str = ""  # the "fpr calibrate: error: ..." message, or the traceback
    notes: list[str] = field(default_factory=list)


def run_cli(problem: Path, out: Path, single: bool = True) -> Run:
    from campaigns.cli import main

    argv = ["calibrate", str(problem), "--out", str(out), "--no-plots"] + (["--single"] if single else [])
    so, se = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    status: int | None
    with contextlib.redirect_stdout(so), contextlib.redirect_stderr(se), warnings.catch_warnings():
        warnings.simplefilter("default")
        try:
            status = main(argv)
        except SystemExit as exc:  # argparse
            status = exc.code if isinstance(exc.code, int) else None
        except BaseException:  # noqa: BLE001 - a traceback is an outcome to report, not to raise
            status = None
            se.write(traceback.format_exc())

    def local(text: str) -> str:
        # the case's folders are named after the case: judged with them in, a message would
        # "name" whatever the case name says
        return text.replace(f"{problem.parent}/", "").replace(str(out), "RESULTS")

    run = Run(status=status, stdout=local(so.getvalue()), stderr=local(se.getvalue()), out=out,
              seconds=time.perf_counter() - t0)
    if status is None:
        run.error = run.stderr.strip().splitlines()[-1] if run.stderr.strip() else "exception"
    else:
        m = re.search(r"fpr calibrate: (?:error: )?(.*)", run.stderr, re.S)
        run.error = m.group(1).strip() if m else ""
    if (out / "result.json").is_file():
        run.result = json.loads((out / "result.json").read_text())
    elif (out / "finding_groups.csv").is_file():
        # the Mach-bin workflow: its printed verdict, and its findings as the console says them, each
        # thing once (finding_groups.csv, in the console's order; a group's headline as the message)
        m = re.search(r"^VERDICT: ([A-Z ]+?) —", run.stdout, re.M)
        rows = pd.read_csv(out / "finding_groups.csv").astype(object)
        rows = rows.where(rows.notna(), None).rename(columns={"headline": "message"})
        run.result = {"verdict": m.group(1).replace(" ", "_") if m else "?",
                      "findings": rows.to_dict(orient="records")}
    return run


def _params(result: dict) -> dict[str, dict]:
    return {p["key"]: p for p in result["parameters"]}


def _deviation(p: dict) -> float:
    s = [v for v in (p.get("std_colored"), p.get("std_crb")) if v is not None and np.isfinite(v)]
    return max(s) if s else float("nan")


def compare_with_base(result: dict, base: dict, n_sigma: float = 3.0) -> tuple[bool, str]:
    """Do the calibration estimates of ``result`` agree with the base case's?"""
    got, ref = _params(result), _params(base)
    worst, worst_key, missing = -1.0, "", []
    for key, p in ref.items():
        if not compared(p):
            continue
        q = got.get(key)
        if q is None or not q["estimated"] or q["value"] is None:
            missing.append(key)
            continue
        z = abs(q["value"] - p["value"]) / _deviation(p)
        if z > worst:
            worst, worst_key = z, key
    if missing:
        return False, f"not estimated: {missing[:4]}"
    return worst <= n_sigma, f"largest change {worst:.2f} deviations ({worst_key})"


def _ranked(result: dict) -> list[dict]:
    """Warnings and failures, most severe first (result.json's order)."""
    return [f for f in result["findings"] if f["severity"] in ("WARNING", "FAILURE")]


def _channels(f: dict) -> set[str]:
    return {c.strip() for c in str(f.get("channel") or "").split(",") if c.strip()}


#: A fix: an imperative, or a close match offered ("did you mean 'resample_hz'?").
FIX_WORDS = (r"\bdid you mean\b|\b(set|use|give|add|remove|declare|trim|pass|check|fix|rename|mark|split|"
             r"save|convert|change|replace|correct|write|drop|sort|fill|widen|map|choose|keep|put|export)\b")
CLASSES = ("clear error", "correct result", "anything else")
WHEN = {"time": r"\bt = |\brows?\b", "line": r"\bline \d+", "row": r"\bt = |\brows?\b|\blines?\b"}


def judge_error(c: Case, run: Run) -> tuple[str, str]:
    msg = run.error
    missing = []
    files = (c.file,) if isinstance(c.file, str) else c.file
    if files and not any(f in msg for f in files):
        missing.append(f"file {' or '.join(files)}")
    if c.names and not any(re.search(rf"(?<![\w.]){re.escape(n)}(?![\w])", msg) for n in c.names):
        missing.append(f"channel/column ({'/'.join(c.names[:3])})")
    if c.when and not re.search(WHEN[c.when], msg):
        missing.append("time/row" if c.when == "time" else "line")
    if not re.search(FIX_WORDS, msg, re.I):
        missing.append("a fix")
    if c.fix and not re.search(c.fix, msg):
        missing.append(f"the fix /{c.fix}/")
    if missing:
        return "anything else", "vague error: does not name " + ", ".join(missing)
    return "clear error", ""


def samples(run: Run) -> tuple[int, int] | None:
    """(maneuvers, samples) as the command printed them."""
    m = re.search(r"^(\d+) maneuvers, (\d+) samples", run.stdout, re.M)
    return (int(m.group(1)), int(m.group(2))) if m else None


def judge(c: Case, run: Run, base: dict | None, base_samples: tuple[int, int] | None = None
          ) -> tuple[str, str]:
    allowed = set(c.expect.split("|"))
    everything = run.stdout + run.stderr
    if run.status is None:
        return "anything else", "traceback: " + run.error
    if "Traceback (most recent call last)" in everything:
        return "anything else", "a traceback was printed"
    if c.forbid and re.search(c.forbid, everything):
        return "anything else", f"wrong advice: matches /{c.forbid}/"
    if c.judge is not None:
        verdict = c.judge(run)
        if verdict is not None:
            return verdict
    if run.status == 2:
        if "reject" not in allowed:
            return "anything else", "refused input that should be accepted or flagged"
        return judge_error(c, run)
    if run.result is None:
        return "anything else", f"exit {run.status} and no result.json"
    res = run.result
    verdict = res["verdict"]
    if "flag" in allowed:
        ranked = _ranked(res)
        if verdict == "SUCCESS" or not ranked:
            return "anything else", f"silent success: verdict {verdict}, no warning"
        first = ranked[0]
        if first["code"] == "bin_failed" and len(ranked) > 1 and any(
                re.search(rf"(?<![\w.]){re.escape(n)}(?![\w])", first["message"]) for n in c.names):
            # the workflow's "bin failed" quotes its estimation's failures, the fault among them by
            # name: the fault's own finding (with its fix) must then be the next one said
            first = ranked[1]
        if not _channels(first) & set(c.names):
            return "anything else", (f"first finding names another channel: {first['code']} "
                                     f"{first.get('channel')}: {first['message'][:80]}")
        if c.fix and not re.search(c.fix, f"{first['message']} {first.get('advice') or ''}"):
            return "anything else", f"its first finding lacks the fix /{c.fix}/: {first['message'][:80]}"
        wrong = [f for f in res["findings"] if f["code"] in DATA_FAULTS and not _channels(f) <= set(c.names)]
        if wrong:
            return "anything else", f"data fault blamed on {wrong[0].get('channel')} ({wrong[0]['code']})"
        return "correct result", f"{verdict}: {first['code']} {first.get('channel')}"
    if "accept" in allowed:
        if base is None:
            return "anything else", "no base result to compare with"
        if verdict == "FAILURE":
            return "anything else", f"verdict FAILURE on good data: {_ranked(res)[0]['message'][:80]}"
        new_faults = [f for f in res["findings"] if f["code"] in DATA_FAULTS]
        if new_faults:
            return "anything else", f"a data fault on good data: {new_faults[0]['message'][:80]}"
        if c.says and not re.search(c.says, everything):
            return "anything else", f"accepted without saying /{c.says}/"
        if c.same_samples and samples(run) != base_samples:
            return "anything else", f"{samples(run)} (maneuvers, samples) where the base has {base_samples}"
        ok, text = compare_with_base(res, base)
        return ("correct result" if ok else "anything else"), f"{verdict}; {text}"
    return "anything else", f"silently accepted: exit {run.status}, verdict {verdict}"


def judge_base(run: Run, ds_dir: Path) -> tuple[str, str]:
    """The base: SUCCESS (or with warnings) and every calibration estimate near the testbed's truth."""
    if run.result is None or run.status not in (0, 3):
        return "anything else", f"exit {run.status}: {run.error[:200]}"
    from campaigns.truth import true_parameters
    from estimator.io import problem_from_dataset

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        problem = problem_from_dataset(ds_dir)
    est = _params(run.result)
    mask = np.array([bool(est.get(p.key, {}).get("estimated", False)) for p in problem.parameters])
    truth = true_parameters(problem, mask).values
    worst, worst_key, n = 0.0, "", 0
    for key, p in est.items():
        if not compared(p) or key not in truth:
            continue
        n += 1
        z = abs(p["value"] - truth[key]) / _deviation(p)
        if z > worst:
            worst, worst_key = z, key
    ok = n > 0 and worst < 4.0
    return ("correct result" if ok else "anything else"), (
        f"{run.result['verdict']}; {n} calibration estimates vs truth, largest error {worst:.2f} "
        f"deviations ({worst_key})")


# ----------------------------------------------------------------------------------------------


def first_line(run: Run) -> str:
    if run.status == 2 or run.status is None:
        text = run.error
    else:
        m = re.search(r"^VERDICT: .*$", run.stdout, re.M)
        text = m.group(0) if m else run.stdout.strip().splitlines()[-1] if run.stdout.strip() else ""
    return text.strip().splitlines()[0] if text.strip() else ""


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("fpr-out/bad_inputs"),
                    help="working folder: the cached dataset and base files, one folder per case")
    ap.add_argument("--only", nargs="+", metavar="NAME", help="run only these cases (the base always runs)")
    ap.add_argument("--write", type=Path, help="also write the table to this file")
    ap.add_argument("--width", type=int, default=100, help="message column width")
    ap.add_argument("--full", action="store_true", help="print each message whole after the table")
    return ap


def _check_cases(only: Sequence[str] | None) -> None:
    """Refuse a corpus with two cases of one name, and an --only naming none of them."""
    names = {c.name for c in CASES}
    if len(names) != len(CASES):
        raise SystemExit("corpus bug: duplicate case names")
    bad = [n for n in only or () if n not in names]
    if bad:
        raise unknown(bad, [c.name for c in CASES], "--only", SystemExit, what="case")


def _working_folder(out: Path) -> Path:
    """The working folder, made and marked as this script's (it replaces its base/ and cases/)."""
    root = out.resolve()
    marker = root / MARKER
    if root.exists() and any(root.iterdir()) and not marker.is_file():
        # the folder's base/ and cases/ are replaced on every run: only in a folder of our own
        raise SystemExit(f"{root} is not empty and was not made by bad_inputs.py (no {MARKER}); "
                         "choose another --out")
    root.mkdir(parents=True, exist_ok=True)
    marker.write_text("working folder of campaigns/benchmarks/bad_inputs.py: base/ and cases/ are "
                      "replaced on every run, dataset/ is kept\n")
    return root


class _Log:
    """The report: printed as it goes, and kept for ``--write``."""

    def __init__(self) -> None:
        self.lines: list[str] = []

    def __call__(self, s: str = "") -> None:
        print(s, flush=True)
        self.lines.append(s)


def _run_variant_bases(root: Path, only: Sequence[str] | None,
                       emit: _Log) -> tuple[dict[str, Path], list[str]]:
    """Write and run the variant bases the selected cases start from: (variant -> its folder, what
    is wrong with those that did not give a correct result)."""
    variant_dirs, wrong = {}, []
    for name in dict.fromkeys(c.base for c in CASES if not only or c.name in only):
        if name == "base":
            continue
        v = VARIANTS[name]
        vdir = root / f"base_{name}"
        if vdir.exists():
            shutil.rmtree(vdir)  # this script's own folder of an earlier run
        write_base(fly_base(root, name), vdir / "input", name)
        variant_dirs[name] = vdir
        vrun = run_cli(vdir / "input" / PROBLEM, vdir / "results", single=v.single)
        vclass, vreason = judge_variant_base(vrun)
        emit(f"base {name} ({v.what}): {vclass}: {vreason} (exit {vrun.status}, {vrun.seconds:.1f} s)")
        if vclass != "correct result":
            wrong.append(f"base {name}: {vclass}")
    return variant_dirs, wrong


def _run_cases(runs: Path, variant_dirs: Mapping[str, Path], args: argparse.Namespace, base_run: Run,
               base: dict | None, emit: _Log) -> list[tuple[Case, Run, str, str]]:
    """Each selected case on a copy of its base, judged; its table row emitted. (case, run,
    outcome, reason) per case."""
    w = args.width
    header = f"{'case':<34}{'category':<15}{'expected':<14}{'outcome':<15}{'exit':>4}  message / verdict"
    emit(header)
    emit("-" * (82 + w))
    rows = []
    for c in CASES:
        if args.only and c.name not in args.only:
            continue
        d = runs / c.name
        shutil.copytree(variant_dirs[c.base] / "input", d / "input")
        c.edit(d / "input")
        run = run_cli(d / "input" / c.problem, d / "results", single=c.single and VARIANTS[c.base].single)
        outcome, reason = judge(c, run, base, samples(base_run))
        msg = first_line(run)
        shown = msg if len(msg) <= w else msg[: w - 3] + "..."
        emit(f"{c.name:<34}{c.category:<15}{c.expect:<14}{outcome:<15}{str(run.status):>4}  {shown}")
        if outcome != "clear error":
            emit(f"{'':<34}{'':<15}{'':<14}{'':<15}{'':>4}  -> {reason}")
        rows.append((c, run, outcome, reason))
    return rows


def _emit_messages(rows: Sequence[tuple[Case, Run, str, str]], full: bool, emit: _Log) -> None:
    """The messages in full: every case's (``--full``) or those of the cases judged anything else."""
    emit()
    emit("messages in full" + ("" if full else " (anything else)") + ":")
    for c, run, o, r in rows:
        if not full and o != "anything else":
            continue
        emit(f"\n[{c.name}] {c.doc}\n  expected {c.expect}; {o}: {r}")
        text = run.error if run.status in (2, None) else re.search(
            r"VERDICT:.*", run.stdout, re.S).group(0) if "VERDICT:" in run.stdout else run.stdout[-1500:]
        emit("  " + "\n  ".join(text.strip().splitlines()[:12]))


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    _check_cases(args.only)
    root = _working_folder(args.out)
    t_start = time.perf_counter()
    ds = fly_base(root)
    base_dir = root / "base"
    if base_dir.exists():
        shutil.rmtree(base_dir)
    write_base(ds, base_dir / "input")
    runs = root / "cases"
    if runs.exists():
        shutil.rmtree(runs)  # this script's own case folders of an earlier run
    runs.mkdir()

    emit = _Log()
    emit("fpr bad-input corpus: fpr calibrate problem.toml --single --out RES --no-plots, per case (on a "
         "variant base, as it says: the _3man cases without --single, the Mach-bin workflow)")
    emit(f"machine: {platform.machine()}, Python {platform.python_version()}; working folder {args.out}")
    base_run = run_cli(base_dir / "input" / PROBLEM, base_dir / "results")
    base_class, base_reason = judge_base(base_run, ds)
    emit(f"base: {base_class}: {base_reason} (exit {base_run.status}, {base_run.seconds:.1f} s)")
    base = base_run.result if base_class == "correct result" else None
    variant_dirs, wrong = _run_variant_bases(root, args.only, emit)
    variant_dirs["base"] = base_dir
    for what in wrong:
        base_class = f"{base_class}; {what}"
    emit()
    rows = _run_cases(runs, variant_dirs, args, base_run, base, emit)
    counts = {k: sum(o == k for _, _, o, _ in rows) for k in CLASSES}
    emit()
    emit(f"{len(rows)} cases, {counts['clear error']} clear errors, {counts['correct result']} correct "
         f"results, {counts['anything else']} anything else (base: {base_class}); "
         f"{time.perf_counter() - t_start:.0f} s")
    bad = [(c, run, r) for c, run, o, r in rows if o == "anything else"]
    if bad or args.full:
        _emit_messages(rows, args.full, emit)
    if args.write:
        args.write.write_text("\n".join(emit.lines) + "\n")
    return 1 if bad or base_class != "correct result" else 0


def judge_variant_base(run: Run) -> tuple[str, str]:
    """A variant base is good data: not refused, a verdict that is no failure, no data-fault finding
    (there is no truth comparison: its maneuvers differ from the base's)."""
    if run.result is None or run.status not in (0, 3):
        return "anything else", f"exit {run.status}: {(run.error or run.stdout[-300:])[:200]}"
    faults = [f for f in run.result["findings"] if f["code"] in DATA_FAULTS]
    if run.result["verdict"] == "FAILURE" or faults:
        return "anything else", f"{run.result['verdict']}; {len(faults)} data-fault finding(s)"
    return "correct result", f"{run.result['verdict']}; no data-fault finding"


if __name__ == "__main__":
    sys.exit(main())
