"""Gross unit checks: values that cannot be right in the declared unit.

A unit mistake (degrees declared as radians, g declared as m/s^2, feet declared as metres) does
not crash anything: the estimator would converge to nonsense. These checks catch the mistakes
that leave values far outside what an aircraft can do, name the channel and the observed range,
and suggest the unit in which the values would be plausible. They cannot catch every mistake:
values plausible in both units (an airspeed of 150 read as kt or m/s; small angles in degrees
declared as radians) pass. Two cross-checks add to them: true airspeed / Mach must be a speed of
sound (:func:`check_tas_against_mach`), and the Euler angles must change as the body rates say
(:mod:`estimator.io.consistency`; the heading, which may be unwrapped, is checked only that way).

=====================  ===============================  =========================================
quantity (channels)    statistic                        plausible (SI)
=====================  ===============================  =========================================
time step (t)          median step                      1e-4 to 2 s
flow angle (alpha_*,   max abs                          <= 1.6 rad (92 deg)
beta_*), theta
bank angle (phi)       max abs                          <= pi (+0.05) rad
other angles but psi   max abs                           <= 2 pi (+0.05) rad
body rate (p, q, r)    max abs                          <= 6 rad/s (344 deg/s)
IMU acceleration       mean of the norm of (ax, ay, az) 0.4 g to 4 g (1 g in steady flight)
true airspeed (tas)    median                           15 to 700 m/s
altitude (h)           median                           -500 to 25 000 m
gear flag (gear)       min, max                         0 to 1
Mach (mach)            median                           0 to 5
=====================  ===============================  =========================================
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from estimator.io.errors import DataError, Where, at_row
from estimator.io.units import UNITS, from_si, to_si, units_of


@dataclass(frozen=True)
class Check:
    """A plausible interval of one statistic of a channel's SI values.

    Attributes
    ----------
    what : the quantity, for messages ("an angle").
    statistic : "maxabs", "median", "mean_norm" or "minmax".
    low, high : plausible interval of the statistic, SI.
    typical : a typical value to rank unit suggestions by closeness (None: rank by ``prefer``).
    prefer : unit suggestions in order of preference.
    """

    what: str
    statistic: str
    low: float
    high: float
    typical: float | None = None
    prefer: tuple[str, ...] = ()


_G = 9.80665
_FLOW = Check("a flow angle", "maxabs", 0.0, 1.6, prefer=("deg", "mrad"))
_CHECKS: dict[str, Check] = {
    "t": Check("a sample time step", "median_step", 1e-4, 2.0, typical=0.025, prefer=("s", "ms")),
    "theta": Check("a pitch angle", "maxabs", 0.0, 1.6, prefer=("deg", "mrad")),
    "phi": Check("a bank angle", "maxabs", 0.0, math.pi + 0.05, prefer=("deg", "mrad")),
    "p": Check("a body rate", "maxabs", 0.0, 6.0, prefer=("deg/s",)),
    "q": Check("a body rate", "maxabs", 0.0, 6.0, prefer=("deg/s",)),
    "r": Check("a body rate", "maxabs", 0.0, 6.0, prefer=("deg/s",)),
    "accel": Check("a specific force in flight", "mean_norm", 0.4 * _G, 4.0 * _G, typical=_G),
    "tas": Check("a true airspeed", "median", 15.0, 700.0, typical=150.0),
    "h": Check("a pressure altitude", "median", -500.0, 25000.0, typical=5000.0),
    "gear": Check("a gear-down flag", "minmax", 0.0, 1.0),
    "mach": Check("a Mach number", "median", 0.0, 5.0),
}
_BY_DIMENSION: dict[str, Check] = {
    "angle": Check("an angle", "maxabs", 0.0, 2 * math.pi + 0.05, prefer=("deg", "mrad")),
    "angular rate": Check("an angular rate", "maxabs", 0.0, 6.0, prefer=("deg/s",)),
}


def check_for(name: str, dimension: str) -> Check | None:
    """The check of a canonical column name (``alpha_*``/``beta_*`` are flow angles), or None."""
    if name in _CHECKS:
        return _CHECKS[name]
    if name == "psi":  # may be unwrapped over several turns: see estimator.io.consistency
        return None
    if dimension == "angle" and (name.startswith("alpha") or name.startswith("beta")):
        return _FLOW
    return _BY_DIMENSION.get(dimension)


def _statistic(check: Check, v: np.ndarray, t_s: np.ndarray) -> tuple[float, int]:
    """Statistic value and the sample index it is attributed to."""
    if check.statistic == "maxabs":
        i = int(np.argmax(np.abs(v)))
        return float(abs(v[i])), i
    if check.statistic == "median":
        return float(np.median(v)), int(np.argmin(np.abs(v - np.median(v))))
    if check.statistic == "median_step":
        return float(np.median(np.diff(t_s))), 0
    if check.statistic == "mean_norm":
        norm = np.linalg.norm(np.atleast_2d(v.T).T.reshape(len(t_s), -1), axis=1)
        return float(np.mean(norm)), int(np.argmax(norm))
    lo, hi = float(np.min(v)), float(np.max(v))
    return (lo if lo < check.low else hi), int(np.argmin(v) if lo < check.low else np.argmax(v))


def _ok(check: Check, v: np.ndarray, t_s: np.ndarray) -> bool:
    if check.statistic == "minmax":
        return bool(np.min(v) >= check.low - 1e-9 and np.max(v) <= check.high + 1e-9)
    s, _ = _statistic(check, v, t_s)
    return check.low <= s <= check.high


def suggest_units(check: Check, raw: np.ndarray, declared: str, t_s_of: Callable) -> list[str]:
    """Units of the declared dimension in which the raw values would pass ``check``, best first."""
    dim = UNITS[declared].dimension
    ok = []
    for u in units_of(dim):
        if u == declared or u == "bool":
            continue
        v = to_si(raw, u, u)
        if _ok(check, v, t_s_of(v)):
            ok.append(u)
    if check.typical is not None:
        def _key(u):
            v = to_si(raw, u, u)
            return abs(math.log(max(_statistic(check, v, t_s_of(v))[0], 1e-300) / check.typical))

        return sorted(ok, key=_key)
    return sorted(ok, key=lambda u: check.prefer.index(u) if u in check.prefer else len(check.prefer))


def check_plausible(name: str, label: str, values_si: np.ndarray, unit: str, t_s: np.ndarray,
                    rows: np.ndarray, where: Where) -> None:
    """Raise :class:`DataError` if ``values_si`` cannot be right in the declared ``unit``.

    Parameters
    ----------
    name : canonical column name (``phi``, ``alpha_zl``, ``t``) or ``"accel"`` for (ax, ay, az).
    label : how the message names the channel and its source column.
    values_si : (N,) values after conversion, or (N, 3) for ``"accel"``.
    unit : the declared unit.
    t_s : (N,) sample times, s (for ``"t"``: the times themselves, SI).
    rows : (N,) data rows of the samples in the file.
    where : file, maneuver and time range.
    """
    check = check_for(name, UNITS[unit].dimension)
    if check is None or values_si.size == 0:
        return
    if _ok(check, values_si, t_s):
        return
    stat, i = _statistic(check, values_si, t_s)
    raw = from_si(values_si, unit, label)
    raw_stat, _ = _statistic(check, raw, from_si(t_s, unit, label) if name == "t" else t_s)
    t_of = (lambda v: v) if name == "t" else (lambda v: t_s)
    cands = suggest_units(check, raw, unit, t_of)
    stat_text = {
        "maxabs": "largest |value|", "median": "median", "median_step": "median time step",
        "mean_norm": "mean magnitude", "minmax": "value",
    }[check.statistic]
    place = f" {at_row(t_s[i], int(rows[i]))}" if check.statistic in ("maxabs", "minmax") else ""
    si_text = "" if UNITS[unit].factor == 1.0 and not UNITS[unit].offset else f" (= {stat:.6g} in SI)"
    lo, hi = check.low, check.high
    hint = (f"the values look like {cands[0]}: set unit = \"{cands[0]}\" for it under [columns]"
            if cands else "check that the column is the right one and that its unit is declared correctly")
    raise DataError(
        f"{where}: {label} is declared in {unit!r} but its {stat_text} is {raw_stat:.6g} {unit}"
        f"{place}{si_text}, which cannot be {check.what} (plausible: {lo:.4g} to "
        f"{hi:.4g} in SI); {hint}"
    )


#: Speed of sound, m/s, from -70 degC to +45 degC: true airspeed / Mach must fall in here.
SPEED_OF_SOUND_MPS = (260.0, 360.0)


def check_tas_against_mach(tas_si: np.ndarray, mach: np.ndarray, unit: str, label: str,
                           where: Where) -> None:
    """True airspeed over Mach is the speed of sound: a cross-check of the airspeed unit.

    Used where Mach is recorded and above 0.1 (below, the ratio is too noisy to say anything).
    """
    ok = mach > 0.1
    if not np.any(ok):
        return
    a = float(np.median(tas_si[ok] / mach[ok]))
    lo, hi = SPEED_OF_SOUND_MPS
    if lo <= a <= hi:
        return
    raw = from_si(tas_si, unit, label)
    cands = [u for u in units_of("speed") if u != unit
             and lo <= float(np.median(to_si(raw[ok], u, u) / mach[ok])) <= hi]
    hint = (f"the values look like {cands[0]}: set unit = \"{cands[0]}\" for it under [columns]" if cands
            else "check the column and its declared unit, and the Mach column")
    raise DataError(
        f"{where}: {label} is declared in {unit!r}, but true airspeed / Mach has a median of "
        f"{a:.4g} m/s, which is not a speed of sound ({lo:.0f} to {hi:.0f} m/s); {hint}"
    )
