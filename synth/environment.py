"""The atmosphere a maneuver is flown in: planet model, steady wind, turbulence, a discrete gust.

:class:`Environment` is plain data (SI units, radians); :mod:`synth.flight` applies it to JSBSim
through :mod:`synth.jsbsim_io`. Turbulence is JSBSim's MIL-F-8785C / MIL-HDBK-1797 model; its
random numbers come from ``turbulence_seed``, so one seed gives bit-identical runs. The realism
level's slow vertical air motion (:class:`VerticalAirMotion`, opt-in; docs/realism.md) is drawn
from the same seed.

Example
-------
>>> env = Environment.from_dict({"wind_ned_mps": [5, -3, 0], "turbulence": "light",
...                              "turbulence_seed": 7})
>>> env.to_dict()["turbulence"]
'light'
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from aircraft_models.schema import check, field_keys
from synth.processes import gauss_markov

PLANETS = ("flat", "wgs84")

#: turbulence level -> (JSBSim milspec probability-of-exceedance index, wind speed at 20 ft, m/s).
#: MIL-F-8785C: light / moderate / severe are exceeded with probability 1e-2 / 1e-3 / 1e-5
#: (indices 3 / 4 / 6) and correspond to 15 / 30 / 45 kt at 20 ft.
TURBULENCE_LEVELS: dict[str, tuple[int, float]] = {
    "none": (0, 0.0),
    "light": (3, 7.717),
    "moderate": (4, 15.433),
    "severe": (6, 23.150),
}


@dataclass(frozen=True)
class Gust:
    """A discrete 1-cosine gust (JSBSim ``atmosphere/cosine-gust``).

    Attributes
    ----------
    amplitude_mps : peak gust speed, m/s (> 0).
    direction_ned : (3,) direction the gust air moves towards, NED (normalized by JSBSim);
        ``(0, 0, -1)`` is an up-gust, which raises the angle of attack.
    start_s : time after the start of the recorded maneuver when the gust begins, s.
    duration_s : total rise-and-fall time, s.
    """

    amplitude_mps: float
    direction_ned: tuple[float, float, float] = (0.0, 0.0, -1.0)
    start_s: float = 5.0
    duration_s: float = 2.0

    def __post_init__(self) -> None:
        d = tuple(float(x) for x in self.direction_ned)
        if len(d) != 3 or not all(math.isfinite(x) for x in d) or math.hypot(*d) == 0.0:
            raise ValueError(
                f"gust.direction_ned must be three finite numbers, not all zero (NED), got "
                f"{self.direction_ned!r}; e.g. [0, 0, -1] for an up-gust"
            )
        object.__setattr__(self, "direction_ned", d)
        if not (0.0 < self.amplitude_mps <= 30.0):
            raise ValueError(
                f"gust.amplitude_mps must be in (0, 30] m/s, got {self.amplitude_mps}; "
                "omit the gust for none"
            )
        if self.start_s < 0.0 or not (0.1 <= self.duration_s <= 30.0):
            raise ValueError(
                f"gust needs start_s >= 0 and duration_s in [0.1, 30] s, got start_s="
                f"{self.start_s}, duration_s={self.duration_s}"
            )


#: The stream of the vertical air motion's generator, beside the maneuver's turbulence seed
#: (``default_rng([turbulence_seed, VERTICAL_AIR_STREAM])``): "vert" in ASCII.
VERTICAL_AIR_STREAM = 0x76657274


@dataclass(frozen=True)
class VerticalAirMotion:
    """Slow vertical motion of the air mass (the realism level; docs/realism.md).

    A stationary first-order Gauss-Markov vertical wind (positive down, NED), drawn per maneuver
    from ``default_rng([turbulence_seed, VERTICAL_AIR_STREAM])`` at the simulation steps and
    flown by JSBSim (:func:`synth.flight.fly_maneuver`), so the aircraft responds and the truth's
    ``true_wind_d_mps`` contains it. Mesoscale motion (gravity waves, 0.1-1 m/s; Nappo, *An
    Introduction to Atmospheric Gravity Waves*, 2nd ed., 2012, ch. 1-2) of a few kilometres'
    scale, crossed at 100-250 m/s: tens of seconds, slower than the MIL-F-8785C turbulence
    (L_w = 533 m: about 3 s).

    Attributes
    ----------
    sigma_mps : its standard deviation, m/s (0 < sigma <= 2).
    tau_s : its correlation time, s (1 <= tau <= 600).
    """

    sigma_mps: float = 0.4
    tau_s: float = 30.0

    def __post_init__(self) -> None:
        for name in ("sigma_mps", "tau_s"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"vertical_air_motion.{name} = {v!r}: expected a finite number")
            object.__setattr__(self, name, float(v))
        if not (0.0 < self.sigma_mps <= 2.0):
            raise ValueError(f"vertical_air_motion.sigma_mps = {self.sigma_mps} must be in (0, 2] m/s; "
                             "omit vertical_air_motion for none")
        if not (1.0 <= self.tau_s <= 600.0):
            raise ValueError(f"vertical_air_motion.tau_s = {self.tau_s} must be in [1, 600] s")

    def wind_down_mps(self, t_s: np.ndarray, seed: int) -> np.ndarray:
        """The vertical wind (NED down, m/s) at times ``t_s`` (s, uniform, from the record's start)
        of the maneuver whose turbulence seed is ``seed``; its first value does not depend on the
        record's length."""
        rng = np.random.default_rng([int(seed), VERTICAL_AIR_STREAM])
        return gauss_markov(np.asarray(t_s, dtype=float), self.sigma_mps, self.tau_s, rng)


@dataclass(frozen=True)
class Environment:
    """Planet, wind and turbulence for one flight.

    Attributes
    ----------
    planet : ``"flat"`` (flat, non-rotating, constant g: the estimator's own earth, so the truth
        satisfies its state equations to ~0.01 m/s) or ``"wgs84"`` (JSBSim's rotating ellipsoid).
    wind_ned_mps : (3,) steady wind, NED, m/s (velocity of the air mass, i.e. where it blows to).
    turbulence : ``"none"``, ``"light"``, ``"moderate"`` or ``"severe"``.
    turbulence_seed : seed of JSBSim's random generator (``simulation/randomseed``).
    gust : optional discrete 1-cosine gust.
    latitude_rad, longitude_rad : where the flight starts (matters on ``"wgs84"`` only), rad.
    vertical_air_motion : optional slow vertical air motion (the realism level), drawn from
        ``turbulence_seed``; in a table ``vertical_air_motion = { sigma_mps = 0.4, tau_s = 30 }``,
        or ``true`` for the typical values.
    """

    planet: str = "flat"
    wind_ned_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    turbulence: str = "none"
    turbulence_seed: int = 0
    gust: Gust | None = None
    latitude_rad: float = math.radians(13.0)
    longitude_rad: float = math.radians(77.6)
    vertical_air_motion: VerticalAirMotion | None = None

    def __post_init__(self) -> None:
        if self.planet not in PLANETS:
            raise ValueError(f"planet must be one of {PLANETS}, got {self.planet!r}")
        w = tuple(float(x) for x in self.wind_ned_mps)
        if len(w) != 3 or not all(math.isfinite(x) for x in w):
            raise ValueError(f"wind_ned_mps must be three finite numbers [N, E, D] in m/s, got {w}")
        if math.hypot(*w) > 40.0 or abs(w[2]) > 5.0:
            raise ValueError(
                f"wind_ned_mps {w} is outside what the testbed models (|wind| <= 40 m/s, "
                "|vertical| <= 5 m/s); SPEC §6 uses up to 20 m/s"
            )
        object.__setattr__(self, "wind_ned_mps", w)
        if self.turbulence not in TURBULENCE_LEVELS:
            raise ValueError(
                f"turbulence must be one of {sorted(TURBULENCE_LEVELS)}, got {self.turbulence!r}"
            )
        if not isinstance(self.turbulence_seed, int) or isinstance(self.turbulence_seed, bool):
            raise ValueError(f"turbulence_seed must be an int, got {self.turbulence_seed!r}")
        if not (0 <= self.turbulence_seed < 2**31):
            raise ValueError(f"turbulence_seed must be in [0, 2**31), got {self.turbulence_seed}")
        if not (abs(self.latitude_rad) < math.radians(85.0)):
            raise ValueError(f"latitude_rad must be within +-85 deg, got {self.latitude_rad}")
        if not (self.vertical_air_motion is None or isinstance(self.vertical_air_motion, VerticalAirMotion)):
            raise ValueError("vertical_air_motion must be a VerticalAirMotion or None, got "
                             f"{self.vertical_air_motion!r}")

    def vertical_wind_ned_mps(self, t_s: np.ndarray) -> np.ndarray | None:
        """(N, 3) the slow vertical air motion at ``t_s`` (NED, only the down component non-zero),
        m/s, drawn from :attr:`turbulence_seed`; None without it."""
        if self.vertical_air_motion is None:
            return None
        t = np.asarray(t_s, dtype=float)
        out = np.zeros((t.size, 3))
        out[:, 2] = self.vertical_air_motion.wind_down_mps(t, self.turbulence_seed)
        return out

    @property
    def turbulence_severity(self) -> int:
        """JSBSim milspec probability-of-exceedance index for :attr:`turbulence`."""
        return TURBULENCE_LEVELS[self.turbulence][0]

    @property
    def turbulence_w20_mps(self) -> float:
        """Wind speed at 20 ft AGL that goes with :attr:`turbulence`, m/s."""
        return TURBULENCE_LEVELS[self.turbulence][1]

    @classmethod
    def from_dict(cls, d: dict) -> Environment:
        """Build from a plain dict (e.g. a TOML table), checking keys and units.

        Keys are the attribute names; ``gust`` is a nested table with :class:`Gust`'s keys,
        ``vertical_air_motion`` one with :class:`VerticalAirMotion`'s (or true/false).
        Degrees are accepted only where the key says so (``latitude_deg``, ``longitude_deg``).

        Raises
        ------
        TypeError
            ``d`` is no dict.
        ValueError
            A key :func:`aircraft_models.schema.check` rejects (unknown: named with its close
            match; given in two units), a gust without ``amplitude_mps``, a value out of range.
        """
        if not isinstance(d, dict):
            raise TypeError(f"environment must be a table/dict, got {type(d).__name__}")
        given = d
        try:
            d = check(given, _ENVIRONMENT_KEYS, "environment")
        except ValueError as exc:
            if any(k.startswith("wind") and k not in _ENVIRONMENT_KEYS for k in given):
                raise ValueError(f"{exc}; the wind is wind_ned_mps = [north, east, down] in m/s") from None
            raise
        for k in ("latitude_rad", "longitude_rad"):
            if k in d and k not in given:
                d[k] = float(d[k])  # given in degrees: a float, as math.radians returned
        gust = d.get("gust")
        if gust is not None:
            gust = check(gust, _GUST_KEYS, "environment.gust")
            d["gust"] = Gust(**{k: (tuple(v) if k == "direction_ned" else float(v))
                                for k, v in gust.items()})
        if "wind_ned_mps" in d:
            d["wind_ned_mps"] = tuple(d["wind_ned_mps"])
        if "vertical_air_motion" in d:
            d["vertical_air_motion"] = _vertical_air_motion(d["vertical_air_motion"])
        return cls(**d)

    def to_dict(self) -> dict:
        """Plain-dict form (lists, floats, strings) that :meth:`from_dict` reads back."""
        out = asdict(self)
        out["wind_ned_mps"] = list(self.wind_ned_mps)
        if self.gust is None:
            del out["gust"]
        else:
            out["gust"]["direction_ned"] = list(self.gust.direction_ned)
        if self.vertical_air_motion is None:  # absent while off: the form written before it existed
            del out["vertical_air_motion"]
        return out


def _vertical_air_motion(value) -> VerticalAirMotion | None:
    """``[environment] vertical_air_motion``: a table, true (the typical values) or false (none)."""
    if isinstance(value, bool):
        return VerticalAirMotion() if value else None
    if value is None or isinstance(value, VerticalAirMotion):
        return value
    if not isinstance(value, dict):
        raise ValueError("environment.vertical_air_motion must be a table { sigma_mps = ..., tau_s = ... }, "
                         f"true or false, got {value!r}")
    return VerticalAirMotion(**check(value, _VERTICAL_KEYS, "environment.vertical_air_motion"))


# the values' types and ranges are checked by the dataclasses themselves
_GUST_KEYS = field_keys(Gust, required=("amplitude_mps",))
_VERTICAL_KEYS = field_keys(VerticalAirMotion, units=("s",))
_ENVIRONMENT_KEYS = field_keys(Environment, units=("rad",))


__all__ = ["Environment", "Gust", "PLANETS", "TURBULENCE_LEVELS", "VERTICAL_AIR_STREAM", "VerticalAirMotion"]
