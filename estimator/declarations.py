"""What a model set declares besides its channels and parameters (the data types; read by
:mod:`estimator.io.modelset`, used by the workflow, its report and the initial conditions).

Plain immutable records, so that the options (:mod:`estimator.options`) and the workflow can name
them without importing the model-set reader.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields

from estimator.problem import ReadOnlyMapping

__all__ = ["Declarations", "InitialConditionSources", "Requirement"]


@dataclass(frozen=True)
class Requirement:
    """Desired 3-sigma accuracy of a calibrated channel (paper §4, Table 2): ``[requirements]``.

    Attributes
    ----------
    sensor : how tables name it (Table 2's row).
    desired_deg : desired 3-sigma accuracy, deg.
    low_alpha_only : judged only below the usable angle of attack that the workflow finds from the
        error growth of the ``alpha_limit_channel``.
    """

    sensor: str
    desired_deg: float
    low_alpha_only: bool = False


@dataclass(frozen=True)
class InitialConditionSources:
    """The data the per-maneuver initial conditions start from: ``[initial_conditions]``.

    Attributes
    ----------
    tas, phi, theta, psi, h : data columns of true airspeed (m/s), the Euler angles (rad) and the
        altitude (m).
    alpha, beta : flow-angle columns, rad: the first one a maneuver has gives the start values'
        angle of attack / sideslip (none: 0).
    """

    tas: str = "tas"
    phi: str = "phi"
    theta: str = "theta"
    psi: str = "psi"
    h: str = "h"
    alpha: tuple[str, ...] = ()
    beta: tuple[str, ...] = ()


@dataclass(frozen=True)
class Declarations:
    """Everything aircraft-specific a model set declares besides its channels and parameters.

    The calibration workflow (:mod:`estimator.workflow`), its report and the initial conditions
    read these, never a channel or parameter name of their own: another aircraft needs another
    model set, not Python. The defaults (a model set without these tables) ask for nothing: no
    Table 2 rows, no apportionment, no report figures by channel.

    Attributes
    ----------
    source : the model set's file.
    requirements : channel -> its Table 2 row and desired accuracy, in the model set's order.
    reference_mach : ``[workflow]``: the Mach of the bin whose installation biases hold for every
        bin (paper: 0.5); None without apportionment.
    apportion : label -> bias family (aircraft-scoped) split per aircraft into the fleet mean and
        installation biases (the labels name the result's columns, e.g. ``installation_left_deg``).
    correction_model : the fleet's correction model: global families (tables or not) whose every
        element is re-estimated with the installation biases held.
    identity_table : the table that starts at the identity: it takes over the fleet-mean bias and
        is reported as its update ``f(x) - x``; None: none.
    alpha_limit_channel : the channel whose usable angle of attack is found from its error growth
        (paper Fig. 7); None: none.
    initial_conditions : where the start values come from.
    crossplots : ``[report]``: channels of the measurement - model cross-plots (paper Fig. 5).
    truth_crossplots : channels of the calibrated - true cross-plots (synthetic data only).
    time_history : channels of the time-history figure (paper Fig. 3).
    sensor_midpoints : ``[sensor_midpoints]``: sensor -> the sensors whose mean position is its
        position when none is given (a pair of probes read as one sensor).
    """

    source: str = ""
    requirements: Mapping[str, Requirement] = field(default_factory=dict)
    reference_mach: float | None = None
    apportion: Mapping[str, str] = field(default_factory=dict)
    correction_model: tuple[str, ...] = ()
    identity_table: str | None = None
    alpha_limit_channel: str | None = None
    initial_conditions: InitialConditionSources = field(default_factory=InitialConditionSources)
    crossplots: tuple[str, ...] = ()
    truth_crossplots: tuple[str, ...] = ()
    time_history: tuple[str, ...] = ()
    sensor_midpoints: Mapping[str, tuple[str, ...]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        # immutable however made: read-only copies of the mappings, tuples of the lists
        def put(name, value):
            object.__setattr__(self, name, value)

        put("requirements", ReadOnlyMapping(self.requirements))
        put("apportion", ReadOnlyMapping(self.apportion))
        put("sensor_midpoints", ReadOnlyMapping({k: tuple(v) for k, v in self.sensor_midpoints.items()}))
        for name in ("correction_model", "crossplots", "truth_crossplots", "time_history"):
            put(name, tuple(getattr(self, name)))

    def to_dict(self) -> dict:
        """Plain JSON values (:meth:`from_dict` reads them back)."""
        ic = {f.name: getattr(self.initial_conditions, f.name) for f in fields(InitialConditionSources)}
        return {
            "source": self.source,
            "requirements": {k: {"sensor": r.sensor, "desired_deg": r.desired_deg,
                                 "low_alpha_only": r.low_alpha_only} for k, r in self.requirements.items()},
            "reference_mach": self.reference_mach, "apportion": dict(self.apportion),
            "correction_model": list(self.correction_model), "identity_table": self.identity_table,
            "alpha_limit_channel": self.alpha_limit_channel,
            "initial_conditions": {k: list(v) if isinstance(v, tuple) else v for k, v in ic.items()},
            "crossplots": list(self.crossplots), "truth_crossplots": list(self.truth_crossplots),
            "time_history": list(self.time_history),
            "sensor_midpoints": {k: list(v) for k, v in self.sensor_midpoints.items()},
        }

    @classmethod
    def from_dict(cls, d: Mapping) -> Declarations:
        """The declarations :meth:`to_dict` gave."""
        ic = {k: tuple(v) if isinstance(v, list) else v for k, v in d["initial_conditions"].items()}
        return cls(
            source=d["source"], requirements={k: Requirement(**r) for k, r in d["requirements"].items()},
            reference_mach=d["reference_mach"], apportion=d["apportion"],
            correction_model=d["correction_model"], identity_table=d["identity_table"],
            alpha_limit_channel=d["alpha_limit_channel"], initial_conditions=InitialConditionSources(**ic),
            crossplots=d["crossplots"], truth_crossplots=d["truth_crossplots"],
            time_history=d["time_history"], sensor_midpoints=d["sensor_midpoints"])
