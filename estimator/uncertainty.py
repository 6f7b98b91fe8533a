r"""Honest standard deviations: coloured, cross-correlated residuals and the IMU's noise.

Cramér-Rao deviations (``sqrt(diag(M^-1))``) assume white residuals and exact inputs. Flight data
have neither. The deviations to quote (``EstimationResult.std_colored``) are the sandwich
(Morelli & Klein 1997, "Accuracy of aircraft parameter estimates from flight test data", in the
matrix form of NASA SIDPAC's ``m_colores``)::

    Cov = M^-1 [ J^T W Sigma W J + C_proc ] M^-1

with ``Sigma`` the residuals' covariance over the samples *and channels* of a maneuver — its
spectrum modelled, not plugged in (:mod:`estimator.core.residual_spectrum`: the all-lags plug-in
of the original method is 1.4 times too optimistic) — and ``C_proc`` the IMU noise integrated as
process noise (:mod:`estimator.core.process_noise`). Residuals of different maneuvers are
uncorrelated, so both middles are computed per maneuver (by FFT, in the parameters its channels
depend on) and projected through the Schur structure of ``M``; the coloured part is floored at
the Cramér-Rao bound. Entry point: :func:`honest_std`.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from scipy import fft as sfft

from estimator.core.process_noise import (
    add_channel_products,
    input_increments,
    suffix_middle_factor,
    white_noise_psd,
)
from estimator.core.residual_spectrum import (
    AR_MAX_ORDER,
    ARModel,
    add_spectral_factor,
    ar_from_autocovariance,
    innovation_cross_spectrum,
)
from estimator.core.sensitivity import worker_threads
from estimator.model import Model
from estimator.normal_equations import NormalEquations, Structure, lm_solve
from estimator.problem import Problem
from estimator.verdict import Finding, Severity

if TYPE_CHECKING:
    from estimator.core.instrumental import DelayCheck
    from estimator.options import SolverOptions
    from estimator.result import Confounding


def _one_sided_weights(L: int) -> np.ndarray:
    """Weights of a real signal's one-sided spectrum of length ``L``: every bin but DC (and Nyquist)
    stands for two."""
    wt = np.full(L // 2 + 1, 2.0)
    wt[0] = 1.0
    if L % 2 == 0:
        wt[-1] = 1.0
    return wt


@dataclass(frozen=True, eq=False)
class HonestOptions:
    """How :func:`honest_std` computes the honest deviations.

    Attributes
    ----------
    rank_rtol : relative eigenvalue threshold of the inverses.
    cross_channel : with the cross-channel terms.
    spectrum : "ar" (modelled) or "periodogram" (the all-lags plug-in).
    imu_only : the IMU noise's share alone (the first two returns equal; the covariance its own).
    imu_maneuvers : (K,) bool, the maneuvers whose IMU noise is counted (None: every one).
    imu_channels : (K, C) bool, the (maneuver, channel) pairs whose sensitivities carry it (None:
        every one).
    """

    rank_rtol: float
    cross_channel: bool = True
    spectrum: str = "ar"
    imu_only: bool = False
    imu_maneuvers: np.ndarray | None = None
    imu_channels: np.ndarray | None = None


@dataclass(frozen=True)
class _Layout:
    """Per maneuver: samples ``n_of``, padded FFT length ``L_of``, the free parameters its channels
    depend on (``union``, sorted indices) and its channel count ``n_chan``."""

    n_of: np.ndarray
    L_of: np.ndarray
    union: list[np.ndarray]
    n_chan: np.ndarray

    def chunks(self) -> list[tuple[int, ...]]:
        """The maneuvers in chunks whose Jacobian spectra (or factor Y) stay below
        ``_COLORED_CHUNK_BYTES``."""
        chunks, cur, size = [], [], 0.0
        for k in range(len(self.n_of)):
            cur.append(k)
            # the Jacobian spectra held until the maneuver's model is fitted, or the factor Y
            size += self.union[k].size * (int(self.L_of[k]) // 2 + 1) * max(int(self.n_chan[k]), 1) * 16.0
            if size >= _COLORED_CHUNK_BYTES:
                chunks.append(tuple(cur))
                cur, size = [], 0.0
        if cur:
            chunks.append(tuple(cur))
        return chunks


def _layout(model: Model, st: Structure) -> _Layout:
    """Each maneuver's sample grid and the free parameters its channels depend on."""
    p = model.problem
    nman = len(p.maneuvers)
    n_of = np.array([m.n for m in p.maneuvers], dtype=np.int64)
    L_of = np.array([sfft.next_fast_len(max(2 * int(n) - 1, 1), real=True) for n in n_of], dtype=np.int64)
    members: list[set[int]] = [set() for _ in range(nman)]
    n_chan = np.zeros(nman, dtype=np.int64)
    for _, mans, colmap, _ in model.channel_layout():
        for b, k in enumerate(mans):
            members[int(k)].update(int(i) for i in colmap[b] if st.free[i])
            n_chan[int(k)] += 1
    return _Layout(n_of, L_of, [np.array(sorted(s), dtype=np.intp) for s in members], n_chan)


class _Shared(NamedTuple):
    """What every chunk shares: the structure, the channels' residual variances (SI^2), the layout,
    the options, the coloured middle being gathered (added to in :meth:`_ChunkMiddles.reduce`, on the
    calling thread) and the lock guarding the per-channel parts the evaluation's threads hand over."""

    st: Structure
    R: np.ndarray
    lay: _Layout
    opt: HonestOptions
    C: NormalEquations
    lock: threading.Lock


@dataclass
class _ChunkMiddles:
    """One chunk of maneuvers' middle matrices in the making: each channel's spectra, added by
    :meth:`spectra` on the evaluation's worker threads, then reduced per maneuver (:meth:`reduce`).

    ``held``: by maneuver, each channel's spectra ("ar"), its part of the periodogram's
    cross-channel factor, or its own middle (without the cross-channel terms); ``B``, ``dEq``: the
    IMU noise's parts, each channel's ``J`` (its weight ``W`` beside it) and ``J_IC``, and the input
    increments (scaled by Q^1/2). Each maneuver's channels are summed in :meth:`reduce`, in channel
    order: summed in the order the evaluation's threads finished them, the sums' rounding, and so
    the deviations, changed from run to run."""

    shared: _Shared
    held: dict[int, list]
    B: dict[int, list]
    dEq: dict[int, np.ndarray]

    def spectra(self, ce) -> None:
        """Take one evaluated channel's Jacobian spectra (its Jacobian dropped once used)."""
        st, R, lay, opt, _, lock = self.shared
        ar = opt.spectrum == "ar"
        # only the slots that are free somewhere: fixed columns drop out of the sandwich
        keep = np.nonzero(st.free[ce.colmap].any(axis=0))[0]
        if keep.size:
            w = 1.0 / R[ce.channel]
            JT = ce.JT
            e = ce.e
            for b, k in enumerate(ce.mans):
                k = int(k)
                r0, r1 = int(ce.rseg[b]), int(ce.rseg[b + 1])
                if r1 == r0:
                    continue
                rows = ce.rows[r0:r1]
                pidx = ce.colmap[b, keep]
                ok = st.free[pidx]
                Jb = JT[keep[ok], r0:r1]
                pos = np.searchsorted(lay.union[k], pidx[ok])
                if k in self.B and (opt.imu_channels is None or opt.imu_channels[k, ce.channel]):
                    # the IMU noise: J^T W and J_IC, summed over the channels in reduce (the
                    # suffix sums and the product with dE Q^1/2 are linear: taken once there)
                    with lock:
                        # Jb is a copy already (fancy indexing); J_IC copied: JT is dropped below
                        self.B[k].append((ce.channel, pos, Jb, JT[:7, r0:r1].T.copy(), rows, w))
                if opt.imu_only:
                    continue
                Lk = int(lay.L_of[k])
                Jp = np.zeros((Jb.shape[0], Lk))
                Jp[:, rows] = Jb
                F = sfft.rfft(Jp, axis=-1)
                ep = np.zeros(Lk)
                ep[rows] = e[r0:r1]
                Ef = sfft.rfft(ep)
                if ar:
                    with lock:
                        self.held[k].append((ce.channel, pos, F, Ef, rows, e[r0:r1].copy(), w))
                    continue
                F *= np.conj(Ef) * (w * np.sqrt(lay.n_of[k] / (r1 - r0)))
                if not opt.cross_channel:  # the channel's own middle
                    Yc = (F * np.sqrt(_one_sided_weights(Lk) / (lay.n_of[k] * Lk))).view(np.float64)
                    F = Yc @ Yc.T
                with lock:  # summed over the channels in reduce
                    self.held[k].append((ce.channel, pos, F))
        ce.JT = None  # used once: do not hold every channel's Jacobian at the same time

    def take_increments(self, model: Model, chunk: tuple[int, ...], imu_psd: dict | None) -> None:
        """The IMU noise's input increments (scaled by ``Q^1/2``) of the chunk's maneuvers with IMU
        noise, from the state sensitivities the chunk's evaluation with the Jacobian integrated
        (``imu_psd``: aircraft -> (6,) white-noise densities, SI^2 s; NaN: unknown, left out)."""
        if not self.B:
            return
        p = model.problem
        for k, Sk in zip(chunk, model.last_sensitivities(chunk), strict=True):
            if k in self.B:
                m = p.maneuvers[k]
                q = np.sqrt(np.nan_to_num(imu_psd[m.aircraft]) / m.dt_s)
                self.dEq[k] = input_increments(Sk[:, :, :7], Sk[:, :, 7:]) * q[None, None, :]

    def reduce(self, chunk: tuple[int, ...], problem: Problem, N: NormalEquations, Sinv: np.ndarray,
               Ainv: list[np.ndarray], Cp: NormalEquations | None) -> None:
        """Add each maneuver's coloured middle to the shared ``C`` and its IMU noise's to ``Cp``
        (``Sinv``, ``Ainv``: the inverses of ``N``'s Schur complement and local blocks).

        The maneuvers' middles are independent: computed on the worker threads (FFTs and products
        that release the interpreter), added in maneuver order (the sums do not depend on which
        thread finished first)."""
        lay, C = self.shared.lay, self.shared.C
        ks = [k for k in chunk if lay.union[k].size]

        def middles(k: int) -> tuple[np.ndarray | None, np.ndarray | None]:
            return self._middles(k, problem, N, Sinv, Ainv)

        if worker_threads() > 1 and len(ks) > 1:
            with ThreadPoolExecutor(worker_threads()) as ex:
                done = list(ex.map(middles, ks))
        else:
            done = [middles(k) for k in ks]
        for k, (middle, imu) in zip(ks, done, strict=True):
            u = np.ascontiguousarray(lay.union[k][None, :])
            if middle is not None:
                C.add_blocks(middle[None], np.zeros((1, u.size)), u, np.array([k]), 1.0)
            if imu is not None:
                Cp.add_blocks(imu[None], np.zeros((1, u.size)), u, np.array([k]), 1.0)

    def _middles(self, k: int, problem: Problem, N: NormalEquations, Sinv: np.ndarray,
                 Ainv: list[np.ndarray]) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Maneuver ``k``'s coloured middle and its IMU noise's, (U, U) each (None: none), its
        channels' spectra and Jacobians dropped."""
        st, _, lay, opt, _, _ = self.shared
        u = lay.union[k]
        Lk = int(lay.L_of[k])
        middle = imu = None
        if opt.spectrum == "ar" and self.held[k]:
            items = sorted(self.held.pop(k), key=lambda it: it[0])
            cov_u = _union_covariance(st, Sinv, Ainv, N, k, u)
            middle = _ar_middle(items, cov_u, u.size, int(lay.n_of[k]), Lk, problem.maneuvers[k].dt_s,
                                opt.cross_channel)
        elif self.held[k] and opt.cross_channel:  # the periodogram's factor, summed over the channels
            Yk = np.zeros((u.size, Lk // 2 + 1), dtype=complex)
            for _, pos, F in sorted(self.held.pop(k), key=lambda it: it[0]):
                _scatter_add(Yk, pos, F)
            Yk *= np.sqrt(_one_sided_weights(Lk) / (lay.n_of[k] * Lk))[None, :]
            Yr = np.ascontiguousarray(Yk).view(np.float64).reshape(u.size, -1)
            middle = Yr @ Yr.T
        elif self.held[k]:  # each channel's own middle, summed
            middle = np.zeros((u.size, u.size))
            for _, pos, Mc in sorted(self.held.pop(k), key=lambda it: it[0]):
                np.add.at(middle, np.ix_(pos, pos), Mc)
        if k in self.B:
            # J^T W J_IC on the grid, summed over the channels (in channel order: class docstring)
            B = np.zeros((int(lay.n_of[k]), u.size, 7))
            for _, pos, Jb, J_ic, rows, w in sorted(self.B.pop(k), key=lambda it: it[0]):
                add_channel_products(B, pos, Jb, J_ic, rows, w)
            Yv = suffix_middle_factor(B, self.dEq.pop(k))
            imu = Yv @ Yv.T
        return middle, imu


def _chunk_middles(chunk: tuple[int, ...], imu_psd: dict | None, shared: _Shared) -> _ChunkMiddles:
    """A chunk's empty accumulators: each channel's spectra (or, without the cross-channel terms,
    its middle) and, for the maneuvers with IMU noise, each channel's parts of it; the input
    increments follow the chunk's evaluation (:meth:`_ChunkMiddles.take_increments`)."""
    opt = shared.opt
    imu_chunk = tuple(k for k in chunk if opt.imu_maneuvers is None or opt.imu_maneuvers[k])
    B: dict[int, list] = {k: [] for k in imu_chunk} if imu_psd is not None else {}
    return _ChunkMiddles(shared, {k: [] for k in chunk}, B, {})


def _floored(std_crb: np.ndarray, sandwiches: tuple, glob: np.ndarray, imu_only: bool
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`honest_std`'s returns from the coloured and IMU sandwiches ``((std, cov), (std, cov))``:
    the coloured deviation floored at the Cramér-Rao bound plus the IMU noise's variance."""
    (std_mk, cov_mk), (std_imu, cov_imu) = sandwiches
    if imu_only:
        return std_imu, std_imu, cov_imu
    floor = np.where(np.isfinite(std_crb), std_crb, 0.0)
    honest = np.sqrt(np.maximum(std_mk, floor) ** 2 + std_imu ** 2)
    # the globals' honest covariance: the coloured one with each deviation raised to its floor
    # (correlations kept), plus the IMU noise's
    g = glob
    raise_to = np.maximum(1.0, floor[g] / np.where(std_mk[g] > 0, std_mk[g], np.inf))
    cov_g = raise_to[:, None] * cov_mk * raise_to[None, :] + cov_imu
    return honest, std_imu, cov_g


def honest_std(model: Model, theta: np.ndarray, N: NormalEquations, st: Structure, R: np.ndarray,
               std_crb: np.ndarray, imu_psd: dict[str, np.ndarray] | None, options: HonestOptions
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""Honest standard deviations: coloured, cross-correlated residuals and the IMU's noise.

    **Coloured residuals** (Morelli & Klein 1997, matrix form). The middle matrix of maneuver ``k``
    is ``J^T W Sigma W J`` over its samples and channels, ``W = R^-1``. With each channel's Jacobian
    placed on the maneuver's sample grid (zero where the channel has no sample in the cost),
    zero-padded to ``L >= 2 n - 1`` and transformed (``F_c``), and ``S(f)`` the channels'
    cross-spectral matrix per sample, by Parseval::

        middle_k = 1/L sum_f Re( F_f^H W S(f) W F_f ) = 1/L sum_f Re( Y_f Y_f^H ),
        Y_f = sum_c W_c F_c,f B_c(f),      S_cd(f) = B_c(f) B_d(f)^H

    ``colored_spectrum = "ar"`` (the default) models ``S`` (:mod:`estimator.core.residual_spectrum`):
    each channel an autoregressive model fitted to its residual periodogram *corrected for what the
    fit absorbed*, ``I_c(f) / (1 - h_c(f))`` with ``h_c(f) = W_c / n_c F_c,f^H Cov(theta) F_c,f``
    the leverage of the fit at frequency ``f`` (the expected periodogram of the residuals of a
    linear fit to white noise is ``sigma^2 (1 - h(f))``); the channels correlated through their
    innovations, whose coherence is a smoothed cross-periodogram (``B_c = Lambda_c(f) / A_c(f)``,
    ``Gamma(f) = Lambda Lambda^H``). Without the correction the residuals' missing low-frequency
    noise would be modelled as absent. ``"periodogram"`` takes the residuals' own
    cross-periodogram (the original all-lags plug-in, biased low: ``B_c = s_c conj(E_c) /
    sqrt(n)``, one column, ``s_c = sqrt(n / n_c)``). ``colored_cross_channel = False`` leaves out
    the cross-channel terms.

    **IMU noise** (:mod:`estimator.core.process_noise`): ``C_proc = sum_j V_j V_j^T`` per maneuver,
    from the initial-condition columns of the Jacobian, the state sensitivities and the IMU's
    white-noise level ``imu_psd`` (aircraft -> (6,) SI^2 s; None: left out).

    Both middles are gathered like the normal equations and the Schur projection of the globals'
    sensitivities is applied per maneuver (:func:`sandwich_std`). The coloured deviation is
    floored at the Cramér-Rao bound (which no unbiased estimate beats) and the IMU noise's
    variance is added. Maneuvers are taken in chunks whose spectra are reduced to per-maneuver
    matrices and dropped before the next chunk, so memory does not grow with the problem.

    Parameters
    ----------
    model, theta : the model and the estimate (all parameter values, SI).
    N, st : the normal equations at the estimate and which parameters are free (global, local).
    R : (C,) the channels' residual variances, SI^2.
    std_crb : (P,) the Cramér-Rao deviations (the floor).
    imu_psd : aircraft -> (6,) the IMU's white-noise densities, or None (no IMU noise term).
    options : the threshold, spectrum and IMU noise's scope (:class:`HonestOptions`).

    Returns
    -------
    (honest deviations, the IMU noise's share alone): (P,) each, SI, NaN where not estimated; and
    the honest covariance of the global parameters (G, G), in ``st.glob`` order.
    """
    nparam = theta.size
    _, _, Sinv, Ainv = lm_solve(N, 0.0, options.rank_rtol)
    lay = _layout(model, st)
    C = NormalEquations(st)
    Cp = NormalEquations(st) if imu_psd is not None else None
    shared = _Shared(st, R, lay, options, C, threading.Lock())
    chunks = lay.chunks()
    if len(chunks) > 1:  # the chunks have their own scratch: the whole problem's is not held beside
        model.release_scratch()
    for chunk in chunks:
        mid = _chunk_middles(chunk, imu_psd, shared)
        # the chunk once more, now with its Jacobian, each channel's spectra computed (on the
        # evaluation's worker threads) as soon as the channel is done
        model.evaluate_all(theta, jacobian=True, keep_jacobian=True, maneuvers=chunk, on_channel=mid.spectra)
        mid.take_increments(model, chunk, imu_psd)  # from the sensitivities it integrated
        model.forget(chunk)  # its layout's scratch, not to be held beside the next chunk's
        mid.reduce(chunk, model.problem, N, Sinv, Ainv, Cp)
    std_mk, cov_mk = sandwich_std(N, st, C, Sinv, Ainv, nparam)
    if Cp is not None:
        std_imu, cov_imu = sandwich_std(N, st, Cp, Sinv, Ainv, nparam)
    else:
        std_imu, cov_imu = np.where(np.isfinite(std_mk), 0.0, np.nan), np.zeros_like(cov_mk)
    return _floored(std_crb, ((std_mk, cov_mk), (std_imu, cov_imu)), st.glob, options.imu_only)


class ManeuverGrid(NamedTuple):
    """Each maneuver's sample grid: ``n`` (K,) samples and ``dt_s`` (K,) sample interval, s."""

    n: np.ndarray
    dt_s: np.ndarray


def innovation_honest_std(N: NormalEquations, st: Structure, series: Callable[[int], tuple],
                          grid: ManeuverGrid, std_crb: np.ndarray, *, rank_rtol: float,
                          cross_channel: bool = True, map_fn: Callable = map
                          ) -> tuple[np.ndarray, np.ndarray]:
    r"""Coloured-innovation deviations of the filter-error method (Jategaonkar 2006, §5.8; the
    Morelli-Klein sandwich of :func:`honest_std` on the innovations).

    The filter-error cost is ``1/2 sum nu~^2`` of the normalised innovations ``nu~ = nu /
    sqrt(s)``, its information matrix ``M = sum J~^T J~`` with ``J~ = (d nu / d theta) / sqrt(s)``
    (gains held). Innovations of the right model are white and ``M^-1`` is their covariance; where
    the model misses something (the turbulence model's form or scale length, a delay, the
    aircraft's response to the gusts) they are coloured, and the sandwich
    ``M^-1 [sum_k J~_k^T Sigma_k J~_k] M^-1`` with ``Sigma_k`` the innovations' modelled spectrum
    (autoregressive per channel, corrected for the fit's leverage, channels coupled through a
    smoothed coherence: :func:`_ar_factor`) is the covariance to quote. Floored at the Cramér-Rao
    bound. The IMU noise as process noise is not in it: the filter-error method adds
    :func:`honest_std`'s ``imu_only`` share
    (:meth:`estimator.filter_error.FilterErrorLikelihood.honest_deviations`).

    Parameters
    ----------
    N, st : the filter-error normal equations at the estimate and which parameters are free.
    series : maneuver index -> (free parameter indices ``cols``, per channel ``(channel, samples,
        nu~, J~ (n_c, cols))``), SI (:meth:`estimator.filter_error.FilterErrorLikelihood.innovation_series`).
    grid : each maneuver's samples and sample interval (:class:`ManeuverGrid`).
    std_crb : (P,) the Cramér-Rao deviations (the floor).
    rank_rtol : relative eigenvalue threshold of the inverses.
    cross_channel : with the cross-channel coherence.
    map_fn : ``map`` or a thread pool's (the maneuvers are independent).

    Returns
    -------
    (P,) honest deviations (NaN where not estimated) and the globals' honest covariance (G, G).
    """
    nparam = std_crb.size
    _, _, Sinv, Ainv = lm_solve(N, 0.0, rank_rtol)
    n_of, dt_of = grid

    def middle(k: int):
        cols, chans = series(k)
        if not cols.size or not chans:
            return k, cols, None
        n, Lk = int(n_of[k]), sfft.next_fast_len(max(2 * int(n_of[k]) - 1, 1), real=True)
        pos = np.arange(cols.size)
        items = []
        for c, rows, e, Jn in chans:
            Jp = np.zeros((cols.size, Lk))
            Jp[:, rows] = Jn.T
            ep = np.zeros(Lk)
            ep[rows] = e
            items.append((c, pos, sfft.rfft(Jp, axis=-1), sfft.rfft(ep), rows, e, 1.0))
        cov_u = _union_covariance(st, Sinv, Ainv, N, k, cols)
        return k, cols, _ar_middle(items, cov_u, cols.size, n, Lk, float(dt_of[k]), cross_channel)

    C = NormalEquations(st)
    for k, cols, Ck in map_fn(middle, range(len(n_of))):
        if Ck is not None:
            C.add_blocks(Ck[None], np.zeros((1, cols.size)), np.ascontiguousarray(cols[None, :]),
                         np.array([k]), 1.0)
    std_mk, cov_mk = sandwich_std(N, st, C, Sinv, Ainv, nparam)
    floor = np.where(np.isfinite(std_crb), std_crb, 0.0)
    honest = np.where(np.isfinite(std_mk), np.maximum(std_mk, floor), np.nan)
    g = st.glob
    raise_to = np.maximum(1.0, floor[g] / np.where(std_mk[g] > 0, std_mk[g], np.inf))
    return honest, raise_to[:, None] * cov_mk * raise_to[None, :]


def _union_covariance(st: Structure, Sinv: np.ndarray, Ainv: list[np.ndarray], N: NormalEquations, k: int,
                      u: np.ndarray) -> np.ndarray:
    """The Cramér-Rao covariance of the parameters ``u`` (indices) of maneuver ``k``: its locals and
    the globals its channels depend on (``Cov_LL = A^-1 + B S^-1 B^T``, ``Cov_LG = -B S^-1``,
    ``B = A^-1 M_LG``)."""
    g = st.gpos[u]
    isg = g >= 0
    out = np.zeros((u.size, u.size))
    gi = g[isg]
    out[np.ix_(isg, isg)] = Sinv[np.ix_(gi, gi)]
    if st.local_of_arr[k].size:
        isl = ~isg
        lp = st.lpos[u[isl]]
        B = Ainv[k] @ N.HGL[k].T  # (L, G)
        out[np.ix_(isl, isl)] = (Ainv[k] + B @ Sinv @ B.T)[np.ix_(lp, lp)]
        cov_lg = -(B @ Sinv)[np.ix_(lp, gi)]
        out[np.ix_(isl, isg)] = cov_lg
        out[np.ix_(isg, isl)] = cov_lg.T
    return out


def _ar_middle(items: list, cov_u: np.ndarray, nu: int, n: int, L: int, dt_s: float, cross: bool
               ) -> np.ndarray:
    """One maneuver's coloured middle ``1/L sum_f w_f Re(Y_f Y_f^H)`` (U, U) from its channels'
    spectra (:func:`_ar_factor`'s arguments; ``w_f`` the one-sided spectrum's weights)."""
    Y = _ar_factor(items, cov_u, nu, n, L, dt_s, cross)  # (U, nf, r): one real gemm, no copy
    Yr = Y.view(np.float64).reshape(nu, -1)
    return Yr @ Yr.T


def _ar_factor(items: list, cov_u: np.ndarray, nu: int, n: int, L: int, dt_s: float, cross: bool
               ) -> np.ndarray:
    """``Y_f sqrt(w_f / L)`` (U, nf, r) of one maneuver from its channels' Jacobian spectra and
    autoregressive residual models (:func:`honest_std`, ``colored_spectrum = "ar"``).

    Each channel's residual periodogram is corrected for the fit's leverage ``h_c(f)`` (capped at
    0.95: the few bins the parameters empty almost completely carry no information either way)
    before its model is fitted; full-rate channels share a smoothed innovation coherence (with
    ``cross``), a channel recorded every ``s``-th sample is modelled on its own samples and alone;
    samples missing from a channel's cost (excluded outliers) are zeros of its series.
    """
    nf = L // 2 + 1
    models, alone = [], []
    for _, pos, F, Ef, rows, e, w in items:
        # the channel's spacing on the grid (4 for 10 Hz in 40 Hz); gaps of whole spacings (samples
        # the robust option excluded) leave zeros in the series: the correlation estimate loses
        # their few pairs, nothing more
        steps = np.diff(rows)
        stride = int(steps.min()) if steps.size else 1
        if steps.size and np.any(steps % stride):
            stride = 0
        nc = rows.size
        if stride == 0:  # irregular samples: no correlation model, the residual variance
            models.append(ARModel(np.zeros(0), float(e @ e) / nc, 1))
            alone.append(True)
            continue
        # the leverage Re(F^H Cov F) per frequency, in real arithmetic on the interleaved parts
        # (Cov is real: a complex product would multiply its zero imaginary part too)
        Fr = F.view(np.float64)
        quad = np.sum(Fr * (cov_u[np.ix_(pos, pos)] @ Fr), axis=0).reshape(-1, 2).sum(axis=1)
        h = np.minimum(w / nc * quad, 0.95)
        I_corr = (np.abs(Ef) ** 2 / nc) / (1.0 - h)
        r = sfft.irfft(I_corr, L)[:(AR_MAX_ORDER + 1) * stride:stride]
        models.append(ar_from_autocovariance(r, nc, stride=stride))
        alone.append(stride != 1 or not cross)
    together = [i for i, a in enumerate(alone) if not a]
    cols = sum(alone) + len(together)
    factors = np.zeros((len(items), nf, cols), dtype=complex)
    j = 0
    for i, a in enumerate(alone):
        if a:
            factors[i, :, j] = models[i].inverse_filter(L) * np.sqrt(models[i].innovation_var)
            j += 1
    if together:
        U = np.zeros((n, len(together)))
        for t, i in enumerate(together):
            rows, e, m = items[i][4], items[i][5], models[i]
            x = np.zeros(n)
            x[rows] = e
            u = m.innovations(x)  # on the grid: a gap's zeros stand in for its missing samples
            ok = rows[rows >= m.order]
            U[ok, t] = u[ok - m.order]
        gam = innovation_cross_spectrum(U, np.array([models[i].innovation_var for i in together]), L, dt_s)
        Lam = _psd_factor(gam)  # (nf, Ct, Ct)
        for t, i in enumerate(together):
            factors[i, :, j:] = models[i].inverse_filter(L)[:, None] * Lam[:, t, :]
    # Y_f = sum_i w_i F_i,f factors_i,f, channel by channel in their order, written straight into
    # the (U, nf, r) layout the middle's product reads (a product per frequency over every
    # parameter and channel multiplies mostly zeros: a channel depends on a few of the parameters)
    Y = np.zeros((nu, nf, cols), dtype=complex)
    for i, (_, pos, F, _, _, _, w) in enumerate(items):
        add_spectral_factor(Y, pos, F, float(w), np.ascontiguousarray(factors[i]))
    Y *= np.sqrt(_one_sided_weights(L) / L)[None, :, None]
    return Y


def _psd_factor(gam: np.ndarray) -> np.ndarray:
    """``Lam`` with ``Lam Lam^H = gam`` per frequency (``gam`` (nf, C, C) positive semi-definite):
    the Cholesky factors, or, should one frequency's matrix be singular (fewer smoothed bins than
    channels), at every frequency the eigenvectors scaled by the square roots of the eigenvalues
    clipped at zero (the same product; which factor does not change the middle)."""
    try:
        return np.linalg.cholesky(gam)
    except np.linalg.LinAlgError:
        lam, vec = np.linalg.eigh(gam)
        return vec * np.sqrt(np.maximum(lam, 0.0))[:, None, :]


def _scatter_add(target: np.ndarray, pos: np.ndarray, values: np.ndarray) -> None:
    """``target[pos] += values``, where slots of one parameter (repeated ``pos``) add up; the common
    case of distinct positions without ``np.add.at`` (which is slow)."""
    if np.unique(pos).size == pos.size:
        target[pos] += values
    else:
        np.add.at(target, pos, values)


#: Maneuvers are taken in chunks whose spectral factors take about this much memory (at the paper's
#: bin size, 70 maneuvers, half of 256 MB took 60 MB off the peak at the same speed; a quarter
#: took 13 MB more and cost a sixth more time: each chunk is evaluated on its own).
_COLORED_CHUNK_BYTES = 128e6


def imu_noise_psd(problem: Problem, imu_noise: str | tuple[float, float]) -> dict[str, np.ndarray] | None:
    """The IMU's white-noise level per aircraft, (6,) SI^2 s (accelerometers, gyros), or None.

    ``imu_noise``: "estimate" (from each maneuver's IMU data, :func:`white_noise_psd`), "none", or
    ``(accel_psd, gyro_psd)`` in m^2/s^3 and rad^2/s for every aircraft.
    """
    if isinstance(imu_noise, str):
        if imu_noise == "none":
            return None
        per: dict[str, list[np.ndarray]] = {}
        for m in problem.maneuvers:
            u = np.hstack([m.accel_imu_mps2, m.omega_rps])
            per.setdefault(m.aircraft, []).append([white_noise_psd(u[:, j], m.dt_s) for j in range(6)])
        # one IMU per aircraft: the median over its maneuvers is robust to one whose sharp inputs
        # leak into the band; NaN where no maneuver was long enough to read it (the caller says so)
        with np.errstate(all="ignore"):
            return {a: np.nanmedian(np.array(v), axis=0) for a, v in per.items()}
    accel, gyro = imu_noise
    psd = np.array([accel] * 3 + [gyro] * 3, dtype=float)
    return {m.aircraft: psd for m in problem.maneuvers}


def sandwich_std(N: NormalEquations, st: Structure, C: NormalEquations, Sinv: np.ndarray,
                 Ainv: list[np.ndarray], nparam: int) -> tuple[np.ndarray, np.ndarray]:
    """Standard deviations of ``M^-1 C M^-1`` for a middle matrix ``C`` gathered like the normal
    equations (global, coupling and per-maneuver local blocks), through the Schur structure of
    ``M`` (``S^-1`` and the local blocks' inverses ``A_k^-1``); and its global block (G, G)."""
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
        cross_k = Ai @ CLG @ Sinv @ Bk.T
        cov = Ai @ CLL @ Ai - cross_k - cross_k.T + Bk @ covG @ Bk.T
        std[st.local_of_arr[k]] = np.sqrt(np.maximum(np.diag(cov), 0.0))
    return std, covG


def std_of(st: Structure, cov_G: np.ndarray, cov_L: list[np.ndarray], n: int) -> np.ndarray:
    """(n,) the Cramér-Rao deviations ``sqrt(diag(cov))`` of the free parameters (global block and each
    local block); NaN for the others."""
    std = np.full(n, np.nan)
    std[st.glob] = np.sqrt(np.maximum(np.diag(cov_G), 0.0))
    for k, idx in enumerate(st.local_of_arr):
        if idx.size:
            std[idx] = np.sqrt(np.maximum(np.diag(cov_L[k]), 0.0))
    return std


class Covariance(NamedTuple):
    """The undamped Cramér-Rao covariance at an estimate
    (:func:`estimator.identifiability.covariance`)."""

    cov_G: np.ndarray  # S^-1, the global block's
    cov_L: list[np.ndarray]  # each maneuver's local block's
    unident: list  # unidentifiable sets, each with the member to hold: (Confounding, index)
    correlated: list[Confounding]  # global-local pairs beyond the correlation threshold


@dataclass(frozen=True)
class Deviations:
    """The deviations at the estimate (:func:`deviations`), one per parameter (NaN: not estimated).

    Attributes
    ----------
    std_crb : Cramér-Rao deviations.
    std_colored : coloured-residual (honest) deviations, IMU noise included; NaN without ``colored``.
    std_imu : the IMU noise's part of them.
    correlation, correlation_colored : the global parameters' correlations, Cramér-Rao and honest.
    unresolved : parameters of a set still unidentifiable at the solution (their deviations NaN).
    imu_psd : the IMU noise densities used, per aircraft (None without ``colored``).
    feedback : the filter-error method's feedback check of the time delays, one
        :class:`estimator.core.instrumental.DelayCheck` per delay it widened or could not judge
        (:meth:`estimator.filter_error.FilterErrorLikelihood.honest_deviations`).
    """

    std_crb: np.ndarray
    std_colored: np.ndarray
    std_imu: np.ndarray
    correlation: np.ndarray
    correlation_colored: np.ndarray
    unresolved: np.ndarray
    imu_psd: dict[str, np.ndarray] | None
    feedback: tuple[DelayCheck, ...] = ()


def deviations(model: Model, theta: np.ndarray, N: NormalEquations, st: Structure, R: np.ndarray,
               cov: Covariance, opt: SolverOptions) -> Deviations:
    """Cramér-Rao and honest deviations and correlations at the estimate, from the undamped
    covariance (:func:`estimator.identifiability.covariance`: ``cov_G``, ``cov_L``) and the
    still-unidentifiable sets (its ``unident``)."""
    cov_G, cov_L, unident = cov.cov_G, cov.cov_L, cov.unident
    problem = model.problem
    ps = problem.parameters
    n = len(ps.keys)
    std = std_of(st, cov_G, cov_L, n)
    # a set still unidentifiable here (the screen's rounds ran out): no deviation means anything
    unresolved = np.zeros(n, dtype=bool)
    for conf, _ in unident:
        unresolved[[ps.index(k) for k in conf.parameters]] = True
    std[unresolved] = np.nan
    dg = np.sqrt(np.maximum(np.diag(cov_G), 1e-300))
    corr_G = cov_G / np.outer(dg, dg)
    std_col = np.full(n, np.nan)
    std_imu = np.full(n, np.nan)
    corr_honest = np.full_like(corr_G, np.nan)
    imu_psd = imu_noise_psd(problem, opt.imu_noise) if opt.colored else None
    if opt.colored:
        std_col, std_imu, cov_hon = honest_std(
            model, theta, N, st, R, std, imu_psd,
            HonestOptions(opt.rank_rtol, cross_channel=opt.colored_cross_channel,
                          spectrum=opt.colored_spectrum))
        std_col[unresolved] = np.nan
        std_imu[unresolved] = np.nan
        dh = np.sqrt(np.maximum(np.diag(cov_hon), 1e-300))
        corr_honest = cov_hon / np.outer(dh, dh)
    return Deviations(std, std_col, std_imu, corr_G, corr_honest, unresolved, imu_psd)


def imu_noise_unknown(imu_psd: dict[str, np.ndarray] | None) -> list[Finding]:
    """A warning when the IMU noise could not be read off an aircraft's data (nothing otherwise)."""
    unread = sorted(a for a, v in (imu_psd or {}).items() if not np.all(np.isfinite(v)))
    if not unread:
        return []
    return [Finding(
        "imu_noise_unknown", Severity.WARNING,
        f"the IMU noise level could not be read off the data of {', '.join(unread)} (every maneuver "
        "shorter than 64 samples): the honest deviations leave the IMU noise out, and the IMU "
        "biases' and initial conditions' deviations may be several times too small",
        "give the IMU's noise densities (SolverOptions.imu_noise: datasheet random walks, squared, SI)")]


def imu_noise_note(dev: Deviations, st: Structure, keys: list[str], opt: SolverOptions) -> list[Finding]:
    """A note of the IMU noise integrated as process noise and how much it adds (nothing without)."""
    imu_psd, std, std_imu = dev.imu_psd, dev.std_crb, dev.std_imu
    if imu_psd is None or not np.isfinite(std_imu).any():
        return []
    inflation = np.where(st.free, np.sqrt(1.0 + (std_imu / np.where(std > 0, std, np.nan)) ** 2), np.nan)
    worst = int(np.nanargmax(inflation)) if np.isfinite(inflation).any() else -1
    levels = "; ".join(
        f"{a}: accelerometers {np.nan_to_num(np.sqrt(v[:3])).max():.2g} m/s/sqrt(s), gyros "
        f"{np.degrees(np.nan_to_num(np.sqrt(v[3:]))).max() * 60.0:.2g} deg/sqrt(h)"
        for a, v in imu_psd.items())
    source = "from the data" if opt.imu_noise == "estimate" else "as given"
    most = (f", most to {keys[worst]} ({inflation[worst]:.2g} x its Cramér-Rao deviation)"
            if worst >= 0 else "")
    return [Finding(
        "imu_noise", Severity.NOTE,
        f"IMU noise integrated as process noise ({source}: {levels}) adds to the coloured "
        f"deviations{most}",
        "give the IMU's datasheet random walks (SolverOptions.imu_noise) if the data's own level, "
        "which counts vibration as noise, is too pessimistic")]
