"""The compiled RK4 state + sensitivity kernel: same states as the plain RK4, exact sensitivities."""

from __future__ import annotations

import numpy as np
import pytest
from _kinematics_reference import integrate_rk4, integrate_sensitivities, specific_force_at_cg

from estimator.core.sensitivity import SENS_NAMES

G = 9.80665


def _case(n=900, rate_hz=32.0):
    t = np.arange(n) / rate_hz
    a = np.stack([np.sin(t) * 2, np.cos(0.5 * t), -9.8 + 3 * np.sin(0.7 * t)], 1)
    om = np.stack([0.3 * np.sin(0.9 * t), 0.1 * np.cos(1.3 * t), 0.05 * np.sin(0.4 * t)], 1)
    omd = np.gradient(om, t, axis=0)
    r = np.array([1.5, 0.1, 0.2])
    p = np.array([150, 2, 10, 0.1, 0.05, 0.3, 3000.0, 0.05, -0.02, 0.1, 0.002, -0.003, 0.001])
    return t, a, om, omd, r, p


def _run(case, p, lever_arm="differentiated"):
    t, a, om, omd, r, _ = case
    return integrate_sensitivities(t, p[:7], a, om, omd, r, p[7:10], p[10:13], G, lever_arm=lever_arm)


def test_states_agree_with_plain_rk4():
    case = _case()
    t, a, om, omd, r, p = case
    X, _ = _run(case, p)
    da, dw = p[7:10], p[10:13]
    Xr = integrate_rk4(t, p[:7], specific_force_at_cg(a - da, om - dw, omd, r), om - dw, G)
    # both are RK4 on the same grid; they differ only in how the lever-arm term is interpolated
    # to the half step (cubic midpoints of a_cg vs a_cg of cubic midpoints: O(dt^4))
    assert np.abs(X[:, :3] - Xr[:, :3]).max() < 1e-4
    assert np.abs(X[:, 3:6] - Xr[:, 3:6]).max() < 1e-6


def test_imu_point_states_agree_with_plain_rk4():
    case = _case()
    t, a, om, omd, r, p = case
    X, _ = _run(case, p, "imu_point")
    da, dw = p[7:10], p[10:13]
    w = om - dw
    # the IMU point's velocity: the state equations with the raw specific force, from V_cg0 + w x r
    x0 = p[:7].copy()
    x0[:3] += np.cross(w[0], r)
    Xr = integrate_rk4(t, x0, a - da, w, G)
    assert np.abs(X[:, :6] - Xr[:, :6]).max() < 1e-9
    # the CG's velocity from it agrees with the differentiated formulation (np.gradient's omega'
    # is accurate to ~1e-4 rad/s^2 here)
    Xd, _ = _run(case, p)
    assert np.abs(X[:, :3] - np.cross(w, r) - Xd[:, :3]).max() < 1e-3
    # the altitude is the CG's in both
    assert np.abs(X[:, 6] - Xd[:, 6]).max() < 1e-3


@pytest.mark.parametrize("lever_arm", ["differentiated", "imu_point"])
@pytest.mark.parametrize("j", range(13), ids=SENS_NAMES)
def test_sensitivities_match_central_differences(j, lever_arm):
    case = _case()
    p = case[-1]
    X, S = _run(case, p, lever_arm)
    h = 1e-6 * max(1.0, abs(p[j]))
    pp, pm = p.copy(), p.copy()
    pp[j] += h
    pm[j] -= h
    fd = (_run(case, pp, lever_arm)[0] - _run(case, pm, lever_arm)[0]) / (2 * h)
    scale = np.abs(S[:, :, j]).max()
    # central differences: truncation ~h^2 |X'''| (relative 1e-8 here) plus round-off
    # ~eps |X| / h, which for the 3000 m altitude state is ~1e-6
    roundoff = 10 * np.finfo(float).eps * np.abs(X).max() / h
    assert np.abs(fd - S[:, :, j]).max() <= 1e-7 * scale + roundoff, SENS_NAMES[j]
