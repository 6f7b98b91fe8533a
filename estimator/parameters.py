"""Parameters as data: name, unit, value, free or fixed, scope, bounds.

A :class:`ParameterSpec` declares a family (``b_l``, scope ``aircraft``; ``f1``, a table with one
value per breakpoint; ``u0``, scope ``maneuver``). Given the maneuvers of a problem, a
:class:`ParameterSet` expands the families into scalar :class:`Parameter` instances with unique
keys — ``b_l[PV1]``, ``f1[3]``, ``u0[m0007]``, ``tau_dru`` — and only the solver flattens the free
ones into a vector.

Scopes: ``global`` (one value), ``aircraft`` (one per aircraft id), ``configuration`` (one per
fleet configuration), ``recorder`` (one per recorder name the channel declares), ``maneuver`` (one
per maneuver). Per-maneuver parameters touch only their own maneuver's data; the solver
eliminates them block by block so one iteration costs time linear in the number of maneuvers.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Protocol

import numpy as np

SCOPES = ("global", "aircraft", "configuration", "recorder", "maneuver")
#: What a parameter is, for reports and for the identifiability checks.
KINDS = ("initial_condition", "imu_bias", "time_delay", "bias", "scale", "table", "other")
#: The kinds that describe a maneuver's flight (its state equations), not the calibration: a
#: parameter of any other kind is a calibration parameter (Table 2's calibration uncertainty)
FLIGHT_KINDS = frozenset({"initial_condition", "imu_bias"})


class ManeuverLike(Protocol):
    """What a scope's instance is read from: a maneuver's ids (:class:`estimator.problem.ManeuverData`,
    named by what it has: :mod:`estimator.problem` builds on this module)."""

    @property
    def id(self) -> str: ...

    @property
    def aircraft(self) -> str: ...

    @property
    def configuration(self) -> str: ...


class ChannelLike(Protocol):
    """What a recorder-scoped instance is read from: a channel's recorder
    (:class:`estimator.problem.ChannelSpec`)."""

    @property
    def recorder(self) -> str: ...


@dataclass(frozen=True)
class ParameterSpec:
    """A declared parameter family.

    Attributes
    ----------
    name : base name used in channel models (``b_l``, ``f1``, ``tau_vane``).
    unit : SI unit of the value ("rad", "s", "m/s^2", "rad/s", "m/s", "m", "1").
    value : start value (SI); for tables one value per breakpoint, or one number for all.
    free : estimated (True) or held at ``value`` (False).
    scope : one of :data:`SCOPES`.
    bounds : (low, high) in SI; ``-inf``/``inf`` for none.
    kind : one of :data:`KINDS`.
    breakpoints : for tables, the breakpoints (SI units of the table's argument).
    per_instance : start values or fixed values for particular instances (scope key -> value).
    free_instances : free/fixed status of particular instances, overriding ``free``.
    fixed_elements : table elements held at their value even when the table is free.
    display_scale, display_unit : how reports show it (e.g. 57.2958, "deg").
    """

    name: str
    unit: str
    value: float | Sequence[float] = 0.0
    free: bool = True
    scope: str = "global"
    bounds: tuple[float, float] = (-math.inf, math.inf)
    kind: str = "other"
    breakpoints: tuple[float, ...] | None = None
    per_instance: Mapping[str, float | Sequence[float]] = field(default_factory=dict)
    free_instances: Mapping[str, bool] = field(default_factory=dict)
    fixed_elements: tuple[int, ...] = ()
    display_scale: float = 1.0
    display_unit: str = ""

    def __post_init__(self) -> None:
        # immutable like the rest of the dataclass: sequences become tuples, mappings read-only
        # views of copies (a caller's list or dict changed later changes nothing here)
        def frozen(v, what: str):
            try:
                return float(v) if np.ndim(v) == 0 else tuple(float(x) for x in np.ravel(v))
            except (TypeError, ValueError):
                raise ValueError(f"parameter {self.name}: {what} {v!r} is not a number or a list of "
                                 f"numbers") from None

        object.__setattr__(self, "value", frozen(self.value, "value"))
        bounds = frozen(self.bounds, "bounds")
        if not isinstance(bounds, tuple) or len(bounds) != 2:
            raise ValueError(f"parameter {self.name}: bounds {self.bounds!r} must be (low, high)")
        object.__setattr__(self, "bounds", bounds)
        if self.breakpoints is not None:
            object.__setattr__(self, "breakpoints", tuple(frozen(self.breakpoints, "breakpoints")))
        object.__setattr__(self, "fixed_elements", tuple(int(k) for k in self.fixed_elements))
        object.__setattr__(self, "per_instance", MappingProxyType(
            {k: frozen(v, f"value of {k}") for k, v in dict(self.per_instance).items()}))
        object.__setattr__(self, "free_instances",
                           MappingProxyType({k: bool(v) for k, v in dict(self.free_instances).items()}))
        if self.scope not in SCOPES:
            raise ValueError(f"parameter {self.name}: scope {self.scope!r} is not one of {SCOPES}")
        if self.kind not in KINDS:
            raise ValueError(f"parameter {self.name}: kind {self.kind!r} is not one of {KINDS}")
        lo, hi = self.bounds
        if not lo < hi:
            raise ValueError(f"parameter {self.name}: bounds {self.bounds} are empty; need low < high")
        if self.breakpoints is not None:
            bp = np.asarray(self.breakpoints, dtype=float)
            if bp.ndim != 1 or bp.size < 2 or np.any(np.diff(bp) <= 0):
                raise ValueError(f"table {self.name}: breakpoints must increase strictly, got {bp}")
        if not self.display_unit:
            object.__setattr__(self, "display_unit", self.unit)

    @property
    def size(self) -> int:
        return 1 if self.breakpoints is None else len(self.breakpoints)

    def start_values(self, instance: str) -> np.ndarray:
        raw = self.per_instance.get(instance, self.value)
        vals = np.broadcast_to(np.asarray(raw, dtype=float), (self.size,)).copy()
        lo, hi = self.bounds
        if np.any(vals < lo) or np.any(vals > hi):
            raise ValueError(
                f"parameter {self.name}{'[' + instance + ']' if instance else ''}: start value "
                f"{vals} outside its bounds {self.bounds}; move the start value or widen the bounds"
            )
        return vals


@dataclass(frozen=True)
class Parameter:
    """One scalar unknown.

    Attributes
    ----------
    key : unique key: ``name``, ``name[instance]``, ``name[k]`` or ``name[instance][k]``.
    name : family name.
    instance : scope instance ("" for global).
    element : table element index, or None.
    """

    key: str
    name: str
    instance: str
    element: int | None
    unit: str
    value: float
    free: bool
    scope: str
    bounds: tuple[float, float]
    kind: str
    display_scale: float = 1.0
    display_unit: str = ""


def make_key(name: str, instance: str = "", element: int | None = None) -> str:
    key = name + (f"[{instance}]" if instance else "")
    return key + (f"[{element}]" if element is not None else "")


def family_of(key: str) -> str:
    """The family (parameter name) of a key made by :func:`make_key`: ``b_l[PT1]`` -> ``b_l``."""
    return key.split("[", 1)[0]


def instance_of(scope: str, maneuver: ManeuverLike, channel: ChannelLike | None = None) -> str:
    """The instance of a ``scope`` family that a maneuver's data (through ``channel``) use.

    ``global``: "" (one value); ``aircraft``, ``configuration``: the maneuver's aircraft or
    configuration id; ``maneuver``: its id; ``recorder``: the channel's recorder ("" without a
    channel).
    """
    return {
        "global": "",
        "aircraft": maneuver.aircraft,
        "configuration": maneuver.configuration,
        "maneuver": maneuver.id,
        "recorder": channel.recorder if channel is not None else "",
    }[scope]


@dataclass(frozen=True)
class ParameterSet:
    """An ordered, immutable set of scalar parameters, looked up by key."""

    parameters: tuple[Parameter, ...]
    specs: Mapping[str, ParameterSpec]

    def __post_init__(self) -> None:
        keys = [p.key for p in self.parameters]
        if len(set(keys)) != len(keys):
            dup = sorted({k for k in keys if keys.count(k) > 1})
            raise ValueError(f"duplicate parameter keys {dup[:5]}")
        object.__setattr__(self, "parameters", tuple(self.parameters))
        object.__setattr__(self, "specs", MappingProxyType(dict(self.specs)))
        object.__setattr__(self, "_index", {k: i for i, k in enumerate(keys)})

    @classmethod
    def expand(cls, specs: Iterable[ParameterSpec], instances: Mapping[str, Sequence[str]]) -> ParameterSet:
        """Expand families into scalars.

        Parameters
        ----------
        specs : the declared families.
        instances : scope -> the instance ids present in the problem (e.g. ``"aircraft"`` ->
            ``["PV1", "PT1"]``); ``global`` needs none.
        """
        params: list[Parameter] = []
        spec_map: dict[str, ParameterSpec] = {}
        for spec in specs:
            if spec.name in spec_map:
                raise ValueError(f"parameter {spec.name} declared twice")
            spec_map[spec.name] = spec
            insts = [""] if spec.scope == "global" else list(instances.get(spec.scope, []))
            unknown = set(spec.per_instance) - set(insts) - {""}
            if unknown:
                raise ValueError(
                    f"parameter {spec.name}: values given for {sorted(unknown)}, which are not "
                    f"{spec.scope} instances of this problem ({insts})"
                )
            for inst in insts:
                vals = spec.start_values(inst)
                free = spec.free_instances.get(inst, spec.free)
                for k, v in enumerate(vals):
                    el = None if spec.breakpoints is None else k
                    params.append(Parameter(
                        key=make_key(spec.name, inst, el), name=spec.name, instance=inst, element=el,
                        unit=spec.unit, value=float(v),
                        free=bool(free) and k not in spec.fixed_elements, scope=spec.scope,
                        bounds=spec.bounds, kind=spec.kind, display_scale=spec.display_scale,
                        display_unit=spec.display_unit,
                    ))
        return cls(tuple(params), spec_map)

    def __len__(self) -> int:
        return len(self.parameters)

    def __iter__(self):
        return iter(self.parameters)

    def index(self, key: str) -> int:
        try:
            return self._index[key]  # type: ignore[attr-defined]
        except KeyError:
            raise KeyError(f"no parameter {key!r}") from None

    def __getitem__(self, key: str) -> Parameter:
        return self.parameters[self.index(key)]

    def key_of(self, name: str, maneuver: ManeuverLike, channel: ChannelLike | None = None,
               element: int | None = None) -> str:
        """The key of family ``name``'s scalar that ``maneuver`` (through ``channel``) uses.

        Parameters
        ----------
        name : the family (``b_l``, ``f1``, ``u0``).
        maneuver : the maneuver whose data the value serves (its id, aircraft, configuration).
        channel : the channel, for recorder-scoped families (its recorder).
        element : the table element, for tables.

        Examples
        --------
        ``b_l`` (per aircraft) in a PV1 maneuver: ``b_l[PV1]``; ``f1`` element 3: ``f1[3]``.
        """
        try:
            spec = self.specs[name]
        except KeyError:
            raise KeyError(f"no parameter family {name!r}; declared: {sorted(self.specs)}") from None
        return make_key(name, instance_of(spec.scope, maneuver, channel), element)

    def __contains__(self, key: str) -> bool:
        return key in self._index  # type: ignore[attr-defined]

    @property
    def keys(self) -> list[str]:
        return [p.key for p in self.parameters]

    @property
    def values(self) -> np.ndarray:
        return np.array([p.value for p in self.parameters])

    @property
    def free_mask(self) -> np.ndarray:
        return np.array([p.free for p in self.parameters], dtype=bool)

    def with_values(self, values: np.ndarray | Mapping[str, float]) -> ParameterSet:
        """A copy with new values (full vector in set order, or a key -> value mapping)."""
        if isinstance(values, Mapping):
            new = list(self.parameters)
            for k, v in values.items():
                i = self.index(k)
                new[i] = replace(new[i], value=float(v))
        else:
            values = np.asarray(values, dtype=float)
            if values.shape != (len(self),):
                raise ValueError(f"expected {len(self)} values, got {values.shape}")
            new = [replace(p, value=float(v)) for p, v in zip(self.parameters, values, strict=True)]
        return ParameterSet(tuple(new), self.specs)

    def with_free(self, free: Mapping[str, bool]) -> ParameterSet:
        """A copy with some parameters freed or fixed, by key or by family name."""
        new = []
        for p in self.parameters:
            f = free.get(p.key, free.get(p.name, p.free))
            new.append(replace(p, free=bool(f)))
        return ParameterSet(tuple(new), self.specs)
