"""The problem's channels and parameters: model set + overrides, pruned to the data, started from it.

- :func:`merge_model_set`: a shipped or user model set, with ``[parameter.NAME]`` overrides
  merged key by key into the model set's declaration and ``[[channel]]`` entries added (or
  replacing the model set's channel of the same name).
- :func:`finalize_parameters`: drops parameter families no selected channel uses, fixes scope
  instances that have no data (a nose-probe bias of an aircraft flown only with the boom), and
  sets the per-maneuver initial conditions' start values from the data.
- :func:`check_maneuver_lengths`: maneuvers too short for their per-maneuver parameters.
"""

from __future__ import annotations

import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from estimator.io.errors import DataError, close_match, warn
from estimator.modelfile import MODELS_DIR, parse_model_set
from estimator.parameters import ParameterSpec
from estimator.problem import STATE_PARAMS, STATE_SIGNALS, ChannelSpec, ManeuverData

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
#: Measured flow channels used (first one present) for the start values of w0 and v0.
ALPHA_SOURCES = ("alpha_zl", "alpha_zr", "alpha_zb", "alpha_zsp")
BETA_SOURCES = ("beta_zsp", "beta_znp", "beta_zbu", "beta_zbl")
_PAIRED_KEYS = ("value", "bounds", "breakpoints", "values")
#: Signals a channel model may use that refer to the channel itself: ``z`` its measurement,
#: ``zhat`` its modelled measurement (see :mod:`estimator.problem`).
OWN_SIGNALS = frozenset({"z", "zhat"})


def read_model_set(name_or_path: str | Path, base_dir: Path | None = None) -> tuple[dict, str]:
    """Raw TOML of a model set: a path (relative to ``base_dir``) or a shipped name (``"tejas"``)."""
    p = Path(name_or_path)
    bare = len(p.parts) == 1 and not p.suffix  # a shipped name; a path never falls back to one
    cands = ([base_dir / p] if base_dir is not None and not p.is_absolute() else []) + [p] + (
        [MODELS_DIR / f"{p.name}.toml"] if bare else [])
    path = next((c for c in cands if c.is_file()), None)
    if path is None:
        shipped = sorted(q.stem for q in MODELS_DIR.glob("*.toml"))
        raise DataError(f"model = {str(name_or_path)!r}: no such model set file and no shipped one "
                        f"of that name (shipped: {shipped})")
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh), str(path)
    except tomllib.TOMLDecodeError as exc:
        raise DataError(f"{path}: not valid TOML: {exc}; fix the syntax there") from None


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
    channels = [dict(c) for c in raw.get("channel", [])]
    for c in extra_channels or ():
        if not isinstance(c, Mapping) or "name" not in c:
            raise DataError(f"{where}: each [[channel]] needs name = ... and model = ...")
        same = [i for i, old in enumerate(channels) if old.get("name") == c["name"]]
        if same:
            channels[same[0]] = dict(c)
        else:
            channels.append(dict(c))
    try:
        chans, specs = parse_model_set({"channel": channels, "parameter": params},
                                       f"{where} (model set {source})")
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
            close = close_match(name, known)
            raise DataError(
                f"{where}: [parameter.{name}] is not a parameter of the model set ({source}) and no "
                "channel uses it" + (f" (did you mean {close!r}?)" if close else "")
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
    return _with_initial_conditions(out, maneuvers, where)


def _fix_instances_without_data(spec: ParameterSpec, channels, maneuvers) -> ParameterSpec:
    if spec.name in STATE_PARAMS or spec.scope in ("global", "maneuver"):
        return spec
    users = [ch for ch in channels if spec.name in ch.expression.names | ch.expression.tables
             or ch.delay == spec.name]
    have: set[str] = set()
    every: set[str] = set()
    for m in maneuvers:
        present = [ch for ch in users if ch.column in m.measurements]
        if spec.scope == "recorder":
            every |= {ch.recorder for ch in channels}
            have |= {ch.recorder for ch in present}
        else:
            inst = m.aircraft if spec.scope == "aircraft" else m.configuration
            every.add(inst)
            if present:
                have.add(inst)
    fixed = {i: False for i in sorted(every - have)}
    if not fixed:
        return spec
    return replace(spec, free_instances={**dict(spec.free_instances), **fixed})


def initial_condition_starts(m: ManeuverData, n_avg: int = IC_AVERAGE_SAMPLES) -> dict[str, float]:
    """Start values of u0 v0 w0 phi0 theta0 psi0 h0 from the maneuver's first samples.

    ``V`` from measured TAS, ``alpha``/``beta`` from the first measured flow channel of
    :data:`ALPHA_SOURCES` / :data:`BETA_SOURCES` (0 if none), ``u = V cos(a) cos(b)``,
    ``v = V sin(b)``, ``w = V sin(a) cos(b)``; Euler angles and altitude as measured. Each is the
    mean of the first ``n_avg`` samples. These are approximate (flow-angle biases and upwash,
    time delays, wind), which is all a start value needs to be.

    Returns
    -------
    The start values that the data allow (no ``u0``/``v0``/``w0`` without TAS).
    """
    data = {**m.signals, **m.measurements}
    k = max(1, min(n_avg, m.n))

    def first(name: str) -> float | None:
        if name not in data:
            return None
        v = data[name]
        fin = np.flatnonzero(np.isfinite(v))  # an own-rate channel is NaN between its samples
        return float(np.mean(v[fin[fin < k]])) if np.any(fin < k) else float(v[fin[0]])

    out: dict[str, float] = {}
    for name, key in (("phi", "phi0"), ("theta", "theta0"), ("psi", "psi0"), ("h", "h0")):
        v = first(name)
        if v is not None:
            out[key] = v
    tas = first("tas")
    if tas is not None:
        alpha = next((first(c) for c in ALPHA_SOURCES if c in data), 0.0)
        beta = next((first(c) for c in BETA_SOURCES if c in data), 0.0)
        out["u0"] = tas * np.cos(alpha) * np.cos(beta)
        out["v0"] = tas * np.sin(beta)
        out["w0"] = tas * np.sin(alpha) * np.cos(beta)
    return out


def _with_initial_conditions(specs: list[ParameterSpec], maneuvers, where: str) -> list[ParameterSpec]:
    starts = {m.id: initial_condition_starts(m) for m in maneuvers}
    out = []
    for spec in specs:
        if spec.name in STATE_PARAMS[:7] and spec.scope == "maneuver":
            given = dict(spec.per_instance)
            computed = {mid: s[spec.name] for mid, s in starts.items() if spec.name in s}
            lacking = [m for m in maneuvers if m.id not in given and m.id not in computed]
            if lacking and spec.name in ("u0", "v0", "w0"):
                m = lacking[0]
                raise DataError(
                    f"{m.source}: no true airspeed (tas) to start {spec.name} from; "
                    f"map tas under [columns] or give [parameter.{spec.name}] values = {{{m.id} = ...}} (m/s)"
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
