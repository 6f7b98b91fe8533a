"""Channel and parameter declarations from TOML: the model-set format.

A model set (``estimator/models/tejas.toml`` is the default, the paper's Table 1) declares
``[[channel]]`` entries and ``[parameter.NAME]`` tables::

    [[channel]]
    name = "alpha_zl"              # canonical channel name = the data column it is compared with
    sensor = "vane_left"           # position from the problem's [sensors]
    model = "f1(alpha_s) - f2(alpha_t) * beta_s + b_l"
    delay = "tau_alpha_zl"         # parameter of its time shift, or omit
    measures = "alpha_s"           # the flow signal it measures (its calibrated value); needed
                                   # when the model uses several (default: the only one)
    recorder = "dru"               # default "dru"
    unit = "rad"                   # default "rad"

    [parameter.b_l]
    unit = "rad"                   # SI unit of the value
    kind = "bias"                  # initial_condition | imu_bias | time_delay | bias | scale | table | other
    scope = "aircraft"             # global | aircraft | configuration | recorder | maneuver
    value_deg = 0.0                # start value (value = ... in SI)
    bounds_deg = [-5.0, 5.0]
    free = true
    [parameter.f1]
    kind = "table"
    breakpoints_deg = [-8.0, 0.0, 8.0, 16.0]
    value = "breakpoints"          # start at the identity, or a number, or one number per breakpoint
    fixed_elements = [1]

Keys ending in ``_deg`` are degrees (for a "rad/s" parameter, deg/s) and are converted here;
``values_deg`` / ``values`` may give one value per instance (``{PV1 = 0.2}``).
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from pathlib import Path

from estimator.parameters import KINDS, SCOPES, ParameterSpec
from estimator.problem import ChannelSpec

MODELS_DIR = Path(__file__).resolve().parent / "models"
_CHANNEL_KEYS = {"name", "column", "model", "sensor", "delay", "recorder", "unit", "measures"}
_PARAM_KEYS = {
    "unit", "kind", "scope", "value", "value_deg", "bounds", "bounds_deg", "free", "breakpoints",
    "breakpoints_deg", "fixed_elements", "values", "values_deg", "free_instances",
}
_DISPLAY = {"rad": (180.0 / math.pi, "deg"), "rad/s": (180.0 / math.pi, "deg/s"), "s": (1000.0, "ms")}


def _deg(d: Mapping, key: str, where: str, default=None):
    """Read ``key`` (SI) or ``key_deg`` (converted); not both."""
    if key in d and f"{key}_deg" in d:
        raise ValueError(f"{where}: give {key} or {key}_deg, not both")
    if f"{key}_deg" in d:
        v = d[f"{key}_deg"]
        if isinstance(v, Mapping):
            return {k: _scale(x, math.pi / 180.0) for k, x in v.items()}
        return _scale(v, math.pi / 180.0)
    return d.get(key, default)


def _scale(v, f):
    if isinstance(v, (list, tuple)):
        return [x * f for x in v]
    return v * f


def parse_channel(d: Mapping, where: str) -> ChannelSpec:
    unknown = set(d) - _CHANNEL_KEYS
    if unknown:
        raise ValueError(f"{where}: unknown keys {sorted(unknown)}; valid: {sorted(_CHANNEL_KEYS)}")
    if "name" not in d or "model" not in d:
        raise ValueError(f"{where}: a channel needs name and model")
    unit = d.get("unit", "rad")
    scale, dunit = _DISPLAY.get(unit, (1.0, unit))
    return ChannelSpec(
        name=d["name"], column=d.get("column", d["name"]), model=d["model"], sensor=d.get("sensor"),
        delay=d.get("delay"), recorder=d.get("recorder", "dru"), unit=unit, display_scale=scale,
        display_unit=dunit, measures=d.get("measures"),
    )


def parse_parameter(name: str, d: Mapping, where: str) -> ParameterSpec:
    unknown = set(d) - _PARAM_KEYS
    if unknown:
        raise ValueError(f"{where}: unknown keys {sorted(unknown)}; valid: {sorted(_PARAM_KEYS)}")
    unit = d.get("unit", "1")
    kind = d.get("kind", "other")
    scope = d.get("scope", "global")
    if kind not in KINDS or scope not in SCOPES:
        raise ValueError(f"{where}: kind must be one of {KINDS} and scope one of {SCOPES}")
    breakpoints = _deg(d, "breakpoints", where)
    value = _deg(d, "value", where, 0.0)
    if value == "breakpoints":
        if breakpoints is None:
            raise ValueError(f"{where}: value = 'breakpoints' needs breakpoints")
        value = list(breakpoints)
    bounds = _deg(d, "bounds", where, [-math.inf, math.inf])
    per_instance = _deg(d, "values", where, {}) or {}
    scale, dunit = _DISPLAY.get(unit, (1.0, unit))
    try:
        return ParameterSpec(
            name=name, unit=unit, value=value, free=bool(d.get("free", True)), scope=scope,
            bounds=(float(bounds[0]), float(bounds[1])), kind=kind,
            breakpoints=tuple(breakpoints) if breakpoints is not None else None,
            per_instance=dict(per_instance), free_instances=dict(d.get("free_instances", {})),
            fixed_elements=tuple(int(i) for i in d.get("fixed_elements", ())),
            display_scale=scale, display_unit=dunit,
        )
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None


def parse_model_set(raw: Mapping, source: str) -> tuple[list[ChannelSpec], list[ParameterSpec]]:
    channels = [parse_channel(c, f"{source}: channel[{i}]") for i, c in enumerate(raw.get("channel", []))]
    params = [parse_parameter(n, p, f"{source}: parameter.{n}") for n, p in raw.get("parameter", {}).items()]
    return channels, params


def load_model_set(name_or_path: str | Path = "tejas") -> tuple[list[ChannelSpec], list[ParameterSpec]]:
    """Read a model set: a shipped name (``"tejas"``) or a TOML path."""
    p = Path(name_or_path)
    if not p.is_file() and len(p.parts) == 1 and not p.suffix:  # a shipped name, never a bad path
        p = MODELS_DIR / f"{p.name}.toml"
    if not p.is_file():
        shipped = sorted(q.stem for q in MODELS_DIR.glob("*.toml"))
        raise FileNotFoundError(f"{name_or_path}: no such model set (shipped: {shipped})")
    with open(p, "rb") as fh:
        raw = tomllib.load(fh)
    return parse_model_set(raw, str(p))
