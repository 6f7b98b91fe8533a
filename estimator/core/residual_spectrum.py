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
    a = np.zeros(0)
    var = r[0]
    best = (n * np.log(var), a, var)
    for p in range(1, pmax + 1):
        k = (r[p] - a @ r[p - 1:0:-1]) / var if a.size else r[1] / var
        if not abs(k) < 1.0:  # round-off at a perfectly predictable series: stop there
            break
        a = np.concatenate([a - k * a[::-1], [k]])
        var *= 1.0 - k * k
        if not var > 0.0:
            break
        aic = n * np.log(var) + 2.0 * p
        if aic < best[0]:
            best = (aic, a.copy(), var)
    return ARModel(best[1], float(best[2]), stride)

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
    n, C = U.shape
    Fu = np.fft.rfft(U, L, axis=0)  # (nf, C)
    P = Fu[:, :, None] * np.conj(Fu[:, None, :])  # (nf, C, C), rank one per frequency
    nf = P.shape[0]
    h = max(1, int(round(0.5 * bandwidth_hz * L * dt_s)))
    # reflect: the periodogram of a real series is conjugate-symmetric about 0 and about L/2 (the
    # last bin is Nyquist itself for an even L; for an odd L the mirror starts at the last bin)
    top = np.conj(P[-2:-h - 2:-1]) if L % 2 == 0 else np.conj(P[-1:-h - 1:-1])
    ext = np.concatenate([np.conj(P[h:0:-1]), P, top], axis=0)
    cs = np.cumsum(ext, axis=0)
    cs = np.concatenate([np.zeros((1, C, C), dtype=complex), cs], axis=0)
    K = (cs[2 * h + 1:2 * h + 1 + nf] - cs[:nf]) / (2 * h + 1)
    d = np.sqrt(np.maximum(np.real(np.einsum("fcc->fc", K)), 1e-300))
    sd = np.sqrt(np.maximum(variances, 0.0))
    scale = sd[None, :] / d
    return K * scale[:, :, None] * scale[:, None, :]
