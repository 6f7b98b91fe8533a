"""Planning study (c): how large may IMU biases, time delays, winds and turbulence be before the
desired accuracy is lost?

One factor at a time around a base scenario (typical errors of SPEC §6, calm air), every point a
Monte Carlo run of :mod:`campaigns.montecarlo` (N replications: new noise, IMU biases drawn per
maneuver, estimation, comparison with the truth). Per point: the 3-sigma accuracy of every
calibrated flow-angle channel against the true flow angle, pass/fail against the desired accuracy
(paper Table 2: vane AOA ±0.5 deg, side-probe AOA and AOSS ±1 deg, nose-probe AOSS ±0.5 deg), the
estimate-minus-truth error of the swept parameter (and whether its estimate sits on a bound of the
model set), the Monte Carlo scatter against the Cramér-Rao bounds and the failed estimations.

Factors (levels in :data:`FULL`):

* ``imu_bias``: the IMU biases, a multiple of the typical preset (accelerometer and gyro bias and
  the per-maneuver spread drawn around them). The biases are estimated per maneuver.
* ``flow_delay``: the delay of every flow-angle sensor (vanes, probes, boom), ms. Estimated.
* ``ins_delay``: the INS recorder's latency (Euler angles), ms. Estimated.
* ``wind``: a steady wind, m/s. Not a state of the model, and it need not be: in a steady uniform
  wind the air-relative velocity obeys the same kinematic equations as the inertial one
  (dV_a/dt = a - omega x V_a in body axes), so the free initial velocity absorbs it, turns included;
  winds that change along the path (shear, gusts, turbulence) are not absorbed.
* ``turbulence``: JSBSim's MIL-F-8785C turbulence, a new realisation per replication. Not
  modelled (the output-error method has no process noise).

Accuracy of a calibrated channel in one replication: ``|mean| + 3 std`` of (calibrated channel -
true flow angle) over every sample of every maneuver, so that a systematic offset counts too; a
requirement group (two vanes, two boom sideslip vanes) takes its worse channel. A point passes a
requirement when the median over the replications meets it.

Run (resumable: the same command again skips finished replications)::

    python -m campaigns.studies.tolerance --out runs/tolerance --results campaigns/studies/results
    python -m campaigns.studies.tolerance --out /tmp/tol --size tiny --replications 1   # a smoke run

It writes ``tolerance.txt`` (the table, headed by the command, machine and wall time, ending with
one conclusion per factor drawn from the numbers), ``tolerance.png`` (one panel per factor) and
``tolerance.csv`` into ``--results`` (default: ``--out``); each point's Monte Carlo run stays in
``OUT/points/``.

The study's parts: :mod:`.config` (requirements, factors and levels, base scenario, points),
:mod:`.run` (the points' Monte Carlo runs), :mod:`.analysis` (metrics per point, one row each),
:mod:`.report` (table, conclusions, text) and :mod:`.plot` (figure); the command line, the invocation
record and the results files are :mod:`campaigns.studies.scaffold`'s.
"""

from __future__ import annotations

from collections.abc import Sequence

from campaigns.studies import scaffold
from campaigns.studies.tolerance import plot, report, run
from campaigns.studies.tolerance.analysis import (
    collect,
    failing_groups,
    group_accuracy,
    point_metrics,
    swept_truth,
)
from campaigns.studies.tolerance.config import (
    DESIRED_3SIGMA_DEG,
    FULL,
    SENSOR_GROUPS,
    SIZES,
    STUDY_CODE,
    TINY,
    Factor,
    Point,
    StudyConfig,
    base_scenario,
    study_points,
)
from campaigns.studies.tolerance.report import conclusion, table_text
from campaigns.studies.tolerance.run import run_points

__all__ = ["DESIRED_3SIGMA_DEG", "FULL", "SENSOR_GROUPS", "SIZES", "STUDY_SPEC", "TINY", "Factor",
           "Point", "StudyConfig", "base_scenario", "collect", "conclusion", "failing_groups",
           "group_accuracy", "main", "point_metrics", "run_points", "study_points", "swept_truth",
           "table_text"]

STUDY_SPEC = scaffold.Study(
    name="tolerance", file=STUDY_CODE, sizes=SIZES, unit="point",
    description="Planning study (c): sweep IMU biases, flow-sensor and INS delays, steady wind and "
    "turbulence one at a time; Monte Carlo accuracy of the calibrated channels against the truth "
    "and pass/fail against the desired accuracy. Resumable: run the same command again.",
    workers_help="points run at once, one process each (default: 2)",
    size_help="full: the study; tiny: one configuration, two maneuvers, two levels per factor; "
              "filter_error: the turbulence rows (none, light, moderate) by the filter-error method",
    run=run.run,
    analyse=lambda config, out_dir, n, errors: collect(study_points(config, out_dir), n, errors),
    report=report.report,
    plot=lambda df, config, path, n: plot.plot(df, config.factors, path, n),
    table=lambda df: df)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m campaigns.studies.tolerance --out DIR [--replications N] ...``"""
    return scaffold.main(STUDY_SPEC, argv)
