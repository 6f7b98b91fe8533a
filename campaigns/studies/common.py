"""What several planning studies share about the flights they set up and the fits they accept.

The world of studies (a) and (b) (altitude, steady wind, seed, the errors drawn every replication),
the typical IMU biases and the spread of their per-maneuver draws (as ``campaigns/mc_20maneuvers.toml``;
studies (a), (b), (c) and the robustness study), scaling the IMU biases in a scenario (study (c) and
the robustness study), and the test of a fit that sits in a wrong minimum and the replications it
leaves (studies (a) and (b)).
One definition each: a study imports them from here, never from a sibling study.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from campaigns.montecarlo.replication import ReplicationResult
from campaigns.montecarlo.summary import load_results
from synth.errors import ErrorConfig

#: studies (a) and (b): flight altitude, m; steady wind, m/s (north, east, down); master seed
ALTITUDE_M = 6000.0
WIND_NED_MPS = (6.0, -4.0, 0.0)
SEED = 2026
#: the spread of the per-maneuver IMU biases drawn around their value (as mc_20maneuvers)
IMU_SPREAD_ACCEL_MPS2 = 0.05
IMU_SPREAD_GYRO_DEG_S = 0.1
#: drawn every replication besides the IMU biases (as campaigns/mc_20maneuvers.toml)
COMMON_DRAWS: dict[str, dict] = {
    "sensors.vane_left.delay_ms": {"dist": "uniform", "half_width": 20.0},
    "sensors.vane_right.delay_ms": {"dist": "uniform", "half_width": 20.0},
    "recorders.ins.clock_offset_ms": {"dist": "uniform", "low": -20.0, "high": 40.0},
    "sensors.boom_alpha_vane.scale": {"dist": "normal", "std": 0.01},
    "sensors.boom_beta_upper_vane.scale": {"dist": "normal", "std": 0.01},
    "sensors.boom_beta_lower_vane.scale": {"dist": "normal", "std": 0.01},
}
#: the vane AOA biases' parameter families: the calibration's headline parameters
VANE_BIAS_FAMILIES = ("b_l", "b_r")
#: an estimate whose phi/theta/psi residual 3-sigma exceeds this sits in a wrong minimum (a good
#: fit leaves the INS noise, ~0.1 deg; turbulence ~1 deg; a wrong minimum 10 deg and more)
ATTITUDE_FIT_LIMIT_DEG = 3.0


def typical_imu_biases() -> tuple[list[float], list[float]]:
    """The typical preset's IMU biases: accelerometer m/s^2, gyro rad/s."""
    imu = ErrorConfig.typical().imu
    return list(imu.accel_bias_mps2), list(imu.gyro_bias_rps)


def typical_imu_biases_deg() -> tuple[list[float], list[float]]:
    """The typical preset's IMU biases: accelerometer m/s^2, gyro deg/s."""
    accel_mps2, gyro_rps = typical_imu_biases()
    return accel_mps2, [math.degrees(b) for b in gyro_rps]


def set_imu_bias(raw: dict, scale: float | str) -> None:
    """Set a scenario mapping's IMU biases to ``scale`` x the typical preset's, in place, and draw
    them per maneuver around that value with ``|scale|`` x the mc_20maneuvers spread."""
    s = float(scale)
    accel_mps2, gyro_deg_s = typical_imu_biases_deg()
    imu = raw["errors"].setdefault("imu", {})
    imu["accel_bias_mps2"] = [s * a for a in accel_mps2]
    imu["gyro_bias_deg_s"] = [s * g for g in gyro_deg_s]
    draws = raw["draw"].setdefault("errors", {})
    draws["imu.accel_bias_mps2"] = {"dist": "normal", "std": abs(s) * IMU_SPREAD_ACCEL_MPS2,
                                     "scope": "maneuver"}
    draws["imu.gyro_bias_deg_s"] = {"dist": "normal", "std": abs(s) * IMU_SPREAD_GYRO_DEG_S,
                                    "scope": "maneuver"}


def fit_ok(result: ReplicationResult) -> bool:
    """The replication converged and its attitude residuals are those of a fit, not of a wrong minimum
    (:data:`ATTITUDE_FIT_LIMIT_DEG`)."""
    if not result.ok or not len(result.channels):
        return False
    ch = result.channels
    att = ch[(ch["kind"] == "residual") & ch["name"].isin(["phi", "theta", "psi"])]
    return bool(len(att)) and float(att["three_sigma"].max()) <= ATTITUDE_FIT_LIMIT_DEG


@dataclass(frozen=True)
class RunReplications:
    """A Monte Carlo run's replications as studies (a) and (b) count them.

    Attributes
    ----------
    results : every replication 0..N-1 with a file (results and failure records).
    ok : those whose estimation converged.
    used : those of them whose fit is one (:func:`fit_ok`): the replications in the statistics.
    """

    results: list[ReplicationResult]
    ok: list[ReplicationResult]
    used: list[ReplicationResult]

    @property
    def failed(self) -> int:
        """Replications whose estimation failed or did not converge."""
        return len(self.results) - len(self.ok)

    @property
    def wrong_minimum(self) -> int:
        """Converged replications whose fit sits in a wrong minimum."""
        return len(self.ok) - len(self.used)

    @property
    def elapsed_s(self) -> float:
        """Median wall time of a replication, s (NaN: none)."""
        return float(np.median([r.elapsed_s for r in self.results])) if self.results else math.nan


def read_run(run_dir: Path, replications: int) -> RunReplications:
    """Replications 0..N-1 of the Monte Carlo run in ``run_dir`` (none when it has not run)."""
    results = load_results(run_dir, replications) if (run_dir / "replications").is_dir() else []
    ok = [r for r in results if r.ok]
    return RunReplications(results=results, ok=ok, used=[r for r in ok if fit_ok(r)])
