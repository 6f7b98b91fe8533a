"""What the estimator is asked to do: maneuvers of data, channel models, sensors, parameters.

Everything here is plain, immutable data in SI units. :mod:`estimator.io` builds a
:class:`Problem` from a problem file (TOML) or from a dataset written by ``fpr fly``;
:mod:`estimator.model` evaluates it and :mod:`estimator.solver` estimates its free parameters.

Channel models are text (:mod:`estimator.core.expressions`) over these signals:

==================  ==========================================================================
``alpha_s``         angle of attack at the channel's sensor, atan2(w_s, u_s), rad
``beta_s``          aerodynamic sideslip at the sensor, asin(v_s / |V_s|), rad
``flank_s``         flank angle at the sensor, atan2(v_s, u_s), rad (what a sideslip vane senses)
``alpha_t``         angle of attack at the CG, rad
``beta_t``          sideslip at the CG, rad
``tas_t``           true airspeed at the CG, m/s
``u_s``, ``v_s``, ``w_s``  body-axis velocity of the sensor's point relative to the maneuver's *steady*
                    air mass, m/s: ``V_s`` itself. Its NED form plus the steady wind is the point's
                    ground velocity (an INS velocity: ``estimator/models/tejas_ins.toml``); the
                    turbulent wind does not move it (the filter-error method gives these signals no
                    wind sensitivity)
``phi``, ``theta``, ``psi``, ``h``  reconstructed Euler angles (rad) and altitude (m)
``p``, ``q``, ``r``   body rates, gyro biases removed, rad/s (for rate-dependent sensor terms)
``z``               the channel's own measurement (SPEC §5: f3, f4 take a measured argument)
``zhat``            the channel's own *modelled* measurement: ``y = F(zhat)`` is solved as an implicit
                    equation. As a table argument it is the measured-angle table of the paper without
                    the errors-in-variables bias that noise in ``z`` causes
any data column     e.g. ``gear`` (1 = gear down), ``mach``, another channel's measurement
==================  ==========================================================================

with ``V_s = V + omega x (r_sensor - r_cg)``, the exact rigid-body velocity (SPEC §3).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from estimator.core.expressions import Expression, parse
from estimator.core.sensitivity import LEVER_ARMS
from estimator.parameters import ParameterSet, ParameterSpec, instance_of

#: Signals computed from the reconstructed states (their derivatives are chained to the states).
STATE_SIGNALS = frozenset(
    {"alpha_s", "beta_s", "flank_s", "alpha_t", "beta_t", "tas_t", "phi", "theta", "psi", "h",
     "p", "q", "r", "u_s", "v_s", "w_s"}
)
#: Flow-angle signals: they need a sensor position, and a channel using one is a flow channel.
SENSOR_SIGNALS = frozenset({"alpha_s", "beta_s", "flank_s"})
#: The sensor point's velocity components (relative to the steady air mass); they need a position.
VELOCITY_SIGNALS = frozenset({"u_s", "v_s", "w_s"})
#: The signals that see the air: the turbulent wind moves them (a channel using none of them does
#: not see it; the filter-error method, estimator.filter_error).
AIR_RELATIVE_SIGNALS = frozenset({"alpha_s", "beta_s", "flank_s", "alpha_t", "beta_t", "tas_t"})
#: Names of the 13 state-equation parameter families, in kernel order.
STATE_PARAMS = ("u0", "v0", "w0", "phi0", "theta0", "psi0", "h0",
                "dax", "day", "daz", "dp", "dq", "dr")


@dataclass(frozen=True)
class ChannelSpec:
    """One observed channel.

    Attributes
    ----------
    name : channel name (``alpha_zl``).
    column : the data column holding its measurement, SI (``alpha_zl_rad``).
    model : observation model text, e.g. ``"f1(alpha_s) - f2(alpha_t) * beta_s + b_l"``.
    sensor : sensor name whose position defines ``alpha_s``/``beta_s``/``flank_s`` (flow channels)
        and ``u_s``/``v_s``/``w_s`` (an inertial velocity's point).
    delay : parameter family of the channel's time shift ``y(t - tau)``, or None.
    recorder : recorder the channel comes from (for recorder-scoped parameters).
    unit : SI unit of the measurement.
    display_scale, display_unit : for reports (57.29578, "deg").
    measures : the flow signal the channel measures (``alpha_s``, ``beta_s`` or ``flank_s``), whose
        value the calibrated channel gives; default: the only sensor signal of its model (None
        if it has none or several and none is declared).
    """

    name: str
    column: str
    model: str
    sensor: str | None = None
    delay: str | None = None
    recorder: str = "dru"
    unit: str = "rad"
    display_scale: float = 1.0
    display_unit: str = ""
    measures: str | None = None
    expression: Expression = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        expr = parse(self.model, where=f"channel {self.name}")
        object.__setattr__(self, "expression", expr)
        positioned = expr.names & (SENSOR_SIGNALS | VELOCITY_SIGNALS)
        if positioned and not self.sensor:
            raise ValueError(
                f"channel {self.name}: model {self.model!r} uses a sensor signal "
                f"({sorted(positioned)}) but declares no sensor; add sensor = \"...\""
            )
        if not self.display_unit:
            object.__setattr__(self, "display_unit", self.unit)
        used = expr.names & SENSOR_SIGNALS
        if self.measures is None and len(used) == 1:
            object.__setattr__(self, "measures", next(iter(used)))
        elif self.measures is not None and self.measures not in used:
            raise ValueError(
                f"channel {self.name}: measures = {self.measures!r} is not a sensor signal of its "
                f"model {self.model!r}; use one of {sorted(used) or ['alpha_s', 'beta_s', 'flank_s']}"
            )


@dataclass(frozen=True)
class ManeuverData:
    """One maneuver's data on a uniform time base, SI units.

    Attributes
    ----------
    id : maneuver id (unique in the problem).
    t_s : (N,) uniform, strictly increasing sample times, s.
    accel_imu_mps2 : (N, 3) specific force measured at the IMU, body axes, m/s^2.
    omega_rps : (N, 3) body rates measured by the IMU, rad/s.
    measurements : channel column -> (N,) measured values (SI); NaN only where an own-rate
        channel (recorded slower than the time base) has no sample.
    signals : other data columns the models may use (``gear``, ``mach``), (N,) each.
    r_cg_body_m : (3,) CG position, body axes, m (reference-point origin).
    aircraft, configuration : for aircraft- and configuration-scoped parameters.
    source : where the data came from (file and time range), for error messages.
    meta : anything else (manifest entry, Mach, gear).
    """

    id: str
    t_s: np.ndarray
    accel_imu_mps2: np.ndarray
    omega_rps: np.ndarray
    measurements: Mapping[str, np.ndarray]
    r_cg_body_m: np.ndarray
    aircraft: str = "aircraft"
    configuration: str = ""
    signals: Mapping[str, np.ndarray] = field(default_factory=dict)
    source: str = ""
    meta: Mapping = field(default_factory=dict)

    @property
    def n(self) -> int:
        return len(self.t_s)

    @property
    def dt_s(self) -> float:
        return float((self.t_s[-1] - self.t_s[0]) / (len(self.t_s) - 1))


class ReadOnlyMapping(Mapping):
    """A read-only mapping (of option names, a model set's declarations, a stage's residuals):
    picklable, unlike ``MappingProxyType``, because problems go to worker processes. It holds a
    copy of what it is given."""

    def __init__(self, options: Mapping[str, Any] = ()) -> None:
        self._d = dict(options)

    def __getitem__(self, key: str) -> Any:
        return self._d[key]

    def __iter__(self):
        return iter(self._d)

    def __len__(self) -> int:
        return len(self._d)

    def __repr__(self) -> str:
        return f"ReadOnlyMapping({self._d!r})"


@dataclass(frozen=True)
class Problem:
    """An estimation problem.

    Attributes
    ----------
    maneuvers : the data.
    channels : the observed channels (a channel absent from a maneuver is skipped there).
    sensors : sensor name -> (3,) position, body axes, m.
    imu_position_body_m : (3,) accelerometer position, body axes, m.
    parameters : the expanded parameter set (start values, free/fixed, bounds).
    g_mps2 : gravity used by the flat-earth state equations.
    source : problem file or dataset path.
    lever_arm : how the state equations treat the accelerometers' lever arm (SPEC §3):
        "imu_point" (default) integrates the IMU point's velocity, exact, no angular acceleration
        needed; "differentiated" removes the lever arm with angular accelerations from smoothed
        differentiation of the rates, the SPEC's method (:mod:`estimator.core.sensitivity`).
    options : the problem file's ``[workflow]``, ``[solver]`` and ``[report]`` options as one flat,
        read-only mapping of option names (:meth:`estimator.calibration.CalibrationOptions.from_mapping`);
        :func:`estimator.calibrate` uses them unless given others.
    """

    maneuvers: tuple[ManeuverData, ...]
    channels: tuple[ChannelSpec, ...]
    sensors: Mapping[str, np.ndarray]
    imu_position_body_m: np.ndarray
    parameters: ParameterSet
    g_mps2: float = 9.80665
    source: str = ""
    lever_arm: str = "imu_point"
    options: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        # read-only: the options are the file's, and a Problem is shared by the workflow's stages
        object.__setattr__(self, "options", ReadOnlyMapping(self.options))
        if self.lever_arm not in LEVER_ARMS:
            raise ValueError(f"{self.source}: lever_arm must be one of {LEVER_ARMS}, got {self.lever_arm!r}")
        ids = [m.id for m in self.maneuvers]
        if len(set(ids)) != len(ids):
            dup = sorted({i for i in ids if ids.count(i) > 1})
            raise ValueError(f"{self.source}: duplicate maneuver ids {dup}")
        for ch in self.channels:
            if ch.sensor and ch.sensor not in self.sensors:
                raise ValueError(
                    f"{self.source}: channel {ch.name} uses sensor {ch.sensor!r}, which has no "
                    f"position; declare it under [sensors] (known: {sorted(self.sensors)})"
                )


def expand_parameters(specs: list[ParameterSpec], maneuvers: Sequence[ManeuverData],
                      channels: Sequence[ChannelSpec]) -> ParameterSet:
    """Expand parameter families over the instances present in the maneuvers and channels.

    The instances are those :func:`estimator.parameters.instance_of` (the one instance rule)
    gives the data: sorted, but per-maneuver ones in the maneuvers' order.
    """
    def used(scope: str, chans: Sequence[ChannelSpec | None] = (None,)) -> list[str]:
        return sorted({instance_of(scope, m, c) for m in maneuvers for c in chans})

    inst = {
        "aircraft": used("aircraft"),
        "configuration": used("configuration"),
        "recorder": used("recorder", channels),
        "maneuver": [instance_of("maneuver", m) for m in maneuvers],
    }
    return ParameterSet.expand(specs, inst)
