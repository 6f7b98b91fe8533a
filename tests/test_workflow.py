"""The calibration workflow's arithmetic (issue 4): Mach bins, bias apportionment, alpha limit."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from estimator.workflow import alpha_limit, apportion, three_sigma


def test_apportionment_of_hand_made_biases():
    # three aircraft; the correction model's bias is +0.2 deg on both vanes, the installation
    # biases (fleet mean zero) are -0.1/+0.3, 0.0/-0.2 and +0.1/-0.1 deg
    model = 0.2
    inst_l = {"A": -0.1, "B": 0.0, "C": 0.1}
    inst_r = {"A": 0.3, "B": -0.2, "C": -0.1}
    left = {a: model + v for a, v in inst_l.items()}
    right = {a: model + v for a, v in inst_r.items()}
    ap = apportion(left, right)
    # (b_l + b_r)/2 per aircraft: 0.3, 0.1, 0.2; fleet mean 0.2 = the model update
    np.testing.assert_allclose(ap["mean_bias"], [0.3, 0.1, 0.2])
    np.testing.assert_allclose(ap["fleet_mean"], 0.2)
    np.testing.assert_allclose(ap["installation_mean"], [0.1, -0.1, 0.0], atol=1e-15)
    np.testing.assert_allclose(ap["installation_left"], list(inst_l.values()), atol=1e-15)
    np.testing.assert_allclose(ap["installation_right"], list(inst_r.values()), atol=1e-15)
    assert ap["std_fleet_mean"].isna().all()  # no covariance given, no deviations invented


def test_apportionment_deviations_follow_the_covariance():
    # independent biases of std s: fleet mean of n aircraft's (l + r)/2 has std s / sqrt(2n);
    # an installation bias b_l - M has variance s^2 (1 - 1/n + 1/(2n)) = s^2 (1 - 1/(2n))
    n, s = 4, 0.01
    ac = [f"a{i}" for i in range(n)]
    ap = apportion(dict.fromkeys(ac, 0.0), dict.fromkeys(ac, 0.0), np.eye(2 * n) * s**2)
    np.testing.assert_allclose(ap["std_fleet_mean"], s / np.sqrt(2 * n))
    np.testing.assert_allclose(ap["std_installation_left"], s * np.sqrt(1 - 1 / (2 * n)))
    np.testing.assert_allclose(ap["std_mean_bias"], s / np.sqrt(2))
    # and against a Monte Carlo of the same arithmetic
    rng = np.random.default_rng(3)
    draws = rng.normal(0.0, s, size=(20000, 2 * n))
    inst = draws[:, :n] - draws.mean(axis=1, keepdims=True)
    assert np.std(inst[:, 0]) == pytest.approx(ap["std_installation_left"].iloc[0], rel=0.03)


def test_apportionment_rejects_mismatched_aircraft():
    with pytest.raises(ValueError, match="same aircraft"):
        apportion({"A": 0.1}, {"B": 0.2})


def test_alpha_limit_is_where_the_error_first_grows_beyond_the_desired_value():
    rng = np.random.default_rng(0)
    alpha = rng.uniform(0.0, 20.0, 40000)
    # 3 sigma 0.15 deg below 12 deg, growing beyond (the nose probe's high-AOA irregularity)
    sigma = np.where(alpha < 12.0, 0.05, 0.05 + 0.2 * (alpha - 12.0))
    err = rng.normal(0.0, sigma)
    bands, limit = alpha_limit(alpha, err, desired_deg=0.5, band_deg=2.0, min_samples=200)
    assert limit == 12.0
    assert bands.loc[bands["alpha_lo_deg"] == 12.0, "passed"].item() is False
    assert three_sigma(np.array([1.0, -1.0])) == pytest.approx(3.0)
    # too few samples in a band: not judged, and no limit at all without judged bands
    bands, limit = alpha_limit(alpha[:50], err[:50], 0.5, 2.0, 200)
    assert limit is None and bands["passed"].isna().all()


def test_assign_bins_leaves_out_varying_mach_and_small_bins():
    from types import SimpleNamespace

    from estimator.workflow import WorkflowOptions, assign_bins

    def man(i, mean, lo, hi, gear=False):
        return SimpleNamespace(id=f"m{i}", aircraft="A", configuration="A",
                               meta={"mach_mean": mean, "mach_min": lo, "mach_max": hi, "gear_down": gear})

    mans = [man(0, 0.51, 0.50, 0.52), man(1, 0.49, 0.47, 0.51), man(2, 0.52, 0.45, 0.60),
            man(3, 0.70, 0.69, 0.71), man(4, 0.31, 0.30, 0.32, True), man(5, 0.48, 0.47, 0.49)]
    df = assign_bins(SimpleNamespace(maneuvers=mans), WorkflowOptions(min_maneuvers=2))
    df = df.set_index("id")
    assert list(df.loc[["m0", "m1", "m5"], "bin"]) == [0.5, 0.5, 0.5] and df.loc["m0", "used"]
    assert not df.loc["m2", "used"] and "varies" in df.loc["m2", "reason"]
    assert not df.loc["m3", "used"] and "only 1" in df.loc["m3", "reason"]
    assert not df.loc["m4", "used"] and "gear-down" in df.loc["m4", "reason"]
    assert isinstance(df, pd.DataFrame)
