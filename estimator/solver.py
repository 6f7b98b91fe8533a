r"""Maximum-likelihood output-error estimation for many maneuvers at once.

Cost (Jategaonkar 2006, §4.3), residuals ``e = z - y`` of channel ``c`` at sample ``i``::

    J(theta, R) = 1/2 sum_c sum_i e_ci^2 / R_c + 1/2 sum_c N_c ln R_c

``R`` (diagonal, one variance per channel) is estimated in closed form from the residuals between
Gauss-Newton steps, ``R_c = sum_i e_ci^2 / N_c`` (relaxation strategy, §4.10). For fixed ``R`` the
Gauss-Newton step solves ``M dtheta = g`` with::

    M = sum J^T R^-1 J,     g = sum J^T R^-1 e

Parameters are *global* (any scope but per maneuver) or *local* (one maneuver's initial conditions,
IMU biases, ...). Local parameters touch only their maneuver's rows, so ``M`` has an arrow
structure; the local blocks are eliminated maneuver by maneuver (Schur complement)::

    S  = M_GG - sum_k M_GLk M_LLk^-1 M_LkG,       S dG = g_G - sum_k M_GLk M_LLk^-1 g_Lk
    dL_k = M_LLk^-1 (g_Lk - M_LkG dG)

so an iteration costs time linear in the number of maneuvers and no Jacobian of everything is
ever formed. A Levenberg-Marquardt damping ``lambda diag(M)`` keeps a bad start from diverging;
bounds are enforced by projection.

Standard deviations: Cramér-Rao, ``sqrt(diag(M^-1))``; and corrected for coloured residuals
(Morelli & Klein 1997, "Accuracy of aircraft parameter estimates from flight test data")::

    Cov = M^-1 [ sum_i sum_j J_i^T R^-1 r(i - j) R^-1 J_j ] M^-1

with ``r`` the residual autocorrelation of each channel and maneuver (every lag), evaluated by
FFT per channel block in the block's own Jacobian columns and projected onto the globals per
maneuver (see :func:`_colored_std`). Rank deficiency of ``S`` or of a local block (a free table
offset beside a free bias, a time shift with no excitation) is detected on the scaled matrix and
reported with the parameters involved; the step then uses the pseudo-inverse and their deviations
are NaN.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy import fft as sfft
from threadpoolctl import threadpool_limits

from estimator.core.assembly import scatter_blocks
from estimator.model import Evaluation, Model, ModelEvaluationError
from estimator.problem import Problem
from estimator.result import Confounding, EstimationResult, ResidualStats


@dataclass(frozen=True)
class SolverOptions:
    """Solver settings.

    Attributes
    ----------
    max_iterations : Gauss-Newton iterations at most.
    rtol_cost : converged when the relative cost decrease of an accepted step is below this ...
    step_tol_sigma : ... and no parameter moved by more than this many Cramér-Rao deviations.
    lm_lambda0 : initial Levenberg-Marquardt damping (relative to diag M).
    rank_rtol : eigenvalues of the scaled information matrix below ``rank_rtol * max`` are treated
        as zero (unidentifiable directions).
    min_support_samples : a parameter that fewer samples depend on (a table breakpoint at the edge
        of the flown range) is held at its start value and reported: a handful of samples would
        set it to fit their noise.
    correlation_warn : |correlation| above this is reported as a confounded pair.
    colored : compute the Morelli-Klein coloured-residual deviations.
    verbose : print one line per iteration.
    """

    max_iterations: int = 40
    rtol_cost: float = 1e-7
    step_tol_sigma: float = 0.01
    lm_lambda0: float = 1e-4
    rank_rtol: float = 1e-10
    correlation_warn: float = 0.995
    min_support_samples: int = 40
    colored: bool = True
    verbose: bool = False


class _Structure:
    """Which free parameters are global and which belong to which maneuver."""

    def __init__(self, problem: Problem, free: np.ndarray):
        ps = problem.parameters
        self.free = free
        self.lo = np.array([p.bounds[0] for p in ps])
        self.hi = np.array([p.bounds[1] for p in ps])
        man_index = {m.id: k for k, m in enumerate(problem.maneuvers)}
        n = len(ps)
        self.gpos = np.full(n, -1)
        self.lpos = np.full(n, -1)
        self.local_of: list[list[int]] = [[] for _ in problem.maneuvers]
        glob: list[int] = []
        for i, p in enumerate(ps):
            if not free[i]:
                continue
            if p.scope == "maneuver":
                k = man_index[p.instance]
                self.lpos[i] = len(self.local_of[k])
                self.local_of[k].append(i)
            else:
                self.gpos[i] = len(glob)
                glob.append(i)
        self.glob = np.array(glob, dtype=int)
        self.local_of_arr = [np.array(v, dtype=int) for v in self.local_of]
        self.man_of = np.full(n, -1)
        for k, v in enumerate(self.local_of):
            self.man_of[v] = k


class _Normal:
    """Arrow-structured normal equations: global block, per-maneuver local and coupling blocks.

    The local blocks of all maneuvers live in padded arrays (``HLL_all[k, :n_k, :n_k]``) so that
    the compiled scatter fills them in one call; ``HLL[k]``, ``HGL[k]``, ``gL[k]`` are views.
    """

    def __init__(self, st: _Structure):
        ng = st.glob.size
        nl = np.array([v.size for v in st.local_of_arr], dtype=np.intp)
        lmax = int(nl.max()) if nl.size else 0
        self.st = st
        self.HGG = np.zeros((ng, ng))
        self.gG = np.zeros(ng)
        self.HLL_all = np.zeros((nl.size, lmax, lmax))
        self.HGL_all = np.zeros((nl.size, ng, lmax))
        self.gL_all = np.zeros((nl.size, lmax))
        self.HLL = [self.HLL_all[k, :n, :n] for k, n in enumerate(nl)]
        self.HGL = [self.HGL_all[k, :, :n] for k, n in enumerate(nl)]
        self.gL = [self.gL_all[k, :n] for k, n in enumerate(nl)]
        self.support = np.zeros(st.free.size, dtype=np.int64)

    def add_blocks(self, H: np.ndarray, g: np.ndarray, colmap: np.ndarray, mans: np.ndarray,
                   w: float) -> None:
        """Add ``w`` times slot-space blocks (``J^T J``, ``J^T e`` per maneuver) of a channel.

        Slot ``s`` of block ``b`` is parameter ``colmap[b, s]``; fixed parameters are left out and
        a parameter that several slots reach gets their sum (as a merged Jacobian column would).
        """
        st = self.st
        scatter_blocks(H, g, colmap, mans.astype(np.int64), float(w), st.gpos, st.lpos,
                       self.HGG, self.gG, self.HLL_all, self.HGL_all, self.gL_all)


    def pinned(self, params: np.ndarray) -> _Normal:
        """A copy whose step leaves ``params`` (parameter indices) where they are.

        Their rows and columns are zeroed with a unit diagonal and a zero gradient: the other
        parameters' step is then the Gauss-Newton step with these held (an active bound).
        """
        st = self.st
        N = _Normal(st)
        N.HGG[:], N.gG[:], N.support[:] = self.HGG, self.gG, self.support
        N.HLL_all[:], N.HGL_all[:], N.gL_all[:] = self.HLL_all, self.HGL_all, self.gL_all
        for i in params:
            j = st.gpos[i]
            if j >= 0:
                N.HGG[j, :] = N.HGG[:, j] = 0.0
                N.HGG[j, j] = 1.0
                N.gG[j] = 0.0
                N.HGL_all[:, j, :] = 0.0
            else:
                k, j = st.man_of[i], st.lpos[i]
                N.HLL_all[k, j, :] = N.HLL_all[k, :, j] = 0.0
                N.HLL_all[k, j, j] = 1.0
                N.gL_all[k, j] = 0.0
                N.HGL_all[k, :, j] = 0.0
        return N


def _full_step(st: _Structure, dG: np.ndarray, dL: list[np.ndarray], n: int) -> np.ndarray:
    step = np.zeros(n)
    step[st.glob] = dG
    for k, idx in enumerate(st.local_of_arr):
        step[idx] = dL[k]
    return step


def _bounded_solve(N: _Normal, st: _Structure, theta: np.ndarray, lam: float, rtol: float):
    """Damped step with active bounds: a parameter on a bound that the step would push outside
    is held there and the step re-solved without it (a few passes of a simple active-set method).

    Clipping such a step instead would leave the others' step computed as if it moved, and the
    iteration would crawl: each step's length (in deviations) never shrinks.
    """
    tiny = 1e-12 * np.maximum(1.0, np.abs(theta))
    at_lo = st.free & (theta <= st.lo + tiny)
    at_hi = st.free & (theta >= st.hi - tiny)
    active = np.zeros(theta.size, dtype=bool)
    M = N
    for _pass in range(4):
        dG, dL, Sinv, Ainv = _lm_solve(M, lam, rtol)
        step = _full_step(st, dG, dL, theta.size)
        out = ~active & ((at_lo & (step < 0)) | (at_hi & (step > 0)))
        if not out.any():
            break
        active |= out
        M = N.pinned(np.flatnonzero(active))
    step[active] = 0.0
    return step, dG, dL, Sinv, Ainv, active


def _build_normal(st: _Structure, ev: Evaluation, R: np.ndarray) -> _Normal:
    N = _Normal(st)
    for ce in ev.channels:
        H, g, cnt = ce.block_normals()
        np.add.at(N.support, ce.colmap.ravel(), cnt.ravel())
        N.add_blocks(H, g, ce.colmap, ce.mans, 1.0 / R[ce.channel])
    return N


def _sym_inverse(H: np.ndarray, rtol: float) -> tuple[np.ndarray, np.ndarray]:
    """Pseudo-inverse of a symmetric PSD matrix via the scaled eigen-decomposition.

    Returns the inverse and the null-space directions (columns, in the unscaled coordinates'
    scaled form, i.e. of ``D^-1/2 H D^-1/2``) whose eigenvalues fall below ``rtol * max``.
    """
    inv, null = _sym_inverse_many([H], rtol)
    return inv[0], null[0]


def _sym_inverse_many(mats: list[np.ndarray], rtol: float) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """:func:`_sym_inverse` of each matrix; matrices of one size are decomposed in one stacked call
    (one per maneuver: a Python loop of small ``eigh`` calls costs more than the arithmetic)."""
    inv: list = [None] * len(mats)
    null: list = [None] * len(mats)
    sizes: dict[int, list[int]] = {}
    for i, H in enumerate(mats):
        sizes.setdefault(H.shape[0], []).append(i)
    for n, idx in sizes.items():
        if n == 0:
            for i in idx:
                inv[i], null[i] = np.zeros((0, 0)), np.zeros((0, 0))
            continue
        H = np.stack([mats[i] for i in idx])
        diag = np.diagonal(H, axis1=1, axis2=2)
        live = diag > 1e-300 * np.maximum(diag.max(axis=1), 1e-300)[:, None]
        # rows with no information at all get a zero inverse (no step) and count as null directions
        d = np.where(live, np.sqrt(np.where(live, diag, 1.0)), 1.0)
        Hs = H / d[:, :, None] / d[:, None, :]
        Hs = np.where(live[:, :, None] & live[:, None, :], Hs, 0.0)
        lam, V = np.linalg.eigh(Hs)
        thr = rtol * np.maximum(lam[:, -1], 1e-300)
        ok = lam > thr[:, None]
        scale = np.divide(1.0, lam, out=np.zeros_like(lam), where=ok)
        inv_s = (V * scale[:, None, :]) @ np.swapaxes(V, 1, 2)
        inv_all = inv_s / d[:, :, None] / d[:, None, :]
        for j, i in enumerate(idx):
            inv[i] = inv_all[j]
            null[i] = V[j][:, ~ok[j]]
    return inv, null


def _confounded_sets(null: np.ndarray, keys: list[str], where: str) -> list[Confounding]:
    out = []
    for j in range(null.shape[1]):
        v = null[:, j]
        big = np.argsort(-np.abs(v))
        members = [keys[i] for i in big if abs(v[i]) > 0.15 * np.abs(v).max()][:8]
        out.append(Confounding(
            parameters=tuple(members),
            kind="unidentifiable",
            detail=(f"{where}: the data cannot tell these parameters apart (a combination of them "
                    "leaves every output unchanged); fix all but one of them, or add maneuvers that "
                    "excite them differently"),
        ))
    return out


def _lm_solve(N: _Normal, lam: float, rtol: float, extra: dict | None = None):
    """Damped Schur-complement solve. Returns (delta_G, [delta_L_k], S^-1, [A_k^-1]).

    ``extra``, if given, receives the Schur complement ``"S"`` and the null directions of the
    (damped) local blocks ``"null_L"``, for the rank checks.
    """
    ng = N.HGG.shape[0]
    S = N.HGG.copy()
    S[np.diag_indices(ng)] *= 1.0 + lam
    r = N.gG.copy()
    damped = []
    for A in N.HLL:
        A = A.copy()
        A[np.diag_indices(A.shape[0])] *= 1.0 + lam
        damped.append(A)
    Ainv, null_L = _sym_inverse_many(damped, rtol)
    for k, Ai in enumerate(Ainv):
        if Ai.shape[0] == 0:
            continue
        B = N.HGL[k] @ Ai
        S -= B @ N.HGL[k].T
        r -= B @ N.gL[k]
    if extra is not None:
        extra["S"], extra["null_L"] = S.copy(), null_L
    Sinv, _ = _sym_inverse(S, rtol)
    dG = Sinv @ r
    dL = [Ai @ (gl - hgl.T @ dG) for Ai, gl, hgl in zip(Ainv, N.gL, N.HGL, strict=True)]
    return dG, dL, Sinv, Ainv


def _residuals(ev: Evaluation, n_channels: int):
    sse = np.zeros(n_channels)
    cnt = np.zeros(n_channels)
    for ce in ev.channels:
        e = ce.e
        # block by block, in maneuver order: the sums of a per-maneuver evaluation, bit for bit
        for b in range(ce.mans.size):
            eb = e[ce.rseg[b]:ce.rseg[b + 1]]
            sse[ce.channel] += eb @ eb
            cnt[ce.channel] += eb.size
    return sse, cnt


def _cost(sse, cnt, R):
    used = cnt > 0
    return 0.5 * np.sum(sse[used] / R[used]) + 0.5 * np.sum(cnt[used] * np.log(R[used]))


def _screen(problem, st: _Structure, evals, R, opt: SolverOptions):
    """Hold parameters the data do not determine; returns the new structure and the reports.

    Parameters no sample depends on (a table breakpoint beyond the flown range, a bias of a sensor
    an aircraft does not carry), and combinations the data cannot separate (a free table offset
    beside a free bias), are held at their start values and reported instead of "estimated".
    """
    keys = problem.parameters.keys
    found: list[Confounding] = []
    for _ in range(6):
        N = _build_normal(st, evals, R)
        info = np.zeros(len(keys))
        info[st.glob] = np.diag(N.HGG)
        for k, idx in enumerate(st.local_of_arr):
            info[idx] = np.diag(N.HLL[k])
        no_data = st.free & ~((info > 0.0) & (N.support >= opt.min_support_samples))
        if no_data.any():
            found.append(Confounding(
                parameters=tuple(keys[i] for i in np.nonzero(no_data)[0]), kind="no_data",
                detail=(f"fewer than {opt.min_support_samples} samples depend on these parameters "
                        "(e.g. a table breakpoint outside the flown range, or a sensor this aircraft "
                        "does not carry); held at their start values"),
            ))
            st = _Structure(problem, st.free & ~no_data)
            continue
        cov_G, cov_L, conf = _covariance(N, st, keys, problem, opt)
        conf = [c for c in conf if c.kind == "unidentifiable"]
        if not conf:
            # a parameter whose Cramér-Rao deviation exceeds half its allowed range is not
            # determined by these data (a pressure-altitude scale in level flight): hold it
            std = np.full(len(keys), np.nan)
            std[st.glob] = np.sqrt(np.maximum(np.diag(cov_G), 0.0))
            for k, idx in enumerate(st.local_of_arr):
                if idx.size:
                    std[idx] = np.sqrt(np.maximum(np.diag(cov_L[k]), 0.0))
            width = st.hi - st.lo
            loose = st.free & np.isfinite(width) & (std > 0.5 * width)
            if not loose.any():
                break
            found.append(Confounding(
                parameters=tuple(keys[i] for i in np.nonzero(loose)[0]), kind="no_data",
                detail=("the data barely depend on these parameters: their Cramér-Rao deviation "
                        "exceeds half their allowed range (bounds); held at their start values"),
            ))
            st = _Structure(problem, st.free & ~loose)
            continue
        free = st.free.copy()
        for c in conf:
            free[[problem.parameters.index(k) for k in c.parameters]] = False
            found.append(Confounding(c.parameters, c.kind,
                                     c.detail + "; all of them were held at their start values"))
        st = _Structure(problem, free)
    return st, found


def estimate(problem: Problem, options: SolverOptions | None = None) -> EstimationResult:
    """Estimate the free parameters of ``problem`` by maximum likelihood (output error).

    Parameters
    ----------
    problem : the problem (data, channel models, parameters with start values).
    options : solver settings.

    Returns
    -------
    EstimationResult with estimates, Cramér-Rao and coloured-residual deviations, correlations,
    residual statistics, iterations, status and message.

    Notes
    -----
    Runs with one BLAS thread (restored on return): every matrix here is small, and waking
    OpenBLAS's worker threads for each of them costs more than the arithmetic.
    """
    with threadpool_limits(limits=1, user_api="blas"):
        return _estimate(problem, options or SolverOptions())


def _estimate(problem: Problem, opt: SolverOptions) -> EstimationResult:
    t0 = time.perf_counter()
    model = Model(problem)
    ps = problem.parameters
    keys = ps.keys
    nch = len(problem.channels)
    st = _Structure(problem, ps.free_mask)
    start = np.clip(ps.values, st.lo, st.hi)
    if not st.free.any():
        raise ValueError(f"{problem.source}: no free parameters; free some in the problem file")

    def evaluate_all(th, jac):
        # the iterations need each block's normal-equation terms, not the Jacobian itself: fresh
        # memory for it each time costs more (page by page from the operating system) than
        # evaluating the last iterate once more for the Morelli-Klein deviations
        return model.evaluate_all(th, jacobian=jac, keep_jacobian=False)

    def variances(sse, cnt):
        return np.maximum(np.where(cnt > 0, sse / np.maximum(cnt, 1), 1.0), 1e-16)

    theta = start.copy()
    evals = evaluate_all(theta, True)
    sse, cnt = _residuals(evals, nch)
    if not cnt.any():
        raise ValueError(f"{problem.source}: no channel has data in any maneuver")
    st, confounding = _screen(problem, st, evals, variances(sse, cnt), opt)
    lam = opt.lm_lambda0
    history: list[float] = []
    it_total = 0
    for _round in range(3):
        if not st.free.any():
            raise ValueError(f"{problem.source}: no identifiable free parameter left; see the "
                             "confounding report: " + "; ".join(", ".join(c.parameters) for c in confounding))
        status, message = 0, f"iteration limit ({opt.max_iterations}) reached before convergence"
        for _it in range(opt.max_iterations):
            it_total += 1
            # relaxation: R from the current residuals, then a Gauss-Newton step for theta
            R = variances(sse, cnt)
            cost0 = _cost(sse, cnt, R)
            history.append(cost0)
            N = _build_normal(st, evals, R)
            accepted = False
            for attempt in range(12):
                step, dG, dL, Sinv, Ainv, active = _bounded_solve(N, st, theta, lam, opt.rank_rtol)
                sig = np.sqrt(np.maximum(np.concatenate(
                    [np.diag(Sinv)] + [np.diag(a) for a in Ainv if a.size]), 1e-300))
                moved = np.abs(np.concatenate([dG] + [d for d in dL if d.size])) / sig
                if attempt == 0:
                    moved_first = moved.max()
                    # decrease of the cost the undamped Gauss-Newton model predicts, g.d / 2
                    # (parameters held on a bound have a zero step and add nothing)
                    gfull = _full_step(st, N.gG, N.gL, theta.size)
                    predicted = 0.5 * (step @ gfull)
                if moved_first < opt.step_tol_sigma:
                    # the Gauss-Newton step is already negligible against the parameters'
                    # deviations: at the minimum (round-off may keep the cost from decreasing)
                    break
                trial = np.clip(theta + step, st.lo, st.hi)
                # the first trial is usually accepted and is then the next iterate: evaluate it
                # with the Jacobian right away (the values are the same either way)
                try:
                    trial_ev = evaluate_all(trial, attempt == 0)
                except ModelEvaluationError:
                    # the step left the model's domain (e.g. a table steeper than 1:1 in an
                    # implicit model): a rejected step, damped further
                    lam = max(lam, 1e-6) * 10.0
                    continue
                sse_t, cnt_t = _residuals(trial_ev, nch)
                cost_t = _cost(sse_t, cnt_t, R)
                if np.isfinite(cost_t) and cost_t <= cost0:
                    accepted = True
                    break
                lam = max(lam, 1e-6) * 10.0
            if not accepted:
                if moved_first < opt.step_tol_sigma:
                    status, message = 1, (f"converged: the Gauss-Newton step ({moved_first:.1e} "
                                          f"sigma) is below {opt.step_tol_sigma} sigma")
                else:
                    status, message = 2, ("no step decreases the cost any further (damping grew to "
                                          f"{lam:.1e}): a minimum, or the model cannot fit the data "
                                          "better")
                break
            # convergence: small relative decrease and steps small against their deviations
            theta = trial
            lam = max(lam * 0.1, 1e-9)
            evals = trial_ev if attempt == 0 else evaluate_all(theta, True)
            sse, cnt = sse_t, cnt_t
            rel = (cost0 - _cost(sse, cnt, R)) / max(abs(cost0), 1e-300)
            if opt.verbose:
                order = np.concatenate([st.glob] + [v for v in st.local_of_arr if v.size])
                print(f"iteration {it_total:3d}: cost {cost0: .6e}, rel. decrease {rel:.2e}, "
                      f"max step {moved.max():.2e} sigma ({keys[order[np.argmax(moved)]]}), "
                      f"lambda {lam:.1e}")
            pred_rel = abs(predicted) / max(abs(cost0), 1e-300)
            if rel < opt.rtol_cost and (moved.max() < opt.step_tol_sigma or pred_rel < opt.rtol_cost):
                status, message = 1, (f"converged: relative cost decrease {rel:.1e} < "
                                      f"{opt.rtol_cost:.0e}, and largest step {moved.max():.1e} "
                                      f"sigma or predicted further decrease {pred_rel:.1e} small")
                break
        # the trajectory moved: a breakpoint may have lost its data, or a combination its
        # excitation; hold those, restore their start values, and iterate again
        st_new, found = _screen(problem, st, evals, variances(sse, cnt), opt)
        if not found:
            break
        confounding += found
        newly_held = st.free & ~st_new.free
        theta[newly_held] = start[newly_held]
        st = st_new
        evals = evaluate_all(theta, True)
        sse, cnt = _residuals(evals, nch)

    # final R and undamped information matrix at the estimate
    R = variances(sse, cnt)
    history.append(_cost(sse, cnt, R))
    N = _build_normal(st, evals, R)
    cov_G, cov_L, final_conf = _covariance(N, st, keys, problem, opt)
    confounding += final_conf
    std = np.full(len(keys), np.nan)
    std[st.glob] = np.sqrt(np.maximum(np.diag(cov_G), 0.0))
    for k, idx in enumerate(st.local_of_arr):
        if idx.size:
            std[idx] = np.sqrt(np.maximum(np.diag(cov_L[k]), 0.0))
    for c in final_conf:
        if c.kind == "unidentifiable":  # correlated parameters keep their (large) deviations
            std[[ps.index(k) for k in c.parameters]] = np.nan
    dg = np.sqrt(np.maximum(np.diag(cov_G), 1e-300))
    corr_G = cov_G / np.outer(dg, dg)
    confounding += _high_correlations(corr_G, [keys[i] for i in st.glob], opt.correlation_warn)
    std_col = np.full(len(keys), np.nan)
    if opt.colored:
        std_col = _colored_std(model, theta, N, st, R, len(keys), opt)
    if any(c.kind in ("unidentifiable", "no_data") for c in confounding):
        message += "; some parameters were held because the data do not determine them (see confounding)"
    return EstimationResult.build(
        problem=problem, values=theta, std_crb=std, std_colored=std_col,
        correlation_keys=tuple(keys[i] for i in st.glob), correlation=corr_G,
        R=dict(zip((c.name for c in problem.channels), R, strict=True)),
        residuals=_stats(problem, evals), iterations=it_total, cost_history=tuple(history),
        status=status, message=message, confounding=tuple(confounding),
        elapsed_s=time.perf_counter() - t0, free_estimated=st.free.copy(),
    )


def _covariance(N: _Normal, st: _Structure, keys, problem: Problem, opt: SolverOptions):
    """Undamped Cramér-Rao covariance of the global block and of each local block."""
    extra: dict = {}
    dG, dL, Sinv, Ainv = _lm_solve(N, 0.0, opt.rank_rtol, extra)
    confounding: list[Confounding] = []
    # rank checks: the Schur complement (globals) and each local block (undamped: lambda = 0)
    _, null = _sym_inverse(extra["S"], opt.rank_rtol)
    confounding += _confounded_sets(null, [keys[i] for i in st.glob], "global parameters")
    cov_L = []
    for k, Ai in enumerate(Ainv):
        idx = st.local_of_arr[k]
        if not idx.size:
            cov_L.append(np.zeros((0, 0)))
            continue
        nullk = extra["null_L"][k]
        confounding += _confounded_sets(nullk, [keys[i] for i in idx],
                                        f"maneuver {problem.maneuvers[k].id}")
        B = Ai @ N.HGL[k].T
        cov_L.append(Ai + B @ Sinv @ B.T)
    del dG, dL
    # correlations across the blocks: Cov(local_k, global) = -A_k^-1 M_LkG S^-1. A per-maneuver
    # initial condition that trades against a fleet-wide bias is exactly the confounding an
    # engineer must see (SPEC §5), and it lives in these blocks, not in the global one
    thr = opt.correlation_warn
    sd_g = np.sqrt(np.maximum(np.diag(Sinv), 1e-300))
    gkeys = [keys[i] for i in st.glob]
    for k, Ai in enumerate(Ainv):
        idx = st.local_of_arr[k]
        if not idx.size or not sd_g.size:
            continue
        cross = -(Ai @ N.HGL[k].T) @ Sinv
        sd_l = np.sqrt(np.maximum(np.diag(cov_L[k]), 1e-300))
        corr = cross / sd_l[:, None] / sd_g[None, :]
        for a, b in zip(*np.nonzero(np.abs(corr) > thr), strict=True):
            confounding.append(Confounding(
                parameters=(keys[idx[a]], gkeys[b]), kind="correlated",
                detail=(f"correlation {corr[a, b]:+.4f}: the data barely separate {keys[idx[a]]} "
                        f"from {gkeys[b]}; their individual values are uncertain"),
            ))
    return Sinv, cov_L, confounding


def _high_correlations(corr: np.ndarray, keys: list[str], thr: float) -> list[Confounding]:
    out = []
    n = corr.shape[0]
    iu = np.triu_indices(n, 1)
    vals = corr[iu]
    for a, b, r in zip(iu[0], iu[1], vals, strict=True):
        if np.isfinite(r) and abs(r) > thr:
            out.append(Confounding(
                parameters=(keys[a], keys[b]), kind="correlated",
                detail=(f"correlation {r:+.4f}: the data barely separate {keys[a]} from {keys[b]}; "
                        "their individual values are uncertain even if their deviations look small"),
            ))
    return out


def _block_autocov(JT: np.ndarray, e: np.ndarray, rseg: np.ndarray, chunk: int = 8) -> np.ndarray:
    """``sum_i sum_j J_i^T r(i - j) J_j`` per block, ``r`` the block's biased residual autocorrelation.

    Every lag is kept (as in Morelli & Klein 1997). With both sequences zero-padded to
    ``L >= 2 n - 1`` the circular convolution is the linear one and the transform of ``r`` is the
    periodogram ``|E_f|^2 / n``, so by Parseval::

        sum_ij J_i^T r(i - j) J_j = 1/(n L) sum_f |E_f|^2 Re(conj(F_f)^T F_f),   F = DFT(J)

    one forward transform per column and a weighted Gram matrix, batched over the blocks.

    Parameters
    ----------
    JT : (m, n) Jacobian of all blocks, slot by slot; e : (n,) residuals; rseg : (B+1,) block row
        offsets.

    Returns
    -------
    (B, m, m)
    """
    nb = rseg.size - 1
    m = JT.shape[0]
    lens = np.diff(rseg)
    out = np.zeros((nb, m, m))
    if nb == 0 or m == 0 or lens.max() == 0:
        return out
    L = sfft.next_fast_len(2 * int(lens.max()) - 1, real=True)
    nf = L // 2 + 1
    wt = np.full(nf, 2.0)  # one-sided spectrum: every bin but DC (and Nyquist) stands for two
    wt[0] = 1.0
    if L % 2 == 0:
        wt[-1] = 1.0
    for c0 in range(0, nb, chunk):
        bl = range(c0, min(nb, c0 + chunk))
        Jp = np.zeros((len(bl), m, L))
        ep = np.zeros((len(bl), L))
        for i, b in enumerate(bl):
            Jp[i, :, :lens[b]] = JT[:, rseg[b]:rseg[b + 1]]
            ep[i, :lens[b]] = e[rseg[b]:rseg[b + 1]]
        Jf = sfft.rfft(Jp, axis=-1)
        Ef = sfft.rfft(ep, axis=-1)
        D = np.sqrt((Ef.real ** 2 + Ef.imag ** 2) * wt / (lens[c0:c0 + len(bl), None] * L))
        Jf *= D[:, None, :]
        # (real, imag) interleaved: the Gram of the real view is sum_f Re(conj(F_p) F_q) D_f^2
        Y = Jf.view(np.float64)
        for i, b in enumerate(bl):
            out[b] = Y[i] @ Y[i].T
    return out


def _colored_std(model: Model, theta: np.ndarray, N: _Normal, st: _Structure, R, nparam,
                 opt) -> np.ndarray:
    """Morelli-Klein standard deviations for every free parameter (sandwich covariance).

    With the arrow structure, ``Cov = M^-1 C M^-1`` needs, per maneuver, only the residual
    autocovariance ``C`` of its own rows in their own Jacobian columns (residuals of different
    channels or maneuvers are uncorrelated in the estimate): each channel block's
    ``J^T R^-1 r R^-1 J`` in slot space (:func:`_block_autocov`), gathered like the normal
    equations into a global part, a coupling part and a local part. The Schur projection of the
    globals' sensitivities, ``J_G - J_L A^-1 M_LG``, is then applied to these small matrices per
    maneuver instead of to the rows.
    """
    _, _, Sinv, Ainv = _lm_solve(N, 0.0, opt.rank_rtol)
    C = _Normal(st)
    done: dict[int, tuple] = {}

    def autocov(ce):
        # only the slots that are free somewhere: fixed columns drop out of the sandwich
        keep = np.nonzero(st.free[ce.colmap].any(axis=0))[0]
        if keep.size:
            done[ce.channel] = (ce, keep, _block_autocov(ce.JT[keep], ce.e, ce.rseg))
        ce.JT = None  # used once: do not hold every channel's Jacobian at the same time

    # the last iterate once more, now with its Jacobian, each channel's autocovariance computed
    # (on the evaluation's worker threads) as soon as the channel is done
    model.evaluate_all(theta, jacobian=True, keep_jacobian=True, on_channel=autocov)
    for c in sorted(done):
        ce, keep, Cb = done[c]
        w = 1.0 / R[c]
        C.add_blocks(Cb, np.zeros((Cb.shape[0], keep.size)), np.ascontiguousarray(ce.colmap[:, keep]),
                     ce.mans, w * w)
    CGG = C.HGG.copy()
    per_k = []
    for k, lidx in enumerate(st.local_of_arr):
        if not lidx.size:
            per_k.append(None)
            continue
        Bk = Ainv[k] @ N.HGL[k].T  # (L, G) = A^-1 M_LG
        CLG_raw = C.HGL[k].T  # (L, G)
        CLL = C.HLL[k]
        BtCLG = Bk.T @ CLG_raw
        CGG += Bk.T @ CLL @ Bk - BtCLG - BtCLG.T
        per_k.append((Bk, CLL, CLG_raw - CLL @ Bk))
    covG = Sinv @ CGG @ Sinv
    std = np.full(nparam, np.nan)
    std[st.glob] = np.sqrt(np.maximum(np.diag(covG), 0.0))
    for k, item in enumerate(per_k):
        if item is None:
            continue
        Bk, CLL, CLG = item
        Ai = Ainv[k]
        cross = Ai @ CLG @ Sinv @ Bk.T
        cov = Ai @ CLL @ Ai - cross - cross.T + Bk @ covG @ Bk.T
        std[st.local_of_arr[k]] = np.sqrt(np.maximum(np.diag(cov), 0.0))
    return std


def _stats(problem: Problem, ev: Evaluation) -> tuple[ResidualStats, ...]:
    blocks = []
    for ce in ev.channels:
        e = ce.e
        for b, k in enumerate(ce.mans):
            blocks.append((int(k), ce.channel, e[ce.rseg[b]:ce.rseg[b + 1]]))
    out = []
    for k, c, e in sorted(blocks, key=lambda x: (x[0], x[1])):  # maneuver by maneuver
        out.append(ResidualStats(
            maneuver=problem.maneuvers[k].id, channel=problem.channels[c].name, n=int(e.size),
            mean=float(e.mean()), std=float(e.std()), rms=float(np.sqrt(np.mean(e * e))),
        ))
    return tuple(out)
