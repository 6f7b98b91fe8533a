"""The FPR state equations and their RK4 integration, against an analytic trajectory.

The trajectory prescribes u, v, w and the Euler angles as sums of sinusoids; the rates follow from
the Euler-angle kinematics and the specific force from the velocity equations, so the state
equations hold exactly and only the integrator's error remains.
"""

from __future__ import annotations

import numpy as np
import pytest
from _kinematics_reference import integrate_rk4, specific_force_at_cg, state_derivative
from hypothesis import given, settings
from hypothesis import strategies as st

from campaigns.analytic_flight import G, analytic
from estimator.core.kinematics import smoothed_derivative


def _run(dt, exact_mid=True, T=20.0, params=None, midpoint="cubic"):
    inputs, states = analytic(params)
    t = np.arange(0.0, T + 1e-9, dt)
    a, om = inputs(t)
    mid = t[:-1] + dt / 2
    a_mid, om_mid = inputs(mid) if exact_mid else (None, None)
    x_ref = states(t)
    x = integrate_rk4(t, x_ref[0], a, om, G, a_mid, om_mid, midpoint=midpoint)
    return np.max(np.abs(x - x_ref), axis=0)


def test_state_equations_hold_on_analytic_trajectory():
    inputs, states = analytic()
    t = np.linspace(0, 10, 201)
    a, om = inputs(t)
    x = states(t)
    xdot_num = np.gradient(x, t, axis=0, edge_order=2)
    xdot = state_derivative(x, a, om, G)
    # central differences of smooth sinusoids at dt = 0.05 s are good to ~dt^2 * x''' / 6
    assert np.allclose(xdot[2:-2], xdot_num[2:-2], atol=5e-3), "state equations inconsistent"


def test_altitude_equation_sign_climb_is_positive():
    # level wings, nose 10 deg up, flying along the body x axis: h' = u sin(theta) > 0
    x = np.array([100.0, 0.0, 0.0, 0.0, np.radians(10.0), 0.0, 0.0])
    xd = state_derivative(x, np.array([0.0, 0.0, -G]), np.zeros(3), G)
    assert xd[6] == pytest.approx(100.0 * np.sin(np.radians(10.0)))
    # the paper's typo (w cos(theta) sin(phi)) would make a banked descent look level
    x = np.array([100.0, 0.0, 10.0, np.radians(60.0), 0.0, 0.0, 0.0])
    xd = state_derivative(x, np.zeros(3), np.zeros(3), G)
    assert xd[6] == pytest.approx(-10.0 * np.cos(np.radians(60.0)))


def test_rk4_is_fourth_order_with_exact_half_step_inputs():
    errs = [_run(dt)[[0, 1, 2, 3, 4, 6]].max() for dt in (0.2, 0.1, 0.05)]
    ratios = [errs[0] / errs[1], errs[1] / errs[2]]
    # fourth order: halving the step divides the global error by 2^4 = 16 (asymptotically)
    assert all(12.0 < r < 20.0 for r in ratios), f"error ratios {ratios}, errors {errs}"


def test_rk4_with_linearly_interpolated_inputs_is_second_order():
    # the half-step inputs interpolated linearly from samples cost two orders: ratio 2^2 = 4
    errs = [_run(dt, exact_mid=False, midpoint="linear")[[0, 1, 2]].max() for dt in (0.1, 0.05, 0.025)]
    ratios = [errs[0] / errs[1], errs[1] / errs[2]]
    assert all(3.0 < r < 5.0 for r in ratios), f"error ratios {ratios}, errors {errs}"


def test_rk4_with_cubic_midpoints_keeps_fourth_order_on_sampled_inputs():
    # four-point cubic midpoints are exact to O(dt^4): RK4 on samples alone is fourth order again
    errs = [_run(dt, exact_mid=False, midpoint="cubic")[[0, 1, 2]].max() for dt in (0.1, 0.05, 0.025)]
    ratios = [errs[0] / errs[1], errs[1] / errs[2]]
    assert all(12.0 < r < 20.0 for r in ratios), f"error ratios {ratios}, errors {errs}"
    linear = _run(0.05, exact_mid=False, midpoint="linear")[[0, 1, 2]].max()
    assert errs[1] < linear / 20, "cubic midpoints must beat linear ones by far at 20 Hz"


@settings(max_examples=15, deadline=None)
@given(
    au=st.floats(0.0, 20.0), av=st.floats(0.0, 10.0), aw=st.floats(0.0, 10.0),
    aphi=st.floats(0.0, 1.2), ath=st.floats(0.0, 0.4),
)
@pytest.mark.slow
def test_zero_error_inputs_reproduce_the_trajectory(au, av, aw, aphi, ath):
    params = dict(au=au, av=av, aw=aw, aphi=aphi, ath=ath)
    err = _run(0.02, T=10.0, params=params)
    # RK4 at 50 Hz on these gentle sinusoids: local error ~ dt^5 x^(5) / 2880 -> far below 1e-6
    assert err[:3].max() < 1e-6 and err[3:6].max() < 1e-8 and err[6] < 1e-5, err


def test_lever_arm_round_trip():
    rng = np.random.default_rng(1)
    om = rng.normal(size=(50, 3))
    omd = rng.normal(size=(50, 3))
    a_cg = rng.normal(size=(50, 3))
    r = np.array([1.5, 0.1, 0.2])
    a_imu = a_cg + np.cross(omd, r) + np.cross(om, np.cross(om, r))
    assert np.allclose(specific_force_at_cg(a_imu, om, omd, r), a_cg, atol=1e-12)


def test_smoothed_derivative_of_sinusoid():
    t = np.arange(0, 10, 0.025)
    y = np.sin(2.0 * t)
    d = smoothed_derivative(t, y, window_s=0.25)
    # quadratic Savitzky-Golay over 0.25 s: bias ~ w^3 T^2 / 40 relative; far below 1 %
    assert np.max(np.abs(d[10:-10] - 2.0 * np.cos(2.0 * t[10:-10]))) < 0.02
