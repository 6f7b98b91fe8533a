"""Error and warning types of the data import, and how messages name where a problem is.

Every message of :mod:`estimator.io` starts with the place (problem file or data file, maneuver,
its time range, the channel and its source column) and ends with how to fix it.
"""

from __future__ import annotations

import difflib
import warnings
from collections.abc import Iterable
from dataclasses import dataclass


class DataError(ValueError):
    """Bad input: a problem file or flight data that cannot be used as given.

    The message names the file, the maneuver and its time range, the channel and its source
    column, the time (and data row) where the problem is, and says how to fix it.
    """


class DataWarning(UserWarning):
    """Something non-fatal was dropped or adjusted on import; the message says what and why."""


def warn(message: str) -> None:
    """Issue a :class:`DataWarning` attributed to the caller of the public function."""
    warnings.warn(message, DataWarning, stacklevel=4)


@dataclass(frozen=True)
class Where:
    """The place in the input a message is about.

    Attributes
    ----------
    file : data file (or dataset maneuver file) the values come from.
    maneuver : maneuver id, or None for a whole file.
    t_range_s : the maneuver's requested time range, s, or None for the whole file.
    """

    file: str
    maneuver: str | None = None
    t_range_s: tuple[float, float] | None = None

    def __str__(self) -> str:
        text = self.file
        if self.maneuver is not None:
            text += f", maneuver {self.maneuver}"
        if self.t_range_s is not None:
            text += f" (t = {self.t_range_s[0]:.3f} to {self.t_range_s[1]:.3f} s)"
        return text


def at_row(t_s: float, row: int) -> str:
    """``"at t = 12.345 s (data row 493)"``: rows count from 0 after the header line."""
    return f"at t = {t_s:.3f} s (data row {row})"


def close_match(name: str, valid: Iterable[str]) -> str | None:
    """The valid name a misspelt one was most likely meant to be, or None.

    :func:`difflib.get_close_matches`, ties broken in favour of a name with the same letters
    (``alpha_lz`` is ``alpha_zl`` with two letters swapped, not ``alpha_zr``).
    """
    name = str(name)
    cands = difflib.get_close_matches(name, [str(v) for v in valid], n=5, cutoff=0.6)
    if not cands:
        return None
    return max(cands, key=lambda c: (round(difflib.SequenceMatcher(None, name, c).ratio(), 9),
                                     sorted(c) == sorted(name)))
