r"""The FPR output-error model of one maneuver: outputs and their exact Jacobian.

For maneuver ``k`` with parameter values ``theta``:

1. States and sensitivities: RK4 of the state equations driven by the IMU (biases subtracted,
   lever arm removed, angular accelerations by smoothed differentiation of the rates), started at
   the maneuver's initial conditions (:mod:`estimator.core.sensitivity`).
2. State signals (``alpha_s``, ``beta_t``, ``phi``, ...) on the sample grid, with derivatives with
   respect to the 13 state-equation parameters (initial conditions, IMU biases)
   (:mod:`estimator.core.observations`).
3. Time shift: each channel's state signals are taken at ``t - tau`` (SPEC §2: ``tau > 0`` lags)
   by linear interpolation; ``d/dtau = -(slope of the signal)``. Data signals (the channel's own
   measurement ``z``, ``gear``) are not shifted: they were recorded at ``t``.
4. The channel's model text is evaluated with forward-mode derivatives
   (:mod:`estimator.core.expressions`) and chained to the parameters.

A channel's first and last ``guard`` samples (the largest time shift its delay bounds allow) are
left out of the cost so that no output ever depends on the signal outside the record.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator.core.expressions import Table
from estimator.core.kinematics import smoothed_derivative
from estimator.core.observations import angle_signals, domega_matrix
from estimator.core.sensitivity import N_SENS, integrate_sensitivities
from estimator.parameters import make_key
from estimator.problem import STATE_PARAMS, STATE_SIGNALS, ChannelSpec, Problem

_EULER_INDEX = {"phi": 3, "theta": 4, "psi": 5, "h": 6}


@dataclass(frozen=True)
class ChannelBlock:
    """One channel of one maneuver: residuals and Jacobian rows in the cost.

    Attributes
    ----------
    channel : index into ``Problem.channels``.
    rows : (n,) sample indices used in the cost.
    y : (n,) model output at those samples (SI).
    z : (n,) measurement.
    J : (n, m) d y / d parameters for ``cols`` (None if not requested).
    cols : (m,) indices into the problem's ParameterSet.
    """

    channel: int
    rows: np.ndarray
    y: np.ndarray
    z: np.ndarray
    J: np.ndarray | None
    cols: np.ndarray


@dataclass(frozen=True)
class ManeuverEval:
    maneuver: int
    X: np.ndarray
    blocks: tuple[ChannelBlock, ...]


class Model:
    """Precomputed structure of a problem; evaluates maneuvers for given parameter values.

    Parameters
    ----------
    problem : the problem.
    derivative_window_s : Savitzky-Golay window for the angular accelerations, s.
    """

    def __init__(self, problem: Problem, derivative_window_s: float = 0.15):
        self.problem = problem
        ps = problem.parameters
        self._tables = {
            name: Table(name, np.asarray(spec.breakpoints))
            for name, spec in ps.specs.items() if spec.breakpoints is not None
        }
        self._omega_dot = [smoothed_derivative(m.t_s, m.omega_rps, window_s=derivative_window_s)
                           for m in problem.maneuvers]
        # which channels each maneuver has, and the guard band of each channel
        self._present = [
            [c for c, ch in enumerate(problem.channels) if ch.column in m.measurements]
            for m in problem.maneuvers
        ]
        self._guard_s = []
        for ch in problem.channels:
            g = 0.0
            if ch.delay:
                spec = ps.specs.get(ch.delay)
                if spec is None:
                    raise ValueError(f"channel {ch.name}: delay parameter {ch.delay!r} is not declared")
                lo, hi = spec.bounds
                g = max(abs(lo), abs(hi)) if np.isfinite(lo) and np.isfinite(hi) else 0.5
            self._guard_s.append(g)
        missing = [n for n in STATE_PARAMS if n not in ps.specs]
        if missing:
            raise ValueError(f"the state-equation parameters {missing} are not declared")
        for ch in problem.channels:
            for name in ch.expression.names - STATE_SIGNALS - {"z", "zhat"}:
                if name in ps.specs:
                    continue
                if not all(name in m.signals or name in m.measurements or name in self._channel_columns
                           for m in problem.maneuvers):
                    raise ValueError(
                        f"channel {ch.name}: model uses {name!r}, which is neither a parameter, a "
                        "state signal, nor a data column of every maneuver"
                    )
            for t in ch.expression.tables:
                if t not in self._tables:
                    raise ValueError(f"channel {ch.name}: table {t!r} is not declared with breakpoints")

    @property
    def _channel_columns(self) -> dict[str, str]:
        return {ch.name: ch.column for ch in self.problem.channels}

    # ------------------------------------------------------------------ parameter resolution
    def key(self, name: str, k: int, channel: ChannelSpec | None = None, element: int | None = None) -> str:
        spec = self.problem.parameters.specs[name]
        m = self.problem.maneuvers[k]
        inst = {
            "global": "",
            "aircraft": m.aircraft,
            "configuration": m.configuration,
            "maneuver": m.id,
            "recorder": channel.recorder if channel is not None else "",
        }[spec.scope]
        return make_key(name, inst, element)

    def value(self, values: np.ndarray, name: str, k: int, channel=None) -> float:
        return float(values[self.problem.parameters.index(self.key(name, k, channel))])

    def state_columns(self, k: int) -> np.ndarray:
        ps = self.problem.parameters
        return np.array([ps.index(self.key(n, k)) for n in STATE_PARAMS])

    def guard_samples(self, k: int, c: int) -> int:
        m = self.problem.maneuvers[k]
        return int(np.ceil(self._guard_s[c] / m.dt_s)) + 1 if self._guard_s[c] > 0 else 0

    @staticmethod
    def _implicit(expr, signals, params, tables, state, z, ch: ChannelSpec, iterations: int = 30):
        """Solve ``y = F(y, ...)`` for a model whose argument ``zhat`` is its own output.

        ``zhat`` is the noise-free model of the measurement: a table of the measured angle,
        evaluated at the *modelled* angle, avoids the errors-in-variables bias that the noisy
        measurement ``z`` as argument causes (SPEC §5). Fixed-point iteration from ``z``; the
        derivatives follow from ``dy = dF + F_zhat dy``, i.e. ``dy = dF / (1 - F_zhat)``.
        """
        sig = dict(signals)
        y = np.asarray(z, dtype=float)
        for _ in range(iterations):
            sig["zhat"] = y
            y_new = np.broadcast_to(expr.evaluate(sig, params, tables).value, y.shape)
            if np.max(np.abs(y_new - y)) < 1e-13:
                y = y_new
                break
            y = y_new
        else:
            raise ValueError(
                f"channel {ch.name}: the implicit model {ch.model!r} does not converge (its "
                "dependence on zhat must be weaker than 1:1); use z instead of zhat or bound the tables"
            )
        sig["zhat"] = y
        dual = expr.evaluate(sig, params, tables, state | {"zhat"})
        f_z = np.broadcast_to(dual.dsignal.pop("zhat", 0.0), y.shape)
        factor = 1.0 / (1.0 - f_z)
        out = dual.scaled(factor)
        out.value = dual.value
        return out

    # ------------------------------------------------------------------ evaluation
    def integrate(self, values: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """States (N, 7) and sensitivities (N, 7, 13) of maneuver k."""
        p = self.problem
        m = p.maneuvers[k]
        sv = values[self.state_columns(k)]
        return integrate_sensitivities(
            m.t_s, sv[:7], m.accel_imu_mps2, m.omega_rps, self._omega_dot[k],
            p.imu_position_body_m - m.r_cg_body_m, sv[7:10], sv[10:13], p.g_mps2,
        )

    def evaluate(self, values: np.ndarray, k: int, jacobian: bool = True) -> ManeuverEval:
        """Outputs (and Jacobian blocks) of every channel present in maneuver ``k``."""
        p = self.problem
        m = p.maneuvers[k]
        X, S = self.integrate(values, k)
        state_cols = self.state_columns(k)
        omega = m.omega_rps - values[state_cols[10:13]]
        n = m.n
        cache: dict[tuple[str, str | None], tuple[np.ndarray, np.ndarray]] = {}

        def state_signal(name: str, sensor: str | None):
            """value (N,), d value / d state params (N, 13)."""
            ck = (name, sensor if name in ("alpha_s", "beta_s", "flank_s") else None)
            if ck in cache:
                return cache[ck]
            if name in _EULER_INDEX:
                i = _EULER_INDEX[name]
                out = (X[:, i], S[:, i, :])
            else:
                if name.endswith("_s"):
                    r = p.sensors[sensor] - m.r_cg_body_m
                    vs = X[:, :3] + np.cross(omega, r)
                    sig = {"alpha_s": "alpha", "beta_s": "beta", "flank_s": "flank"}[name]
                else:
                    r = None
                    vs = X[:, :3]
                    sig = {"alpha_t": "alpha", "beta_t": "beta", "tas_t": "tas"}[name]
                val, dv = angle_signals(vs)[sig]
                d = np.einsum("ni,nij->nj", dv, S[:, :3, :]) if jacobian else None
                if jacobian and r is not None:
                    # V_s depends on omega = omega_m - d_omega: dV_s/d(d_omega) = -dV_s/domega
                    d[:, 10:13] -= dv @ domega_matrix(r)
                out = (val, d)
            cache[ck] = out
            return out

        blocks = []
        for c in self._present[k]:
            ch = p.channels[c]
            expr = ch.expression
            tau = self.value(values, ch.delay, k, ch) if ch.delay else 0.0
            # linear interpolation at t - tau on the uniform grid
            s = (m.t_s - tau - m.t_s[0]) / m.dt_s
            i0 = np.clip(np.floor(s).astype(np.intp), 0, n - 2)
            w = np.clip(s - i0, 0.0, 1.0)[:, None]
            signals: dict[str, np.ndarray] = {}
            dstate: dict[str, np.ndarray] = {}
            dtau: dict[str, np.ndarray] = {}
            for name in expr.names & STATE_SIGNALS:
                val, d = state_signal(name, ch.sensor)
                signals[name] = (1 - w[:, 0]) * val[i0] + w[:, 0] * val[i0 + 1]
                if jacobian:
                    dstate[name] = (1 - w) * d[i0] + w * d[i0 + 1]
                    dtau[name] = -(val[i0 + 1] - val[i0]) / m.dt_s
            z = m.measurements[ch.column]
            signals["z"] = z
            for name in expr.names - STATE_SIGNALS - {"z", "zhat"}:
                if name in p.parameters.specs:
                    continue
                if name in m.signals:
                    signals[name] = m.signals[name]
                elif name in m.measurements:
                    signals[name] = m.measurements[name]
                else:
                    signals[name] = m.measurements[self._channel_columns[name]]
            params = {name: self.value(values, name, k, ch)
                      for name in expr.names if name in p.parameters.specs}
            tables = {}
            for t in expr.tables:
                keys = [self.key(t, k, ch, e) for e in range(self._tables[t].breakpoints.size)]
                tables[t] = (self._tables[t], values[[p.parameters.index(kk) for kk in keys]])
            if "zhat" in expr.names:
                dual = self._implicit(expr, signals, params, tables, frozenset(dstate), z, ch)
            else:
                dual = expr.evaluate(signals, params, tables, frozenset(dstate))
            y = np.broadcast_to(dual.value, (n,))
            g = self.guard_samples(k, c)
            rows = np.arange(g, n - g)
            J = None
            cols: list[int] = list(state_cols)
            if jacobian:
                blocks_j = [np.zeros((n, N_SENS))]
                for name, dy in dual.dsignal.items():
                    blocks_j[0] += np.broadcast_to(dy, (n,))[:, None] * dstate[name]
                for name, dy in dual.dparam.items():
                    blocks_j.append(np.broadcast_to(dy, (n,))[:, None])
                    cols.append(p.parameters.index(self.key(name, k, ch)))
                for t, terms in dual.dtable.items():
                    K = self._tables[t].breakpoints.size
                    tb = np.zeros((n, K))
                    ar = np.arange(n)
                    for idx, coef in terms:
                        np.add.at(tb, (ar, np.broadcast_to(idx, (n,))), np.broadcast_to(coef, (n,)))
                    blocks_j.append(tb)
                    cols.extend(p.parameters.index(self.key(t, k, ch, e)) for e in range(K))
                if ch.delay:
                    dyt = np.zeros(n)
                    for name, dy in dual.dsignal.items():
                        dyt += np.broadcast_to(dy, (n,)) * dtau[name]
                    blocks_j.append(dyt[:, None])
                    cols.append(p.parameters.index(self.key(ch.delay, k, ch)))
                J = np.hstack(blocks_j)[rows]
            blocks.append(ChannelBlock(c, rows, np.array(y[rows]), z[rows], J, np.asarray(cols)))
        return ManeuverEval(k, X, tuple(blocks))
