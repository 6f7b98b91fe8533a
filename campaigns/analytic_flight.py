"""Analytic flights: states, IMU inputs and air-data channels that satisfy SPEC §3 exactly.

u, v, w and the Euler angles are sums of sinusoids (:class:`Sinus`); the body rates follow from
the Euler-angle kinematics and the specific force from the velocity equations
(:func:`kinematic_flight`), so the flat-earth state equations hold exactly and only numerical
errors of the code under test remain. The measured channels are the paper's Table 1 models
(``estimator/models/tejas.toml``) applied by hand to the exact flow at each sensor,
``V + omega x (r_s - r_cg)`` at ``t - tau`` (:func:`tejas_channels`), independently of the
estimator's model code.

Two users build on these pieces:

- :class:`Flight`: the estimator tests' two-maneuver flight with fixed trajectories
  (:func:`analytic`) and injected truth (:func:`truth_values`), as an estimation problem; also the
  problem of the coloured-noise benchmark (``campaigns/benchmarks/bench_colored.py``);
- ``campaigns/benchmarks/synthetic_fpr.py``: random trajectories, a fleet, a boom and noise.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import NamedTuple

import numpy as np
from scipy.integrate import solve_ivp

from estimator.io.modelset import load_model_set
from estimator.problem import ManeuverData, Problem, expand_parameters

G = 9.80665
DEG = np.pi / 180.0
#: Sensor positions, body axes, m (the nose-probe aircraft's and the flight-test boom's).
SENSORS = {
    "imu": np.array([1.80, 0.10, 0.20]),
    "vane_left": np.array([6.20, -0.45, 0.25]),
    "vane_right": np.array([6.20, 0.45, 0.25]),
    "side_probe": np.array([6.60, 0.0, 0.05]),
    "nose_probe": np.array([8.30, 0.0, 0.22]),
    "boom_alpha_vane": np.array([9.40, 0.0, 0.22]),
    "boom_beta_upper_vane": np.array([9.55, 0.0, 0.12]),
    "boom_beta_lower_vane": np.array([9.55, 0.0, 0.32]),
    "ins": np.array([2.40, -0.10, 0.25]),
}
TABLES = ("f1", "f2", "f3", "f4", "f5")
#: White measurement noise of the channels, standard deviations (SI).
NOISE_SIGMA = {"phi": 0.03 * DEG, "theta": 0.03 * DEG, "psi": 0.03 * DEG, "tas": 0.3, "h": 1.0,
               "alpha_zl": 0.07 * DEG, "alpha_zr": 0.07 * DEG, "alpha_zsp": 0.1 * DEG,
               "beta_zsp": 0.1 * DEG, "beta_znp": 0.1 * DEG, "vn": 0.05, "ve": 0.05, "vd": 0.05}

#: A trajectory: inputs(t) -> (specific force at the CG, body rates), states(t) -> (N, 6 or 7).
Inputs = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
States = Callable[[np.ndarray], np.ndarray]


class Sinus:
    """``f(t) = bias + slope t + sum A sin(w t + phase)``, with its derivative.

    ``terms``: ``(A, w, phase)`` triples, w in rad/s.
    """

    def __init__(self, bias: float, terms=(), slope: float = 0.0):
        self.bias, self.terms, self.slope = bias, terms, slope

    def __call__(self, t):
        return self.bias + self.slope * t + sum(a * np.sin(w * t + ph) for a, w, ph in self.terms)

    def d(self, t):
        return self.slope + sum(a * w * np.cos(w * t + ph) for a, w, ph in self.terms)


def kinematic_flight(u: Sinus, v: Sinus, w: Sinus, phi: Sinus, theta: Sinus, psi: Sinus
                     ) -> tuple[Inputs, States]:
    """The inputs and states (u, v, w m/s; phi, theta, psi rad; no altitude) of the trajectory.

    Returns
    -------
    inputs : t_s -> ((N, 3) specific force at the CG m/s^2, (N, 3) body rates rad/s), from the
        Euler-angle kinematics and the flat-earth velocity equations, exact.
    states : t_s -> (N, 6) states.
    """
    def inputs(t):
        ph, tt = phi(t), theta(t)
        phd, thd, psd = phi.d(t), theta.d(t), psi.d(t)
        p = phd - psd * np.sin(tt)
        q = thd * np.cos(ph) + psd * np.cos(tt) * np.sin(ph)
        r = -thd * np.sin(ph) + psd * np.cos(tt) * np.cos(ph)
        uu, vv, ww = u(t), v(t), w(t)
        ax = u.d(t) - (r * vv - q * ww - G * np.sin(tt))
        ay = v.d(t) - (p * ww - r * uu + G * np.cos(tt) * np.sin(ph))
        az = w.d(t) - (q * uu - p * vv + G * np.cos(tt) * np.cos(ph))
        return np.stack([ax, ay, az], -1), np.stack([p, q, r], -1)

    def states(t):
        return np.stack([u(t), v(t), w(t), phi(t), theta(t), psi(t)], -1)

    return inputs, states


def analytic(params: dict | None = None) -> tuple[Inputs, States]:
    """The estimator tests' fixed trajectory (150 m/s, amplitudes ``params`` may change).

    ``states(t, h0=3000.0)`` adds the altitude, m, by integrating ``h'`` (tolerance 1e-10 m);
    ``h0=None`` leaves it NaN (for a caller that interpolates an altitude integrated once).
    """
    p = params or {}
    u = Sinus(150.0, ((p.get("au", 5.0), 0.4, 0.0),))
    v = Sinus(0.0, ((p.get("av", 3.0), 0.9, 0.2),))
    w = Sinus(10.0, ((p.get("aw", 4.0), 0.6, 1.0),))
    phi = Sinus(0.0, ((p.get("aphi", 0.5), 0.7, 0.0),))
    th = Sinus(0.1, ((p.get("ath", 0.2), 0.5, 0.3),))
    psi = Sinus(0.4, ((0.1, 0.3, 0.0),), slope=0.05)
    inputs, six = kinematic_flight(u, v, w, phi, th, psi)

    def states(t, h0=3000.0):
        def hdot(tt, h):
            return [u(tt) * np.sin(th(tt)) - v(tt) * np.cos(th(tt)) * np.sin(phi(tt))
                    - w(tt) * np.cos(th(tt)) * np.cos(phi(tt))]
        if h0 is None:
            h = np.full(t.size, np.nan)
        elif t.size == 1:
            h = np.array([h0])
        else:
            h = solve_ivp(hdot, (t[0], t[-1]), [h0], t_eval=t, rtol=1e-12, atol=1e-10).y[0]
        return np.column_stack([six(t), h])

    return inputs, states


def imu_inputs(inputs: Inputs, t_s: np.ndarray, r_imu_from_cg_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact specific force at the IMU (lever arm ``r_imu_from_cg_m``, m) and body rates at ``t_s``.

    The angular acceleration is a central difference (step 1e-5 s: error ~1e-10 rad/s^2).
    """
    a_cg, om = inputs(t_s)
    eps = 1e-5
    omd = (inputs(t_s + eps)[1] - inputs(t_s - eps)[1]) / (2 * eps)
    r = r_imu_from_cg_m
    return a_cg + np.cross(omd, r) + np.cross(om, np.cross(om, r)), om


def local_flow(x: np.ndarray, omega_rps: np.ndarray, r_from_cg_m: np.ndarray | None):
    """Flow at a sensor ``r_from_cg_m`` (m; None: the CG) from states ``x`` (N, >= 3) and rates.

    Returns alpha, beta, flank angle ``atan2(v, u)`` (rad) and airspeed (m/s), each (N,).
    """
    vel = x[:, :3] + (np.cross(omega_rps, r_from_cg_m) if r_from_cg_m is not None else 0.0)
    speed = np.linalg.norm(vel, axis=1)
    return (np.arctan2(vel[:, 2], vel[:, 0]), np.arcsin(vel[:, 1] / speed),
            np.arctan2(vel[:, 1], vel[:, 0]), speed)


def truth_tables(breakpoints: dict[str, np.ndarray], z: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Truth correction tables near the model set's start values from standard normal draws ``z``
    (one per breakpoint); f1(0) = f3(0) = 0 as the model set holds them."""
    out = {
        "f1": breakpoints["f1"] * (1.0 + 0.03 * z["f1"]),
        "f2": 0.1 + 0.05 * z["f2"],
        "f3": 0.3 * DEG * z["f3"],
        "f4": 0.05 * z["f4"],
        "f5": 1.0 + 0.05 * z["f5"],
    }
    out["f1"][np.argmin(np.abs(breakpoints["f1"]))] = 0.0
    out["f3"][np.argmin(np.abs(breakpoints["f3"]))] = 0.0
    return out


class ChannelTruth(NamedTuple):
    """The true parameters of the ``tejas`` channels: ``taus``, the time delays by parameter name
    (``tau_phi``, ..., ``tau_alpha_zl``, ``tau_sp``, ``tau_np``); ``biases``: ``b_l``, ``b_r``,
    ``b_sa``, ``b_sb`` (and ``b_n`` with the nose probe), and the vanes' sideslip reference offset
    ``c_vb`` of ``tejas_ins`` if given (0 otherwise: the ``tejas`` model has none); the correction
    ``tables`` f1..f5 by name and their ``breakpoints``."""

    taus: Mapping[str, float]
    biases: Mapping[str, float]
    tables: Mapping[str, np.ndarray]
    breakpoints: Mapping[str, np.ndarray]


def tejas_channels(t_s: np.ndarray, states_at: States, inputs: Inputs, sensors: dict[str, np.ndarray],
                   r_cg_m: np.ndarray, truth: ChannelTruth, nose_probe: bool = True) -> dict[str, np.ndarray]:
    """Noise-free channels of the ``tejas`` model set at ``t_s`` (SI), applied by hand.

    ``states_at(t)``: (N, 7) states with altitude; ``truth``: the channels' delays, biases and
    tables. Attitude, altitude and airspeed; the two vanes; the side probe (its angle-of-attack
    model is implicit: a fixed point, a contraction); with ``nose_probe``, its sideslip.
    """
    taus, biases, tables, breakpoints = truth

    def flow(ts, sensor):
        return local_flow(states_at(ts), inputs(ts)[1], sensors[sensor] - r_cg_m if sensor else None)

    def tab(name, arg):
        return np.interp(arg, breakpoints[name], tables[name])

    meas = {}
    for name, idx in (("phi", 3), ("theta", 4), ("psi", 5), ("h", 6)):
        meas[name] = states_at(t_s - taus[f"tau_{name}"])[:, idx]
    meas["tas"] = flow(t_s - taus["tau_tas"], None)[3]
    for ch, sensor, sign in (("alpha_zl", "vane_left", -1.0), ("alpha_zr", "vane_right", 1.0)):
        ts = t_s - taus[f"tau_{ch}"]
        a_s, b_s, _, _ = flow(ts, sensor)
        meas[ch] = (tab("f1", a_s) + sign * tab("f2", flow(ts, None)[0]) * (b_s + biases.get("c_vb", 0.0))
                    + biases[f"b_{ch[-1]}"])
    a_s, b_s, _, _ = flow(t_s - taus["tau_sp"], "side_probe")
    z = a_s.copy()
    # alpha_zsp = alpha_s + f3(alpha_zsp) + b_sa: a contraction (|f3'| << 1); on these flights it
    # reaches its fixed point to the last bit in fewer than 30 iterations
    for _ in range(60):
        z = a_s + tab("f3", z) + biases["b_sa"]
    meas["alpha_zsp"] = z
    meas["beta_zsp"] = (b_s + biases["b_sb"]) / (1.0 - tab("f4", z))
    if nose_probe:
        ts = t_s - taus["tau_np"]
        _, b_s, _, _ = flow(ts, "nose_probe")
        meas["beta_znp"] = tab("f5", flow(ts, None)[0]) * (b_s + biases["b_n"])
    return meas


# ----------------------------------------------------------------------------- the tests' flight
R_CG = np.array([0.33, 0.0, 0.13])
CHANNELS = ["phi", "theta", "psi", "tas", "h", "alpha_zl", "alpha_zr", "alpha_zsp", "beta_zsp", "beta_znp"]
#: The INS velocity channels (model set ``tejas_ins``) and their delays in :class:`Flight` with ``ins``.
INS_CHANNELS = ("vn", "ve", "vd")
INS_DELAYS_S = {"tau_vn": 0.012, "tau_ve": 0.012, "tau_vd": 0.012}
RATE_HZ = 40.0
#: The sensors of :class:`Flight` (no boom).
FLIGHT_SENSORS = {k: SENSORS[k] for k in ("imu", "vane_left", "vane_right", "side_probe", "nose_probe")}


def ned_to_body(euler_rad: np.ndarray) -> np.ndarray:
    """``C_bn`` (N, 3, 3), NED to body axes, from Euler angles (N, 3) (phi, theta, psi), rad."""
    ph, th, ps = euler_rad[:, 0], euler_rad[:, 1], euler_rad[:, 2]
    c1, s1, c2, s2, c3, s3 = np.cos(ps), np.sin(ps), np.cos(th), np.sin(th), np.cos(ph), np.sin(ph)
    r3 = np.zeros((ph.size, 3, 3))  # psi about z
    r3[:, 0, 0], r3[:, 0, 1], r3[:, 1, 0], r3[:, 1, 1], r3[:, 2, 2] = c1, s1, -s1, c1, 1.0
    r2 = np.zeros((ph.size, 3, 3))  # theta about y
    r2[:, 0, 0], r2[:, 0, 2], r2[:, 1, 1], r2[:, 2, 0], r2[:, 2, 2] = c2, -s2, 1.0, s2, c2
    r1 = np.zeros((ph.size, 3, 3))  # phi about x
    r1[:, 0, 0], r1[:, 1, 1], r1[:, 1, 2], r1[:, 2, 1], r1[:, 2, 2] = 1.0, c3, s3, -s3, c3
    return r1 @ r2 @ r3


def gauss_markov_wind(t_s: np.ndarray, sigma_mps: float, L_m: float, v_mps: float,
                      rng: np.random.Generator) -> np.ndarray:
    """Three independent first-order Gauss-Markov components (N, 3) on a uniform grid, stationary
    from the start: ``x[k+1] = a x[k] + sigma sqrt(1 - a^2) n``, ``a = exp(-V dt / L)`` (exact)."""
    a = np.exp(-v_mps * float(t_s[1] - t_s[0]) / L_m)
    n = rng.standard_normal((t_s.size, 3))
    x = np.empty((t_s.size, 3))
    x[0] = sigma_mps * n[0]
    q = sigma_mps * np.sqrt(1.0 - a * a)
    for k in range(1, t_s.size):
        x[k] = a * x[k - 1] + q * n[k]
    return x


def dryden_body_wind(t_s: np.ndarray, sigma_mps: float, L_m: float, v_mps: float,
                     rng: np.random.Generator) -> np.ndarray:
    """MIL-F-8785C Dryden turbulence in body axes, stationary from the start: the five states of
    :func:`estimator.core.wind_filter.dryden_body` stepped exactly (``x[k+1] = Phi x[k] + G n``,
    ``G G^T = Qd``) and mapped to (u, v, w) by its ``DRYDEN_OUTPUT``.

    Parameters
    ----------
    t_s : (N,) uniform time grid, s.
    sigma_mps : intensity of each component, m/s.
    L_m : scale length, m.
    v_mps : airspeed, m/s (Taylor's hypothesis).
    rng : random generator.

    Returns
    -------
    (N, 3) turbulent wind in body axes (u, v, w), m/s.
    """
    from estimator.core.wind_filter import DRYDEN_OUTPUT, dryden_body

    Phi, Qd, P0 = dryden_body(v_mps, L_m, sigma_mps, float(t_s[1] - t_s[0]))
    # Qd's second-order pairs are nearly singular for tiny steps (the noise enters the derivative
    # state only): their Cholesky factor from the eigen-decomposition, not numpy's cholesky
    w, V = np.linalg.eigh(Qd)
    G = V * np.sqrt(np.maximum(w, 0.0))
    n = rng.standard_normal((t_s.size, 5))
    x = np.empty((t_s.size, 5))
    x[0] = np.sqrt(np.diag(P0)) * n[0]
    for k in range(1, t_s.size):
        x[k] = Phi @ x[k - 1] + G @ n[k]
    return x @ DRYDEN_OUTPUT.T


def poor_start(ps) -> dict[str, float]:
    """Start values for a recovery test: every free parameter off its truth by a sizeable amount
    (``Flight.problem(start=poor_start)``; SI, as the parameters)."""
    out = {}
    for p in ps:
        if not p.free:
            continue
        off = {"initial_condition": 0.5 if p.unit == "m/s" else 0.01, "imu_bias": 0.5 * p.value,
               "time_delay": 0.02, "bias": 0.3 * DEG, "table": 0.2 * DEG if p.unit == "rad" else 0.05}
        out[p.key] = p.value + off.get(p.kind, 0.0)
    return out


def truth_values(rng: np.random.Generator) -> dict:
    """Injected parameter values of :class:`Flight` (SI); the tables from ``_table_noise``."""
    return {
        "dax": 0.08, "day": -0.05, "daz": 0.12, "dp": 0.2 * DEG, "dq": -0.3 * DEG, "dr": 0.15 * DEG,
        "tau_phi": 0.02, "tau_theta": 0.02, "tau_psi": 0.02, "tau_tas": 0.0, "tau_h": 0.0,
        "tau_alpha_zl": 0.03, "tau_alpha_zr": 0.045, "tau_sp": 0.08, "tau_np": 0.06, "k_h": 0.0, "k_spr": 0.0,
        "b_l": 0.3 * DEG, "b_r": -0.2 * DEG, "b_sa": 0.25 * DEG, "b_sb": -0.15 * DEG, "b_n": 0.1 * DEG,
        "c_vb": 0.0,  # tejas_ins only; these maneuvers' alpha range leaves it undetermined (held)
        "f1": None, "f2": None, "f3": None, "f4": None, "f5": None,
        "_table_noise": rng.normal(size=40),
    }


@functools.lru_cache(maxsize=16)
def _fine_altitude(params: tuple, T: float) -> tuple[np.ndarray, np.ndarray]:
    """The altitude of :func:`analytic` ``(dict(params))`` on a 1-ms grid from -1 s to ``T + 1`` s:
    ``(t_fine, h_fine)``, read-only (integrated once per trajectory and length: the tests build
    the same flights over and over)."""
    t_fine = np.arange(-1.0, T + 1.0, 1e-3)
    h_fine = analytic(dict(params))[1](t_fine)[:, 6]
    t_fine.flags.writeable = False
    h_fine.flags.writeable = False
    return t_fine, h_fine


class Flight:
    """Two maneuvers of analytic flight (:func:`analytic`) with the channels generated by hand.

    Parameters
    ----------
    truth : :func:`truth_values`.
    specs : the ``tejas`` model set's parameter specifications (their table breakpoints).
    T : maneuver length, s.
    tau_override : time delays replacing the truth's.
    turbulence_form : "gauss_markov" (the default, above) or "dryden": MIL-F-8785C's Dryden
        turbulence in body axes (:func:`dryden_body_wind`; :attr:`wind_ned_mps` is then its NED
        equivalent, ``C_bn^T dW_body``).
    turbulence : ``(sigma_mps, L_m, seed)``: the flow sensors (and the airspeed) see the air moving
        with a turbulent wind ``dW`` (NED, m/s; three independent first-order Gauss-Markov
        components of intensity ``sigma`` and scale length ``L`` at the flight's 150 m/s, drawn
        exactly on a 1 ms grid and interpolated), ``V_air = V - C_bn dW``, while the IMU and the
        attitude and altitude channels follow the (ground-relative) flight; the draw of maneuver
        ``k`` is :attr:`wind_ned_mps` ``[id]`` = (t_s, dW). None: calm air.
    steady_wind_ned_mps : a steady wind ``W0`` (NED, m/s) the air moves with besides: the flow
        sees ``V - C_bn (W0 + dW)``, and the initial velocities the estimator recovers are the
        air-relative ones.
    ins : also the INS ground velocities at the INS point (``vn, ve, vd``, delays
        :data:`INS_DELAYS_S`), and the problem uses the ``tejas_ins`` model set (whose steady wind
        ``wind_n, wind_e, wind_d`` is ``W0``).
    """

    def __init__(self, truth: dict, specs, T: float = 25.0, tau_override: dict | None = None,
                 turbulence: tuple[float, float, int] | None = None,
                 steady_wind_ned_mps=(0.0, 0.0, 0.0), ins: bool = False,
                 turbulence_form: str = "gauss_markov"):
        if turbulence_form not in ("gauss_markov", "dryden"):
            raise ValueError(f"turbulence_form must be 'gauss_markov' or 'dryden', got {turbulence_form!r}")
        self.turbulence_form = turbulence_form
        self.turbulence = turbulence
        self.steady_wind_ned_mps = np.asarray(steady_wind_ned_mps, dtype=float)
        self.ins = ins
        self.wind_ned_mps: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self.specs = {s.name: s for s in specs}
        tn = truth["_table_noise"]
        self.bp = {n: np.asarray(self.specs[n].breakpoints) for n in TABLES}
        # slices of one draw: the tables keep their values when a breakpoint count changes elsewhere
        start = {"f1": 0, "f2": 10, "f3": 20, "f4": 25, "f5": 30}
        self.tables = truth_tables(self.bp, {n: tn[start[n]:start[n] + self.bp[n].size] for n in TABLES})
        self.truth = {**truth, **(INS_DELAYS_S if ins else {}), **(tau_override or {})}
        self.maneuvers = [self._maneuver(f"m{k}", T, params) for k, params in
                          enumerate([dict(au=8.0, aphi=0.4, ath=0.15), dict(av=6.0, aw=6.0, aphi=0.8)])]

    def _maneuver(self, mid: str, T: float, params: dict) -> ManeuverData:
        tr = self.truth
        inputs, states = analytic(params)
        t = np.arange(0.0, T + 1e-9, 1.0 / RATE_HZ)
        a_imu, om = imu_inputs(inputs, t, FLIGHT_SENSORS["imu"] - R_CG)
        da = np.array([tr["dax"], tr["day"], tr["daz"]])
        dw = np.array([tr["dp"], tr["dq"], tr["dr"]])
        # h comes from an ODE: integrate it once on a fine grid, interpolate (error ~1e-9 m)
        t_fine, h_fine = _fine_altitude(tuple(sorted(params.items())), T)

        def states_at(ts):
            x = states(ts, None)
            x[:, 6] = np.interp(ts, t_fine, h_fine)
            return x

        w0 = self.steady_wind_ned_mps

        def flow_states(ts):
            # the air's velocity relative to the aircraft in the steady wind: V - C_bn W0
            x = states_at(ts)
            x[:, :3] -= np.einsum("nij,j->ni", ned_to_body(x[:, 3:6]), w0)
            return x

        if self.turbulence is not None and self.turbulence_form == "dryden":
            gust_b = dryden_body_wind(t_fine, *self.turbulence[:2], 150.0,
                                      np.random.default_rng([self.turbulence[2], int(mid[1:])]))
            b_at = np.stack([np.interp(t, t_fine, d) for d in gust_b.T], 1)
            self.wind_ned_mps[mid] = (t, np.einsum("nji,nj->ni", ned_to_body(states_at(t)[:, 3:6]), b_at))

            def flow_states(ts):
                # the air's velocity relative to the aircraft: V - C_bn W0 - dW_body
                x = states_at(ts)
                x[:, :3] -= (np.einsum("nij,j->ni", ned_to_body(x[:, 3:6]), w0)
                             + np.stack([np.interp(ts, t_fine, d) for d in gust_b.T], 1))
                return x
        elif self.turbulence is not None:
            gust = gauss_markov_wind(t_fine, *self.turbulence[:2], 150.0,
                                     np.random.default_rng([self.turbulence[2], int(mid[1:])]))
            self.wind_ned_mps[mid] = (t, np.stack([np.interp(t, t_fine, d) for d in gust.T], 1))

            def flow_states(ts):
                # the air's velocity relative to the aircraft: V - C_bn (W0 + dW)
                x = states_at(ts)
                w_ned = w0 + np.stack([np.interp(ts, t_fine, d) for d in gust.T], 1)
                x[:, :3] -= np.einsum("nij,nj->ni", ned_to_body(x[:, 3:6]), w_ned)
                return x

        # the attitude and altitude channels are the same either way (flow_states changes the
        # velocity only)
        meas = tejas_channels(t, flow_states, inputs, FLIGHT_SENSORS, R_CG,
                              ChannelTruth(tr, tr, self.tables, self.bp))
        if self.ins:
            r_ins = SENSORS["ins"] - R_CG
            for name in INS_CHANNELS:
                ts = t - tr[f"tau_{name}"]
                x = states_at(ts)
                v_ins = x[:, :3] + np.cross(inputs(ts)[1], r_ins)  # ground-relative, body axes
                v_ned = np.einsum("nji,nj->ni", ned_to_body(x[:, 3:6]), v_ins)
                meas[name] = v_ned[:, INS_CHANNELS.index(name)]
        # the initial conditions relative to the steady air (a turbulent dW is the wind states')
        x0 = states_at(t[:1])
        x0[:, :3] -= ned_to_body(x0[:, 3:6])[0] @ w0
        self_ic = dict(zip(("u0", "v0", "w0", "phi0", "theta0", "psi0", "h0"), x0[0], strict=True))
        self_ic.update(zip(("wind_n", "wind_e", "wind_d"), w0, strict=True))
        return ManeuverData(
            id=mid, t_s=t, accel_imu_mps2=a_imu + da, omega_rps=om + dw, measurements=meas,
            r_cg_body_m=R_CG, aircraft="AC1", configuration="AC1", meta={"ic": self_ic},
        )

    def problem(self, free=None, start="truth", noise=None, rng=None) -> Problem:
        """The estimation problem; parameters at the truth, or perturbed, free as asked.

        ``free``: names of the free parameters (None: the model set's); ``start``: "truth" or a
        function of the parameter set giving start values by key; ``noise``: channel -> white
        noise standard deviation (SI), drawn from ``rng``.
        """
        tr = self.truth
        mans = self.maneuvers
        if noise:
            mans = [replace(m, measurements={
                c: v + rng.normal(0.0, noise[c], v.size) for c, v in m.measurements.items()})
                for m in mans]
        channels, specs = load_model_set("tejas_ins" if self.ins else "tejas")
        channels = [c for c in channels if c.name in CHANNELS or (self.ins and c.name in INS_CHANNELS)]
        out = []
        used = {"u0", "v0", "w0", "phi0", "theta0", "psi0", "h0", "dax", "day", "daz", "dp", "dq", "dr"}
        for c in channels:
            used |= c.expression.names | c.expression.tables | ({c.delay} if c.delay else set())
        for s in specs:
            if s.name not in used:
                continue
            if s.kind == "initial_condition":
                s = replace(s, per_instance={m.id: m.meta["ic"][s.name] for m in mans})
            elif s.name in self.tables:
                s = replace(s, value=tuple(self.tables[s.name]))
            else:
                s = replace(s, value=tr[s.name])
            if free is not None:
                s = replace(s, free=s.name in free)
            out.append(s)
        ps = expand_parameters(out, mans, channels)
        if start != "truth":
            ps = ps.with_values(start(ps))
        sensors = {**FLIGHT_SENSORS, "ins": SENSORS["ins"]} if self.ins else FLIGHT_SENSORS
        return Problem(tuple(mans), tuple(channels), sensors, FLIGHT_SENSORS["imu"], ps, G, "analytic")
