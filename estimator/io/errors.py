"""Error and warning types of the data import, and how messages name where a problem is.

Every message of :mod:`estimator.io` starts with the place (problem file or data file, maneuver,
its time range, the channel and its source column) and ends with how to fix it.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

# one definition of the close match, shared with every TOML format (re-exported here for the io modules)
from aircraft_models.schema import close_match

__all__ = ["DataError", "DataWarning", "Where", "at_row", "close_match", "warn"]


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
