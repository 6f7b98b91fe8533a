"""The coloured-noise Monte Carlo of ``bench_colored.py`` and its test: problem, noise, sandwich.

The problem is the estimator tests' two-maneuver analytic flight (:class:`campaigns.analytic_flight.Flight`)
with coloured, cross-correlated noise (:class:`CorrelatedNoise`); a replication
(:func:`replicate`) estimates it from the truth with fresh noise and reports the solver's
deviations; :func:`sandwich_std` evaluates the Morelli-Klein sandwich independently of the solver
(by FFT, also with the true noise covariance: :func:`oracle`); :func:`ratios` compares the scatter
of the estimates with the reported deviations.
``tests/estimator_tests/test_colored_uncertainty.py`` checks these against the sandwich's
definition and runs a small Monte Carlo; ``bench_colored.py`` the full one.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import fft as sfft
from scipy.signal import lfilter
from threadpoolctl import threadpool_limits

from campaigns.analytic_flight import DEG, NOISE_SIGMA, RATE_HZ, Flight, truth_values
from estimator.io.modelset import load_model_set
from estimator.model import Model
from estimator.solver import SolverOptions, estimate

DT_S = 1.0 / RATE_HZ
#: Noise standard deviations per channel (SI): those of the estimator's white-noise test.
SIGMA = dict(NOISE_SIGMA)
#: Channels sharing a common noise component, and the share of each channel's variance it has.
GROUPS = {"alpha": ("alpha_zl", "alpha_zr", "alpha_zsp"), "beta": ("beta_zsp", "beta_znp")}
RHO = {"alpha_zl": 0.6, "alpha_zr": 0.6, "alpha_zsp": 0.6, "beta_zsp": 0.5, "beta_znp": 0.5}


@dataclass(frozen=True)
class CorrelatedNoise:
    """Coloured, cross-correlated measurement noise.

    Channel ``c`` gets ``sigma_c (sqrt(rho_c) g + sqrt(1 - rho_c) u_c)``: ``g`` the unit-variance
    AR(1) process of its group (correlation time ``tau_common_s``), ``u_c`` its own
    (``tau_own_s``); a correlation time of 0 is white noise. Stationary from the first sample.
    """

    tau_common_s: float = 0.5
    tau_own_s: float = 0.2
    sigma: dict = field(default_factory=lambda: dict(SIGMA))
    rho: dict = field(default_factory=lambda: dict(RHO))
    groups: dict = field(default_factory=lambda: dict(GROUPS))

    def group_of(self, c: str) -> str | None:
        return next((g for g, cs in self.groups.items() if c in cs), None)

    @staticmethod
    def ar1(rng: np.random.Generator, tau_s: float, n: int, m: int = 1) -> np.ndarray:
        """(m, n) unit-variance AR(1) sequences, ``x[t+1] = a x[t] + sqrt(1 - a^2) w``."""
        w = rng.standard_normal((m, n))
        if tau_s == 0.0:
            return w
        a = np.exp(-DT_S / tau_s)
        x = np.empty((m, n))
        x[:, 0] = w[:, 0]
        x[:, 1:] = lfilter([np.sqrt(1.0 - a * a)], [1.0, -a], w[:, 1:], axis=1, zi=a * w[:, :1])[0]
        return x

    def draw(self, rng: np.random.Generator, channels, n: int, m: int = 1) -> dict[str, np.ndarray]:
        """(m, n) noise per channel (``m`` independent records); one maneuver when m = 1."""
        common = {g: self.ar1(rng, self.tau_common_s, n, m) for g in self.groups}
        out = {}
        for c in channels:
            r = self.rho.get(c, 0.0)
            x = np.sqrt(1.0 - r) * self.ar1(rng, self.tau_own_s, n, m)
            if r:
                x += np.sqrt(r) * common[self.group_of(c)]
            out[c] = self.sigma[c] * (x[0] if m == 1 else x)
        return out

    @staticmethod
    def _acf(tau_s: float, lag: np.ndarray) -> np.ndarray:
        return (lag == 0).astype(float) if tau_s == 0.0 else np.exp(-np.abs(lag) * DT_S / tau_s)

    def cov(self, c: str, d: str, lag) -> np.ndarray:
        """``E[v_c(t + lag) v_d(t)]``, lag in samples."""
        lag = np.asarray(lag)
        rc, rd = self.rho.get(c, 0.0), self.rho.get(d, 0.0)
        if c == d:
            return self.sigma[c] ** 2 * (rc * self._acf(self.tau_common_s, lag)
                                         + (1.0 - rc) * self._acf(self.tau_own_s, lag))
        if rc and rd and self.group_of(c) == self.group_of(d):
            return self.sigma[c] * self.sigma[d] * np.sqrt(rc * rd) * self._acf(self.tau_common_s, lag)
        return np.zeros(lag.shape)

    def describe(self) -> str:
        grp = "; ".join(f"{g}: {', '.join(cs)} (common share rho = "
                        f"{', '.join(f'{self.rho[c]:g}' for c in cs)})" for g, cs in self.groups.items())
        sig = ", ".join(f"{c} {v / DEG:g} deg" if c.startswith(("alpha", "beta", "phi", "theta", "psi"))
                        else f"{c} {v:g} {'m/s' if c == 'tas' else 'm'}" for c, v in self.sigma.items())
        return (f"AR(1) noise, common components tau = {self.tau_common_s:g} s, own components tau = "
                f"{self.tau_own_s:g} s (0 = white); groups {grp}; other channels independent; "
                f"sigma {sig}")


def make_flight(T_s: float = 30.0) -> Flight:
    """The estimator tests' two-maneuver analytic flight, maneuvers ``T_s`` long."""
    _, specs = load_model_set("tejas")
    return Flight(truth_values(np.random.default_rng(5)), specs, T=T_s)


def noisy_problem(flight: Flight, noise: CorrelatedNoise, rng: np.random.Generator, free=None,
                  own_rate: dict | None = None):
    """The flight's problem (parameters at the truth) with fresh noise on every channel.

    ``own_rate``: channel -> keep every k-th sample (NaN between: an own-rate channel).
    """
    mans = []
    for m in flight.maneuvers:
        v = noise.draw(rng, list(m.measurements), m.t_s.size)
        meas = {c: z + v[c] for c, z in m.measurements.items()}
        for c, k in (own_rate or {}).items():
            meas[c] = np.where(np.arange(meas[c].size) % k == 0, meas[c], np.nan)
        mans.append(replace(m, measurements=meas))
    fl = copy.copy(flight)
    fl.maneuvers = mans
    return fl.problem(free=free)


# ----------------------------------------------------------------------------- independent sandwich
def jacobian_blocks(problem, theta: np.ndarray, free_idx: np.ndarray):
    """Per maneuver, channel index -> (rows, residual z - y, Jacobian in the free parameters)."""
    model = Model(problem)
    pos = np.full(theta.size, -1)
    pos[free_idx] = np.arange(free_idx.size)
    out = []
    for k in range(len(problem.maneuvers)):
        chans = {}
        for b in model.evaluate(theta, k, jacobian=True).blocks:
            J = np.zeros((b.rows.size, free_idx.size))
            for j, col in enumerate(b.cols):
                if pos[col] >= 0:
                    J[:, pos[col]] += b.J[:, j]
            chans[b.channel] = (b.rows, b.z - b.y, J)
        out.append(chans)
    return out


def _one_sided(L: int) -> np.ndarray:
    wt = np.full(L // 2 + 1, 2.0)
    wt[0] = 1.0
    if L % 2 == 0:
        wt[-1] = 1.0
    return wt


def sandwich_std(blocks, R: np.ndarray, n_of, variants: dict, names=None):
    """Cramér-Rao and sandwich deviations, dense over all maneuvers (no Schur elimination).

    ``Cov = M^-1 C M^-1``, ``M = sum J^T W J``, ``C = sum_k sum_cd sum_ij a_c(i) R_cd(i - j) a_d(j)^T``
    with ``a_c(i) = W_c J_c(i)^T`` on maneuver ``k``'s sample grid (zero where channel ``c`` has
    no sample in the cost). ``variants``: name -> ``(source, cross, window_s)``, ``source`` either
    "residual" (``R_cd(m) = sum_t e_c(t + m) e_d(t) / sqrt(n_c n_d)``, the solver's biased
    estimate, every lag unless ``window_s``: lags beyond it dropped) or a function
    ``cov(c_name, d_name, lags)`` (the true noise covariance; ``names``: channel names);
    ``cross`` False keeps the terms ``c = d`` only. Evaluated by FFT (zero-padded to
    ``L >= 2 n - 1``: linear, not circular, correlation).
    """
    p = next(iter(blocks[0].values()))[2].shape[1]
    M = np.zeros((p, p))
    C = {v: np.zeros((p, p)) for v in variants}
    for k, chans in enumerate(blocks):
        n = int(n_of[k])
        L = sfft.next_fast_len(2 * n - 1, real=True)
        cs = list(chans)
        F = np.zeros((len(cs), p, L // 2 + 1), complex)
        E = np.zeros((len(cs), L // 2 + 1), complex)
        cnt = np.zeros(len(cs))
        for a, c in enumerate(cs):
            rows, e, J = chans[c]
            M += J.T @ J / R[c]
            A = np.zeros((p, L))
            A[:, rows] = J.T / R[c]
            ee = np.zeros(L)
            ee[rows] = e
            F[a], E[a], cnt[a] = sfft.rfft(A, axis=1), sfft.rfft(ee), rows.size
        # lag of each position of a length-L correlation; the padding between is no lag at all
        lag = np.zeros(L, dtype=np.int64)
        lag[:n] = np.arange(n)
        lag[L - (n - 1):] = np.arange(-(n - 1), 0)
        valid = np.zeros(L, bool)
        valid[:n] = valid[L - (n - 1):] = True
        Ft = np.ascontiguousarray(F.transpose(2, 0, 1))  # (f, c, p)
        Fw = np.conj(Ft) * _one_sided(L)[:, None, None]
        for v, (source, cross, window_s) in variants.items():
            if callable(source):
                S = np.empty((len(cs), len(cs), L // 2 + 1), complex)
                for a, c in enumerate(cs):
                    for b, d in enumerate(cs):
                        S[a, b] = sfft.rfft(np.where(valid, source(names[c], names[d], lag), 0.0))
            else:
                S = E[:, None, :] * np.conj(E[None, :, :]) / np.sqrt(cnt[:, None, None] * cnt[None, :, None])
                if window_s is not None:
                    S = sfft.rfft(sfft.irfft(S, L, axis=-1) * (np.abs(lag) * DT_S <= window_s), axis=-1)
            if not cross:
                S = S * np.eye(len(cs))[:, :, None]
            # sum_ij x(i) r(i - j) y(j) = 1/L sum_f conj(X_f) R_f Y_f (Parseval, real signals)
            G = np.matmul(np.ascontiguousarray(S.transpose(2, 0, 1)), Ft)
            C[v] += (Fw.reshape(-1, p).T @ G.reshape(-1, p)).real / L
    Minv = np.linalg.inv(M)
    out = {"crb": np.sqrt(np.diag(Minv))}
    for v, Cv in C.items():
        out[v] = np.sqrt(np.maximum(np.diag(Minv @ Cv @ Minv), 0.0))
    return out


# ----------------------------------------------------------------------------- Monte Carlo
def replicate(flight: Flight, noise: CorrelatedNoise, seed: int, free=None, windows_s=(),
              per_channel: str = "solver", check: bool = False, periodogram: bool = False) -> dict:
    """One replication: fresh noise (seed ``seed``), estimated from the truth.

    Returns the free-estimated indices, the estimates, the solver's Cramér-Rao deviations and its
    honest (coloured, cross-channel: autoregressive residual spectrum) ones as ``cross``; the
    per-channel form of the same as ``per_channel`` (``colored_cross_channel=False``, a second
    estimation) if ``per_channel == "solver"``, else the per-channel all-lags plug-in from
    :func:`sandwich_std`; with ``periodogram``, the solver's all-lags plug-in
    (``colored_spectrum="periodogram"``, the estimator's former deviations) as ``periodogram``.
    ``check`` evaluates the all-lags forms both ways (solver and :func:`sandwich_std`) and reports
    the largest relative difference as ``check_dev``. With ``windows_s``, what-if deviations of
    the cross-channel all-lags plug-in with the residual correlation truncated at those lags (s),
    ``window_<w>s``.

    The analytic flight's IMU inputs are exact: no IMU noise term (``imu_noise="none"``).
    """
    prob = noisy_problem(flight, noise, np.random.default_rng(seed), free=free)
    opt = SolverOptions(start="given", diagnose=False, imu_noise="none")
    res = estimate(prob, opt)
    fi = np.nonzero(res.free_estimated)[0]
    out = {"seed": seed, "free": fi, "values": res.values[fi], "crb": res.std_crb[fi],
           "cross": res.std_colored[fi], "success": bool(res.status.converged)}
    if per_channel == "solver":
        pc = estimate(prob, replace(opt, colored_cross_channel=False))
        assert np.array_equal(np.nonzero(pc.free_estimated)[0], fi)
        out["per_channel"] = pc.std_colored[fi]
    if periodogram or check:
        pg = estimate(prob, replace(opt, colored_spectrum="periodogram"))
        assert np.array_equal(np.nonzero(pg.free_estimated)[0], fi)
        out["periodogram"] = pg.std_colored[fi]
    variants = {f"window_{w:g}s": ("residual", True, w) for w in windows_s}
    if per_channel != "solver" or check:
        variants["per_channel_mine"] = ("residual", False, None)
    if check:
        variants["cross_mine"] = ("residual", True, None)
    if variants:
        Rv = np.array([res.R[c.name] for c in prob.channels])
        with threadpool_limits(1, "blas"):
            mine = sandwich_std(jacobian_blocks(prob, res.values, fi), Rv, [m.n for m in prob.maneuvers],
                                variants)
        if check:
            pgc = estimate(prob, replace(opt, colored_spectrum="periodogram", colored_cross_channel=False))
            # the solver floors every coloured deviation at the Cramér-Rao bound
            out["check_dev"] = max(
                float(np.max(np.abs(np.maximum(mine["per_channel_mine"], mine["crb"])
                                    / pgc.std_colored[fi] - 1))),
                float(np.max(np.abs(np.maximum(mine["cross_mine"], mine["crb"]) / out["periodogram"] - 1))),
                float(np.max(np.abs(mine["crb"] / out["crb"] - 1))))
        if per_channel != "solver":
            out["per_channel"] = mine["per_channel_mine"]
        out.update({v: mine[v] for v in variants if v.startswith("window_")})
    return out


def oracle(flight: Flight, noise: CorrelatedNoise, free_idx: np.ndarray, free=None) -> dict:
    """Deviations from the sandwich with the true noise covariance, at the truth (weights
    ``1 / sigma^2``): cross-channel ("oracle") and its per-channel form ("oracle_per_channel")."""
    prob = flight.problem(free=free)
    Rv = np.array([noise.sigma[c.name] ** 2 for c in prob.channels])
    with threadpool_limits(1, "blas"):
        out = sandwich_std(jacobian_blocks(prob, prob.parameters.values, free_idx), Rv,
                           [m.n for m in prob.maneuvers],
                           {"oracle": (noise.cov, True, None),
                            "oracle_per_channel": (noise.cov, False, None)},
                           names=[c.name for c in prob.channels])
    return {"oracle": out["oracle"], "oracle_per_channel": out["oracle_per_channel"], "crb_truth": out["crb"]}


def ratios(values: np.ndarray, reported: dict[str, np.ndarray], groups: dict[str, np.ndarray],
           n_boot: int = 400, seed: int = 0) -> dict:
    """Monte Carlo scatter over mean reported deviation, per parameter and pooled.

    values : (N, P) estimates; reported : form -> (N, P) deviations per replication, or (P,) fixed.
    groups : name -> boolean (P,) mask; pooled = geometric mean of the members' ratios.
    Standard errors by bootstrap over replications (the parameters' estimates are correlated, so
    a pooled ratio is not as precise as P independent ones).
    """
    N = values.shape[0]

    def point(idx):
        mc = values[idx].std(axis=0, ddof=1)
        per = {f: mc / (r[idx].mean(axis=0) if r.ndim == 2 else r) for f, r in reported.items()}
        pooled = {(f, g): float(np.exp(np.mean(np.log(per[f][m])))) for f in per for g, m in groups.items()}
        return mc, per, pooled

    mc, per, pooled = point(np.arange(N))
    rng = np.random.default_rng(seed)
    boots = [point(rng.integers(0, N, N)) for _ in range(n_boot)]
    se_per = {f: np.std([b[1][f] for b in boots], axis=0, ddof=1) for f in per}
    se_pooled = {key: float(np.std([b[2][key] for b in boots], ddof=1)) for key in pooled}
    return {"mc_std": mc, "ratio": per, "ratio_se": se_per, "pooled": pooled, "pooled_se": se_pooled,
            "nominal_se": 1.0 / np.sqrt(2.0 * N)}


def run_monte_carlo(flight, noise, seeds, free=None, windows_s=(), per_channel="solver", check_first=0):
    """Replications ``seeds`` in this process (the first ``check_first`` checked, see
    :func:`replicate`); arrays of the estimates and deviations (:func:`collect`)."""
    return collect([replicate(flight, noise, s, free, windows_s, per_channel, check=i < check_first)
                    for i, s in enumerate(seeds)])


def collect(reps: list[dict]) -> dict:
    """Stack replications; those whose free-estimated set differs from the first's are dropped
    (counted)."""
    fi = reps[0]["free"]
    same = [r for r in reps if np.array_equal(r["free"], fi)]
    forms = [k for k in reps[0] if k not in ("seed", "free", "values", "success", "check_dev")
             and all(k in r for r in same)]
    return {"free": fi, "values": np.array([r["values"] for r in same]),
            "reported": {f: np.array([r[f] for r in same]) for f in forms},
            "n_dropped": len(reps) - len(same), "n_failed": sum(not r["success"] for r in same),
            "check_dev": [r["check_dev"] for r in reps if "check_dev" in r]}
