r"""The FPR output-error model: outputs and their exact Jacobian, for all maneuvers at once.

For maneuver ``k`` with parameter values ``theta``:

1. States and sensitivities: RK4 of the state equations driven by the IMU (biases subtracted),
   started at the maneuver's initial conditions (:mod:`estimator.core.sensitivity`). The lever arm
   (``Problem.lever_arm``): by default the states are the IMU point's velocity, which needs none;
   or the SPEC's lever-arm correction with angular accelerations from smoothed differentiation
   of the rates, the states then being the CG's. Attitude and altitude are the CG's either way,
   and so are the initial conditions ``u0, v0, w0``; :attr:`Evaluation.X` reports the CG's.
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

How it is computed (the arithmetic is the per-maneuver one above; only its organisation is for
speed): all maneuvers are integrated in one compiled call; each channel is evaluated once for
all maneuvers that have it, on their concatenated samples, with per-sample parameter values where
a parameter's instance differs between maneuvers (a per-aircraft bias); everything that does not
depend on the parameters (concatenated data, half-step inputs, angular accelerations, guard rows,
index maps from each channel's Jacobian columns to parameters) is prepared once. The Jacobian of
a channel is assembled in slot space — 13 state-equation columns, then one column per parameter,
per table value and for the time shift, the same for every maneuver, with a per-maneuver map to
the parameter indices — by a compiled kernel that chains the interpolated signal derivatives to
the sensitivities row by row, each block's ``J^T J`` and ``J^T e`` right after
(:mod:`estimator.core.assembly`); the solver needs only those, so the Jacobian itself is kept
only when asked. The compiled kernels release the GIL: a large problem runs the two halves of the
integration, the state signals and the channels on a two-thread pool that ends with the call
(results do not depend on the scheduling). :meth:`Model.evaluate` (one maneuver, per-channel
blocks) is a view of :meth:`Model.evaluate_all`.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from estimator.core.assembly import (
    BlockNormals,
    ChannelSignals,
    RowShift,
    SignalStacks,
    SparseTerms,
    channel_normals,
    shift_index,
    shift_values,
)
from estimator.core.expressions import Table
from estimator.core.kinematics import smoothed_derivative
from estimator.core.observations import flow_signal_batch
from estimator.core.sensitivity import (
    LEVER_ARMS,
    N_SENS,
    ImuSamples,
    Inputs,
    integrate_many,
    worker_threads,
)
from estimator.problem import AIR_RELATIVE_SIGNALS, STATE_PARAMS, STATE_SIGNALS, Problem

_EULER_INDEX = {"phi": 3, "theta": 4, "psi": 5, "h": 6}
_RATE_INDEX = {"p": 0, "q": 1, "r": 2}
_FLOW_KIND = {"alpha_s": "alpha", "beta_s": "beta", "flank_s": "flank",
              "alpha_t": "alpha", "beta_t": "beta", "tas_t": "tas", "u_s": "u", "v_s": "v", "w_s": "w"}
_ORIGIN = np.zeros(3)
#: Problems with at least this many samples evaluate their channels on two threads.
_THREADED_SAMPLES = 20000
#: Newton iterations at most for an implicit (``zhat``) model, plain fixed-point iterations at most
#: after them (a safeguard), and their tolerance.
IMPLICIT_ITERATIONS = 30
IMPLICIT_FIXED_POINT_ITERATIONS = 300
IMPLICIT_TOL = 1e-13
#: An implicit model's iterations that keep a step this large (the channel's SI unit) without
#: shrinking it — Newton's largest step not halved in 8 iterations, the fixed point's not down by a
#: tenth in 30 — cycle (a table steeper than 1:1 between two breakpoints) and are given up at once:
#: a cycle's steps never reach IMPLICIT_TOL, and the budgets above would only be spent to say so
#: (a fixed point contracting by less than 0.35 % per step would not reach it within them either).
IMPLICIT_STALLED_STEP = 1e-6


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


@dataclass
class ChannelEval:
    """One channel evaluated for all its maneuvers; rows of maneuver ``mans[b]`` are
    ``rseg[b]:rseg[b+1]`` (a *block*).

    Attributes
    ----------
    channel : index into ``Problem.channels``.
    mans : (B,) maneuver indices (into ``Problem.maneuvers``) of the blocks.
    rseg : (B+1,) row offsets of the blocks.
    rows : (n,) sample index (within its maneuver) of each row.
    y, z : (n,) model output and measurement at the rows.
    JT : (m, n) Jacobian in slot space, stored slot by slot (None if not requested or not kept):
        row ``s`` within block ``b`` is the derivative with respect to parameter ``colmap[b, s]``.
    colmap : (B, m) parameter index of each slot, per block.
    normal : per block ``J^T J``, ``J^T e`` and non-zero counts per slot (with the Jacobian).
    dydv : (n, 3) ``dy / dV`` at the rows, the output's derivative with respect to the body-axis
        velocity of the air at the sensors (a uniform change of the air's velocity relative to
        the states' velocity, i.e. minus a wind in body axes), m/s -> SI of the channel; with the
        Jacobian when asked for (``evaluate_all(..., wind=True)``), else None. The filter-error
        method's wind sensitivity (:mod:`estimator.filter_error`).
    shift_s : (n,) the channel's time shift ``tau`` at the rows, s (with ``dydv``): the row's
        output is the flight at ``t - tau``.
    slope : (n,) ``dy / dx`` at the rows, the output's derivative with respect to the flow signal
        the channel measures (``ChannelSpec.measures``; with the Jacobian, else None): where it
        vanishes or changes sign the calibration cannot be applied (inverted).
    """

    channel: int
    mans: np.ndarray
    rseg: np.ndarray
    rows: np.ndarray
    y: np.ndarray
    z: np.ndarray
    JT: np.ndarray | None
    colmap: np.ndarray
    normal: tuple | None = field(default=None, repr=False)
    dydv: np.ndarray | None = field(default=None, repr=False)
    shift_s: np.ndarray | None = field(default=None, repr=False)
    slope: np.ndarray | None = field(default=None, repr=False)

    @property
    def J(self) -> np.ndarray | None:
        """(n, m) the Jacobian rows (a view of ``JT``)."""
        return None if self.JT is None else self.JT.T

    @property
    def e(self) -> np.ndarray:
        return self.z - self.y

    def block_normals(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per block ``J^T J`` (B, m, m), ``J^T e`` (B, m) and non-zero counts per column (B, m).

        Unweighted: the solver weights them with 1/R of the channel, which changes between
        iterations while the Jacobian does not.
        """
        if self.normal is None:
            raise ValueError("evaluated without the Jacobian")
        return self.normal


@dataclass
class Evaluation:
    """Every channel of a set of maneuvers, evaluated at one parameter vector.

    Attributes
    ----------
    maneuvers : the maneuver indices evaluated.
    X : (N, 7) states (the CG's velocity, attitude, altitude) of those maneuvers, concatenated;
        maneuver ``maneuvers[i]`` is ``X[seg[i]:seg[i+1]]``.
    seg : sample offsets.
    channels : one :class:`ChannelEval` per channel present in any of the maneuvers.
    """

    maneuvers: tuple[int, ...]
    X: np.ndarray
    seg: np.ndarray
    channels: list[ChannelEval]


def _signal_key(name: str, sensor: str | None) -> tuple[str, str | None]:
    """A state signal's identity: a sensor signal (``*_s``: flow angles, velocity components)
    differs per sensor, the others do not."""
    return name, (sensor if name.endswith("_s") else None)



class ModelEvaluationError(ValueError):
    """The model cannot be evaluated at these parameter values (an implicit model diverges)."""


def _filled(t_s: np.ndarray, v: np.ndarray) -> np.ndarray:
    """A measurement as a model input at every sample: an own-rate channel (NaN between its
    samples) interpolated linearly; it is fitted only where it has samples."""
    fin = np.isfinite(v)
    return v if fin.all() else np.interp(t_s, t_s[fin], v[fin])


class _ChannelLayout:
    """What a channel needs that does not depend on the parameter values, for a maneuver set."""

    def __init__(self, model: Model, c: int, ks: tuple[int, ...], sub_seg: np.ndarray,
                 grids: dict[tuple[int, ...], tuple[np.ndarray, ...]]):
        """``grids``: the per-sample time grids already built for a set of maneuver positions,
        shared by the channels present in the same maneuvers (read only)."""
        p = model.problem
        ps = p.parameters
        ch = p.channels[c]
        expr = ch.expression
        self.c, self.ch, self.expr = c, ch, expr
        pos = [i for i, k in enumerate(ks) if c in model._present_set[k]]
        self.pos = np.array(pos, dtype=np.intp)
        self.mans = np.array([ks[i] for i in pos], dtype=np.intp)
        mans = [p.maneuvers[k] for k in self.mans]
        lens = np.array([m.n for m in mans], dtype=np.intp)
        self.lens = lens
        self.cseg = np.concatenate([[0], np.cumsum(lens)]).astype(np.intp)
        # evaluation samples: every sample of the channel's maneuvers (the implicit models'
        # fixed point is iterated over all of them, as for one maneuver); rows: the cost's
        grid = grids.get(tuple(pos))
        if grid is None:
            grid = grids[tuple(pos)] = (
                np.repeat(sub_seg[self.pos], lens).astype(np.int64),  # maneuver's first sample
                np.concatenate([m.t_s for m in mans]) if mans else np.zeros(0),
                np.repeat([m.t_s[0] for m in mans], lens),
                np.repeat([m.dt_s for m in mans], lens),
                np.repeat(lens - 2, lens).astype(np.int64))
        self.off, self.t, self.t0, self.dt, self.last = grid
        rows, local, rseg = [], [], [0]
        for b, k in enumerate(self.mans):
            g = model.guard_samples(int(k), c)
            r = np.arange(g, lens[b] - g)
            # an own-rate channel (NaN between its samples) is fitted at its samples only
            r = r[np.isfinite(mans[b].measurements[ch.column][r])]
            local.append(r)
            rows.append(self.cseg[b] + r)
            rseg.append(rseg[-1] + r.size)
        self.rows = np.concatenate(rows) if rows else np.zeros(0, dtype=np.intp)
        self.local_rows = np.concatenate(local) if local else np.zeros(0, dtype=np.intp)
        self.rseg = np.array(rseg, dtype=np.intp)
        self.z = np.concatenate([_filled(m.t_s, m.measurements[ch.column]) for m in mans]
                                ) if mans else np.zeros(0)
        self.z_rows = self.z[self.rows]
        self.data: dict[str, np.ndarray] = {}
        for name in expr.names - STATE_SIGNALS - {"z", "zhat"}:
            if name in ps.specs:
                continue
            cols = model._channel_columns
            self.data[name] = np.concatenate([_filled(m.t_s,
                m.signals[name] if name in m.signals else
                m.measurements[name] if name in m.measurements else m.measurements[cols[name]])
                for m in mans])
        self.state_names = sorted(expr.names & STATE_SIGNALS)
        # slot space: 13 state-equation parameters, parameters, tables (K each), time shift
        self.pnames = sorted(n for n in expr.names if n in ps.specs)
        self.tnames = sorted(expr.tables)
        cols = [model._state_idx[self.mans]]
        self.pslot, self.pidx = {}, {}
        nslot = len(STATE_PARAMS)
        for name in self.pnames:
            idx = np.array([ps.index(ps.key_of(name, m, ch)) for m in mans], dtype=np.intp)
            self.pidx[name] = idx
            self.pslot[name] = nslot
            cols.append(idx[:, None])
            nslot += 1
        self.tbase, self.tidx = {}, {}
        for t in self.tnames:
            K = model._tables[t].breakpoints.size
            idx = np.array([[ps.index(ps.key_of(t, m, ch, e)) for e in range(K)] for m in mans],
                           dtype=np.intp).reshape(len(self.mans), K)
            self.tidx[t] = idx
            self.tbase[t] = nslot
            cols.append(idx)
            nslot += K
        self.didx = None
        if ch.delay:
            self.didx = np.array([ps.index(ps.key_of(ch.delay, m, ch)) for m in mans],
                                 dtype=np.intp)
            self.dslot = nslot
            cols.append(self.didx[:, None])
            nslot += 1
        self.m = nslot
        # relative work of an evaluation with the Jacobian (rows times slots), to balance threads
        self.cost = float(self.rows.size * (self.m + 13))
        self.colmap = np.hstack(cols).astype(np.intp) if len(self.mans) else np.zeros((0, nslot), np.intp)
        # whether every maneuver uses the same instance, per index array of this layout (fixed:
        # asked at every evaluation); keyed by identity, the arrays living as long as the layout
        owned = [*self.pidx.values(), *self.tidx.values(), *([self.didx] if ch.delay else [])]
        self._common = {id(idx): _same_instance(idx) for idx in owned}

    def index_per_sample(self, idx: np.ndarray, values: np.ndarray):
        """Values of per-maneuver parameter indices (B,) or (B, K): one value (a scalar, or a (K,)
        table) if every maneuver uses the same instance, as for one maneuver; else one per
        evaluation sample."""
        common = self._common.get(id(idx))
        if common is None:
            common = _same_instance(idx)
        if common:
            first = values[idx[0]]
            return float(first) if idx.ndim == 1 else first
        return np.repeat(values[idx], self.lens, axis=0)


def _same_instance(idx: np.ndarray) -> bool:
    """Do all maneuvers' rows of the index array ``idx`` (B,) or (B, K) name the same parameters?"""
    return bool(idx.shape[0]) and bool(np.all(idx == idx[:1]))


class _Layout:
    """The concatenated data of a maneuver set and its channel layouts."""

    def __init__(self, model: Model, ks: tuple[int, ...]):
        p = model.problem
        self.ks = ks
        lens = np.array([p.maneuvers[k].n for k in ks], dtype=np.intp)
        self.seg = np.concatenate([[0], np.cumsum(lens)]).astype(np.int64)
        full = model._inputs
        if ks == tuple(range(len(p.maneuvers))):
            self.inputs = full
        else:
            idx = np.concatenate([np.arange(full.seg[k], full.seg[k + 1]) for k in ks])
            self.inputs = Inputs(self.seg, full.t_s[idx],
                                 ImuSamples(full.a_m[idx], full.om_m[idx], full.omd[idx]),
                                 ImuSamples(full.a_mid[idx], full.om_mid[idx], full.omd_mid[idx]),
                                 full.r_imu_cg[list(ks)], lever_arm=full.lever_arm)
        self.lens = lens
        self.r_cg = np.repeat(np.array([p.maneuvers[k].r_cg_body_m for k in ks], dtype=float).reshape(-1, 3),
                              lens, axis=0)
        # the point whose velocity the states are (the flow at a sensor at r_s is
        # V + omega x (r_s - r_ref)); for the IMU point, the CG is a sensor at r_cg too
        self.imu_point = full.lever_arm == "imu_point"
        self.r_ref = (np.repeat(np.reshape(p.imu_position_body_m, (1, 3)).astype(float), lens.sum(), axis=0)
                      if self.imu_point else self.r_cg)
        self.r_ref_cg = self.r_ref - self.r_cg  # the CG "sensor" at the origin: r = r_cg - r_ref
        self.state_idx = model._state_idx[list(ks)]
        self.S: np.ndarray | None = None  # sensitivity buffer, reused by every evaluation
        present = sorted({c for k in ks for c in model._present[k]})
        grids: dict[tuple[int, ...], tuple[np.ndarray, ...]] = {}
        self.channels = [_ChannelLayout(model, c, ks, self.seg[:-1], grids) for c in present]
        # every state signal the channels use, numbered for the derivative stacks SA, SB, SV
        keys = {_signal_key(n, cl.ch.sensor) for cl in self.channels for n in cl.state_names}
        self.sig_id = {k: i for i, k in enumerate(sorted(keys, key=str))}
        self.SA = self.SB = self.SV = None


class _TimeShift(NamedTuple):
    """A channel's samples at ``t - tau`` on its maneuvers' grids: each sample's left grid index
    ``P0`` and the weight ``w`` of the right one (linear interpolation)."""

    P0: np.ndarray
    w: np.ndarray


def _signals_then_channels(lay: _Layout, state_signal: Callable, channel: Callable) -> list:
    """Every state signal first (the channels then only read them), then the channels (``channel``
    evaluates one), which are independent: on two threads for a large problem (the compiled kernels
    and numpy's array loops release the GIL; the threads end before this returns). The channels'
    evaluations in ``lay.channels`` order."""
    # one request per signal identity (a CG signal is the same for every sensor)
    needed = list({_signal_key(name, cl.ch.sensor): (name, cl.ch.sensor)
                   for cl in lay.channels for name in cl.state_names}.values())
    if worker_threads() > 1 and lay.inputs.t_s.size >= _THREADED_SAMPLES and len(lay.channels) > 1:
        with ThreadPoolExecutor(worker_threads()) as ex:
            # distinct signals write distinct rows of the stacks and cache keys
            list(ex.map(lambda ns: state_signal(*ns), needed))
            # longest first, so that the two threads finish together
            order = sorted(range(len(lay.channels)), key=lambda i: -lay.channels[i].cost)
            done = dict(zip(order, ex.map(lambda i: channel(lay.channels[i]), order), strict=True))
        return [done[i] for i in range(len(lay.channels))]
    for ns in needed:
        state_signal(*ns)
    return [channel(cl) for cl in lay.channels]


class Model:
    """Precomputed structure of a problem; evaluates maneuvers for given parameter values.

    A Model reuses scratch buffers between evaluations: use one Model per thread.

    Parameters
    ----------
    problem : the problem.
    derivative_window_s : Savitzky-Golay window for the angular accelerations, s (used by the
        "differentiated" lever arm only).
    lever_arm : the state equations' lever-arm formulation, "imu_point" or "differentiated"
        (:mod:`estimator.core.sensitivity`); None: the problem's (``Problem.lever_arm``).
    """

    def __init__(self, problem: Problem, derivative_window_s: float = 0.15, lever_arm: str | None = None):
        self.problem = problem
        self.lever_arm = problem.lever_arm if lever_arm is None else lever_arm
        if self.lever_arm not in LEVER_ARMS:
            raise ValueError(f"lever_arm must be one of {LEVER_ARMS}, got {self.lever_arm!r}")
        ps = problem.parameters
        self._tables = {
            name: Table(name, np.asarray(spec.breakpoints))
            for name, spec in ps.specs.items() if spec.breakpoints is not None
        }
        # angular accelerations: the differentiated lever arm's only (unused, zero, otherwise)
        self._omega_dot = [smoothed_derivative(m.t_s, m.omega_rps, window_s=derivative_window_s)
                           if self.lever_arm == "differentiated" else np.zeros_like(m.omega_rps)
                           for m in problem.maneuvers]
        # which channels each maneuver has, and the guard band of each channel
        self._present = [
            [c for c, ch in enumerate(problem.channels) if ch.column in m.measurements]
            for m in problem.maneuvers
        ]
        self._present_set = [set(v) for v in self._present]
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
        mans = problem.maneuvers
        self._inputs = Inputs.concatenate(
            [m.t_s for m in mans], [m.accel_imu_mps2 for m in mans], [m.omega_rps for m in mans],
            self._omega_dot,
            np.array([problem.imu_position_body_m - m.r_cg_body_m for m in mans], dtype=float).reshape(-1, 3),
            lever_arm=self.lever_arm,
        )
        self._state_idx = np.array([self.state_columns(k) for k in range(len(mans))],
                                   dtype=np.intp).reshape(len(mans), len(STATE_PARAMS))
        self._layouts: dict[tuple[int, ...], _Layout] = {}

    @property
    def _channel_columns(self) -> dict[str, str]:
        return {ch.name: ch.column for ch in self.problem.channels}

    # ------------------------------------------------------------------ parameter resolution
    # (keys: estimator.parameters.ParameterSet.key_of, the one resolver)
    def state_columns(self, k: int) -> np.ndarray:
        ps = self.problem.parameters
        return np.array([ps.index(ps.key_of(n, self.problem.maneuvers[k])) for n in STATE_PARAMS])

    def guard_samples(self, k: int, c: int) -> int:
        m = self.problem.maneuvers[k]
        return int(np.ceil(self._guard_s[c] / m.dt_s)) + 1 if self._guard_s[c] > 0 else 0

    def _layout(self, ks: tuple[int, ...]) -> _Layout:
        lay = self._layouts.get(ks)
        if lay is None:
            lay = self._layouts[ks] = _Layout(self, ks)
        return lay

    def forget(self, maneuvers: tuple[int, ...]) -> None:
        """Drop the cached layout of the maneuver subset ``maneuvers`` (maneuver indices) and its
        scratch buffers: a subset evaluated once (a chunk of the honest deviations) would hold
        them for the model's life. The whole problem's layout is kept."""
        ks = tuple(int(k) for k in maneuvers)
        if ks != tuple(range(len(self.problem.maneuvers))):
            self._layouts.pop(ks, None)

    def release_scratch(self) -> None:
        """Free every cached layout's scratch buffers (the sensitivities and the state signals'
        derivative stacks; the next evaluation with the Jacobian allocates them again): before
        evaluating chunks of the maneuvers, which have their own."""
        for lay in self._layouts.values():
            lay.S = lay.SA = lay.SB = lay.SV = None

    def channel_layout(self) -> list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
        """The static structure of every channel over all maneuvers, as :meth:`evaluate_all` gives it.

        Returns
        -------
        One ``(channel, mans, colmap, rseg)`` per channel present: channel index, (B,) maneuver
        indices of its blocks, (B, m) parameter index of each Jacobian slot per block, (B+1,) row
        offsets of the blocks in the cost.
        """
        lay = self._layout(tuple(range(len(self.problem.maneuvers))))
        return [(cl.c, cl.mans, cl.colmap, cl.rseg) for cl in lay.channels]

    # ------------------------------------------------------------------ evaluation
    def last_sensitivities(self, maneuvers: tuple[int, ...]) -> list[np.ndarray]:
        """The sensitivities ``dX/d(x0, IMU biases)`` (N_k, 7, 13) per maneuver that the last
        :meth:`evaluate_all` with the Jacobian of exactly this maneuver set integrated: views of
        its scratch, valid until the set is evaluated again, forgotten or its scratch released."""
        lay = self._layouts.get(tuple(int(k) for k in maneuvers))
        if lay is None or lay.S is None:
            raise ValueError(f"maneuvers {maneuvers}: not evaluated with the Jacobian as a set; call "
                             "evaluate_all(values, jacobian=True, maneuvers=...) first")
        return [lay.S[lay.seg[i]:lay.seg[i + 1]] for i in range(len(lay.ks))]

    def evaluate(self, values: np.ndarray, k: int, jacobian: bool = True) -> ManeuverEval:
        """Outputs (and Jacobian blocks) of every channel present in maneuver ``k``."""
        ev = self.evaluate_all(values, jacobian, maneuvers=(k,))
        blocks = []
        for ce in ev.channels:
            blocks.append(ChannelBlock(ce.channel, ce.rows, ce.y, ce.z, ce.J, ce.colmap[0].copy()))
        return ManeuverEval(k, ev.X, tuple(blocks))

    def evaluate_all(self, values: np.ndarray, jacobian: bool = True,
                     maneuvers: tuple[int, ...] | None = None, keep_jacobian: bool = True,
                     on_channel=None, wind: bool = False) -> Evaluation:
        """Outputs (and Jacobians) of every channel of the given maneuvers (default: all).

        Parameters
        ----------
        values : (P,) all parameter values, in ``ParameterSet`` order.
        jacobian : also the Jacobian (sensitivities are integrated only then) and each block's
            normal-equation terms (:meth:`ChannelEval.block_normals`).
        maneuvers : maneuver indices; None for every maneuver of the problem.
        keep_jacobian : keep the Jacobian (``ChannelEval.J``), else only each block's
            normal-equation terms (less memory traffic when the Jacobian itself is not needed).
        on_channel : called with each :class:`ChannelEval` as soon as it is complete (possibly
            on a worker thread, channels in any order): a caller that needs each channel's
            Jacobian once can use it and drop it (``ce.JT = None``) instead of holding all.
        wind : with the Jacobian, also each channel's sensitivity to the air's velocity
            (:attr:`ChannelEval.dydv`).
        """
        p = self.problem
        ks = tuple(range(len(p.maneuvers))) if maneuvers is None else tuple(int(k) for k in maneuvers)
        lay = self._layout(ks)
        values = np.asarray(values, dtype=float)
        sv = values[lay.state_idx]
        if jacobian and lay.S is None:
            lay.S = np.empty((lay.inputs.t_s.size, 7, N_SENS))
        # S is scratch (consumed below, never handed out): one buffer per maneuver set
        X, S = integrate_many(lay.inputs, sv, p.g_mps2, sensitivities=jacobian, out_S=lay.S)
        omega = lay.inputs.om_m - np.repeat(sv[:, 10:13], lay.lens, axis=0)
        cache: dict = {}
        if jacobian and lay.SA is None:
            # derivative stacks of every state signal of the maneuver set, reused (see lay.S)
            n, ns = lay.inputs.t_s.size, len(lay.sig_id)
            lay.SA, lay.SB, lay.SV = np.zeros((ns, n, 3)), np.zeros((ns, n, 3)), np.zeros((ns, n))

        def state_signal(name: str, sensor: str | None):
            """value (N,), and for the Jacobian (q, id, has_b): the signal's derivative is
            ``SA[id] . S[:, :3, :]`` plus ``SB[id]`` on the gyro-bias columns (if ``has_b``), or
            ``S[:, q, :]`` for an Euler angle or the altitude (``q >= 0``); ``SV[id]`` its value."""
            ck = _signal_key(name, sensor)
            if ck in cache:
                return cache[ck]
            sid = lay.sig_id[ck]
            if name in _EULER_INDEX:
                i = _EULER_INDEX[name]
                out = (X[:, i], (i, sid, False))
                if jacobian:
                    lay.SV[sid] = X[:, i]
            elif name in _RATE_INDEX:
                # a bias-corrected body rate: depends on its gyro bias only (d/d(d_omega) = -1)
                j = _RATE_INDEX[name]
                val = omega[:, j]
                if jacobian:
                    lay.SA[sid] = 0.0
                    lay.SB[sid] = 0.0
                    lay.SB[sid][:, j] = -1.0
                    lay.SV[sid] = val
                out = (val, (-1, sid, True))
            else:
                sensor_pos, r_ref = (p.sensors[sensor], lay.r_ref) if name.endswith("_s") else (None, None)
                if sensor_pos is None and lay.imu_point:
                    sensor_pos, r_ref = _ORIGIN, lay.r_ref_cg
                dv_out = lay.SA[sid] if jacobian else None
                b_out = lay.SB[sid] if jacobian and sensor_pos is not None else None
                val, _, _ = flow_signal_batch(X, omega, r_ref, sensor_pos, _FLOW_KIND[name], jacobian,
                                              dv_out=dv_out, b_out=b_out)
                if jacobian:
                    lay.SV[sid] = val
                out = (val, (-1, sid, sensor_pos is not None))
            cache[ck] = out
            return out

        def channel(cl):
            ce = self._evaluate_channel(cl, lay, values, S, state_signal, keep_jacobian, wind)
            if on_channel is not None:
                on_channel(ce)
            return ce

        channels = _signals_then_channels(lay, state_signal, channel)
        if lay.imu_point:  # report the CG's states
            X = X.copy()
            X[:, :3] += np.cross(omega, lay.r_cg - lay.r_ref)
        return Evaluation(ks, X, lay.seg, channels)

    def _evaluate_channel(self, cl: _ChannelLayout, lay: _Layout, values, S, state_signal,
                          keep: bool, wind: bool = False) -> ChannelEval:
        ch, expr = cl.ch, cl.expr
        jacobian = S is not None
        tau = cl.index_per_sample(cl.didx, values) if cl.didx is not None else 0.0
        # linear interpolation at t - tau on each maneuver's uniform grid
        n_all = cl.z.size
        P0 = np.empty(n_all, dtype=np.int64)
        w = np.empty(n_all)
        shift_index(cl.t, np.atleast_1d(np.asarray(tau, dtype=float)), cl.t0, cl.dt, cl.last, cl.off, P0, w)
        signals: dict[str, np.ndarray] = {}
        for name in cl.state_names:
            val, _ = state_signal(name, ch.sensor)
            signals[name] = np.empty(n_all)
            shift_values(np.ascontiguousarray(val), P0, w, signals[name])
        signals["z"] = cl.z
        signals.update(cl.data)
        params = {name: cl.index_per_sample(cl.pidx[name], values) for name in cl.pnames}
        tables = {t: (self._tables[t], cl.index_per_sample(cl.tidx[t], values)) for t in cl.tnames}
        state = frozenset(cl.state_names) if jacobian else frozenset()
        if "zhat" in expr.names:
            dual, value = self._implicit(cl, signals, params, tables, state, jacobian)
        elif jacobian:
            dual = expr.evaluate(signals, params, tables, state)
            value = dual.value
        else:
            dual, value = None, expr.value(signals, params, tables)
        y = np.broadcast_to(value, cl.z.shape)[cl.rows]
        J, normal, dydv, shift, slope = None, None, None, None, None
        if jacobian:
            J, normal = self._jacobian(cl, lay, dual, S, state_signal, _TimeShift(P0, w), cl.z_rows - y,
                                       keep)
            if ch.measures is not None and ch.measures in dual.dsignal:
                slope = np.broadcast_to(dual.dsignal[ch.measures], (n_all,))[cl.rows].copy()
            if wind:
                dydv = self._velocity_sensitivity(cl, lay, dual, state_signal, w, P0)
                shift = np.broadcast_to(np.asarray(tau, dtype=float), (n_all,))[cl.rows].copy()
        return ChannelEval(cl.c, cl.mans, cl.rseg, cl.local_rows, y, cl.z_rows, J, cl.colmap, normal,
                           dydv, shift, slope)

    @staticmethod
    def _velocity_sensitivity(cl: _ChannelLayout, lay: _Layout, dual, state_signal, w, P0):
        """``dy/dV`` (n, 3) at the channel's rows: the model's derivatives with respect to its
        flow signals times theirs with respect to the velocity (``lay.SA``), at the shifted time."""
        rows = cl.rows
        n_all = cl.z.size
        out = np.zeros((rows.size, 3))
        p0, wr = P0[rows], w[rows][:, None]
        for name, d in dual.dsignal.items():
            if name not in AIR_RELATIVE_SIGNALS:
                # Euler angles, altitude, rates and the velocity relative to the steady air mass
                # (an inertial velocity's) do not see the turbulent wind
                continue
            _, (q, sid, _) = state_signal(name, cl.ch.sensor)
            sa = lay.SA[sid]
            out += np.broadcast_to(d, (n_all,))[rows][:, None] * ((1.0 - wr) * sa[p0] + wr * sa[p0 + 1])
        return out

    @staticmethod
    def _jacobian(cl: _ChannelLayout, lay: _Layout, dual, S, state_signal, shift: _TimeShift, e,
                  keep: bool):
        """Slot-space Jacobian of a channel and its per-block normal-equation terms
        (see :func:`estimator.core.assembly.channel_normals`)."""
        P0, w = shift
        rows = cl.rows
        n = rows.size
        n_all = cl.z.size
        names = list(dual.dsignal)
        G = np.empty((len(names), n))
        sig_q = np.empty(len(names), dtype=np.int64)
        sig_id = np.empty(len(names), dtype=np.int64)
        has_b = np.zeros(len(names), dtype=np.bool_)
        qs: set[int] = set()
        for i, name in enumerate(names):
            G[i] = np.broadcast_to(dual.dsignal[name], (n_all,))[rows]
            _, (q, sid, hb) = state_signal(name, cl.ch.sensor)
            sig_q[i], sig_id[i], has_b[i] = q, sid, hb
            qs.update((q,) if q >= 0 else (0, 1, 2))
        slots, coefs = [], []
        for name, dy in dual.dparam.items():
            slots.append(np.full(n, cl.pslot[name], dtype=np.intp))
            coefs.append(np.broadcast_to(dy, (n_all,))[rows])
        for t, terms in dual.dtable.items():
            for idx, coef in terms:
                slots.append(cl.tbase[t] + np.broadcast_to(idx, (n_all,))[rows])
                coefs.append(np.broadcast_to(coef, (n_all,))[rows])
        tslot = np.ascontiguousarray(np.stack(slots, axis=1) if slots else np.zeros((n, 0)), dtype=np.int64)
        tcoef = np.ascontiguousarray(np.stack(coefs, axis=1) if coefs else np.zeros((n, 0)))
        nb = cl.rseg.size - 1
        H = np.empty((nb, cl.m, cl.m))
        g = np.empty((nb, cl.m))
        cnt = np.empty((nb, cl.m), dtype=np.int64)
        JT = np.empty((cl.m, n if keep else 0))
        channel_normals(S, RowShift(P0[rows], w[rows], cl.dt[rows]),
                        ChannelSignals(G, sig_q, sig_id, has_b, np.array(sorted(qs), dtype=np.int64)),
                        SignalStacks(lay.SA, lay.SB, lay.SV), SparseTerms(tslot, tcoef),
                        cl.dslot if cl.didx is not None else -1, e, cl.rseg.astype(np.int64), cl.m,
                        BlockNormals(H, g, cnt, JT))
        return (JT if keep else None), (H, g, cnt)

    def _implicit(self, cl: _ChannelLayout, signals, params, tables, state, jacobian: bool):
        """Solve ``y = F(y, ...)`` for a model whose argument ``zhat`` is its own output.

        ``zhat`` is the noise-free model of the measurement: a table of the measured angle,
        evaluated at the *modelled* angle, avoids the errors-in-variables bias that the noisy
        measurement ``z`` as argument causes (SPEC §5). Newton's method on ``y - F(y) = 0`` from
        ``z`` (then, should it not settle, fixed-point iteration), each maneuver until its own steps
        are below ``IMPLICIT_TOL`` (the iteration is sample-wise, so all maneuvers iterate together
        and a converged one is held); either phase ends early where its steps cycle
        (``IMPLICIT_STALLED_STEP``). The derivatives follow from ``dy = dF + F_zhat dy``, i.e.
        ``dy = dF / (1 - F_zhat)``.

        Returns
        -------
        (Dual or None, value): the Dual with the derivatives if ``jacobian``.
        """
        expr, ch = cl.expr, cl.ch
        sig = dict(signals)
        y = np.asarray(cl.z, dtype=float)
        active = np.ones(cl.lens.size, dtype=bool)
        starts = cl.cseg[:-1]
        zhat = frozenset({"zhat"})

        largest: list[float] = []  # the largest step of a still iterating maneuver, per iteration

        def settle(step: np.ndarray) -> bool:
            """Apply a step where the maneuver is still iterating; True when all have converged."""
            nonlocal y, active
            dev = np.maximum.reduceat(np.abs(step), starts) if starts.size else np.zeros(0)
            largest.append(float(dev[active].max()) if active.any() else 0.0)
            y = np.where(np.repeat(active, cl.lens), y - step, y)
            active &= ~(dev < IMPLICIT_TOL)
            return not active.any()

        def cycling(span: int, factor: float) -> bool:
            """The largest step still above IMPLICIT_STALLED_STEP and not below ``factor`` times
            itself ``span`` iterations earlier."""
            return (len(largest) > span and largest[-1] > IMPLICIT_STALLED_STEP
                    and largest[-1] > factor * largest[-1 - span])

        done = False
        # Newton on y - F(y) = 0: a plain fixed-point iteration contracts only by |dF/dzhat| per
        # step, too slowly once a table's slope approaches its bound (f4 = 0.5); where 1 - F' is
        # (next to) zero it takes the plain step
        for _ in range(IMPLICIT_ITERATIONS):
            sig["zhat"] = y
            d = expr.evaluate(sig, params, tables, zhat, by_parameters=False)  # d/dzhat alone
            r = y - np.broadcast_to(d.value, y.shape)
            denom = 1.0 - np.broadcast_to(d.dsignal.get("zhat", 0.0), y.shape)
            if settle(np.where(np.abs(denom) > 1e-3, r / np.where(denom == 0.0, 1.0, denom), r)):
                done = True
                break
            if cycling(8, 0.5):
                break
        # a safeguard for a piecewise-linear table whose kinks make Newton cycle: the fixed point
        largest.clear()
        for _ in range(0 if done else IMPLICIT_FIXED_POINT_ITERATIONS):
            sig["zhat"] = y
            if settle(y - np.broadcast_to(expr.value(sig, params, tables), y.shape)):
                done = True
                break
            if cycling(30, 0.9):
                break
        if not done:
            raise ModelEvaluationError(
                f"channel {ch.name}: the implicit model {ch.model!r} does not converge (its "
                "dependence on zhat must be weaker than 1:1); use z instead of zhat or bound the tables"
            )
        sig["zhat"] = y
        if not jacobian:
            return None, expr.value(sig, params, tables)
        dual = expr.evaluate(sig, params, tables, state | {"zhat"})
        f_z = np.broadcast_to(dual.dsignal.pop("zhat", 0.0), y.shape)
        factor = 1.0 / (1.0 - f_z)
        out = dual.scaled(factor)
        out.value = dual.value
        return out, out.value
