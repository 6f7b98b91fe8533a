"""Unit cross-check of the Euler angles against the body rates (Euler kinematics).

The measured Euler angles must change as the IMU's body rates say::

    phi'   = p + (q sin(phi) + r cos(phi)) tan(theta)
    theta' = q cos(phi) - r sin(phi)
    psi'   = (q sin(phi) + r cos(phi)) / cos(theta)

For each angle whose kinematic rate or whose own rate of change varies enough
(:data:`MIN_RATE_STD_RPS`: either is excitation; rates in rad/s declared deg/s make the kinematic
rate 57 times too small to pass that gate alone, while the angles still move), the slope of a
straight-line fit (with offset, which absorbs gyro biases) of the angle's smoothed time derivative
against the smoothed kinematic rate must be near 1. A slope near 57.3 or 1/57.3 is a
degree/radian mistake: of that angle if one angle is off, of the rates if every tested angle is
off the same way, or if the angle's declared unit cannot be wrong that way (an angle declared in
degrees that changes 57 times faster than the rates say is not in radians: the rates, declared in
deg/s, are in rad/s). This catches what range checks cannot: small angles in degrees declared rad,
an unwrapped heading, rates in deg/s declared rad/s and rates in rad/s declared deg/s (a pitch
doublet, whose bank and heading hardly move, tests the pitch angle alone). Fits with poor
correlation (little excitation, noise, recorder delays) decide nothing.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from estimator.io.errors import DataError, Where

#: Angles are checked only if the kinematic rate's standard deviation exceeds this, rad/s.
MIN_RATE_STD_RPS = 0.02
#: ... and only if the derivative and the kinematic rate correlate at least this well.
MIN_CORRELATION = 0.8
#: Slopes within [1/SLOPE_TOLERANCE, SLOPE_TOLERANCE] pass.
SLOPE_TOLERANCE = 2.0
_SMOOTH_S = 0.25
_DEG = 180.0 / math.pi


def _smooth(x: np.ndarray, n: int) -> np.ndarray:
    if n <= 1:
        return x
    return np.convolve(np.pad(x, (n // 2, n - 1 - n // 2), mode="edge"), np.ones(n) / n, mode="valid")


def euler_slopes(si: Mapping[str, np.ndarray], t_s: np.ndarray) -> dict[str, float]:
    """Angle name -> slope of d(angle)/dt against its kinematic rate, for the angles that can tell."""
    if not all(k in si for k in ("phi", "theta")):
        return {}
    p, q, r = si["p"], si["q"], si["r"]
    phi, theta = si["phi"], si["theta"]
    n = max(1, int(round(_SMOOTH_S / float(np.median(np.diff(t_s))))))
    kin = {
        "phi": p + (q * np.sin(phi) + r * np.cos(phi)) * np.tan(theta),
        "theta": q * np.cos(phi) - r * np.sin(phi),
        "psi": (q * np.sin(phi) + r * np.cos(phi)) / np.cos(theta),
    }
    out = {}
    for name, rate in kin.items():
        if name not in si or len(t_s) < 4 * n:
            continue
        y = _smooth(rate, n)
        x = _smooth(np.gradient(np.unwrap(si[name]), t_s), n)
        # excited if either moves: rates in rad/s declared deg/s shrink y 57 times, not x
        if max(np.std(y), np.std(x)) < MIN_RATE_STD_RPS or np.std(x) == 0 or np.std(y) == 0:
            continue
        if not np.corrcoef(x, y)[0, 1] >= MIN_CORRELATION:  # NaN decides nothing either
            continue
        out[name] = float(np.polyfit(y, x, 1)[0])
    return out


def _deg_rad_guess(slope: float) -> str | None:
    """"x57" if ``slope`` is near 57.3, "/57" if near 1/57.3, else None."""
    if abs(math.log(abs(slope) / _DEG)) < 0.5:
        return "x57"
    if abs(math.log(abs(slope) * _DEG)) < 0.5:
        return "/57"
    return None


def _angle_can_be(unit: str, guess: str | None) -> bool:
    """Can an angle declared in ``unit`` be off by the factor ``guess`` ("x57": changes 57 times
    faster than the rates say, so it would be in degrees declared as radians; "/57": in radians
    declared as degrees)? None (no degree/radian factor): it may be anything."""
    if guess is None:
        return True
    return unit == ("rad" if guess == "x57" else "deg")


def check_euler_rates(si: Mapping[str, np.ndarray], t_s: np.ndarray, units: Mapping[str, str],
                      labels: Mapping[str, str], where: Where) -> None:
    """Raise :class:`DataError` if an angle or the rates are off by a degree/radian factor."""
    slopes = euler_slopes(si, t_s)
    bad = {k: s for k, s in slopes.items() if not 1 / SLOPE_TOLERANCE <= s <= SLOPE_TOLERANCE}
    if not bad:
        return
    rates = ", ".join(labels[c] for c in ("p", "q", "r"))
    rate_units = sorted({units[c] for c in ("p", "q", "r")})
    text = "; ".join(f"{labels[k]} changes {s:.3g} times as fast as the body rates say"
                     for k, s in bad.items())
    guesses = {k: _deg_rad_guess(s) for k, s in bad.items()}
    if len(bad) == len(slopes) and len(set(guesses.values())) == 1 and (
            len(bad) > 1 or not _angle_can_be(units[next(iter(bad))], next(iter(guesses.values())))):
        g = next(iter(guesses.values()))
        one = next(iter(bad))
        why = ("every tested Euler angle disagrees the same way" if len(bad) > 1 else
               f"{labels[one]} is declared in {units[one]!r}, and no angle unit is {_DEG:.4g} times "
               f"{'smaller' if g == 'x57' else 'larger'} than that")
        hint = f"{why}, so the body rates are likely in the wrong unit: {rates} are declared in {rate_units}"
        if g is not None:
            real = "deg/s" if g == "/57" else "rad/s"
            hint += (f" but look like {real} (x {_DEG:.4g} too {'large' if real == 'deg/s' else 'small'} "
                     f"as read): declare unit = \"{real}\" for p, q and r")
    else:
        parts = []
        for k, g in guesses.items():
            if g is None:
                parts.append(f"check the column and unit of {k}")
            else:
                like = "deg" if g == "x57" else "rad"
                parts.append(f"{k} is declared in {units[k]!r} but looks like {like}")
        hint = "; ".join(parts) + f" (unless the rates {rates}, declared in {rate_units}, are wrong)"
    raise DataError(
        f"{where}: the Euler angles disagree with the body rates (Euler kinematics): {text}; {hint}; "
        "fix the unit under [columns]"
    )
