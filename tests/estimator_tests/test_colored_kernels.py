"""The compiled kernels of the honest deviations against their plain numpy definitions.

The coloured-residual sandwich's factor (:func:`estimator.core.residual_spectrum.add_spectral_factor`),
the innovations' smoothed cross-periodogram (``innovation_cross_spectrum``), the autoregressive
fit (``ar_from_autocovariance``) and the IMU noise's suffix sums
(:mod:`estimator.core.process_noise`) compute sums the numpy formulations below state directly;
the kernels only reorder them, so they agree to round-off (1e-12 relative: sums of a few thousand
terms of one sign at most, each rounded at 1e-16).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from estimator.core.process_noise import add_channel_products, suffix_middle_factor
from estimator.core.residual_spectrum import (
    add_spectral_factor,
    ar_from_autocovariance,
    innovation_cross_spectrum,
)

RTOL = 1e-12  # round-off of reordered sums (module docstring)


def _close(a, b, rtol=RTOL):
    scale = max(float(np.max(np.abs(b))), 1e-300)
    return float(np.max(np.abs(a - b))) / scale <= rtol


def test_spectral_factor_is_the_per_frequency_product():
    rng = np.random.default_rng(1)
    nu, nf, r = 9, 33, 4
    chans = [(np.array([0, 3, 5]), 0.7), (np.array([3, 3, 8]), 2.0), (np.array([1, 2]), 0.1)]
    Fs = [rng.normal(size=(p.size, nf)) + 1j * rng.normal(size=(p.size, nf)) for p, _ in chans]
    facs = rng.normal(size=(len(chans), nf, r)) + 1j * rng.normal(size=(len(chans), nf, r))
    Y = np.zeros((nu, nf, r), dtype=complex)
    for (pos, w), F, fac in zip(chans, Fs, facs, strict=True):
        add_spectral_factor(Y, pos, F, w, fac)
    # the definition: H[f, u, i] = w_i sum of F_i's rows at u (repeats add up), Y_f = H_f factors_f
    H = np.zeros((nf, nu, len(chans)), dtype=complex)
    for i, ((pos, w), F) in enumerate(zip(chans, Fs, strict=True)):
        np.add.at(H[:, :, i].T, pos, w * F)
    ref = np.einsum("fui,ifk->ufk", H, facs)
    assert _close(Y, ref), "the kernel's factor differs from H_f factors_f beyond round-off"


def test_imu_suffix_factor_is_the_suffix_sum_times_the_increments():
    rng = np.random.default_rng(2)
    n, nu = 40, 6
    chans = [(np.array([0, 2, 4]), np.arange(3, 37), 0.5),   # a guard band: rows 3..36
             (np.array([2, 2, 5]), np.arange(0, 40, 4), 3.0),  # every 4th sample, a repeated slot
             (np.array([1]), np.arange(n), 1.0)]
    b = np.zeros((n, nu, 7))
    ref_b = np.zeros((nu, n, 7))
    for pos, rows, w in chans:
        J = rng.normal(size=(pos.size, rows.size))
        J_ic = rng.normal(size=(rows.size, 7))
        add_channel_products(b, pos, J, J_ic, rows, w)
        outer = np.zeros((pos.size, n, 7))
        outer[:, rows] = J[:, :, None] * J_ic[None, :, :] * w
        np.add.at(ref_b, pos, outer)
    assert _close(b, ref_b.transpose(1, 0, 2)), "J^T W J_IC placed on the grid wrongly"
    dE = rng.normal(size=(n, 7, 6))
    Y = suffix_middle_factor(b, dE)
    A = np.cumsum(b[::-1], axis=0)[::-1]
    V = np.einsum("jsc,jcq->jsq", A, dE)  # (n, U, 6)
    ref = V.transpose(1, 0, 2).reshape(nu, -1)
    assert Y.shape == (nu, n * 6)
    assert _close(Y, ref), "V_j = (sum_{i>=j} b_i) dE_j differs beyond round-off"
    assert _close(Y @ Y.T, np.einsum("jsq,jtq->st", V, V)), "C_proc = sum_j V_j V_j^T"


def _cross_spectrum_reference(U, variances, L, dt_s, bandwidth_hz=0.3):
    """The Daniell-smoothed cross-periodogram by a cumulative sum over the reflected bins."""
    n, C = U.shape
    Fu = np.fft.rfft(U, L, axis=0)
    P = Fu[:, :, None] * np.conj(Fu[:, None, :])
    nf = P.shape[0]
    h = max(1, int(round(0.5 * bandwidth_hz * L * dt_s)))
    top = np.conj(P[-2:-h - 2:-1]) if L % 2 == 0 else np.conj(P[-1:-h - 1:-1])
    ext = np.concatenate([np.conj(P[h:0:-1]), P, top], axis=0)
    cs = np.concatenate([np.zeros((1, C, C), dtype=complex), np.cumsum(ext, axis=0)], axis=0)
    K = (cs[2 * h + 1:2 * h + 1 + nf] - cs[:nf]) / (2 * h + 1)
    d = np.sqrt(np.maximum(np.real(np.einsum("fcc->fc", K)), 1e-300))
    scale = np.sqrt(variances)[None, :] / d
    return K * scale[:, :, None] * scale[:, None, :]


# the Nyquist bin itself (even L) or not (odd); a window of one bin each side (dt 0.025 s) or of
# four (0.1 s), reflected over several bins at both ends
@pytest.mark.parametrize("L, dt_s", [(256, 0.025), (255, 0.025), (256, 0.1), (255, 0.1)])
def test_cross_spectrum_running_window_matches_the_cumulative_sum(L, dt_s):
    rng = np.random.default_rng(3)
    n = 120
    common = np.convolve(rng.normal(size=n + 9), np.ones(10) / 10, mode="valid")
    U = rng.normal(size=(n, 3)) + common[:, None] * np.array([1.0, 0.5, -0.8])
    U[::7, 2] = 0.0  # a channel's missing samples are zeros of its series
    var = np.array([1.2, 0.9, 1.5])
    K = innovation_cross_spectrum(U, var, L, dt_s)
    ref = _cross_spectrum_reference(U, var, L, dt_s)
    assert K.shape == ref.shape == (L // 2 + 1, 3, 3)
    # a running sum over a few hundred bins: its round-off relative to the largest bin
    assert _close(K, ref, 1e-11), "the smoothed cross-periodogram differs beyond round-off"
    assert np.allclose(np.real(np.einsum("fcc->fc", K)), var[None, :], rtol=1e-10), (
        "the diagonal is each model's innovation variance by construction")
    assert np.all(np.linalg.eigvalsh(K) > -1e-9 * var.max()), "positive semi-definite per frequency"


def _levinson_reference(r, n, max_order=40, per_order=10):
    pmax = int(min(max_order, n // per_order, r.size - 1))
    if pmax < 1 or not r[0] > 0.0:
        return np.zeros(0), float(max(r[0], 0.0))
    a, var = np.zeros(0), r[0]
    best = (n * np.log(var), a, var)
    for p in range(1, pmax + 1):
        k = (r[p] - a @ r[p - 1:0:-1]) / var if a.size else r[1] / var
        if not abs(k) < 1.0:
            break
        a = np.concatenate([a - k * a[::-1], [k]])
        var *= 1.0 - k * k
        if not var > 0.0:
            break
        aic = n * np.log(var) + 2.0 * p
        if aic < best[0]:
            best = (aic, a.copy(), var)
    return best[1], best[2]


@settings(max_examples=40, deadline=None)
@given(phi=st.floats(-0.95, 0.95), phi2=st.floats(-0.4, 0.4), n=st.integers(20, 2000),
       seed=st.integers(0, 2**16))
def test_levinson_matches_the_recursion(phi, phi2, n, seed):
    # a stationary AR(2) (its characteristic roots inside the unit circle): an explosive one
    # overflows over 2000 samples and its autocovariance is no autocovariance
    assume(phi + phi2 < 0.98 and phi2 - phi < 0.98)
    rng = np.random.default_rng(seed)
    x = rng.normal(size=n + 2)
    for t in range(2, x.size):
        x[t] += phi * x[t - 1] + phi2 * x[t - 2]
    x = x[2:]
    r = np.array([x[:n - k] @ x[k:] / n for k in range(min(41, n))])
    model = ar_from_autocovariance(r, n)
    a, var = _levinson_reference(r, n)
    assert model.order == a.size, "Akaike's choice of the order differs from the recursion's"
    assert np.allclose(model.a, a, rtol=1e-10, atol=1e-12)
    assert model.innovation_var == pytest.approx(var, rel=1e-12)
