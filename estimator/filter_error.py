r"""The filter-error method: flight path reconstruction in turbulence, the wind as estimated states.

Why (Jategaonkar 2006, ch. 5; Maine & Iliff 1981): the output-error method integrates the IMU into
the ground-relative motion and asks the flow sensors to see it. In a steady wind that is exact
(the air-relative body velocity obeys the same equation as the ground-relative one, so the free
initial velocities absorb it), but a wind that changes within a maneuver is a disturbance no
parameter models: the flow residuals become coloured, common to every sensor, and the estimates
biased with deviations far too small. Here the turbulent wind is a random process the estimation
tracks.

**The model.** With ``X`` the states the output-error model integrates (initial velocities free),
the air's velocity at a sensor is, exactly in a steady wind ``W0``::

    V_s = X_v + omega x (r_s - r_cg) - C_bn dW(t),      dW = W(t) - W0 (north, east, down)

(``C_bn`` the rotation from NED to body axes), and ``dW`` has three independent first-order
Gauss-Markov components (the Dryden form of MIL-F-8785C, isotropic above 2000 ft)::

    d(dW)/dt = -(V/L) dW + sigma sqrt(2 V / L) eta

or, with ``WindOptions(form="dryden")``, MIL-F-8785C's Dryden turbulence in body axes: the
longitudinal component as above, the lateral and vertical second-order (five states,
:func:`estimator.core.wind_filter.dryden_body`; ``h = -(dy/dV) D``, ``D`` the states' map to the
body-axis wind, and the wind history turned back to NED with the attitude). On JSBSim's
turbulence (turb-type 4, Tustin: that form), it leaves the flow delays as long as the
first-order form does (docs/method.md, the filter-error method).

``L`` the scale length (1750 ft = 533.4 m above 2000 ft), ``sigma`` the turbulence intensity
(estimated per maneuver), ``V`` the maneuver's mean true airspeed. The IMU senses what the gusts
do to the aircraft, so the attitude, altitude and inertial channels do not see ``dW``.
Linearised at the current parameters, a channel's output moves by ``h . dW`` with
``h = -(dy/dV) C_bn`` (``dy/dV``: :attr:`estimator.model.ChannelEval.dydv`), so each maneuver's
residuals ``e = z - y(theta)`` obey a linear state-space model in ``dW`` with the measurement
noise ``R`` (one variance per channel, as in the output-error method).

**The cost** is the negative log-likelihood of the innovations ``nu`` of a Kalman filter on that
model (sequential scalar updates, :mod:`estimator.core.wind_filter`)::

    J(theta) = 1/2 sum_k sum_i (nu_ki^2 / s_ki + ln s_ki),        d nu / d theta = -L_f J

with ``s`` the innovation variances and ``L_f`` the filter acting on the Jacobian's columns, its
gains held at the linearisation (the usual filter-error approximation). The Gauss-Newton
iterations are the output-error ones (:func:`estimator.gauss_newton.gauss_newton`); between their
steps the noise statistics are relaxed (as ``R`` is for output error, Jategaonkar §5.5): ``sigma``
of each maneuver maximises the likelihood with ``R`` held (Brent's search on ``ln sigma``),
and ``R`` of each channel takes its expectation-maximisation update from the fixed-interval
(Rauch-Tung-Striebel) smoother, ``R_c = mean((e - h dW_s)^2 + h P_s h^T)``. With ``sigma`` -> 0
the filter passes the residuals through unchanged and the cost is the output-error one.

Which maneuvers get wind states: by default those whose residuals after an output-error fit
the diagnostics call turbulent (:mod:`estimator.diagnostics`: flow residuals far above their
floors, coloured and common to several sensors while the inertial channels fit), the others
none: a wind state would otherwise take up one sensor's model-structure error too (on calm
JSBSim data the 22-deg wind-up turns came out at 0.9-1.25 m/s from the nose probe's high-alpha
error, and their bin did not converge).

What separates the wind from the flow-sensor calibration: the same ``dW`` is seen by every flow
sensor and by the airspeed, each through its own geometry, while a calibration error belongs to
one sensor and is a function of its flow angle; a constant error of every angle sensor alike is
told from a steady wind only by the heading and attitude changes across the maneuvers (the
Gauss-Markov wind has zero mean: it absorbs a constant only as much as its prior allows).

**The deviations**: Cramér-Rao from the information matrix ``sum J~^T J~`` of the normalised
innovations (``J~ = (d nu / d theta) / sqrt(s)``), and the honest ones the Morelli-Klein sandwich
on the innovations (:func:`estimator.uncertainty.innovation_honest_std`): the Cramér-Rao bound
where the innovations are white, larger where the model leaves them coloured (a scale length ten
times too short: 2.5 times, ``tests/estimator_tests/test_filter_error.py``). Neither sees an error
the innovations do not show: a systematic one the filter fits away as white (on JSBSim's
turbulence, the sideslip biases; docs/method.md). The fit-quality diagnostics judge the innovations
scaled to the measurement noise, ``nu sqrt(R / s)`` (:meth:`FilterErrorLikelihood.predictions`):
outliers, stuck channels, unit errors and gross misfits are found as in the output-error
residuals, and air motion the wind states do not follow still reads as turbulence; what they
cannot see is a moderate scale error the wind states partly take up (a vane scaled 1.1:
innovations at the noise, where the output-error residuals are 1.5-1.9x it).

**Table 2** (measurement minus model, :func:`estimator.workflow.stage_residuals`): the sensor saw
the model's flow plus the turbulent wind, so each channel is compared with the model output plus
its response to the smoothed wind, ``h . dW_s``. But not the wind all channels smoothed: that one
the channel helped shape, and a sensor error the calibration model cannot take (a step in one
vane) would be partly taken for a gust. Each sensor is compared with the wind the *other* sensors
give, its own channels left out of the smoother's measurement updates
(:func:`estimator.core.wind_filter.smooth_left_out`; :func:`wind_responses`)::

    e_i = z_i - y_i(theta) - h_i . E[dW_k | e_j : sensor_j != sensor_i]

(a sensor's channels together: the side probes' sideslip takes their angle of attack as input, and
a fault of the pair shows in both). The left-out wind's own error stays in ``e``, which the sensor
does not have: Table 2 takes its variance ``h_i P_s h_i^T`` (the left-out smoother's) out of the
residual's mean square (:func:`estimator.accuracy.three_sigma`). Analytic flights in the filter's
own turbulence: 0-4 % above the sensors' noise so, 5-14 % with it left in, where the model output
alone is 3-4.5 times it (``tests/estimator_tests/test_filter_error_table2.py``). What no
measurement minus model shows is a calibration error the fit shares out consistently over the
sensors: an aircraft's common sideslip offset, which the wind states leave weakly fixed
(``filter_error_partial``), moves every sideslip channel's bias and the reconstructed sideslip
alike (the demo's light-turbulence block: PT1's sideslip biases 0.21-0.23 deg off at 2.3 honest
deviations; the residual's scatter in its sideslip cells 0.07-0.19 deg against 0.28-0.58 deg
against the truth). Table 2 therefore adds the calibration's own uncertainty to the scatter
(:mod:`estimator.accuracy`, :func:`estimator.workflow.calibration_deviations`): there 0.37-0.40
deg, still short of the boom's 0.58 (over seeds the boom's sideslip cells are 1.25 times optimistic:
docs/validation.md; ``tests/estimator_tests/test_table2_uncertainty.py``).
The filter reruns from the result alone: its values, ``R`` and
:attr:`estimator.result.EstimationResult.wind_model` (the wind states' form, scale length and
each maneuver's intensity); the observations are placed on the samples by the delays at the
estimate (the iterations kept those of their first linearisation: a delay that crossed half a
sample since places a channel one sample apart).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from functools import partial
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import pandas as pd

from estimator.checks import fit_traces
from estimator.core.cross_correlation import high_pass, lagged_correlation
from estimator.core.instrumental import (  # the feedback check (its names were this module's)
    FEEDBACK_LAGS_S,
    FEEDBACK_WEAK,
    DelayCheck,
    instrument_sums,
    iv_difference,
    judge_delays,
    widen_for_feedback,
)
from estimator.core.kinematics import rotation_ned_to_body
from estimator.core.sensitivity import worker_threads
from estimator.diagnostics import DiagnosticOptions, diagnose
from estimator.gauss_newton import gauss_newton, iterate
from estimator.likelihood import Fit, Postlude, Prelude, evaluate
from estimator.model import Evaluation, Model
from estimator.normal_equations import NormalEquations, Structure, residual_sums
from estimator.options import DRYDEN_SCALE_LENGTH_M as DRYDEN_SCALE_LENGTH_M  # re-exported from its old home
from estimator.options import WindOptions
from estimator.problem import AIR_RELATIVE_SIGNALS
from estimator.result import WindModel
from estimator.uncertainty import (
    HonestOptions,
    ManeuverGrid,
    deviations,
    honest_std,
    imu_noise_psd,
    innovation_honest_std,
)
from estimator.verdict import Finding, Severity, Status

if TYPE_CHECKING:
    from estimator.gauss_newton import Iterated
    from estimator.options import SolverOptions
    from estimator.parameters import Parameter
    from estimator.uncertainty import Covariance, Deviations

#: Search bounds of the turbulence intensity, m/s: from next to nothing to severe.
SIGMA_SEARCH_MPS = (1e-3, 15.0)
#: The first relaxation searches all of SIGMA_SEARCH_MPS, the later ones a factor of
#: SIGMA_REFINE_FACTOR either side of the last value, to SIGMA_XTOL in ln(sigma)
SIGMA_REFINE_FACTOR = 1.5
SIGMA_XTOL = 1e-3
#: ... starting from the last value with a parabola through it and SIGMA_STEP (in ln sigma) either
#: side: the negative log-likelihood is smooth in ln sigma, and near its optimum nearly a parabola
SIGMA_STEP = 0.02
#: Rounds at most of the noise relaxation, and the relative change of R and the intensities that
#: ends it (1 %: the weights within 1 % move the estimates by far less than their deviations;
#: 0.1 % cost the 70-maneuver benchmark 3.4 s more, R's EM updates converging only linearly)
RELAX_ROUNDS = 12
RELAX_TOL = 1e-2
#: The noise statistics (R, the intensities; not the linearisation) are kept where the residuals
#: moved by less than this fraction of each channel's noise (rms) since they were relaxed
#: (FilterErrorLikelihood.relax)
HOLD_NOISE_BELOW = 0.01
#: ... and after SETTLE_AFTER relaxations, where they moved by less than SETTLED_BELOW
SETTLE_AFTER = 4
SETTLED_BELOW = 0.1
#: ... and after HOLD_AFTER relaxations, held whatever the residuals do
HOLD_AFTER = 6
#: Output-error iterations at most before the turbulence diagnosis that picks the maneuvers with
#: wind states (FilterErrorLikelihood.before_iterations)
PREFIT_ITERATIONS = 10
#: Filter-error iterations at most before the maneuvers without wind states are diagnosed again
PROBE_ITERATIONS = 5
#: The aircraft's answer to the gusts (FilterErrorLikelihood.answer_findings): a flow channel's
#: innovations against the IMU's specific force along the body axis the channel sees the air on,
#: high-passed over ANSWER_HIGH_PASS_S (a maneuver's own motion is slower; a gust's answer is
#: immediate, lift and side force), at the IMU ANSWER_LAGS_S after the innovation at most (the
#: aircraft's acceleration builds up over a few samples). Reported beyond ANSWER_Z standard errors
#: (Bartlett's; two-sided, at the 5-13 lags tried at 40-120 Hz: at most about 1e-5 false findings
#: per maneuver and channel) and where it explains at least ANSWER_R^2 = 1 % of the innovations'
#: variance.
ANSWER_HIGH_PASS_S = 1.0
ANSWER_LAGS_S = 0.1
ANSWER_Z = 5.0
ANSWER_R = 0.1


@dataclass
class _Maneuver:
    """One maneuver's observations at a linearisation point, sorted by sample."""

    k: int
    n_samples: int
    pieces: list[tuple[int, int, int, int]]  # (channel-eval index, its block, first row, last row + 1)
    order: np.ndarray  # permutation of the concatenated pieces into sample order
    sample: np.ndarray  # (n,) sample index of each observation
    channel: np.ndarray  # (n,) channel index of each observation
    h: np.ndarray  # (n, ns) sensitivity to the wind states (ns = 3 NED, or 5 Dryden body-axis)
    v_mps: float  # mean true airspeed
    c_bn: np.ndarray | None = None  # (n_samples, 3, 3) NED -> body rotation C_bn (Dryden form:
    # the wind history back to NED)


class _Answer(NamedTuple):
    """One maneuver's innovation-IMU correlation beyond the thresholds (answer_findings)."""

    maneuver: str
    r: float
    z: float  # |r| in standard errors
    lag_s: float
    axis: str  # body axis of the IMU's specific force: x, y or z
    t_s: tuple[float, float]  # the maneuver's time span, s
    delays: tuple[str, ...]  # the channel's time-delay parameters


def feedback_findings(parameters: Sequence[Parameter], feedback: Sequence[DelayCheck]
                      ) -> list[Finding]:
    """The feedback check's findings.

    Parameters
    ----------
    parameters : the problem's parameters (``DelayCheck.parameter`` indexes them).
    feedback : the check's judgements (:attr:`estimator.uncertainty.Deviations.feedback`).

    Returns
    -------
    A ``delay_feedback`` note naming the delays widened by the instrumental estimate's
    difference, a ``delay_weak_instrument`` note naming those widened for a weak instrument (notes:
    their honest deviations already say it), a note naming those not judged (each only where there
    are any), deviations in each delay's display unit.
    """
    ps = parameters

    def change(f: DelayCheck) -> tuple[str, float, str]:
        q = ps[f.parameter]
        k, unit = q.display_scale, ("" if q.display_unit in ("", "1") else f" {q.display_unit}")
        lo, hi = q.bounds
        # wider than the allowed range: the flight does not determine the delay at all
        wide = ", wider than its allowed range: not determined by this flight" if (
            math.isfinite(hi - lo) and f.std_after_s > hi - lo) else ""
        return f"{q.key} {f.std_before_s * k:.3g} -> {f.std_after_s * k:.3g}{unit}{wide}", k, unit

    def diff(f: DelayCheck, k: float, unit: str) -> str:
        return (f"instrumental estimate {f.difference_s * k:+.3g}{unit} off"
                + (f", {abs(f.difference_s) / f.difference_std_s:.1f} deviations of the "
                   "difference" if not f.weak else ""))

    judged = [f for f in feedback if math.isfinite(f.std_after_s)]
    differs = [f for f in judged if not f.weak]
    weak = [f for f in judged if f.weak]
    unjudged = [ps[f.parameter].key for f in feedback if not math.isfinite(f.std_after_s)]
    out = []
    if differs:
        parts = []
        for f in differs:
            text, k, unit = change(f)
            parts.append(f"{text} ({diff(f, k, unit)})")
        out.append(Finding(
            "delay_feedback", Severity.NOTE,
            "filter-error method: the time delays' estimate is not what an instrumental-variable "
            f"estimate of the same data gives (each delay's sensitivity {FEEDBACK_LAGS_S[0]:g}-"
            f"{FEEDBACK_LAGS_S[-1]:g} s earlier as its instrument, untouched by the gust at the "
            "sample): the likelihood takes the IMU that drives the state equations as independent "
            "of the innovations, and where the aircraft answers the gusts (gust_answer) it is not, "
            "and the delays come out biased (on JSBSim's light turbulence 4-7 ms long); "
            "innovations coloured by another model error can set the two estimates apart too. "
            "Their honest deviations are widened by the difference (beyond its own noise, in "
            "quadrature): " + "; ".join(parts),
            "read these delays as that uncertain; for delays as sharp as calm air gives, calibrate "
            "them in calm air (the output-error method) and hold them with the sideslip biases "
            "(gust_answer's advice)",
            parameters=tuple(ps[f.parameter].key for f in differs),
            value=max(abs(f.difference_s) / f.difference_std_s for f in differs)))
    if weak:
        parts = []
        for f in weak:
            text, k, unit = change(f)
            parts.append(f"{text} (its instrumental estimate {f.ratio:.1f} times less precise, "
                         f"{diff(f, k, unit)})")
        out.append(Finding(
            "delay_weak_instrument", Severity.NOTE,
            "filter-error method: the feedback check cannot test these time delays, their "
            f"instrument (the sensitivity {FEEDBACK_LAGS_S[0]:g}-{FEEDBACK_LAGS_S[-1]:g} s earlier) "
            f"more than {FEEDBACK_WEAK:g} times less precise than the likelihood: the likelihood "
            "draws its information on them from their sensitivity's fast part, which can be the "
            "aircraft's answer to the gusts, measured by the IMU that drives the state equations "
            "(on JSBSim's light turbulence the airspeed delay came out 0.23-0.31 s long at 5-11 "
            "of the likelihood's honest deviations; where the wind states follow fast the "
            "instrument is weak without any such bias too). Their honest deviations are widened "
            "to what the instrument supports and the difference together: " + "; ".join(parts),
            "read these delays as that uncertain; for a sharp value calibrate them in calm air "
            "(the output-error method) and hold them",
            parameters=tuple(ps[f.parameter].key for f in weak),
            value=max(f.ratio for f in weak)))
    if unjudged:
        out.append(Finding(
            "delay_feedback", Severity.NOTE,
            "filter-error method: the feedback check of the time delays (an instrumental-"
            f"variable estimate against the likelihood's) cannot judge {', '.join(unjudged)}: "
            "after the information matrix's rank cut the difference or the likelihood has no "
            "variance of its own left",
            "read these delays' deviations as the likelihood's alone; a bias from the "
            "aircraft's answer to the gusts would not show in them",
            parameters=tuple(unjudged)))
    return out


@dataclass
class FilterNoise:
    """The noise statistics of a filter-error iterate: ``R`` per channel, ``sigma`` per maneuver,
    and the linearisation (wind sensitivities, observation order) they go with."""

    R: np.ndarray
    sigma_mps: np.ndarray
    maneuvers: list[_Maneuver]
    dt_s: np.ndarray


@dataclass(frozen=True)
class FilterFit(Fit):
    """The filter-error likelihood at the estimate (:meth:`FilterErrorLikelihood.at_estimate`):
    besides the :class:`~estimator.likelihood.Fit`, its findings on the turbulence and the
    aircraft's answer to the gusts, the smoothed wind history and the wind model."""

    wind_findings: tuple[Finding, ...]
    wind: pd.DataFrame | None
    wind_model: WindModel | None


def _missed_note(missed: frozenset[str], when: str) -> str:
    return (f"filter-error method: {when} the diagnostics of the innovations found turbulence in "
            f"{len(missed)} maneuver(s) without wind states ({', '.join(sorted(missed)[:8])}"
            f"{' ...' if len(missed) > 8 else ''}), which the output-error fit had not shown: given "
            "wind states")


class FilterErrorLikelihood:
    """The filter-error cost for :func:`estimator.gauss_newton.gauss_newton` (module docstring), a
    :class:`~estimator.likelihood.Likelihood`."""

    def __init__(self, model: Model, wind: WindOptions | None = None,
                 turbulent: frozenset[str] | None = None):
        """``turbulent``: the ids of the maneuvers that get wind states (None: every one); the
        others are calm throughout."""
        self.model = model
        self.wind = WindOptions() if wind is None else wind
        ids = [m.id for m in model.problem.maneuvers]
        self.windy = np.array([turbulent is None or i in turbulent for i in ids])
        p = model.problem
        self.n_channels = len(p.channels)
        self.dt_s = np.array([float(np.median(np.diff(m.t_s))) for m in p.maneuvers])
        self._R: np.ndarray | None = None
        self._sigma: np.ndarray | None = None
        self._placement: dict[tuple[int, int], np.ndarray] = {}
        self._last: FilterNoise | None = None
        self._relaxed = 0
        self._last_e: list[np.ndarray] = []
        self._fresh = np.zeros(len(ids), dtype=bool)
        # the compiled filter is loaded (and compiled) only when the method is used
        from estimator.core import wind_filter

        self._wf = wind_filter

    def widened(self, turbulent: frozenset[str]) -> FilterErrorLikelihood:
        """A likelihood with wind states in ``turbulent`` maneuvers too, starting from this one's
        noise statistics and observation placement (the new maneuvers' intensities searched over
        the whole range at its first relaxation; relaxed again from there, not held)."""
        out = FilterErrorLikelihood(self.model, self.wind, turbulent)
        out._placement = dict(self._placement)
        if self._R is not None:
            out._R = self._R.copy()
            out._sigma = np.where(out.windy & ~self.windy, 1.0, self._sigma)
            out._fresh = out.windy & ~self.windy
        return out

    # --- the five methods the iterations use ------------------------------------------------
    def evaluate(self, theta: np.ndarray, jacobian: bool) -> Evaluation:
        if not jacobian:
            return evaluate(self.model, theta, False)
        return self.model.evaluate_all(theta, jacobian=True, keep_jacobian=True, wind=True)

    def stats(self, ev: Evaluation) -> Evaluation:
        return ev

    def relax(self, ev: Evaluation, stats) -> FilterNoise:
        """Linearise at ``ev`` (an evaluation with the Jacobian) and relax ``sigma`` and ``R``.

        The linearisation (the wind sensitivities ``h``, which move with the table slopes, scale
        factors and attitude, and the flight speed) is always ``ev``'s, as the filter-error method
        relinearises its system matrices at every iteration (Jategaonkar 2006, ch. 5); what may be
        kept is the noise statistics. Where the residuals moved by less than
        :data:`HOLD_NOISE_BELOW` of each channel's noise since the last relaxation
        (:data:`SETTLED_BELOW` after :data:`SETTLE_AFTER` relaxations), ``R`` and the intensities
        are kept: relaxing again there only moves them within their own tolerance, and the
        Gauss-Newton iterations would chase that (a two-cycle of the cost, 2 in 9e5, along a weakly
        determined table node). After :data:`HOLD_AFTER` relaxations they are held for good, as
        in the alternating scheme of Jategaonkar (2006, §5.5); :meth:`noise_drift` measures what
        the hold left. The estimate is then the fixed point of the iterations: the optimum of the
        likelihood linearised at itself. The iterations towards it are no descent on one cost
        (their gradient leaves out how the linearisation moves with the parameters): where they
        do not settle they end at the iteration limit, a failure the verdict says.

        Why not hold the linearisation with the noise statistics, relinearising only between whole
        runs of iterations: the optimum of a held linearisation is not the fixed point, and where
        the wind states take up part of a sensor's error, each fresh linearisation moves that
        optimum back and forth by several deviations, so the estimate is wherever the last run
        stopped.
        """
        if self._last is not None and (self._relaxed >= HOLD_AFTER or self._moved_little(
                ev, self._last, HOLD_NOISE_BELOW if self._relaxed < SETTLE_AFTER else SETTLED_BELOW)):
            self._last = FilterNoise(self._last.R, self._last.sigma_mps, self._linearise(ev), self.dt_s)
            return self._last
        return self._relax_now(ev)

    def noise_drift(self, ev: Evaluation) -> tuple[float, float]:
        """How far the noise statistics would move if relaxed at ``ev`` once more: the largest
        relative change of a maneuver's intensity and of a channel's ``R`` (the likelihood's state
        left as it was). After :data:`HOLD_AFTER` relaxations the iterations run on held noise
        statistics; this says how far from their own optimum the estimate left them."""
        if self._last is None:
            return 0.0, 0.0
        saved = (self._R, self._sigma, self._last, self._last_e, self._relaxed, self._fresh)
        try:
            new = self._relax_now(ev)
        finally:
            self._R, self._sigma, self._last, self._last_e, self._relaxed, self._fresh = saved
        old = saved[2]
        windy = (old.sigma_mps > 0) | (new.sigma_mps > 0)
        ds = 0.0
        if windy.any():
            ds = float(np.max(np.abs(new.sigma_mps[windy] - old.sigma_mps[windy])
                              / np.maximum(old.sigma_mps[windy], self.wind.calm_sigma_mps)))
        return ds, float(np.max(np.abs(new.R / old.R - 1.0)))

    def _relax_now(self, ev: Evaluation) -> FilterNoise:
        """:meth:`relax` without the hold: linearise at ``ev`` and relax ``sigma`` and ``R``."""
        self._relaxed += 1
        mans = self._linearise(ev)
        if self._R is None:
            sse, cnt = residual_sums(ev, self.n_channels)
            R = np.maximum(np.where(cnt > 0, sse / np.maximum(cnt, 1), 1.0), 1e-16)
        else:
            R = self._R.copy()
        sigma = (np.where(self.windy, 1.0, 0.0) if self._sigma is None else self._sigma.copy())
        # the intensities (R held), then R's EM update (the intensities held) until R settles, then
        # the intensities again, until neither moves: the Gauss-Newton step that follows sees a
        # settled noise model, not one still drifting (an EM update converges only linearly, and
        # each intensity search costs a dozen filter runs, an EM update one smoother run)
        es = [ce.e for ce in ev.channels]
        # the whole search range at the first relaxation, and for maneuvers new to the wind states
        wide_of = np.full(self.windy.size, self._sigma is None) | self._fresh
        self._fresh = np.zeros(self.windy.size, dtype=bool)
        search, settled = True, False
        for _ in range(RELAX_ROUNDS):
            if search:
                wide_now = wide_of.copy()

                def best(m: _Maneuver, R=R, wide_of=wide_now) -> float:
                    before = sigma[m.k]
                    wide = bool(wide_of[m.k])
                    if not self.windy[m.k]:
                        return 0.0
                    if self.wind.sigma_mps is not None:
                        return self.wind.sigma_mps
                    e = self._residuals(ev, m, es)
                    if wide:
                        lo, hi = SIGMA_SEARCH_MPS
                    elif before == 0.0:  # calm before: is it still?
                        lo, hi = SIGMA_SEARCH_MPS[0], SIGMA_REFINE_FACTOR * self.wind.calm_sigma_mps
                    else:
                        lo = max(before / SIGMA_REFINE_FACTOR, SIGMA_SEARCH_MPS[0])
                        hi = min(before * SIGMA_REFINE_FACTOR, SIGMA_SEARCH_MPS[1])
                    s = self._best_sigma(m, e, R, lo, hi, None if wide or before == 0.0 else before)
                    if not wide and s > hi / (1.0 + 10.0 * SIGMA_XTOL):
                        # at the edge of the narrow bracket: the optimum is beyond it
                        s = self._best_sigma(m, e, R, *SIGMA_SEARCH_MPS)
                    return 0.0 if s < self.wind.calm_sigma_mps else s

                before = sigma.copy()
                for m, s in zip(mans, self._map(best, mans), strict=True):
                    sigma[m.k] = s
                moved = max((abs(sigma[m.k] - before[m.k]) / max(before[m.k], 1e-3) for m in mans),
                            default=0.0)
                wide_of[:] = False
                search, settled = False, moved < RELAX_TOL
            R_new = self._em_variances(ev, mans, R, sigma)
            moved_R = float(np.max(np.abs(R_new / R - 1.0)))
            R = R_new
            if moved_R < RELAX_TOL:
                if settled:
                    break
                search = True  # R has settled: the intensities once more
        self._R, self._sigma = R, sigma
        self._last = FilterNoise(R, sigma, mans, self.dt_s)
        self._last_e = [ce.e.copy() for ce in ev.channels]
        return self._last

    def _moved_little(self, ev: Evaluation, noise: FilterNoise, below: float) -> bool:
        """Did every channel's residuals move by less than ``below`` of its noise (rms)?"""
        if len(ev.channels) != len(self._last_e):
            return False
        for ce, e0 in zip(ev.channels, self._last_e, strict=True):
            if ce.e.shape != e0.shape:
                return False
            d = ce.e - e0
            if d.size and np.sqrt(np.mean(d * d) / noise.R[ce.channel]) >= below:
                return False
        return True

    def cost(self, stats: Evaluation, noise: FilterNoise) -> float:
        es = [ce.e for ce in stats.channels]
        parts = self._map(lambda m: self._nll(m, self._residuals(stats, m, es), noise.R,
                                              noise.sigma_mps[m.k]), noise.maneuvers)
        return float(sum(parts))

    def normal(self, st: Structure, ev: Evaluation, noise: FilterNoise) -> NormalEquations:
        return self.normal_of(st, self.normal_blocks(st, ev, noise))

    def normal_blocks(self, st: Structure, ev: Evaluation, noise: FilterNoise) -> list[tuple]:
        """Each maneuver's normal-equation block over the free parameters of ``st`` it depends on:
        ``(k, cols, H, g, nonzeros)``. The filter acts on the Jacobian column by column (its gains
        held), so the block of a structure with fewer free parameters is the sub-block of these
        (:meth:`normal_of`): the identifiability screen filters once, not once per pass."""
        es = [ce.e for ce in ev.channels]

        def blocks(m: _Maneuver):
            cols, J = self._jacobian(ev, m, st)
            nu, s, dnu = self._innovations(m, self._residuals(ev, m, es), noise.R,
                                           noise.sigma_mps[m.k], J)
            w = dnu / np.sqrt(s)[:, None]
            return m.k, cols, w.T @ w, -(w.T @ (nu / np.sqrt(s))), np.count_nonzero(J, axis=0)

        return self._map(blocks, noise.maneuvers)

    @staticmethod
    def normal_of(st: Structure, blocks: list[tuple]) -> NormalEquations:
        """The normal equations of structure ``st`` from :meth:`normal_blocks` of ``st`` or of a
        structure whose free parameters include ``st``'s."""
        N = NormalEquations(st)
        for k, cols, H, g, nz in blocks:
            keep = st.free[cols]
            if not keep.all():
                cols, H, g, nz = cols[keep], H[np.ix_(keep, keep)], g[keep], nz[keep]
            N.add_blocks(H[None], g[None], cols[None], np.array([k]), 1.0)
            np.add.at(N.support, cols, nz)
        return N

    # --- the solver's hooks around the iterations (estimator.likelihood.Likelihood) ------------
    def before_iterations(self, theta: np.ndarray, st: Structure, opt: SolverOptions,
                          evals: Evaluation | None = None) -> Prelude:
        """The maneuvers that get wind states (:meth:`turbulent_maneuvers`), then, where some have
        none, a few filter-error iterations and the maneuvers without wind states whose
        innovations are turbulent given them too (at once, not at the solution: 70 maneuvers, 4
        missed by the output-error fit, 18 filter-error iterations to a solution, 7 more after
        widening). ``evals``: unused (the method evaluates with the wind sensitivities)."""
        theta, turbulent, n_oem = self.turbulent_maneuvers(theta, st, opt)
        lik = self if turbulent is None else FilterErrorLikelihood(self.model, self.wind, turbulent)
        notes, history = [], []
        if turbulent is not None:
            notes.append(
                f"filter-error method: the output-error fit first ({n_oem} iterations); the "
                f"diagnostics found turbulence in {len(turbulent)} of {len(self.model.problem.maneuvers)} "
                "maneuvers, which get wind states; "
                + ("the filter-error iterations start where that fit started" if turbulent else
                   "without them the method is output error, which goes on from that fit"))
        evals = lik.evaluate(theta, True)
        iterations = n_oem
        if lik.windy.any() and not lik.windy.all():
            probe = iterate(self.model, theta, st, replace(
                opt, max_iterations=min(opt.max_iterations, PROBE_ITERATIONS)), evals, lik)
            theta, evals = probe.theta, probe.evals
            iterations += probe.iterations
            history += probe.history
            lik, evals, missed = lik.widened_where_turbulent(st, theta, evals)
            if missed:
                notes.append(_missed_note(missed, f"after {probe.iterations} filter-error iterations"))
        return Prelude(lik, theta, evals, iterations, history, notes)

    def turbulent_maneuvers(self, theta: np.ndarray, st: Structure, opt: SolverOptions
                            ) -> tuple[np.ndarray, frozenset[str] | None, int]:
        """The filter-error method's start, the maneuvers that get its wind states and the
        iterations spent finding them.

        With :class:`~estimator.options.WindOptions` ``where = "diagnosed"`` (the default) an
        output-error fit runs first; the maneuvers whose residuals there the diagnostics call
        turbulent get wind states (at the staged start the diagnostics missed some of the turbulent
        maneuvers: its residuals still carry what the fit removes). The filter-error iterations then
        start from ``theta``, not from that fit: in turbulence the output-error fit is drawn away
        from the filter-error minimum along directions the filter-error iterations then crawl back
        (70 turbulent maneuvers of the estimator benchmark: 38 filter-error iterations to the
        iteration limit from that fit, 10 to convergence from the staged start). Where no maneuver
        is turbulent the method is output error and goes on from that fit. ``"all"``: every
        maneuver (None), from ``theta``.
        """
        if self.wind.where == "all":
            return theta, None, 0
        problem = self.model.problem
        # the diagnostics need the residuals' pattern, not a converged fit: in turbulence the
        # output-error iterations crawl (planning study (c): 3 of 8 light-turbulence fits then started
        # the filter-error iterations from a fit stopped at the 40-iteration limit, and failed)
        it = gauss_newton(self.model, theta, st, replace(opt, max_iterations=min(opt.max_iterations,
                                                                                  PREFIT_ITERATIONS)))
        # any spread between the sensors' residuals: the verdict's turbulence finding asks them to
        # agree within 3x (one gust moves every sensor alike), but a maneuver's gusts can be mostly
        # vertical (study (c), light: alpha 0.46 against sideslip 0.15 deg, 3.02x); left without wind
        # states, that maneuver dragged the filter-error fit to a wrong minimum (a table node 100
        # deviations off), which only the diagnostics of its innovations then caught
        diagnosis = diagnose(*fit_traces(problem, it.evals, st),
                             DiagnosticOptions(g_mps2=problem.g_mps2, turbulence_spread=math.inf))
        turbulent = frozenset(f.maneuver for f in diagnosis.findings if f.code == "turbulence")
        start = it.theta if not turbulent and np.all(np.isfinite(it.theta)) else theta
        return start, turbulent, it.iterations

    def widened_where_turbulent(self, st: Structure, theta: np.ndarray, evals: Evaluation
                                ) -> tuple[FilterErrorLikelihood, Evaluation, frozenset[str]]:
        """``(lik, evals, missed)``: the likelihood with wind states also in the maneuvers without
        them whose innovations (their residuals) the diagnostics call turbulent at ``evals``, the
        evaluation for it and those maneuvers (unchanged, and empty, where every maneuver has wind
        states or none is missed). The output-error fit that chose the maneuvers can miss some:
        the estimator benchmark's 70 turbulent maneuvers, 4 (their turbulence findings then
        failed the verdict)."""
        if self.windy.all():
            return self, evals, frozenset()
        problem = self.model.problem
        noise = self.relax(evals, self.stats(evals))
        diagnosis = diagnose(*fit_traces(problem, evals, st, self.predictions(evals, noise)),
                             DiagnosticOptions(g_mps2=problem.g_mps2, turbulence_spread=math.inf))
        ids = [m.id for m in problem.maneuvers]
        quiet = {i for i, w in zip(ids, self.windy, strict=True) if not w}
        missed = frozenset(f.maneuver for f in diagnosis.findings
                           if f.code == "turbulence" and f.maneuver in quiet)
        if not missed:
            return self, evals, missed
        lik = self.widened(frozenset(i for i, w in zip(ids, self.windy, strict=True) if w) | missed)
        return lik, lik.evaluate(theta, True), missed

    def screen_normal(self, st: Structure, ev: Evaluation
                      ) -> Callable[[Structure], NormalEquations] | None:
        """The identifiability screen at a solution judges by this method's own information (its
        wind states take some of what the output-error residuals show): filtered once for the
        screen's widest structure ``st``, each pass takes its sub-blocks (None before the first
        relaxation)."""
        if self.noise is None:
            return None
        return partial(self.normal_of, blocks=self.normal_blocks(st, ev, self.noise))

    def after_iterations(self, it: Iterated, st: Structure, opt: SolverOptions) -> Postlude:
        """A safety net: the check after the first filter-error iterations can miss a maneuver
        (:meth:`widened_where_turbulent`), which gets wind states and more iterations."""
        lik, iterations, history, notes = self, 0, [], []
        theta, evals = it.theta, it.evals
        missed: frozenset[str] = frozenset()
        if it.status.converged or it.status == Status.ITERATION_LIMIT:
            lik, evals, missed = self.widened_where_turbulent(st, theta, evals)
        if missed:
            it = iterate(self.model, theta, st, opt, evals, lik)
            iterations += it.iterations
            history += it.history
            notes.append(_missed_note(missed, "at its solution") + f" ({it.iterations} iterations)")
        return Postlude(lik, it, iterations, history, notes)

    # --- at the estimate (estimator.likelihood.Likelihood) ----------------------------------
    def at_estimate(self, theta: np.ndarray, st: Structure, ev: Evaluation, it: Iterated,
                    opt: SolverOptions) -> FilterFit:
        """The noise statistics relaxed at the estimate, the cost, the information matrix, the
        findings on the turbulence (:meth:`turbulence_findings`, :meth:`answer_findings`), the
        smoothed wind and the wind model (what Table 2 reruns the smoother with)."""
        noise = self.relax(ev, self.stats(ev))
        cost = self.cost(ev, noise)
        N = self.normal(st, ev, noise)
        drift = self.noise_drift(ev) if self.held else None
        wind_findings = self.turbulence_findings(noise, opt.colored, drift) + self.answer_findings(ev, noise)
        return FilterFit(theta, st, ev, noise, noise.R, cost, N, tuple(wind_findings),
                         self.wind_table(ev, noise), self.wind_model(noise))

    def deviations(self, fit: FilterFit, cov: Covariance, opt: SolverOptions) -> Deviations:
        """The Cramér-Rao deviations of the filter-error information matrix, and (``colored``) the
        honest ones: the coloured innovations' and the IMU noise (:meth:`honest_deviations`)."""
        dev = deviations(self.model, fit.theta, fit.N, fit.st, fit.R, cov, replace(opt, colored=False))
        if opt.colored:
            dev = self.honest_deviations(fit.st, fit.evals, fit.noise, fit.N, dev, opt, fit.theta)
        return dev

    def findings(self, fit: FilterFit, dev: Deviations, opt: SolverOptions) -> list[Finding]:
        """The findings on the turbulence and the gusts' answer, and the feedback check's: where it
        widened every delay an answer finding names, what that finding says is in the honest
        deviations, information (a NOTE); a delay it could not judge keeps the warning."""
        wind_findings = list(fit.wind_findings)
        if opt.colored:
            keys = self.model.problem.parameters.keys
            widened = {keys[f.parameter] for f in dev.feedback if math.isfinite(f.std_after_s)}
            wind_findings = [replace(f, severity=Severity.NOTE)
                             if f.code == "gust_answer" and f.parameters and set(f.parameters) <= widened
                             else f for f in wind_findings]
            wind_findings = wind_findings + feedback_findings(self.model.problem.parameters.parameters,
                                                              dev.feedback)
        return wind_findings

    def result_fields(self, fit: FilterFit) -> dict:
        return {"wind": fit.wind, "wind_model": fit.wind_model}

    def honest_deviations(self, st: Structure, ev: Evaluation, noise: FilterNoise, N: NormalEquations,
                          dev, opt, theta: np.ndarray):
        """``dev`` (the Cramér-Rao :class:`estimator.uncertainty.Deviations`) with the honest
        deviations and correlations: the coloured innovations' (:func:`innovation_honest_std`)
        and the IMU noise as process noise (:func:`honest_std`, ``imu_only``), propagated through
        every channel of the maneuvers without wind states (their innovations are their
        residuals) and, in the others, through the channels that do not see the air (Euler
        angles, altitudes, INS velocities): the gyro noise integrates into the attitude, which no wind state
        follows. Not through the air-relative channels there: with the output-error
        sensitivities and the filter-error information matrix that is meaningless (the initial
        velocities, which the wind states leave nearly free, came out at 150-1300 m/s on study
        (c)'s light turbulence). Without it the gyro biases of a turbulent flight with MEMS IMU
        noise came out 5-11 honest deviations off; with it within 1.7 (review of 7897c6e)."""
        p = self.model.problem
        imu_psd = imu_noise_psd(p, opt.imu_noise)
        std_imu, cov_imu = np.where(np.isfinite(dev.std_crb), 0.0, np.nan), 0.0
        if imu_psd is not None:
            calm = np.ones(len(p.maneuvers), dtype=bool)
            for m in noise.maneuvers:
                calm[m.k] = noise.sigma_mps[m.k] == 0.0
            ground = np.array([not (ch.expression.names & AIR_RELATIVE_SIGNALS) for ch in p.channels])
            std_imu, _, cov_imu = honest_std(
                self.model, theta, N, st, noise.R, dev.std_crb, imu_psd,
                HonestOptions(opt.rank_rtol, imu_only=True, imu_channels=calm[:, None] | ground[None, :]))
        mans = {m.k: m for m in noise.maneuvers}
        is_delay = np.array([q.kind == "time_delay" for q in p.parameters.parameters])
        air = np.array([bool(ch.expression.names & AIR_RELATIVE_SIGNALS) for ch in p.channels])
        # the delays of the channels that see the air, where the loop closes: instrumented in
        # every channel's innovations (the filter's updates carry one channel's delay into the
        # others' innovations)
        instrumented = np.zeros_like(is_delay)
        for ce in ev.channels:
            if air[ce.channel]:
                for b in range(len(ce.mans)):
                    instrumented[[i for i in ce.colmap[b] if is_delay[i]]] = True
        sums: dict[int, tuple] = {}

        def series(k: int):
            if k not in mans:
                return np.zeros(0, dtype=np.intp), []
            cols, chans = self.innovation_series(st, ev, noise, mans[k])
            # the delays' feedback check rides on the same series (one filter pass)
            lags_samples = np.unique(np.maximum(np.rint(np.asarray(FEEDBACK_LAGS_S) / self.dt_s[k]),
                                                1)).astype(np.int64)
            parts = [instrument_sums(rows, J, nu, instrumented[cols], lags_samples)
                     for _, rows, nu, J in chans]
            sums[k] = (cols, [sum(x) for x in zip(*parts, strict=True)] if parts else None)
            return cols, chans

        std, cov = innovation_honest_std(
            N, st, series, ManeuverGrid(np.array([m.n for m in p.maneuvers]), self.dt_s), dev.std_crb,
            rank_rtol=opt.rank_rtol, cross_channel=opt.colored_cross_channel,
            map_fn=lambda fn, ks: self._map(fn, list(ks)))
        std = np.sqrt(std ** 2 + std_imu ** 2)
        cov = cov + cov_imu
        feedback = [f for f in self._delay_feedback(sums, instrumented, st, std, opt.rank_rtol)
                    if not dev.unresolved[f.parameter]]
        std, cov = widen_for_feedback(std, cov, st.gpos, feedback)
        std[dev.unresolved] = np.nan
        std_imu[dev.unresolved] = np.nan
        dh = np.sqrt(np.maximum(np.diag(cov), 1e-300))
        return replace(dev, std_colored=std, correlation_colored=cov / np.outer(dh, dh), std_imu=std_imu,
                       imu_psd=imu_psd, feedback=tuple(feedback))

    def _delay_feedback(self, sums: dict[int, tuple], instrumented: np.ndarray, st: Structure,
                        std: np.ndarray, rank_rtol: float) -> list[DelayCheck]:
        """The feedback check (:func:`judge_delays`) of the delays ``instrumented`` (those of the
        channels that see the air), from the maneuvers' instrument sums."""
        # in maneuver order: the sums are filled by worker threads, the result must not depend on them
        D, V, V_ml = iv_difference([(sums[k][0], *sums[k][1]) for k in sorted(sums)
                                    if sums[k][1] is not None], st.gpos, rank_rtol)
        return judge_delays(D, V, V_ml, instrumented & st.free & (st.gpos >= 0), std)

    def predictions(self, ev: Evaluation, noise: FilterNoise) -> list[np.ndarray]:
        """Every channel's measurement less its innovation scaled to the measurement noise,
        ``z - nu sqrt(R / s)``, laid out as the evaluation's ``ChannelEval.y``: what the fit-quality
        diagnostics judge the measurements against, so that they look at the innovations (white,
        of variance ``R``, where the model, wind included, is right). Scaled, because a
        maneuver's first innovations carry the wind's prior uncertainty too (``s`` >> ``R``): raw,
        they read as outliers at every maneuver's start."""
        es = [ce.e for ce in ev.channels]
        out = [ce.y.copy() for ce in ev.channels]

        def one(m: _Maneuver) -> np.ndarray:
            nu, s, _ = self._innovations(m, self._residuals(ev, m, es), noise.R, noise.sigma_mps[m.k])
            back = np.empty_like(nu)
            back[m.order] = nu * np.sqrt(noise.R[m.channel] / s)  # back to the pieces' order
            return back

        for m, nu in zip(noise.maneuvers, self._map(one, noise.maneuvers), strict=True):
            at = 0
            for ci, _, r0, r1 in m.pieces:
                out[ci][r0:r1] = ev.channels[ci].z[r0:r1] - nu[at:at + r1 - r0]
                at += r1 - r0
        return out

    def innovation_series(self, st: Structure, ev: Evaluation, noise: FilterNoise, m: _Maneuver
                          ) -> tuple[np.ndarray, list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]]:
        """One maneuver's normalised innovations and their Jacobian, per channel, for the
        coloured-innovation deviations (:func:`estimator.uncertainty.innovation_honest_std`).

        Returns the free parameters ``cols`` the maneuver depends on and, per channel, ``(channel,
        samples, nu / sqrt(s), (d nu / d theta) / sqrt(s))`` on the maneuver's sample grid, in time
        order; an observation placed (by its delay) on a sample another of the channel's
        observations already holds (a few at a maneuver's edge) is left out.
        """
        es = [ce.e for ce in ev.channels]
        cols, J = self._jacobian(ev, m, st)
        nu, s, dnu = self._innovations(m, self._residuals(ev, m, es), noise.R, noise.sigma_mps[m.k], J)
        root = np.sqrt(s)
        out = []
        for c in np.unique(m.channel):
            idx = np.flatnonzero(m.channel == c)
            rows, first = np.unique(m.sample[idx], return_index=True)
            idx = idx[first]
            out.append((int(c), rows, nu[idx] / root[idx], dnu[idx] / root[idx, None]))
        return cols, out

    def wind_table(self, ev: Evaluation, noise: FilterNoise) -> pd.DataFrame:
        """The smoothed turbulent wind of every maneuver at ``ev`` (:attr:`EstimationResult.wind`)."""
        parts = []
        es = [ce.e for ce in ev.channels]
        for m in noise.maneuvers:
            man = self.model.problem.maneuvers[m.k]
            xs, Ps = self.wind_ned(m, *self.wind_history(m, self._residuals(ev, m, es), noise.R,
                                                         noise.sigma_mps[m.k]))
            sd = np.sqrt(np.maximum(np.diagonal(Ps, axis1=1, axis2=2), 0.0))
            parts.append(pd.DataFrame({
                "maneuver": man.id, "t_s": man.t_s[:m.n_samples],
                "wind_n_mps": xs[:, 0], "wind_e_mps": xs[:, 1], "wind_d_mps": xs[:, 2],
                "std_n_mps": sd[:, 0], "std_e_mps": sd[:, 1], "std_d_mps": sd[:, 2]}))
        return pd.concat(parts, ignore_index=True)

    def wind_model(self, noise: FilterNoise) -> WindModel:
        """The wind states of ``noise`` as the result keeps them (:attr:`EstimationResult.wind_model
        <estimator.result.EstimationResult.wind_model>`): form, scale length and each maneuver's
        intensity, m/s (0: no wind states)."""
        ids = [m.id for m in self.model.problem.maneuvers]
        return WindModel(self.wind.form, self.wind.scale_length_m,
                         dict(zip(ids, (float(x) for x in noise.sigma_mps), strict=True)))

    def left_out_wind(self, ev: Evaluation, noise: FilterNoise, group: np.ndarray
                      ) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Every channel's response to the wind smoothed from the other groups' channels.

        Parameters
        ----------
        ev : an evaluation with the wind sensitivities (``Model.evaluate_all(..., wind=True)``),
            the one ``noise.maneuvers`` were linearised at.
        noise : the noise statistics (``R`` per channel, the intensities per maneuver).
        group : (n_channels,) int, each channel's group (its sensor): a channel's wind is smoothed
            with every channel of its group left out of the measurement updates.

        Returns
        -------
        Two lists, per channel of ``ev`` (laid out as its ``ChannelEval.y``): ``h . E[dW | the
        other groups' residuals]``, the channel's SI unit, and its variance ``h^T Cov(dW | ...) h``,
        SI squared (:func:`estimator.core.wind_filter.smooth_left_out`); zero in maneuvers
        without wind states and in channels that do not see the air.
        """
        es = [ce.e for ce in ev.channels]
        out = [np.zeros(ce.y.shape) for ce in ev.channels]
        var = [np.zeros(ce.y.shape) for ce in ev.channels]

        def one(m: _Maneuver) -> tuple[np.ndarray, np.ndarray] | None:
            sigma = float(noise.sigma_mps[m.k])
            if sigma == 0.0:
                return None
            Phi, Qd, P0 = self._process(m, sigma)
            p, v = self._wf.smooth_left_out(m.sample, self._residuals(ev, m, es), m.h, noise.R[m.channel],
                                            group[m.channel], self._wf.WindModel(Phi, Qd, P0),
                                            m.n_samples)
            back, back_v = np.empty_like(p), np.empty_like(v)
            back[m.order], back_v[m.order] = p, v  # back to the pieces' order
            return back, back_v

        for m, wv in zip(noise.maneuvers, self._map(one, noise.maneuvers), strict=True):
            if wv is None:
                continue
            at = 0
            for ci, _, r0, r1 in m.pieces:
                out[ci][r0:r1] = wv[0][at:at + r1 - r0]
                var[ci][r0:r1] = wv[1][at:at + r1 - r0]
                at += r1 - r0
        return out, var

    @property
    def noise(self) -> FilterNoise | None:
        """The noise statistics of the last relaxation with the last linearisation (None before the
        first relaxation)."""
        return self._last

    @property
    def held(self) -> bool:
        """Are the noise statistics held for good (:data:`HOLD_AFTER` relaxations done)?"""
        return self._relaxed >= HOLD_AFTER

    def turbulence_findings(self, noise: FilterNoise, colored: bool = True,
                 drift: tuple[float, float] | None = None) -> list[Finding]:
        """What the method estimated of the air, and what it does not yet give (``colored``: the
        deviations are the coloured innovations'; ``drift``: :meth:`noise_drift` at the estimate
        when the noise statistics were held)."""
        p = self.model.problem
        sig = noise.sigma_mps
        calm = [p.maneuvers[k].id for k in np.flatnonzero((sig == 0.0) & self.windy)]
        quiet = [p.maneuvers[k].id for k in np.flatnonzero(~self.windy)]
        if quiet:
            more = " ..." if len(quiet) > 6 else ""
            calm_note = (f"{len(quiet)} maneuver(s) without wind states (the diagnostics found no "
                         f"turbulence there, in the output-error residuals nor in the innovations: "
                         f"{', '.join(quiet[:6])}{more})")
        if not self.windy.any():
            air = f"no maneuver shows turbulence: the estimates are the output-error ones ({calm_note})"
        elif len(calm) + len(quiet) == sig.size and not (sig > 0).any():
            air = (f"every maneuver calm (turbulence intensity below {self.wind.calm_sigma_mps:g} "
                   "m/s): the estimates are the output-error ones"
                   + (f"; {calm_note}" if quiet else ""))
        else:
            lo, hi = int(np.argmin(np.where(sig > 0, sig, np.inf))), int(np.argmax(sig))
            air = (f"turbulence intensity estimated per maneuver, {sig[lo]:.2g} m/s "
                   f"({p.maneuvers[lo].id}) to {sig[hi]:.2g} m/s ({p.maneuvers[hi].id}) (Dryden, L = "
                   f"{self.wind.scale_length_m:g} m)"
                   + (f"; calm (below {self.wind.calm_sigma_mps:g} m/s, no wind states): "
                      f"{', '.join(calm[:8])}{' ...' if len(calm) > 8 else ''}" if calm else "")
                   + (f"; {calm_note}" if quiet else ""))
        if drift is not None:
            air += (f"; the noise statistics held after {HOLD_AFTER} relaxations (at the estimate "
                    f"they would move by {100 * drift[0]:.1f} % (intensity) and {100 * drift[1]:.1f} % "
                    "(measurement noise variance) at most)")
        return [
            Finding("turbulence", Severity.NOTE, f"filter-error method: {air}"),
            Finding("filter_error_partial", Severity.NOTE,
                    "filter-error method: "
                    + ("the honest deviations are the coloured innovations' sandwich and the IMU "
                       "noise as process noise (in turbulent maneuvers through the channels that do "
                       "not see the air only: attitude, altitude, INS velocities)" if colored else
                       "the deviations are Cramér-Rao bounds of its information matrix, without the "
                       "coloured-innovation correction")
                    + "; the method is experimental: on JSBSim's simulated turbulence the flow "
                    "delays come out 4-7 ms long and the airspeed's 0.24-0.31 s off, because the "
                    "aircraft answers the gusts and the IMU that drives the state equations "
                    "measures that answer, which the wind model takes as independent of the motion "
                    "(JSBSim flying through a wind of exactly the filter's form: 12-14 ms long; "
                    "turbulence drawn apart from the flight: within 2.3 ms; not the wind "
                    "states' form nor the sampling rate; the gust_answer warnings name the "
                    "channels and maneuvers whose innovations show that answer"
                    + (", and the feedback check widens the delays' deviations to cover it: "
                       "delay_feedback for the flow delays, delay_weak_instrument for the "
                       "airspeed's" if colored else "") + "); with "
                    "the wind as "
                    "states the flight's kinematics fix an aircraft's common "
                    "sideslip offset (every sideslip channel's bias alike) only to 0.05-0.1 deg, so a "
                    "calibration model that sees the sideslip through an alpha-dependent shape with "
                    "no free reference offset of its own lets that shape fix it, wrongly wherever "
                    "the shape is wrong, with small Cramér-Rao deviations (the paper's vane model: "
                    "an aircraft's offsets 0.19 deg off at 7 of them; the shipped INS model set "
                    "frees the vanes' sideslip reference offset for this, and on JSBSim's "
                    "turbulence they came out 0.14-0.30 deg off at 1.9-3.0 honest deviations on a "
                    "40-Hz time base, 0.38-0.50 deg at 2.4-3.2 on a 120-Hz one, always the same "
                    "way: one side "
                    "probe's installation bias, through the airdata computer's two-probe inversion, "
                    "is a small sideslip error the side probe's model cannot represent, and the "
                    "weakly fixed offset follows it); "
                    "check the estimates against a calm-air calibration before use",
                    "calibrate where the air is calm by the output-error method, or hold the sideslip "
                    "biases and the flow delays together at calm-air values; treat these "
                    "deviations as lower bounds"),
        ]

    def answer_findings(self, ev: Evaluation, noise: FilterNoise) -> list[Finding]:
        """Where the innovations show the aircraft's answer to the gusts, one finding per channel.

        The wind model takes the wind as independent of the motion, but the aircraft answers each
        gust at once (lift, side force, drag) and the IMU that drives the state equations measures
        that answer; the part of each gust the filter has not yet followed is then correlated with
        the IMU, and the flow channels' time delays (whose sensitivity is the flow angles' rate)
        take that correlation up (docs/method.md; campaigns/benchmarks/results/whatif_sideslip.txt). Per
        turbulent maneuver and flow channel: the normalised innovations against the IMU's specific
        force along the body axis of the channel's largest wind sensitivity, high-passed
        (:data:`ANSWER_HIGH_PASS_S`), at lags 0 to :data:`ANSWER_LAGS_S` (IMU after innovation);
        reported where it passes :data:`ANSWER_Z` standard errors and :data:`ANSWER_R`. Its sign
        is no test: the filter's sequential updates within a sample can leave a later channel's
        innovation opposite to an earlier one's (on JSBSim's turbulence the side probe's alpha is
        positive, nearly every other flow channel negative; in the what-if study's calm_motion
        case, where the aircraft did not answer the gusts the sensors see, no channel shows any).
        """
        p = self.model.problem
        es = [ce.e for ce in ev.channels]
        kinds = [q.kind for q in p.parameters.parameters]
        keys = p.parameters.keys
        axes = "xyz"
        hits: dict[int, list[_Answer]] = {}
        tried: dict[int, int] = {}
        for m in noise.maneuvers:
            sigma = float(noise.sigma_mps[m.k])
            if sigma == 0.0:
                continue
            man = p.maneuvers[m.k]
            dt = float(self.dt_s[m.k])
            nu, s, _ = self._innovations(m, self._residuals(ev, m, es), noise.R, sigma)
            nu = nu / np.sqrt(s)
            width = max(int(round(ANSWER_HIGH_PASS_S / dt)), 3)
            acc = high_pass(np.asarray(man.accel_imu_mps2[:m.n_samples], dtype=float), width)
            lags = np.arange(0, int(round(ANSWER_LAGS_S / dt)) + 1)
            for ci, b, r0, r1 in m.pieces:
                ce = ev.channels[ci]
                sens = np.mean(ce.dydv[r0:r1], axis=0)
                if not np.any(sens):
                    continue  # a channel that does not see the air
                ax = int(np.argmax(np.abs(sens)))
                idx = np.flatnonzero(m.channel == ce.channel)
                rows, first = np.unique(m.sample[idx], return_index=True)
                if rows.size < 10 * lags.size:
                    continue
                r, se = lagged_correlation(nu[idx[first]], rows, acc[:, ax], lags, width)
                tried[ce.channel] = tried.get(ce.channel, 0) + 1
                z = np.abs(r) / se
                if not np.isfinite(z).any():
                    continue
                j = int(np.nanargmax(z))
                if z[j] > ANSWER_Z and abs(r[j]) >= ANSWER_R:
                    delays = tuple(keys[i] for i in ce.colmap[b] if kinds[i] == "time_delay")
                    hits.setdefault(ce.channel, []).append(_Answer(
                        man.id, float(r[j]), float(z[j]), float(lags[j] * dt), axes[ax],
                        (float(man.t_s[0]), float(man.t_s[m.n_samples - 1])), delays))
        out = []
        for c, found in hits.items():
            ch = p.channels[c]
            worst = max(found, key=lambda h: abs(h.r))
            rs = [h.r for h in found]
            delays = tuple(dict.fromkeys(k for h in found for k in h.delays))
            what = ("the channel's time delay then comes out too long and its deviation too small "
                    "(JSBSim's simulated turbulence: the flow delays 4-7 ms long at 2.7-4.6 "
                    "deviations at 40 Hz, the airspeed's 0.24-0.31 s, before the feedback check "
                    "widened them: delay_feedback, delay_weak_instrument)" if delays else
                    "the channel's calibration parameters may then be biased beyond their deviations")
            out.append(Finding(
                "gust_answer", Severity.WARNING,
                f"filter-error method: {ch.name}'s innovations correlate with the IMU's specific "
                f"force along body {worst.axis} (high-passed over {ANSWER_HIGH_PASS_S:g} s, up to "
                f"{ANSWER_LAGS_S:g} s later) in {len(found)} of {tried[c]} turbulent maneuvers "
                f"(r = {min(rs):+.2f} to {max(rs):+.2f}; the strongest {worst.maneuver}, "
                f"{worst.t_s[0]:.1f}-{worst.t_s[1]:.1f} s: r = {worst.r:+.2f} at {worst.lag_s:.3f} s, "
                f"{worst.z:.0f} standard errors): the IMU that drives the state equations measures "
                "the aircraft's answer to the gusts (lift, side force, drag), which the wind model "
                "takes as independent of the motion (a sensor that responds to acceleration itself, "
                f"vibration or a vane's mass unbalance, would show the same); {what}",
                "calibrate in calm air (the output-error method), or hold the flow delays together "
                "with the sideslip biases at calm-air values (what-if study: the sideslip sensors' "
                "3 sigma 0.69-0.71 deg with everything free, 0.47-0.50 with the flow delays held, "
                "0.07-0.18 with the delays and sideslip offsets held)",
                channel=ch.name, maneuver=worst.maneuver, t_s=worst.t_s, parameters=delays,
                value=worst.r))
        return out

    # --- the pieces ---------------------------------------------------------------------------
    def _linearise(self, ev: Evaluation) -> list[_Maneuver]:
        seg = ev.seg
        pos = {k: i for i, k in enumerate(ev.maneuvers)}
        per: dict[int, list] = {k: [] for k in ev.maneuvers}
        for ci, ce in enumerate(ev.channels):
            if ce.dydv is None:
                raise ValueError("the filter-error method needs the evaluation's wind sensitivities "
                                 "(Model.evaluate_all(..., wind=True))")
            for b, k in enumerate(ce.mans):
                per[int(k)].append((ci, b, int(ce.rseg[b]), int(ce.rseg[b + 1])))
        out = []
        dryden = self.wind.form == "dryden"
        for k, pieces in per.items():
            i = pos[k]
            X = ev.X[seg[i]:seg[i + 1]]
            C = rotation_ned_to_body(X[:, 3:6])
            samples, chans, hs = [], [], []
            dt = float(self.dt_s[k])
            for ci, _, r0, r1 in pieces:
                ce = ev.channels[ci]
                # a channel recorded with a delay tau shows the air at t - tau: its observation
                # belongs to the wind of that sample (to the nearest sample: the wind's increments
                # over half a sample are a few per cent of its intensity). The placement is taken
                # at the first linearisation and kept: a delay estimate crossing half a sample
                # would otherwise move observations between iterations and the cost with them
                key = (int(ce.channel), int(k))
                if key not in self._placement:
                    self._placement[key] = np.rint(ce.shift_s[r0:r1] / dt).astype(np.int64)
                rows = np.clip(ce.rows[r0:r1] - self._placement[key], 0, seg[i + 1] - seg[i] - 1)
                samples.append(rows)
                chans.append(np.full(rows.size, ce.channel))
                # h = -(dy/dV) C_bn: the output's change per unit NED wind; in the Dryden form the
                # states are body-axis: -(dy/dV) times the states' map to the body-axis wind
                if dryden:
                    hs.append(-ce.dydv[r0:r1] @ self._wf.DRYDEN_OUTPUT)
                else:
                    hs.append(-np.einsum("ni,nij->nj", ce.dydv[r0:r1], C[rows]))
            sample = np.concatenate(samples)
            order = np.argsort(sample, kind="stable")
            out.append(_Maneuver(k, int(seg[i + 1] - seg[i]), pieces, order, sample[order],
                                 np.concatenate(chans)[order], np.concatenate(hs)[order],
                                 float(np.mean(np.linalg.norm(X[:, :3], axis=1))),
                                 C if dryden else None))
        return out

    @staticmethod
    def _residuals(ev: Evaluation, m: _Maneuver, channel_e: list[np.ndarray] | None = None
                   ) -> np.ndarray:
        """The maneuver's residuals in observation order (``channel_e``: every channel's ``e``,
        computed once for all maneuvers: ``ChannelEval.e`` computes ``z - y`` on each access)."""
        es = channel_e if channel_e is not None else [ce.e for ce in ev.channels]
        return np.concatenate([es[ci][r0:r1] for ci, _, r0, r1 in m.pieces])[m.order]

    @staticmethod
    def _map(fn, items: list) -> list:
        """``fn`` over ``items`` (maneuvers: independent), on the estimator's worker threads when
        there are several (the filter and smoother kernels release the GIL); results in order."""
        if worker_threads() > 1 and len(items) > 1:
            with ThreadPoolExecutor(worker_threads()) as ex:
                return list(ex.map(fn, items))
        return [fn(x) for x in items]

    @staticmethod
    def _jacobian(ev: Evaluation, m: _Maneuver, st: Structure) -> tuple[np.ndarray, np.ndarray]:
        """The maneuver's Jacobian (n, c) over the free parameters ``cols`` it depends on."""
        # the block index itself, not a search of its first row: an empty block before it (a
        # maneuver with no sample of the channel in the cost) shares that row
        blocks = [(ev.channels[ci], b, r0, r1) for ci, b, r0, r1 in m.pieces]
        used = np.unique(np.concatenate([ce.colmap[b] for ce, b, _, _ in blocks]))
        cols = used[st.free[used]]
        where = np.full(st.free.size, -1)
        where[cols] = np.arange(cols.size)
        n = m.order.size
        J = np.zeros((n, cols.size))
        at = 0
        for ce, b, r0, r1 in blocks:
            nb = r1 - r0
            for s, col in enumerate(ce.colmap[b]):
                j = where[col]
                if j >= 0:
                    J[at:at + nb, j] += ce.JT[s, r0:r1]
            at += nb
        return cols, J[m.order]

    def wind_history(self, m: _Maneuver, e: np.ndarray, R: np.ndarray, sigma: float):
        """The smoothed wind states (n_samples, ns) of one maneuver and their covariance
        (n_samples, ns, ns) (zero in calm air); :meth:`wind_ned` turns them into the NED wind."""
        ns = m.h.shape[1]
        if sigma == 0.0:
            return np.zeros((m.n_samples, ns)), np.zeros((m.n_samples, ns, ns))
        Phi, Qd, P0 = self._process(m, sigma)
        return self._wf.smooth(m.sample, e, m.h, R[m.channel], self._wf.WindModel(Phi, Qd, P0), m.n_samples)

    @staticmethod
    def wind_ned(m: _Maneuver, xs: np.ndarray, Ps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The turbulent wind (n_samples, 3), NED, m/s, and its covariance (n_samples, 3, 3) from
        the wind states of :meth:`wind_history`."""
        if m.c_bn is None:
            if xs.shape[1] != 3:
                raise ValueError(f"wind_ned: {xs.shape[1]} wind states without the attitude to turn "
                                 "them to NED (a maneuver linearised without C_bn); report this as a bug")
            return xs, Ps
        from estimator.core.wind_filter import DRYDEN_OUTPUT

        T = np.einsum("nji,jk->nik", m.c_bn, DRYDEN_OUTPUT)  # states -> NED: C_bn^T D
        return np.einsum("nij,nj->ni", T, xs), np.einsum("nij,njk,nlk->nil", T, Ps, T)

    def _process(self, m: _Maneuver, sigma: float):
        if self.wind.form == "dryden":
            return self._wf.dryden_body(m.v_mps, self.wind.scale_length_m, sigma, float(self.dt_s[m.k]))
        return self._wf.gauss_markov(m.v_mps, self.wind.scale_length_m, sigma, float(self.dt_s[m.k]))

    def _innovations(self, m: _Maneuver, e: np.ndarray, R: np.ndarray, sigma: float,
                     J: np.ndarray | None = None):
        """Innovations, their variances and (with ``J``) their Jacobian; a calm maneuver's are its
        residuals, ``R`` and ``-J``."""
        if J is None:
            J = np.zeros((e.size, 0))
        r = R[m.channel]
        if sigma == 0.0:
            return e, r, -J
        Phi, Qd, P0 = self._process(m, sigma)
        nu, s, dnu, _ = self._wf.innovations(m.sample, e, m.h, r, J, self._wf.WindModel(Phi, Qd, P0),
                                             m.n_samples)
        return nu, s, dnu

    def _nll(self, m: _Maneuver, e: np.ndarray, R: np.ndarray, sigma: float) -> float:
        nu, s, _ = self._innovations(m, e, R, sigma)
        return 0.5 * float(np.sum(nu * nu / s + np.log(s)))

    def _best_sigma(self, m: _Maneuver, e: np.ndarray, R: np.ndarray, lo_mps: float,
                    hi_mps: float, start_mps: float | None = None) -> float:
        """The intensity in ``[lo, hi]`` of the least negative log-likelihood, to SIGMA_XTOL in
        ``ln sigma``: from ``start`` (the last relaxation's value, near the optimum) by successive
        parabolas (:func:`_parabolic_minimum`, about four filter runs), else, or where that does not
        settle, Brent's bounded search (about eight)."""
        def f(x: float) -> float:
            return self._nll(m, e, R, math.exp(x))

        a, b = math.log(lo_mps), math.log(hi_mps)
        x = None
        if start_mps is not None and lo_mps < start_mps < hi_mps:
            x = _parabolic_minimum(f, math.log(start_mps), a, b, SIGMA_STEP, SIGMA_XTOL)
        if x is not None:
            return math.exp(x)
        # imported here: scipy.optimize takes half a second to import, and only this search needs it
        from scipy.optimize import minimize_scalar

        res = minimize_scalar(f, bounds=(a, b), method="bounded", options={"xatol": SIGMA_XTOL})
        return math.exp(float(res.x))

    def _em_variances(self, ev: Evaluation, mans: list[_Maneuver], R: np.ndarray,
                      sigma: np.ndarray) -> np.ndarray:
        """``R_c = mean((e - h dW_s)^2 + h P_s h^T)`` over the channel's observations (smoother)."""
        es = [ce.e for ce in ev.channels]

        def expected_square(m: _Maneuver) -> np.ndarray:
            e = self._residuals(ev, m, es)
            if sigma[m.k] == 0.0:
                return e * e
            xs, Ps = self.wind_history(m, e, R, sigma[m.k])
            r = e - np.einsum("ni,ni->n", m.h, xs[m.sample])
            return r * r + np.einsum("ni,nij,nj->n", m.h, Ps[m.sample], m.h)

        num = np.zeros(self.n_channels)
        cnt = np.zeros(self.n_channels)
        for m, sq in zip(mans, self._map(expected_square, mans), strict=True):
            np.add.at(num, m.channel, sq)
            np.add.at(cnt, m.channel, 1.0)
        return np.maximum(np.where(cnt > 0, num / np.maximum(cnt, 1), R), 1e-16)


def sensor_groups(model: Model) -> np.ndarray:
    """(n_channels,) int: each channel's group for :meth:`FilterErrorLikelihood.left_out_wind`,
    one per sensor (``Channel.sensor``), a channel without a sensor a group of its own."""
    names = [ch.sensor if ch.sensor is not None else f"channel:{ch.name}"
             for ch in model.problem.channels]
    first = {n: i for i, n in reversed(list(enumerate(names)))}
    return np.array([first[n] for n in names], dtype=np.int64)


def wind_responses(model: Model, values: np.ndarray, R: np.ndarray, wind: WindModel
                   ) -> tuple[Evaluation, list[np.ndarray]]:
    """The model's outputs at ``values`` and each channel's response to the turbulent wind the
    other sensors give (module docstring, Table 2): what each sensor saw is ``ce.y + w``.

    Parameters
    ----------
    model : the model of the estimated problem.
    values : (P,) the estimate, SI.
    R : (n_channels,) each channel's measurement-noise variance at the estimate (the filter's
        ``R``; :attr:`EstimationResult.R <estimator.result.EstimationResult.R>` in channel order),
        SI squared.
    wind : the estimate's wind states (:attr:`EstimationResult.wind_model
        <estimator.result.EstimationResult.wind_model>`), naming every maneuver of the problem.

    Returns
    -------
    ev : the evaluation at ``values`` (with the wind sensitivities ``dydv``, without the Jacobian).
    w : per channel of ``ev``, laid out as its ``ChannelEval.y``: ``h . E[dW | the other sensors'
        residuals]``, the channel's SI unit (:meth:`FilterErrorLikelihood.left_out_wind`,
        :func:`sensor_groups`); zero where the maneuver has no wind states or the channel does
        not see the air.
    w_var : per channel likewise, the variance of ``w`` (the smoother's, conditional on the
        estimate and the wind model), SI squared.

    Raises
    ------
    ValueError
        ``wind`` does not name a maneuver of the problem, or ``R`` is not one positive variance per
        channel.
    """
    p = model.problem
    missing = [m.id for m in p.maneuvers if m.id not in wind.sigma_mps]
    if missing:
        raise ValueError(f"wind_responses: the wind model names no intensity for maneuver(s) "
                         f"{', '.join(missing[:5])}: give the wind model of this problem's estimate")
    R = np.asarray(R, dtype=float)
    if R.shape != (len(p.channels),) or not np.all(R > 0.0):
        raise ValueError(f"wind_responses: R must be one positive variance per channel "
                         f"({len(p.channels)}), got {R!r}")
    sigma = np.array([wind.sigma_mps[m.id] for m in p.maneuvers])
    lik = FilterErrorLikelihood(model, WindOptions(scale_length_m=wind.scale_length_m, form=wind.form),
                                frozenset(m.id for m, s in zip(p.maneuvers, sigma, strict=True) if s > 0))
    # the wind sensitivities come with the Jacobian pass; the Jacobian itself is not kept
    ev = model.evaluate_all(np.asarray(values, dtype=float), jacobian=True, keep_jacobian=False, wind=True)
    noise = FilterNoise(R, sigma, lik._linearise(ev), lik.dt_s)
    w, w_var = lik.left_out_wind(ev, noise, sensor_groups(model))
    return ev, w, w_var


def _parabolic_minimum(f, x0: float, lo: float, hi: float, step: float, xtol: float,
                       max_evals: int = 12) -> float | None:
    """The minimum of a smooth ``f`` on ``[lo, hi]`` near ``x0``, by successive parabolic
    interpolation, or ``None`` (the caller then searches the whole bracket).

    From ``x0 - step, x0, x0 + step``, the next point is the vertex of the parabola through the
    lowest point so far and its neighbours (both sides where it has them; a jump at most four times
    their span, within the bounds); where the neighbours lie more than four times farther on one
    side than on the other, a point twice the near distance towards the far one instead (one-sided
    parabolas converge slowly). A vertex within ``xtol`` of the lowest point is returned only from
    a parabola through that point and neighbours at most ``step`` either side (else those two are
    evaluated first): its error is then about ``step^2 |f3| / (6 f2)`` (``f2``, ``f3`` the second
    and third derivatives; with ``step`` = 0.02 in ln sigma and a log-likelihood's ``|f3 / f2|`` of
    a few, 1e-4 or less). A bound is returned only where ``f`` is known one ``step`` inside it and
    the parabola through the bound and its two nearest points has its vertex beyond it (or within
    ``xtol``), and ``f`` one ``xtol`` inside it is not lower. ``None`` where the points are not
    convex about the lowest one, a vertex repeats a point, or ``max_evals`` evaluations do not
    settle it.
    """
    x0 = min(max(x0, lo), hi)
    xs = sorted({max(x0 - step, lo), x0, min(x0 + step, hi)})
    if len(xs) < 3:
        return None
    fs = [f(x) for x in xs]
    tol = step * (1.0 + 1e-9)
    while len(xs) < max_evals:
        order = sorted(range(len(xs)), key=xs.__getitem__)
        at = min(range(len(order)), key=lambda i: fs[order[i]])  # the lowest, in x order
        best = xs[order[at]]
        inside = 0 < at < len(order) - 1
        # the lowest point and its neighbours either side (a bracket), else its two on one side
        pick = order[max(0, min(at - 1, len(order) - 3)):][:3]
        (a, fa), (b, fb), (c, fc) = ((xs[i], fs[i]) for i in pick)
        d1 = (fb - fa) / (b - a)
        curv = ((fc - fb) / (c - b) - d1) / (c - a)  # half the second derivative
        span = c - a
        if best in (lo, hi) and not inside:
            # the minimum at a bound: once f is known one step inside, and the parabola through
            # the bound and its two nearest points has its vertex beyond it (or within xtol)
            nearest = min((x for x in xs if x != best), key=lambda x: abs(x - best))
            if abs(nearest - best) > tol:
                v = best + step if best == lo else best - step
            else:
                v = 0.5 * (a + b) - d1 / (2.0 * curv) if curv > 0.0 else best
                if not (lo < v < hi) or abs(v - best) < xtol:
                    # the parabola is a model of f: confirm that f a tolerance inside is not
                    # lower, else hand over (hypothesis found a minimum 0.002 inside the bound,
                    # where the parabola put it beyond)
                    inward = best + xtol if best == lo else best - xtol
                    return best if f(inward) >= fs[xs.index(best)] else None
            if v in xs:
                return None
            xs.append(v)
            fs.append(f(v))
            continue
        near, far = sorted((b - a, c - b))
        if inside and far > 4.0 * near:
            v = best + (2.0 * near if c - b == far else -2.0 * near)
        elif curv > 0.0:
            v = 0.5 * (a + b) - d1 / (2.0 * curv)
        elif inside:
            return None  # a bracket that is not convex: not the smooth function this is for
        else:  # downhill to a side, not convex there: step on
            v = best + (2.0 * span if at else -2.0 * span)
        v = min(max(v, best - 4.0 * span, lo), best + 4.0 * span, hi)
        if abs(v - best) < xtol:
            if inside and b - a <= tol and c - b <= tol:
                return v
            # not yet a local bracket: the lowest point's neighbours one step either side first
            new = [x for x in (max(best - step, lo), min(best + step, hi)) if x not in xs]
            if not new:
                return None
            for x in new:
                xs.append(x)
                fs.append(f(x))
            continue
        if v in xs:  # the parabolas repeat a point without settling
            return None
        xs.append(v)
        fs.append(f(v))
    return None
