r"""A parametric model of the residuals' spectrum, for honest coloured-residual deviations.

The Morelli-Klein correction (Morelli & Klein 1997) replaces the white-noise assumption of the
Cramér-Rao bound by the residuals' own correlation: ``Cov = M^-1 [J^T W Sigma W J] M^-1``. Summing
the residuals' sample correlation over every lag (the original plug-in) is biased low, and not a
little: the residuals are orthogonal to the Jacobian's columns at the estimate, so the noise power
the parameters absorbed — at the low frequencies where biases, initial conditions and IMU biases
live — is missing from them; for a bias the all-lags sum is the Bartlett estimator with bandwidth
equal to the record length, whose expectation is a third of the truth whatever the correlation
time (Kiefer & Vogelsang 2002). On the analytic flight with coloured, cross-correlated noise its
deviations are 1.39 times too small; with the true noise covariance the same sandwich is right
(Monte Carlo scatter / deviation 1.005, campaigns/benchmarks/results/colored_mc.txt).

So the noise covariance is modelled instead, and the model fitted to the residuals: the missing
band is narrow against the whole spectrum, which fixes a low-order model's parameters, and the
model then carries the spectrum into that band (Priestley 1981, §7.8 on autoregressive spectral
estimation; the same idea as prewhitening in heteroskedasticity-and-autocorrelation-consistent
covariances, Andrews & Monahan 1992). Per maneuver and channel an autoregressive model::

    e_t = sum_{l=1..p} a_l e_{t-l} + u_t,       S_c(w) = var(u_c) / |A_c(e^{-iw})|^2,
    A_c(z) = 1 - sum_l a_l z^l

fitted by Levinson-Durbin to the biased autocovariance (a stable, minimum-phase model), its order
``p <= p_max`` by Akaike's criterion. Channels are correlated through their innovations at equal
times (``Sigma_u``, the flow sensors' common air-data or air-motion error), so the cross-spectral
matrix is ``S(w) = D(w) Sigma_u D(w)^H``, ``D = diag(1 / A_c(e^{-iw}))``. A channel recorded at
every ``s``-th sample (DGPS height) is modelled on its own samples, ``S(w) = S_c(s w)`` on the
common grid, and taken as uncorrelated with the others.

Before the model is fitted, each residual periodogram is divided by ``1 - h(f)``, the fit's
leverage at that frequency (the solver's :mod:`estimator.uncertainty`): without it the model
learns the band the parameters emptied as missing noise. Monte Carlo on the analytic flight
(1200 replications, pooled over 52 parameters): scatter / reported deviation 1.066 +- 0.004 for
correlation times of 0.5 / 0.2 s (the all-lags plug-in 1.389), 0.99-1.08 from white noise to
1 s and for 20-40 s maneuvers; per parameter kind 0.91-1.21.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

#: Longest autoregressive model, in samples (1 s at 40 Hz), and the fewest samples per order.
AR_MAX_ORDER = 40
AR_SAMPLES_PER_ORDER = 10


@dataclass(frozen=True)
class ARModel:
    """An autoregressive model of one residual series.

    Attributes
    ----------
    a : (p,) coefficients ``a_1 .. a_p`` (``A(z) = 1 - sum a_l z^l``).
    innovation_var : var(u), SI^2.
    stride : the series' sample spacing on the maneuver's grid (1, or 4 for 10 Hz in 40 Hz).
    """

    a: np.ndarray
    innovation_var: float
    stride: int = 1

    @property
    def order(self) -> int:
        return int(self.a.size)

    def inverse_filter(self, L: int) -> np.ndarray:
        """``1 / A(e^{-i s w})`` at the ``L // 2 + 1`` frequencies of a real DFT of length ``L`` on
        the maneuver's grid (``s`` the stride)."""
        w = 2.0 * np.pi * np.arange(L // 2 + 1) / L * self.stride
        if not self.a.size:
            return np.ones(w.size, dtype=complex)
        lags = np.arange(1, self.a.size + 1)
        A = 1.0 - np.exp(-1j * np.outer(w, lags)) @ self.a
        return 1.0 / A

    def innovations(self, e: np.ndarray) -> np.ndarray:
        """``u_t = e_t - sum a_l e_{t-l}`` for ``t >= p`` (the first ``p`` left out)."""
        p = self.a.size
        u = e[p:].copy()
        for lag in range(1, p + 1):
            u -= self.a[lag - 1] * e[p - lag:e.size - lag]
        return u


def ar_from_autocovariance(r: np.ndarray, n: int, max_order: int = AR_MAX_ORDER, stride: int = 1) -> ARModel:
    """Levinson-Durbin fit of an autoregressive model to an autocovariance, its order by Akaike's
    criterion ``n ln var(u_p) + 2 p``.

    Parameters
    ----------
    r : (>= 1,) the autocovariance at lags 0, 1, ... (in the series' own samples), SI^2.
    n : the number of samples it was estimated from.
    max_order : the longest model tried (capped at ``n / AR_SAMPLES_PER_ORDER`` and ``r.size - 1``).
    stride : the series' sample spacing on the maneuver's grid.

    Returns
    -------
    The model; order 0 (white) for a series too short or without variance.
    """
    r = np.asarray(r, dtype=float)
    pmax = int(min(max_order, n // AR_SAMPLES_PER_ORDER, r.size - 1))
    if pmax < 1 or not r[0] > 0.0:
        return ARModel(np.zeros(0), float(max(r[0], 0.0)), stride)
    a, var = _levinson_aic(r, n, pmax)
    return ARModel(a, float(var), stride)


@njit(cache=True, nogil=True)
def _levinson_aic(r: np.ndarray, n: int, pmax: int) -> tuple[np.ndarray, float]:
    """Levinson-Durbin up to order ``pmax``, the order chosen by Akaike's criterion.

    Parameters
    ----------
    r : (>= pmax + 1,) the autocovariance at lags 0, 1, ..., ``r[0] > 0``, SI^2.
    n : the number of samples it was estimated from.
    pmax : the longest model tried.

    Returns
    -------
    The coefficients ``a_1 .. a_p`` of the order ``p`` (0 included) of least ``n ln var_p + 2 p``
    and that order's innovation variance, SI^2; the recursion stops early where round-off makes
    a reflection coefficient reach 1 or the variance vanish.
    """
    a = np.zeros(pmax)
    prev = np.zeros(pmax)
    var = r[0]
    best_aic, best_p, best_var = n * np.log(var), 0, var
    best = np.zeros(pmax)
    for p in range(1, pmax + 1):
        acc = r[p]
        for j in range(p - 1):  # a_1 .. a_{p-1} against r[p-1] .. r[1]
            acc -= a[j] * r[p - 1 - j]
        k = acc / var
        if not abs(k) < 1.0:  # round-off at a perfectly predictable series: stop there
            break
        for j in range(p - 1):  # loops, not slice assignments: no shape-check message to compile
            prev[j] = a[j]
        for j in range(p - 1):
            a[j] = prev[j] - k * prev[p - 2 - j]
        a[p - 1] = k
        var *= 1.0 - k * k
        if not var > 0.0:
            break
        aic = n * np.log(var) + 2.0 * p
        if aic < best_aic:
            best_aic, best_p, best_var = aic, p, var
            for j in range(p):
                best[j] = a[j]
    return best[:best_p].copy(), best_var

#: Full width of the frequency smoothing of the innovations' cross-periodogram, Hz.
COHERENCE_BANDWIDTH_HZ = 0.3


def innovation_cross_spectrum(U: np.ndarray, variances: np.ndarray, L: int, dt_s: float,
                              bandwidth_hz: float = COHERENCE_BANDWIDTH_HZ) -> np.ndarray:
    """The innovations' cross-spectral matrix per frequency, ``Gamma(f)`` (nf, C, C).

    The innovations of the channels' own autoregressive models are nearly white, but a component
    common to several channels with its own correlation time makes their *coherence* depend on
    frequency (strongest where the common part has its power). So it is estimated as a smoothed
    cross-periodogram (Daniell kernel, ``bandwidth_hz`` wide, reflected at zero and Nyquist), and
    scaled so that its diagonal is each model's innovation variance (the coherency of the
    smoothed periodogram, times the standard deviations): positive semi-definite per frequency.

    Parameters
    ----------
    U : (n, C) the innovations on the maneuver's grid, zero where a channel has none.
    variances : (C,) each model's innovation variance.
    L : the DFT length (zero-padded, >= 2 n - 1).
    dt_s : the sample interval, s.
    bandwidth_hz : the smoothing width.
    """
    Fu = np.fft.rfft(U, L, axis=0)  # (nf, C)
    # no wider than the spectrum itself: the reflection mirrors the record's own bins only
    h = min(max(1, int(round(0.5 * bandwidth_hz * L * dt_s))), Fu.shape[0] - 1)
    sd = np.sqrt(np.maximum(np.asarray(variances, dtype=float), 0.0))
    return _smoothed_coherency(np.ascontiguousarray(Fu), h, L % 2 == 0, sd)


@njit(cache=True, nogil=True)
def _smoothed_coherency(Fu: np.ndarray, h: int, even: bool, sd: np.ndarray) -> np.ndarray:
    """The Daniell-smoothed cross-periodogram, scaled to the coherency times the deviations.

    ``K(f) = 1/(2h+1) sum_{|g-f|<=h} Fu_g Fu_g^H``, reflected at zero and Nyquist (the periodogram
    of a real series is conjugate-symmetric about 0 and about L/2: the last bin is Nyquist itself
    for an even ``L``; for an odd one the mirror starts at the last bin), as a running sum over
    the window; then ``K_cd sd_c sd_d / sqrt(K_cc K_dd)``.

    Parameters
    ----------
    Fu : (nf, C) complex, the innovations' DFT (length ``L``, ``nf = L // 2 + 1``), SI.
    h : the window's half width in bins, ``0 <= h <= nf - 1``.
    even : whether ``L`` is even.
    sd : (C,) each channel's innovation standard deviation, SI.

    Returns
    -------
    (nf, C, C) complex, SI^2: positive semi-definite per frequency, its diagonal ``sd^2``.
    """
    nf, C = Fu.shape
    K = np.empty((nf, C, C), dtype=np.complex128)
    S = np.zeros((C, C), dtype=np.complex128)
    top = 2 * (nf - 1) if even else 2 * nf - 1
    for g in range(-h, h + 1):
        _add_periodogram(S, Fu, g, top, 1.0)
    width = 2 * h + 1
    d = np.empty(C)
    for f in range(nf):
        if f > 0:
            _add_periodogram(S, Fu, f + h, top, 1.0)
            _add_periodogram(S, Fu, f - h - 1, top, -1.0)
        for i in range(C):
            d[i] = np.sqrt(max(S[i, i].real / width, 1e-300))
        for i in range(C):
            for j in range(C):
                K[f, i, j] = S[i, j] / width * (sd[i] / d[i]) * (sd[j] / d[j])
    return K


@njit(cache=True, nogil=True)
def _add_periodogram(S: np.ndarray, Fu: np.ndarray, g: int, top: int, sign: float) -> None:
    """``S += sign Fu_g Fu_g^H`` for bin ``g`` of the reflected sequence (``g < 0``: the conjugate
    of bin ``-g``; beyond the last bin, of bin ``top - g``)."""
    nf, C = Fu.shape
    src = -g if g < 0 else (top - g if g >= nf else g)
    mirrored = g < 0 or g >= nf
    for i in range(C):
        for j in range(C):
            v = Fu[src, i] * np.conj(Fu[src, j])
            S[i, j] += sign * (np.conj(v) if mirrored else v)


@njit(cache=True, nogil=True)
def add_spectral_factor(Y: np.ndarray, pos: np.ndarray, F: np.ndarray, w: float,
                        factor: np.ndarray) -> None:
    """``Y[pos[a], f, :] += w F[a, f] factor[f, :]`` in place: one channel's part of the
    coloured-residual sandwich's factor ``Y_f = sum_c W_c F_c,f B_c(f)``
    (:func:`estimator.uncertainty.honest_std`), channels in common parameters adding up.

    Parameters
    ----------
    Y : (U, nf, r) complex, the maneuver's factor over its ``U`` parameters.
    pos : (m,) each Jacobian row's parameter position in ``Y`` (repeats add up).
    F : (m, nf) complex, the DFT of the channel's Jacobian rows on the maneuver's grid.
    w : the channel's weight, 1/SI^2.
    factor : (nf, r) complex, the channel's row of the residual spectrum's factor ``B_c(f)``.
    """
    m, nf = F.shape
    r = factor.shape[1]
    for a in range(m):
        u = pos[a]
        for f in range(nf):
            c = w * F[a, f]
            for k in range(r):
                Y[u, f, k] += c * factor[f, k]
