"""The true value of every estimator parameter of a problem built from a synthetic dataset.

This joins the two halves (the dataset's truth, the estimator's parameters), which is why it
lives in ``campaigns/``. What "true" means, per kind:

- **initial conditions**: the true air-relative velocity and Euler angles at the maneuver's first
  sample, taken at the IMU's time (the model's time axis is the IMU's: its channels lag by the
  DRU delay);
- **IMU biases**: the injected ``imu.accel_bias_mps2`` / ``imu.gyro_bias_rps``;
- **time shifts**: the injected total lag of the channel minus that of the IMU (the reference);
- **calibration parameters** (tables, biases, scale factors): the injected errors are physical
  (local flow, installation biases, the airdata computer's tables), not values of the model's
  parameters, so their truth is the *projection* of the true system onto the model structure:
  the least-squares fit of each channel's model to its clean channel (``true_clean_<channel>``:
  every deterministic error, no noise, no delay) with the true flow at the sensor as input, over
  the problem's own samples. It is what the estimator would find with perfect IMU, perfect
  initial conditions and no noise; any difference beyond the Cramér-Rao bound is estimation
  error, and the fit's own residual (reported) is the model-structure error.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from estimator.core.expressions import Table
from estimator.io import dataset_column, load_truth
from estimator.problem import SENSOR_SIGNALS, ChannelSpec, ManeuverData, Problem
from estimator.result import EstimationResult

IMU_REFERENCE = "ax_imu_mps2"


def _sensor_col(kind: str, sensor: str) -> str:
    """The true column of a sensor signal; the side-probe pair is at the probes' mean position."""
    return f"true_{kind}_sp_rad" if sensor == "side_probe" else f"true_{kind}_{sensor}_rad"


@dataclass(frozen=True)
class TruthProjection:
    """True parameter values and how well the model structure can represent the truth.

    Attributes
    ----------
    values : parameter key -> true value (SI); parameters without a truth are absent.
    structure_rms : channel -> rms of the clean channel minus the best-fitting model, SI.
    """

    values: Mapping[str, float]
    structure_rms: Mapping[str, float]


def _interp_truth(tr: pd.DataFrame, col: str, t: np.ndarray) -> np.ndarray:
    return np.interp(t, tr["t_s"].to_numpy(), tr[col].to_numpy())


def truths_of(problem: Problem, cache: dict | None = None) -> dict[str, pd.DataFrame]:
    """Every maneuver's truth (:func:`estimator.io.load_truth`), each read once per ``cache``.

    Parameters
    ----------
    problem : a problem built from a synthetic dataset.
    cache : a dict the caller keeps for one run (a report's stages, a replication's projection and
        error table), keyed by the maneuver's dataset, file, sortie window and id; None: read
        here. The frames are shared: read them, never change them.

    Returns
    -------
    maneuver id -> its truth (``t_s`` and every ``true_*`` column).
    """
    out = {}
    for m in problem.maneuvers:
        meta = m.meta
        key = (meta.get("dataset"), meta.get("file"), tuple(meta.get("sortie_window_s", ())), m.id)
        if cache is None:
            out[m.id] = load_truth(problem, m.id)
            continue
        if key not in cache:
            cache[key] = load_truth(problem, m.id)
        out[m.id] = cache[key]
    return out


def true_parameters(problem: Problem, estimated: np.ndarray | None = None,
                    truth_cache: dict | None = None) -> TruthProjection:
    """True values of the problem's parameters (see the module docstring).

    Parameters
    ----------
    problem : the problem, built from a synthetic dataset.
    estimated : (P,) the parameters the estimator estimated (``EstimationResult.free_estimated``);
        the projection frees the same calibration parameters, so that where the estimator held one
        member of a confounded set (a table value anchoring the biases) the truth is anchored
        there too. None: the problem's free parameters.
    truth_cache : the maneuvers' truth, read once for several callers (:func:`truths_of`).
    """
    ps = problem.parameters
    specs = ps.specs
    values: dict[str, float] = {}
    truths = truths_of(problem, truth_cache)
    chan_col = {c.name: c.column for c in problem.channels}

    def lag(inj: Mapping, column: str) -> float | None:
        v = inj.get(f"time_shift_s.{column}")
        return None if v is None else float(v) - float(inj.get(f"time_shift_s.{IMU_REFERENCE}", 0.0))

    for m in problem.maneuvers:
        inj = m.meta.get("injected", {})
        tr = truths[m.id]
        # the model's clock is the IMU's: its sample at t shows the flight at t - (IMU lag)
        t_imu = m.t_s[:1] - float(inj.get(f"time_shift_s.{IMU_REFERENCE}", 0.0))
        ic = {"u0": "true_u_air_mps", "v0": "true_v_air_mps", "w0": "true_w_air_mps",
              "phi0": "true_phi_rad", "theta0": "true_theta_rad", "psi0": "true_psi_rad"}
        for name, col in ic.items():
            if name in specs:
                values[ps.key_of(name, m)] = float(_interp_truth(tr, col, t_imu)[0])
        # the steady wind of the INS-velocity model (tejas_ins): the maneuver's mean true wind (the
        # turbulent part is the wind states', zero-mean) plus the INS velocity bias, which a
        # steady wind cannot be told from
        vbias = inj.get("ins.velocity_bias_mps")
        for i, name in enumerate(("wind_n", "wind_e", "wind_d")):
            col = f"true_{name}_mps"
            if name in specs and col in tr:
                values[ps.key_of(name, m)] = float(np.mean(tr[col])) + (float(vbias[i]) if vbias else 0.0)
        acc = inj.get("imu.accel_bias_mps2")
        gyr = inj.get("imu.gyro_bias_rps")
        for i, name in enumerate(("dax", "day", "daz")):
            if acc is not None and name in specs:
                values[ps.key_of(name, m)] = float(acc[i])
        for i, name in enumerate(("dp", "dq", "dr")):
            if gyr is not None and name in specs:
                values[ps.key_of(name, m)] = float(gyr[i])
        for ch in problem.channels:
            if ch.delay and ch.column in m.measurements:
                d = lag(inj, maneuver_column(ch.column, m))
                if d is not None:
                    values[ps.key_of(ch.delay, m, ch)] = d
    free = ps.free_mask if estimated is None else np.asarray(estimated, dtype=bool)
    structure = _project_calibration(problem, truths, values, chan_col, free)
    return TruthProjection(values=values, structure_rms=structure)


def maneuver_column(canonical: str, m) -> str:
    """The dataset column of a canonical name in maneuver ``m`` (its manifest entry lists them)."""
    return dataset_column(canonical, m.meta.get("channel_units", ()))


#: model signal -> the truth column it is at the CG (or from the IMU's true rates)
_TRUE_CG_COLUMNS = {"alpha_t": "true_alpha_cg_rad", "beta_t": "true_beta_cg_rad",
                    "tas_t": "true_tas_mps", "p": "true_p_rps", "q": "true_q_rps", "r": "true_r_rps"}
#: sensor signal -> the kind of its truth column (``true_<kind>_<sensor>_rad``)
SENSOR_SIGNAL_KINDS = {"alpha_s": "alpha", "beta_s": "beta", "flank_s": "flank"}


def true_signals(at, columns, sensor: str) -> dict[str, np.ndarray]:
    """The model's state signals from the truth: each sensor signal the truth has for ``sensor``
    and the CG ones, each read by ``at(column)`` (e.g. interpolated at the samples wanted)."""
    sig = {name: at(_sensor_col(kind, sensor)) for name, kind in SENSOR_SIGNAL_KINDS.items()
           if _sensor_col(kind, sensor) in columns}
    sig |= {name: at(col) for name, col in _TRUE_CG_COLUMNS.items()}
    return sig


def problem_tables(problem: Problem) -> dict[str, Table]:
    """Every table family of a problem as a :class:`Table` (its breakpoints)."""
    return {n: Table(n, np.asarray(s.breakpoints)) for n, s in problem.parameters.specs.items()
            if s.breakpoints}


def parameter_indices(problem: Problem, m, ch, tables: dict[str, Table]
                      ) -> tuple[dict[str, int], dict[str, np.ndarray]]:
    """Where a channel model's parameters and table values for maneuver ``m`` sit in the
    parameter vector: ``(scalar name -> index, table name -> (K,) indices)``. KeyError if an
    instance is missing (an aircraft without that parameter)."""
    ps = problem.parameters
    expr = ch.expression
    return ({n: ps.index(ps.key_of(n, m, ch)) for n in expr.names if n in ps.specs},
            {n: np.array([ps.index(ps.key_of(n, m, ch, e)) for e in range(tables[n].breakpoints.size)])
             for n in expr.tables})


def values_at(theta: np.ndarray, tables: dict[str, Table], param_at: Mapping[str, int],
              table_at: Mapping[str, np.ndarray]) -> tuple[dict, dict]:
    """``(params, tabs)`` as :meth:`Expression.evaluate` takes them, at the values ``theta`` (SI),
    from :func:`parameter_indices`."""
    return ({n: theta[i] for n, i in param_at.items()},
            {n: (tables[n], theta[idx]) for n, idx in table_at.items()})


def channel_values(problem: Problem, theta: np.ndarray, m, ch, tables: dict[str, Table]):
    """A channel model's parameters and tables for maneuver ``m`` at the values ``theta`` (SI):
    ``(params, tabs)`` as :meth:`Expression.evaluate` takes them. KeyError if an instance is
    missing (an aircraft without that parameter)."""
    return values_at(theta, tables, *parameter_indices(problem, m, ch, tables))


def _cases(problem: Problem, truths, chan_col) -> list[_Case]:
    """Every (channel, maneuver) whose clean channel the truth has, with the signals the channel's
    model reads taken from the truth."""
    ps = problem.parameters
    cases = []
    for ch in problem.channels:
        if not ch.expression.names & SENSOR_SIGNALS:  # no flow angle: attitude, air data, INS
            continue
        for m in problem.maneuvers:
            tr = truths[m.id]
            clean_col = f"true_clean_{maneuver_column(ch.column, m)}"
            if ch.column not in m.measurements or clean_col not in tr:
                continue
            t = tr["t_s"].to_numpy()
            y = tr[clean_col].to_numpy()
            sig = true_signals(lambda c, tr=tr: tr[c].to_numpy(), tr.columns, ch.sensor)
            sig |= {"z": y, "zhat": y}
            for name in ch.expression.names - set(sig):
                if name in ps.specs:
                    continue
                clean_other = f"true_clean_{maneuver_column(chan_col.get(name, name), m)}"
                if clean_other in tr:
                    sig[name] = tr[clean_other].to_numpy()
                elif name in m.signals:
                    sig[name] = np.interp(t, m.t_s, m.signals[name])
            cases.append(_Case(ch, m, sig, y))
    return cases


@dataclass
class _Case:
    """One (channel, maneuver) of the projection: the signals its model reads from the truth, its
    clean channel, and what stays the same from one Gauss-Newton step to the next — where its
    parameters sit in ``theta``, its block's columns and, for a model affine in its parameters,
    the block itself."""

    channel: ChannelSpec
    maneuver: ManeuverData
    signals: dict
    y: np.ndarray
    param_at: dict = field(default_factory=dict)  # scalar parameter -> index in theta
    table_at: dict = field(default_factory=dict)  # table -> indices in theta of its breakpoints
    columns: np.ndarray | None = None  # the block's free calibration parameters (sorted)
    scalar_local: dict = field(default_factory=dict)  # scalar parameter -> block column
    table_local: dict = field(default_factory=dict)  # table -> block column per breakpoint, or -1
    affine_A: np.ndarray | None = None  # the block, where it does not depend on the parameters
    affine_qr: tuple | None = None  # and its QR factors

    def values(self, theta: np.ndarray, tables: dict[str, Table]) -> tuple[dict, dict]:
        """The model's parameters and tables at ``theta`` (:func:`values_at`)."""
        return values_at(theta, tables, self.param_at, self.table_at)


def _case_layout(problem: Problem, case: _Case, tables: dict[str, Table], index: Mapping[str, int],
                 dual) -> None:
    """Where ``case``'s parameters sit in ``theta`` and in its block (``index``: a free
    calibration parameter's column), from its model's first evaluation ``dual``."""
    ps = problem.parameters
    ch, m = case.channel, case.maneuver
    scalar = {n: index[ps.key_of(n, m, ch)] for n in dual.dparam if ps.key_of(n, m, ch) in index}
    # each breakpoint's column, -1 where it is not a free calibration parameter
    breaks = {n: np.array([index.get(ps.key_of(n, m, ch, e), -1)
                           for e in range(tables[n].breakpoints.size)]) for n in dual.dtable}
    case.columns = np.unique(np.concatenate([np.fromiter(scalar.values(), int, len(scalar))]
                                            + [c[c >= 0] for c in breaks.values()]))
    local = {int(c): j for j, c in enumerate(case.columns)}
    case.scalar_local = {n: local[c] for n, c in scalar.items()}
    case.table_local = {n: np.array([local.get(int(c), -1) for c in b]) for n, b in breaks.items()}


def _fill_block(case: _Case, dual) -> np.ndarray:
    """``case``'s block from its model's evaluation ``dual``: (samples, columns), the derivatives
    along the free calibration parameters it depends on."""
    y = case.y
    A = np.zeros((y.size, case.columns.size))
    for n, j in case.scalar_local.items():
        A[:, j] += np.broadcast_to(dual.dparam[n], y.shape)
    samples = np.arange(y.size)
    for n, terms in dual.dtable.items():
        to_local = case.table_local[n]
        for idx, coef in terms:
            # one breakpoint per sample and term: a sample's column gets its coefficient
            c = to_local[np.broadcast_to(idx, y.shape)]
            hit = c >= 0
            A[samples[hit], c[hit]] += np.broadcast_to(coef, y.shape)[hit]
    return A


def _case_block(problem: Problem, theta: np.ndarray, case: _Case, tables: dict[str, Table],
                index: Mapping[str, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One case's linearised fit at ``theta``: ``(columns, A, b)``, ``A`` (samples, columns) the
    derivatives of the channel model along the free calibration parameters it depends on (their
    ``index`` entries, sorted), ``b`` the clean channel minus the model.

    At the first call the case's layout is found and whether its model is affine in its free
    parameters (:meth:`~estimator.core.expressions.Expression.affine_in`, read off the model's
    tree): then its block does not depend on them, and it is kept with its QR factors, only its
    value evaluated after that (``f5(alpha_t) * (beta_s + b_n)`` with both free is not affine: the
    column of ``b_n`` is ``f5``'s value).
    """
    expr, y = case.channel.expression, case.y
    if case.affine_A is not None:
        return case.columns, case.affine_A, y - np.broadcast_to(
            expr.value(case.signals, *case.values(theta, tables)), y.shape)
    first = case.columns is None
    if first:
        case.param_at, case.table_at = parameter_indices(problem, case.maneuver, case.channel, tables)
    dual = expr.evaluate(case.signals, *case.values(theta, tables))
    if first:
        _case_layout(problem, case, tables, index, dual)
    A = _fill_block(case, dual)
    if first:
        free = set(case.scalar_local) | {n for n, c in case.table_local.items() if (c >= 0).any()}
        if expr.affine_in(free):
            case.affine_A, case.affine_qr = A, np.linalg.qr(A)
    return case.columns, A, y - np.broadcast_to(dual.value, y.shape)


def solve_blocks(blocks, n_columns: int, factors=None) -> tuple[np.ndarray, np.ndarray]:
    """The least-squares solution of row blocks that each touch a few columns, as
    ``np.linalg.lstsq`` (default rank cut) gives it for the whole matrix over its live columns.

    Each block ``A_c = Q_c R_c`` is reduced to its triangular factor: the stack of the ``R_c`` has
    the stack of the ``A_c``'s singular values, so the same solution and, with the rank cut set as
    the whole matrix's (``eps x rows``), the same rank decision; the whole matrix is never formed.

    Parameters
    ----------
    blocks : ``(columns, A, b)`` per block: ``columns`` (k,) int, the block's column indices,
        sorted; ``A`` (n, k); ``b`` (n,).
    n_columns : the whole matrix's columns.
    factors : per block, its ``A``'s QR factors ``(Q, R)`` where the caller has them, or None.

    Returns
    -------
    ``(x, live)``: ``live`` (n_columns,) bool, the columns with a nonzero entry; ``x`` the solution
    over them (minimum norm where they are rank-deficient).
    """
    R_rows, rhs = [], []
    live = np.zeros(n_columns, dtype=bool)
    n_rows = 0
    for k, (columns, A, b) in enumerate(blocks):
        n_rows += A.shape[0]
        live[columns[(A != 0.0).any(axis=0)]] = True
        Q, R = factors[k] if factors is not None and factors[k] is not None else np.linalg.qr(A)
        R_full = np.zeros((R.shape[0], n_columns))
        R_full[:, columns] = R
        R_rows.append(R_full)
        rhs.append(Q.T @ b)
    rcond = np.finfo(float).eps * max(n_rows, int(live.sum()))
    R_all = np.vstack(R_rows) if R_rows else np.zeros((0, n_columns))
    rhs_all = np.concatenate(rhs) if rhs else np.zeros(0)
    x, *_ = np.linalg.lstsq(R_all[:, live], rhs_all, rcond=rcond)
    return x, live


def _project_calibration(problem: Problem, truths, values: dict, chan_col, free: np.ndarray
                         ) -> dict[str, float]:
    """Least-squares fit of the calibration parameters to the clean channels (module docstring).

    Gauss-Newton from the problem's start values, projected onto the parameters' bounds: most
    calibration models are affine in their parameters, some are not (``f5(alpha_t) * (beta_s +
    b_n)``). Each step is the least-squares solution of every case's rows at once
    (:func:`solve_blocks`): a case touches a few of the parameters, and the whole design matrix
    (840,000 rows in the demo) is never formed.
    """
    ps = problem.parameters
    calib_kinds = ("table", "bias", "scale")
    tables = problem_tables(problem)
    cases = _cases(problem, truths, chan_col)
    theta = ps.values.copy()
    free_calib = [p.key for p, f in zip(ps, free, strict=True) if f and p.kind in calib_kinds]
    index = {k: i for i, k in enumerate(free_calib)}
    if not free_calib or not cases:
        return {}
    for _ in range(8):
        blocks = [_case_block(problem, theta, case, tables, index) for case in cases]
        step, live = solve_blocks(blocks, len(free_calib), [case.affine_qr for case in cases])
        moved = 0.0
        for j, k in enumerate(np.array(free_calib)[live]):
            # within the parameter's bounds, as the estimator: a breakpoint the samples hardly
            # reach would otherwise take any value (f2 at -4 deg alpha: -60 on a few samples)
            lo, hi = ps[k].bounds
            i = ps.index(k)
            new = min(max(theta[i] + step[j], lo), hi)
            moved = max(moved, abs(new - theta[i]))
            theta[i] = new
        # converged when the parameters stop moving: the step of one held on its bound does not
        # vanish (it asks for the same move at every iteration)
        if moved < 1e-12:
            break
    for k, ok in zip(free_calib, live, strict=True):
        if ok:
            values[k] = float(theta[ps.index(k)])
    # structure error: what the best fit leaves, per channel
    out: dict[str, list[np.ndarray]] = {}
    for case in cases:
        fit = np.broadcast_to(case.channel.expression.value(case.signals, *case.values(theta, tables)),
                              case.y.shape)
        out.setdefault(case.channel.name, []).append(case.y - fit)
    return {c: float(np.sqrt(np.mean(np.concatenate(v) ** 2))) for c, v in out.items()}


def recovery_table(result: EstimationResult, truth: TruthProjection) -> pd.DataFrame:
    """Estimate, truth, Cramér-Rao and coloured deviations and z-scores of every estimated
    parameter that has a truth, in display units (a held one has no deviation to judge it by)."""
    df = result.to_pandas()
    df = df[df["estimated"] & df.index.isin(list(truth.values))].copy()
    df["truth_display"] = [truth.values[k] * result.parameters[k].display_scale for k in df.index]
    df["error_display"] = df["value_display"] - df["truth_display"]
    df["z_crb"] = df["error_display"] / df["std_crb_display"]
    df["z_colored"] = df["error_display"] / df["std_colored_display"]
    return df[["kind", "value_display", "truth_display", "error_display", "std_crb_display",
               "std_colored_display", "z_crb", "z_colored", "display_unit"]]
