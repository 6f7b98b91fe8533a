"""A good flight with real-world imperfections is not called a failure (SPEC §9, issue's must-show).

One configuration at Mach 0.5 flown at the testbed's realism level (docs/realism.md: INS attitude
from a filter, IMU scale and misalignment, static-source error and pneumatic lag, GNSS velocity held
between fixes, slow vertical air motion; calm air, a steady wind): a pitch doublet, a wind-up turn
and a steady-heading sideslip. Its kinematic residuals are coloured and a few times their white-noise
floor, as real recorded data are; the verdict must say so as notes, with no failure and at most a
few warning groups. The verdict corpus (campaigns/benchmarks/verdict_corpus.py) runs 24 such flights
and the fleet workflow; this test keeps one of them in the suite.
"""

from __future__ import annotations

import math
import warnings

import pytest

from estimator.io import problem_from_dataset
from estimator.solver import estimate
from estimator.verdict import Severity, Verdict

CAMPAIGN = {
    "name": "realism_verdict", "fleet": "fleet_default", "seed": 9201, "common_rate_hz": 40.0,
    "environment": {"planet": "flat", "wind_ned_mps": [6.0, -4.0, 0.0], "turbulence": "none",
                    "vertical_air_motion": {"sigma_mps": 0.4, "tau_s": 30.0}},
    "errors": {"preset": "real_world"},
    "flights": [
        {"configurations": ["PV1-NP"], "mach": [0.5], "maneuvers": ["pitch_doublet", "shss"],
         "altitude_m": 6000.0},
        {"configurations": ["PV1-NP"], "mach": [0.5], "maneuvers": ["windup_turn"], "altitude_m": 6000.0,
         "maneuver": {"alpha_max_rad": math.radians(12.0), "nz_max": 4.5}}],
}


@pytest.mark.slow
def test_a_good_flight_at_the_realism_level_is_not_a_failure(fly_once):
    path = fly_once(CAMPAIGN, "test_verdict_realism")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the held GNSS velocity and the boom's missing channels
        problem = problem_from_dataset(path)
    res = estimate(problem)
    groups = res.finding_groups()
    text = res.summary(max_findings=30)
    assert res.verdict != Verdict.FAILURE, text
    assert sum(g.severity == Severity.WARNING for g in groups) <= 3, text
    # the real-world residuals are there, and said as notes: coloured, above the white-noise floor
    kinematic = [g for g in groups if g.channel in ("phi", "theta", "psi", "tas", "h", "h_dgps")]
    assert kinematic, "the realism level leaves coloured kinematic residuals: " + text
    assert all(g.severity == Severity.NOTE for g in kinematic), text
    fq = res.fit_quality.to_pandas()
    theta = fq[fq["channel"] == "theta"]
    assert theta["ratio"].max() > 2.0 and theta["rho1"].max() > 0.8, theta[["maneuver", "ratio", "rho1"]]
