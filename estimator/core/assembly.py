r"""Compiled assembly of the estimator's Jacobian rows and normal equations.

A channel's Jacobian row at sample ``i`` is, in *slot space* (13 state-equation parameters, then
the channel's parameters, table values and time shift; :mod:`estimator.model`)::

    J[i, :13] = sum_slot sum_q CA[i, slot, q] S[P_slot(i), q, :]  (+ CB[i] on the gyro-bias slots)
    J[i, s]  += c   for each sparse term (s, c) of the row

where ``P_0(i), P_1(i) = P_0(i) + 1`` are the two samples the time-shifted signal interpolates
between, ``S`` the state sensitivities, and ``CA`` the chain-rule coefficients
``dy/dsignal * (interpolation weight) * dsignal/dstate``. Forming this directly from ``S`` avoids
an (N, 13) derivative array per signal and its interpolation.
"""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def jacobian_rows(S, P0, CA, CB, qlist, tslot, tcoef, J):
    """Fill the slot-space Jacobian rows ``J`` (n, m) (zero on entry).

    Parameters
    ----------
    S : (N, 7, 13) state sensitivities of the concatenated maneuvers.
    P0 : (n,) left interpolation sample of each row (``P0 + 1`` is the right one).
    CA : (n, 2, 7) coefficients of ``S[P0]`` and ``S[P0 + 1]`` per state.
    CB : (n, 3) direct derivative with respect to the gyro biases (slots 10-12).
    qlist : states with non-zero coefficients (the others are skipped).
    tslot, tcoef : (n, T) sparse terms: ``J[i, tslot[i, t]] += tcoef[i, t]``.
    J : (n, m) output.
    """
    n = P0.shape[0]
    nq = qlist.shape[0]
    nt = tslot.shape[1]
    for r in range(n):
        p0 = P0[r]
        for a in range(nq):
            q = qlist[a]
            c0 = CA[r, 0, q]
            c1 = CA[r, 1, q]
            for j in range(13):
                J[r, j] += c0 * S[p0, q, j] + c1 * S[p0 + 1, q, j]
        for j in range(3):
            J[r, 10 + j] += CB[r, j]
        for t in range(nt):
            J[r, tslot[r, t]] += tcoef[r, t]


@njit(cache=True)
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
