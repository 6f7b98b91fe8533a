r"""Test maneuvers found in a whole flight: their kind, when the excitation starts and ends, a grade.

The paper's section 3 cuts each maneuver out of the recorded streams of a sortie with "a special
software tool"; this module is that tool. It reads the motion only (IMU, attitude, altitude and
speed; no pilot input, no event marker), as a log holds it, and finds each kind by the input that
makes it:

==========================  ==============================================================
pitch doublet, 3211,        step inputs in load factor: spikes of the pitch acceleration
pull-up/push-over           :math:`\dot q` (a step's onset), taken in runs of alternating
                            sign (each input returns); a doublet's three steps up to 2.5 s
                            apart at about equal widths, a 3211's four or more whose first
                            widths go 3:2:1, a pull-up/push-over's three at 2 s or more
                            apart; runs of one kind less than ``maneuver_gap_s`` apart are
                            one maneuver
roller coaster, pull-ups    a sinusoidal load factor: at least ``sine_min_half_cycles``
with rudder doublets        regular half-cycles of :math:`n_z - 1`; with yaw-rate pulses
                            it is the rudder-doublet kind
wind-up turn                a bank beyond ``turn_bank_deg`` for ``turn_min_s`` while the load
                            factor winds up by ``turn_min_rise_g``
steady-heading sideslip     a lateral specific force held beyond ``sideslip_ay_mps2`` for
                            ``sideslip_min_s`` at a steady heading; cut into pieces of about
                            ``piece_s``
level acceleration /        the speed changing by ``speed_rate`` for ``speed_min_s`` at a
deceleration                steady altitude, wings level
steady turn, straight leg   a bank held (or the wings level and the heading held) for
                            ``leg_min_s``: a small UAV's waypoint course; only with
                            ``legs_and_turns``
==========================  ==============================================================

A maneuver starts where its signal leaves the steady flight before it (the first step, the
first crossing, the roll-in, the sideslip's or the speed's departure) and ends where its last
input ends (the last step, the last crossing, the turn's roll-out, the sideslip's release, 95 %
of the speed change done). Where two candidates overlap, the one found first wins, in this
order: pitch steps, wind-up turns, sideslips, sinusoids, speed changes, turns and legs. The
window written for a calibration adds ``lead_s`` of the steady flight before (the initial
conditions) and ``trail_s`` of the response after (none after a sideslip's release or a turn's
roll-out: what follows is the next leg), never into a neighbour.

Each maneuver is graded ``keep``, ``borderline`` or ``discard`` with its reason: too short, the
speed drifting (a maneuver of one test point), too little excitation, a data dropout (a gap in
the samples, or a channel without values), on the ground (an airspeed, where one is recorded,
below ``min_airspeed_mps``).

The thresholds (:class:`ExtractionOptions`) are the defaults of the testbed's fighter-class
sorties; a small UAV's doublets and turns are faster and smaller: set them in the problem file's
``[extraction]`` table.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace

import numpy as np
import pandas as pd

G0_MPS2 = 9.80665
RAD2DEG = 180.0 / math.pi
#: Kinds this module finds, in the order of precedence where candidates overlap.
KINDS = ("pitch_doublet", "3211", "pullup_pushover", "windup_turn", "shss", "roller_coaster",
         "pullup_rudder_doublets", "level_accel", "level_decel", "steady_turn", "straight_leg")
GRADES = ("keep", "borderline", "discard")


#: Thresholds that may be 0 (a margin, a limit that can be switched off); the others must be > 0.
_ZERO_ALLOWED = frozenset({"lead_s", "trail_s", "release_margin_s", "min_excitation_s", "min_airspeed_mps",
                           "return_gap_s", "rudder_yaw_rate_dps", "sideslip_heading_rate_dps"})


@dataclass(frozen=True)
class ExtractionOptions:
    """Thresholds of the maneuver finder (module docstring); units in the names.

    Defaults suit the testbed's fighter-class sorties; a small UAV needs its own
    (``[extraction]`` in the problem file).
    """

    #: pitch acceleration of a step input's onset, deg/s^2
    step_qdot_dps2: float = 8.0
    #: at most this long between the steps of one input (a pull-up's push), s
    step_gap_s: float = 5.0
    #: at most this long between the inputs of one maneuver (doublets every 10 s, 3211s every 12 s), s
    maneuver_gap_s: float = 15.0
    #: smallest amplitude of a sinusoidal load factor, g
    sine_min_amplitude_g: float = 0.2
    #: fewest half-cycles of a roller coaster
    sine_min_half_cycles: int = 4
    #: range of a sinusoid's half-period, s
    sine_half_period_s: tuple[float, float] = (1.5, 10.0)
    #: a yaw-rate pulse that makes a load-factor sinusoid the rudder-doublet kind, deg/s
    rudder_yaw_rate_dps: float = 1.5
    #: bank of a wind-up turn, deg
    turn_bank_deg: float = 25.0
    #: shortest wind-up turn (bank beyond turn_bank_deg), s
    turn_min_s: float = 8.0
    #: smallest wind-up of the load factor in a turn, g
    turn_min_rise_g: float = 0.25
    #: lateral specific force of a steady sideslip, m/s^2
    sideslip_ay_mps2: float = 0.4
    #: shortest steady sideslip, s
    sideslip_min_s: float = 20.0
    #: heading rate allowed in a steady-heading sideslip, deg/s
    sideslip_heading_rate_dps: float = 1.0
    #: length of the pieces a steady sideslip is cut into, s (the paper's 30-40 s)
    piece_s: float = 35.0
    #: rate of a level speed change: Mach per s, or m/s^2 where no Mach is recorded
    speed_rate_mach_per_s: float = 1.5e-3
    speed_rate_mps2: float = 0.5
    #: shortest level speed change, s
    speed_min_s: float = 8.0
    #: climb rate allowed in a level speed change, m/s
    level_climb_rate_mps: float = 5.0
    #: a speed change starting this soon after one of the other sign ends is the way back to
    #: the test point's speed (a transition), not a maneuver, s
    return_gap_s: float = 10.0
    #: every maneuver but a turn or leg starts from steady flight: this long, s, the load factor
    #: within steady_nz_g of its mean, wings level, the altitude held
    steady_s: float = 3.0
    steady_nz_g: float = 0.05
    #: steady flight kept before each excitation, and response after it, s
    lead_s: float = 2.0
    trail_s: float = 3.0
    #: a steady sideslip's or wind-up turn's window ends this long before its release is seen, s
    release_margin_s: float = 0.5
    #: steady turns and straight legs (a small UAV's waypoint course) are looked for too
    legs_and_turns: bool = False
    #: bank of a steady turn, deg; bank of a straight leg at most, deg; its heading rate at most,
    #: deg/s; the shortest turn or leg, s (longer ones are cut into pieces of about piece_s)
    steady_turn_bank_deg: float = 15.0
    level_bank_deg: float = 5.0
    leg_heading_rate_dps: float = 3.0
    leg_min_s: float = 8.0
    #: grades: shortest excitation kept, s
    min_excitation_s: float = 4.0
    #: grades: the drift of a one-point maneuver's speed, Mach (or airspeed change / mean), from
    #: its first to its last 2 s: borderline above the first, discard above the second (half and
    #: a whole of the testbed campaigns' 0.1 Mach steps)
    drift_limits: tuple[float, float] = (0.05, 0.10)
    #: grades: below this airspeed the aircraft is on the ground, m/s
    min_airspeed_mps: float = 10.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, tuple):
                if not (0 <= v[0] < v[1]):
                    raise ValueError(f"{f.name} = {list(v)}: two numbers, the first 0 or more and "
                                     f"smaller than the second, e.g. {list(f.default)}")
            elif isinstance(v, bool):
                continue
            elif not math.isfinite(v) or v < 0 or (v == 0 and f.name not in _ZERO_ALLOWED):
                least = "0 or more" if f.name in _ZERO_ALLOWED else "more than 0"
                raise ValueError(f"{f.name} = {v!r}: must be a number, {least} (default {f.default})")
        if self.sine_min_half_cycles < 2:
            raise ValueError(f"sine_min_half_cycles = {self.sine_min_half_cycles}: at least 2 (one "
                             "cycle); the default is 4")

    @classmethod
    def from_mapping(cls, table: Mapping, where: str = "[extraction]") -> ExtractionOptions:
        """Options from a table (``[extraction]`` of a problem file); unknown keys refused."""
        names = {f.name: f for f in fields(cls)}
        unknown = sorted(set(table) - set(names))
        if unknown:
            raise ValueError(f"{where}: unknown key(s) {unknown}; the thresholds are {sorted(names)}")
        out = {}
        for k, v in table.items():
            default = getattr(cls, k)
            if isinstance(default, tuple):
                if not (isinstance(v, (list, tuple)) and len(v) == 2
                        and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
                    raise ValueError(f"{where}: {k} = {v!r} must be two numbers, e.g. {list(default)}")
                out[k] = (float(v[0]), float(v[1]))
            elif isinstance(default, bool):
                if not isinstance(v, bool):
                    raise ValueError(f"{where}: {k} = {v!r} must be true or false (no quotes)")
                out[k] = v
            elif isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ValueError(f"{where}: {k} = {v!r} must be a number (default {default})")
            elif isinstance(default, int) and not float(v).is_integer():
                raise ValueError(f"{where}: {k} = {v!r} must be a whole number (default {default})")
            else:
                out[k] = type(default)(v)
        try:
            return cls(**out)
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None


@dataclass(frozen=True)
class FlightSignals:
    """A whole flight's motion on one time base, SI (rad, rad/s, m/s^2, m, m/s; body axes).

    Attributes
    ----------
    t_s : (N,) time, s, increasing.
    az_mps2, q_rps : IMU normal specific force and pitch rate (required).
    ay_mps2, p_rps, r_rps, phi_rad, psi_rad, h_m : optional (None: the kinds needing them are
        not looked for, and the table says so).
    mach, tas_mps : speed (at least one of them for the level speed changes and the grades).
    source : what the flight was read from (for messages).
    own_rate : the fields recorded at their own, slower rate, without a value between their
        samples (interpolated; not a dropout).
    """

    t_s: np.ndarray
    az_mps2: np.ndarray
    q_rps: np.ndarray
    ay_mps2: np.ndarray | None = None
    p_rps: np.ndarray | None = None
    r_rps: np.ndarray | None = None
    phi_rad: np.ndarray | None = None
    psi_rad: np.ndarray | None = None
    h_m: np.ndarray | None = None
    mach: np.ndarray | None = None
    tas_mps: np.ndarray | None = None
    source: str = "flight"
    own_rate: frozenset[str] = frozenset()


@dataclass(frozen=True)
class FoundManeuver:
    """One maneuver found (times in the flight's time base, s).

    ``t_excitation_start_s``/``t_excitation_end_s`` bound the inputs; ``t_start_s``/``t_end_s``
    the window written for a calibration (with ``lead_s``/``trail_s``); ``excitation`` is the
    kind's measure in ``excitation_unit`` (load-factor range, g; sideslip force, m/s^2; speed
    change, Mach or m/s); ``speed`` the mean Mach (or airspeed, m/s) and ``speed_variation`` its
    drift over the window: its mean over the last 2 s minus that over the first 2 s (for a level
    speed change, about the change).
    """

    id: str
    kind: str
    t_excitation_start_s: float
    t_excitation_end_s: float
    t_start_s: float
    t_end_s: float
    speed: float
    speed_variation: float
    speed_unit: str
    excitation: float
    excitation_unit: str
    grade: str
    reason: str
    piece: int = 0


@dataclass(frozen=True)
class ManeuverTable:
    """The maneuvers found in a flight (:func:`find_maneuvers`), in time order."""

    maneuvers: tuple[FoundManeuver, ...]
    source: str
    options: ExtractionOptions
    not_searched: tuple[str, ...] = ()
    notes: tuple[str, ...] = field(default=())

    def to_pandas(self) -> pd.DataFrame:
        """One row per maneuver (a new DataFrame each time), indexed by id."""
        cols = [f.name for f in fields(FoundManeuver)]
        return pd.DataFrame([[getattr(m, c) for c in cols] for m in self.maneuvers],
                            columns=cols).set_index("id")

    def kept(self, borderline: bool = True) -> tuple[FoundManeuver, ...]:
        """The maneuvers graded keep (and borderline, unless ``borderline`` is false)."""
        ok = ("keep", "borderline") if borderline else ("keep",)
        return tuple(m for m in self.maneuvers if m.grade in ok)

    @property
    def message(self) -> str:
        """One paragraph: how many of each grade, what was not looked for and why."""
        counts = {g: sum(m.grade == g for m in self.maneuvers) for g in GRADES}
        text = (f"{self.source}: {len(self.maneuvers)} maneuver(s) found: {counts['keep']} keep, "
                f"{counts['borderline']} borderline, {counts['discard']} discard")
        if self.not_searched:
            text += f"; not looked for: {'; '.join(self.not_searched)}"
        return text + "".join(f"; {n}" for n in self.notes)

    def problem_maneuvers(self, borderline: bool = True, prefix: str = "") -> list[dict]:
        """The ``maneuvers = [...]`` entries of a problem file (the windows, ids ``prefix + id``)."""
        return [{"id": prefix + m.id, "t_start_s": round(m.t_start_s, 3), "t_end_s": round(m.t_end_s, 3)}
                for m in self.kept(borderline)]


# ------------------------------------------------------------------------------ signal helpers
def _smooth(x: np.ndarray, n: int) -> np.ndarray:
    # imported here: reading a problem file imports this module for its options, and scipy's
    # signal processing would add half a second to every fpr calibrate
    from scipy.ndimage import uniform_filter1d

    return uniform_filter1d(x, max(1, n), mode="nearest")


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges ``[lo, hi)`` where ``mask`` is true."""
    d = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True))


def _bridge(mask: np.ndarray, n_gap: int) -> np.ndarray:
    """``mask`` with its false gaps of at most ``n_gap`` samples filled."""
    out = mask.copy()
    runs = _runs(mask)
    for (_, hi), (lo, _) in zip(runs[:-1], runs[1:], strict=True):
        if lo - hi <= n_gap:
            out[hi:lo] = True
    return out


def _departure(x: np.ndarray, k: int, level: float, floor: float, n_before: int) -> int:
    """Where ``x``, steady before, starts towards ``level`` (reached at sample ``k``): walk back
    while ``|x|`` exceeds ``max(5 % of |level|, floor)``, then again, finer (2 %), while ``x``
    differs from its median over the ``n_before`` samples before that point (its own steady
    value there, which need not be zero)."""
    j = k
    while j > 0 and abs(x[j]) > max(0.05 * abs(level), floor):
        j -= 1
    base = float(np.median(x[max(0, j - n_before):j])) if j > 0 else 0.0
    while j > 0 and abs(x[j] - base) > max(0.02 * abs(level - base), 0.5 * floor):
        j -= 1
    return j


@dataclass(frozen=True)
class _Prepared:
    """The flight on a uniform grid with the derived signals every detector uses."""

    t_s: np.ndarray
    dt_s: float
    nz: np.ndarray            # load factor, g (0.2-s smoothed)
    qdot_dps2: np.ndarray     # pitch acceleration, deg/s^2
    signals: dict             # optional channels on the grid (name -> array)
    gaps: list                # (t0, t1, channel or "") of the gaps in the samples, s


def _prepare(f: FlightSignals) -> _Prepared:
    """The flight on a uniform grid at its median step; the gaps: steps over 3 x the median, and
    runs of over 3 samples without a value in a channel not recorded at its own rate (a log's
    dropout), named."""
    t = np.asarray(f.t_s, dtype=float)
    steps = np.diff(t)
    dt = float(np.median(steps))
    gaps = [(float(t[i]), float(t[i + 1]), "") for i in np.flatnonzero(steps > 3.0 * dt)]
    grid = np.arange(t[0], t[-1] + 0.5 * dt, dt)
    names = ("az_mps2", "q_rps", "ay_mps2", "p_rps", "r_rps", "phi_rad", "psi_rad", "h_m", "mach",
             "tas_mps")
    sig = {}
    for name in names:
        v = getattr(f, name)
        if v is None:
            continue
        v = np.asarray(v, dtype=float)
        ok = np.isfinite(v)
        if not ok.any():
            if name in ("az_mps2", "q_rps"):
                raise ValueError(f"{f.source}: {name} has no value at all; the maneuver finder needs it")
            continue
        if name not in f.own_rate:
            gaps += [(float(t[max(a - 1, 0)]), float(t[min(b, len(t) - 1)]), name)
                     for a, b in _runs(~ok) if b - a > 3]
        if name == "psi_rad":
            v = v.copy()
            v[ok] = np.unwrap(v[ok])  # heading crosses 180 deg
        sig[name] = np.interp(grid, t[ok], v[ok])
    n02 = int(round(0.2 / dt))
    nz = -_smooth(sig["az_mps2"], n02) / G0_MPS2
    qdot = np.gradient(_smooth(sig["q_rps"], n02), dt) * RAD2DEG
    return _Prepared(grid, dt, nz, qdot, sig, gaps)


@dataclass(frozen=True)
class _Candidate:
    kind: str
    i0: int                 # excitation start, sample of the grid
    i1: int                 # excitation end
    excitation: float
    unit: str


def _onset(qdot: np.ndarray, k: int) -> int:
    """The onset of the step whose pitch-acceleration peak is at ``k``: walk back while the
    acceleration stays above 15 % of the peak (the peak lags the input by the aircraft's response)."""
    sign, level = np.sign(qdot[k]), 0.15 * abs(qdot[k])
    j = k
    while j > 0 and sign * qdot[j - 1] > level:
        j -= 1
    return j


def _step_list(pp: _Prepared, o: ExtractionOptions) -> list[tuple[int, float, float]]:
    """Step inputs as ``(peak sample, sign, |qdot|)``: peaks of the pitch acceleration, without
    the response's own settling (an opposite peak within 0.45 s smaller than 0.7 x the step, or
    within 0.7 s smaller than 0.4 x it; a 3211's unit steps, 0.6 s apart, are as large)."""
    from scipy.signal import find_peaks  # (as in _smooth)

    h = np.abs(pp.qdot_dps2)
    peaks, _ = find_peaks(h, height=o.step_qdot_dps2, distance=max(1, int(round(0.3 / pp.dt_s))))
    kept: list[tuple[int, float, float]] = []
    for k in peaks:
        s, a = float(np.sign(pp.qdot_dps2[k])), float(h[k])
        if kept:
            k0, s0, a0 = kept[-1]
            close = (k - k0) * pp.dt_s
            if s != s0 and ((close <= 0.45 and a < 0.7 * a0) or (close <= 0.7 and a < 0.4 * a0)):
                continue
            if s == s0 and close <= 0.8:
                if a > a0:
                    kept[-1] = (k0, s0, a)
                continue
        kept.append((int(k), s, a))
    return kept


def _classify_input(times: np.ndarray) -> str | None:
    """The kind of one input from its steps' times (alternating signs): a doublet's three steps
    at about equal widths up to 2.5 s, a 3211's four or five at 3:2:1:1, a pull-up/push-over's
    three at 2 s or more apart."""
    w = np.diff(times)
    if len(times) >= 4:
        r0, r1 = w[0] / w[2], w[1] / w[2]
        if 2.0 <= r0 <= 4.0 and 1.3 <= r1 <= 2.7:
            return "3211"
        return None
    if len(times) == 3:
        if w.max() <= 2.5 and 0.6 <= w[0] / w[1] <= 1.6:
            return "pitch_doublet"
        if w.min() >= 2.0:
            return "pullup_pushover"
    return None


def _pitch_steps(pp: _Prepared, o: ExtractionOptions) -> list[_Candidate]:
    """Doublets, 3211s and pull-up/push-overs: runs of alternating steps, joined per kind."""
    steps = _step_list(pp, o)
    runs: list[list[tuple[int, float, float]]] = []
    for st in steps:
        if runs and st[1] != runs[-1][-1][1] and (st[0] - runs[-1][-1][0]) * pp.dt_s <= o.step_gap_s:
            runs[-1].append(st)
        else:
            runs.append([st])
    inputs = []  # (kind, first onset, last onset)
    for run in runs:
        kind = _classify_input(pp.t_s[[k for k, _, _ in run]])
        if kind is None:
            continue
        last = _onset(pp.qdot_dps2, run[-1][0])
        if kind == "3211" and len(run) == 4:  # the last step below the threshold: one unit width
            last += run[3][0] - run[2][0]
        inputs.append((kind, _onset(pp.qdot_dps2, run[0][0]), last))
    out: list[_Candidate] = []
    for kind, i0, i1 in inputs:
        prev = out[-1] if out else None
        if prev and prev.kind == kind and (i0 - prev.i1) * pp.dt_s <= o.maneuver_gap_s:
            out[-1] = replace(prev, i1=i1)
        else:
            out.append(_Candidate(kind, i0, i1, 0.0, "g"))
    # a test input is flown from a trimmed test point (a turn's entry and exit are not one)
    return [replace(c, excitation=float(np.ptp(pp.nz[c.i0:c.i1 + 1]))) for c in out
            if _steady_before(pp, c.i0, o)]


def _crossings(x: np.ndarray, n_merge: int) -> np.ndarray:
    """Zero crossings of ``x`` (sample after the sign change), those closer than ``n_merge``
    samples merged (noise about zero)."""
    idx = np.flatnonzero(np.signbit(x[1:]) != np.signbit(x[:-1])) + 1
    merged: list[int] = []
    for i in idx:
        if merged and i - merged[-1] < n_merge:
            merged[-1] = (merged[-1] + i) // 2
        else:
            merged.append(int(i))
    return np.asarray(merged, dtype=int)


def _half_cycles(x: np.ndarray, dt: float, o: ExtractionOptions) -> list[tuple[int, int, float, bool]]:
    """The half-cycles of ``x`` between its zero crossings: ``(start, end, amplitude, good)``,
    good when as long as a sinusoid's half-period and as large as ``sine_min_amplitude_g``."""
    cross = _crossings(x, int(round(0.2 / dt)))
    lo_s, hi_s = o.sine_half_period_s
    out = []
    for a, b in zip(cross[:-1], cross[1:], strict=True):
        amp = float(np.max(np.abs(x[a:b])))
        out.append((int(a), int(b), amp, lo_s <= (b - a) * dt <= hi_s and amp >= o.sine_min_amplitude_g))
    return out


def _regular(h: tuple[int, int, float, bool], seq: list) -> bool:
    """Whether half-cycle ``h`` continues the sinusoid ``seq``: its length within 30 % and its
    amplitude within 0.6-1.6 x theirs (medians)."""
    if not h[3]:
        return False
    if not seq:
        return True
    n = float(np.median([b - a for a, b, _, _ in seq]))
    amp = float(np.median([s[2] for s in seq]))
    return abs((h[1] - h[0]) - n) <= 0.3 * n and 0.6 <= h[2] / amp <= 1.6


def _return(x: np.ndarray, h: tuple, amp: float) -> int:
    """Where half-cycle ``h`` returns to half of ``amp`` after its extremum (its
    crossing can come much later: after the last input nothing drives the load factor back
    through its mean), else its end."""
    a, b = h[0], h[1]
    k = a + int(np.argmax(np.abs(x[a:b])))
    back = np.flatnonzero(np.abs(x[k:b]) < 0.5 * amp)
    return k + int(back[0]) if len(back) else b


def _closed(x: np.ndarray, seq: list, h: tuple) -> list:
    """``seq`` with its end: the half-cycle ``h`` that broke it is its last one if it is as large
    and returns to zero in time (a long tail after the last input); each half-cycle as
    ``(start, end, ...)`` with the last end at its return."""
    amp = float(np.median([s[2] for s in seq]))
    n = float(np.median([b - a for a, b, _, _ in seq]))
    if h[1] > h[0] and 0.6 <= h[2] / amp <= 1.6:
        r = _return(x, h, amp)
        if r - h[0] <= 1.3 * n:
            return seq + [(h[0], r, h[2], True)]
    return seq[:-1] + [(seq[-1][0], _return(x, seq[-1], amp), seq[-1][2], True)]


def _sines(pp: _Prepared, o: ExtractionOptions) -> list[_Candidate]:
    """Roller coasters and pull-ups with rudder doublets: regular half-cycles of the load factor
    about its 20-s mean; with yaw-rate pulses (rudder doublets) the second kind, cut after the
    last half-cycle that has one (the transition after it has none)."""
    dt = pp.dt_s
    x = _smooth(pp.nz, int(round(0.5 / dt))) - _smooth(pp.nz, int(round(20.0 / dt)))
    r = pp.signals.get("r_rps")
    r_hp = None if r is None else np.abs(r - _smooth(r, int(round(4.0 / dt)))) * RAD2DEG
    seqs, seq = [], []
    for h in _half_cycles(x, dt, o) + [(0, 0, 0.0, False)]:
        if _regular(h, seq):
            seq.append(h)
            continue
        closed = _closed(x, seq, h) if seq else []
        if len(closed) >= o.sine_min_half_cycles:
            seqs.append(closed)
        seq = [h] if h[3] else []
    out = []
    for seq in seqs:
        if not _steady_before(pp, seq[0][0], o):
            continue  # a transition's oscillation, not a maneuver flown from a test point
        kind = "roller_coaster"
        if r_hp is not None:
            yawed = [k for k, (a, b, _, _) in enumerate(seq) if np.max(r_hp[a:b]) > o.rudder_yaw_rate_dps]
            if len(yawed) >= o.sine_min_half_cycles // 2:
                kind, seq = "pullup_rudder_doublets", seq[:yawed[-1] + 1]
        out.append(_Candidate(kind, seq[0][0], seq[-1][1],
                              2.0 * float(np.median([s[2] for s in seq])), "g"))
    return out


def _roll_in(phi: np.ndarray, k: int, floor_rad: float) -> int:
    """Walk back from sample ``k`` of a steep bank while the bank keeps falling (going back) and
    is beyond ``floor_rad``: where the roll-in starts."""
    j = k
    while j > 0 and abs(phi[j]) > floor_rad and abs(phi[j - 1]) < abs(phi[j]) + 1e-4:
        j -= 1
    return j


def _ramp_start(pp: _Prepared, i_roll: int, k: int) -> int:
    """Where the load factor's wind-up starts: its line over the roll-in (``i_roll`` to ``k``)
    met with its level before, at most 3 s before the roll-in (at low speed the bank of a
    level turn follows the load factor, which starts winding up first)."""
    n3 = int(round(3.0 / pp.dt_s))
    if i_roll < n3 or k - i_roll < 3:
        return i_roll
    level = float(np.median(pp.nz[i_roll - n3:i_roll]))
    slope, offset = np.polyfit(np.arange(i_roll, k), pp.nz[i_roll:k], 1)
    if slope <= 0:
        return i_roll
    return int(np.clip(round((level - offset) / slope), i_roll - n3, i_roll))


def _pull_start(pp: _Prepared, i_roll: int) -> int:
    """Where the pull of a wind-up starts: walking back from the roll-in while the pitch rate
    (0.5-s mean) is above its level 3-6 s before by 0.1 deg/s, at most 3 s (the pull rotates the
    aircraft before the load factor, and the bank that follows it, show it)."""
    dt = pp.dt_s
    n3, n6 = int(round(3.0 / dt)), int(round(6.0 / dt))
    if i_roll < n6:
        return i_roll
    q = _smooth(pp.signals["q_rps"], int(round(0.5 / dt))) * RAD2DEG
    level = float(np.median(q[i_roll - n6:i_roll - n3]))
    j = i_roll
    while j > i_roll - n3 and q[j - 1] > level + 0.1:
        j -= 1
    return j


def _windups(pp: _Prepared, o: ExtractionOptions) -> list[_Candidate]:
    """Wind-up turns: a steep bank held while the load factor winds up to a peak; the turn ends
    where the load factor falls from it (the roll-out; the bank may stay, turning back)."""
    phi = pp.signals.get("phi_rad")
    if phi is None:
        return []
    dt = pp.dt_s
    bank = _bridge(np.abs(phi) * RAD2DEG > o.turn_bank_deg, int(round(1.0 / dt)))
    out = []
    for a, b in _runs(bank):
        if (b - a) * dt < o.turn_min_s:
            continue
        i_roll = _roll_in(_smooth(phi, int(round(0.5 / dt))), a, 1.0 / RAD2DEG)
        i0 = min(_ramp_start(pp, i_roll, a), _pull_start(pp, i_roll))
        k_peak = a + int(np.argmax(pp.nz[a:b]))
        rise = float(pp.nz[k_peak] - pp.nz[i0])
        if rise < o.turn_min_rise_g:
            continue
        after = np.flatnonzero(pp.nz[k_peak:b] < pp.nz[k_peak] - 0.25 * rise)
        i1 = k_peak + int(after[0]) if len(after) else b - 1
        # back to where the fall starts: the last sample still within 5 % of the rise of the peak
        held = np.flatnonzero(pp.nz[k_peak:i1 + 1] >= pp.nz[k_peak] - 0.05 * rise)
        i1 = k_peak + int(held[-1])
        if (i1 - a) * dt < o.turn_min_s or k_peak < i0 + 0.6 * (i1 - i0) or not _steady_before(pp, i0, o):
            continue
        out.append(_Candidate("windup_turn", i0, i1, rise, "g"))
    return out


def _sideslips(pp: _Prepared, o: ExtractionOptions) -> list[_Candidate]:
    """Steady-heading sideslips: a lateral specific force held at a steady heading."""
    ay, psi = pp.signals.get("ay_mps2"), pp.signals.get("psi_rad")
    if ay is None or psi is None:
        return []
    dt = pp.dt_s
    x = _smooth(ay, int(round(1.0 / dt)))
    x = x - float(np.median(x))
    psidot = np.gradient(_smooth(psi, int(round(2.0 / dt))), dt) * RAD2DEG
    held = _bridge(np.abs(x) > o.sideslip_ay_mps2, int(round(2.0 / dt)))
    out = []
    for a, b in _runs(held):
        if (b - a) * dt < o.sideslip_min_s or np.median(np.abs(psidot[a:b])) > o.sideslip_heading_rate_dps:
            continue
        level = float(np.median(x[a:b]))
        i0 = _departure(x * np.sign(level), a, abs(level), 0.05, int(round(3.0 / dt)))
        if not _steady_before(pp, i0, o):
            continue
        inside = np.flatnonzero(np.abs(x[a:b]) >= 0.8 * abs(level))
        out.append(_Candidate("shss", i0, a + int(inside[-1]), abs(level), "m/s^2"))
    return out


def _steady_before(pp: _Prepared, i0: int, o: ExtractionOptions) -> bool:
    """Whether the ``steady_s`` ending 1 s before sample ``i0`` are steady flight: the load
    factor within ``steady_nz_g`` of its mean, wings within ``level_bank_deg`` of level, the
    altitude held (a trimmed test point, which every test input is flown from)."""
    n, off = int(round(o.steady_s / pp.dt_s)), int(round(1.0 / pp.dt_s))
    i0 -= off  # an excitation found late (a pull's load factor first dips, non-minimum phase)
    if i0 < off // 2:
        return False  # under half a second of flight to judge
    sl = slice(max(0, i0 - n), i0)  # at the start of a recording, what there is
    ok = float(np.ptp(pp.nz[sl])) <= 2 * o.steady_nz_g
    if "phi_rad" in pp.signals:
        ok &= float(np.max(np.abs(pp.signals["phi_rad"][sl]))) * RAD2DEG < o.level_bank_deg
    if "h_m" in pp.signals:
        h = _smooth(pp.signals["h_m"][max(0, i0 - 2 * n):i0], int(round(2.0 / pp.dt_s)))[-(i0 - sl.start):]
        ok &= float(np.ptp(h)) < o.level_climb_rate_mps * o.steady_s
    return bool(ok)


def _speed_changes(pp: _Prepared, o: ExtractionOptions) -> list[_Candidate]:
    """Level accelerations and decelerations: the speed changing at a steady altitude (the climb
    rate within ``level_climb_rate_mps`` most of the time), wings level, from steady flight; one
    starting within ``return_gap_s`` of the end of a change of the other sign is the way back to
    a test point's speed and is not one."""
    mach = pp.signals.get("mach")
    v, thr, unit = ((mach, o.speed_rate_mach_per_s, "Mach") if mach is not None
                    else (pp.signals.get("tas_mps"), o.speed_rate_mps2, "m/s"))
    if v is None:
        return []
    dt = pp.dt_s
    n2 = int(round(2.0 / dt))
    rate = np.gradient(_smooth(v, n2), dt)
    level = np.ones(len(v), dtype=bool)
    if "h_m" in pp.signals:
        level &= np.abs(np.gradient(_smooth(pp.signals["h_m"], n2), dt)) < o.level_climb_rate_mps
    if "phi_rad" in pp.signals:
        level &= np.abs(pp.signals["phi_rad"]) * RAD2DEG < 10.0
    found = []  # (candidate, from steady flight)
    for sign, kind in ((1.0, "level_accel"), (-1.0, "level_decel")):
        for a, b in _runs(_bridge(sign * rate > thr, int(round(1.0 / dt)))):
            i0 = _departure(sign * rate, a, float(np.max(sign * rate[a:b])), 0.2 * thr, n2)
            e = b
            while e < len(v) - 1 and sign * rate[e] > 0.1 * thr:
                e += 1
            change = sign * (v[i0:e + 1] - v[i0])
            i1 = i0 + int(np.flatnonzero(change >= 0.95 * float(np.max(change)))[0])
            ok = (b - a) * dt >= o.speed_min_s and level[a:b].mean() > 0.5 and _steady_before(pp, i0, o)
            found.append((_Candidate(kind, i0, i1, float(np.max(change)), unit), e, ok))
    found.sort(key=lambda f: f[0].i0)
    gap = int(round(o.return_gap_s / dt))
    return [c for k, (c, _, ok) in enumerate(found)
            if ok and not any(p.kind != c.kind and p.i0 < c.i0 and c.i0 - e <= gap for p, e, _ in found[:k])]


def _held_runs(mask: np.ndarray, pp: _Prepared, o: ExtractionOptions) -> list[tuple[int, int]]:
    """Runs of ``mask`` (gaps under 1 s bridged) at least ``leg_min_s`` long, cut into pieces of
    about ``piece_s``."""
    dt = pp.dt_s
    out = []
    for a, b in _runs(_bridge(mask, int(round(1.0 / dt)))):
        if (b - a) * dt < o.leg_min_s:
            continue
        k = max(1, int(round((b - a) * dt / o.piece_s)))
        edges = np.linspace(a, b, k + 1).round().astype(int)
        # neighbouring pieces share no sample (one that touched the last would be dropped as
        # overlapping it)
        out += [(int(lo), int(hi) - 1) for lo, hi in zip(edges[:-1], edges[1:], strict=True)]
    return out


def _turns_and_legs(pp: _Prepared, o: ExtractionOptions) -> list[_Candidate]:
    """Steady turns (a bank beyond ``steady_turn_bank_deg`` held within 10 deg of its median)
    and straight legs (wings within ``level_bank_deg`` of level, the heading held within
    ``leg_heading_rate_dps``): a small UAV's waypoint course, found only with
    ``legs_and_turns`` (a test sortie's steady flight between maneuvers is not one)."""
    phi, psi = pp.signals.get("phi_rad"), pp.signals.get("psi_rad")
    if not o.legs_and_turns or phi is None or psi is None:
        return []
    dt = pp.dt_s
    bank = _smooth(phi, int(round(1.0 / dt))) * RAD2DEG
    psidot = np.gradient(_smooth(psi, int(round(2.0 / dt))), dt) * RAD2DEG
    out = []
    for sign in (1.0, -1.0):
        turning = sign * bank > o.steady_turn_bank_deg
        for a, b in _held_runs(turning, pp, o):
            if np.max(np.abs(bank[a:b] - np.median(bank[a:b]))) <= 10.0:
                out.append(_Candidate("steady_turn", a, b, float(np.median(np.abs(bank[a:b]))), "deg"))
    level = (np.abs(bank) < o.level_bank_deg) & (np.abs(psidot) < o.leg_heading_rate_dps)
    out += [_Candidate("straight_leg", a, b, float(np.ptp(pp.nz[a:b])), "g")
            for a, b in _held_runs(level, pp, o)]
    return out


#: The finders in their order of precedence (module docstring).
_FINDERS = (_pitch_steps, _windups, _sideslips, _sines, _speed_changes, _turns_and_legs)


def _resolved(pp: _Prepared, o: ExtractionOptions) -> list[_Candidate]:
    """Every finder's candidates; one overlapping a candidate found earlier is dropped."""
    accepted: list[_Candidate] = []
    for finder in _FINDERS:
        for c in finder(pp, o):
            if not any(c.i0 <= a.i1 and a.i0 <= c.i1 for a in accepted):
                accepted.append(c)
    return sorted(accepted, key=lambda c: c.i0)


def _windows(pp: _Prepared, found: list[_Candidate], o: ExtractionOptions) -> list[tuple[float, float]]:
    """Each excitation with ``lead_s`` before and ``trail_s`` after, never past a neighbour's
    excitation nor overlapping its window (cut half-way between the two), within the flight."""
    t = pp.t_s
    wins = [(max(t[0], t[c.i0] - o.lead_s), min(t[-1], t[c.i1] + o.trail_s)) for c in found]
    for k in range(1, len(wins)):
        (s0, e0), (s1, e1) = wins[k - 1], wins[k]
        if e0 > s1:
            mid = 0.5 * (t[found[k - 1].i1] + t[found[k].i0])
            wins[k - 1], wins[k] = (s0, min(e0, mid)), (max(s1, mid), e1)
    # a steady sideslip ends with its release and a wind-up turn with its roll-out: what follows
    # is the next leg's flight, not their response; their windows end release_margin_s before
    # the release is seen (the load factor or side force lags it by the aircraft's response)
    return [(s, t[c.i1] - o.release_margin_s) if c.kind in ("shss", "windup_turn") else (s, e)
            for (s, e), c in zip(wins, found, strict=True)]


def _little(c: _Candidate, o: ExtractionOptions) -> float:
    """The excitation below which a maneuver is borderline: 1.5 x what finds it (a pitch input's
    load-factor range: 0.2 g; a sinusoid's: twice its smallest amplitude; steady turns and legs
    are steady flight, none)."""
    speed = (o.speed_rate_mach_per_s if c.unit == "Mach" else o.speed_rate_mps2) * o.speed_min_s
    base = {"windup_turn": o.turn_min_rise_g, "shss": o.sideslip_ay_mps2, "level_accel": speed,
            "level_decel": speed, "roller_coaster": 2 * o.sine_min_amplitude_g,
            "pullup_rudder_doublets": 2 * o.sine_min_amplitude_g, "steady_turn": 0.0, "straight_leg": 0.0}
    return 1.5 * base.get(c.kind, 0.2)


def _speed(pp: _Prepared, s: float, e: float) -> tuple[float, float, str]:
    """Mean speed over ``[s, e]`` and its drift: the change from the first to the last 2 s (a
    pull-up's speed swings and comes back; a drifting test point's does not). Mach where
    recorded, else airspeed, m/s."""
    sel = np.flatnonzero((pp.t_s >= s) & (pp.t_s <= e))
    n2 = max(1, min(len(sel) // 4, int(round(2.0 / pp.dt_s))))
    for name, unit in (("mach", "Mach"), ("tas_mps", "m/s")):
        v = pp.signals.get(name)
        if v is not None:
            v = v[sel]
            return float(np.mean(v)), float(np.mean(v[-n2:]) - np.mean(v[:n2])), unit
    return math.nan, math.nan, ""


def _grade(pp: _Prepared, c: _Candidate, s: float, e: float, ex0: float, ex1: float,
           o: ExtractionOptions) -> tuple[str, str]:
    """``(grade, reason)`` of a maneuver with window ``[s, e]`` and excitation ``[ex0, ex1]``."""
    for g0, g1, name in pp.gaps:
        if g0 < e and g1 > s:
            return "discard", f"a data dropout from t = {g0:.2f} to {g1:.2f} s" + (f" ({name})" * bool(name))
    tas = pp.signals.get("tas_mps")
    sel = (pp.t_s >= s) & (pp.t_s <= e)
    if tas is not None and float(np.mean(tas[sel])) < o.min_airspeed_mps:
        return "discard", f"on the ground (airspeed {np.mean(tas[sel]):.1f} m/s < {o.min_airspeed_mps:g})"
    if ex1 - ex0 < o.min_excitation_s:
        return "discard", f"too short ({ex1 - ex0:.1f} s of excitation < {o.min_excitation_s:g} s)"
    mean, spread, unit = _speed(pp, s, e)
    if c.kind not in ("level_accel", "level_decel") and unit:
        drift = abs(spread) if unit == "Mach" else abs(spread) / max(mean, 1e-9)
        what = (f"Mach drifting by {spread:+.3f}" if unit == "Mach"
                else f"airspeed drifting by {100 * spread / max(mean, 1e-9):+.0f} %")
        if drift > o.drift_limits[1]:
            return "discard", f"{what} (> {o.drift_limits[1]:g}): not one test point"
        if drift > o.drift_limits[0]:
            return "borderline", f"{what} (> {o.drift_limits[0]:g})"
    if c.excitation < _little(c, o):
        return "borderline", f"little excitation ({c.excitation:.3g} {c.unit})"
    return "keep", ""


def _rows(pp: _Prepared, found: list[_Candidate], o: ExtractionOptions) -> list[FoundManeuver]:
    """The table's rows: one per maneuver, a steady sideslip one per piece."""
    t = pp.t_s
    rows = []
    for n, (c, (s, e)) in enumerate(zip(found, _windows(pp, found, o), strict=True)):
        ex0, ex1 = float(t[c.i0]), float(t[c.i1])
        pieces = [(s, e)]
        if c.kind == "shss":
            k = max(1, int(round((e - s) / o.piece_s)))
            edges = np.linspace(s, e, k + 1)
            pieces = list(zip(edges[:-1], edges[1:], strict=True))
        for j, (ps, pe) in enumerate(pieces):
            px0, px1 = max(ex0, ps), min(ex1, pe)
            grade, reason = _grade(pp, c, ps, pe, px0, px1, o)
            mean, spread, unit = _speed(pp, ps, pe)
            rows.append(FoundManeuver(
                id=f"x{n:03d}" + (f"s{j}" if len(pieces) > 1 else ""), kind=c.kind,
                t_excitation_start_s=px0, t_excitation_end_s=px1, t_start_s=float(ps),
                t_end_s=float(pe), speed=mean, speed_variation=spread, speed_unit=unit,
                excitation=c.excitation, excitation_unit=c.unit, grade=grade, reason=reason, piece=j))
    return rows


def find_maneuvers(flight: FlightSignals, options: ExtractionOptions | None = None) -> ManeuverTable:
    """The test maneuvers of a whole flight (module docstring).

    Parameters
    ----------
    flight : the flight's motion, SI, body axes (:class:`FlightSignals`).
    options : thresholds (:class:`ExtractionOptions`; default: the testbed's fighter-class ones).

    Returns
    -------
    ManeuverTable
        In time order, each with its kind, excitation and window (s, the flight's time base),
        speed, excitation measure and grade with its reason.

    Raises
    ------
    ValueError
        If the time is not increasing or the flight is shorter than 10 s; names the source.
    """
    o = options or ExtractionOptions()
    t = np.asarray(flight.t_s, dtype=float)
    if len(t) < 3 or not np.all(np.diff(t) > 0):
        raise ValueError(f"{flight.source}: the time must increase from sample to sample")
    if t[-1] - t[0] < 10.0:
        raise ValueError(f"{flight.source}: {t[-1] - t[0]:.1f} s of flight; a maneuver needs more")
    pp = _prepare(flight)
    missing = []
    if "phi_rad" not in pp.signals:
        missing.append("wind-up turns (no bank angle phi)")
    if "ay_mps2" not in pp.signals or "psi_rad" not in pp.signals:
        missing.append("steady-heading sideslips (no lateral acceleration ay or heading psi)")
    if "mach" not in pp.signals and "tas_mps" not in pp.signals:
        missing.append("level speed changes (no Mach or airspeed)")
    return ManeuverTable(tuple(_rows(pp, _resolved(pp, o), o)), flight.source, o, tuple(missing))
