r"""Compiled assembly of the estimator's Jacobian rows and normal equations.

A channel's Jacobian row at sample ``i`` is, in *slot space* (13 state-equation parameters, then
the channel's parameters, table values and time shift; :mod:`estimator.model`)::

    J[i, :13] = sum_slot sum_q CA[i, slot, q] S[P_slot(i), q, :]  (+ CB[i] on the gyro-bias slots)
    J[i, s]  += c   for each sparse term (s, c) of the row

where ``P_0(i), P_1(i) = P_0(i) + 1`` are the two samples the time-shifted signal interpolates
between, ``S`` the state sensitivities, and ``CA`` the chain-rule coefficients
``dy/dsignal * (interpolation weight) * dsignal/dstate``. Forming this directly from ``S`` avoids
an (N, 13) derivative array per signal and its interpolation; forming it block by block (one
channel of one maneuver) in a buffer that stays in cache, with the block's ``J^T J`` right after,
avoids writing and re-reading the whole Jacobian (the hot loop is memory-bound otherwise). The
Gram matrices are compiled loops rather than BLAS calls: they are small, and a multi-threaded BLAS
spends more on waking its threads than on the arithmetic (twice the estimator's time on two
busy cores).

Also here: the scatter of those blocks into the arrow-structured normal equations, and the
time-shift interpolation of a channel's state signals. Every kernel releases the GIL, so that
independent channels can run on two threads.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit


class RowShift(NamedTuple):
    """Each Jacobian row's time-shifted sample: it interpolates between samples ``P0`` and
    ``P0 + 1`` (int64) with weight ``W`` on the second; ``dt_s`` its maneuver's sample interval, s.
    (n,) each."""

    P0: np.ndarray
    W: np.ndarray
    dt_s: np.ndarray


class ChannelSignals(NamedTuple):
    """The state signals a channel's model reads: ``G`` (n_sig, n) d output / d signal per row;
    ``sig_q`` (n_sig,) the state index of an Euler angle or the altitude, or -1 for a velocity
    signal; ``sig_id`` (n_sig,) each signal's row in the :class:`SignalStacks`; ``has_b`` (n_sig,)
    the gyro-bias derivative ``B`` applies; ``qlist`` the states any signal depends on."""

    G: np.ndarray
    sig_q: np.ndarray
    sig_id: np.ndarray
    has_b: np.ndarray
    qlist: np.ndarray


class SignalStacks(NamedTuple):
    """Every state signal of an evaluation: ``A``, ``B`` (n_all, N, 3) a velocity signal's
    derivatives with respect to (u, v, w) and, directly, to the gyro biases; ``V`` (n_all, N) the
    signals' values."""

    A: np.ndarray
    B: np.ndarray
    V: np.ndarray


class SparseTerms(NamedTuple):
    """(n, T) each: a row's sparse Jacobian terms, ``coef`` added at slot ``slot`` (int64)."""

    slot: np.ndarray
    coef: np.ndarray


class BlockNormals(NamedTuple):
    """:func:`channel_normals`' outputs: ``H`` (B, m, m) ``J^T J``, ``g`` (B, m) ``J^T e``, ``cnt``
    (B, m) int64 non-zeros per slot, and ``JT`` (m, n) the Jacobian slot by slot, or an (m, 0)
    array not to keep it."""

    H: np.ndarray
    g: np.ndarray
    cnt: np.ndarray
    JT: np.ndarray


@njit(cache=True, nogil=True)
def channel_normals(S, shift, signals, stacks, sparse, dslot, e, rseg, m, out):
    """Jacobian rows of a channel, block by block, and each block's normal-equation terms.

    Row ``r`` (interpolating between samples ``P0[r]`` and ``P0[r] + 1`` with weight ``W[r]``)::

        J[r, :13] = sum_q c0_q S[P0, q, :] + c1_q S[P0 + 1, q, :]   (+ gyro-bias terms)
        c0_q = sum_sig G[sig, r] (1 - W[r]) a_sig,q[P0],   c1_q likewise with W[r] at P0 + 1

    with ``a_sig`` the signal's derivative with respect to the state (``A[sig]`` for a velocity
    signal, a unit vector for an Euler angle or the altitude, ``sig_q[sig] >= 0``); the time-shift
    slot ``dslot`` gets ``sum_sig G[sig, r] * -(V[sig, P0 + 1] - V[sig, P0]) / dt[r]``; the sparse
    terms add ``coef`` at ``slot``. A block's columns are built in a small buffer that stays in
    cache, and its ``J^T J`` follows from it (:func:`_gram`). The rows are built here, not in a
    function of their own: called per row, one made the kernel three times slower.

    Parameters
    ----------
    S : (N, 7, 13) sensitivities.
    shift, signals, stacks, sparse : :class:`RowShift` (per row), :class:`ChannelSignals`,
        :class:`SignalStacks` (every signal of the evaluation), :class:`SparseTerms`.
    dslot : slot of the time shift, or -1.
    e : (n,) residuals; rseg : (B+1,) block row offsets; m : number of slots.
    out : :class:`BlockNormals`, written.
    """
    P0, W, dt = shift
    G, sig_q, sig_id, has_b, qlist = signals
    A, B, V = stacks
    tslot, tcoef = sparse
    H, g, cnt, JT = out
    nsig = G.shape[0]
    nq = qlist.shape[0]
    nt = tslot.shape[1]
    keep = JT.shape[1] > 0
    lmax = 0
    for b in range(rseg.shape[0] - 1):
        lmax = max(lmax, rseg[b + 1] - rseg[b])
    buf = np.zeros((m, lmax))  # column-major: a column's rows are contiguous for the Gram
    first = np.empty(m, dtype=np.int64)
    last = np.empty(m, dtype=np.int64)
    c0 = np.zeros(7)
    c1 = np.zeros(7)
    b3 = np.zeros(3)
    jrow = np.zeros(13)
    for b in range(rseg.shape[0] - 1):
        r0 = rseg[b]
        nb = rseg[b + 1] - r0
        # zero the block column by column (contiguous), then write each row's entries once
        for s in range(m):
            buf[s, :nb] = 0.0
        for i in range(nb):
            r = r0 + i
            p0 = P0[r]
            w1 = W[r]
            w0 = 1 - w1
            for q in range(7):
                c0[q] = 0.0
                c1[q] = 0.0
            for k in range(3):
                b3[k] = 0.0
            dyt = 0.0
            for sg in range(nsig):
                gr = G[sg, r]
                g0 = gr * w0
                g1 = gr * w1
                q = sig_q[sg]
                sid = sig_id[sg]
                if q >= 0:
                    c0[q] += g0
                    c1[q] += g1
                else:
                    for k in range(3):
                        c0[k] += g0 * A[sid, p0, k]
                        c1[k] += g1 * A[sid, p0 + 1, k]
                    if has_b[sg]:
                        for k in range(3):
                            b3[k] += g0 * B[sid, p0, k] + g1 * B[sid, p0 + 1, k]
                if dslot >= 0:
                    dyt += gr * (-(V[sid, p0 + 1] - V[sid, p0]) / dt[r])
            for j in range(13):
                jrow[j] = 0.0
            for a in range(nq):
                q = qlist[a]
                x0 = c0[q]
                x1 = c1[q]
                for j in range(13):
                    jrow[j] += x0 * S[p0, q, j] + x1 * S[p0 + 1, q, j]
            for k in range(3):
                jrow[10 + k] += b3[k]
            for j in range(13):
                buf[j, i] = jrow[j]
            for t in range(nt):
                buf[tslot[r, t], i] += tcoef[r, t]
            if dslot >= 0:
                buf[dslot, i] += dyt
        _column_extents(buf, nb, first, last, cnt[b])
        _gram(buf, first, last, e[r0:r0 + nb], H[b], g[b])
        if keep:
            for s in range(m):  # loops, not slice assignments: no shape-check message to compile
                for i in range(nb):
                    JT[s, r0 + i] = buf[s, i]


@njit(cache=True, nogil=True)
def _column_extents(buf, nb, first, last, cnt):
    """Non-zero rows of each column of the block's first ``nb`` rows (table columns are zero where
    the argument is elsewhere): the first and last (``first``, ``last``) and the count (``cnt``)."""
    for s in range(buf.shape[0]):
        col = buf[s]
        lo = 0
        while lo < nb and col[lo] == 0.0:
            lo += 1
        hi = nb - 1
        while hi >= lo and col[hi] == 0.0:
            hi -= 1
        c = 0
        for i in range(lo, hi + 1):
            c += col[i] != 0.0
        cnt[s] = c
        first[s] = lo
        last[s] = hi


@njit(cache=True, fastmath={"reassoc", "contract"})
def _gram(buf, first, last, e, H, g):
    """``H = J^T J`` and ``g = J^T e`` of a column-major block, each dot product over the rows
    where the columns can be non-zero; four columns per pass over a column (each load of it is
    used four times), the sums vectorised (they may be reassociated). The loops run over slices
    from 0 so that no index can be negative (no wrap-around test to keep them from vectorising)."""
    m = buf.shape[0]
    for s1 in range(m):
        lo1 = first[s1]
        hi1 = last[s1] + 1
        g[s1] = _dot(buf[s1, lo1:hi1], e[lo1:hi1])
        s2 = s1
        while s2 + 3 < m:
            lo = max(lo1, min(min(first[s2], first[s2 + 1]), min(first[s2 + 2], first[s2 + 3])))
            hi = min(hi1, max(max(last[s2], last[s2 + 1]), max(last[s2 + 2], last[s2 + 3])) + 1)
            a0, a1, a2, a3 = _dot4(buf[s1, lo:hi], buf[s2, lo:hi], buf[s2 + 1, lo:hi],
                                   buf[s2 + 2, lo:hi], buf[s2 + 3, lo:hi])
            H[s1, s2] = a0
            H[s2, s1] = a0
            H[s1, s2 + 1] = a1
            H[s2 + 1, s1] = a1
            H[s1, s2 + 2] = a2
            H[s2 + 2, s1] = a2
            H[s1, s2 + 3] = a3
            H[s2 + 3, s1] = a3
            s2 += 4
        while s2 < m:
            lo = max(lo1, first[s2])
            hi = min(hi1, last[s2] + 1)
            a0 = _dot(buf[s1, lo:hi], buf[s2, lo:hi])
            H[s1, s2] = a0
            H[s2, s1] = a0
            s2 += 1


@njit(cache=True, fastmath={"reassoc", "contract"})
def _dot(x, y):
    acc = 0.0
    for i in range(x.shape[0]):
        acc += x[i] * y[i]
    return acc


@njit(cache=True, fastmath={"reassoc", "contract"})
def _dot4(x, y0, y1, y2, y3):
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    a3 = 0.0
    for i in range(x.shape[0]):
        v = x[i]
        a0 += v * y0[i]
        a1 += v * y1[i]
        a2 += v * y2[i]
        a3 += v * y3[i]
    return a0, a1, a2, a3


@njit(cache=True, nogil=True)
def scatter_blocks(H, g, colmap, mans, w, gpos, lpos, HGG, gG, HLL, HGL, gL):
    """Add ``w`` times slot-space normal-equation blocks into the arrow-structured system.

    Parameters
    ----------
    H : (B, m, m) per block ``J^T J`` in slot space; g : (B, m) ``J^T e``.
    colmap : (B, m) parameter index of each slot, per block; mans : (B,) maneuver of each block.
    w : weight (1 / R of the channel).
    gpos, lpos : (P,) position of each parameter among the free globals / its maneuver's free
        locals, -1 if it is not one (fixed parameters have both -1 and are left out).
    HGG (G, G), gG (G,), HLL (K, L, L), HGL (K, G, L), gL (K, L) : accumulated in place. Several
        slots reaching one parameter add up, as merged Jacobian columns would.
    """
    nb, m = colmap.shape
    for b in range(nb):
        k = mans[b]
        for s1 in range(m):
            p1 = colmap[b, s1]
            g1 = gpos[p1]
            l1 = lpos[p1]
            if g1 < 0 and l1 < 0:
                continue
            if g1 >= 0:
                gG[g1] += w * g[b, s1]
            else:
                gL[k, l1] += w * g[b, s1]
            for s2 in range(m):
                p2 = colmap[b, s2]
                g2 = gpos[p2]
                l2 = lpos[p2]
                v = w * H[b, s1, s2]
                if g1 >= 0:
                    if g2 >= 0:
                        HGG[g1, g2] += v
                    elif l2 >= 0:
                        HGL[k, g1, l2] += v
                elif l2 >= 0:
                    HLL[k, l1, l2] += v


@njit(cache=True, nogil=True)
def shift_index(t, tau, t0, dt, last, off, P0, W):
    """Linear interpolation at ``t - tau`` on each maneuver's uniform grid, in one pass.

    ``s = (t - tau - t0) / dt``, left sample ``clip(floor(s), 0, last)`` (``last = n - 2`` of the
    sample's maneuver), weight ``clip(s - i0, 0, 1)``; ``P0 = off + i0`` indexes the concatenated
    samples. The same operations as the array expressions they replace. ``tau`` has one value,
    or one per sample.
    """
    one = tau.shape[0] == 1
    for i in range(t.shape[0]):
        s = (t[i] - (tau[0] if one else tau[i]) - t0[i]) / dt[i]
        i0 = min(max(int(np.floor(s)), 0), last[i])
        W[i] = min(max(s - i0, 0.0), 1.0)
        P0[i] = off[i] + i0


@njit(cache=True, nogil=True)
def shift_values(val, P0, W, out):
    """``out = (1 - W) * val[P0] + W * val[P0 + 1]``."""
    for i in range(P0.shape[0]):
        w = W[i]
        out[i] = (1 - w) * val[P0[i]] + w * val[P0[i] + 1]
