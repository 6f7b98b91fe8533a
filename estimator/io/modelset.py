"""Model sets: the channel models and parameters of an aircraft, from TOML, fitted to a problem.

One module for the model-set format, from the file to the problem's parameters:

- :func:`read_model_set` finds a model set (a shipped name or a path) and reads its TOML;
  :func:`parse_model_set` turns it into channels and parameter specs; :func:`load_model_set`
  does both;
- :func:`merge_model_set`: a shipped or user model set, with ``[parameter.NAME]`` overrides
  merged key by key into the model set's declaration and ``[[channel]]`` entries added (or
  replacing the model set's channel of the same name);
- :func:`finalize_parameters`: drops parameter families no selected channel uses, fixes scope
  instances that have no data (a bias of an aircraft whose sensor it belongs to was not fitted),
  and sets the per-maneuver initial conditions' start values from the data;
- :func:`check_maneuver_lengths`: maneuvers too short for their per-maneuver parameters.

The format
----------

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

Everything else particular to the aircraft is declared beside them (:class:`Declarations`;
optional, each name checked against the model set's channels and parameters)::

    [requirements]                 # Table 2: a row per channel, its desired 3-sigma accuracy
    alpha_zl = { sensor = "vane AOA left", desired_3sigma_deg = 0.5 }
    beta_znp = { sensor = "nose-probe AOSS (low AOA)", desired_3sigma_deg = 0.5, low_alpha_only = true }

    [workflow]                     # the fleet workflow (estimator.workflow)
    reference_mach = 0.5           # the bin whose installation biases hold for every bin
    apportion_biases = { left = "b_l", right = "b_r" }   # label = aircraft-scoped bias family
    correction_model = ["f1", "f2"]    # global families re-estimated with those biases held
    identity_table = "f1"          # starts at the identity; takes the fleet-mean bias
    alpha_limit_channel = "beta_znp"   # its error growth sets the usable alpha (low_alpha_only)

    [initial_conditions]           # the data the start values come from
    tas = "tas"                    # and phi, theta, psi, h (default: those names)
    alpha = ["alpha_zl", "alpha_zr"]   # the first a maneuver has (none: 0)
    beta = ["beta_zsp"]

    [report]                       # the channels of the report's figures
    crossplots = ["alpha_zl"]      # measurement - model vs model (paper Fig. 5)
    truth_crossplots = ["alpha_zl"]    # calibrated - true (synthetic data)
    time_history = ["theta", "tas", "alpha_zl"]   # measured vs model (paper Fig. 3)

    [plausible]                    # the aircraft's ranges for the import's unit checks, where the
    tas = { range = [5.0, 60.0], unit = "m/s" }   # built-in ones (a fighter's) are not its own:
                                   # the median's range (airspeed, height, Mach), the largest
                                   # |value|'s (angles, rates: max(|low|, |high|)); accel: the
                                   # specific force's magnitude. The problem file's [plausible] wins
    [sensor_midpoints]             # a sensor without a position of its own is the mean of these
    side_probe = ["side_probe_left", "side_probe_right"]   # (a pair of probes read as one sensor)

The channels read from a model set carry these (:class:`DeclaredChannel`), so that a problem
built from it tells the workflow and its report what to show (:func:`declarations_of`).
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

import numpy as np

from aircraft_models.schema import Key, check, did_you_mean
from estimator.declarations import Declarations, InitialConditionSources, Requirement
from estimator.io.errors import DataError, warn
from estimator.parameters import KINDS, SCOPES, ParameterSpec, instance_of
from estimator.problem import STATE_PARAMS, STATE_SIGNALS, ChannelSpec, ManeuverData

#: The shipped model sets: ``<name>.toml``.
MODELS_DIR = Path(__file__).resolve().parent.parent / "models"
#: The model set a problem uses unless it names one: the paper's (``models/tejas.toml``).
DEFAULT_MODEL_SET = "tejas"

#: A maneuver needs at least this many samples per free per-maneuver parameter (initial
#: conditions, IMU biases): those are estimated from that maneuver alone, and with fewer samples
#: their estimates (and the Cramér-Rao bounds) are dominated by noise and by the time shifts.
MIN_SAMPLES_PER_FREE_PARAMETER = 10
#: ... and must last at least this long: a free u0, v0, w0 absorbs the maneuver's mean wind and
#: IMU biases are separable from the initial conditions only over several seconds of motion.
MIN_DURATION_S = 5.0
#: Initial-condition start values average the first this many samples (noise), see
#: :func:`initial_condition_starts`.
IC_AVERAGE_SAMPLES = 5
_PAIRED_KEYS = ("value", "bounds", "breakpoints", "values")
#: Signals a channel model may use that refer to the channel itself: ``z`` its measurement,
#: ``zhat`` its modelled measurement (see :mod:`estimator.problem`).
OWN_SIGNALS = frozenset({"z", "zhat"})
_CHANNEL_KEYS = ("name", "column", "model", "sensor", "delay", "recorder", "unit", "measures")
#: value, bounds, breakpoints and values may be given in degrees (``value_deg``, ...): converted to rad
_PARAM_KEYS = {
    **dict.fromkeys(("unit", "kind", "scope"), Key()), "value": Key(unit="rad"),
    "bounds": Key(unit="rad"), "free": Key(), "breakpoints": Key(unit="rad"),
    "fixed_elements": Key(), "values": Key(unit="rad"), "free_instances": Key(),
}
_DISPLAY = {"rad": (180.0 / math.pi, "deg"), "rad/s": (180.0 / math.pi, "deg/s"), "s": (1000.0, "ms")}


def parse_channel(d: Mapping, where: str) -> ChannelSpec:
    """A ``[[channel]]`` table as a :class:`ChannelSpec` (``where`` names it in messages)."""
    check(d, _CHANNEL_KEYS, where)
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
    """A ``[parameter.NAME]`` table as a :class:`ParameterSpec` (``_deg`` keys converted)."""
    d = check(d, _PARAM_KEYS, where)
    unit = d.get("unit", "1")
    kind = d.get("kind", "other")
    scope = d.get("scope", "global")
    if kind not in KINDS or scope not in SCOPES:
        raise ValueError(f"{where}: kind must be one of {KINDS} and scope one of {SCOPES}")
    breakpoints = d.get("breakpoints")
    value = d.get("value", 0.0)
    if value == "breakpoints":
        if breakpoints is None:
            raise ValueError(f"{where}: value = 'breakpoints' needs breakpoints")
        value = list(breakpoints)
    bounds = d.get("bounds", [-math.inf, math.inf])
    per_instance = d.get("values", {}) or {}
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


# ------------------------------------------------------------------------------ declarations
# the records themselves (Requirement, InitialConditionSources, Declarations) live in
# estimator.declarations, imported above (their names here are those)


def sensor_positions(positions: Mapping[str, np.ndarray], declarations: Declarations
                     ) -> dict[str, np.ndarray]:
    """The sensor positions with each of the model set's midpoint sensors added where it has no
    position of its own and every sensor it is the mean of has one (:class:`Declarations`)."""
    out = dict(positions)
    for name, parts in declarations.sensor_midpoints.items():
        if name not in out and all(p in out for p in parts):
            out[name] = np.mean([np.asarray(out[p], dtype=float) for p in parts], axis=0)
    return out


@dataclass(frozen=True)
class DeclaredChannel(ChannelSpec):
    """A channel read from a model set: it carries its model set's :class:`Declarations`, so that a
    :class:`~estimator.problem.Problem` built from the model set tells the workflow, the report and
    the initial conditions what the model set declares (:func:`declarations_of`)."""

    declarations: Declarations | None = field(default=None, compare=False, repr=False)


def declarations_of(problem_or_channels) -> Declarations:
    """The declarations of the model set a problem's channels (or the channels given) come from.

    Channels built by hand (plain :class:`ChannelSpec`) declare nothing: the defaults.
    """
    channels = getattr(problem_or_channels, "channels", problem_or_channels)
    found = {id(d): d for c in channels if (d := getattr(c, "declarations", None)) is not None}
    if len(found) > 1:
        raise ValueError(f"the channels come from {len(found)} model sets "
                         f"({sorted({d.source for d in found.values()})}); a problem has one")
    return next(iter(found.values()), Declarations())


_SECTIONS = ("channel", "parameter", "requirements", "workflow", "initial_conditions", "report",
             "sensor_midpoints", "plausible")
_REQUIREMENT_KEYS = ("sensor", "desired_3sigma_deg", "low_alpha_only")
_WORKFLOW_KEYS = ("reference_mach", "apportion_biases", "correction_model", "identity_table",
                  "alpha_limit_channel")
_IC_KEYS = ("tas", "phi", "theta", "psi", "h", "alpha", "beta")
_REPORT_KEYS = ("crossplots", "truth_crossplots", "time_history")


def _names(value, where: str, valid: Sequence[str], what: str) -> tuple[str, ...]:
    """A list of names, each one of ``valid`` (a typo named with its close match)."""
    if isinstance(value, str) or not isinstance(value, (list, tuple)) or not all(
            isinstance(v, str) for v in value):
        raise ValueError(f"{where}: must be a list of {what} names, e.g. [\"{next(iter(valid), 'x')}\"]")
    for v in value:
        if v not in valid:
            raise ValueError(f"{where}: {v!r} is not a {what} of the model set{did_you_mean(v, valid)}; "
                             f"its {what}s: {' '.join(valid)}")
    return tuple(value)


def parse_declarations(raw: Mapping, channels: Sequence[ChannelSpec], params: Sequence[ParameterSpec],
                       source: str, origin: str | None = None) -> Declarations:
    """The ``[requirements]``, ``[workflow]``, ``[initial_conditions]``, ``[report]`` and
    ``[sensor_midpoints]`` tables (module docstring), checked against the model set's channels and
    parameters; ``source`` names them in messages, ``origin`` is the model set's file (default:
    ``source``)."""
    names = [c.name for c in channels]
    columns = list(dict.fromkeys([*names, *(c.column for c in channels)]))
    specs = {s.name: s for s in params}
    reqs = {}
    req_raw = raw.get("requirements", {})
    if not isinstance(req_raw, Mapping):
        raise ValueError(f"{source}: [requirements] must be a table: CHANNEL = {{ sensor = ..., "
                         "desired_3sigma_deg = ... }")
    _names(list(req_raw), f"{source}: [requirements]", names, "channel")
    for ch, r in req_raw.items():
        where = f"{source}: [requirements] {ch}"
        check(r, _REQUIREMENT_KEYS, where)
        if not isinstance(r.get("sensor"), str) or not isinstance(r.get("desired_3sigma_deg"), (int, float)):
            raise ValueError(f"{where}: needs sensor = \"its name in Table 2\" and desired_3sigma_deg = "
                             "a number (deg)")
        reqs[ch] = Requirement(r["sensor"], float(r["desired_3sigma_deg"]),
                               bool(r.get("low_alpha_only", False)))

    wf = raw.get("workflow", {})
    where = f"{source}: [workflow]"
    check(wf, _WORKFLOW_KEYS, where)
    apportion = wf.get("apportion_biases", {})
    if not isinstance(apportion, Mapping) or not all(isinstance(v, str) for v in apportion.values()):
        raise ValueError(f"{where}: apportion_biases must be a table label = \"bias family\", "
                         "e.g. { left = \"b_left\", right = \"b_right\" }")
    for label, fam in apportion.items():
        if fam not in specs or specs[fam].scope != "aircraft":
            raise ValueError(f"{where}: apportion_biases {label} = {fam!r} is not an aircraft-scoped "
                             f"parameter of the model set (its parameters: {' '.join(specs)})")
    ref = wf.get("reference_mach")
    if apportion and (isinstance(ref, bool) or not isinstance(ref, (int, float))):
        raise ValueError(f"{where}: apportion_biases needs reference_mach = the Mach number of the bin "
                         "whose installation biases hold for every bin (e.g. 0.5)")
    tables = [s.name for s in params if s.kind == "table"]
    globals_ = [s.name for s in params if s.scope == "global"]
    correction = _names(wf.get("correction_model", []), f"{where} correction_model", globals_,
                        "global parameter")
    identity = wf.get("identity_table")
    if identity is not None:
        _names([identity], f"{where} identity_table", tables, "table")
    limit_ch = wf.get("alpha_limit_channel")
    if limit_ch is not None:
        _names([limit_ch], f"{where} alpha_limit_channel", names, "channel")
        if limit_ch not in reqs:
            raise ValueError(f"{where}: alpha_limit_channel {limit_ch!r} needs a desired accuracy: "
                             f"declare [requirements] {limit_ch} = {{ ... }}")
    low = [c for c, r in reqs.items() if r.low_alpha_only]
    if low and limit_ch is None:
        raise ValueError(f"{source}: [requirements] {low[0]} has low_alpha_only = true, which needs "
                         "[workflow] alpha_limit_channel (whose error growth sets the usable alpha)")

    ic = raw.get("initial_conditions", {})
    where = f"{source}: [initial_conditions]"
    check(ic, _IC_KEYS, where)
    scalars = {}
    for key in ("tas", "phi", "theta", "psi", "h"):
        if key in ic:
            scalars[key] = _names([ic[key]], f"{where} {key}", columns, "channel")[0]
    sources = InitialConditionSources(
        **scalars, alpha=_names(ic.get("alpha", []), f"{where} alpha", columns, "channel"),
        beta=_names(ic.get("beta", []), f"{where} beta", columns, "channel"))

    rep = raw.get("report", {})
    where = f"{source}: [report]"
    check(rep, _REPORT_KEYS, where)
    report = {k: _names(rep.get(k, []), f"{where} {k}", names, "channel") for k in sorted(_REPORT_KEYS)}

    mids = raw.get("sensor_midpoints", {})
    where = f"{source}: [sensor_midpoints]"
    if not isinstance(mids, Mapping):
        raise ValueError(f"{where}: must be a table SENSOR = [\"its part\", \"its other part\"]")
    _names(list(mids), where, list(dict.fromkeys(c.sensor for c in channels if c.sensor)), "sensor")
    for name, parts in mids.items():
        if (isinstance(parts, str) or not isinstance(parts, (list, tuple)) or len(parts) < 2
                or not all(isinstance(x, str) for x in parts)):
            raise ValueError(f"{where} {name}: must be a list of two or more sensor names (the sensors "
                             f"whose mean position is {name}'s)")
    return Declarations(
        source=origin or source, requirements=reqs, reference_mach=None if ref is None else float(ref),
        apportion=dict(apportion), correction_model=correction, identity_table=identity,
        alpha_limit_channel=limit_ch, initial_conditions=sources,
        **report, sensor_midpoints={k: tuple(v) for k, v in mids.items()},
    )


def parse_model_set(raw: Mapping, source: str, origin: str | None = None
                    ) -> tuple[list[DeclaredChannel], list[ParameterSpec]]:
    """The channels and parameter specs of a model set's TOML (``source`` names it in messages).

    Each channel carries the model set's :class:`Declarations` (:func:`declarations_of`), whose
    ``source`` is ``origin`` (the model set's file; default: ``source``).
    """
    check(raw, _SECTIONS, source)
    channels = [parse_channel(c, f"{source}: channel[{i}]") for i, c in enumerate(raw.get("channel", []))]
    params = [parse_parameter(n, p, f"{source}: parameter.{n}") for n, p in raw.get("parameter", {}).items()]
    decl = parse_declarations(raw, channels, params, source, origin)
    init = [f.name for f in fields(ChannelSpec) if f.init]
    return [DeclaredChannel(**{k: getattr(c, k) for k in init}, declarations=decl) for c in channels], params


def model_set_path(name_or_path: str | Path, base_dir: Path | None = None) -> Path:
    """The file of a model set: a path (relative to ``base_dir`` first) or a shipped name (``"tejas"``).

    A bare name (no directory, no suffix) that is no file falls back to the shipped model set of
    that name; a path never does.
    """
    p = Path(name_or_path)
    bare = len(p.parts) == 1 and not p.suffix
    cands = ([base_dir / p] if base_dir is not None and not p.is_absolute() else []) + [p] + (
        [MODELS_DIR / f"{p.name}.toml"] if bare else [])
    path = next((c for c in cands if c.is_file()), None)
    if path is None:
        shipped = sorted(q.stem for q in MODELS_DIR.glob("*.toml"))
        raise DataError(f"model = {str(name_or_path)!r}: no such model set file and no shipped one "
                        f"of that name (shipped: {shipped})")
    return path


def read_model_set(name_or_path: str | Path, base_dir: Path | None = None,
                   _chain: tuple[str, ...] = ()) -> tuple[dict, str]:
    """Raw TOML of a model set (:func:`model_set_path`) and the path it was read from.

    A model set with ``extends = "NAME"`` (a shipped name, or a path relative to its own file) is
    that model set with its own additions (:func:`extend_model_set`), so that a variant (the
    paper's models plus the INS velocities: ``tejas_ins``) states only what it adds.
    """
    path = model_set_path(name_or_path, base_dir).resolve()
    try:
        with open(path, "rb") as fh:
            raw = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise DataError(f"{path}: not valid TOML: {exc}; fix the syntax there") from None
    if "extends" not in raw:
        return raw, str(path)
    base_name = raw["extends"]
    if not isinstance(base_name, str) or not base_name:
        raise DataError(f"{path}: extends must name a model set (a shipped name such as \"tejas\", "
                        f"or a path relative to this file); got {base_name!r}")
    if str(path) in _chain:
        raise DataError(f"{path}: model sets extend each other in a circle "
                        f"({' -> '.join((*_chain, str(path)))}); break the circle")
    # relative to the extending file only (never the working directory), or a shipped name
    cand = Path(base_name)
    local = cand if cand.is_absolute() else path.parent / cand
    bare = len(cand.parts) == 1 and not cand.suffix
    if local.is_file():
        target = local
    elif bare and (MODELS_DIR / f"{cand.name}.toml").is_file():
        target = MODELS_DIR / f"{cand.name}.toml"
    else:
        shipped = sorted(q.stem for q in MODELS_DIR.glob("*.toml"))
        raise DataError(f"{path}: extends = {base_name!r}: no such file beside it ({local}) and no "
                        f"shipped model set of that name (shipped: {shipped}); fix the name")
    base, base_path = read_model_set(target, None, (*_chain, str(path)))
    return extend_model_set(base, raw, f"{path} (extends {base_path})"), str(path)


def extend_model_set(base: Mapping, own: Mapping, where: str) -> dict:
    """A model set's raw TOML on top of the one it ``extends``.

    ``[[channel]]`` entries are added, or replace the base's channel of the same name;
    ``[parameter.NAME]`` tables are added, or replace the base's table of that name (whole, so
    that nothing of the base's declaration lingers unseen); in the other tables (``[requirements]``,
    ``[workflow]``, ``[report]``, ...) each key replaces the base's.
    """
    out = {k: v for k, v in base.items() if k != "extends"}
    for key, val in own.items():
        if key == "extends":
            continue
        if key == "channel":
            out["channel"] = _merged_channels(base.get("channel", []), val, where)
        elif isinstance(val, Mapping) and isinstance(base.get(key), Mapping):
            out[key] = {**base[key], **val}
        else:
            out[key] = val
    return out


def _merged_channels(base: Sequence, extra: Sequence, where: str) -> list[dict]:
    """``[[channel]]`` tables of ``base`` with ``extra`` added, each replacing the base's channel
    of the same name."""
    channels = [dict(c) for c in base]
    for c in extra:
        if not isinstance(c, Mapping) or "name" not in c:
            raise DataError(f"{where}: each [[channel]] needs name = ... and model = ...")
        same = [i for i, old in enumerate(channels) if old.get("name") == c["name"]]
        if same:
            channels[same[0]] = dict(c)
        else:
            channels.append(dict(c))
    return channels


def load_model_set(name_or_path: str | Path = DEFAULT_MODEL_SET
                   ) -> tuple[list[ChannelSpec], list[ParameterSpec]]:
    """The channels and parameter specs of a model set: a shipped name (``"tejas"``) or a TOML path."""
    raw, source = read_model_set(name_or_path)
    return parse_model_set(raw, source)


def merge_model_set(raw: Mapping, parameter_overrides: Mapping | None, extra_channels: Sequence | None,
                    source: str, where: str) -> tuple[list[ChannelSpec], list[ParameterSpec], set[str]]:
    """Channels and parameter specs of a model set with the problem's additions.

    Returns
    -------
    channels, parameter specs, and the names of parameters the problem declared or changed.
    """
    params = {k: dict(v) for k, v in raw.get("parameter", {}).items()}
    for name, ov in (parameter_overrides or {}).items():
        if not isinstance(ov, Mapping):
            raise DataError(f"{where}: [parameter.{name}] must be a table of keys, e.g. free = false")
        cur = params.setdefault(name, {})
        for key, val in ov.items():
            stem = key[:-4] if key.endswith("_deg") else key
            if stem in _PAIRED_KEYS:  # value_deg replaces value and vice versa
                cur.pop(stem, None)
                cur.pop(stem + "_deg", None)
            cur[key] = val
    channels = _merged_channels(raw.get("channel", []), extra_channels or (), where)
    try:
        chans, specs = parse_model_set({**raw, "channel": channels, "parameter": params},
                                       f"{where} (model set {source})", origin=source)
    except DataError:
        raise
    except ValueError as exc:
        raise DataError(str(exc)) from None
    # a [parameter.NAME] the model set does not declare and no channel uses is a typo, not a new
    # parameter: left alone, its settings would silently change nothing
    used = referenced(chans)
    known = sorted({s.name for s in specs} - (set(parameter_overrides or {}) - set(raw.get("parameter", {}))))
    for name in parameter_overrides or {}:
        if name not in raw.get("parameter", {}) and name not in used:
            raise DataError(
                f"{where}: [parameter.{name}] is not a parameter of the model set ({source}) and no "
                "channel uses it" + did_you_mean(name, known)
                + f"; its parameters: {' '.join(known)}. Fix the name, or use it in a [[channel]] model"
            )
    return chans, specs, set(parameter_overrides or {})


def referenced(channels: Sequence[ChannelSpec]) -> set[str]:
    """Parameter families the state equations and the channels use (names, tables, delays)."""
    used = set(STATE_PARAMS)
    for ch in channels:
        used |= set(ch.expression.names) | set(ch.expression.tables)
        if ch.delay:
            used.add(ch.delay)
    return used


def check_data_names(channels: Sequence[ChannelSpec], specs: Sequence[ParameterSpec],
                     maneuvers: Sequence[ManeuverData]) -> None:
    """Each data signal a channel model uses must exist in every maneuver where the channel does."""
    params = {s.name for s in specs}
    col = {ch.name: ch.column for ch in channels}
    for m in maneuvers:
        for ch in channels:
            if ch.column not in m.measurements:
                continue
            for name in sorted(ch.expression.names - STATE_SIGNALS - OWN_SIGNALS - params):
                if name in m.signals or name in m.measurements or col.get(name) in m.measurements:
                    continue
                raise DataError(
                    f"{m.source}: channel {ch.name}'s model {ch.model!r} uses "
                    f"{name!r}, which is neither a declared parameter nor a data column of this "
                    f"maneuver (it has {sorted([*m.measurements, *m.signals])}); map {name} under "
                    f"[columns], declare [parameter.{name}], or leave channel {ch.name} out"
                )


def finalize_parameters(specs: Sequence[ParameterSpec], user_declared: set[str],
                        channels: Sequence[ChannelSpec], maneuvers: Sequence[ManeuverData],
                        where: str) -> list[ParameterSpec]:
    """Prune unused families, fix instances without data, set initial-condition start values."""
    used = referenced(channels)
    unused = sorted(s.name for s in specs if s.name not in used and s.name in user_declared)
    if unused:
        warn(f"{where}: parameter(s) {unused} are used by none of the channels "
             f"{[c.name for c in channels]} and are ignored")
    declared = {s.name for s in specs}
    missing_state = [n for n in STATE_PARAMS if n not in declared]
    if missing_state:
        raise DataError(f"{where}: the state-equation parameters {missing_state} are not declared; "
                        "the model set must declare u0 v0 w0 phi0 theta0 psi0 h0 dax day daz dp dq dr")
    out = []
    for spec in specs:
        if spec.name not in used:
            continue
        spec = _fix_instances_without_data(spec, channels, maneuvers)
        out.append(spec)
    return _with_initial_conditions(out, maneuvers, where, declarations_of(channels).initial_conditions)


def _fix_instances_without_data(spec: ParameterSpec, channels, maneuvers) -> ParameterSpec:
    if spec.name in STATE_PARAMS or spec.scope in ("global", "maneuver"):
        return spec
    users = [ch for ch in channels if spec.name in ch.expression.names | ch.expression.tables
             or ch.delay == spec.name]
    have: set[str] = set()
    every: set[str] = set()
    for m in maneuvers:  # the instances the data have, by the one instance rule
        every |= {instance_of(spec.scope, m, ch) for ch in channels}
        have |= {instance_of(spec.scope, m, ch) for ch in users if ch.column in m.measurements}
    fixed = {i: False for i in sorted(every - have)}
    if not fixed:
        return spec
    return replace(spec, free_instances={**dict(spec.free_instances), **fixed})


def initial_condition_starts(m: ManeuverData, n_avg: int = IC_AVERAGE_SAMPLES,
                             sources: InitialConditionSources | None = None) -> dict[str, float]:
    """Start values of u0 v0 w0 phi0 theta0 psi0 h0 from the maneuver's first samples.

    ``V`` from measured TAS, ``alpha``/``beta`` from the first flow channel of the model set's
    ``[initial_conditions]`` lists that the maneuver has (0 if none), ``u = V cos(a) cos(b)``,
    ``v = V sin(b)``, ``w = V sin(a) cos(b)``; Euler angles and altitude as measured. Each is the
    mean of the first ``n_avg`` samples. These are approximate (flow-angle biases and upwash,
    time delays, wind), which is all a start value needs to be.

    Parameters
    ----------
    m : the maneuver.
    n_avg : samples averaged.
    sources : the data columns to start from (:class:`InitialConditionSources`; default: the
        state's own names and no flow angles).

    Returns
    -------
    The start values that the data allow (no ``u0``/``v0``/``w0`` without TAS).
    """
    src = sources or InitialConditionSources()
    data = {**m.signals, **m.measurements}
    k = max(1, min(n_avg, m.n))

    def first(name: str) -> float | None:
        if name not in data:
            return None
        v = data[name]
        fin = np.flatnonzero(np.isfinite(v))  # an own-rate channel is NaN between its samples
        return float(np.mean(v[fin[fin < k]])) if np.any(fin < k) else float(v[fin[0]])

    out: dict[str, float] = {}
    for name, key in ((src.phi, "phi0"), (src.theta, "theta0"), (src.psi, "psi0"), (src.h, "h0")):
        v = first(name)
        if v is not None:
            out[key] = v
    tas = first(src.tas)
    if tas is not None:
        alpha = next((first(c) for c in src.alpha if c in data), 0.0)
        beta = next((first(c) for c in src.beta if c in data), 0.0)
        out["u0"] = tas * np.cos(alpha) * np.cos(beta)
        out["v0"] = tas * np.sin(beta)
        out["w0"] = tas * np.sin(alpha) * np.cos(beta)
    return out


def _with_initial_conditions(specs: list[ParameterSpec], maneuvers, where: str,
                             sources: InitialConditionSources) -> list[ParameterSpec]:
    starts = {m.id: initial_condition_starts(m, sources=sources) for m in maneuvers}
    out = []
    for spec in specs:
        if spec.name in STATE_PARAMS[:7] and spec.scope == "maneuver":
            given = dict(spec.per_instance)
            computed = {mid: s[spec.name] for mid, s in starts.items() if spec.name in s}
            lacking = [m for m in maneuvers if m.id not in given and m.id not in computed]
            if lacking and spec.name in ("u0", "v0", "w0"):
                m = lacking[0]
                raise DataError(
                    f"{m.source}: no true airspeed ({sources.tas}) to start {spec.name} from; "
                    f"map {sources.tas} under [columns] or give [parameter.{spec.name}] values = "
                    f"{{{m.id} = ...}} (m/s)"
                )
            spec = replace(spec, per_instance={**computed, **given})
        out.append(spec)
    return out


def check_maneuver_lengths(specs: Sequence[ParameterSpec], maneuvers: Sequence[ManeuverData]) -> None:
    """Every maneuver must be long enough for its own free parameters (see the constants)."""
    per = [s for s in specs if s.scope == "maneuver"]
    for m in maneuvers:
        n_free = sum(s.size - len(s.fixed_elements) for s in per if s.free_instances.get(m.id, s.free))
        need = MIN_SAMPLES_PER_FREE_PARAMETER * n_free
        dur = float(m.t_s[-1] - m.t_s[0])
        if m.n < need or dur < MIN_DURATION_S:
            raise DataError(
                f"{m.source}: too short to estimate its {n_free} free per-maneuver "
                f"parameters (initial conditions, IMU biases, altitude scale): {m.n} samples over "
                f"{dur:.2f} s; "
                f"needs at least {need} samples ({MIN_SAMPLES_PER_FREE_PARAMETER} per free parameter) "
                f"and {MIN_DURATION_S:.0f} s. Widen its time range, or hold some of its parameters "
                "fixed (e.g. [parameter.dax] free = false)"
            )
