"""Recovery test (issue 3, must-show 1): the estimator recovers injected values from JSBSim data.

JSBSim flies 14 maneuvers (pitch doublet, 3211, wind-up turn, SHSS in three segments, pull-up
with rudder doublets; two configurations, one with the nose probe and one with the boom) with
every error source of the synthesizer on and noise on (flow-angle, pressure, INS, DGPS noise,
quantization, delays, installation biases, scale factors, IMU biases, steady wind). The local-flow
truth and the airdata computer's baseline are the linear, model-representable pair
(``aircraft_models/local_flow_linear.toml``), so the model structure of
``estimator/models/tejas.toml`` can represent the truth and any deviation is estimation error,
to be judged against the Cramér-Rao bound.

IMU noise is off: SPEC §6's typical-error table lists none, and in the output-error method it
acts as unmodelled process noise (it is integrated into the states), for which the Cramér-Rao
bound of the OEM is not the right yardstick (a filter-error method would be).

The truth of every parameter comes from :mod:`campaigns.truth` (injected values; calibration
parameters as the projection of the true system onto the model structure).
"""

from __future__ import annotations

import time
import warnings

import pandas as pd
import pytest
from _campaigns import linear_campaign

from campaigns.truth import recovery_table, true_parameters
from estimator.io import problem_from_dataset
from estimator.parameters import family_of
from estimator.solver import SolverOptions, estimate

#: 14 maneuvers flown and estimated once for the module: ~5 s
pytestmark = pytest.mark.slow

CAMPAIGN = linear_campaign("recovery", 11, [{
    "configurations": ["PV1-NP", "PT1-BOOM"],
    "mach": [0.6],
    "maneuvers": ["pitch_doublet", "3211", "windup_turn", "shss", "pullup_rudder_doublets"],
    "altitude_m": 6000.0,
}], wind_ned_mps=[6.0, -4.0, 0.0], turbulence="none", quiet_imu=True)

#: Every parameter's estimate must lie within this many Cramér-Rao standard deviations of its truth.
Z_MAX = 3.0

#: Known deviations, checked separately (strict xfail: the day they pass, this list must shrink).
#: The nose-probe gain table f5 at alpha 4 deg (z = -3.2, 0.0008 in gain, 0.004 deg of sideslip at
#: 4.5 deg; f5 at 12 deg is +2.6 sigma the other way, the four f5 values together chi2 = 17.9 on 4
#: degrees of freedom): the nose probe's truth is not exactly representable by the four-breakpoint
#: gain table, the projection leaves 0.00026 deg rms (campaigns.truth structure_rms), and with
#: ~20,000 samples of 0.019 deg noise the Cramér-Rao resolution (~0.00013 deg) is finer than that
#: structure error, so the estimate and the projection (clean signals, equal weights) may split
#: it differently. Not the qc lag, not the vane lag of f_np's AOA input (aligning both to the
#: probe's lag leaves it unchanged). 1 of the 134 checked estimates is beyond 3 sigma (0.36
#: expected by chance); all 50 global ones together chi2 = 65 on 50 (p = 0.07).
#: Fixed since: the per-maneuver daz/dq of the sharpest pitch maneuvers (|z| 3.0-4.3) and
#: tau_dgps (z = 5.6) came from the 10 Hz DGPS height being interpolated onto the 40 Hz base (a
#: low-pass the model read as a delay); it is now fitted at its own samples (own-rate channels),
#: and tau_h, held at 0 while its truth is -7.8 ms, is free.
#: Other seeds: seed 12 puts the vane biases and f1 off by ~0.005 deg together (one direction of
#: highly correlated parameters, up to 4.6 sigma): the Monte Carlo campaigns of issue 5 measure
#: whether the Cramér-Rao bound is honest across replications.
#: Since the flaperon fix of issue 13 (1bb5560: gear-down and turning flights on the aircraft's own
#: lift curve) f5[1] flies at z = -2.06 in this campaign: no known deviation is left.
_KNOWN: tuple[str, ...] = ()


@pytest.fixture(scope="module")
def recovery(fly_once) -> pd.DataFrame:
    t0 = time.perf_counter()
    out = fly_once(CAMPAIGN, "test_recovery")
    t_fly = time.perf_counter() - t0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        problem = problem_from_dataset(out, overrides={"h0": {"free": True}})
        result = estimate(problem, SolverOptions())
    table = recovery_table(result, true_parameters(problem, result.free_estimated))
    with pd.option_context("display.width", 200, "display.max_rows", 500):
        shown = table[~table["kind"].isin(["initial_condition"])]
        print(f"\nflown in {t_fly:.1f} s, estimated in {time.perf_counter() - t0 - t_fly:.1f} s "
              f"({len(problem.maneuvers)} maneuvers): {result.message}")
        print(shown[["kind", "value_display", "truth_display", "std_crb_display", "z_crb",
                     "display_unit"]].to_string(float_format=lambda v: f"{v: .5g}"))
    assert result.status == 1, result.message
    return table


CHECKED_KINDS = ("imu_bias", "time_delay", "bias", "scale", "table")


def _outliers(table: pd.DataFrame) -> pd.DataFrame:
    t = table[table["kind"].isin(CHECKED_KINDS)]
    return t[~(t["z_crb"].abs() < Z_MAX)]


def test_recovery_within_three_cramer_rao_sigmas(recovery):
    checked = recovery[recovery["kind"].isin(CHECKED_KINDS)]
    # every kind the issue names is in the table (nothing silently lost to a missing truth)
    assert set(checked["kind"]) == set(CHECKED_KINDS)
    for name in ("b_l", "b_r", "b_sa", "b_sb", "b_n", "b_ba", "b_bu", "b_bl",
                 "k_ba", "k_bu", "k_bl", "k_spr", "f1", "f2", "f3", "f4", "f5", "tau_sp"):
        assert any(family_of(k) == name for k in checked.index), f"no truth for {name}"
    bad = _outliers(recovery)
    bad = bad[~bad.index.isin(list(_KNOWN))]
    assert bad.empty, f"estimates beyond {Z_MAX} Cramér-Rao sigmas:\n{bad.to_string()}"

