"""Every option of the estimator, in one module: the settings classes and the option tables.

- :class:`SolverOptions` — one estimation (:func:`estimator.solver.estimate`), with the
  filter-error method's turbulence model :class:`WindOptions` inside;
- :class:`DiagnosticOptions` — the thresholds of the fit-quality diagnostics
  (:mod:`estimator.diagnostics`);
- :class:`WorkflowOptions` — the Mach-bin workflow (:func:`estimator.workflow.run_workflow`), its
  solver settings inside;
- :class:`CalibrationOptions` — :func:`estimator.calibration.calibrate` (the workflow's and the
  report's), and :func:`option_tables`, the option names by the TOML table of a problem file or
  scenario that holds them (``[workflow]``, ``[solver]``, ``[report]``).

A data-type module: it imports no estimation code, so that reading a problem file
(:mod:`estimator.io.problemfile` checks its option tables here) loads neither the solver nor the
workflow. The old homes re-export their classes (``from estimator.solver import SolverOptions``
still works).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aircraft_models.schema import unknown
from estimator.declarations import Declarations

__all__ = [
    "DRYDEN_SCALE_LENGTH_M", "METHODS", "STARTS", "WIND_FORMS", "CalibrationOptions", "DiagnosticOptions",
    "SolverOptions", "WindOptions", "WorkflowOptions", "option_tables",
]


# --------------------------------------------------------------------------------------------------
# the filter-error method's turbulence model

#: MIL-F-8785C scale length above 2000 ft (1750 ft), m.
DRYDEN_SCALE_LENGTH_M = 533.4
#: The wind states' forms (WindOptions.form).
WIND_FORMS = ("gauss_markov", "dryden")

@dataclass(frozen=True)
class WindOptions:
    """The turbulence model of the filter-error method.

    Attributes
    ----------
    scale_length_m : Dryden scale length ``L``, m (1750 ft above 2000 ft).
    sigma_mps : turbulence intensity, m/s; None: estimated per maneuver.
    where : which maneuvers get wind states: "diagnosed" (default) — those whose output-error
        residuals the diagnostics call turbulent (flow residuals far above their floors, coloured
        and common to several sensors while the inertial channels fit: air motion, not a sensor's
        model-structure error); the others are calm; "all" — every maneuver, its intensity
        estimated (a structure error of one sensor is then taken for wind: on the demo's calm
        data the 22-deg wind-up turns came out at 0.9-1.25 m/s from the nose probe's high-alpha
        error, and that bin did not converge).
    form : the wind states' form: "gauss_markov" (default) — three first-order Gauss-Markov NED
        components (Dryden's longitudinal spectrum for all three); "dryden" — MIL-F-8785C's Dryden
        turbulence in body axes: the longitudinal component first-order, the lateral and vertical
        second-order (five states; :func:`estimator.core.wind_filter.dryden_body`), the form
        JSBSim's Tustin turbulence (turb-type 4) has.
    calm_sigma_mps : a maneuver whose estimated intensity is below this is taken as flown in calm
        air (no wind states: its innovations are its residuals, as in the output-error method).
        Calm data still give a small intensity — the wind states then follow what the calibration
        model cannot (0.006-0.19 m/s in the JSBSim calm-air maneuvers, against 0.9-1.2 m/s in
        light turbulence) — and would move the estimates by a few deviations away from the
        output-error ones for no gain.
    """

    scale_length_m: float = DRYDEN_SCALE_LENGTH_M
    sigma_mps: float | None = None
    calm_sigma_mps: float = 0.3
    where: str = "diagnosed"
    form: str = "gauss_markov"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.scale_length_m) and self.scale_length_m > 0):
            raise ValueError(f"WindOptions.scale_length_m must be a positive length in m, got "
                             f"{self.scale_length_m!r}")
        if self.form not in WIND_FORMS:
            raise ValueError(f"WindOptions.form must be one of {WIND_FORMS}, got {self.form!r}")
        if self.where not in ("diagnosed", "all"):
            raise ValueError(f"WindOptions.where must be 'diagnosed' or 'all', got {self.where!r}")
        if self.sigma_mps is not None and not (math.isfinite(self.sigma_mps) and self.sigma_mps > 0):
            raise ValueError(f"WindOptions.sigma_mps must be positive (m/s) or None to estimate it, got "
                             f"{self.sigma_mps!r}")


# --------------------------------------------------------------------------------------------------
# one estimation

#: Start strategies: the staged, data-driven start (:mod:`estimator.start`) or the problem's values.
STARTS = ("staged", "given")
#: Estimation methods: output error (calm air) and filter error (turbulence; wind states).
METHODS = ("output_error", "filter_error")

@dataclass(frozen=True)
class SolverOptions:
    """Solver settings.

    Attributes
    ----------
    max_iterations : Gauss-Newton iterations at most (per stage of the start, and per round of
        the estimation).
    step_tol_sigma : converged when the undamped Gauss-Newton step is below this many Cramér-Rao
        deviations for every parameter ...
    decrease_tol : ... or when the cost decrease it predicts is below this (log-likelihood units:
        0.001 is a change of 0.002 in chi-square, statistically nothing).
    lm_lambda0 : initial Levenberg-Marquardt damping (relative to diag M).
    rank_rtol : eigenvalues of the scaled information matrix below ``rank_rtol * max`` are treated
        as zero (unidentifiable directions).
    min_support_samples : a parameter that fewer samples depend on (a table breakpoint at the edge
        of the flown range) is held at its start value and reported: a handful of samples would
        set it to fit their noise.
    correlation_warn : |correlation| above this is reported as a confounded pair.
    colored : compute the Morelli-Klein coloured-residual deviations.
    colored_cross_channel : with the residual cross-correlations between the channels of a
        maneuver (the full matrix form); False: each channel alone.
    colored_spectrum : the residuals' spectrum in the coloured deviations: "ar" (autoregressive
        models fitted to the residuals, :mod:`estimator.core.residual_spectrum`) or "periodogram"
        (their own correlation at every lag, the original plug-in: biased low).
    imu_noise : the IMU noise whose integration adds to the coloured deviations (process noise,
        :mod:`estimator.core.process_noise`): "estimate" (from the IMU data, per aircraft), "none",
        or ``(accel_psd, gyro_psd)``, the white-noise densities in m^2/s^3 and rad^2/s (a
        datasheet's velocity and angle random walk, squared, in SI).
    start : "staged" (default), "given", or a tuple of them: one estimation from each, the best
        verdict kept (then the lowest cost).
    robust : exclude the residual outliers the diagnostics find and estimate again (reported).
    diagnose : run the fit-quality diagnostics (the verdict then rests on the convergence and the
        identifiability checks alone if False).
    screen_rounds : estimations at most when the identifiability screen at the solution holds
        further parameters.
    verbose : print one line per iteration.
    method : "output_error" (default; calm air) or "filter_error": the turbulent wind as estimated
        Gauss-Markov states, the cost the likelihood of a Kalman filter's innovations
        (:mod:`estimator.filter_error`). The start, the identifiability screen and a first
        output-error fit are the output-error method's; the maneuvers whose residuals there the
        diagnostics call turbulent get wind states (``wind.where``); the deviations are those
        of the filter-error information matrix, Cramér-Rao and (``colored``) the coloured
        innovations' sandwich (:func:`estimator.uncertainty.innovation_honest_std`; always the
        autoregressive spectrum model, whatever ``colored_spectrum``).
    wind : the filter-error method's turbulence model (:class:`WindOptions`;
        None: its defaults, the intensity estimated per maneuver).
    """

    max_iterations: int = 40
    step_tol_sigma: float = 0.01
    decrease_tol: float = 1e-3
    lm_lambda0: float = 1e-4
    rank_rtol: float = 1e-10
    correlation_warn: float = 0.995
    min_support_samples: int = 40
    colored: bool = True
    colored_cross_channel: bool = True
    colored_spectrum: str = "ar"
    imu_noise: str | tuple[float, float] = "estimate"
    start: str | tuple[str, ...] = "staged"
    robust: bool = False
    diagnose: bool = True
    screen_rounds: int = 3
    verbose: bool = False
    method: str = "output_error"
    wind: WindOptions | None = None

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"SolverOptions: method must be one of {METHODS}, got {self.method!r}")
        if isinstance(self.wind, Mapping):  # a problem file's or scenario's [solver] table
            try:
                object.__setattr__(self, "wind", WindOptions(**dict(self.wind)))
            except TypeError as exc:
                raise ValueError(f"SolverOptions: wind = {dict(self.wind)!r}: {exc}; its keys are "
                                 "scale_length_m, sigma_mps, calm_sigma_mps, where, form") from None
        if self.wind is not None and not isinstance(self.wind, WindOptions):
            raise ValueError(f"SolverOptions: wind must be WindOptions or a table of its keys, got "
                             f"{self.wind!r}")
        if self.wind is not None and self.method != "filter_error":
            raise ValueError("SolverOptions: wind options are for method='filter_error' (the "
                             "output-error method has no wind states)")
        starts = (self.start,) if isinstance(self.start, str) else tuple(self.start)
        bad = [s for s in starts if s not in STARTS]
        if bad or not starts:
            raise ValueError(f"SolverOptions: start must be one of {STARTS} or a tuple of them, "
                             f"got {self.start!r}")
        if isinstance(self.imu_noise, str):
            if self.imu_noise not in ("estimate", "none"):
                raise ValueError(f"SolverOptions: imu_noise must be 'estimate', 'none' or (accel_psd, "
                                 f"gyro_psd), got {self.imu_noise!r}")
        elif len(self.imu_noise) != 2 or not all(np.isfinite(v) and v >= 0 for v in self.imu_noise):
            raise ValueError(f"SolverOptions: imu_noise = {self.imu_noise!r}: two densities >= 0, "
                             "(m^2/s^3, rad^2/s)")
        if self.colored_spectrum not in ("ar", "periodogram"):
            raise ValueError(f"SolverOptions: colored_spectrum must be 'ar' or 'periodogram', got "
                             f"{self.colored_spectrum!r}")
        if self.max_iterations < 1:
            raise ValueError(f"SolverOptions: max_iterations must be >= 1, got {self.max_iterations}")


# --------------------------------------------------------------------------------------------------
# the fit-quality diagnostics' thresholds

@dataclass(frozen=True)
class DiagnosticOptions:
    """Every threshold of the diagnostics, with where its value comes from.

    The evidence quoted with each value is from fits of JSBSim synthetic data (``fpr fly``: typical
    errors, realistic and linear local flow, nose-probe and boom configurations, Mach 0.3-0.8, six
    maneuver kinds, eight seeds: 15 estimations, 1262 channel-maneuvers) and of the same data with
    injected faults (stuck, dead and partly stuck vanes, spikes, unit errors in a flow angle, the
    pitch angle, the altitude and the airspeed, a flipped accelerometer, dead gyros, light
    turbulence, estimates moved off their minimum).
    """

    # --- noise floor -----------------------------------------------------------------------------
    floor_order: int = 3
    """k of the k-th differences: 3 keeps more of a maneuver's own curvature out of the floor at
    40 Hz (good fits: the highest floor, relative to the residual, 33 % high with k = 2, 22 % with
    k = 3, in the sharpest maneuvers; the median ratio is 1.00 either way)."""
    floor_max_spacing: int = 8
    floor_interp_jump: float = 0.25
    floor_plateau: float = 0.05
    """The floor is the larger of the spacing-1 and 2 estimates (``floor_max_spacing`` 1: spacing 1
    only); if the spacing-2 one is more than ``floor_interp_jump`` above the spacing-1 one (a stream
    interpolated from under ~30 Hz), spacings 3, 4, ... up to ``floor_max_spacing`` are tried until
    the estimate grows by less than ``floor_plateau`` from one to the next, and the floor is the
    largest; without such a plateau, signal leaks into the differences and the spacing-1 and 2
    floor stands (module docstring: resampled channels). White noise linearly interpolated from 64,
    50, 25, 10 Hz onto 40 Hz: 1.01, 1.00, 1.01, 1.00 of its standard deviation (spacing 1 alone:
    0.99, 0.93, 0.38, 0.02); white noise: 1.01, sampling deviation 2.4 % (400 replications of 1600
    samples each). Turbulence (a gust spectrum falling as f^-2) grows the estimate by 10-20 % per
    spacing: a 10 % plateau made its floors up to 50 % high."""
    floor_block: int = 64
    """Samples per block of the local noise estimate (0: one block, the whole record): the floor is
    the root of the mean of the blocks' variances, so noise that grows along a maneuver (the nose
    probe at high AOA, low dynamic pressure) counts where it is (good fits: the ratio of a Mach 0.3
    nose probe falls from 2.5 to 1.7, the other channels move by < 1 %)."""
    floor_clip: float = 4.0
    """Differences beyond this many robust deviations are left out of the floor (clipped RMS)."""
    floor_resolution: float = 1e-4
    """The smallest floor, in display units (deg, m, m/s): no recorded flight channel is resolved
    finer (a 24-bit +-180 deg word: 2e-5 deg; INS attitude noise 0.02-0.05 deg), and below it the
    "noise" is numerical (noise-free synthetic data: third differences of smooth signals at 1e-7
    rad, model residuals at 1e-6 rad, which read as 3-6 x a floor estimated from them)."""
    gap_factor: float = 1.5
    """A time step over this times the median step is a gap (as :mod:`estimator.io.timebase`)."""
    lattice_tol: float = 0.02
    """A channel is quantised if >= ``lattice_fraction`` of its non-zero sample differences are within
    this fraction of a step of a multiple of the smallest one."""
    lattice_fraction: float = 0.98
    hold_fraction: float = 0.5
    """A channel (not quantised) whose consecutive samples repeat more often than this is a
    sample-and-hold of a slower stream: its floor is taken from the first sample of each run."""

    # --- residual against the floor ----------------------------------------------------------------
    misfit_ratio: float = 3.0
    misfit_warn_ratio: float = 2.0
    """A kinematic channel (Euler angles, airspeed, altitudes, INS velocities: exact kinematics)
    above ``misfit_warn_ratio`` floors is said ("misfit"), a FAILURE only where the misfit is gross
    (above ``misfit_ratio`` floors and beyond the physical limits below), a NOTE otherwise. The
    ratio alone does not tell a wrong minimum from real data: white-noise fits, synthetic (15
    estimations, 648 kinematic channel-maneuvers): 0.90-1.28; real recorded flights of good
    quality (the field's textbook data-compatibility cases, a transport aircraft and a fighter):
    height 4.2 m rms at 22 x its floor, airspeed 2.7-5.5 x, pitch 6-8 x, heading 2.3-14.6 x, bank
    2.6-5.8 x, lag-1 autocorrelation 0.86-0.99 (filtered INS attitude, baro lag and static-source
    error, IMU scale and misalignment, vertical air motion); a real small UAV (UMN Thor, flight 75,
    AHRS attitude): bank 0.33-0.61 deg at 3.7-10 x, pitch 0.18-0.47 deg at 6.6-30 x, heading
    0.27-1.6 deg at 17-140 x, airspeed 0.6-1.1 m/s at 2.1-4 x; the testbed's realism level
    (docs/realism.md; the verdict corpus's 24 flights and 3 fleet workflows): pitch up to 11 x,
    heading 3.5 x, height 46 x (the DGPS height), lag-1 autocorrelation 0.5-0.99; a fit held 0.05
    deg/s off its pitch-gyro bias: pitch 0.45 deg at 19 x. The physical size separates them
    (below; the margins: ``campaigns/benchmarks/results/verdict_corpus.txt``)."""
    misfit_attitude_deg: float = 1.5
    """A bank or pitch residual above this rms is gross: a working attitude reference never leaves it
    (an INS 0.05-0.3 deg, SPEC §6; the textbook flights' pitch 6-8 x a floor of a few hundredths of
    a degree; the realism level at most 0.34 deg; a small UAV's AHRS 0.33-0.93 deg, UMN Thor flight
    75 in 30-60 s pieces), a fit at a
    wrong point does (a pitch-gyro bias held 0.3 deg/s off: 2.8 deg; a roll-gyro bias: 3.0 deg;
    the wrong minima of the zero start before the staged start: about 10 deg). Margins in
    ``campaigns/benchmarks/results/verdict_corpus.txt``."""
    misfit_heading_deg: float = 2.5
    """... a heading residual above this rms (the textbook flights: 2.3-14.6 x their floor, under a
    degree; the realism level at most 0.11 deg; UMN Thor 0.27-1.7 deg; a yaw-gyro bias held 0.3
    deg/s off: 3.0 deg over 40 s)."""
    misfit_speed_fraction: float = 0.03
    misfit_speed_mps: float = 2.0
    """... an airspeed or velocity residual above the larger of this fraction of the channel's mean
    and this many m/s (static-source position error 0.5-1 % of the airspeed; a UAV's 1.1 m/s at 17
    m/s in gusts of a 6 m/s wind; the realism level at most 0.84 m/s; an x-accelerometer bias held
    0.3 m/s^2 off: 2.5 m/s, 1.6 %, which the fit's delay on its bound says)."""
    misfit_height_m: float = 50.0
    """... a height residual above this rms (static-source error 1-2 % of the impact pressure: up to
    10-30 m at high dynamic pressure; the textbook flights: 4.2 m; the realism level at most 16 m,
    in banked wind-up turns; a roll-gyro bias held 0.3 deg/s off: 203 m)."""
    noise_floor_ratio: float = 2.0
    """Flow channel above this many floors: "noise_floor" (a model-structure error), judged by its
    effect on the channel's Table 2 accuracy (:mod:`estimator.diagnostics`): a NOTE where the
    channel meets it, a WARNING where not. Good fits, realistic and linear local flow: 0.82-1.28
    (543 channel-maneuvers) except the nose probe's beta_znp in high-AOA maneuvers (wind-up turns):
    up to 5.5, the synthesizer's nose-probe irregularity (paper §4.2, "impossible to model"), beyond
    the probe's usable alpha range (the demo: 3 sigma 0.13 deg over the bin below 12 deg against
    0.5, a note); the realism level: 1.4-6 x, within every accuracy; the real UAV's five-hole probe:
    3-3.7 x, 3 sigma 7-10 deg against 1 deg, its scale factors on their bounds (a failure)."""
    local_window_s: float = 2.0
    """Window of the local residual RMS that locates where a channel misfits, s."""
    alpha_band_deg: float = 2.0
    min_band_samples: int = 200
    """The usable alpha range of a ``low_alpha_only`` channel: the highest alpha up to which every
    band of this width with at least this many samples keeps the channel's 3 sigma within its desired
    accuracy (:func:`estimator.accuracy.alpha_limit`, as the workflow's Table 2 finds it)."""

    # --- outliers ----------------------------------------------------------------------------------
    outlier_sigma: float = 7.0
    """Outlier threshold in robust deviations of the high-passed residual."""
    outlier_block: int = 40
    """Samples per block of the local scale (0: the whole record only): an outlier must also stand out
    of its neighbourhood, so that noise growing along a maneuver (the nose probe at high AOA) is not
    taken for outliers (good fits: 120 false outliers in 15 estimations without it, 0 with it)."""
    outlier_max_fraction: float = 0.01
    """Above this fraction of outlying samples a channel misfits rather than has outliers."""
    outlier_warn_share: float = 0.1
    """Outliers are a WARNING when they carry more than this share of their channel's residual sum
    of squares in the maneuver (they drag the fit and the 3-sigma accuracy: a 30-deg vane spike
    99 %, a true airspeed dropping to 0 for one sample 99 %) or, for a channel with a stated
    accuracy, when the largest is beyond it; otherwise a NOTE (one nose-probe sample of its
    irregular high-alpha noise at 7 floors, 0.17 deg: 4 % of its maneuver's residual)."""

    # --- slope, units ------------------------------------------------------------------------------
    slope_max_rel_se: float = 0.05
    """A slope is assessed only if its standard error is below this fraction of it."""
    slope_min_signal: float = 3.0
    """... and the model output's standard deviation is above this many floors (or, for the slope
    on the kinematic angle, the angle's above ``slope_ref_min_rad``)."""
    slope_ref_min_rad: float = 0.005
    scale_tol: float = 0.3
    """A slope outside [1 / (1 + tol), 1 + tol] in a channel that misfits is a scale error. Good fits:
    0.88-1.13 where assessable (805 channel-maneuvers), 1.00-1.01 in those above 2 floors."""
    unit_tol: float = 0.07
    """A slope within this relative distance of a unit factor names it. Injected unit errors gave
    slopes within 5 % of their factor; a fit dragged by a stuck vane gave 1.748 (10 % from 1.9438)."""
    flow_unit_min_factor: float = 10.0
    """Flow channels are checked against the factors >= this (or <= its inverse) only: deg/rad (good
    fits: slopes on the kinematic angle 0.58-1.45, upwash and structure; 0.50 and 0.55 with a
    TAS in knots or a flipped accelerometer elsewhere)."""
    floor_jump_tol: float = 0.35
    """A noise floor this close (relative) to a factor >= 10 (57.2958) times the channel's median floor
    over the maneuvers names the unit (good fits: 0.39-2.8 x the median; one maneuver in degrees
    declared as radians: 54.7)."""
    level_tol: float = 0.05
    """A mean level z / y within this of a unit factor names it (absolute quantities: h, tas)."""

    # --- stuck / dead ------------------------------------------------------------------------------
    stuck_min_s: float = 2.0
    """A constant run this long, s ..."""
    stuck_min_samples: int = 10
    """... and of at least this many samples ..."""
    stuck_model_range: float = 5.0
    """... during which the model output moves by more than this many floors or quantisation steps."""
    dead_input_attitude_rad: float = math.radians(1.0)
    """An IMU axis constant while the measured attitude changes by more than this is dead."""
    g_mps2: float = 9.80665
    accel_sign_min_g: float = 0.5
    """A body-z specific force whose maneuver mean is positive and above this (g) is flipped: in
    flight it is -n g cos(theta) cos(phi) (good data: -2.74 to -0.77 g maneuver means; flipped: +0.97
    to +1.52 g). The attitude is not used: an Euler angle in wrong units misled an attitude-based
    check into a false alarm."""
    accel_g_units_min: float = 0.03
    accel_g_units_max: float = 0.25
    """A body-z mean between -0.25 g and -0.03 g (in m/s^2) is a specific force recorded in g but
    declared as m/s^2 (-1 "m/s^2" in level flight); no calibration maneuver averages under 0.25 g."""

    # --- turbulence and colour ---------------------------------------------------------------------
    turbulence_ratio: float = 2.0
    """Flow channels above this many floors ..."""
    turbulence_rho1: float = 0.8
    """... with a lag-1 autocorrelation above this ..."""
    turbulence_corr: float = 0.5
    """... correlated (|r| above this) with another such flow channel of the maneuver."""
    turbulence_max_mean: float = 0.5
    """... whose residual mean is at most this fraction of its RMS ..."""
    turbulence_spread: float = 3.0
    """... and whose residual standard deviations (display units) agree within this factor."""
    coloured_rho1: float = 0.5
    """NOTE "coloured": a lag-1 autocorrelation above this (more than half the residual's variance is
    slow: the Cramér-Rao deviations are optimistic by sqrt((1 + rho1) / (1 - rho1)) > 1.7, which the
    honest deviations take in) in a channel above ``coloured_min_ratio`` floors not flagged
    otherwise (said with the channel's other residual findings, one group). White-noise fits: at
    most 0.40 (resampled noise is mildly coloured itself); real recorded flights: 0.86-0.99; the
    realism level: 0.5-0.99."""
    coloured_min_ratio: float = 1.2


# --------------------------------------------------------------------------------------------------
# the Mach-bin workflow

@dataclass(frozen=True)
class WorkflowOptions:
    """Settings of :func:`~estimator.workflow.run_workflow`.

    Attributes
    ----------
    bin_width : Mach bin width; bins are centred on its multiples.
    max_mach_variation : maneuvers whose Mach varies by more than this are left out.
    min_maneuvers : bins with fewer maneuvers are left out.
    reference_mach : Mach of the bin whose installation biases hold for every bin; None: the model
        set's (``[workflow] reference_mach``, paper: 0.5).
    alpha_band_deg : width of the alpha bands of the usable-alpha search, deg.
    min_band_samples : bands with fewer samples are not judged.
    declarations : what the model set declares (requirements, the bias families apportioned and
        the tables re-estimated, the usable-alpha channel); None: those of the model set the
        problem's channels come from (:func:`~estimator.io.modelset.declarations_of`).
    solver : estimator settings for every estimation (the steps that start from an earlier
        step's estimate start from it: ``start = "given"``).
    progress : called with a line of text as the workflow proceeds.
    """

    bin_width: float = 0.1
    max_mach_variation: float = 0.05
    min_maneuvers: int = 3
    reference_mach: float | None = None
    alpha_band_deg: float = 2.0
    min_band_samples: int = 200
    declarations: Declarations | None = None
    solver: SolverOptions = field(default_factory=SolverOptions)
    progress: Callable[[str], None] | None = None


# --------------------------------------------------------------------------------------------------
# calibrate(): the workflow and its report; the option tables

#: WorkflowOptions fields that are not options of a flat mapping (objects, not settings)
_NOT_FLAT = {"declarations", "solver", "progress"}


def _field_names(cls) -> list[str]:
    return [f.name for f in dataclasses.fields(cls)]


def option_tables() -> dict[str, tuple[str, ...]]:
    """The option names by the TOML table that holds them (a problem file's, a scenario's):
    ``workflow`` (:class:`WorkflowOptions`), ``solver`` (:class:`SolverOptions`) and ``report``
    (``plots``)."""
    return {"workflow": tuple(n for n in _field_names(WorkflowOptions) if n not in _NOT_FLAT),
            "solver": tuple(_field_names(SolverOptions)), "report": ("plots",)}


@dataclass(frozen=True)
class CalibrationOptions:
    """Settings of :func:`~estimator.calibration.calibrate`: the workflow's (its ``solver`` inside)
    and the report's.

    Attributes
    ----------
    workflow : :class:`WorkflowOptions` (bins, reference Mach, the solver's settings in
        ``workflow.solver``); its ``progress`` is replaced by :func:`~estimator.calibration.calibrate`'s.
    plots : draw the report's figures.
    """

    workflow: WorkflowOptions = field(default_factory=WorkflowOptions)
    plots: bool = True

    @classmethod
    def option_names(cls) -> tuple[str, ...]:
        """Every name :meth:`from_mapping` accepts."""
        wf = [n for n in _field_names(WorkflowOptions) if n not in _NOT_FLAT]
        return (*wf, *_field_names(SolverOptions), "plots")

    @classmethod
    def from_mapping(cls, options: Mapping[str, Any] | None = None) -> CalibrationOptions:
        """Options from one flat mapping of names (the CLI's flags, a ``[workflow]``/``[solver]`` table).

        Names are the fields of :class:`WorkflowOptions` (``max_mach_variation``, ``reference_mach``,
        ...), of :class:`SolverOptions` (``max_iterations``, ``colored``, ``start`` -- ``"both"``
        meaning ``("staged", "given")`` --, ...) and ``plots``. A missing name keeps its default.

        Raises
        ------
        ValueError
            an unknown name, with the close match and the valid names.
        """
        options = dict(options or {})
        solver_names, wf_names = set(_field_names(SolverOptions)), set(cls.option_names()) - set(
            _field_names(SolverOptions)) - {"plots"}
        bad = [k for k in options if k not in solver_names | wf_names | {"plots"}]
        if bad:
            raise unknown(bad, cls.option_names(), "", ValueError, what="calibration option")
        solver = {k: v for k, v in options.items() if k in solver_names}
        if solver.get("start") == "both":
            solver["start"] = ("staged", "given")
        wf = {k: v for k, v in options.items() if k in wf_names}
        return cls(workflow=WorkflowOptions(**wf, solver=SolverOptions(**solver)),
                   plots=bool(options.get("plots", True)))
