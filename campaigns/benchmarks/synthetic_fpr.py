"""Synthetic flight-test campaigns for the estimator benchmark, without JSBSim.

Each maneuver is an *analytic* flight: u, v, w and the Euler angles are sums of sinusoids (random
mean speed, angle of attack, bank, amplitudes, frequencies and phases), the body rates follow
from the Euler-angle kinematics and the specific force from the velocity equations, so the
flat-earth state equations (SPEC §3) hold exactly. The IMU sits away from the CG (lever arm), its
accelerometers and gyros carry per-maneuver biases; altitude is the quadrature of ``h'``. The
measured channels are the paper's Table 1 models (``estimator/models/tejas.toml``) applied to
the exact flow at each sensor, ``V + omega x (r_s - r_cg)`` at ``t - tau``, with per-aircraft
biases, shared correction tables and white noise; DGPS height is the geometric altitude with a
per-maneuver offset. So the estimator's model fits the data to the noise, and a benchmark
measures the solver, not a model mismatch.

A fleet of five aircraft: three with the nose probe, two with the flight-test boom (paper §3),
each with its own CG and installation biases. Data are generated in memory in about a second for
70 maneuvers, independently of the estimator's code: the kinematics, the lever arms and the channel
models are those of :mod:`campaigns.analytic_flight`, the estimator tests' analytic flight.

Optionally the campaign is flown in turbulence (``turbulence=(sigma_mps, L_m, seed)``), as
:class:`campaigns.analytic_flight.Flight` flies it: a turbulent wind ``dW`` (NED; three independent
first-order Gauss-Markov components, :func:`~campaigns.analytic_flight.gauss_markov_wind`, at the
maneuver's mean airspeed) moves the air, so the flow channels (vanes, probes, boom) and the
airspeed see ``V - C_bn dW``, while the IMU, the attitude, the altitude and the DGPS height follow
the (ground-relative) flight. Each maneuver has its own draw from its own generator, seeded by
``(seed, maneuver number)``: the main generator's stream (trajectories, truth, noise) is the
calm campaign's, so a turbulent campaign differs from the calm one by the wind alone, and without
turbulence the data are those generated before the option existed.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.integrate import cumulative_simpson

from campaigns.analytic_flight import (
    DEG,
    NOISE_SIGMA,
    SENSORS,
    TABLES,
    ChannelTruth,
    G,
    Sinus,
    gauss_markov_wind,
    imu_inputs,
    kinematic_flight,
    local_flow,
    ned_to_body,
    tejas_channels,
    truth_tables,
)
from estimator.io.modelset import finalize_parameters, load_model_set
from estimator.problem import ManeuverData, Problem, expand_parameters

#: aircraft id -> carries the boom (else the nose probe)
FLEET = {"PV1": False, "PV2": False, "PV3": False, "PT1": True, "PT2": True}
NOISE = {**NOISE_SIGMA, "h_dgps": 0.5, "alpha_zb": 0.05 * DEG, "beta_zbu": 0.05 * DEG, "beta_zbl": 0.05 * DEG}
TAUS = {"tau_phi": 0.02, "tau_theta": 0.02, "tau_psi": 0.02, "tau_tas": 0.0, "tau_h": 0.0, "tau_dgps": 0.1,
        "tau_alpha_zl": 0.03, "tau_alpha_zr": 0.045, "tau_sp": 0.08, "tau_np": 0.06,
        "tau_ba": 0.01, "tau_bu": 0.015, "tau_bl": 0.015}
SCALES = {"k_ba": 0.02, "k_bu": -0.03, "k_bl": 0.025}


def _trajectory(rng: np.random.Generator):
    """A random analytic flight: (inputs(t) -> (a_cg, omega), states(t) -> (N, 6) without h)."""
    def terms(n, amp, wlo=0.3, whi=2.5):
        return tuple((amp * rng.uniform(0.3, 1.0), rng.uniform(wlo, whi), rng.uniform(0, 2 * np.pi))
                     for _ in range(n))

    speed = rng.uniform(110.0, 230.0)
    alpha0 = rng.uniform(-1.0, 16.0) * DEG
    u = Sinus(speed * np.cos(alpha0), terms(2, 0.05 * speed, 0.1, 0.6))
    v = Sinus(0.0, terms(2, 0.05 * speed))
    w = Sinus(speed * np.sin(alpha0), terms(2, 0.06 * speed))
    phi = Sinus(rng.uniform(-0.3, 0.3), terms(2, 0.6))
    th = Sinus(alpha0 + rng.uniform(-0.05, 0.1), terms(2, 0.15))
    psi = Sinus(rng.uniform(-np.pi, np.pi), terms(1, 0.1, 0.1, 0.5), slope=rng.uniform(-0.05, 0.05))
    return kinematic_flight(u, v, w, phi, th, psi)


def _tables(specs: dict, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Truth correction tables near the model set's start values (f1(0) = f3(0) = 0 as held)."""
    return truth_tables({n: np.asarray(specs[n].breakpoints) for n in TABLES},
                        {n: rng.normal(size=len(specs[n].breakpoints)) for n in TABLES})


def _maneuver(mid: str, aircraft: str, duration_s: float, rate_hz: float, truth: dict,
              rng: np.random.Generator, turbulence: tuple[float, float, int] | None = None,
              number: int = 0) -> ManeuverData:
    inputs, states = _trajectory(rng)
    boom = FLEET[aircraft]
    r_cg = np.array([0.33, 0.0, 0.13]) + rng.normal(0.0, [0.05, 0.005, 0.01])
    t = np.arange(int(round(duration_s * rate_hz)) + 1) / rate_hz
    a_imu, om = imu_inputs(inputs, t, SENSORS["imu"] - r_cg)
    da = rng.normal(0.0, 0.1, 3)
    dw = rng.normal(0.0, 0.2 * DEG, 3)
    # altitude: quadrature of h' on a grid 16x finer than the samples (Simpson, error ~1e-9 m)
    sub = 16
    t_fine = np.arange(-sub * int(0.4 * rate_hz), sub * (t.size - 1) + 1) / (sub * rate_hz)
    x = states(t_fine)
    u, v, w, ph, th = x[:, 0], x[:, 1], x[:, 2], x[:, 3], x[:, 4]
    hdot = u * np.sin(th) - v * np.cos(th) * np.sin(ph) - w * np.cos(th) * np.cos(ph)
    h_fine = rng.uniform(2000.0, 9000.0) + cumulative_simpson(hdot, x=t_fine, initial=0.0)

    def states_at(ts):
        return np.column_stack([states(ts), np.interp(ts, t_fine, h_fine)])

    meta = {}
    flow_states = states_at
    if turbulence is not None:
        sigma_mps, L_m, seed = turbulence
        # the Dryden correlation at the maneuver's mean airspeed; drawn exactly on the fine grid,
        # from a generator of its own (the main stream stays the calm campaign's)
        v_mean_mps = float(np.linalg.norm(x[:, :3], axis=1).mean())
        gust = gauss_markov_wind(t_fine, sigma_mps, L_m, v_mean_mps,
                                 np.random.default_rng([int(seed), number]))

        def wind_at(ts):
            return np.stack([np.interp(ts, t_fine, d) for d in gust.T], 1)

        def flow_states(ts):
            # the air's velocity relative to the aircraft, V - C_bn dW; attitude and altitude as flown
            xs = states_at(ts)
            xs[:, :3] -= np.einsum("nij,nj->ni", ned_to_body(xs[:, 3:6]), wind_at(ts))
            return xs

        meta = {"wind_ned_mps": wind_at(t), "turbulence": (float(sigma_mps), float(L_m), int(seed))}

    def flow(ts, sensor):
        return local_flow(flow_states(ts), inputs(ts)[1], SENSORS[sensor] - r_cg)

    ac = truth["aircraft"][aircraft]
    # the attitude and altitude channels are the same either way (flow_states changes the
    # velocity only)
    meas = tejas_channels(t, flow_states, inputs, SENSORS, r_cg,
                          ChannelTruth(TAUS, ac, truth["tables"], truth["breakpoints"]), nose_probe=not boom)
    # DGPS height: geometric (pressure altitude here is geometric too: k_h = 0), its own offset;
    # listed after h (the noise below is drawn in this order)
    dgps = states_at(t - TAUS["tau_dgps"])[:, 6] + rng.uniform(-30.0, 30.0)
    items = list(meas.items())
    after_h = list(meas).index("h") + 1
    meas = dict(items[:after_h] + [("h_dgps", dgps)] + items[after_h:])
    if boom:
        ts = t - TAUS["tau_ba"]
        meas["alpha_zb"] = (1.0 + SCALES["k_ba"]) * flow(ts, "boom_alpha_vane")[0] + ac["b_ba"]
        for ch, sensor, k in (("beta_zbu", "boom_beta_upper_vane", "bu"),
                              ("beta_zbl", "boom_beta_lower_vane", "bl")):
            fl = flow(t - TAUS[f"tau_{k}"], sensor)[2]
            meas[ch] = (1.0 + SCALES[f"k_{k}"]) * fl + ac[f"b_{k}"]
    for c in meas:
        meas[c] = meas[c] + rng.normal(0.0, NOISE[c], t.size)
    return ManeuverData(
        id=mid, t_s=t, accel_imu_mps2=a_imu + da, omega_rps=om + dw, measurements=meas,
        r_cg_body_m=r_cg, aircraft=aircraft, configuration=aircraft, source=f"synthetic {mid}",
        meta={"imu_bias": np.concatenate([da, dw]), **meta},
    )


def synthetic_problem(n_maneuvers: int, seed: int = 1, rate_hz: float = 32.0,
                      duration_s: tuple[float, float] = (30.0, 40.0),
                      turbulence: tuple[float, float, int] | None = None) -> Problem:
    """A campaign of ``n_maneuvers`` analytic maneuvers as an estimation problem.

    Parameters
    ----------
    n_maneuvers : number of maneuvers, spread round-robin over the five aircraft of :data:`FLEET`.
    seed : random seed (trajectories, truth, noise); the same seed gives the same problem.
    rate_hz : sample rate, Hz.
    duration_s : maneuver lengths are uniform in this range, s.
    turbulence : ``(sigma_mps, L_m, seed)``: the campaign flown in turbulence of intensity
        ``sigma_mps`` (m/s, each NED component) and scale length ``L_m`` (m; Dryden above 2000 ft:
        533.4), maneuver ``k``'s wind drawn from ``default_rng([seed, k])`` (module docstring);
        the draw at the samples is ``meta["wind_ned_mps"]`` (n, 3). None: calm air.

    Returns
    -------
    The problem with every channel of the ``tejas`` model set that has data, the default free
    parameters plus ``h0`` (so each maneuver has 13 free initial conditions and IMU biases), start
    values as a user gets them (initial conditions from the first samples, everything else at the
    model set's start values), and the truth (the IMU biases, with turbulence the wind) in
    ``problem.maneuvers[k].meta``.
    """
    rng = np.random.default_rng(seed)
    channels, specs = load_model_set("tejas")
    spec_map = {s.name: s for s in specs}
    truth = {
        "tables": _tables(spec_map, rng),
        "breakpoints": {n: np.asarray(spec_map[n].breakpoints) for n in TABLES},
        "aircraft": {a: {n: rng.uniform(-0.5, 0.5) * DEG for n in
                         ("b_l", "b_r", "b_sa", "b_sb", "b_n", "b_ba", "b_bu", "b_bl")} for a in FLEET},
    }
    fleet = list(FLEET)
    mans = [_maneuver(f"m{k:04d}", fleet[k % len(fleet)], rng.uniform(*duration_s), rate_hz, truth, rng,
                      turbulence, k)
            for k in range(n_maneuvers)]
    specs = [replace(s, free=True) if s.name == "h0" else s for s in specs]
    present = {c for m in mans for c in m.measurements}
    channels = [c for c in channels if c.column in present]
    final = finalize_parameters(specs, set(), channels, mans, "synthetic")
    ps = expand_parameters(final, mans, channels)
    return Problem(tuple(mans), tuple(channels), SENSORS, SENSORS["imu"], ps, G, f"synthetic({n_maneuvers})")
