"""Fit-quality diagnostics: does the estimate explain the data?

A converged output-error fit is not yet a trustworthy one: a wrong minimum converges, and so does a
fit to a stuck vane. After an estimation, :func:`diagnose` judges the residual of every channel of
every maneuver against the data itself and returns :class:`~estimator.verdict.Finding` s (the
verdict's reasons: any FAILURE fails the estimation, any WARNING qualifies it) and a fit-quality
table, one row per (maneuver, channel). No noise level is declared anywhere: each channel's noise
floor is estimated from its own measurement, so the checks work on flight data no one here
generated. Pure numerical code, SI in, no I/O, no state; vectorised over the channels (padded 2-D
arrays, a block of rows at a time).

Methods
-------
**Noise floor** (the standard deviation of the measurement noise, from the measurement alone). The
k-th difference of white noise of variance s^2 at sample spacing L, ``D = Delta_L^k z``, has
variance ``C(2k, k) s^2`` whatever L, while a smooth signal contributes ``~ (L dt)^k z^(k)``,
negligible for k = 3 at 40 Hz except in the sharpest parts of a maneuver (von Neumann,
"Distribution of the ratio of the mean square successive difference to the variance", Ann. Math.
Stat. 12, 1941; Rice, "Bandwidth choice for nonparametric regression", Ann. Stat. 12, 1984;
Gasser, Sroka & Jennen-Steinmetz, "Residual variance and residual pattern in nonlinear
regression", Biometrika 73, 1986). Made robust (Hampel, "The influence curve and its role in robust
estimation", JASA 69, 1974; Rousseeuw & Croux, "Alternatives to the median absolute deviation",
JASA 88, 1993): per block of 64 differences a first scale ``s0 = median|D| / 0.6745`` (D is
centred on 0), then the mean square of the D with ``|D| <= 4 s0``; the floor is the root of the
blocks' mean, divided by ``C(2k, k) kappa(4)``, where ``kappa(c) = 1 - 2 c phi(c) / (2 Phi(c) - 1)``
= 0.99893 is the variance of a standard normal truncated at +-c. The sharp parts of a maneuver (a
doublet's edges) and outliers are clipped, noise that grows along a maneuver (the nose probe at
high AOA) counts where it is, and the estimate keeps nearly the efficiency of the plain variance
(the MAD alone would be discretised by quantised data). Sampling error for white Gaussian noise:
``var(s^2_hat) = (2 / n) s^4 sum_j rho_j^2`` with ``rho_j = (-1)^j C(2k, k + j) / C(2k, k)`` the
autocorrelation of D; for k = 3 ``sum_j rho_j^2 = 2.31``, so ``sd(s_hat) / s = sqrt(1.155 / n)``
(2.7 % for 1600 samples).

Traps, and what is done about them:

* a channel recorded at another rate and *linearly resampled* onto the common time base (a 64 Hz
  DRU, a 50 Hz INS onto 40 Hz): interpolation correlates neighbouring samples, which shrinks
  short-spacing differences (spacing 1: -7 % for 50 Hz, -62 % for 25 Hz) but not those whose
  samples never share an interpolation interval. The floor is the larger of the spacing-1 and 2
  estimates (white noise: +1 %, half a sampling deviation); if the spacing-2 one is over 25 %
  larger (a stream from under ~30 Hz), spacings 3, 4, ... 8 are tried until the estimate grows by
  less than 5 % (the interpolation's reach is passed), and the floor is the largest; an estimate
  that keeps growing is signal leaking into the differences (turbulence, a sharp maneuver), and
  the spacing-1 and 2 floor stands;
* an *own-rate* channel (DGPS height at 10 Hz) is given by its finite samples at their own times;
  differences are taken over its samples and never across a time gap (a step over 1.5 x the
  median step, as :mod:`estimator.io.timebase`);
* a *quantised* channel with step q (every sample difference a multiple of q): the floor is at
  least ``q / sqrt(12)``, the quantisation error of a signal that moves by more than q between
  samples (Widrow & Kollar, *Quantization Noise*, Cambridge University Press, 2008), which is what
  a quantisation-only channel leaves in the residual while its differences are mostly 0; with
  noise, the differences give ``sqrt(s^2 + q^2 / 12)`` (Sheppard's correction);
* a channel whose values repeat in runs without being quantised (a slower stream held) is
  estimated from the first sample of each run;
* a *stuck* stretch (exactly repeated values) is left out of its channel's floor, and reported; a
  constant channel has floor 0 and no ratio (no division by zero).

**Ratio.** ``rms(z - y) / floor`` over the cost's samples, outliers excluded: about 1 (+- a few %)
for a fit whose residual is the measurement noise. It is not judged alone: real recorded data of
good quality leave residuals 2-20 x their white-noise floor, coloured (a filtered INS attitude, baro
lag and static-source error, IMU scale and misalignment, vertical air motion). A kinematic channel
(Euler angles, airspeed, altitudes; exact kinematics) above its floor is a *misfit*: a FAILURE (a
wrong minimum or a data fault) only where it is gross, beyond what a working INS and air-data system
leave (:class:`DiagnosticOptions`, ``misfit_*``), a NOTE otherwise. A flow channel above its floor
has a model-structure error, judged by its effect on the channel's Table 2 accuracy (below its
usable alpha range for a ``low_alpha_only`` channel: :func:`estimator.accuracy.alpha_limit`): a
NOTE where the channel meets it, a WARNING where not. The local RMS over 2 s windows says when.

**Outliers.** The residual minus the median of its six neighbours (a high-pass that a spike of one
or two samples, e.g. one sample interpolated onto two, passes whole, and that the sample itself
does not pull to 0), scaled by its own MAD and by the MAD of its neighbourhood (blocks of 40
samples: noise that grows along a maneuver is no outlier). Beyond 7 robust deviations: for
Gaussian noise 2.6e-12 false outliers per sample, one in ~2e5 problems of 100 maneuvers x 12
channels x 1600 samples. They are a WARNING where they matter (a tenth of the channel's residual in
the maneuver, or beyond its desired accuracy, or what alone makes it miss Table 2), a NOTE otherwise.

**Whiteness.** The lag-1 autocorrelation ``rho1`` of the residual; ``(1 + rho1) / (1 - rho1)`` is
the factor by which an AR(1) residual inflates the variance of a mean (the bandwidth factor of the
table), so the Cramér-Rao deviations are optimistic by its root (Morelli & Klein, *Aircraft System
Identification*, 2nd ed., 2016, on coloured residuals).

**Slope and units.** The least-squares slope of z on y about their means (y is the noise-free model
output, so the slope is not attenuated by the measurement noise), its standard error from the
regression residual with ``n (1 - r1) / (1 + r1)`` effective samples (Bretherton et al., "The
effective number of independent observations", J. Climate 12, 1999). A model that cannot rescale
its channel leaves a slope far from 1: within 7 % of a unit conversion (57.2958 deg/rad, 3.2808
ft/m, 1.9438 kt/(m/s), 3.6 km/h/(m/s), 9.80665 m/s^2/g, or their inverses) it names it
(*unit_error*), otherwise, if the channel misfits, it is a *scale_error*. A flow channel is also
regressed on the kinematic angle of the reconstructed states at the reference point
(``atan2(w, u)``, ``asin(v / V)``): a model with a free scale or table absorbs a unit error in y,
not in the kinematics; a flow channel is only tested against factors of 10 or more (deg/rad), as
a fault elsewhere drags its shared tables and the states by tens of per cent. A flow channel whose
floor is 57.3 x (+- 35 %) the median floor of the same channel over the maneuvers is in other
units in that maneuver. An absolute quantity (h, tas) whose mean level z / y is within 5 % of a
factor names it too.

**Stuck and dead channels, dead inputs.** The longest run of exactly repeated measurement values: a
run of at least 2 s and 10 samples during which the model output moves by more than 5 floors (or
quantisation steps) is a stuck channel, a dead one if the value is 0. An IMU axis constant for
2 s while the measured attitude changes by more than 1 deg is a dead input.

**Accelerometer sign and units.** In flight the body-z specific force is ``-n g cos(theta)
cos(phi)``, negative (n the load factor): a maneuver mean above +0.5 g is a flipped axis; one
between -0.25 g and -0.03 g is a specific force recorded in g but declared as m/s^2.

**Turbulence.** Unmodelled air motion moves every air-relative channel of a maneuver alike:
flow-angle (and airspeed) residuals far above their floors, coloured, zero-mean, correlated between
sensors and of similar size, while the inertial channels (Euler angles, altitudes) fit. The
output-error method models no process noise (Maine & Iliff, *Application of parameter estimation
to aircraft stability and control: the output-error approach*, NASA RP-1168, 1986): such a
maneuver biases the estimates and is reported once, as turbulence, instead of channel by channel.

**Order and attribution.** Findings are sorted by severity, then data faults (dead inputs,
accelerometer sign, dead and stuck channels, unit errors) before their consequences (misfits,
scale errors, turbulence, structure errors, outliers, colour); a consequence in a maneuver (or
channel) with a data fault says so: a fault drags the whole fit through the shared parameters.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from estimator.accuracy import alpha_limit, three_sigma
from estimator.options import DiagnosticOptions
from estimator.verdict import Finding, Severity

#: MAD of a standard normal (its 0.75 quantile).
_MAD_NORMAL = 0.6744897501960817
_DEG = 180.0 / math.pi

#: Unit conversions a slope is compared with: (factor, what a slope near it means).
#: A measurement recorded in unit U but declared as SI is ``factor * true``.
UNIT_FACTORS: tuple[tuple[float, str, str], ...] = (
    (_DEG, "recorded in degrees but declared as radians (x 57.2958)", "rad"),
    (1.0 / _DEG, "recorded in radians but declared as degrees (x 1/57.2958)", "rad"),
    (1.0 / 0.3048, "recorded in feet but declared as metres (x 3.2808)", "m"),
    (0.3048, "recorded in metres but declared as feet (x 0.3048)", "m"),
    (3600.0 / 1852.0, "recorded in knots but declared as m/s (x 1.9438)", "m/s"),
    (1852.0 / 3600.0, "recorded in m/s but declared as knots (x 0.5144)", "m/s"),
    (3.6, "recorded in km/h but declared as m/s (x 3.6)", "m/s"),
    (1.0 / 3.6, "recorded in m/s but declared as km/h (x 1/3.6)", "m/s"),
    (9.80665, "recorded in m/s^2 but declared as g (x 9.80665)", "m/s^2"),
    (1.0 / 9.80665, "recorded in g but declared as m/s^2 (x 1/9.80665)", "m/s^2"),
)

#: Channel names (before any "_") of air-data channels: relative to the air, like the flow angles.
AIR_DATA_NAMES = frozenset({"tas", "mach", "cas", "eas", "ias", "qc", "qbar"})
_LATTICE_SAMPLES = 512
#: A 12-comparator sorting network for six values (checked on all 0-1 inputs: the 0-1 principle).
_SORT6 = ((1, 2), (4, 5), (0, 2), (3, 5), (0, 1), (3, 4), (1, 4), (0, 3), (2, 5), (1, 3), (2, 4), (2, 3))
_FLOW_PREFIX = {"alpha": "alpha", "beta": "beta", "flank": "flank"}
_IMU_AXES = ("ax_imu_mps2", "ay_imu_mps2", "az_imu_mps2", "p_rps", "q_rps", "r_rps")

#: Order of the findings within a severity: causes before their consequences.
_CODE_ORDER = {c: i for i, c in enumerate((
    "dead_input", "accel_sign", "dead_channel", "stuck_channel", "unit_error", "misfit", "scale_error",
    "outlier", "turbulence", "noise_floor", "coloured"))}
#: Codes that name a fault of the data itself (the other findings of a maneuver may follow from them).
_CAUSES = frozenset({"dead_input", "accel_sign", "dead_channel", "stuck_channel", "unit_error"})


@dataclass(frozen=True)
class ChannelFit:
    """One channel of one maneuver at the estimate.

    Attributes
    ----------
    maneuver : maneuver id.
    channel : channel name (``"alpha_zl"``, ``"theta"``, ``"tas"``).
    flow : True for a flow-angle channel measured at a sensor (vane, probe: ``alpha_*``, ``beta_*``),
        whose calibration model may be imperfect; False for a kinematic or air-data channel (phi,
        theta, psi, tas, h, h_dgps) whose model is exact kinematics.
    t_s : (n,) times of the samples in the cost, s.
    z : (n,) measurement at those samples, SI.
    y : (n,) model output at the estimate, SI.
    measured_t_s : (N,) times of every finite sample of the measurement, s (N >= n).
    measured : (N,) those samples, SI (for the noise floor).
    unit : SI unit.
    display_scale, display_unit : for messages (57.29578, "deg").
    parameters : free parameter keys of this channel's model in this maneuver (named in findings).
    air_relative : the channel measures the motion relative to the air (flow angles, true airspeed):
        gusts move it, which the output-error model cannot follow; default: flow channels and the
        air-data names of :data:`AIR_DATA_NAMES` (``tas``, ``mach``, ...).
    measures : what a flow channel measures, ``"alpha"``, ``"beta"`` or ``"flank"`` (for the slope
        against the kinematic angle); default: from the channel name's prefix, "" if none.
    desired_3sigma : the channel's desired 3-sigma accuracy (the model set's ``[requirements]``),
        SI (rad), or None: a residual above the floor is judged against it (its effect on the
        calibration), a spike by its share of the residual.
    low_alpha_only : the channel's accuracy is judged only up to its usable angle of attack (the
        model set's ``low_alpha_only``, paper Fig. 7: the nose probe's sideslip): a residual above
        its floor beyond that range is a NOTE where the channel meets its accuracy within it.
    """

    maneuver: str
    channel: str
    flow: bool
    t_s: np.ndarray
    z: np.ndarray
    y: np.ndarray
    measured_t_s: np.ndarray
    measured: np.ndarray
    unit: str = "rad"
    display_scale: float = 1.0
    display_unit: str = ""
    parameters: tuple[str, ...] = ()
    air_relative: bool | None = None
    measures: str | None = None
    desired_3sigma: float | None = None
    low_alpha_only: bool = False

    def __post_init__(self) -> None:
        for name in ("t_s", "z", "y", "measured_t_s", "measured"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=float).reshape(-1))
        if not (self.t_s.size == self.z.size == self.y.size):
            raise ValueError(f"ChannelFit {self.maneuver}/{self.channel}: t_s, z and y differ in length "
                             f"({self.t_s.size}, {self.z.size}, {self.y.size})")
        if self.measured_t_s.size != self.measured.size:
            raise ValueError(f"ChannelFit {self.maneuver}/{self.channel}: measured_t_s and measured differ "
                             f"in length ({self.measured_t_s.size}, {self.measured.size})")
        if self.measures is None:
            prefix = self.channel.split("_")[0]
            object.__setattr__(self, "measures", _FLOW_PREFIX.get(prefix, "") if self.flow else "")
        if self.air_relative is None:
            object.__setattr__(self, "air_relative",
                               bool(self.flow) or self.channel.split("_")[0].lower() in AIR_DATA_NAMES)
        if not self.display_unit:
            object.__setattr__(self, "display_unit", self.unit)


@dataclass(frozen=True)
class ManeuverInputs:
    """The IMU inputs of one maneuver and the reconstructed states at the estimate.

    Attributes
    ----------
    maneuver : maneuver id.
    t_s : (N,) sample times, s.
    accel_imu_mps2 : (N, 3) measured specific force at the IMU, body axes (x fwd, y right, z down), m/s^2.
    omega_rps : (N, 3) measured body rates p, q, r, rad/s.
    states : (N, 7) reconstructed u, v, w (m/s, body), phi, theta, psi (rad), h (m).
    euler_measured_rad : (N, 3) measured phi, theta, psi where available (NaN elsewhere), rad.
    """

    maneuver: str
    t_s: np.ndarray
    accel_imu_mps2: np.ndarray
    omega_rps: np.ndarray
    states: np.ndarray
    euler_measured_rad: np.ndarray | None = None


@dataclass(frozen=True)
class Diagnosis:
    """What the diagnostics found.

    Attributes
    ----------
    findings : most severe first, causes before their consequences.
    table : one row per (maneuver, channel) (:func:`diagnose` lists the columns).
    outliers : (maneuver, channel) -> (k,) times of the outlier samples, s.
    usable_alpha_deg : ``low_alpha_only`` channel -> its usable angle of attack, deg (where found).
    """

    findings: tuple[Finding, ...]
    table: pd.DataFrame
    outliers: Mapping[tuple[str, str], np.ndarray] = field(default_factory=dict)
    usable_alpha_deg: Mapping[str, float] = field(default_factory=dict)

    def to_pandas(self) -> pd.DataFrame:
        """The fit-quality table."""
        return self.table


# ================================================================================================
# vectorised kernels on padded (R, N) arrays (NaN = no sample)
# ================================================================================================


def _pad(arrays: Sequence[np.ndarray], width: int | None = None) -> np.ndarray:
    """(R, width) rows padded with NaN (width: the longest row, at least 1)."""
    n = max((a.shape[0] for a in arrays), default=0) if width is None else width
    out = np.full((len(arrays), max(n, 1)), np.nan)
    for i, a in enumerate(arrays):
        out[i, :a.shape[0]] = a
    return out


def _row_median(A: np.ndarray) -> np.ndarray:
    """Median of each row ignoring NaN (NaN for an empty row); faster than np.nanmedian."""
    if A.shape[1] == 0:
        return np.full(A.shape[0], np.nan)
    cnt = np.sum(~np.isnan(A), axis=1)
    S = np.sort(np.where(np.isnan(A), np.inf, A), axis=1)
    lo = np.clip((cnt - 1) // 2, 0, A.shape[1] - 1)
    hi = np.clip(cnt // 2, 0, A.shape[1] - 1)
    rows = np.arange(A.shape[0])
    med = 0.5 * (S[rows, lo] + S[rows, hi])
    return np.where(cnt > 0, med, np.nan)


def _kappa(c: float) -> float:
    """Variance of a standard normal truncated at +-c."""
    phi = math.exp(-0.5 * c * c) / math.sqrt(2 * math.pi)
    return 1.0 - 2.0 * c * phi / math.erf(c / math.sqrt(2))


def _spacing_floor(X: np.ndarray, cg: np.ndarray | None, L: int, opt: DiagnosticOptions) -> np.ndarray:
    """Robust k-th difference estimate of the noise of each row at sample spacing ``L``: the clipped
    variance of the differences per block of ``floor_block`` of them, averaged over the blocks (the
    mean variance of a noise that changes along the record), or over the whole row if it has no
    full block. NaN if the row is too short."""
    R, N = X.shape
    k = opt.floor_order
    span = k * L
    if N <= span:
        return np.full(R, np.nan)
    ck = math.comb(2 * k, k) * _kappa(opt.floor_clip)
    D = X
    for _ in range(k):
        D = D[:, L:] - D[:, :-L]
    if cg is not None:  # no difference across a time gap
        D = np.where(cg[:, span:] - cg[:, :-span] == 0, D, np.nan)
    A = np.abs(D)
    B = opt.floor_block or A.shape[1]
    nb = -(-A.shape[1] // B)
    Ab = np.full((R, nb * B), np.nan)
    Ab[:, :A.shape[1]] = A
    Ab = Ab.reshape(R * nb, B)
    s0 = _row_median(Ab) / _MAD_NORMAL
    with np.errstate(invalid="ignore"):
        keep = Ab <= opt.floor_clip * s0[:, None]
    cnt = keep.sum(axis=1).reshape(R, nb)
    num = np.where(keep, Ab * Ab, 0.0).sum(axis=1).reshape(R, nb)
    full = cnt >= (max(B // 2, 1) if opt.floor_block else 1)
    tot = np.where(full, num, 0.0).sum(axis=1)
    ntot = np.where(full, cnt, 0).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        est = np.where(ntot > 0, np.sqrt(tot / np.maximum(ntot, 1) / ck), np.nan)
    short = ~(ntot > 0) & (np.sum(~np.isnan(A), axis=1) > 0)
    if opt.floor_block and short.any():  # no block half full: the whole row at once
        est[short] = _spacing_floor(X[short], None if cg is None else cg[short], L,
                                    replace(opt, floor_block=0))
    return est


def _difference_floor(T: np.ndarray, X: np.ndarray, opt: DiagnosticOptions) -> np.ndarray:
    """Noise floor of each row (module docstring): the k-th difference estimate at spacing 1, 2, ...
    until it stops growing (white noise: at once; noise linearly interpolated from a slower stream:
    once the spacing exceeds the interpolation's reach), NaN if too short."""
    R, N = X.shape
    dT = np.diff(T, axis=1)
    cg = None
    if N > 1:
        # a gap: a step over gap_factor times the median one (padding steps are NaN: never a gap)
        med_dt = _row_median(dT)
        with np.errstate(invalid="ignore"):
            gap = dT > opt.gap_factor * med_dt[:, None]
        if gap.any():
            cg = np.concatenate([np.zeros((R, 1)), np.cumsum(gap, axis=1)], axis=1)
    s1 = _spacing_floor(X, cg, 1, opt)
    if opt.floor_max_spacing < 2:
        return s1
    s2 = _spacing_floor(X, cg, 2, opt)
    floor = np.fmax(s1, s2)
    # a stream interpolated from under ~30 Hz: the spacing-2 estimate jumps, and further spacings
    # reach a plateau within a few; signal leaking into the differences (turbulence, a sharp
    # maneuver) keeps growing them instead: then the spacing-1 and 2 estimate stands
    with np.errstate(invalid="ignore"):
        rows = np.flatnonzero(s2 > (1.0 + opt.floor_interp_jump) * s1)
    best, prev = floor[rows], s2[rows]
    settled = np.zeros(rows.size, dtype=bool)
    for L in range(3, opt.floor_max_spacing + 1):
        todo = np.flatnonzero(~settled)
        if not todo.size:
            break
        r = rows[todo]
        cur = _spacing_floor(X[r], None if cg is None else cg[r], L, opt)
        best[todo] = np.fmax(best[todo], cur)
        with np.errstate(invalid="ignore"):
            settled[todo] = ~(cur > (1.0 + opt.floor_plateau) * prev[todo])
        prev[todo] = cur
    floor[rows[settled]] = best[settled]
    return floor


def _quantum(X: np.ndarray, opt: DiagnosticOptions) -> np.ndarray:
    """Quantisation step of each row (0 if its sample differences are not multiples of one step)."""
    if X.shape[1] < 2:
        return np.zeros(X.shape[0])
    A = np.abs(np.diff(X, axis=1))
    tol = 1e-9 * np.max(np.where(np.isnan(X), 0.0, np.abs(X)), axis=1) + 1e-300
    with np.errstate(invalid="ignore"):
        nz = A > tol[:, None]
    q = np.min(np.where(nz, A, np.inf), axis=1)
    qq = np.where(np.isfinite(q), q, 1.0)
    # the lattice test on the first samples is enough (a quantiser does not change along a record)
    A, nz = A[:, :_LATTICE_SAMPLES], nz[:, :_LATTICE_SAMPLES]
    with np.errstate(invalid="ignore"):
        r = A / qq[:, None]
        on = nz & (np.abs(r - np.rint(r)) <= opt.lattice_tol)
    n_nz = nz.sum(axis=1)
    ok = (n_nz >= 10) & (on.sum(axis=1) >= opt.lattice_fraction * n_nz) & np.isfinite(q)
    return np.where(ok, q, 0.0)


def _longest_runs(X: np.ndarray, T: np.ndarray):
    """Longest run of exactly repeated values per row: (samples, start index, end index, t0, t1)."""
    R, N = X.shape
    if N < 2:
        z = np.zeros(R, dtype=np.intp)
        return z + 1, z, z, np.full(R, np.nan), np.full(R, np.nan)
    eq = X[:, 1:] == X[:, :-1]
    idx = np.broadcast_to(np.arange(1, N), (R, N - 1))
    last_break = np.maximum.accumulate(np.where(eq, 0, idx), axis=1)
    runlen = idx - last_break  # run length (in pairs) ending at sample idx
    end = np.argmax(runlen, axis=1) + 1
    length = runlen[np.arange(R), end - 1] + 1
    start = end - length + 1
    rows = np.arange(R)
    return length, start, end, T[rows, start], T[rows, end]


def _nanmean_rows(A: np.ndarray) -> np.ndarray:
    """(R, 1) mean of each row ignoring NaN (0 for an empty row)."""
    ok = ~np.isnan(A)
    return (np.where(ok, A, 0.0).sum(axis=1) / np.maximum(ok.sum(axis=1), 1))[:, None]


def _lag1(C: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Lag-1 autocorrelation of each row of ``C`` about its mean over ``mask`` (pairs need both)."""
    n = np.maximum(mask.sum(axis=1), 1)
    C = np.where(mask, C, 0.0)
    C = np.where(mask, C - (C.sum(axis=1) / n)[:, None], 0.0)
    num = np.einsum("ij,ij->i", C[:, 1:], C[:, :-1])
    den = np.einsum("ij,ij->i", C, C)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / den, np.nan)


def _neighbour_median(E: np.ndarray) -> np.ndarray:
    """Median of the six neighbours (i-3 .. i+3) of each sample, the sample itself left out (the mean
    of the middle two; edges: nearest sample repeated). With the sample left out, the difference to it
    is not pulled to 0; with six, a two-sample spike next door does not move the median."""
    n = E.shape[1]
    P = np.concatenate([np.repeat(E[:, :1], 3, axis=1), E, np.repeat(E[:, -1:], 3, axis=1)], axis=1)
    v = [P[:, i:i + n] for i in (0, 1, 2, 4, 5, 6)]
    for a, b in _SORT6:  # a sorting network: elementwise, much faster than a partition along an axis
        v[a], v[b] = np.minimum(v[a], v[b]), np.maximum(v[a], v[b])
    return 0.5 * (v[2] + v[3])


def _local_scale(D: np.ndarray, B: int) -> np.ndarray:
    """(R, N) robust local scale of each row: the MAD scale (about 0) of blocks of ``B`` samples, the
    largest of a block and its two neighbours (noise that grows along the maneuver is not an outlier)."""
    R, N = D.shape
    nb = -(-N // B)
    P = np.full((R, nb * B), np.nan)
    P[:, :N] = np.abs(D)
    s = (_row_median(P.reshape(R * nb, B)) / _MAD_NORMAL).reshape(R, nb)
    s = np.where(np.isnan(s), 0.0, s)
    left = np.concatenate([s[:, :1], s[:, :-1]], axis=1)
    right = np.concatenate([s[:, 1:], s[:, -1:]], axis=1)
    s = np.maximum(s, np.maximum(left, right))
    return np.repeat(s, B, axis=1)[:, :N]


def _fill_edges(E: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Each row's tail (padding) filled with its last value (for running filters)."""
    last = E[np.arange(E.shape[0]), np.maximum(n - 1, 0)]
    cols = np.arange(E.shape[1])[None, :]
    return np.where(cols >= n[:, None], last[:, None], E)


def _slope(Y: np.ndarray, Z: np.ndarray, mask: np.ndarray):
    """Least-squares slope of Z on Y about their means per row (samples in ``mask``), its standard
    error (effective samples from the regression residual's lag-1 autocorrelation) and the std of Y."""
    n = mask.sum(axis=1)
    nn = np.maximum(n, 1)
    Yv = np.where(mask, Y, 0.0)
    Zv = np.where(mask, Z, 0.0)
    yc = np.where(mask, Yv - (Yv.sum(axis=1) / nn)[:, None], 0.0)
    zc = np.where(mask, Zv - (Zv.sum(axis=1) / nn)[:, None], 0.0)
    syy = np.einsum("ij,ij->i", yc, yc)
    with np.errstate(invalid="ignore", divide="ignore"):
        b = np.where(syy > 0, np.einsum("ij,ij->i", yc, zc) / syy, np.nan)
        r = zc - np.nan_to_num(b)[:, None] * yc
        r1 = np.clip(np.nan_to_num(_lag1(r, mask)), 0.0, 0.999)
        neff = np.maximum(n * (1 - r1) / (1 + r1), 2.0)
        sr = np.sqrt(np.einsum("ij,ij->i", r, r) / np.maximum(n - 2, 1))
        sy = np.sqrt(syy / nn)
        se = sr / sy / np.sqrt(neff)
    return b, se, sy


def _unit_match(value: float, tol: float, unit: str | None = None) -> tuple[float, str, str] | None:
    """The unit factor closest to |value| (log distance) if within ``tol``; None otherwise. Only the
    conversions of the channel's own quantity (its SI ``unit``: an altitude is never in knots)."""
    if not np.isfinite(value) or value == 0:
        return None
    a = abs(value)
    factors = [f for f in UNIT_FACTORS if unit is None or f[2] == unit]
    if not factors:
        return None  # a quantity without a common unit confusion (a pressure, a Mach number)
    best = min(factors, key=lambda f: abs(math.log(a / f[0])))
    return best if abs(a / best[0] - 1.0) <= tol else None


# ================================================================================================
# public helpers (each detector on plain arrays)
# ================================================================================================


def noise_floor(t_s: np.ndarray, x: np.ndarray, options: DiagnosticOptions | None = None
                ) -> tuple[float, float]:
    """Noise floor of one measurement from its own samples (module docstring).

    Parameters
    ----------
    t_s : (N,) sample times, s (an own-rate channel's own times; gaps are respected).
    x : (N,) samples, any unit (NaN samples are dropped).
    options : thresholds.

    Returns
    -------
    (floor, quantum) in the unit of ``x``: the noise standard deviation (0 for a constant channel,
    NaN if too short) and the quantisation step (0 if not quantised).
    """
    opt = options or DiagnosticOptions()
    t_s = np.asarray(t_s, dtype=float)
    x = np.asarray(x, dtype=float)
    ok = np.isfinite(x) & np.isfinite(t_s)
    floors, quanta = _floors([t_s[ok]], [x[ok]], opt)
    return float(floors[0]), float(quanta[0])


def _floors(ts: Sequence[np.ndarray], xs: Sequence[np.ndarray], opt: DiagnosticOptions,
            exclude: Sequence[tuple[int, int] | None] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Floors and quantisation steps of many measurements (finite samples, own times);
    ``exclude[i] = (start, end)``: a stuck run of sample indices left out but for its first sample
    (the time gap it leaves is not differenced across)."""
    ts, xs = list(ts), list(xs)
    for i, ex in enumerate(exclude or ()):
        if ex is not None:
            ts[i] = np.concatenate([ts[i][:ex[0] + 1], ts[i][ex[1] + 1:]])
            xs[i] = np.concatenate([xs[i][:ex[0] + 1], xs[i][ex[1] + 1:]])
    X = _pad(xs)
    q = _quantum(X, opt)
    # a slower stream held (not quantised, mostly repeats): the first sample of each run
    rep = (X[:, 1:] == X[:, :-1]).sum(axis=1)
    pairs = np.array([max(x.size - 1, 1) for x in xs])
    for i in np.flatnonzero((q == 0) & (rep > opt.hold_fraction * pairs) & (rep < pairs)):
        first = np.concatenate([[True], xs[i][1:] != xs[i][:-1]])
        ts[i], xs[i] = ts[i][first], xs[i][first]
        X[i] = np.nan
        X[i, :first.sum()] = xs[i]
    sigma = _difference_floor(_pad(ts, X.shape[1]), X, opt)
    return np.fmax(sigma, q / math.sqrt(12.0)), q


# ================================================================================================
# the diagnosis
# ================================================================================================


def _common_correlation(fits: Sequence[ChannelFit], keep: Sequence[np.ndarray], stuck: np.ndarray
                        ) -> tuple[np.ndarray, dict[int, list[tuple[int, float]]]]:
    """Correlation of the flow-channel residuals within each maneuver: each row's largest
    |correlation| with another flow channel's (NaN: none) and, by row, every partner's row and
    correlation."""
    common = np.full(len(fits), np.nan)
    flow_rows: dict[str, list[int]] = {}
    for i, f in enumerate(fits):
        if f.flow and not stuck[i]:
            flow_rows.setdefault(f.maneuver, []).append(i)
    partners: dict[int, list[tuple[int, float]]] = {}
    for rows in flow_rows.values():
        if len(rows) < 2:
            continue
        t_common = fits[rows[0]].t_s
        for i in rows[1:]:
            t_common = np.intersect1d(t_common, fits[i].t_s, assume_unique=True)
        if t_common.size < 10:
            continue
        M = np.empty((len(rows), t_common.size))
        for j, i in enumerate(rows):
            pos = np.searchsorted(fits[i].t_s, t_common)
            M[j] = np.where(keep[i], fits[i].z - fits[i].y, np.nan)[pos]
        M = M - _nanmean_rows(M)
        M = np.where(np.isnan(M), 0.0, M)
        norm = np.sqrt(np.sum(M * M, axis=1))
        with np.errstate(invalid="ignore", divide="ignore"):
            C = (M @ M.T) / np.outer(norm, norm)
        np.fill_diagonal(C, np.nan)
        for j, i in enumerate(rows):
            common[i] = np.nanmax(np.abs(C[j])) if np.any(np.isfinite(C[j])) else np.nan
            partners[i] = [(rows[jj], float(C[j, jj])) for jj in range(len(rows)) if jj != j]
    return common, partners


def _fit_table(fits: Sequence[ChannelFit], cols: Mapping[str, np.ndarray], bandwidth_factor: np.ndarray,
               common: np.ndarray, scale: np.ndarray) -> pd.DataFrame:
    """The fit-quality table (:func:`diagnose`) from the per-row statistics."""
    stuck, mean, rms, floor = cols["stuck"], cols["mean"], cols["rms"], cols["floor"]
    return pd.DataFrame({
        "maneuver": [f.maneuver for f in fits], "channel": [f.channel for f in fits],
        "flow": [bool(f.flow) for f in fits], "unit": [f.unit for f in fits], "n": cols["n"],
        "n_measured": cols["n_meas"], "mean": mean, "rms": rms, "rms_all": cols["rms_all"],
        "noise_floor": floor, "quantum": cols["quantum"], "ratio": cols["ratio"], "rho1": cols["rho1"],
        "bandwidth_factor": bandwidth_factor, "n_outliers": cols["n_out"],
        "slope": cols["slope"], "slope_se": cols["slope_se"], "slope_kinematic": cols["slope_k"],
        "slope_kinematic_se": cols["slope_k_se"], "common_corr": common, "stuck": stuck,
        "stuck_t0_s": np.where(stuck, cols["run_t0"], np.nan),
        "stuck_t1_s": np.where(stuck, cols["run_t1"], np.nan),
        "stuck_value": cols["stuck_value"], "display_unit": [f.display_unit for f in fits],
        "mean_display": mean * scale, "rms_display": rms * scale, "noise_floor_display": floor * scale,
    }, columns=_COLUMNS)


def _row_findings(st: _Stats, out: Sequence[np.ndarray], done: np.ndarray,
                  accuracy: Mapping[str, _Accuracy], opt: DiagnosticOptions
                  ) -> tuple[list[Finding], dict[tuple[str, str], np.ndarray]]:
    """Each row's outlier finding and, for a row no finding explains yet (``done`` false), its
    residual's: no floor, misfit, flow residual or coloured. Also the outliers' times (s) by
    (maneuver, channel)."""
    findings: list[Finding] = []
    outliers: dict[tuple[str, str], np.ndarray] = {}
    fits, ratio, rho1, stuck = st.fits, st.ratio, st.rho1, st.stuck
    for i, f in enumerate(fits):
        if st.n_out[i] and not stuck[i] and not st.many[i]:
            t = f.t_s[out[i]]
            outliers[(f.maneuver, f.channel)] = t
            findings.append(_outlier_finding(st, i, t, opt))
        if done[i]:
            continue
        if not np.isfinite(ratio[i]):
            if not stuck[i]:  # a stuck channel has its own finding; this one simply has too few samples
                findings.append(Finding(
                    "no_floor", Severity.NOTE,
                    f"{_where(f)}: its noise floor could not be estimated ({f.z.size} samples in the "
                    "cost): its residual is not judged", channel=f.channel, maneuver=f.maneuver))
            continue
        if not f.flow and ratio[i] > opt.misfit_warn_ratio:
            sev = Severity.FAILURE if _gross(st, i, opt) else Severity.NOTE
            findings.append(_ratio_finding(st, i, opt, "misfit", sev))
        elif f.flow and ratio[i] > opt.noise_floor_ratio:
            findings.append(_flow_residual_finding(st, i, opt, accuracy.get(f.channel)))
        elif ratio[i] > opt.coloured_min_ratio and rho1[i] > opt.coloured_rho1:
            findings.append(_coloured_finding(st, i, Severity.NOTE))
    return findings, outliers


def diagnose(channels: Sequence[ChannelFit], inputs: Sequence[ManeuverInputs] = (),
             options: DiagnosticOptions | None = None) -> Diagnosis:
    """Judge a finished fit against the data: findings and the fit-quality table.

    Parameters
    ----------
    channels : every channel of every maneuver at the estimate (SI).
    inputs : each maneuver's IMU inputs and reconstructed states (for the dead-input and
        accelerometer-sign checks, and the flow channels' slope on the kinematic angle).
    options : thresholds (:class:`DiagnosticOptions`).

    Returns
    -------
    Diagnosis. Its table has one row per (maneuver, channel): ``maneuver, channel, flow, unit,
    n`` (cost samples), ``n_measured``, ``mean, rms`` (SI; rms without the outliers), ``rms_all``
    (with them), ``noise_floor, quantum, ratio`` (rms / floor), ``rho1`` (lag-1 autocorrelation),
    ``bandwidth_factor`` ((1 + rho1) / (1 - rho1)), ``n_outliers``, ``slope, slope_se`` (z on y),
    ``slope_kinematic, slope_kinematic_se`` (flow channels: z on the kinematic angle),
    ``common_corr`` (largest |correlation| with another flow channel's residual in the maneuver),
    ``stuck, stuck_t0_s, stuck_t1_s, stuck_value``, ``display_unit`` and ``mean_display,
    rms_display, noise_floor_display``.
    """
    opt = options or DiagnosticOptions()
    fits = list(channels)
    by_man_inputs = {m.maneuver: m for m in inputs}
    R = len(fits)
    findings: list[Finding] = []
    if R == 0:
        findings += _input_findings(inputs, opt)
        return Diagnosis(tuple(_ordered(findings)), pd.DataFrame(columns=_COLUMNS), {})

    # per-row statistics, a block of rows at a time (the working set stays in the cache)
    parts = [_row_stats(fits[i:i + _CHUNK], by_man_inputs, opt) for i in range(0, R, _CHUNK)]
    cols = {k: np.concatenate([p[k] for p in parts]) for k in parts[0] if k not in ("keep", "out")}
    keep = [k for p in parts for k in p["keep"]]
    out = [o for p in parts for o in p["out"]]
    floor, ratio, rho1, stuck = cols["floor"], cols["ratio"], cols["rho1"], cols["stuck"]
    slope, slope_se, slope_k = cols["slope"], cols["slope_se"], cols["slope_k"]
    with np.errstate(invalid="ignore", divide="ignore"):
        bw = (1 + rho1) / (1 - rho1)
    common, partners = _common_correlation(fits, keep, stuck)
    scale = np.array([f.display_scale for f in fits])
    table = _fit_table(fits, cols, bw, common, scale)

    # ---- findings --------------------------------------------------------------------------------
    st = _Stats(fits=fits, floor=floor, quantum=cols["quantum"], rms=cols["rms"], mean=cols["mean"],
                ratio=ratio, rho1=rho1, slope=slope, slope_se=slope_se, y_sd=cols["y_sd"], slope_k=slope_k,
                slope_k_se=cols["slope_k_se"], ref_sd=cols["ref_sd"],
                floor_jump=_floor_jump(fits, floor, stuck), stuck=stuck, stuck_value=cols["stuck_value"],
                run_t0=cols["run_t0"], run_t1=cols["run_t1"], n_out=cols["n_out"], many=cols["many"],
                keep=keep, common=common, partners=partners, scale=scale,
                slope_median=_channel_slope(fits, slope, slope_se, opt))
    findings += _input_findings(inputs, opt)
    accuracy = _flow_accuracy(fits, keep, by_man_inputs, opt)
    done = np.zeros(R, dtype=bool)  # a row whose residual is explained by a finding on it
    for i in np.flatnonzero(stuck):
        findings.append(_stuck_finding(st, i))
        done[i] = True
    flows = np.array([bool(f.flow) for f in fits])
    with np.errstate(invalid="ignore", divide="ignore"):
        suspect = ((ratio > np.where(flows, opt.noise_floor_ratio, opt.misfit_warn_ratio))
                   | (np.abs(np.log(np.abs(slope_k))) > math.log(1.5)))
    for i in np.flatnonzero(suspect & ~done):
        fnd = _unit_finding(st, i, opt)
        if fnd is not None:
            findings.append(fnd)
            done[i] = True
    turb = _turbulence(st, done, opt)
    findings = _beside_turbulence(findings, turb[0])
    findings += turb[0]
    done |= turb[1]
    per_row, outliers = _row_findings(st, out, done, accuracy, opt)
    findings = _outliers_beyond_accuracy(findings + per_row, fits, keep)
    usable = {ch: a.limit_deg for ch, a in accuracy.items() if a.limit_deg is not None}
    return Diagnosis(tuple(_ordered(_attribute(findings))), table, outliers, usable)


def _outliers_beyond_accuracy(findings: list[Finding], fits: list[ChannelFit], keep: list[np.ndarray]
                              ) -> list[Finding]:
    """Outlier findings of a flow channel that misses its desired accuracy only because of them
    say so: the 3 sigma of measurement minus model over the estimation's maneuvers (as Table 2
    judges it, every sample counted) against the same without the outlier samples. One 25-deg
    vane sample in 3600 makes it 1.27 deg (0.14 deg without it) against a desired 0.5 deg; the
    robust option (``--robust``) excludes it. Other findings are returned as they are."""
    rows: dict[str, list[int]] = {}
    for i, f in enumerate(fits):
        if f.flow and f.desired_3sigma is not None:
            rows.setdefault(f.channel, []).append(i)
    said: dict[str, tuple[str, str]] = {}
    for ch, mine in rows.items():
        valid = [np.isfinite(fits[i].z - fits[i].y) for i in mine]
        cut = [v & ~k for v, k in zip(valid, (keep[i] for i in mine), strict=True)]
        if not any(c.any() for c in cut):
            continue
        e = [(fits[i].z - fits[i].y) for i in mine]
        with_ = three_sigma(np.concatenate([x[v] for x, v in zip(e, valid, strict=True)]))
        without = three_sigma(np.concatenate([x[v & ~c] for x, v, c in zip(e, valid, cut, strict=True)]))
        f0 = fits[mine[0]]
        des = float(f0.desired_3sigma)
        if not (with_ > des >= without):
            continue
        k, unit, n = f0.display_scale, f0.display_unit, int(sum(c.sum() for c in cut))
        what = "this sample alone makes" if n == 1 else f"these {n} samples alone make"
        said[ch] = (
            f"; {what} {ch} miss its desired accuracy: 3 sigma of measurement - model over the "
            f"estimation's {len(mine)} maneuver(s) (as Table 2 judges it) {with_ * k:.3g} {unit} with "
            f"{'it' if n == 1 else 'them'}, {without * k:.3g} {unit} without, against {des * k:.3g} {unit}",
            f"{'it is' if n == 1 else 'they are'} what makes {ch} miss its Table 2 accuracy: rerun with the "
            "robust option (fpr calibrate --robust), which excludes outliers; check the recording at those "
            "times")
    if not said:
        return findings
    return [replace(g, message=g.message + said[g.channel][0], advice=said[g.channel][1],
                    severity=max(g.severity, Severity.WARNING))
            if g.code == "outlier" and g.channel in said else g for g in findings]


def _alpha_cg_rad(f: ChannelFit, m: ManeuverInputs) -> np.ndarray:
    """The reconstructed angle of attack at the reference point at the channel's samples, rad."""
    X = np.asarray(m.states, dtype=float)
    return np.interp(f.t_s, np.asarray(m.t_s, dtype=float), np.arctan2(X[:, 2], X[:, 0]))


@dataclass(frozen=True)
class _Accuracy:
    """A flow channel's accuracy over the estimation, as Table 2 judges it: 3 sigma of its residual
    pooled over the maneuvers (below the usable alpha for a ``low_alpha_only`` channel), SI."""

    pooled: float
    limit_deg: float | None
    below: dict[int, float]  # row -> that maneuver's 3 sigma below the limit, SI
    alpha_from_deg: dict[int, float]  # row -> the lowest alpha at or above the limit, deg


def _flow_accuracy(fits: list[ChannelFit], keep: list[np.ndarray], by_man_inputs: Mapping,
                   opt: DiagnosticOptions) -> dict[str, _Accuracy]:
    """Per flow channel with a stated accuracy: its 3 sigma pooled over the estimation's maneuvers,
    and for a ``low_alpha_only`` channel its usable alpha range (paper Fig. 7, as the workflow's
    Table 2 finds it: :func:`estimator.accuracy.alpha_limit`) and each maneuver's 3 sigma below it."""
    out: dict[str, _Accuracy] = {}
    rows: dict[str, list[int]] = {}
    for i, f in enumerate(fits):
        if f.flow and f.desired_3sigma is not None:
            rows.setdefault(f.channel, []).append(i)
    for ch, mine in rows.items():
        e = [(fits[i].z - fits[i].y)[keep[i]] for i in mine]
        pooled = three_sigma(np.concatenate(e)) if e else math.nan
        f0 = fits[mine[0]]
        if not (f0.low_alpha_only and all(fits[i].maneuver in by_man_inputs for i in mine)):
            out[ch] = _Accuracy(pooled, None, {}, {})
            continue
        alpha = {i: _alpha_cg_rad(fits[i], by_man_inputs[fits[i].maneuver]) * _DEG for i in mine}
        a = np.concatenate([alpha[i][keep[i]] for i in mine])
        lim = alpha_limit(a, np.concatenate(e) * _DEG, float(f0.desired_3sigma) * _DEG, opt.alpha_band_deg,
                          opt.min_band_samples)[1]
        # the usable range is lenient only where it holds most of the channel's samples: it is where
        # the channel meets its accuracy by construction, and a channel usable over a sliver of its
        # flight is judged on the whole (the paper's nose probe: up to 12 deg, most of a flight)
        if lim is None or np.mean(a < lim) < 0.5:
            out[ch] = _Accuracy(pooled, None, {}, {})
            continue
        below, start = {}, {}
        for i in mine:
            sel = keep[i] & (alpha[i] < lim)
            below[i] = three_sigma((fits[i].z - fits[i].y)[sel]) if sel.any() else math.nan
            up = keep[i] & (alpha[i] >= lim)
            start[i] = float(np.min(alpha[i][up])) if up.any() else math.nan
        sel = [(fits[i].z - fits[i].y)[keep[i] & (alpha[i] < lim)] for i in mine]
        out[ch] = _Accuracy(three_sigma(np.concatenate(sel)), lim, below, start)
    return out


#: Rows (channels x maneuvers) processed at a time.
_CHUNK = 96


def _row_stats(fits: list, by_man_inputs: Mapping, opt: DiagnosticOptions) -> dict:
    """Floors, stuck runs, residual statistics, outliers and slopes of some rows."""
    R = len(fits)
    # ---- the measurements: stuck runs, floors ----------------------------------------------------
    mt = [f.measured_t_s[np.isfinite(f.measured)] for f in fits]
    mx = [f.measured[np.isfinite(f.measured)] for f in fits]
    n_meas = np.array([x.size for x in mx])
    MX, MT = _pad(mx), _pad(mt)
    run_len, run_start, run_end, run_t0, run_t1 = _longest_runs(MX, MT)
    candidate = (run_len >= opt.stuck_min_samples) & (run_t1 - run_t0 >= opt.stuck_min_s)
    exclude = [(int(run_start[i]), int(run_end[i])) if candidate[i] and run_len[i] < n_meas[i] else None
               for i in range(R)]
    floor, quantum = _floors(mt, mx, opt, exclude)
    # no recorded channel is resolved finer than floor_resolution: below it, "noise" is numerical
    resolution = opt.floor_resolution / np.array([abs(f.display_scale) or 1.0 for f in fits])
    floor = np.fmax(floor, resolution)
    floor = np.where(candidate & (run_len >= n_meas), 0.0, floor)  # constant throughout

    # ---- residuals -------------------------------------------------------------------------------
    n = np.array([f.z.size for f in fits])
    Z, Y = _pad([f.z for f in fits]), _pad([f.y for f in fits])
    valid = ~np.isnan(Z) & ~np.isnan(Y)
    E = np.where(valid, Z - Y, 0.0)
    stuck = np.zeros(R, dtype=bool)
    stuck_value = np.full(R, np.nan)
    for i in np.flatnonzero(candidate):
        f = fits[i]
        yr = f.y[(f.t_s >= run_t0[i]) & (f.t_s <= run_t1[i])]
        if yr.size < 2:
            continue
        base = max(floor[i] if np.isfinite(floor[i]) else 0.0, quantum[i])
        value = float(MX[i, run_start[i]])
        if float(np.ptp(yr)) > max(opt.stuck_model_range * base, 1e-9 * max(1.0, abs(value))):
            stuck[i] = True
            stuck_value[i] = value

    # outliers: the residual less the median of its six neighbours, against its robust scale
    Ef = _fill_edges(E, n)
    D = np.where(valid, Ef - _neighbour_median(Ef), np.nan)
    sD = _row_median(np.abs(D - _row_median(D)[:, None])) / _MAD_NORMAL
    base = np.fmax(sD, resolution)[:, None]
    if opt.outlier_block:
        base = np.fmax(base, _local_scale(D, opt.outlier_block))
    with np.errstate(invalid="ignore"):
        out = valid & (np.abs(D) > opt.outlier_sigma * base) & (base > 0) & ~stuck[:, None]
    n_out = out.sum(axis=1)
    many = n_out > opt.outlier_max_fraction * np.maximum(n, 1)
    keep = valid & ~(out & ~many[:, None])  # a channel with many "outliers" misfits: keep them
    Ek = np.where(keep, E, 0.0)
    cnt = np.maximum(keep.sum(axis=1), 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = Ek.sum(axis=1) / cnt
        rms = np.sqrt(np.einsum("ij,ij->i", Ek, Ek) / cnt)
        rms_all = np.sqrt(np.einsum("ij,ij->i", E, E) / np.maximum(n, 1))
        ratio = np.where(floor > 0, rms / floor, np.nan)
    rho1 = _lag1(E, keep)
    slope, slope_se, y_sd = _slope(Y, Z, keep)

    # slope of a flow channel on the kinematic angle from the reconstructed states
    slope_k = np.full(R, np.nan)
    slope_k_se = np.full(R, np.nan)
    ref_sd = np.full(R, np.nan)
    kin_rows = [i for i, f in enumerate(fits) if f.flow and f.measures and f.maneuver in by_man_inputs]
    if kin_rows:
        REF = np.zeros((len(kin_rows), Z.shape[1]))
        for j, i in enumerate(kin_rows):
            f = fits[i]
            m = by_man_inputs[f.maneuver]
            X = np.asarray(m.states, dtype=float)
            u, v, w = X[:, 0], X[:, 1], X[:, 2]
            if f.measures == "alpha":
                ang = np.arctan2(w, u)
            elif f.measures == "beta":
                ang = np.arcsin(np.clip(v / np.maximum(np.sqrt(u * u + v * v + w * w), 1e-9), -1, 1))
            else:
                ang = np.arctan2(v, u)
            REF[j, :f.t_s.size] = np.interp(f.t_s, np.asarray(m.t_s, dtype=float), ang)
        kr = np.array(kin_rows)
        slope_k[kr], slope_k_se[kr], ref_sd[kr] = _slope(REF, Z[kr], keep[kr])
    return {"n": n, "n_meas": n_meas, "floor": floor, "quantum": quantum, "mean": mean, "rms": rms,
            "rms_all": rms_all, "ratio": ratio, "rho1": rho1, "slope": slope, "slope_se": slope_se,
            "y_sd": y_sd, "slope_k": slope_k, "slope_k_se": slope_k_se, "ref_sd": ref_sd, "stuck": stuck,
            "stuck_value": stuck_value, "run_t0": run_t0, "run_t1": run_t1, "n_out": n_out, "many": many,
            "keep": [keep[i, :n[i]] for i in range(R)], "out": [out[i, :n[i]] for i in range(R)]}


_COLUMNS = ["maneuver", "channel", "flow", "unit", "n", "n_measured", "mean", "rms", "rms_all", "noise_floor",
            "quantum", "ratio", "rho1", "bandwidth_factor", "n_outliers", "slope", "slope_se",
            "slope_kinematic", "slope_kinematic_se", "common_corr", "stuck", "stuck_t0_s", "stuck_t1_s",
            "stuck_value", "display_unit", "mean_display", "rms_display", "noise_floor_display"]


@dataclass
class _Stats:
    fits: list
    floor: np.ndarray
    quantum: np.ndarray
    rms: np.ndarray
    mean: np.ndarray
    ratio: np.ndarray
    rho1: np.ndarray
    slope: np.ndarray
    slope_se: np.ndarray
    y_sd: np.ndarray
    slope_k: np.ndarray
    slope_k_se: np.ndarray
    ref_sd: np.ndarray
    floor_jump: np.ndarray
    stuck: np.ndarray
    stuck_value: np.ndarray
    run_t0: np.ndarray
    run_t1: np.ndarray
    n_out: np.ndarray
    many: np.ndarray
    keep: list
    common: np.ndarray
    partners: dict
    scale: np.ndarray
    slope_median: np.ndarray


def _channel_slope(fits: list, slope: np.ndarray, slope_se: np.ndarray, opt: DiagnosticOptions) -> np.ndarray:
    """Each row's channel's median slope of z on y over the maneuvers where it is assessed (NaN
    where none is): a unit or scale mistake is the channel's, in every maneuver, while one
    maneuver's slope alone can be whatever else its residual holds (at the realism level the
    static-source error in wind-up turns made the airspeed's 1.44-1.9 against 1.0 in the others, an
    INS drift in steady-sideslip segments the pitch's and DGPS height's 0.53-1.37)."""
    ok = np.isfinite(slope) & np.isfinite(slope_se) & (slope_se <= opt.slope_max_rel_se * np.abs(slope))
    out = np.full(len(fits), np.nan)
    by_ch: dict[str, list[int]] = {}
    for i, f in enumerate(fits):
        by_ch.setdefault(f.channel, []).append(i)
    for rows in by_ch.values():
        good = [i for i in rows if ok[i]]
        if good:
            out[rows] = float(np.median(slope[good]))
    return out


def _floor_jump(fits: list, floor: np.ndarray, stuck: np.ndarray) -> np.ndarray:
    """Each row's noise floor over the median floor of the same channel over the maneuvers (NaN with
    fewer than three maneuvers)."""
    out = np.full(len(fits), np.nan)
    by_ch: dict[str, list[int]] = {}
    for i, f in enumerate(fits):
        if not stuck[i] and np.isfinite(floor[i]) and floor[i] > 0:
            by_ch.setdefault(f.channel, []).append(i)
    for rows in by_ch.values():
        if len(rows) >= 3:
            out[rows] = floor[rows] / float(np.median(floor[rows]))
    return out


def _fmt(value: float, f: ChannelFit) -> str:
    """A value in display units, with the unit."""
    v = value * f.display_scale
    return f"{v:.3g} {f.display_unit}".rstrip()


def _where(f: ChannelFit) -> str:
    return f"{f.channel} in maneuver {f.maneuver}"


def _stuck_finding(st: _Stats, i: int) -> Finding:
    f = st.fits[i]
    c = st.stuck_value[i]
    t0, t1 = float(st.run_t0[i]), float(st.run_t1[i])
    inrun = (f.t_s >= t0) & (f.t_s <= t1)
    moved = float(np.ptp(f.y[inrun]))
    whole = t0 <= f.measured_t_s[0] and t1 >= f.measured_t_s[-1]
    span = "over the whole maneuver" if whole else "from"
    dead = c == 0.0
    code = "dead_channel" if dead else "stuck_channel"
    what = "dead: it reads exactly 0" if dead else f"stuck at {_fmt(c, f)}"
    return Finding(
        code, Severity.FAILURE,
        f"{_where(f)} is {what} {span} t = {t0:.2f} to {t1:.2f} s ({t1 - t0:.1f} s) while its model output "
        f"moves by {_fmt(moved, f)} there",
        "check the sensor, its wiring and the recording; exclude the channel (or that time range) from the "
        "estimation, and fix or drop its parameters"
        + (f" ({', '.join(f.parameters[:6])})" if f.parameters else ""),
        channel=f.channel, maneuver=f.maneuver, t_s=(t0, t1), parameters=tuple(f.parameters), value=t1 - t0)


def _unit_finding(st: _Stats, i: int, opt: DiagnosticOptions) -> Finding | None:
    """A unit or scale error of a channel: the slope of z on y, or (flow channels) on the kinematic
    angle, a jump of the noise floor against the same channel's other maneuvers, or (absolute
    quantities) the mean levels; the first that names one."""
    f = st.fits[i]
    misfits = bool(np.isfinite(st.ratio[i]) and st.ratio[i] > (opt.noise_floor_ratio if f.flow
                                                               else opt.misfit_warn_ratio))
    b, se = st.slope[i], st.slope_se[i]
    # a kinematic channel's slope names a unit or scale only where the channel as a whole is off
    # (its median slope over the maneuvers beyond the scale tolerance, signed: an inverted channel's
    # is -1, :func:`_channel_slope`), not one maneuver's anomaly (a fit a unit mistake drags leaves
    # the maneuvers' slopes 2.8-3.4 for feet declared as metres: the median names it, each
    # maneuver's own slope the factor)
    own = st.slope_median[i]
    slope_ok = bool(np.isfinite(b) and np.isfinite(se) and se <= opt.slope_max_rel_se * abs(b)
                    and (f.flow or (np.isfinite(own)
                                    and not 1 / (1 + opt.scale_tol) <= own <= 1 + opt.scale_tol)))
    return (_unit_from_slope(st, i, opt, slope_ok) or (_unit_from_floor(st, i, opt) if misfits else None)
            or (_from_level(st, i, opt) if misfits else None)
            or (_scale_from_slope(st, i, opt) if misfits and slope_ok else None))


def _declare(f: ChannelFit, m: tuple[float, str, str]) -> str:
    """The advice of a unit error: the unit the channel is recorded in, to declare (``m``: a
    :data:`UNIT_FACTORS` entry)."""
    rec = re.search(r"recorded in (.+?) but", m[1])
    unit = {"degrees": "deg", "radians": "rad", "feet": "ft", "metres": "m", "knots": "kt",
            "km/h": "km/h", "m/s": "m/s", "m/s^2": "m/s^2", "g": "g"}.get(rec.group(1) if rec else "")
    return (f"declare the unit it is recorded in (unit = \"{unit}\" for {f.channel} under [columns] of "
            "the problem file, or fix the data) and estimate again" if unit else
            "fix the channel's unit in the problem file (or the data) and estimate again")


def _unit_from_slope(st: _Stats, i: int, opt: DiagnosticOptions, slope_ok: bool) -> Finding | None:
    """A unit named by the slope of the measurement on its model output (``slope_ok``: assessed) or,
    for a flow channel, on the kinematic angle of the reconstructed flight path."""
    f = st.fits[i]
    b, se = st.slope[i], st.slope_se[i]
    bk, sek = st.slope_k[i], st.slope_k_se[i]
    # A flow channel is tested against the deg/rad factor only (>= flow_unit_min_factor): a channel
    # that moves >= 10 x its kinematic angle is resolved as well as the scale test's 0.005 rad when
    # the angle moves a tenth of that (a sideslip within +-0.7 deg: sd 0.0043 rad, slope 57.33 +-
    # 1.56), and a slope that far from 1 is told at twice the relative error the scale test needs
    # (in degrees declared as radians, the larger the sideslip the more the fit is dragged and the
    # more coloured its residual: +-4.6 % of 57.3 at +-1.3 deg); the match then allows 2 such errors
    kin_ok = bool(f.flow and np.isfinite(bk) and np.isfinite(sek)
                  and sek <= 2.0 * opt.slope_max_rel_se * abs(bk)
                  and st.ref_sd[i] > opt.slope_ref_min_rad / opt.flow_unit_min_factor)
    cands = []
    if kin_ok:
        cands.append((bk, sek, f"the kinematic {f.measures} at the reference point of the reconstructed "
                               "flight path"))
    if slope_ok:
        cands.append((b, se, "its model output"))
    for val, err, against in cands:
        tol = max(opt.unit_tol, 2.0 * err / abs(val)) if f.flow else opt.unit_tol
        m = _unit_match(val, tol, f.unit)
        if m is None or abs(math.log(abs(val))) < math.log(1.5):
            continue
        # a flow channel's model shares tables with other channels, and its kinematic angle comes from
        # states a fault elsewhere can drag: slopes of 0.5-2 are seen then (0.50 on the kinematic
        # angle with a TAS in knots), never a factor of ten; flow angles come in deg or rad anyway
        if f.flow and abs(math.log(m[0])) < math.log(opt.flow_unit_min_factor):
            continue
        sign = "; its sign is inverted too" if val < 0 else ""
        return Finding(
            "unit_error", Severity.FAILURE,
            f"{_where(f)}: the measurement is {val:.4g} x {against} (+- {err:.2g}); the channel is probably "
            f"{m[1]}{sign} (residual {_fmt(st.rms[i], f)} rms, {_ratio_text(st, i)})",
            _declare(f, m), channel=f.channel, maneuver=f.maneuver, parameters=tuple(f.parameters),
            value=float(val))
    return None


def _unit_from_floor(st: _Stats, i: int, opt: DiagnosticOptions) -> Finding | None:
    """A unit named by the noise floor against the same channel's in the other maneuvers (large
    factors only: a floor changes with the flight condition by a few times, not by ten)."""
    f = st.fits[i]
    jump = st.floor_jump[i]
    big = math.log(opt.flow_unit_min_factor)
    if not (np.isfinite(jump) and abs(math.log(jump)) > big):
        return None
    m = _unit_match(jump, opt.floor_jump_tol, f.unit)
    if m is None or abs(math.log(m[0])) <= big:
        return None
    return Finding(
        "unit_error", Severity.FAILURE,
        f"{_where(f)}: its noise floor {_fmt(st.floor[i], f)} is {jump:.3g} x the same channel's "
        f"median floor over the maneuvers; the channel is probably {m[1]} in this maneuver "
        f"(residual {_fmt(st.rms[i], f)} rms, {_ratio_text(st, i)})",
        "fix the unit of this maneuver's data (another recorder or file?) and estimate again",
        channel=f.channel, maneuver=f.maneuver, parameters=tuple(f.parameters), value=float(jump))


def _from_level(st: _Stats, i: int, opt: DiagnosticOptions) -> Finding | None:
    """An absolute quantity's unit or scale named by its mean level against the model's: one far
    from zero against its variation (airspeed, altitude), where the model's level is its own."""
    f = st.fits[i]
    ym = float(np.mean(f.y)) if f.y.size else np.nan
    zm = float(np.mean(f.z)) if f.z.size else np.nan
    if f.flow or not (np.isfinite(ym) and np.isfinite(zm) and ym != 0 and abs(ym) > 10 * np.std(f.y)):
        return None
    lv = zm / ym
    m = _unit_match(lv, opt.level_tol, f.unit)
    if m is not None and abs(math.log(abs(lv))) > math.log(1.5):
        return Finding(
            "unit_error", Severity.FAILURE,
            f"{_where(f)}: the measurement's mean level is {lv:.4g} x the model's "
            f"({_fmt(zm, f)} against {_fmt(ym, f)}); the channel is probably {m[1]}",
            _declare(f, m), channel=f.channel, maneuver=f.maneuver, parameters=tuple(f.parameters), value=lv)
    if not (1 / (1 + opt.scale_tol) <= lv <= 1 + opt.scale_tol):
        return Finding(
            "scale_error", Severity.FAILURE,
            f"{_where(f)}: the measurement's mean level is {lv:.3g} x the model's ({_fmt(zm, f)} against "
            f"{_fmt(ym, f)}), no known unit conversion (residual {_fmt(st.rms[i], f)} rms, "
            f"{_ratio_text(st, i)})",
            "check the channel's scale factor, unit and sensor in the problem file and the data",
            channel=f.channel, maneuver=f.maneuver, parameters=tuple(f.parameters), value=float(lv))
    return None


def _scale_from_slope(st: _Stats, i: int, opt: DiagnosticOptions) -> Finding | None:
    """A misfitting channel that is a multiple of its model output (no unit conversion), where the
    model output moves enough to tell."""
    f = st.fits[i]
    b, se = st.slope[i], st.slope_se[i]
    if not st.y_sd[i] > opt.slope_min_signal * max(st.floor[i], 0.0) or (
            1 / (1 + opt.scale_tol) <= b <= 1 + opt.scale_tol):
        return None
    extra = (" — the measurement hardly follows the model: a stuck, disconnected or wrong sensor?"
             if abs(b) < 0.1 else " — its sign is inverted" if abs(b + 1) < 0.1 else "")
    return Finding(
        "scale_error", Severity.FAILURE,
        f"{_where(f)}: the measurement is {b:.3g} x its model output (+- {se:.2g}), "
        f"no known unit conversion{extra} (residual {_fmt(st.rms[i], f)} rms, {_ratio_text(st, i)})",
        "check the channel's scale factor, sign and sensor in the problem file and the data; a wrong "
        "minimum or a fault in another channel drags a fit too: read the other findings",
        channel=f.channel, maneuver=f.maneuver, parameters=tuple(f.parameters), value=float(b))


def _ratio_text(st: _Stats, i: int) -> str:
    f = st.fits[i]
    if not np.isfinite(st.ratio[i]):
        return "no noise floor"
    return f"{st.ratio[i]:.1f} x its noise floor {_fmt(st.floor[i], f)}"


def _local_span(st: _Stats, i: int, opt: DiagnosticOptions, threshold: float
                ) -> tuple[float, float] | None:
    """The time span whose local residual RMS (``local_window_s`` windows) exceeds ``threshold``
    floors."""
    f = st.fits[i]
    e = np.where(st.keep[i], f.z - f.y, np.nan)
    if f.t_s.size < 4 or not st.floor[i] > 0:
        return None
    dt = float(np.median(np.diff(f.t_s)))
    w = max(int(round(opt.local_window_s / dt)), 1)
    e2 = np.where(np.isnan(e), 0.0, e * e)
    c = np.concatenate([[0.0], np.cumsum(e2)])
    k = np.concatenate([[0], np.cumsum(~np.isnan(e))])
    lo = np.clip(np.arange(f.t_s.size) - w // 2, 0, f.t_s.size)
    hi = np.clip(lo + w, 0, f.t_s.size)
    with np.errstate(invalid="ignore", divide="ignore"):
        local = np.sqrt((c[hi] - c[lo]) / np.maximum(k[hi] - k[lo], 1))
    above = np.flatnonzero(local > threshold * st.floor[i])
    if not above.size:
        return None
    return float(f.t_s[above[0]]), float(f.t_s[above[-1]])


def _unit_slug(f: ChannelFit) -> str:
    """The display unit as a name suffix of a finding's numbers (``deg``, ``m``, ``mps``)."""
    u = (f.display_unit or f.unit or "").strip().lower()
    return {"m/s": "mps", "m/s^2": "mps2", "deg/s": "degps", "": "si"}.get(u, re.sub(r"\W+", "", u) or "si")


def _numbers(st: _Stats, i: int) -> dict[str, float]:
    """A residual finding's numbers (:attr:`Finding.numbers`), display units in their names."""
    f = st.fits[i]
    u = _unit_slug(f)
    k = f.display_scale
    out = {"ratio": float(st.ratio[i]), f"rms_{u}": float(st.rms[i] * k), f"mean_{u}": float(st.mean[i] * k),
           f"floor_{u}": float(st.floor[i] * k)}
    if np.isfinite(st.rho1[i]):
        out["rho1"] = float(st.rho1[i])
    return out


def _gross_limit(f: ChannelFit, opt: DiagnosticOptions) -> tuple[float, str] | None:
    """The rms beyond which a kinematic channel's misfit is gross, SI, and what it is; None for a
    channel of another kind (judged by its ratio alone)."""
    unit = (f.unit or "").strip()
    if unit == "rad":
        if f.channel.lower().startswith(("psi", "heading", "yaw")):
            return math.radians(opt.misfit_heading_deg), "a heading"
        return math.radians(opt.misfit_attitude_deg), "an attitude"
    if unit == "m/s":
        level = float(np.mean(np.abs(f.y))) if f.y.size else 0.0
        return max(opt.misfit_speed_fraction * level, opt.misfit_speed_mps), "a speed"
    if unit == "m":
        return opt.misfit_height_m, "a height"
    return None


def _gross(st: _Stats, i: int, opt: DiagnosticOptions) -> bool:
    """A kinematic misfit beyond what real recorded data show (:class:`DiagnosticOptions`,
    ``misfit_ratio`` and the physical limits): a wrong minimum or a fault, not the slow errors of a
    real INS and air-data system."""
    f = st.fits[i]
    if not st.ratio[i] > opt.misfit_ratio:
        return False
    lim = _gross_limit(f, opt)
    return lim is None or float(st.rms[i]) > lim[0]


def _ratio_finding(st: _Stats, i: int, opt: DiagnosticOptions, code: str, sev: Severity) -> Finding:
    f = st.fits[i]
    thr = opt.misfit_warn_ratio if code == "misfit" else opt.noise_floor_ratio
    span = _local_span(st, i, opt, thr)
    where = f"; largest from t = {span[0]:.1f} to {span[1]:.1f} s" if span else ""
    colour = f", lag-1 autocorrelation {st.rho1[i]:.2f}" if np.isfinite(st.rho1[i]) else ""
    msg = (f"{_where(f)}: residual {_fmt(st.rms[i], f)} rms (mean {_fmt(st.mean[i], f)}), "
           f"{_ratio_text(st, i)}{colour}{where}")
    numbers = _numbers(st, i)
    if code == "misfit" and sev >= Severity.FAILURE:
        lim = _gross_limit(f, opt)
        beyond = f" and beyond {lim[1]} error real data show ({_fmt(lim[0], f)} rms)" if lim else ""
        msg += (f": the fit does not explain this kinematic channel, whose model is exact kinematics{beyond}"
                " — a wrong minimum or a fault in the data")
        advice = ("read the other findings first (a data fault drags the fit); otherwise start from "
                  "better values (IMU biases, initial conditions), try several starts, and check this "
                  "channel's data")
    elif code == "misfit":
        msg += (": slow, coloured errors of the kind real recorded data carry (a filtered INS attitude, "
                "baro lag and static-source error, IMU scale and misalignment, vertical air motion), not a "
                "gross misfit; the honest deviations take their colour in, not a systematic error the "
                "model set lacks (read the estimates on their bounds and Table 2)")
        advice = ""
    else:
        msg += ": more than its noise — a model-structure error (the calibration model cannot follow the "
        msg += "data here) or unmodelled air motion"
        advice = ("look at the time history of this channel's residual; extend the model (table "
                  "breakpoints, terms) or leave out the part it cannot follow, and expect its deviations "
                  "to be optimistic")
    return Finding(code, sev, msg, advice, channel=f.channel, maneuver=f.maneuver,
                   t_s=span or (), parameters=tuple(f.parameters), value=float(st.ratio[i]), numbers=numbers)


def _flow_residual_finding(st: _Stats, i: int, opt: DiagnosticOptions, acc: _Accuracy | None) -> Finding:
    """A flow channel above its floor ("noise_floor"), judged by its effect on the channel's accuracy:
    a NOTE where the scatter of its residual (the part of Table 2 the residual shows; the workflow's
    Table 2 adds the calibration's own uncertainty and says a miss itself, ``accuracy_miss``) meets
    its desired accuracy over the estimation (pooled over its maneuvers, below the usable alpha range
    for a ``low_alpha_only`` channel) or in this maneuver; a WARNING where neither holds, or no
    accuracy is stated to judge it by."""
    f = st.fits[i]
    g = _ratio_finding(st, i, opt, "noise_floor", Severity.WARNING)
    if acc is None or f.desired_3sigma is None:
        return g
    k, unit, des = f.display_scale, f.display_unit, float(f.desired_3sigma)
    own = 3.0 * float(st.rms[i])
    nums = {**g.numbers, "scatter_three_sigma_deg": own * k, "desired_deg": des * k,
            "pooled_scatter_three_sigma_deg": acc.pooled * k}
    where = ""
    if acc.limit_deg is not None:
        own = acc.below.get(i, math.nan)
        nums.update(usable_alpha_deg=acc.limit_deg, scatter_three_sigma_below_deg=own * k)
        if math.isfinite(acc.alpha_from_deg.get(i, math.nan)):
            nums["alpha_from_deg"] = acc.alpha_from_deg[i]
        where = f" below alpha {acc.limit_deg:.0f} deg (its usable range, paper Fig. 7)"
    ok_here = math.isfinite(own) and own <= des
    ok_all = math.isfinite(acc.pooled) and acc.pooled <= des
    said = (f"; 3 sigma of its residual{where} {own * k:.2g} {unit} in this maneuver, {acc.pooled * k:.2g} "
            f"{unit} over the estimation's maneuvers, against its desired {des * k:.2g} {unit}")
    if ok_here or ok_all:
        return replace(g, severity=Severity.NOTE, advice="", message=g.message + said
                       + ": the channel meets its accuracy", numbers=nums)
    return replace(g, message=g.message + said + ": beyond it", numbers=nums)


def _coloured_finding(st: _Stats, i: int, sev: Severity) -> Finding:
    f = st.fits[i]
    return Finding(
        "coloured", sev,
        f"{_where(f)}: residual coloured (lag-1 autocorrelation {st.rho1[i]:.3f}: the Cramér-Rao "
        f"deviations of its parameters are optimistic by about "
        f"{math.sqrt((1 + st.rho1[i]) / (1 - st.rho1[i])):.1f}x, which the honest deviations take in) at "
        f"{_ratio_text(st, i)}",
        "read the honest (coloured-residual) deviations; a slow drift in a residual can be a model the fit "
        "lacks (a delay, a bias, a table breakpoint)",
        channel=f.channel, maneuver=f.maneuver, parameters=tuple(f.parameters), value=float(st.rho1[i]),
        numbers=_numbers(st, i))


def _outlier_finding(st: _Stats, i: int, t: np.ndarray, opt: DiagnosticOptions) -> Finding:
    """Outlier samples: a WARNING where they matter — their share of the channel's residual sum of
    squares in the maneuver above ``outlier_warn_share`` (they drag the fit and Table 2), or the
    largest beyond the channel's desired accuracy; a NOTE otherwise (one sample of the nose probe's
    irregular high-alpha noise at 7 floors)."""
    f = st.fits[i]
    pos = np.searchsorted(f.t_s, t)
    e_all = f.z - f.y
    e = e_all[pos]
    j = int(np.argmax(np.abs(e)))
    total = float(np.nansum(e_all * e_all))
    share = float(np.nansum(e * e) / total) if total > 0 else 1.0
    largest = float(abs(e[j]))
    matters = share > opt.outlier_warn_share or (f.desired_3sigma is not None and largest > f.desired_3sigma)
    times = ", ".join(f"{v:.3f}" for v in t[:6]) + (" ..." if t.size > 6 else "")
    u = _unit_slug(f)
    return Finding(
        "outlier", Severity.WARNING if matters else Severity.NOTE,
        f"{_where(f)}: {t.size} outlier sample(s) at t = {times} s, the largest {_fmt(float(e[j]), f)} "
        f"against a noise floor of {_fmt(st.floor[i], f)} ({100 * share:.0f} % of the residual's sum of "
        "squares in this maneuver)",
        "rerun with the robust option (fpr calibrate --robust), which excludes them; check the recording "
        "at those times" if matters else "",
        channel=f.channel, maneuver=f.maneuver, t_s=tuple(float(v) for v in t),
        parameters=tuple(f.parameters), value=float(t.size),
        numbers={f"largest_abs_{u}": largest * f.display_scale,
                 f"floor_{u}": float(st.floor[i] * f.display_scale), "share": share})


def _turbulence(st: _Stats, done: np.ndarray, opt: DiagnosticOptions
                ) -> tuple[list[Finding], np.ndarray]:
    """Per maneuver: air-relative residuals far above their floors, coloured, zero-mean, common to
    several sensors and of similar size, while the inertial channels fit (module docstring)."""
    out, used = [], np.zeros(len(st.fits), dtype=bool)
    by_man: dict[str, list[int]] = {}
    for i, f in enumerate(st.fits):
        by_man.setdefault(f.maneuver, []).append(i)
    for man, rows in by_man.items():
        inertial = [i for i in rows if not st.fits[i].air_relative and np.isfinite(st.ratio[i])]
        if any(st.ratio[i] > opt.misfit_warn_ratio for i in inertial):
            continue
        # gusts are zero-mean about the wind the initial conditions absorb; a dragged or faulty fit
        # leaves offsets (|mean| / rms of 0.56-1.0 seen, 0.07-0.47 in light turbulence)
        hot = {i for i in rows if st.fits[i].air_relative and not done[i] and np.isfinite(st.ratio[i])
               and st.ratio[i] > opt.turbulence_ratio and st.rho1[i] > opt.turbulence_rho1
               and abs(st.mean[i]) <= opt.turbulence_max_mean * st.rms[i]}
        group = sorted(i for i in hot if st.fits[i].flow and any(
            j in hot and abs(c) > opt.turbulence_corr for j, c in st.partners.get(i, [])))
        if len(group) < 2:
            continue
        sd = np.sqrt(np.maximum(st.rms[group] ** 2 - st.mean[group] ** 2, 0.0) * st.scale[group] ** 2)
        if sd.max() > opt.turbulence_spread * sd.min():
            continue  # one gust moves every sensor by about as much (light turbulence: within 1.9x)
        group += sorted(i for i in hot if not st.fits[i].flow)  # airspeed: longitudinal gusts
        parts = ", ".join(f"{st.fits[i].channel} {_fmt(st.rms[i], st.fits[i])} ({st.ratio[i]:.0f}x)"
                          for i in group)
        corr = max(abs(c) for i in group for j, c in st.partners.get(i, []) if j in group)
        kin = ", ".join(sorted({st.fits[i].channel for i in inertial}))
        what = "flow-angle" + (" and airspeed" if any(not st.fits[i].flow for i in group) else "")
        # a failure, not a warning: with gusts the output-error estimates are biased and even the
        # honest deviations optimistic (light turbulence, linear flow: time delays and tables up to
        # 4-5 of them off), and the accuracy the paper asks for is lost (planning study (c))
        out.append(Finding(
            "turbulence", Severity.FAILURE,
            f"maneuver {man}: {what} residuals far above their noise floors ({parts}), coloured (lag-1 "
            f"autocorrelation >= {min(st.rho1[i] for i in group):.2f}) and common to {len(group)} sensors "
            f"(residual correlation up to {corr:.2f}) while the inertial channels fit ({kin}): turbulence or "
            "other unmodelled air motion",
            "calibrate from maneuvers flown in calm air, or estimate with the wind as states (the "
            "filter-error method: fpr calibrate --method filter_error, SolverOptions(method="
            "'filter_error'); experimental, read its warnings), or leave this maneuver out: the "
            "output-error method models no process noise, so gusts bias the flow-angle estimates and "
            "make their deviations optimistic",
            channel=", ".join(st.fits[i].channel for i in group), maneuver=man,
            parameters=tuple(dict.fromkeys(p for i in group for p in st.fits[i].parameters)),
            value=float(max(st.ratio[i] for i in group))))
        used[group] = True
    return out, used


def _beside_turbulence(findings: list[Finding], turbulence: list[Finding]) -> list[Finding]:
    """A flow channel's scale error in a maneuver the turbulence finding covers says so: gusts
    correlated with the maneuver's own flow-angle changes make a channel look rescaled (light
    turbulence in planning study (c): 1.33 x on the boom's sideslip vanes of one maneuver)."""
    turbulent = {f.maneuver for f in turbulence}
    out = []
    for f in findings:
        if f.code == "scale_error" and f.maneuver in turbulent:
            f = replace(f, message=f"{f.message}; this maneuver's flow residuals show turbulence too, "
                        "whose gusts can make a channel look rescaled",
                        advice="read the turbulence finding of this maneuver first; " + f.advice)
        out.append(f)
    return out


def _input_findings(inputs: Sequence[ManeuverInputs], opt: DiagnosticOptions) -> list[Finding]:
    """Dead IMU axes and a sign-flipped (or g-scaled) body-z accelerometer, per maneuver."""
    out: list[Finding] = []
    if not inputs:
        return out
    series, ts, owner = [], [], []
    for k, m in enumerate(inputs):
        A = np.asarray(m.accel_imu_mps2, dtype=float)
        W = np.asarray(m.omega_rps, dtype=float)
        t = np.asarray(m.t_s, dtype=float)
        for j in range(3):
            series.append(A[:, j])
            ts.append(t)
            owner.append((k, j, "accel"))
        for j in range(3):
            series.append(W[:, j])
            ts.append(t)
            owner.append((k, j, "gyro"))
    X, T = _pad(series), _pad(ts)
    length, start, end, t0, t1 = _longest_runs(X, T)
    for r in np.flatnonzero((length >= opt.stuck_min_samples) & (t1 - t0 >= opt.stuck_min_s)):
        k, j, kind = owner[r]
        m = inputs[k]
        att = _attitude(m)
        t = np.asarray(m.t_s, dtype=float)
        inrun = (t >= t0[r]) & (t <= t1[r])
        change = 0.0
        for a in range(3):
            v = att[inrun, a]
            v = v[np.isfinite(v)]
            if v.size > 1:
                change = max(change, float(np.ptp(np.unwrap(v))))
        if change <= opt.dead_input_attitude_rad:
            continue
        name = _IMU_AXES[j if kind == "accel" else 3 + j]
        value = float(X[r, start[r]])
        unit, sc = ("m/s^2", 1.0) if kind == "accel" else ("deg/s", _DEG)
        whole = t0[r] <= t[0] and t1[r] >= t[-1]
        out.append(Finding(
            "dead_input", Severity.FAILURE,
            f"IMU input {name} in maneuver {m.maneuver} is constant at {value * sc:.4g} {unit} "
            f"{'over the whole maneuver' if whole else 'from'} t = {t0[r]:.2f} to {t1[r]:.2f} s while the "
            f"measured attitude changes by {change * _DEG:.1f} deg: a dead or disconnected "
            f"{'accelerometer' if kind == 'accel' else 'gyro'}",
            "check the IMU channel and its mapping in the problem file; the flight path cannot be "
            "reconstructed without it: leave this maneuver out until it is fixed",
            channel=name, maneuver=m.maneuver, t_s=(float(t0[r]), float(t1[r])), value=float(change * _DEG)))
    g = opt.g_mps2
    for m in inputs:
        A = np.asarray(m.accel_imu_mps2, dtype=float)
        az = A[:, 2][np.isfinite(A[:, 2])]
        if az.size < 2 or np.ptp(az) == 0:
            continue
        mz = float(np.mean(az))
        if mz > opt.accel_sign_min_g * g:
            out.append(Finding(
                "accel_sign", Severity.FAILURE,
                f"IMU input az_imu_mps2 in maneuver {m.maneuver}: the body-z specific force averages "
                f"{mz:+.2f} m/s^2 ({mz / g:+.2f} g), where flight gives about -n g (body z down: -1 g in "
                "level flight, n the load factor): its sign is flipped",
                "invert the sign of the z accelerometer (the problem file's column mapping, or the IMU's "
                "axis convention: x forward, y right, z down) and estimate again",
                channel="az_imu_mps2", maneuver=m.maneuver, value=mz / g))
        elif -opt.accel_g_units_max * g < mz < -opt.accel_g_units_min * g:
            out.append(Finding(
                "unit_error", Severity.FAILURE,
                f"IMU input az_imu_mps2 in maneuver {m.maneuver}: the body-z specific force averages "
                f"{mz:+.3g} m/s^2, where flight gives about -n g (-9.81 m/s^2 in level flight, n the load "
                "factor): the accelerometers are probably recorded in g but declared as m/s^2 (x 1/9.80665)",
                "fix the accelerometers' unit in the problem file and estimate again",
                channel="az_imu_mps2", maneuver=m.maneuver, value=mz / g))
    return out


def _attitude(m: ManeuverInputs) -> np.ndarray:
    """(N, 3) measured Euler angles where finite, else the reconstructed ones."""
    X = np.asarray(m.states, dtype=float)
    att = X[:, 3:6].copy() if X.ndim == 2 and X.shape[1] >= 6 else np.full((len(m.t_s), 3), np.nan)
    if m.euler_measured_rad is not None:
        E = np.asarray(m.euler_measured_rad, dtype=float)
        if E.shape == att.shape:
            fin = np.isfinite(E)
            use = fin.sum(axis=0) >= 2
            att[:, use] = np.where(fin[:, use], E[:, use], np.nan)
    return att


def _attribute(findings: list[Finding]) -> list[Finding]:
    """Say on each consequence-type finding which data fault of the estimation probably caused it."""
    causes = [f for f in findings if f.code in _CAUSES and f.severity >= Severity.FAILURE]
    if not causes:
        return findings
    out = []
    for f in findings:
        if f.code in _CAUSES or f.code == "outlier":
            out.append(f)
            continue
        chan = [c for c in causes if c.channel == f.channel and c.maneuver != f.maneuver]
        same = [c for c in causes if c.maneuver == f.maneuver]
        if same:
            c, where = same[0], "in this maneuver"
        elif chan:
            c = chan[0]
            where = f"in maneuver {c.maneuver} (the same channel: is it faulty here too?)"
        else:
            c = causes[0]
            where = f"in maneuver {c.maneuver} (shared parameters carry it here)"
        note = (f" [probably a consequence of the {c.code.replace('_', ' ')} of {c.channel} {where}: fix "
                "that first]")
        out.append(Finding(f.code, f.severity, f.message + note, f.advice, f.channel, f.maneuver, f.t_s,
                           f.parameters, f.value))
    return out


def _ordered(findings: list[Finding]) -> list[Finding]:
    """Most severe first; within a severity, data faults before their consequences."""
    return sorted(findings, key=lambda f: (-int(f.severity), _CODE_ORDER.get(f.code, 99)))
