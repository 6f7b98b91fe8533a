"""Assemble a :class:`Problem` from source tables, maneuver requests, channels and parameters."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from estimator.io.assemble import ManeuverRequest, SourceTable, build_maneuver, check_dimensions
from estimator.io.errors import DataError, close_match, warn
from estimator.io.modelset import (
    check_data_names,
    check_maneuver_lengths,
    declarations_of,
    finalize_parameters,
    sensor_positions,
)
from estimator.io.units import UNITS
from estimator.parameters import ParameterSpec
from estimator.problem import LEVER_ARMS, ChannelSpec, Problem, expand_parameters


def select_channels(channels: Sequence[ChannelSpec], explicit: Sequence[str] | None,
                    where: str) -> list[ChannelSpec]:
    """The channels the problem asks for (``channels = [...]``), or all of them."""
    if explicit is None:
        return list(channels)
    by_name = {c.name: c for c in channels}
    if isinstance(explicit, str) or not all(isinstance(n, str) for n in explicit):
        example = ", ".join(f'"{c.name}"' for c in channels[:2])
        raise DataError(f"{where}: channels must be a list of channel names, e.g. [{example}]")
    unknown = [n for n in explicit if n not in by_name]
    if unknown:
        raise DataError(f"{where}: channels {unknown} are not in the model set (it has {list(by_name)}); "
                        "fix the names or declare them with [[channel]]")
    return [by_name[n] for n in dict.fromkeys(explicit)]


@dataclass(frozen=True)
class StateEquations:
    """The flat-earth state equations' constants: gravity and the lever-arm formulation.

    Attributes
    ----------
    g_mps2 : gravity, m/s^2.
    lever_arm : "imu_point" or "differentiated" (:class:`~estimator.problem.Problem`).
    """

    g_mps2: float = 9.80665
    lever_arm: str = LEVER_ARMS[0]


@dataclass(frozen=True)
class StateSetup:
    """What the state equations take besides the data.

    Attributes
    ----------
    sensors : sensor positions, body axes, m (the model set's midpoint sensors are added:
        :func:`~estimator.io.modelset.sensor_positions`).
    imu_position_body_m : accelerometer position, body axes, m.
    equations : gravity and the lever-arm formulation (:class:`StateEquations`).
    """

    sensors: Mapping[str, np.ndarray]
    imu_position_body_m: np.ndarray
    equations: StateEquations = StateEquations()


def build_problem(
    pairs: Sequence[tuple[SourceTable, ManeuverRequest]],
    channels: Sequence[ChannelSpec],
    specs: Sequence[ParameterSpec],
    *,
    user_declared: set[str],
    explicit_channels: Sequence[str] | None,
    setup: StateSetup,
    source: str,
) -> Problem:
    """Check and assemble the problem.

    Parameters
    ----------
    pairs : (table, maneuver request) per maneuver.
    channels, specs : the model set with the problem's changes.
    user_declared : parameter names the problem file declared or changed (warned about if unused).
    explicit_channels : the problem's ``channels`` list, or None for "every channel with data".
    setup : the sensors' and accelerometer's positions, gravity and the lever-arm formulation
        (:class:`StateSetup`).
    source : problem file or dataset, for messages.
    """
    sensors, imu_position_body_m = setup.sensors, setup.imu_position_body_m
    g_mps2, lever_arm = setup.equations.g_mps2, setup.equations.lever_arm
    if lever_arm not in LEVER_ARMS:
        raise DataError(f"{source}: lever_arm = {lever_arm!r}; one of {', '.join(map(repr, LEVER_ARMS))}")
    if not 9.7 <= g_mps2 <= 9.9:
        raise DataError(f"{source}: g_mps2 = {g_mps2} is not an Earth gravity in m/s^2 (9.78 to 9.83); "
                        "give it in m/s^2, e.g. 9.80665")
    chans = select_channels(channels, explicit_channels, source)
    sensors = sensor_positions(sensors, declarations_of(channels))
    expected = {c.column: UNITS[c.unit].dimension for c in chans if c.unit in UNITS}
    for table in {id(t): t for t, _ in pairs}.values():
        check_dimensions(table, expected)
    columns = {c.column for c in chans}
    maneuvers = [build_maneuver(t, r, columns) for t, r in pairs]
    seen: dict[str, str] = {}
    for m in maneuvers:
        if m.id in seen:
            raise DataError(f"{source}: maneuver id {m.id!r} is used twice ({seen[m.id]} and {m.source}); "
                            "give each maneuver its own id")
        seen[m.id] = m.source
    absent = [c.name for c in chans if not any(c.column in m.measurements for m in maneuvers)]
    if absent and explicit_channels is not None:
        raise DataError(f"{source}: channels {absent} are listed in channels = [...] but no maneuver has "
                        "data for them; map their columns under [columns] or take them off the list")
    if absent:
        warn(f"{source}: channel(s) {absent} of the model set have no data in any maneuver and are left out")
        chans = [c for c in chans if c.name not in absent]
    if not chans:
        raise DataError(f"{source}: no channel has data; map at least the measured channels under [columns]")
    for c in chans:
        if c.sensor and c.sensor not in sensors:
            unused = [n for n in sensors if n != "imu" and all(ch.sensor != n for ch in channels)]
            typo = close_match(c.sensor, unused)
            raise DataError(
                f"{source}: channel {c.name} is measured at sensor {c.sensor!r}, which has no "
                f"position; add {c.sensor} = [x, y, z] under [sensors] (known: {sorted(sensors)}"
                + (f"; is {typo!r}, which no channel uses, a misspelling of it?" if typo else "") + ")"
            )
    check_data_names(chans, specs, maneuvers)
    final = finalize_parameters(specs, user_declared, chans, maneuvers, source)
    check_maneuver_lengths(final, maneuvers)
    try:
        params = expand_parameters(final, maneuvers, chans)
        return Problem(maneuvers=tuple(maneuvers), channels=tuple(chans), sensors=dict(sensors),
                       imu_position_body_m=np.asarray(imu_position_body_m, dtype=float),
                       parameters=params, g_mps2=float(g_mps2), source=source, lever_arm=lever_arm)
    except DataError:
        raise
    except ValueError as exc:
        raise DataError(f"{source}: {exc}") from None


def subproblem(problem: Problem, maneuver_ids: Sequence[str], *,
               values: Mapping[str, float] | None = None,
               free: Mapping[str, bool] | None = None) -> Problem:
    """The same problem restricted to some of its maneuvers (a Mach bin, the gear-down ones).

    Parameter families are re-expanded over the instances the subset has (an aircraft without
    maneuvers in it has no bias there), channels without data in the subset are left out, and
    an instance whose channels have no data is fixed, exactly as when the problem was built.

    Parameters
    ----------
    problem : the full problem.
    maneuver_ids : ids of the maneuvers to keep, in the order given.
    values : parameter key -> value (SI) to start from or hold; keys absent from the subset are
        ignored (an aircraft not in it).
    free : parameter key or family name -> free (True) or held (False), applied after ``values``.
    """
    by_id = {m.id: m for m in problem.maneuvers}
    unknown = [i for i in maneuver_ids if i not in by_id]
    if unknown:
        raise DataError(f"{problem.source}: no maneuver(s) {unknown[:5]} in the problem")
    if not maneuver_ids:
        raise DataError(f"{problem.source}: an empty set of maneuvers has nothing to estimate")
    mans = [by_id[i] for i in maneuver_ids]
    chans = [c for c in problem.channels if any(c.column in m.measurements for m in mans)]
    ids = set(maneuver_ids)
    specs = [replace(s, per_instance={i: v for i, v in s.per_instance.items() if i in ids})
             if s.scope == "maneuver" else s for s in problem.parameters.specs.values()]
    specs = finalize_parameters(specs, set(), chans, mans, problem.source)
    params = expand_parameters(specs, mans, chans)
    if values:
        params = params.with_values({k: v for k, v in values.items() if k in params})
    if free:
        params = params.with_free(free)
    return replace(problem, maneuvers=tuple(mans), channels=tuple(chans), parameters=params)


def without_samples(problem: Problem, samples: dict[tuple[str, str], np.ndarray]) -> Problem:
    """The problem with some samples of some channels removed (NaN: not in the cost): ``samples``
    maps (maneuver id, channel name) to the sample times to remove (the solver's robust pass)."""
    col = {c.name: c.column for c in problem.channels}
    mans = []
    for m in problem.maneuvers:
        meas = dict(m.measurements)
        for (man, ch), t in samples.items():
            if man != m.id or col.get(ch) not in meas:
                continue
            v = np.array(meas[col[ch]], dtype=float)
            idx = np.searchsorted(m.t_s, t)
            idx = idx[(idx < m.t_s.size)]
            idx = idx[np.isclose(m.t_s[idx], t[: idx.size], atol=1e-9 + 1e-6 * m.dt_s)]
            v[idx] = np.nan
            meas[col[ch]] = v
        mans.append(replace(m, measurements=meas))
    return replace(problem, maneuvers=tuple(mans))
