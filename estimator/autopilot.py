"""A calibrated airspeed scale written the way an autopilot takes it: PX4 and ArduPilot parameters.

The airspeed channel's model is ``tas_measured = (1 + k) tas_true`` (``k``: the model set's scale
factor of the airspeed, named by the caller), where the measured airspeed is what the autopilot
computed in flight with the parameters then in force. The corrected parameters are:

- PX4 ``ASPD_SCALE_n`` multiplies the indicated airspeed: ``scale_new = scale_old / (1 + k)``;
- ArduPilot ``ARSPD_RATIO`` multiplies the measured differential pressure,
  ``airspeed = sqrt(ratio * dp)``: ``ratio_new = ratio_old / (1 + k)^2`` (the ratio in force
  times the square of the airspeed's correction, never the scale itself).

Their deviations follow from ``k``'s (first order): ``scale_old / (1 + k)^2 sigma_k`` and
``2 ratio_old / (1 + k)^3 sigma_k``. Nothing is written when the estimate must not be used: a
FAILURE verdict, or the scale factor not estimated (held, or on a bound); the refusal says why
(UAV users have crashed on a corrupted airspeed ratio).

Files: QGroundControl's parameter file (``.params``: ``vehicle component name value type``,
tab-separated, type 9 = float) and Mission Planner's (``.param``: ``NAME,VALUE``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

#: The autopilots and the parameter each takes the airspeed correction in.
PARAMETERS = {"px4": "ASPD_SCALE_1", "ardupilot": "ARSPD_RATIO"}
#: QGroundControl's type code of a float parameter (MAV_PARAM_TYPE_REAL32).
QGC_FLOAT = 9


class ExportRefused(ValueError):
    """The calibration must not go into an autopilot; the message says why and what to do."""


@dataclass(frozen=True)
class AutopilotParameter:
    """One corrected autopilot parameter.

    Attributes
    ----------
    autopilot : ``"px4"`` or ``"ardupilot"``.
    name : the parameter (``ASPD_SCALE_1``, ``ARSPD_RATIO``).
    in_force : its value during the flight.
    value : the corrected value.
    std : its (honest) standard deviation.
    scale_key, k, k_std : the airspeed scale factor it comes from, its estimate and deviation [1].
    """

    autopilot: str
    name: str
    in_force: float
    value: float
    std: float
    scale_key: str
    k: float
    k_std: float

    def to_pandas(self) -> pd.DataFrame:
        return pd.DataFrame([self.__dict__])


def corrected(autopilot: str, in_force: float, k: float, k_std: float, name: str | None = None,
              scale_key: str = "") -> AutopilotParameter:
    """The corrected airspeed parameter of ``autopilot`` for a scale factor ``k`` +- ``k_std``.

    Parameters
    ----------
    autopilot : ``"px4"`` (``ASPD_SCALE_n``) or ``"ardupilot"`` (``ARSPD_RATIO``).
    in_force : the parameter's value during the flight.
    k, k_std : the airspeed scale factor (``tas_measured = (1 + k) tas_true``) and its deviation [1].
    name : the parameter's name (default: :data:`PARAMETERS`; ``ASPD_SCALE_2`` for a second sensor).
    scale_key : the scale factor's parameter key, carried into the result.
    """
    if autopilot not in PARAMETERS:
        raise ValueError(f"autopilot {autopilot!r}: one of {sorted(PARAMETERS)}")
    if not (math.isfinite(in_force) and in_force > 0):
        raise ValueError(f"{name or PARAMETERS[autopilot]} in force = {in_force!r}: a positive number")
    c = 1.0 + k
    if autopilot == "px4":
        value, std = in_force / c, in_force / c**2 * k_std
    else:
        value, std = in_force / c**2, 2.0 * in_force / c**3 * k_std
    return AutopilotParameter(autopilot, name or PARAMETERS[autopilot], float(in_force), float(value),
                              float(std), scale_key, float(k), float(k_std))


def from_result(result_json: str | Path, autopilot: str, in_force: float, scale_key: str,
                name: str | None = None) -> AutopilotParameter:
    """The corrected parameter from a calibration's ``result.json`` (``fpr calibrate --single``);
    ``scale_key``: the model set's scale factor of the airspeed (the ``uav`` set's ``k_tas``).

    Raises
    ------
    ExportRefused
        The verdict is FAILURE, or the scale factor is not an estimate to use (held, on a bound,
        without a deviation): the message says why.
    """
    path = Path(result_json)
    doc = json.loads(path.read_text(encoding="utf-8"))
    rows = {p["key"]: p for p in doc.get("parameters", [])}
    if scale_key not in rows:
        scales = sorted(k for k, p in rows.items() if p.get("kind") == "scale")
        raise ExportRefused(f"{path}: no parameter {scale_key!r} (the airspeed's scale factor); the scale "
                            f"factors there: {scales}: name it (--scale)")
    p = rows[scale_key]
    verdict = str(doc.get("verdict", ""))
    if verdict == "FAILURE":
        raise ExportRefused(f"{path}: the verdict is FAILURE ({doc.get('verdict_text', '')}): its estimates "
                            "must not go into an autopilot; fix what the findings name first")
    std = p.get("std_colored")
    if p.get("state") != "estimated" or std is None or not math.isfinite(float(std)):
        raise ExportRefused(f"{path}: {scale_key} is {p.get('state')} ({p.get('reason') or 'no deviation'}), "
                            "not an estimate the data determine: nothing is written")
    return corrected(autopilot, in_force, float(p["value"]), float(std), name, scale_key)


def _comment(p: AutopilotParameter) -> str:
    """The comment line beside a parameter: its value in force, the corrected one and its deviation."""
    return (f"# {p.name}: in force {p.in_force:.6g}, corrected {p.value:.6g} +- {p.std:.2g} "
            f"({p.scale_key} = {p.k:.5g} +- {p.k_std:.2g})")


def write_qgc(path: str | Path, params: list[AutopilotParameter], vehicle: int = 1,
              component: int = 1) -> Path:
    """A QGroundControl parameter file (``.params``) of the PX4 parameters, their deviations as comments."""
    lines = ["# Onboard parameters for Vehicle 1: airspeed calibration by fpr (estimator.autopilot)",
             "#", "# Vehicle-Id Component-Id Name Value Type"]
    for p in params:
        lines.append(_comment(p))
        lines.append(f"{vehicle}\t{component}\t{p.name}\t{p.value:.6f}\t{QGC_FLOAT}")
    out = Path(path)
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return out


def write_mission_planner(path: str | Path, params: list[AutopilotParameter]) -> Path:
    """A Mission Planner parameter file (``.param``: ``NAME,VALUE``) of the ArduPilot parameters."""
    lines = []
    for p in params:
        lines.append(_comment(p))
        lines.append(f"{p.name},{p.value:.6f}")
    out = Path(path)
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return out


def in_force_from_ulog(path: str | Path, name: str) -> float:
    """A parameter's value in force during a PX4 flight: the log's initial value; an error if the
    flight changed it (which value the airspeed was computed with is then ambiguous)."""
    from pyulog import ULog

    log = ULog(str(path), message_name_filter_list=[])
    if name not in log.initial_parameters:
        near = sorted(k for k in log.initial_parameters if k.startswith(name.split("_")[0]))[:10]
        raise ValueError(f"{path}: the log holds no parameter {name!r} (similar: {near}); give its value")
    changed = [(t, v) for t, n, v in log.changed_parameters if n == name]
    if changed:
        raise ValueError(f"{path}: {name} changed during the flight ({len(changed)} time(s), first at "
                         f"{changed[0][0] / 1e6:.1f} s): give the value the calibrated maneuvers flew with")
    return float(log.initial_parameters[name])

