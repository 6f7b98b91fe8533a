r"""The normal equations of the output-error cost, in the arrow structure of many maneuvers.

For fixed residual variances ``R`` the Gauss-Newton step solves ``M dtheta = g`` with::

    M = sum J^T R^-1 J,     g = sum J^T R^-1 e

Parameters are *global* (any scope but per maneuver) or *local* (one maneuver's initial conditions,
IMU biases, ...). Local parameters touch only their maneuver's rows, so ``M`` has an arrow
structure; the local blocks are eliminated maneuver by maneuver (Schur complement)::

    S  = M_GG - sum_k M_GLk M_LLk^-1 M_LkG,       S dG = g_G - sum_k M_GLk M_LLk^-1 g_Lk
    dL_k = M_LLk^-1 (g_Lk - M_LkG dG)

so an iteration costs time linear in the number of maneuvers and no Jacobian of everything is
ever formed. A Levenberg-Marquardt damping ``lambda diag(M)`` keeps a bad start from diverging;
bounds are an active set (a parameter on a bound that the step pushes outward is held there).
Inverses are taken on the scaled matrix by eigen-decomposition: eigenvalues below ``rtol * max``
are unidentifiable directions (zero step, reported by the solver). The cost (Jategaonkar 2006,
§4.3) and the closed-form ``R`` (relaxation, §4.10) are here too.
"""

from __future__ import annotations

import numpy as np

from estimator.core.assembly import scatter_blocks
from estimator.model import Evaluation
from estimator.problem import Problem


class Structure:
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


class NormalEquations:
    """Arrow-structured normal equations: global block, per-maneuver local and coupling blocks.

    The local blocks of all maneuvers live in padded arrays (``HLL_all[k, :n_k, :n_k]``) so that
    the compiled scatter fills them in one call; ``HLL[k]``, ``HGL[k]``, ``gL[k]`` are views.
    """

    def __init__(self, st: Structure):
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


    def pinned(self, params: np.ndarray) -> NormalEquations:
        """A copy whose step leaves ``params`` (parameter indices) where they are.

        Their rows and columns are zeroed with a unit diagonal and a zero gradient: the other
        parameters' step is then the Gauss-Newton step with these held (an active bound).
        """
        st = self.st
        N = NormalEquations(st)
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


def full_step(st: Structure, dG: np.ndarray, dL: list[np.ndarray], n: int) -> np.ndarray:
    step = np.zeros(n)
    step[st.glob] = dG
    for k, idx in enumerate(st.local_of_arr):
        step[idx] = dL[k]
    return step


def bounded_solve(N: NormalEquations, st: Structure, theta: np.ndarray, lam: float, rtol: float):
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
    # each pass pins at least one more parameter, so this ends; the last solve is of the final set
    while True:
        dG, dL, Sinv, Ainv = lm_solve(M, lam, rtol)
        step = full_step(st, dG, dL, theta.size)
        out = ~active & ((at_lo & (step < 0)) | (at_hi & (step > 0)))
        if not out.any():
            break
        active |= out
        M = N.pinned(np.flatnonzero(active))
    step[active] = 0.0
    return step, dG, dL, Sinv, Ainv, active


def build_normal(st: Structure, ev: Evaluation, R: np.ndarray) -> NormalEquations:
    N = NormalEquations(st)
    for ce in ev.channels:
        H, g, cnt = ce.block_normals()
        np.add.at(N.support, ce.colmap.ravel(), cnt.ravel())
        N.add_blocks(H, g, ce.colmap, ce.mans, 1.0 / R[ce.channel])
    return N


def sym_inverse(H: np.ndarray, rtol: float) -> tuple[np.ndarray, np.ndarray]:
    """Pseudo-inverse of a symmetric PSD matrix via the scaled eigen-decomposition.

    Returns the inverse and the null-space directions (columns, in the unscaled coordinates'
    scaled form, i.e. of ``D^-1/2 H D^-1/2``) whose eigenvalues fall below ``rtol * max``.
    """
    inv, null = sym_inverse_many([H], rtol)
    return inv[0], null[0]


def sym_inverse_many(mats: list[np.ndarray], rtol: float) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """:func:`sym_inverse` of each matrix; matrices of one size are decomposed in one stacked call
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



def lm_solve(N: NormalEquations, lam: float, rtol: float, extra: dict | None = None):
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
    Ainv, null_L = sym_inverse_many(damped, rtol)
    for k, Ai in enumerate(Ainv):
        if Ai.shape[0] == 0:
            continue
        B = N.HGL[k] @ Ai
        S -= B @ N.HGL[k].T
        r -= B @ N.gL[k]
    if extra is not None:
        extra["S"], extra["null_L"] = S.copy(), null_L
    Sinv, _ = sym_inverse(S, rtol)
    dG = Sinv @ r
    dL = [Ai @ (gl - hgl.T @ dG) for Ai, gl, hgl in zip(Ainv, N.gL, N.HGL, strict=True)]
    return dG, dL, Sinv, Ainv


def residual_sums(ev: Evaluation, n_channels: int):
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


def ml_cost(sse, cnt, R):
    used = cnt > 0
    return 0.5 * np.sum(sse[used] / R[used]) + 0.5 * np.sum(cnt[used] * np.log(R[used]))



def channel_variances(sse: np.ndarray, cnt: np.ndarray) -> np.ndarray:
    """Closed-form residual variance per channel (the relaxation step), SI^2."""
    return np.maximum(np.where(cnt > 0, sse / np.maximum(cnt, 1), 1.0), 1e-16)
