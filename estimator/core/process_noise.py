r"""IMU noise as process noise: its level from the data, and what it adds to the parameters' covariance.

The output-error method integrates the measured accelerations and rates as if they were exact. Their
noise is integrated too: a random walk in velocity and attitude that no parameter models, strongest
at low frequency, exactly where the IMU biases and initial conditions live (a bias is a ramp). The
residuals do not show it (the biases and initial conditions have absorbed its low-frequency part),
so neither the Cramér-Rao bound nor the coloured-residual correction can account for it; the IMU
biases' scatter is then 2-3 times their Cramér-Rao deviation.

**Its effect, linearised** (the output-error analogue of the process-noise term of the filter-error
method; Jategaonkar 2006, §5.2). An input error ``du_j`` (6 IMU axes) at sample ``j`` moves the
states at ``i >= j`` by ``Phi_i Phi_j^-1 B_j dt du_j``, with ``Phi_i = dx_i/dx0`` the state
transition from the initial conditions and ``B_j`` the input matrix. Both come from the forward
sensitivities the estimator integrates anyway: with ``S_b(i) = dx_i/d(IMU biases)`` (a bias is
the same input error at every sample, with the opposite sign), ``E_i = Phi_i^-1 S_b(i)`` is the
running sum of ``-Phi_j^-1 B_j dt``, so ``dE_j = E_j - E_{j-1}`` is one sample's contribution. An
output ``y_i`` moves by ``J_IC,i Phi_i^-1 dx_i`` with ``J_IC,i = dy_i/dx0`` (the initial-condition
columns of its Jacobian). For white input noise of covariance ``Q`` per sample the gradient
``g = sum_i J_i^T W e_i`` then has covariance::

    C_proc = sum_j V_j V_j^T,     V_j = A_j dE_j Q^1/2,     A_j = sum_{i >= j} J_i^T W J_IC,i

(suffix sums over the samples and channels of a maneuver: linear in the maneuver's length), and
``M^-1 C_proc M^-1`` is the parameters' covariance from the IMU noise. It adds to the
coloured-residual (Morelli-Klein) covariance: the part of the random walk the residuals still show
is then counted twice, a small conservative excess because what remains after the biases and
initial conditions is the weak high-frequency end of a random walk. The direct effect of gyro
noise on a flow angle (through ``omega x r``, ~1e-5 rad) is left out.

**The noise level from the data.** ``Q = S0 / dt`` per model sample, ``S0`` the white-noise power
spectral density (``SI^2 s``: a random walk from it has variance ``S0 t``). Aircraft motion has
next to no content in the upper third of the band of a 40-Hz record, so ``S0`` is estimated there:
the periodogram of the third difference (which removes the smooth motion; its gain
``(2 sin(pi f dt))^6`` is divided out), Hann-windowed, median over the band (robust to the motion's
harmonics; divided by ln 2, the median of a chi-square-2 bin over its mean), per maneuver; then the
median over the maneuvers of an aircraft (one IMU, the same noise; robust to a maneuver whose
sharp inputs leak into the band). On data resampled from another rate (an IMU at 64 Hz
interpolated to 40 Hz) it reads 1.1-1.2 times the true level: conservative. Vibration that reaches
the band counts as noise (conservative again); a datasheet's random-walk coefficients can be
given instead.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: The band the noise level is read in, in cycles per sample (upper third below Nyquist).
NOISE_BAND = (0.3, 0.45)


def white_noise_psd(x: np.ndarray, dt_s: float, band: tuple[float, float] = NOISE_BAND) -> float:
    """White-noise power spectral density of a recorded signal, read off its upper band.

    Parameters
    ----------
    x : (N,) the signal, SI.
    dt_s : its sample interval, s.
    band : the band, in cycles per sample.

    Returns
    -------
    S0 in SI^2 s (a random walk of this noise has variance ``S0 t``); NaN for fewer than 64 samples.
    """
    x = np.asarray(x, dtype=float)
    if x.size < 64 or not np.all(np.isfinite(x)):
        return float("nan")
    d = np.diff(x, 3)
    win = np.hanning(d.size)
    P = np.abs(np.fft.rfft((d - d.mean()) * win)) ** 2 / np.sum(win * win)
    f = np.fft.rfftfreq(d.size)
    sel = (f >= band[0]) & (f <= band[1])
    level = np.median(P[sel] / (2.0 * np.sin(np.pi * f[sel])) ** 6) / np.log(2.0)
    return float(level * dt_s)


def input_increments(phi: np.ndarray, s_bias: np.ndarray) -> np.ndarray:
    """Each sample's share of the input sensitivity, mapped back to the initial conditions.

    Parameters
    ----------
    phi : (N, 7, 7) ``dx_i / dx0``, the state transition from the initial conditions.
    s_bias : (N, 7, 6) ``dx_i / d(IMU biases)`` (accelerometers, then gyros).

    Returns
    -------
    (N, 7, 6) ``dE_j = E_j - E_{j-1}``, ``E_i = phi_i^-1 s_bias_i`` (module docstring).
    """
    E = np.linalg.solve(phi, s_bias)
    return np.diff(E, axis=0, prepend=np.zeros((1,) + E.shape[1:]))


@njit(cache=True, nogil=True)
def add_channel_products(b: np.ndarray, pos: np.ndarray, J: np.ndarray, J_ic: np.ndarray,
                         rows: np.ndarray, w: float) -> None:
    """Add one channel's ``J_i^T W J_IC,i`` to a maneuver's ``b`` in place (channels in common
    parameters add up; called channel by channel, in a fixed order).

    Parameters
    ----------
    b : (N, U, 7) the maneuver's sums on its sample grid, over its ``U`` parameters.
    pos : (m,) each Jacobian row's parameter position in ``b`` (repeats add up).
    J : (m, n) the channel's Jacobian over those parameters at its ``n`` samples in the cost, SI.
    J_ic : (n, 7) its initial-condition columns.
    rows : (n,) the samples' indices on the grid.
    w : the channel's weight ``W = 1 / R``, 1/SI^2.
    """
    m, n = J.shape
    c = J_ic.shape[1]
    for a in range(m):
        u = pos[a]
        for r in range(n):
            t = rows[r]
            ja = J[a, r]
            for j in range(c):
                b[t, u, j] += ja * J_ic[r, j] * w


@njit(cache=True, nogil=True)
def suffix_middle_factor(b: np.ndarray, dE_q: np.ndarray) -> np.ndarray:
    """The factor ``Y`` of a maneuver's ``C_proc = Y Y^T``: ``V_j = (sum_{i >= j} b_i) dE_q_j``
    (module docstring), parameter-major.

    Parameters
    ----------
    b : (N, U, 7) ``sum_c J_i^T W J_IC,i`` on the maneuver's sample grid, summed over its channels
        (:func:`add_channel_products`; zero where no channel has a sample in the cost).
    dE_q : (N, 7, 6) the input increments times ``Q^1/2``.

    Returns
    -------
    (U, N * 6): row ``u`` holds ``V_j[u, :]`` for ``j = 0 .. N-1`` in turn.
    """
    n, nu, c = b.shape
    q = dE_q.shape[2]
    Y = np.empty((nu, n * q))
    A = np.zeros((nu, c))  # the suffix sum, from the last sample back
    for t in range(n - 1, -1, -1):
        for u in range(nu):
            for j in range(c):
                A[u, j] += b[t, u, j]
            for k in range(q):
                s = 0.0
                for j in range(c):
                    s += A[u, j] * dE_q[t, j, k]
                Y[u, t * q + k] = s
    return Y
