r"""The time delays' feedback check: an instrumental-variable estimate against the likelihood's.

Why (Söderström & Stoica 1983, *Instrumental Variable Methods for System Identification*; Ljung
1999, *System Identification* §13.4; Hausman 1978, *Econometrica* 46, 1251): the filter-error
estimate solves the likelihood's normal equations ``sum J~^T nu~ = 0`` (normalised innovations
``nu~``, their Jacobian ``J~``). A time delay's column of ``J~`` is the filtered rate of the flow
angle the model integrates from the IMU; in turbulence the IMU measures the aircraft's answer to
the gust that the innovation at the same sample carries (lift and side force follow the air at
once), so that column is correlated with the current innovation, the loop is closed without a
delay, and the estimate is biased (JSBSim's light turbulence: the flow delays 4-7 ms long at 3-5
deviations). An instrument ``Z`` correlated with the regressor but not with the current innovation
removes the bias: each delay's column taken ``L`` samples earlier (the mean over the lags ``L``),
every other column as it is. From the estimate, one step of each (linearised)::

    d_ML = -(J~^T J~)^-1 J~^T nu~,          d_IV = -(Z^T J~)^-1 Z^T nu~
    V_ML = (J~^T J~)^-1,                     V_IV = (Z^T J~)^-1 Z^T Z (J~^T Z)^-1

Without feedback both estimates are consistent and the likelihood's efficient, so their difference
``D = d_IV - d_ML`` has the variance ``V_IV - V_ML`` (Hausman); a ``D`` beyond it measures the
likelihood estimate's bias, and ``D^2 - (V_IV - V_ML)`` estimates its square. The instrumental
estimate itself is not the better value: where the flow sensors are noise-free (the likelihood's
bias 1-3 ms) it moves 4-12 ms the other way (campaigns/benchmarks/whatif_sideslip.py), and it is
1.2-2.1x less precise (the flow delays there); its difference is used to widen the deviations,
not to move the estimate.
"""

from __future__ import annotations

import numpy as np


def instrument_sums(rows: np.ndarray, J: np.ndarray, nu: np.ndarray, is_delay: np.ndarray,
                    lags_samples: np.ndarray) -> tuple[np.ndarray, ...]:
    """One channel's contributions to the normal equations of both estimates.

    Parameters
    ----------
    rows : (n,) the observations' sample indices, increasing.
    J : (n, p) the normalised innovations' Jacobian, SI per parameter.
    nu : (n,) the normalised innovations, 1.
    is_delay : (p,) which columns are time delays (instrumented).
    lags_samples : (m,) the instruments' lags, samples (>= 1): a delay's instrument at a sample
        is the mean of its column at those samples earlier (zero where a sample is missing).

    Returns
    -------
    ``Z^T J``, ``Z^T nu``, ``Z^T Z``, ``J^T J``, ``J^T nu``: (p, p), (p,), (p, p), (p, p), (p,).
    """
    Z = J.copy()
    d = np.flatnonzero(is_delay)
    if d.size:
        Z[:, d] = 0.0
        for lag in lags_samples:
            at = np.searchsorted(rows, rows - lag)
            ok = (at < rows.size) & (rows[np.minimum(at, rows.size - 1)] == rows - lag)
            Z[np.ix_(np.flatnonzero(ok), d)] += J[np.ix_(at[ok], d)] / lags_samples.size
    return Z.T @ J, Z.T @ nu, Z.T @ Z, J.T @ J, J.T @ nu


def iv_difference(blocks, gpos: np.ndarray, rank_rtol: float
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The instrumental-variable step less the likelihood's, and that difference's variance, of
    the global parameters (each maneuver's own parameters eliminated: Schur complements).

    Parameters
    ----------
    blocks : per maneuver ``(cols, ZJ, Zn, ZZ, JJ, Jn)``: the parameter indices it informs and the
        sums of :func:`instrument_sums` over its channels on them. Maneuvers are independent.
    gpos : (P,) each parameter's position among the globals, -1 for a maneuver's own.
    rank_rtol : relative singular-value threshold of the inverses (on matrices normalised to unit
        information per parameter).

    Returns
    -------
    (P,) ``D = d_IV - d_ML``, (P,) ``V_IV - V_ML`` (its variance where there is no feedback) and
    (P,) ``V_ML``, SI; NaN for a maneuver's own parameters and where a global is not informed.
    ``(V_IV / V_ML)^-1/2`` is the instrument's correlation with the regressor, roughly: a weak
    instrument's difference is far from normal and is no test
    (:func:`estimator.filter_error.judge_delays` widens such a delay instead).
    """
    P, G = gpos.size, int(gpos.max(initial=-1)) + 1
    D, V, V_ml = np.full(P, np.nan), np.full(P, np.nan), np.full(P, np.nan)
    S_iv, S_ml, W_iv = np.zeros((G, G)), np.zeros((G, G)), np.zeros((G, G))
    b_iv, b_ml = np.zeros(G), np.zeros(G)
    for cols, ZJ, Zn, ZZ, JJ, Jn in blocks:
        g, loc = np.flatnonzero(gpos[cols] >= 0), np.flatnonzero(gpos[cols] < 0)
        gi = gpos[cols[g]]
        # T = [I, -A_GL A_LL^-1]: the maneuver's equations with its own parameters eliminated
        T_iv, T_ml = _eliminate(ZJ, g, loc, rank_rtol), _eliminate(JJ, g, loc, rank_rtol)
        S_iv[np.ix_(gi, gi)] += T_iv @ ZJ[:, g]
        S_ml[np.ix_(gi, gi)] += T_ml @ JJ[:, g]
        b_iv[gi] += T_iv @ Zn
        b_ml[gi] += T_ml @ Jn
        W_iv[np.ix_(gi, gi)] += T_iv @ ZZ @ T_iv.T
    free = np.flatnonzero((np.diag(S_ml) > 0.0) & (np.diag(W_iv) > 0.0))
    if not free.size:
        return D, V, V_ml
    s = 1.0 / np.sqrt(np.diag(S_ml)[free])  # unit information: the thresholds are relative
    S = np.outer(s, s)
    Mi = np.linalg.pinv(S_ml[np.ix_(free, free)] * S, rtol=rank_rtol, hermitian=True)
    Ai = np.linalg.pinv(S_iv[np.ix_(free, free)] * S, rtol=rank_rtol)
    d_ml = -(Mi @ (b_ml[free] * s)) * s
    d_iv = -(Ai @ (b_iv[free] * s)) * s
    v_iv = np.einsum("ij,jk,ik->i", Ai, W_iv[np.ix_(free, free)] * S, Ai) * s * s
    at = np.flatnonzero(gpos >= 0)[np.argsort(gpos[gpos >= 0])][free]
    D[at] = d_iv - d_ml
    V[at] = np.maximum(v_iv - np.diag(Mi) * s * s, 0.0)
    V_ml[at] = np.diag(Mi) * s * s
    return D, V, V_ml


def _eliminate(A: np.ndarray, g: np.ndarray, loc: np.ndarray, rank_rtol: float) -> np.ndarray:
    """``[I, -A_GL A_LL^-1]`` laid out on the block's columns (globals ``g``, locals ``loc``)."""
    T = np.zeros((g.size, g.size + loc.size))
    T[np.arange(g.size), g] = 1.0
    if loc.size:
        d = np.diag(A)[loc]
        s = 1.0 / np.sqrt(np.where(d > 0.0, d, 1.0))
        inv = np.linalg.pinv(A[np.ix_(loc, loc)] * np.outer(s, s), rtol=rank_rtol) * np.outer(s, s)
        T[:, loc] = -A[np.ix_(g, loc)] @ inv
    return T
