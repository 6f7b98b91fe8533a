"""A calibration that cannot be applied fails the verdict (estimator.checks.not_invertible).

Where a channel model's slope with respect to the flow angle it measures nearly vanishes (below a
quarter) or changes sign, flow angles far apart give nearly one reading and the flight-control
computer cannot turn the measurement back into a flow angle (estimator.calibrated raises there).
Planning study (c) saw a filter-error fit converge so, a vane table segment at slope 0.04, with
only a poor-model warning.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from campaigns.analytic_flight import NOISE_SIGMA, Flight, truth_values
from estimator.io.modelset import load_model_set
from estimator.solver import SolverOptions, estimate


@pytest.fixture(scope="module")
def calm():
    specs = load_model_set("tejas")[1]
    fl = Flight(truth_values(np.random.default_rng(5)), specs, T=25.0)
    return fl.problem(noise=NOISE_SIGMA, rng=np.random.default_rng(3))


def test_a_flat_table_segment_where_the_vanes_fly_fails_the_verdict(calm):
    """f1 held flat between 4 and 8 deg (f1[3] = f1[4]), where the flight's vane AOA lies (2-7
    deg): both vanes' calibrations cannot be applied there, each a failure naming the channel, the
    maneuvers and times; the true calibration gives no such finding."""
    ps = calm.parameters
    flat = float(ps.values[ps.index("f1[4]")])
    bent = dataclasses.replace(calm, parameters=ps.with_values({"f1[3]": flat}).with_free(
        {"f1[3]": False, "f1[4]": False}))
    res = estimate(bent, SolverOptions(start="given", diagnose=False, colored=False))
    found = {f.channel: f for f in res.findings if f.code == "not_invertible"}
    assert set(found) == {"alpha_zl", "alpha_zr"}, [f.code for f in res.findings]
    f = found["alpha_zl"]
    assert f.severity.name == "FAILURE" and res.verdict.name == "FAILURE"
    assert "alpha_s" in f.message and "m0 " in f.message and f.value < 1e-6
    good = estimate(calm, SolverOptions(start="given", diagnose=False, colored=False))
    assert not [f for f in good.findings if f.code == "not_invertible"]


def test_a_nearly_flat_segment_fails_too(calm):
    """A slope of 0.1 between 4 and 8 deg (f1[3] 0.4 deg below f1[4]): a reading error of 1 deg
    would be 10 deg of flow angle there - a failure; the model sets' lowest sensor gain (0.5) is
    not."""
    ps = calm.parameters
    f4 = float(ps.values[ps.index("f1[4]")])
    for gap_deg, fails in ((0.4, True), (4.0 * 0.6, False)):
        bent = dataclasses.replace(calm, parameters=ps.with_values({"f1[3]": f4 - np.radians(gap_deg)})
                                   .with_free({"f1[3]": False, "f1[4]": False}))
        res = estimate(bent, SolverOptions(start="given", diagnose=False, colored=False))
        found = [f for f in res.findings if f.code == "not_invertible"]
        assert bool(found) == fails, (gap_deg, [f.message for f in found])
