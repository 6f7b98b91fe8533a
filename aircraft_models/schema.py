"""The keys of a TOML table, declared once and checked in one place.

Every TOML format of the project (problem file, model set, dataset selection, campaign and its
environment and maneuver tables, errors block, Monte Carlo scenario, fleet, airframe and
local-flow files) declares each table's keys (:func:`field_keys` derives them from a dataclass)
and checks the table with :func:`check`:

- an unknown key is an error naming the table (``where``), the key, its close match ("did you
  mean ...?") and the valid keys;
- a value of the wrong type is an error naming the key, the type expected and the value given;
- a key declared with a unit is accepted with that unit's other suffixes (``_deg`` for ``_rad``,
  ``_in``/``_ft`` for ``_m``, ...) and its value converted to SI.

The caller passes the exception class its format raises (``DataError``, ``CampaignError``,
``ValueError``). Standard library only, importing nothing of the project: ``estimator``, ``synth``
and ``campaigns`` all use it (tests/test_boundaries.py).

Example
-------
>>> check({"r_cg_in": [10.0, 0.0, 0.0], "id": "PV1"}, {"id": Key(str, required=True),
...        "r_cg_m": Key(list, unit="m")}, "fleet.toml: aircraft[0]")
{'r_cg_m': [0.254, 0.0, 0.0], 'id': 'PV1'}
"""

from __future__ import annotations

import difflib
import math
import numbers
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, fields
from typing import Any

#: SI unit -> the suffixes a key in that unit may carry and each one's factor to SI (SI first)
SUFFIXES: dict[str, tuple[tuple[str, float], ...]] = {
    "rad": (("_rad", 1.0), ("_deg", math.pi / 180.0)),
    "rad/s": (("_rps", 1.0), ("_deg_s", math.pi / 180.0)),
    "rad/rad": (("_rad_per_rad", 1.0), ("_deg_per_deg", 1.0)),
    "m": (("_m", 1.0), ("_in", 0.0254), ("_ft", 0.3048)),
    "s": (("_s", 1.0), ("_ms", 1e-3)),
}
_ABSENT = object()
_TYPE_WORDS = {bool: "true or false", str: "a string (in quotes)", int: "a whole number",
               float: "a number", list: "a list [...]", Mapping: "a table", dict: "a table"}


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


def did_you_mean(name: str, valid: Iterable[str]) -> str:
    """``" (did you mean 'x'?)"`` with the close match of ``name``, or ``""`` if there is none."""
    m = close_match(name, valid)
    return f" (did you mean {m!r}?)" if m is not None else ""


def unknown(names: Iterable[str], valid: Iterable[str], where: str, error: type[Exception] = ValueError,
            what: str = "key") -> Exception:
    """The error (to raise) for ``names`` not among ``valid``: the place (none if ``where`` is
    empty), each name with its close match, and the valid names in their declared order."""
    names, valid = [str(n) for n in names], [str(v) for v in valid]
    hints = ", ".join(f"{n!r}{did_you_mean(n, valid)}" for n in names)
    return error(f"{where}{': ' if where else ''}unknown {what}{'s' if len(names) > 1 else ''} {hints}; "
                 f"valid: {', '.join(valid)}")


@dataclass(frozen=True)
class Key:
    """One declared key of a table.

    Attributes
    ----------
    type : the type(s) its value must have (``float`` accepts whole numbers; ``bool`` is no
        number); None: any.
    required : the table must give it.
    default : filled in when the table does not give it (unless required); absent: left out.
    unit : its SI unit, a key of :data:`SUFFIXES`: the key may then carry that unit's other
        suffixes (a name ending in the SI suffix, ``noise_rad``, is also ``noise_deg``; a bare
        name, ``value``, also ``value_deg``), the value (a number, or a list or table of them) is
        converted to SI and returned under the declared name.
    """

    type: type | tuple[type, ...] | None = None
    required: bool = False
    default: Any = _ABSENT
    unit: str | None = None

    def spellings(self, name: str) -> dict[str, float]:
        """Each accepted spelling of the key ``name`` and its factor to SI."""
        if self.unit is None:
            return {name: 1.0}
        (si, _), *others = SUFFIXES[self.unit]
        stem = name[: -len(si)] if name.endswith(si) else name
        return {name: 1.0, **{stem + suffix: f for suffix, f in others}}


def field_keys(cls: type, required: Iterable[str] = (), units: Iterable[str] = ()) -> dict[str, Key]:
    """The keys of a table that builds the dataclass ``cls``: one per field, untyped (the
    dataclass checks its values), those in ``required`` required; a field named with the SI
    suffix of one of ``units`` (keys of :data:`SUFFIXES`; ``heading_rad`` for ``"rad"``) is
    declared in that unit, so its other suffixes are accepted too (``heading_deg``)."""
    required = set(required)
    si = {SUFFIXES[u][0][0]: u for u in units}
    return {f.name: Key(required=f.name in required,
                        unit=next((u for s, u in si.items() if f.name.endswith(s)), None))
            for f in fields(cls)}


def _scale(value: Any, factor: float, where: str, key: str, error: type[Exception]) -> Any:
    if isinstance(value, (list, tuple)):
        return [_scale(v, factor, where, key, error) for v in value]
    if isinstance(value, Mapping):
        return {k: _scale(v, factor, where, key, error) for k, v in value.items()}
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise error(f"{where}: {key} = {value!r} must be a number (or a list or table of numbers)")
    return value * factor


def _is(value: Any, types: type | tuple[type, ...]) -> bool:
    types = types if isinstance(types, tuple) else (types,)
    if isinstance(value, bool):
        return bool in types
    return isinstance(value, types) or (float in types and isinstance(value, int))


def check(table: Any, keys: Mapping[str, Key] | Iterable[str], where: str,
          error: type[Exception] = ValueError, what: str = "key") -> dict[str, Any]:
    """``table`` checked against its declared ``keys`` (a name -> :class:`Key` mapping, or names).

    Returns
    -------
    dict
        The table by declared name: unit suffixes converted to SI, defaults filled in.

    Raises
    ------
    error
        ``table`` is no table; an unknown key (with the close match and the valid keys); a key
        given twice (in two units); a value of the wrong type; a required key missing.
    """
    keys = dict(keys) if isinstance(keys, Mapping) else {k: Key() for k in keys}
    if not isinstance(table, Mapping):
        raise error(f"{where}: must be a table of keys ({', '.join(keys)}), got {table!r}")
    spelling = {s: (name, f) for name, key in keys.items() for s, f in key.spellings(name).items()}
    bad = [k for k in table if k not in spelling]
    if bad:
        raise unknown(bad, spelling, where, error, what)
    out: dict[str, Any] = {}
    given: dict[str, str] = {}
    for k, value in table.items():
        name, factor = spelling[k]
        if name in given:
            raise error(f"{where}: {name} given twice (as {given[name]} and {k}); keep one")
        given[name] = k
        key = keys[name]
        if key.type is not None and not _is(value, key.type):
            types = key.type if isinstance(key.type, tuple) else (key.type,)
            expected = " or ".join(_TYPE_WORDS.get(t, t.__name__) for t in types)
            raise error(f"{where}: {k} = {value!r} must be {expected}, got {type(value).__name__}")
        out[name] = value if factor == 1.0 else _scale(value, factor, where, k, error)
    for name, key in keys.items():
        if name not in out and key.required:
            raise error(f"{where}: missing key {name!r}")
        if name not in out and key.default is not _ABSENT:
            out[name] = key.default
    return out
