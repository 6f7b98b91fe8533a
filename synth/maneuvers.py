"""Flight-test maneuvers: what to fly (:class:`ManeuverSpec`) and the pilot that flies it.

The pilot is a Python controller per maneuver kind, acting on the f16's fly-by-wire inputs:
``fcs/elevator-cmd-norm`` (a load-factor command; negative pulls), ``fcs/aileron-cmd-norm`` (a
roll-rate command), ``fcs/rudder-cmd-norm`` (positive gives positive sideslip), throttle and
speedbrake. Controllers see the SI state row of :class:`synth.jsbsim_io.SampleReader` and return
the five inputs for the next step. Closed loops hold what a test pilot holds: heading with bank,
altitude with load factor, Mach with throttle (and, in the wind-up turn, with bank-induced dive),
sideslip with rudder. When a loop cannot hold its target, the controller raises
:class:`ManeuverFailure`; :mod:`synth.flight` turns that into a ``FlightError`` naming the run.

Kinds and what they excite (SPEC §7, paper §3):

=========================  ==========================================================
``pitch_doublet``          load-factor doublets every 10 s -> alpha, q
``3211``                   3-2-1-1 load-factor multisteps -> alpha, q over a wide band
``pullup_pushover``        pull to ``nz_max``, push to ``nz_min``, twice -> large alpha range
``roller_coaster``         sinusoidal load factor -> repeated nz / alpha cycles
``windup_turn``            coordinated turn (rudder holds zero sideslip), alpha ramp to
                           ``alpha_max_rad`` or g ramp to ``nz_max`` at constant Mach
``shss``                   steady-heading sideslip at ``beta_rad``, split into segments
``pullup_rudder_doublets`` slow pull-ups / push-overs with rudder doublets -> alpha x beta
``level_accel``            full dry power at constant altitude -> Mach sweep up, centred on
                           ``mach`` (see :attr:`ManeuverSpec.trim_mach`)
``level_decel``            idle power at constant altitude -> Mach sweep down, centred likewise
=========================  ==========================================================
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import asdict, dataclass

import numpy as np

from aircraft_models.schema import check, field_keys
from synth.jsbsim_io import COL, F16_AFT_COMMAND_STOP_NORM

KINDS = (
    "pitch_doublet",
    "3211",
    "pullup_pushover",
    "roller_coaster",
    "windup_turn",
    "shss",
    "pullup_rudder_doublets",
    "level_accel",
    "level_decel",
)
#: Alias used by campaigns and benchmarks.
MANEUVER_KINDS = KINDS

#: Requested Mach range (SPEC §7: subsonic, Mach 0.3-0.9).
MACH_RANGE = (0.3, 0.9)
#: Requested altitude range, m.
ALTITUDE_RANGE_M = (300.0, 12000.0)

#: radians per degree
DEG_TO_RAD = math.pi / 180.0

#: Per-kind defaults of the optional fields; a field not listed for a kind does not apply to it.
DEFAULTS: dict[str, dict[str, float]] = {
    "pitch_doublet": {"duration_s": 30.0, "delta_nz": 1.0, "pulse_s": 1.0},
    "3211": {"duration_s": 30.0, "delta_nz": 0.8, "pulse_s": 0.6},
    "pullup_pushover": {"duration_s": 30.0, "nz_max": 2.5, "nz_min": 0.0, "pulse_s": 3.0},
    "roller_coaster": {"duration_s": 36.0, "delta_nz": 1.0, "period_s": 6.0},
    "windup_turn": {"duration_s": 40.0, "alpha_max_rad": 14.0 * DEG_TO_RAD, "nz_max": 6.0},
    "shss": {"duration_s": 105.0, "beta_rad": 4.5 * DEG_TO_RAD, "segment_s": 35.0},
    "pullup_rudder_doublets": {
        "duration_s": 30.0,
        "delta_nz": 1.0,
        "period_s": 12.0,
        "rudder_norm": 0.8,
        "pulse_s": 1.0,
    },
    "level_accel": {"duration_s": 35.0, "delta_mach": 0.12},
    "level_decel": {"duration_s": 35.0, "delta_mach": 0.12},
}

#: Defaults at Mach 0.3 where they differ: at low dynamic pressure the same load factor needs
#: twice the alpha and bleeds speed below the Mach range. Interpolated linearly in Mach up to
#: :data:`FULL_DEFAULTS_FROM_MACH`, above which :data:`DEFAULTS` apply.
LOW_SPEED_DEFAULTS: dict[str, dict[str, float]] = {
    "pitch_doublet": {"delta_nz": 0.5},
    "3211": {"delta_nz": 0.4},
    "pullup_pushover": {"nz_max": 1.8, "nz_min": 0.4},
    "roller_coaster": {"delta_nz": 0.5},
    "pullup_rudder_doublets": {"delta_nz": 0.5},
}
FULL_DEFAULTS_FROM_MACH = 0.5

#: Defaults from Mach :data:`HIGH_SPEED_DEFAULTS_FROM_MACH` up where they differ: the wind-up turn
#: winds up to 12 deg or 4.5 g, whichever comes first. Measured with the f16's shipped nose-up
#: command stop (-1; the generated model's is -2.5, synth.jsbsim_io, which gives more, so these
#: defaults keep the command within the shipped range, and the turns fly as they did before the
#: stop moved): the FCS ran out of stick at an alpha that falls with Mach, and sooner with a
#: forward CG: PT1, whose nose
#: ballast puts its CG furthest forward in the fleet, reaches at most 12.9 deg (4.2 g) at Mach 0.7,
#: 6000 m, 13.2 deg (4.9 g) at Mach 0.8, 8000 m and 4.8 g (9.4 deg) at Mach 0.9, 8000 m, the other
#: aircraft 0.3-2 deg more (calm air); winding up more slowly does not help (12.8-12.9 deg at Mach
#: 0.7 over 25, 40 or 60 s). So DEFAULTS' 14 deg or 6 g is out of reach there, while 12 deg or
#: 4.5 g is within reach of every configuration of the default fleet at Mach 0.7-0.9 from 3000 m
#: (4.5 g binds; the FCS gives 5.5 g or more) to 10000 m (12 deg binds), except at Mach 0.9 above
#: 8000 m (PT1: 4.25 g at 9000 m). Interpolated linearly in Mach from
#: :data:`FULL_DEFAULTS_UP_TO_MACH`, below which DEFAULTS apply: at the default campaign's Mach 0.4-0.6
#: points PT1 reaches 14 deg with 0.1-0.5 deg to spare.
HIGH_SPEED_DEFAULTS: dict[str, dict[str, float]] = {
    "windup_turn": {"alpha_max_rad": 12.0 * DEG_TO_RAD, "nz_max": 4.5},
}
FULL_DEFAULTS_UP_TO_MACH = 0.6
HIGH_SPEED_DEFAULTS_FROM_MACH = 0.7


def default_value(kind: str, name: str, mach: float) -> float:
    """Default of field ``name`` for ``kind`` at ``mach``.

    :data:`DEFAULTS` between Mach :data:`FULL_DEFAULTS_FROM_MACH` and
    :data:`FULL_DEFAULTS_UP_TO_MACH`, interpolated linearly towards :data:`LOW_SPEED_DEFAULTS` at
    Mach 0.3 and towards :data:`HIGH_SPEED_DEFAULTS` at Mach :data:`HIGH_SPEED_DEFAULTS_FROM_MACH`,
    which hold up to Mach 0.9.
    """
    mid = DEFAULTS[kind][name]
    if mach > FULL_DEFAULTS_UP_TO_MACH:
        hi = HIGH_SPEED_DEFAULTS.get(kind, {}).get(name, mid)
        if mach >= HIGH_SPEED_DEFAULTS_FROM_MACH:
            return float(hi)  # exactly, not through the interpolation's rounding
        f = (mach - FULL_DEFAULTS_UP_TO_MACH) / (HIGH_SPEED_DEFAULTS_FROM_MACH - FULL_DEFAULTS_UP_TO_MACH)
        return float(mid + f * (hi - mid))
    lo = LOW_SPEED_DEFAULTS.get(kind, {}).get(name, mid)
    f = min(1.0, max(0.0, (mach - MACH_RANGE[0]) / (FULL_DEFAULTS_FROM_MACH - MACH_RANGE[0])))
    return float(lo + f * (mid - lo))


_FIELD_HELP = {
    "delta_nz": "load-factor amplitude of the stick inputs (dimensionless, e.g. 1.0)",
    "pulse_s": "width of one stick/rudder pulse, s",
    "nz_max": "load factor at the top of the pull-up / where a wind-up turn stops",
    "nz_min": "load factor at the bottom of the push-over",
    "period_s": "period of the load-factor cycle, s",
    "alpha_max_rad": "angle of attack at the end of the wind-up, rad",
    "beta_rad": "sideslip held through the SHSS run, rad (sign = side)",
    "segment_s": "length of the pieces the SHSS run is split into, s (30-40 as the paper flies; "
                 "up to duration_s, one unsplit run, for planning studies)",
    "rudder_norm": "rudder doublet amplitude, normalized command (0-1)",
    "delta_mach": "Mach change to reach in the level acceleration/deceleration",
}

_OPTIONAL = tuple(_FIELD_HELP)


class ManeuverFailure(RuntimeError):
    """A controller could not fly its maneuver. ``advice`` says what to change."""

    def __init__(self, what: str, t_s: float, advice: str) -> None:
        super().__init__(what)
        self.what = what
        self.t_s = t_s
        self.advice = advice


@dataclass(frozen=True)
class ManeuverSpec:
    """What to fly.

    Attributes
    ----------
    kind : one of :data:`KINDS`.
    mach : Mach number, 0.3-0.9: the trim Mach, except for level_accel / level_decel, where it
        is the centre of the sweep (:attr:`trim_mach` is where they start).
    altitude_m : trim altitude above mean sea level, m.
    gear_down : landing gear extended (approach / take-off configuration).
    duration_s : recorded length, s; default per kind (30-40 s, SHSS 105 s split in segments
        of ``segment_s``, 35 s by default; ``segment_s = duration_s`` flies it as one piece).
    heading_rad : initial true heading, rad.
    delta_nz, pulse_s, nz_max, nz_min, period_s, alpha_max_rad, beta_rad, segment_s,
    rudder_norm, delta_mach : excitation settings; ``None`` takes the kind's default in
        :data:`DEFAULTS` (reduced towards Mach 0.3 per :data:`LOW_SPEED_DEFAULTS` and from Mach
        0.6 to 0.7 and above per :data:`HIGH_SPEED_DEFAULTS`); setting one that does not apply to
        the kind is an error.
    """

    kind: str
    mach: float
    altitude_m: float
    gear_down: bool = False
    duration_s: float | None = None
    heading_rad: float = 0.0
    delta_nz: float | None = None
    pulse_s: float | None = None
    nz_max: float | None = None
    nz_min: float | None = None
    period_s: float | None = None
    alpha_max_rad: float | None = None
    beta_rad: float | None = None
    segment_s: float | None = None
    rudder_norm: float | None = None
    delta_mach: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"maneuver kind {self.kind!r} is unknown; choose one of {KINDS}")
        where = f"{self.kind} maneuver"
        if not (MACH_RANGE[0] <= self.mach <= MACH_RANGE[1]):
            raise ValueError(
                f"{where}: mach {self.mach} is outside {MACH_RANGE}; the testbed flies subsonic "
                "maneuvers between Mach 0.3 and 0.9"
            )
        if not (ALTITUDE_RANGE_M[0] <= self.altitude_m <= ALTITUDE_RANGE_M[1]):
            raise ValueError(
                f"{where}: altitude_m {self.altitude_m} is outside {ALTITUDE_RANGE_M} m (metres, "
                "not feet)"
            )
        if not math.isfinite(self.heading_rad) or abs(self.heading_rad) > 2 * math.pi:
            raise ValueError(f"{where}: heading_rad must be within +-2 pi rad, got {self.heading_rad}")
        defaults = DEFAULTS[self.kind]
        for name in _OPTIONAL:
            value = getattr(self, name)
            if value is None:
                if name in defaults:
                    object.__setattr__(self, name, default_value(self.kind, name, self.mach))
            elif name not in defaults:
                applies = [k for k, d in DEFAULTS.items() if name in d]
                raise ValueError(
                    f"{where}: {name} ({_FIELD_HELP[name]}) does not apply to {self.kind}; it "
                    f"is used by {applies}. Remove it."
                )
            elif not math.isfinite(value):
                raise ValueError(f"{where}: {name} must be finite, got {value}")
        if self.duration_s is None:
            object.__setattr__(self, "duration_s", float(defaults["duration_s"]))
        self._check_ranges(where)

    def _check_ranges(self, where: str) -> None:
        def need(ok: bool, msg: str) -> None:
            if not ok:
                raise ValueError(f"{where}: {msg}")

        d = self.duration_s
        if self.kind == "shss":
            # the paper splits SHSS runs into 30-40 s pieces (the default, 35 s); longer pieces, up
            # to the whole run (segment_s = duration_s), are allowed so planning studies can fly
            # the alternative (campaigns/studies/shss_segments.py)
            need(25.0 <= self.segment_s, f"segment_s {self.segment_s} must be at least 25 s "
                 "(the paper splits SHSS runs into 30-40 s pieces)")
            need(self.segment_s <= d <= 300.0, f"duration_s {d} must be between segment_s and 300 s")
            need(1.0 * DEG_TO_RAD <= abs(self.beta_rad) <= 8.0 * DEG_TO_RAD,
                 f"|beta_rad| {self.beta_rad} must be 1-8 deg in radians (e.g. {4.5 * DEG_TO_RAD:.4f};"
                 " negative for left sideslip)")
        else:
            need(10.0 <= d <= 60.0, f"duration_s {d} must be 10-60 s; FPR needs maneuvers of "
                 "30-40 s so the free initial conditions absorb the mean wind")
        if self.delta_nz is not None:
            need(0.05 <= self.delta_nz <= 4.0, f"delta_nz {self.delta_nz} must be 0.05-4")
        if self.pulse_s is not None:
            need(0.2 <= self.pulse_s <= 6.0, f"pulse_s {self.pulse_s} must be 0.2-6 s")
        if self.period_s is not None:
            need(2.0 <= self.period_s <= d / 2, f"period_s {self.period_s} must be 2 s to "
                 "duration_s/2 so at least two cycles are flown")
        if self.nz_max is not None:
            need(1.2 <= self.nz_max <= 8.0, f"nz_max {self.nz_max} must be 1.2-8 (the f16 FCS "
                 "limits load factor to 9)")
        if self.nz_min is not None:
            need(-1.0 <= self.nz_min <= 0.8, f"nz_min {self.nz_min} must be -1 to 0.8")
        if self.alpha_max_rad is not None:
            need(4.0 * DEG_TO_RAD <= self.alpha_max_rad <= 25.0 * DEG_TO_RAD,
                 f"alpha_max_rad {self.alpha_max_rad} must be 4-25 deg in radians")
        if self.rudder_norm is not None:
            need(0.05 <= self.rudder_norm <= 1.0, f"rudder_norm {self.rudder_norm} must be 0.05-1")
        if self.delta_mach is not None:
            need(0.02 <= self.delta_mach <= 0.3, f"delta_mach {self.delta_mach} must be 0.02-0.3")

    @property
    def trim_mach(self) -> float:
        """Mach number the maneuver starts (is trimmed) at.

        ``mach`` itself for every kind except the level acceleration / deceleration, whose Mach
        sweep of ``delta_mach`` is centred on ``mach`` (so that its mean Mach, by which the paper
        bins maneuvers, is the one asked for), shifted where needed to stay within Mach 0.3-0.9.
        """
        if self.kind == "level_accel":
            return min(max(self.mach - 0.5 * self.delta_mach, MACH_RANGE[0]),
                       MACH_RANGE[1] - self.delta_mach)
        if self.kind == "level_decel":
            return max(min(self.mach + 0.5 * self.delta_mach, MACH_RANGE[1]),
                       MACH_RANGE[0] + self.delta_mach)
        return self.mach

    @property
    def n_segments(self) -> int:
        """Number of recorded pieces the run is split into (1 except for SHSS)."""
        if self.kind != "shss":
            return 1
        return max(1, int(round(self.duration_s / self.segment_s)))

    @classmethod
    def from_dict(cls, d: dict) -> ManeuverSpec:
        """Build from a plain dict; ``*_deg`` keys are accepted and converted to ``*_rad``.

        Raises
        ------
        TypeError
            ``d`` is no dict.
        ValueError
            An unknown key (with its close match and the valid keys), a key given in two units,
            a missing ``kind``, ``mach`` or ``altitude_m``, or a value out of range.
        """
        if not isinstance(d, dict):
            raise TypeError(f"maneuver must be a table/dict, got {type(d).__name__}")
        given = d
        try:
            d = check(given, _SPEC_KEYS, "maneuver")
        except ValueError as exc:
            note = ("; the altitude is altitude_m, in metres"
                    if any("alt" in k and k not in _SPEC_KEYS for k in given)
                    else f"; kind is one of {', '.join(KINDS)}" if "kind" not in given else "")
            if note:
                raise ValueError(f"{exc}{note}") from None
            raise
        for k in d:
            if k not in given:
                d[k] = float(d[k])  # given in degrees: a float, as math.radians returned
        return cls(**d)

    def to_dict(self) -> dict:
        """Plain dict with every field resolved (defaults filled, ``None`` fields dropped)."""
        return {k: v for k, v in asdict(self).items() if v is not None}


# the values' types and ranges are checked by ManeuverSpec itself
_SPEC_KEYS = field_keys(ManeuverSpec, required=("kind", "mach", "altitude_m"), units=("rad",))


# --- controllers ----------------------------------------------------------------------------------

_U, _V, _W = COL["u_mps"], COL["v_mps"], COL["w_mps"]
_P, _Q, _R = COL["p_rps"], COL["q_rps"], COL["r_rps"]
_PHI, _THETA, _PSI = COL["phi_rad"], COL["theta_rad"], COL["psi_rad"]
_ALPHA, _BETA = COL["alpha_rad"], COL["beta_rad"]
_MACH, _TAS, _H = COL["mach"], COL["tas_mps"], COL["h_m"]
_FY, _FZ, _MASS, _G = COL["fy_n"], COL["fz_n"], COL["mass_kg"], COL["g_mps2"]
_ELEVATOR_CMD = COL["elevator_cmd_norm"]


def wrap_angle_rad(angle_rad: float) -> float:
    """``angle_rad`` wrapped into [-pi, pi), rad."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def _clip(x: float, lo: float, hi: float) -> float:
    return lo if x < lo else hi if x > hi else x


@dataclass
class TrimPoint:
    """The trimmed state a maneuver starts from (SI)."""

    mach: float
    altitude_m: float
    heading_rad: float
    alpha_rad: float
    theta_rad: float
    throttle_cmd_norm: float
    tas_mps: float


class Controller(ABC):
    """Base pilot: wings-level heading hold, altitude hold, Mach hold helpers.

    Subclasses implement :meth:`inputs` returning ``(elevator, aileron, rudder, throttle,
    speedbrake)`` normalized commands. The elevator command is built from a load-factor increment
    through the f16 FCS's steady-state law (stick = -(6.2 g / V - 0.02) * delta_nz), so amplitudes
    are in load factor whatever the Mach number.
    """

    #: seconds of hands-off trimmed flight recorded before the first input
    lead_in_s = 2.0

    def __init__(self, spec: ManeuverSpec, trim: TrimPoint, dt_s: float) -> None:
        self.spec = spec
        self.trim = trim
        self.dt_s = dt_s
        self.h_cmd_m = trim.altitude_m
        self.psi_cmd_rad = trim.heading_rad
        self.mach_cmd = trim.mach
        self._mach_int = 0.0
        self._rud_int = 0.0
        self.notes: dict = {}

    # building blocks -----------------------------------------------------------------------------
    @staticmethod
    def nz(x: np.ndarray) -> float:
        """Load factor along -z body (1 in level flight)."""
        return -x[_FZ] / (x[_MASS] * x[_G])

    @staticmethod
    def hdot_mps(x: np.ndarray) -> float:
        """Climb rate, m/s (from earth-relative body velocity and attitude)."""
        sth, cth = math.sin(x[_THETA]), math.cos(x[_THETA])
        return x[_U] * sth - (x[_V] * math.sin(x[_PHI]) + x[_W] * math.cos(x[_PHI])) * cth

    @staticmethod
    def stick(delta_nz: float, x: np.ndarray) -> float:
        """Elevator command giving a load-factor increment ``delta_nz`` in steady state."""
        g = x[_G]
        return -(6.2 * g / max(x[_TAS], 50.0) - 0.02) * delta_nz

    @staticmethod
    def aileron_for_bank(phi_cmd_rad: float, x: np.ndarray, k_per_s: float = 2.0) -> float:
        """Roll-rate command holding a bank angle (0.318 normalizes rad/s for the f16 FCS)."""
        return _clip(0.31821 * k_per_s * wrap_angle_rad(phi_cmd_rad - x[_PHI]), -0.6, 0.6)

    def rudder_for_sideslip(self, beta_cmd_rad: float, x: np.ndarray, k_p: float = 10.0,
                            k_i: float = 8.0) -> float:
        """Rudder command holding the sideslip ``beta_cmd_rad``: proportional-integral on the
        sideslip error (gains per rad and per rad s), the integral (the rudder trim) held while
        the rudder is saturated."""
        err_b = beta_cmd_rad - x[_BETA]
        rud_raw = k_p * err_b + self._rud_int
        if abs(rud_raw) < 1.0 or rud_raw * err_b < 0:
            self._rud_int += k_i * err_b * self.dt_s
        return _clip(rud_raw, -1.0, 1.0)

    def bank_for_heading(self, x: np.ndarray, limit_rad: float = 20 * DEG_TO_RAD) -> float:
        return _clip(2.5 * wrap_angle_rad(self.psi_cmd_rad - x[_PSI]), -limit_rad, limit_rad)

    def dnz_for_altitude(self, x: np.ndarray) -> float:
        """Load-factor increment holding ``h_cmd_m`` (omega_n ~0.3 rad/s, zeta ~0.8)."""
        return _clip(0.01 * (self.h_cmd_m - x[_H]) - 0.05 * self.hdot_mps(x), -1.5, 1.5)

    def throttle_for_mach(self, x: np.ndarray, lo: float = 0.0, hi: float = 1.0) -> float:
        err = self.mach_cmd - x[_MACH]
        thr = self.trim.throttle_cmd_norm + 8.0 * err + self._mach_int
        # anti-windup: integrate only while the throttle is not saturated in the error's direction
        if lo < thr < hi or (thr >= hi and err < 0) or (thr <= lo and err > 0):
            self._mach_int += 1.5 * err * self.dt_s
        return _clip(thr, lo, hi)

    # interface -----------------------------------------------------------------------------------
    @abstractmethod
    def inputs(self, t_s: float, x) -> tuple[float, float, float, float, float]:
        """Pilot inputs for the next step from the SI state row ``x`` (indexed by ``COL``)."""

    def check(self, t_s: float, x: np.ndarray) -> None:
        """Raise :class:`ManeuverFailure` when the maneuver's own target is lost (per step).

        The default has no target beyond the departure limits that :mod:`synth.flight` checks.
        """
        return None

    def finish(self, si: np.ndarray, t_s: np.ndarray) -> None:
        """Check the whole recorded run; raise :class:`ManeuverFailure` if it missed its goal.

        The default accepts any run that stayed within the departure limits.
        """
        return None

    def excitation_s(self, si: np.ndarray, t_s: np.ndarray) -> tuple[float, float]:
        """When the maneuver's own inputs act, s from its start: from the end of the hands-off
        lead-in to the end of the last input (the truth a maneuver extraction is judged by).

        The default: the whole run after the lead-in (the input is held to the end).
        """
        return self.lead_in_s, float(t_s[-1])


class _WingsLevel(Controller, ABC):
    """Stick program in load factor, wings level (gentle heading hold), throttle at trim."""

    @abstractmethod
    def dnz(self, t_s: float) -> float:
        """Load-factor increment commanded at ``t_s``."""

    def rudder(self, t_s: float) -> float:
        return 0.0

    def inputs(self, t_s, x):
        phi_cmd = self.bank_for_heading(x, limit_rad=5 * DEG_TO_RAD)
        return (
            self.stick(self.dnz(t_s), x),
            self.aileron_for_bank(phi_cmd, x),
            self.rudder(t_s),
            self.trim.throttle_cmd_norm,
            0.0,
        )


def _pulse_train(t_s: float, starts: list[float], widths: list[float], signs: list[float]) -> float:
    for t0 in starts:
        tau = t_s - t0
        if tau < 0:
            continue
        edge = 0.0
        for w, s in zip(widths, signs, strict=True):
            if tau < edge + w:
                return s
            edge += w
    return 0.0


class PitchDoublet(_WingsLevel):
    """Load-factor doublets (+, -) of ``pulse_s`` each, every 10 s."""

    def __init__(self, spec, trim, dt_s):
        super().__init__(spec, trim, dt_s)
        w = spec.pulse_s
        self.starts = [t for t in np.arange(self.lead_in_s, spec.duration_s - 2 * w - 3.0, 10.0)]
        self.widths, self.signs = [w, w], [1.0, -1.0]

    def dnz(self, t_s):
        return self.spec.delta_nz * _pulse_train(t_s, self.starts, self.widths, self.signs)

    def excitation_s(self, si, t_s):
        return float(self.starts[0]), float(self.starts[-1] + sum(self.widths))


class Multistep3211(PitchDoublet):
    """3-2-1-1 load-factor multisteps (unit ``pulse_s``), every 12 s."""

    def __init__(self, spec, trim, dt_s):
        super().__init__(spec, trim, dt_s)
        w = spec.pulse_s
        self.widths, self.signs = [3 * w, 2 * w, w, w], [1.0, -1.0, 1.0, -1.0]
        self.starts = [t for t in np.arange(self.lead_in_s, spec.duration_s - 7 * w - 3.0, 12.0)]


class PullupPushover(_WingsLevel):
    """Pull to ``nz_max`` for ``pulse_s``, push to ``nz_min`` long enough to level off, twice."""

    def __init__(self, spec, trim, dt_s):
        super().__init__(spec, trim, dt_s)
        up = spec.nz_max - 1.0
        down = 1.0 - spec.nz_min
        push_s = spec.pulse_s * up / down  # return the flight path to where it started
        self.widths, self.signs = [spec.pulse_s, push_s], [up, -down]
        cycle = spec.pulse_s + push_s + 5.0
        self.starts = [t for t in np.arange(self.lead_in_s, spec.duration_s - cycle + 4.0, cycle)]

    def dnz(self, t_s):
        return _pulse_train(t_s, self.starts, self.widths, self.signs)

    def excitation_s(self, si, t_s):
        return float(self.starts[0]), float(self.starts[-1] + sum(self.widths))


class RollerCoaster(_WingsLevel):
    """Sinusoidal load factor 1 +- ``delta_nz`` with period ``period_s``."""

    def dnz(self, t_s):
        tau = t_s - self.lead_in_s
        n_cycles = math.floor((self.spec.duration_s - self.lead_in_s - 1.0) / self.spec.period_s)
        if tau < 0 or tau > n_cycles * self.spec.period_s:
            return 0.0
        return self.spec.delta_nz * math.sin(2 * math.pi * tau / self.spec.period_s)

    def excitation_s(self, si, t_s):
        n_cycles = math.floor((self.spec.duration_s - self.lead_in_s - 1.0) / self.spec.period_s)
        return self.lead_in_s, self.lead_in_s + n_cycles * self.spec.period_s


class PullupRudderDoublets(RollerCoaster):
    """Slow load-factor cycles with a rudder doublet at every peak and trough."""

    def rudder(self, t_s):
        # a (+, -) doublet centred on every peak and trough of the load-factor sine
        tau = t_s - self.lead_in_s
        w = self.spec.pulse_s
        half = 0.5 * self.spec.period_s
        n_cycles = math.floor((self.spec.duration_s - self.lead_in_s - 1.0) / self.spec.period_s)
        first = 0.5 * half - w
        if tau < first or tau >= n_cycles * self.spec.period_s:
            return 0.0
        phase = (tau - first) % half
        if phase < w:
            return self.spec.rudder_norm
        if phase < 2 * w:
            return -self.spec.rudder_norm
        return 0.0


class WindupTurn(Controller):
    """Constant-Mach turn winding up to ``alpha_max_rad`` or ``nz_max``, whichever comes first.

    Alpha and load factor are ramped together, from trim to their targets over the run (less
    the last 3 s, which hold them): a pull follows the alpha ramp unless that would exceed the
    load-factor ramp, in which case it follows the load-factor ramp (one integrating loop on the
    smaller of the two errors, the load-factor error converted to alpha by
    :attr:`ALPHA_PER_G_RAD`). Where alpha binds (low Mach), g rises as alpha is swept; where load
    factor binds (high Mach), the turn still winds up steadily and ends on ``nz_max`` rather than
    reaching it early and holding it. Mach is held with throttle; once the throttle is at its
    limit the bank angle steepens beyond that of a level turn, trading altitude for speed, as a
    test pilot does.

    The turn is coordinated: the rudder holds the sideslip at zero (within 0.1-0.25 deg in calm
    air; without it the f16, its yaw damper removed, slipped 2.5-3.5 deg through the turn and
    climbed 250-400 m below Mach 0.8). Coordinated, the level-turn bank holds altitude within
    about 60 m up to Mach 0.7; above it the bank steepens to hold Mach and the turn descends up
    to about 115 m.

    The f16's FCS caps the alpha a wind-up reaches. Its pitch loop is proportional only (the
    integrator of ``fcs/g-load-pid`` is held by its ``trigger``, which is 1 in flight) and adds
    1.047 x alpha to the elevator while scheduling the command's authority down from 1 at 0 deg to
    0.11 at 28.6 deg. With the shipped nose-up stop of stick plus trim (-1) full aft stick balanced
    at about 17-20 deg wings level at low speed and at 12-14 deg in Mach 0.4-0.6 turns, short of
    the real F-16's 25 deg; the generated model moves that stop to
    :data:`synth.jsbsim_io.F16_AFT_COMMAND_STOP_NORM` (-2.5), where full aft command balances at
    22-24 deg in a 1.5 g turn at low dynamic pressure (less with a forward CG, and less in a
    tighter turn, whose pitch rate feeds back). A wind-up ends, as a test pilot's does, at full aft
    command (at or beyond the stop through the final hold) when that is at most
    :attr:`FCS_LIMIT_MARGIN_RAD` short of ``alpha_max_rad`` (``notes['aft_stop']``); further short,
    it fails. High-alpha turns (``alpha_max_rad`` 22 deg in the default campaign) are flown where
    the dynamic pressure is low, so the 1 g alpha is already near 14 deg: Mach 0.3 at 5500 m,
    Mach 0.4 at 9500 m, where every configuration of the default fleet reaches 22 deg at
    1.4-1.5 g, climbing about 100 m, with its command at -1.3 to -1.9.
    """

    mach_tolerance = 0.05
    bank_rate_rps = 15.0 * DEG_TO_RAD
    #: load-factor error -> alpha-error units of the pull loop, rad per g (loop gain in g: an
    #: integral of 25 x 0.08 = 2 per s)
    ALPHA_PER_G_RAD = 0.08
    #: sideslip loop (:meth:`Controller.rudder_for_sideslip`), per rad and per rad s: stiffer
    #: than the SHSS's, for the roll-in's adverse yaw and the rudder the turn rate needs, which
    #: grow with the wind-up (10, 8 left 0.7-0.8 deg of sideslip at the roll-in; these, 0.1-0.25)
    RUDDER_GAINS = (40.0, 80.0)
    #: how far short of ``alpha_max_rad`` a wind-up may end when the stick is at its aft stop
    #: through the final hold (the FCS's alpha limit, class docstring): forward-CG aircraft stop
    #: 1-1.7 deg short of the defaults at Mach 0.4-0.6, and of a high-alpha turn's target
    FCS_LIMIT_MARGIN_RAD = 2.0 * DEG_TO_RAD

    def __init__(self, spec, trim, dt_s):
        super().__init__(spec, trim, dt_s)
        self.ramp_end_s = spec.duration_s - 3.0
        self._dnz_int = 0.0
        self._gamma_int = 0.0
        self._phi_cmd = 0.0
        self.alpha_peak_rad = -1.0

    def _ramp(self, t_s: float) -> float:
        """Fraction 0..1 of the wind-up reached at ``t_s``."""
        if t_s < self.lead_in_s:
            return 0.0
        return min(1.0, (t_s - self.lead_in_s) / (self.ramp_end_s - self.lead_in_s))

    def alpha_cmd(self, t_s: float) -> float:
        a0 = self.trim.alpha_rad
        return a0 + self._ramp(t_s) * (self.spec.alpha_max_rad - a0)

    def nz_cmd(self, t_s: float) -> float:
        return 1.0 + self._ramp(t_s) * (self.spec.nz_max - 1.0)

    def inputs(self, t_s, x):
        nz = self.nz(x)
        # pull on the smaller of the alpha error and the load-factor error (in alpha units)
        err = min(self.alpha_cmd(t_s) - x[_ALPHA],
                  self.ALPHA_PER_G_RAD * (self.nz_cmd(t_s) - nz))
        self._dnz_int += 25.0 * err * self.dt_s
        dnz = self._dnz_int + 4.0 * err
        self.alpha_peak_rad = max(self.alpha_peak_rad, x[_ALPHA])
        thr = self.throttle_for_mach(x)
        err_m = self.mach_cmd - x[_MACH]
        # once the throttle is at its stop, speed is held by descending: integrate a dive angle
        if (thr >= 1.0 and err_m > 0) or self._gamma_int < 0:
            self._gamma_int = _clip(self._gamma_int - 2.0 * err_m * self.dt_s, -40 * DEG_TO_RAD, 0.0)
        gamma_cmd = self._gamma_int - 3.0 * max(err_m, 0.0)
        gamma = math.asin(_clip(self.hdot_mps(x) / max(x[_TAS], 50.0), -1.0, 1.0))
        if t_s < self.lead_in_s:
            phi_cmd = 0.0
        else:
            # bank of a level turn at this load factor, steepened to fly the commanded path
            phi_lvl = math.acos(_clip(1.0 / max(nz, 1.0), 0.0, 1.0))
            phi_cmd = _clip(phi_lvl + 2.0 * (gamma - gamma_cmd), 0.0, 85 * DEG_TO_RAD)
        # roll in and adjust bank smoothly, as a pilot does (and as IMU lever-arm corrections,
        # which need angular accelerations, prefer)
        step = self.bank_rate_rps * self.dt_s
        self._phi_cmd += _clip(phi_cmd - self._phi_cmd, -step, step)
        return (self.stick(dnz, x), self.aileron_for_bank(self._phi_cmd, x),
                self.rudder_for_sideslip(0.0, x, *self.RUDDER_GAINS), thr, 0.0)

    def check(self, t_s, x):
        if t_s > self.lead_in_s and abs(x[_MACH] - self.mach_cmd) > self.mach_tolerance:
            raise ManeuverFailure(
                f"Mach drifted to {x[_MACH]:.3f}, more than {self.mach_tolerance} from "
                f"{self.mach_cmd:.3f} (alpha {math.degrees(x[_ALPHA]):.1f} deg, nz "
                f"{self.nz(x):.1f})",
                t_s,
                "lower alpha_max_rad, lengthen duration_s, or fly higher / at lower Mach",
            )

    def finish(self, si, t_s):
        reached = float(np.max(si[:, _ALPHA]))
        self.notes["alpha_peak_rad"] = reached
        self.notes["nz_peak"] = float(np.max(-si[:, _FZ] / (si[:, _MASS] * si[:, _G])))
        # the command at the f16's nose-up stop through the final hold: the FCS gives no more
        hold = t_s >= self.ramp_end_s
        at_stop = bool(np.max(si[hold, _ELEVATOR_CMD]) <= F16_AFT_COMMAND_STOP_NORM)
        self.notes["aft_stop"] = at_stop
        # a wind-up turn ends at alpha_max or nz_max, whichever comes first, or at the FCS's
        # limit when that is at most FCS_LIMIT_MARGIN_RAD short of alpha_max
        short = (reached < self.spec.alpha_max_rad - 1.0 * DEG_TO_RAD
                 and self.notes["nz_peak"] < self.spec.nz_max - 0.3)
        if short and not (at_stop and reached >= self.spec.alpha_max_rad - self.FCS_LIMIT_MARGIN_RAD):
            raise ManeuverFailure(
                f"reached neither alpha {math.degrees(self.spec.alpha_max_rad):.1f} deg (got "
                f"{math.degrees(reached):.1f}) nor load factor {self.spec.nz_max:.1f} (got "
                f"{self.notes['nz_peak']:.1f})"
                + (", the stick at its aft stop" if at_stop else ""),
                float(t_s[-1]),
                "lower alpha_max_rad or nz_max to what the f16's FCS gives at full aft "
                "command: about 22-24 deg of alpha in a 1.5 g turn at Mach 0.3-0.4 and low "
                "dynamic pressure, 20-22 deg at Mach 0.4-0.5 and 3000-6000 m (the least with a "
                "forward CG); from Mach 0.6 the turn runs out of thrust first (Mach drifts) near "
                "20 deg and 4.6 g at Mach 0.6, 15-18 deg and 5.5-6.5 g at Mach 0.7-0.9; a slower "
                "wind-up (longer duration_s) does not raise them",
            )


class SteadyHeadingSideslip(Controller):
    """Sideslip held with rudder, heading with bank, altitude with elevator, Mach with throttle.

    The sideslip ramps in smoothly (peak 1.6 deg/s) after the lead-in and is then held for the
    rest of the run, which is split into ``n_segments`` pieces of about ``segment_s``. With the
    heading held, the flight path must turn by the sideslip change (track = heading + beta); the
    bank for that turn rate is fed forward.

    Lateral loops, as a test pilot flies an SHSS:

    * rudder: proportional-integral on the sideslip error (the integral is the rudder trim);
    * bank: the f16's roll channel is a proportional roll-rate command, so holding a bank
      against the sideslip's rolling moment (dihedral effect) needs a standing aileron command;
      an integrator on the bank error supplies it (the aileron trim), so the bank follows its
      command with no steady error;
    * heading: the bank command is the bank that balances the side force (fed forward from the
      measured lateral acceleration, low-pass filtered against turbulence) plus a
      proportional-integral-rate heading correction.

    The heading loop's gains are in turn rate: a bank change of ``dphi`` turns the flight path at
    ``g tan(dphi) / V``, so they scale with the true airspeed to keep the loop's bandwidth.
    """

    heading_tolerance_rad = 5.0 * DEG_TO_RAD
    altitude_tolerance_m = 150.0
    beta_rate_rps = 1.0 * DEG_TO_RAD
    #: aileron command saturating the f16's ailerons in a steady bank (FCS: surface = 4 x command)
    AILERON_FULL = 0.25
    #: time constant of the side-force feedforward's low-pass filter, s
    ff_tau_s = 0.5

    def __init__(self, spec, trim, dt_s):
        super().__init__(spec, trim, dt_s)
        self.seg_len_s = spec.duration_s / spec.n_segments
        self._beta_cmd = 0.0
        self._psi_int = 0.0
        self._ail_int = 0.0
        self._phi_ff = 0.0

    def beta_cmd(self, t_s: float) -> tuple[float, float]:
        """Commanded sideslip, rad, and its rate, rad/s: a smooth (1 - cos) ramp, then held."""
        ramp_s = 1.5 * abs(self.spec.beta_rad) / self.beta_rate_rps
        tau = t_s - self.lead_in_s
        if tau <= 0.0:
            return 0.0, 0.0
        if tau >= ramp_s:
            return self.spec.beta_rad, 0.0
        w = math.pi / ramp_s
        return (0.5 * self.spec.beta_rad * (1.0 - math.cos(w * tau)),
                0.5 * self.spec.beta_rad * w * math.sin(w * tau))

    def inputs(self, t_s, x):
        dt = self.dt_s
        self._beta_cmd, beta_rate = self.beta_cmd(t_s)
        rudder = self.rudder_for_sideslip(self._beta_cmd, x)
        # the side force of the sideslip is balanced by bank: g cos(theta) sin(phi) = -a_y
        ay = x[_FY] / x[_MASS]
        phi_ff = math.asin(_clip(-ay / (x[_G] * math.cos(x[_THETA])), -0.6, 0.6))
        self._phi_ff += (phi_ff - self._phi_ff) * dt / self.ff_tau_s
        # heading: PI + heading-rate damping, gains scaled to turn rate (V / g)
        kv = max(x[_TAS], 50.0) / 100.0
        err_psi = wrap_angle_rad(self.psi_cmd_rad - x[_PSI])
        sph, cph = math.sin(x[_PHI]), math.cos(x[_PHI])
        psidot = (x[_Q] * sph + x[_R] * cph) / math.cos(x[_THETA])
        phi_fb = _clip(kv * (3.0 * err_psi - 4.0 * psidot), -12 * DEG_TO_RAD, 12 * DEG_TO_RAD)
        phi_cmd = self._phi_ff + phi_fb + self._psi_int
        if abs(phi_fb) < 12 * DEG_TO_RAD:
            self._psi_int = _clip(self._psi_int + kv * 0.5 * err_psi * dt, -15 * DEG_TO_RAD, 15 * DEG_TO_RAD)
        # track = heading + beta: a sideslip ramp at constant heading needs a turn
        phi_cmd += math.atan(x[_TAS] * beta_rate / x[_G])
        # bank: proportional roll-rate command plus the aileron trim (integral of the bank error,
        # 1 per s relative to the proportional 2 per s; held while the ailerons are saturated)
        aileron = self.aileron_for_bank(phi_cmd, x) + self._ail_int
        err_phi = wrap_angle_rad(phi_cmd - x[_PHI])
        if abs(aileron) < self.AILERON_FULL or aileron * err_phi < 0:
            self._ail_int = _clip(self._ail_int + 0.31821 * 1.0 * err_phi * dt,
                                  -self.AILERON_FULL, self.AILERON_FULL)
        aileron = _clip(aileron, -0.6, 0.6)
        dnz = self.dnz_for_altitude(x) + (1.0 / math.cos(x[_PHI]) - 1.0)
        return (self.stick(dnz, x), aileron, rudder, self.throttle_for_mach(x), 0.0)

    def check(self, t_s, x):
        if abs(wrap_angle_rad(x[_PSI] - self.psi_cmd_rad)) > self.heading_tolerance_rad:
            raise ManeuverFailure(
                f"heading drifted {math.degrees(wrap_angle_rad(x[_PSI] - self.psi_cmd_rad)):.1f} deg "
                f"(sideslip {math.degrees(x[_BETA]):.1f} deg)",
                t_s, "reduce beta_rad")
        if abs(x[_H] - self.h_cmd_m) > self.altitude_tolerance_m:
            raise ManeuverFailure(
                f"altitude drifted {x[_H] - self.h_cmd_m:+.0f} m", t_s, "reduce beta_rad")

    def finish(self, si, t_s):
        n = self.spec.n_segments
        peaks = []
        for i in range(n):
            sl = (t_s >= i * self.seg_len_s) & (t_s < (i + 1) * self.seg_len_s)
            peak = float(np.max(np.abs(si[sl, _BETA])))
            peaks.append(peak)
            if peak < abs(self.spec.beta_rad) - 0.5 * DEG_TO_RAD:
                raise ManeuverFailure(
                    f"segment {i} reached |beta| {math.degrees(peak):.2f} deg of the requested "
                    f"{math.degrees(abs(self.spec.beta_rad)):.2f} deg (rudder authority)",
                    float(i * self.seg_len_s),
                    "reduce beta_rad; the f16's rudder gives about 5 deg of sideslip",
                )
        self.notes["beta_peak_rad_per_segment"] = peaks


class LevelSpeedChange(Controller):
    """Level acceleration (full power) or deceleration (idle) at constant altitude.

    Once the target Mach (trim Mach +- ``delta_mach``) is reached the throttle holds it.
    """

    altitude_tolerance_m = 150.0
    #: throttle command of maximum dry thrust (the f16 doubles it; above 1.0 is afterburner);
    #: afterburner would reach the target in a few seconds and leave little of the sweep
    MIL_POWER = 0.5

    def __init__(self, spec, trim, dt_s):
        super().__init__(spec, trim, dt_s)
        self.sign = 1.0 if spec.kind == "level_accel" else -1.0
        self.target_mach = trim.mach + self.sign * spec.delta_mach
        self.reached = False
        self._mach_prev = trim.mach
        self._mach_rate = 0.0

    def _mach_lead(self, x: np.ndarray) -> float:
        """Mach predicted 4 s ahead: the engine spools down slowly, so switch early."""
        rate = (x[_MACH] - self._mach_prev) / self.dt_s
        self._mach_prev = x[_MACH]
        self._mach_rate += (rate - self._mach_rate) * self.dt_s / 1.0
        return x[_MACH] + 4.0 * self._mach_rate

    def inputs(self, t_s, x):
        phi_cmd = self.bank_for_heading(x, limit_rad=5 * DEG_TO_RAD)
        speedbrake = 0.0
        if t_s < self.lead_in_s:
            thr = self.trim.throttle_cmd_norm
        elif not self.reached and self.sign * (self.target_mach - self._mach_lead(x)) > 0:
            # no speedbrake: the f16 model's speedbrake shifts trim alpha by about -5 deg,
            # which would make the deceleration useless for alpha calibration
            thr = self.MIL_POWER if self.sign > 0 else 0.0
        else:
            if not self.reached:
                self.reached = True
                self.mach_cmd = self.target_mach
                self._mach_int = 0.0
            thr = self.throttle_for_mach(x)
        dnz = self.dnz_for_altitude(x)
        return (self.stick(dnz, x), self.aileron_for_bank(phi_cmd, x), 0.0, thr, speedbrake)

    def check(self, t_s, x):
        if abs(x[_H] - self.h_cmd_m) > self.altitude_tolerance_m:
            raise ManeuverFailure(
                f"altitude drifted {x[_H] - self.h_cmd_m:+.0f} m from {self.h_cmd_m:.0f} m",
                t_s, "reduce delta_mach or fly at a Mach where the f16 has more excess power")

    def finish(self, si, t_s):
        dm = float(np.ptp(si[:, _MACH]))
        self.notes["mach_change"] = dm
        if dm < 0.75 * self.spec.delta_mach:
            raise ManeuverFailure(
                f"Mach changed by only {dm:.3f} of the requested {self.spec.delta_mach:.3f}",
                float(t_s[-1]), "lengthen duration_s or reduce delta_mach")

    def excitation_s(self, si, t_s):
        """From the power change to the speed's end: the first time 95 % of the run's Mach
        change is done when the target was reached (the throttle returns to holding Mach about
        4 s before, on a prediction); the run's end when it was not (the power held to it)."""
        if not self.reached:
            return self.lead_in_s, float(t_s[-1])
        mach = si[:, _MACH]
        k0 = int(np.searchsorted(t_s, self.lead_in_s))
        change = self.sign * (mach[k0:] - mach[k0])
        done = np.flatnonzero(change >= 0.95 * float(np.max(change)))
        return self.lead_in_s, float(t_s[k0 + done[0]]) if len(done) else float(t_s[-1])


CONTROLLERS: dict[str, type[Controller]] = {
    "pitch_doublet": PitchDoublet,
    "3211": Multistep3211,
    "pullup_pushover": PullupPushover,
    "roller_coaster": RollerCoaster,
    "windup_turn": WindupTurn,
    "shss": SteadyHeadingSideslip,
    "pullup_rudder_doublets": PullupRudderDoublets,
    "level_accel": LevelSpeedChange,
    "level_decel": LevelSpeedChange,
}


def make_controller(spec: ManeuverSpec, trim: TrimPoint, dt_s: float) -> Controller:
    """The pilot for ``spec`` starting from ``trim`` with step ``dt_s``."""
    return CONTROLLERS[spec.kind](spec, trim, dt_s)
