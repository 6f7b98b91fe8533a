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

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

#: The time delays' feedback check (estimator.core.instrumental): each delay's instrument is its
#: sensitivity FEEDBACK_LAGS_S earlier (the mean over these lags; at least one sample): older than
#: the filter's memory of the innovations (under a sample at 40-120 Hz in light turbulence), young
#: enough to follow a maneuver's flow-angle rate (150 ms: the instrument too weak, the difference
#: 20-40 ms of noise on the what-if data). A delay's deviation is widened where the difference to
#: the likelihood estimate exceeds FEEDBACK_Z of its deviations (two-sided 5 % each; with 6-8
#: flow delays judged one at a time, a fit without feedback gets a widening about a third of the
#: time, which errs on the safe side: on the what-if data the Gauss-Markov wind drawn apart from
#: the flight had 3 delays widened, the calm cases none). The difference's variance takes the
#: innovations as white; where they are coloured it is too small and the check fires more often.
FEEDBACK_LAGS_S = (0.05, 0.075, 0.1)
FEEDBACK_Z = 2.0
#: ... tested only where the instrumental estimate's deviation is at most FEEDBACK_WEAK times the
#: likelihood's (the instrument's correlation with the regressor 1/3 at least; the flow delays'
#: 1.2-2.1 times on the what-if data, the airspeed delay's 5-57: a weak instrument's difference is
#: far from normal, no test: there it moved 0.05-0.9 s on data where the delay is 0.02-0.3 s off).
#: A weak instrument means the likelihood draws its information on the delay from the regressor's
#: fast part, which in gusts the aircraft answers can be that answer (the airspeed delay on
#: JSBSim's turbulence: 0.23-0.31 s long at 5-11 honest deviations, its instrument 8-10 times less
#: precise; with the aircraft's answer removed 2 times, and the delay right): such a delay's
#: honest deviation becomes what the instrument supports and the difference together
#: (judge_delays)
FEEDBACK_WEAK = 3.0


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
    (:func:`judge_delays` widens such a delay instead).
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


class DelayCheck(NamedTuple):
    """The feedback check's judgement of one time delay (:func:`judge_delays`)."""

    parameter: int  # index into the problem's parameters
    std_before_s: float  # honest deviation before the check
    std_after_s: float  # after it (NaN: not judged)
    difference_s: float  # instrumental - likelihood estimate
    difference_std_s: float  # its deviation (Hausman: sqrt(Var IV - Var ML))
    ratio: float  # the instrumental estimate's deviation over the likelihood's

    @property
    def weak(self) -> bool:
        """The instrument weak (``ratio`` > FEEDBACK_WEAK): no test, the deviation widened to what
        the instrument supports and the difference together."""
        return self.ratio > FEEDBACK_WEAK

    @property
    def differs(self) -> bool:
        """A strong instrument's difference beyond FEEDBACK_Z of its deviations: widened by it."""
        return not self.weak and abs(self.difference_s) > FEEDBACK_Z * self.difference_std_s


def judge_delays(D: np.ndarray, V: np.ndarray, V_ml: np.ndarray, candidates: np.ndarray,
                 std: np.ndarray) -> list[DelayCheck]:
    """The time delays the feedback check widens or cannot judge.

    Parameters
    ----------
    D, V, V_ml : per parameter, the instrumental-variable minus the likelihood estimate, its
        variance and the likelihood's white-innovation variance, SI
        (:func:`estimator.core.instrumental.iv_difference`).
    candidates : the delays to judge (bool per parameter).
    std : their honest deviations before the check, s.

    Returns
    -------
    One :class:`DelayCheck` per delay widened or not judged (the others are left as they were).

    Notes
    -----
    A strong instrument (its estimate's deviation at most FEEDBACK_WEAK times the likelihood's):
    where the difference exceeds FEEDBACK_Z of its own deviations (Hausman), the deviation becomes
    ``sqrt(std^2 + D^2 - Var D)``. A weak one: no test (its difference is far from normal); the
    deviation becomes ``sqrt((std r)^2 + D^2)``, ``r`` the ratio of the deviations. The motive is
    Anderson & Rubin's (1949) set: for one parameter, linear, with an instrument that is
    exogenous and innovations white of known variance, the values the moment ``Z^T nu(tau) = 0``
    does not reject are the instrumental estimate plus or minus c of its deviations, with exact
    coverage whatever the instrument's strength, so that the likelihood's error is at most ``|D|``
    plus that. Here the other parameters are estimated too, the innovations are coloured (``r``
    keeps the sandwich's factor) and the step is linearised: an approximation, and on the
    what-if data it covered the airspeed delay's bias in every case. Where the rank cut left the
    difference or the likelihood no variance (or the instrumental variance came out below the
    likelihood's), the delay is not judged (``std_after_s`` NaN).
    """
    out = []
    for i in np.flatnonzero(candidates & np.isfinite(D) & np.isfinite(std)):
        if not (V_ml[i] > 0.0 and V[i] > 1e-9 * V_ml[i]):
            out.append(DelayCheck(int(i), float(std[i]), math.nan, float(D[i]), math.nan, math.nan))
            continue
        c = DelayCheck(int(i), float(std[i]), math.nan, float(D[i]), math.sqrt(V[i]),
                       math.sqrt((V[i] + V_ml[i]) / V_ml[i]))
        if c.weak:
            out.append(c._replace(std_after_s=math.sqrt((std[i] * c.ratio) ** 2 + D[i] ** 2)))
        elif c.differs:
            out.append(c._replace(std_after_s=math.sqrt(std[i] ** 2 + D[i] ** 2 - V[i])))
    return out


def widen_for_feedback(std: np.ndarray, cov: np.ndarray, gpos: np.ndarray,
                       feedback: Sequence[DelayCheck]) -> tuple[np.ndarray, np.ndarray]:
    """The honest deviations and covariance with the feedback check's widening.

    Parameters
    ----------
    std : (P,) honest deviations per parameter, SI.
    cov : (G, G) their covariance over the global parameters, SI.
    gpos : (P,) each parameter's position among the globals (-1 for a maneuver's own).
    feedback : the check's judgements (:func:`judge_delays`); those not judged change nothing.

    Returns
    -------
    std, cov : new arrays (the inputs are not changed), SI: every judged delay's deviation its
    ``std_after_s``. Its variance grows by ``std_after^2 - std_before^2``: a weak instrument's as
    the delay's own term (its difference mostly the instrument's own noise); the strong ones'
    together as one rank-one term, its signs the differences', because their bias is common (the
    same gusts, the same loop), so that a combination of delays is as uncertain as its parts.
    """
    std, cov = std.copy(), cov.copy()
    b = np.zeros(cov.shape[0])
    for f in feedback:
        if math.isfinite(f.std_after_s):
            std[f.parameter] = f.std_after_s
            g = gpos[f.parameter]
            grow = f.std_after_s ** 2 - f.std_before_s ** 2
            if f.weak:
                cov[g, g] += grow
            else:
                b[g] = math.copysign(math.sqrt(grow), f.difference_s)
    return std, cov + np.outer(b, b)
