r"""Maximum-likelihood output-error estimation for many maneuvers at once: :func:`estimate`.

Cost (Jategaonkar 2006, §4.3), residuals ``e = z - y`` of channel ``c`` at sample ``i``::

    J(theta, R) = 1/2 sum_c sum_i e_ci^2 / R_c + 1/2 sum_c N_c ln R_c

``R`` (diagonal, one variance per channel) is estimated in closed form from the residuals between
Gauss-Newton steps (relaxation strategy, §4.10); the Gauss-Newton steps solve the normal equations
in their arrow structure (:mod:`estimator.normal_equations`), Levenberg-Marquardt-damped, bounds
as an active set.

Convergence is judged on the *undamped* Gauss-Newton step ``M^-1 g`` (bounds active), never on a
step the damping shrank: converged when it is below ``step_tol_sigma`` Cramér-Rao deviations for
every parameter, or when the decrease it predicts, ``g^T M^-1 g / 2`` (log-likelihood units), is
below ``decrease_tol``, or when no step achieves more than ``decrease_tol`` (then along the
undamped direction too; a poor quadratic model there is reported). Status codes follow scipy's
convention (:class:`~estimator.verdict.Status`: positive = converged). A converged minimum may
still be wrong: the verdict (:mod:`estimator.verdict`) also weighs the fit-quality diagnostics
(:mod:`estimator.diagnostics`: residuals against each channel's own noise floor, stuck channels,
unit errors, outliers, turbulence) and the identifiability checks.

Start: by default a staged, data-driven start (:mod:`estimator.start`) fits the attitude, then
speed and height, then the flow channels before the full estimation, so that large IMU biases
from zero start values reach the right minimum.

Identifiability is judged where it matters, at the solution (and, for what needs no residuals,
before the iterations): parameters no sample depends on (a table breakpoint beyond the flown
range) and combinations the data cannot separate (a free table offset beside free biases: one
member of each such set is held, the fewest that restore the rank) are held at their start
values; at the solution, a parameter whose Cramér-Rao deviation exceeds half its allowed range is
held too, and the estimation iterates again. Each held parameter keeps its reason
(:attr:`EstimationResult.state`).

Standard deviations: Cramér-Rao, ``sqrt(diag(M^-1))``, with the correlations; and the honest ones
(:mod:`estimator.uncertainty`): coloured and cross-correlated residuals with a modelled spectrum,
and the IMU's noise as process noise.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
from threadpoolctl import threadpool_limits

from estimator.model import Evaluation, Model, ModelEvaluationError
from estimator.normal_equations import (
    NormalEquations,
    Structure,
    bounded_solve,
    build_normal,
    channel_variances,
    full_step,
    lm_solve,
    ml_cost,
    residual_sums,
    sym_inverse,
)
from estimator.problem import STATE_PARAMS, Problem
from estimator.result import Confounding, EstimationResult, ResidualStats
from estimator.start import staged_plan
from estimator.uncertainty import honest_std, imu_noise_psd
from estimator.verdict import Finding, Severity, Status, judge

#: Start strategies: the staged, data-driven start (:mod:`estimator.start`) or the problem's values.
STARTS = ("staged", "given")


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

    def __post_init__(self) -> None:
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



def _confounded_sets(null: np.ndarray, idx: np.ndarray, problem: Problem, where: str
                     ) -> list[tuple[Confounding, int]]:
    """Each null direction as a confounded set, with the one member to hold so the rank returns.

    The member held is one that takes a large part in the direction (at least half the largest
    component), a table value before a bias or scale (a free table offset beside free biases:
    anchoring the table keeps the biases, which carry the installation, free), then the largest.
    The outputs are the same whichever member is held: only how the set shares the combination.
    """
    ps = problem.parameters
    out = []
    chosen: set[int] = set()
    for j in range(null.shape[1]):
        v = np.abs(null[:, j])
        order = np.argsort(-v)
        members = [int(idx[i]) for i in order if v[i] > 0.15 * v.max()]
        cands = [int(idx[i]) for i in order if v[i] >= 0.5 * v.max() and int(idx[i]) not in chosen]
        cands = cands or [m for m in members if m not in chosen] or members
        hold = min(cands, key=lambda i: (ps.parameters[i].kind != "table", cands.index(i)))
        chosen.add(hold)
        names = [ps.parameters[i].key for i in members]
        out.append((Confounding(
            parameters=tuple(names),
            kind="unidentifiable",
            detail=(f"{where}: the data cannot tell {', '.join(names[:8])}"
                    f"{' ...' if len(names) > 8 else ''} apart (a combination of "
                    f"them leaves every output unchanged); {ps.parameters[hold].key} is held at its "
                    "start value to anchor the others, whose estimates are relative to it. Fix one "
                    "of them yourself, or fly maneuvers that excite them differently"),
        ), hold))
    return out


@dataclass(frozen=True)
class _Hold:
    """Parameters held at their start values by the identifiability screen, and why."""

    params: tuple[int, ...]
    kind: str  # "no_data", "unidentifiable" or "undetermined"
    confounding: Confounding


def _screen(problem: Problem, st: Structure, evals: Evaluation, R: np.ndarray, opt: SolverOptions,
            loose: bool) -> tuple[Structure, list[_Hold]]:
    """Hold the parameters the data do not determine; returns the new structure and the holds.

    Parameters no sample depends on (a table breakpoint beyond the flown range, a bias of a sensor
    an aircraft does not carry) and combinations the data cannot separate (one member per null
    direction) are held. With ``loose``, so is a parameter whose Cramér-Rao deviation exceeds half
    its allowed range (a pressure-altitude scale in level flight). Judged away from the solution,
    where ``R`` holds the residuals of a wrong trajectory, the deviations are inflated: the
    estimation therefore judges every requested parameter again at its solution.
    """
    ps = problem.parameters
    keys = ps.keys
    holds: list[_Hold] = []
    for _ in range(12):
        if not st.free.any():
            break
        N = build_normal(st, evals, R)
        no_data = st.free & ~_has_data(N, st, opt.min_support_samples)
        if no_data.any():
            held = tuple(int(i) for i in np.nonzero(no_data)[0])
            holds.append(_Hold(held, "no_data", Confounding(
                parameters=tuple(keys[i] for i in held), kind="no_data",
                detail=(f"fewer than {opt.min_support_samples} samples depend on these parameters "
                        "(e.g. a table breakpoint outside the flown range, or a sensor this aircraft "
                        "does not carry); held at their start values"))))
            st = Structure(problem, st.free & ~no_data)
            continue
        cov_G, cov_L, unident, _ = _covariance(N, st, problem, opt)
        if unident:
            free = st.free.copy()
            for conf, hold in unident:
                free[hold] = False
                holds.append(_Hold((hold,), "unidentifiable", conf))
            st = Structure(problem, free)
            continue
        if loose:
            std = _std_of(st, cov_G, cov_L, len(keys))
            width = st.hi - st.lo
            bad = st.free & np.isfinite(width) & (std > 0.5 * width)
            if bad.any():
                held = tuple(int(i) for i in np.nonzero(bad)[0])
                holds.append(_Hold(held, "undetermined", Confounding(
                    parameters=tuple(keys[i] for i in held), kind="undetermined",
                    detail=("the data barely depend on these parameters: at the solution their "
                            "Cramér-Rao deviation exceeds half their allowed range (bounds); held at "
                            "their start values"))))
                st = Structure(problem, st.free & ~bad)
                continue
        break
    return st, holds


def _has_data(N: NormalEquations, st: Structure, min_support: int) -> np.ndarray:
    """(P,) the free parameters some information and at least ``min_support`` samples depend on."""
    info = np.zeros(st.free.size)
    info[st.glob] = np.diag(N.HGG)
    for k, idx in enumerate(st.local_of_arr):
        info[idx] = np.diag(N.HLL[k])
    return st.free & (info > 0.0) & (N.support >= min_support)


def _std_of(st: Structure, cov_G: np.ndarray, cov_L: list[np.ndarray], n: int) -> np.ndarray:
    std = np.full(n, np.nan)
    std[st.glob] = np.sqrt(np.maximum(np.diag(cov_G), 0.0))
    for k, idx in enumerate(st.local_of_arr):
        if idx.size:
            std[idx] = np.sqrt(np.maximum(np.diag(cov_L[k]), 0.0))
    return std


@dataclass
class _Iterated:
    """What a Gauss-Newton run left: the iterate, its evaluation and how it ended."""

    theta: np.ndarray
    evals: Evaluation
    sse: np.ndarray
    cnt: np.ndarray
    status: Status
    message: str
    iterations: int
    history: list[float]
    step_sigma: float  # the last undamped Gauss-Newton step, in deviations (largest)
    poor: tuple[str, ...] = ()  # where that step exceeded a deviation at convergence (poor model)


def _evaluate(model: Model, theta: np.ndarray, jacobian: bool) -> Evaluation:
    # the iterations need each block's normal-equation terms, not the Jacobian itself: fresh
    # memory for it each time costs more (page by page from the operating system) than
    # evaluating the last iterate once more for the Morelli-Klein deviations
    return model.evaluate_all(theta, jacobian=jacobian, keep_jacobian=False)


def _gauss_newton(model: Model, theta: np.ndarray, st: Structure, opt: SolverOptions,
                  evals: Evaluation | None = None, label: str = "") -> _Iterated:
    """Levenberg-Marquardt-safeguarded Gauss-Newton iterations with relaxation of ``R`` (module
    docstring) until the undamped step is negligible."""
    nch = len(model.problem.channels)
    keys = model.problem.parameters.keys
    theta = theta.copy()
    if evals is None:
        evals = _evaluate(model, theta, True)
    sse, cnt = residual_sums(evals, nch)
    lam = opt.lm_lambda0
    history: list[float] = []
    status, message = Status.ITERATION_LIMIT, ""
    moved_max = np.inf
    poor: tuple[str, ...] = ()
    it = 0
    order = np.concatenate([st.glob] + [v for v in st.local_of_arr if v.size]).astype(int)
    for it in range(1, opt.max_iterations + 1):
        R = channel_variances(sse, cnt)
        cost0 = ml_cost(sse, cnt, R)
        history.append(cost0)
        N = build_normal(st, evals, R)
        # the undamped Gauss-Newton step judges convergence: a damped one shrinks with the damping
        gn, _, _, Sinv, Ainv, _ = bounded_solve(N, st, theta, 0.0, opt.rank_rtol)
        sig = np.zeros(theta.size)
        sig[st.glob] = np.diag(Sinv)
        for k, idx in enumerate(st.local_of_arr):
            if idx.size:
                sig[idx] = np.diag(Ainv[k])
        sig = np.sqrt(np.maximum(sig, 1e-300))
        moved = np.abs(gn[order]) / sig[order]
        moved_max = float(moved.max()) if moved.size else 0.0
        predicted = 0.5 * float(gn @ full_step(st, N.gG, N.gL, theta.size))
        if moved_max < opt.step_tol_sigma:
            status = Status.CONVERGED_STEP
            message = (f"converged: the undamped Gauss-Newton step is {moved_max:.1e} deviations at "
                       f"most (< {opt.step_tol_sigma})")
            break
        if predicted < opt.decrease_tol:
            status = Status.CONVERGED_DECREASE
            message = (f"converged: the Gauss-Newton model predicts a further cost decrease of "
                       f"{max(predicted, 0.0):.1e} (< {opt.decrease_tol}); largest step "
                       f"{moved_max:.1e} deviations")
            break
        best = None  # (decrease, iterate, its evaluation, sse, cnt, evaluated with the Jacobian)
        evaluated = 0  # trial points the model could be evaluated at
        for attempt in range(12):
            step = bounded_solve(N, st, theta, lam, opt.rank_rtol)[0]
            trial = np.clip(theta + step, st.lo, st.hi)
            try:
                # the first trial is usually accepted and is then the next iterate: evaluate it
                # with the Jacobian right away (the values are the same either way)
                trial_ev = _evaluate(model, trial, attempt == 0)
            except ModelEvaluationError:
                # the step left the model's domain (e.g. a table steeper than 1:1 in an implicit
                # model): a rejected step, damped further
                lam = max(lam, 1e-6) * 10.0
                continue
            evaluated += 1
            sse_t, cnt_t = residual_sums(trial_ev, nch)
            cost_t = ml_cost(sse_t, cnt_t, R)
            if np.isfinite(cost_t) and cost_t < cost0:
                best = (cost0 - cost_t, trial, trial_ev, sse_t, cnt_t, attempt == 0)
                break
            lam = max(lam, 1e-6) * 10.0
        if best is None or best[0] < max(opt.decrease_tol, 0.1 * predicted):
            # the damped steps achieve (next to) nothing: search along the undamped Gauss-Newton
            # direction itself, whose quadratic model can be poor along a parameter the data barely
            # determine (one that enters the outputs only to second order, like v0 without a
            # sideslip channel). What no step achieves, the minimum does not offer either.
            for t in 10.0 ** -np.arange(0, 9):
                trial = np.clip(theta + t * gn, st.lo, st.hi)
                try:
                    trial_ev = _evaluate(model, trial, False)
                except ModelEvaluationError:
                    continue
                evaluated += 1
                sse_t, cnt_t = residual_sums(trial_ev, nch)
                cost_t = ml_cost(sse_t, cnt_t, R)
                if np.isfinite(cost_t) and cost0 - cost_t > (best[0] if best else 0.0):
                    best = (cost0 - cost_t, trial, trial_ev, sse_t, cnt_t, False)
        if not evaluated:
            status = Status.STALLED
            message = ("stalled: the model cannot be evaluated at any step from here (each leaves its "
                       f"domain; e.g. an implicit model that does not converge); the undamped "
                       f"Gauss-Newton step is {moved_max:.2g} deviations")
            break
        if best is None or best[0] < opt.decrease_tol:
            if best is not None:  # take the little there is
                theta, sse, cnt = best[1], best[3], best[4]
                evals = _evaluate(model, theta, True)
            achieved = best[0] if best is not None else 0.0
            poor = tuple(keys[order[i]] for i in np.argsort(-moved) if moved[i] >= 1.0)
            if moved_max < 10.0 * opt.step_tol_sigma:
                # within a tenth of a deviation of the minimum, where round-off (or a kink of an
                # interpolated delay or table) keeps the cost from decreasing any further
                status = Status.CONVERGED_STEP
                message = (f"converged: the undamped Gauss-Newton step is {moved_max:.1e} deviations "
                           f"at most; no step decreases the cost by more than {achieved:.1e} (round-off)")
            elif best is None:
                # not even a tiny step along the gradient lowers the cost: the gradient does not
                # describe the cost here (a kink, a model or Jacobian fault), so this is no minimum
                status = Status.STALLED
                message = (f"stalled: no step decreases the cost at all (damping grew to {lam:.1e}, and "
                           "along the undamped direction too), yet the Gauss-Newton model predicts "
                           f"{predicted:.3g} with a step of {moved_max:.2g} deviations "
                           f"({keys[order[int(np.argmax(moved))]]}): the gradient does not describe "
                           "the cost here")
            else:
                status = Status.CONVERGED_DECREASE
                message = (f"converged: no step decreases the cost by more than {achieved:.1e} "
                           f"(< {opt.decrease_tol}), although the Gauss-Newton model predicts "
                           f"{predicted:.3g} with a step of {moved_max:.2g} deviations "
                           f"({', '.join(poor[:4]) or keys[order[int(np.argmax(moved))]]}): the "
                           "quadratic model is poor there")
            break
        decrease, theta, trial_ev, sse, cnt, with_jac = best
        lam = max(lam * 0.1, 1e-9)
        evals = trial_ev if with_jac else _evaluate(model, theta, True)
        if opt.verbose:
            rel = decrease / max(abs(cost0), 1e-300)
            print(f"{label}iteration {it:3d}: cost {cost0: .6e}, rel. decrease {rel:.2e}, undamped step "
                  f"{moved_max:.2e} sigma ({keys[order[int(np.argmax(moved))]]}), lambda {lam:.1e}")
    else:
        message = (f"not converged: iteration limit ({opt.max_iterations}) reached; the undamped "
                   f"Gauss-Newton step is still {moved_max:.2g} deviations")
    return _Iterated(theta, evals, sse, cnt, status, message, it, history, moved_max, poor)


def estimate(problem: Problem, options: SolverOptions | None = None) -> EstimationResult:
    """Estimate the free parameters of ``problem`` by maximum likelihood (output error).

    Parameters
    ----------
    problem : the problem (data, channel models, parameters with start values).
    options : solver settings.

    Returns
    -------
    EstimationResult with estimates, Cramér-Rao and coloured-residual deviations, correlations,
    residual statistics, the solver status, the fit-quality findings and the verdict.

    Raises
    ------
    ValueError
        For a problem that cannot be estimated as asked: no free parameter, or no channel with data
        (the message says which and how to fix it). Everything that goes wrong in the estimation
        itself — the model leaving its domain, nothing determined, no convergence, a fault in the
        data — is a result with a failure verdict, not an exception.

    Notes
    -----
    Runs with one BLAS thread (restored on return): every matrix here is small, and waking
    OpenBLAS's worker threads for each of them costs more than the arithmetic.
    """
    opt = options or SolverOptions()
    starts = (opt.start,) if isinstance(opt.start, str) else tuple(dict.fromkeys(opt.start))
    with threadpool_limits(limits=1, user_api="blas"):
        best: EstimationResult | None = None
        tried = []
        for s in starts:
            res = _estimate_robust(problem, replace(opt, start=s))
            tried.append(f"{s}: {res.verdict.name.lower()}, cost {_final_cost(res):.6g}")
            if best is None or _rank(res) < _rank(best):
                best = res
        assert best is not None
        if len(starts) > 1:
            best = best.with_findings((Finding(
                "starts", Severity.INFO,
                f"estimated from {len(starts)} starts ({'; '.join(tried)}); the best verdict, then the "
                "lowest cost, is kept"),))
        return best


def _final_cost(res: EstimationResult) -> float:
    return res.cost_history[-1] if res.cost_history else np.inf


def _rank(res: EstimationResult) -> tuple[int, float]:
    return res.verdict.rank, _final_cost(res)


def _estimate_guarded(problem: Problem, opt: SolverOptions) -> EstimationResult:
    """:func:`_estimate`, with a numerical breakdown (the model leaving its domain, a singular
    matrix) turned into a failed result: a verdict, not an exception, for data that cause it."""
    t0 = time.perf_counter()
    try:
        return _estimate(problem, opt)
    except (ModelEvaluationError, np.linalg.LinAlgError) as exc:
        return _failed(problem, problem.parameters.values, t0,
                       f"the estimation broke down numerically: {type(exc).__name__}: {exc}",
                       "read the channel named; check its data and units, or start closer to the data")


def _estimate_robust(problem: Problem, opt: SolverOptions) -> EstimationResult:
    """:func:`_estimate`, and with ``opt.robust`` once more without the outliers it found."""
    res = _estimate_guarded(problem, opt)
    if not opt.robust or not res.outliers:
        return res
    excluded = dict(res.outliers)
    sub = _without_samples(problem, excluded)
    sub = replace(sub, parameters=sub.parameters.with_values(res.values))
    again = _estimate_guarded(sub, replace(opt, start="given"))
    notes = tuple(Finding(
        "excluded", Severity.INFO,
        f"robust option: {t.size} outlier sample(s) of {ch} in maneuver {man} excluded from the fit "
        f"(at t = {', '.join(f'{v:.3f}' for v in t[:5])}{' ...' if t.size > 5 else ''} s)",
        channel=ch, maneuver=man, t_s=tuple(float(v) for v in t)) for (man, ch), t in excluded.items())
    return again.with_findings(notes, iterations=res.iterations)


def _without_samples(problem: Problem, samples: dict[tuple[str, str], np.ndarray]) -> Problem:
    """The problem with some samples of some channels removed (NaN: not in the cost)."""
    col = {c.name: c.column for c in problem.channels}
    mans = []
    for m in problem.maneuvers:
        meas = dict(m.measurements)
        for (man, ch), t in samples.items():
            if man != m.id or col.get(ch) not in meas:
                continue
            v = np.array(meas[col[ch]], dtype=float)
            idx = np.searchsorted(m.t_s, t)
            idx = idx[(idx < m.t_s.size)]
            idx = idx[np.isclose(m.t_s[idx], t[: idx.size], atol=1e-9 + 1e-6 * m.dt_s)]
            v[idx] = np.nan
            meas[col[ch]] = v
        mans.append(replace(m, measurements=meas))
    return replace(problem, maneuvers=tuple(mans))


def _staged_start(problem: Problem, theta: np.ndarray, free: np.ndarray, opt: SolverOptions
                  ) -> tuple[np.ndarray, list[str]]:
    """Run the stages of :func:`estimator.start.staged_plan` from ``theta``; returns the last
    stage's estimate and one line per stage."""
    notes = []
    for stage in staged_plan(problem, free):
        sub = replace(problem, channels=tuple(problem.channels[i] for i in stage.channels))
        model = Model(sub)
        try:
            ev = _evaluate(model, theta, True)
        except ModelEvaluationError as exc:
            notes.append(f"start stage {stage.name}: skipped ({exc})")
            continue
        st = Structure(sub, stage.free)
        # a stage frees only what its channels depend on; the rest waits for a later stage
        N = build_normal(st, ev, np.ones(len(sub.channels)))
        st = Structure(sub, stage.free & _has_data(N, st, opt.min_support_samples))
        if not st.free.any():
            continue
        it = _gauss_newton(model, theta, st, opt, ev, label=f"start ({stage.name}) ")
        theta = it.theta
        notes.append(f"start stage {stage.name}: {len(stage.channels)} channels, {int(st.free.sum())} "
                     f"free, {it.iterations} iterations, {it.status.name.lower()}")
        if opt.verbose:
            print(notes[-1])
    return theta, notes


def _estimate(problem: Problem, opt: SolverOptions) -> EstimationResult:
    t0 = time.perf_counter()
    model = Model(problem)
    ps = problem.parameters
    nch = len(problem.channels)
    requested = ps.free_mask
    if not requested.any():
        raise ValueError(f"{problem.source}: no free parameters; free some in the problem file")
    lo = np.array([p.bounds[0] for p in ps])
    hi = np.array([p.bounds[1] for p in ps])
    start = np.clip(ps.values, lo, hi)
    theta = start.copy()
    try:
        evals = _evaluate(model, theta, True)
    except ModelEvaluationError as exc:
        return _failed(problem, start, t0, f"the model cannot be evaluated at the start values: {exc}",
                       "check the units and signs of the channel named (a measurement far outside its "
                       "model's range cannot be fitted), or give start values closer to the data")
    sse, cnt = residual_sums(evals, nch)
    if not cnt.any():
        raise ValueError(f"{problem.source}: no channel has data in any maneuver")
    stage_notes: list[str] = []
    if opt.start == "staged":
        staged, stage_notes = _staged_start(problem, theta, requested, opt)
        try:
            # the stages fit subsets of the channels: an implicit channel left out may be outside
            # its domain where they ended; then the full estimation starts from the given values
            evals = _evaluate(model, staged, True)
            theta = staged
        except ModelEvaluationError as exc:
            stage_notes.append(f"the staged start is left: the full model cannot be evaluated where it "
                               f"ended ({exc}); the estimation starts from the given values")
        sse, cnt = residual_sums(evals, nch)
    # the screen before the iterations also holds what looks undetermined there, which keeps a
    # parameter the data hardly see from wandering to a bound on the way; the screen at the
    # solution judges every requested parameter again, and frees what the data determine there
    st, holds = _screen(problem, Structure(problem, requested), evals, channel_variances(sse, cnt), opt,
                        loose=True)
    if not st.free.any():
        return _failed(problem, theta, t0, "no free parameter is determined by the data: "
                       + "; ".join(f"{h.kind}: {', '.join(h.confounding.parameters[:12])}" for h in holds),
                       "fly maneuvers that excite the parameters asked for, or fix them in the problem file",
                       Status.UNDETERMINED)
    held = requested & ~st.free
    stage_notes += _restore_held(model, theta, start, held)
    evals = _evaluate(model, theta, True)
    iterations, history = 0, []
    for rnd in range(1, max(opt.screen_rounds, 1) + 1):
        try:
            it = _gauss_newton(model, theta, st, opt, evals)
        except ModelEvaluationError as exc:  # cannot happen after a successful start: a safeguard
            return _failed(problem, theta, t0, str(exc), "report this as a bug, with the data")
        theta, evals = it.theta, it.evals
        iterations += it.iterations
        history += it.history
        if not it.status.converged or rnd == opt.screen_rounds:
            break
        # identifiability at the solution: the whole screen again, from the requested free set
        st_new, holds_new = _screen(problem, Structure(problem, requested), evals,
                                    channel_variances(it.sse, it.cnt), opt, loose=True)
        if np.array_equal(st_new.free, st.free):
            holds = holds_new
            break
        stage_notes += _restore_held(model, theta, start, st.free & ~st_new.free)
        st, holds = st_new, holds_new
        evals = _evaluate(model, theta, True)
    return _finish(problem, model, theta, start, st, holds, evals, it, iterations, history, stage_notes,
                   opt, t0)


def _restore_held(model: Model, theta: np.ndarray, start: np.ndarray, held: np.ndarray) -> list[str]:
    """Put newly held parameters back at their start values (in place), unless the model cannot be
    evaluated there (an implicit model whose table the start values make steeper than 1:1 next to
    estimated neighbours): then they stay where the estimation left them, and a note says so."""
    moved = held & (theta != start)
    if not moved.any():
        return []
    trial = theta.copy()
    trial[moved] = start[moved]
    try:
        _evaluate(model, trial, False)
    except ModelEvaluationError as exc:
        keys = model.problem.parameters.keys
        return [f"{', '.join(keys[i] for i in np.flatnonzero(moved))} held at the values the estimation "
                f"had reached, not at their start values: the model cannot be evaluated there ({exc})"]
    theta[moved] = start[moved]
    return []


def _failed(problem: Problem, theta: np.ndarray, t0: float, why: str, advice: str,
            status: Status = Status.MODEL_ERROR) -> EstimationResult:
    """A result for an estimation that could not run (the model fails, nothing is determined)."""
    n = len(problem.parameters)
    nan = np.full(n, np.nan)
    requested = problem.parameters.free_mask
    return EstimationResult.build(
        problem=problem, values=theta, std_crb=nan, std_colored=nan, correlation_keys=(),
        correlation=np.zeros((0, 0)), R={}, residuals=(), iterations=0, cost_history=(),
        status=status, message=why, confounding=(), elapsed_s=time.perf_counter() - t0,
        free_estimated=np.zeros(n, dtype=bool),
        state=tuple("fixed" if not f else "not estimated" for f in requested),
        state_reason=tuple("" if not f else "the estimation failed" for f in requested),
        findings=(Finding(status.name.lower(), Severity.FAILURE, why, advice),),
    )


def _finish(problem, model, theta, start, st, holds, evals, it, iterations, history, stage_notes, opt, t0
            ) -> EstimationResult:
    """Covariances, diagnostics, findings and verdict at the estimate."""
    ps = problem.parameters
    keys = ps.keys
    requested = ps.free_mask
    R = channel_variances(it.sse, it.cnt)
    history = history + [ml_cost(it.sse, it.cnt, R)]
    N = build_normal(st, evals, R)
    cov_G, cov_L, unident, correlated = _covariance(N, st, problem, opt)
    std = _std_of(st, cov_G, cov_L, len(keys))
    confounding = [h.confounding for h in holds]
    # a set still unidentifiable here (the screen's rounds ran out): no deviation means anything
    unresolved = np.zeros(len(keys), dtype=bool)
    for conf, _ in unident:
        confounding.append(conf)
        unresolved[[ps.index(k) for k in conf.parameters]] = True
    std[unresolved] = np.nan
    dg = np.sqrt(np.maximum(np.diag(cov_G), 1e-300))
    corr_G = cov_G / np.outer(dg, dg)
    correlated = correlated + _high_correlations(corr_G, [keys[i] for i in st.glob], opt.correlation_warn)
    confounding += correlated
    std_col = np.full(len(keys), np.nan)
    std_imu = np.full(len(keys), np.nan)
    corr_honest = np.full_like(corr_G, np.nan)
    imu_psd = imu_noise_psd(problem, opt.imu_noise) if opt.colored else None
    unread = sorted(a for a, v in (imu_psd or {}).items() if not np.all(np.isfinite(v)))
    if unread:
        findings_pre = [Finding(
            "imu_noise_unknown", Severity.WARNING,
            f"the IMU noise level could not be read off the data of {', '.join(unread)} (every maneuver "
            "shorter than 64 samples): the honest deviations leave the IMU noise out, and the IMU "
            "biases' and initial conditions' deviations may be several times too small",
            "give the IMU's noise densities (SolverOptions.imu_noise: datasheet random walks, squared, SI)")]
    else:
        findings_pre = []
    if opt.colored:
        std_col, std_imu, cov_hon = honest_std(model, theta, N, st, R, std, imu_psd,
                                               rank_rtol=opt.rank_rtol,
                                               cross_channel=opt.colored_cross_channel,
                                               spectrum=opt.colored_spectrum)
        std_col[unresolved] = np.nan
        std_imu[unresolved] = np.nan
        dh = np.sqrt(np.maximum(np.diag(cov_hon), 1e-300))
        corr_honest = cov_hon / np.outer(dh, dh)
    # what each parameter is: estimated, on a bound, held (why) or fixed
    state, reason = [], []
    why = {i: h for h in holds for i in h.params}
    tiny = 1e-9 * np.maximum(1.0, np.abs(theta))
    for i, p in enumerate(ps):
        if not requested[i]:
            state.append("fixed")
            reason.append("fixed in the problem (model set or problem file)")
        elif not st.free[i]:
            h = why.get(i)
            state.append("held")
            reason.append({"no_data": f"no data: fewer than {opt.min_support_samples} samples depend on it",
                           "undetermined": "undetermined: its Cramér-Rao deviation exceeds half its "
                                           "allowed range",
                           "unidentifiable": "unidentifiable: " + (h.confounding.detail if h else "")
                           }.get(h.kind if h else "", "held")
                          + ("" if theta[i] == start[i] else "; held where the estimation left it, not at "
                             "its start value (the model cannot be evaluated there)"))
        elif unresolved[i]:
            state.append("unidentifiable")
            reason.append("unidentifiable at the solution: " + next(c.detail for c, _ in unident
                                                                   if p.key in c.parameters))
        elif theta[i] <= st.lo[i] + tiny[i] or theta[i] >= st.hi[i] - tiny[i]:
            state.append("on_bound")
            side = "lower" if theta[i] <= st.lo[i] + tiny[i] else "upper"
            unit = "" if p.unit in ("", "1") else f" {p.unit}"  # "0.5", not "0.5 1"
            reason.append(f"on its {side} bound {theta[i]:.6g}{unit}: the data push it beyond; the "
                          "estimate is the bound")
        else:
            state.append("estimated")
            reason.append("")
    # which maneuvers inform each global parameter (its coupling block with their locals)
    informs = {keys[g]: {problem.maneuvers[k].id for k in range(len(problem.maneuvers))
                         if N.HGL[k].shape[1] and np.any(N.HGL[k][j] != 0.0)}
               for j, g in enumerate(st.glob)}
    findings = findings_pre + _parameter_findings(problem, holds, unident, correlated, state, reason, opt,
                                                  informs)
    if imu_psd is not None and np.isfinite(std_imu).any():
        inflation = np.where(st.free, np.sqrt(1.0 + (std_imu / np.where(std > 0, std, np.nan)) ** 2), np.nan)
        worst = int(np.nanargmax(inflation)) if np.isfinite(inflation).any() else -1
        levels = "; ".join(
            f"{a}: accelerometers {np.nan_to_num(np.sqrt(v[:3])).max():.2g} m/s/sqrt(s), gyros "
            f"{np.degrees(np.nan_to_num(np.sqrt(v[3:]))).max() * 60.0:.2g} deg/sqrt(h)"
            for a, v in imu_psd.items())
        source = "from the data" if opt.imu_noise == "estimate" else "as given"
        most = (f", most to {keys[worst]} ({inflation[worst]:.2g} x its Cramér-Rao deviation)"
                if worst >= 0 else "")
        findings.append(Finding(
            "imu_noise", Severity.INFO,
            f"IMU noise integrated as process noise ({source}: {levels}) adds to the coloured "
            f"deviations{most}",
            "give the IMU's datasheet random walks (SolverOptions.imu_noise) if the data's own level, "
            "which counts vibration as noise, is too pessimistic"))
    findings += [Finding("start", Severity.INFO, "; ".join(stage_notes))] if stage_notes else []
    if it.poor:
        findings.append(Finding(
            "poor_model", Severity.WARNING,
            f"at the estimate the Gauss-Newton model is poor along {', '.join(it.poor[:6])}: it predicts a "
            f"step of {it.step_sigma:.2g} deviations, yet no step decreases the cost; the data barely "
            "determine these parameters (to first order), so their deviations are not to be trusted",
            "fix them at known values, or add channels or maneuvers that see them (e.g. a sideslip "
            "sensor for v0)", parameters=it.poor))
    if not it.status.converged:
        findings.append(Finding(
            "not_converged", Severity.FAILURE, it.message,
            "raise --max-iterations if the step was still shrinking; otherwise read the other findings: "
            "a fault in the data or a wrong minimum stops the iteration too"))
    diagnosis_table, outliers = None, {}
    if opt.diagnose:
        from estimator.diagnostics import DiagnosticOptions, diagnose

        diagnosis = diagnose(*_fit_traces(problem, evals, st), DiagnosticOptions(g_mps2=problem.g_mps2))
        # the data's findings first: a fault in the data explains the parameters' findings, not the
        # other way round (findings are shown by severity, in this order within one)
        # parameters on a bound that can cause a residual finding rather than follow from it: a
        # channel's time delays, and the state equations' (IMU biases, initial conditions) of the
        # finding's maneuver. Not tables or scales: gusts push those onto their bounds themselves.
        on_bound: dict[str, list[str]] = {}
        for i, s in enumerate(state):
            p = ps.parameters[i]
            if s == "on_bound" and p.name in STATE_PARAMS:
                on_bound.setdefault(p.instance, []).append(p.key)
            elif s == "on_bound" and p.kind == "time_delay":
                on_bound.setdefault("*", []).append(p.key)
        findings = [_beside_bounds(f, on_bound) for f in diagnosis.findings] + findings
        diagnosis_table, outliers = diagnosis.table, dict(diagnosis.outliers)
    verdict = judge(it.status, findings)
    message = it.message
    return EstimationResult.build(
        std_imu_noise=std_imu, imu_noise_psd=imu_psd,
        problem=problem, values=theta, std_crb=std, std_colored=std_col,
        correlation_keys=tuple(keys[i] for i in st.glob), correlation=corr_G,
        correlation_colored=corr_honest,
        R=dict(zip((c.name for c in problem.channels), R, strict=True)),
        residuals=_stats(problem, evals), iterations=iterations, cost_history=tuple(history),
        status=it.status, message=message, confounding=tuple(confounding),
        elapsed_s=time.perf_counter() - t0, free_estimated=st.free.copy(), state=tuple(state),
        state_reason=tuple(reason), findings=tuple(findings), verdict=verdict,
        fit_quality=diagnosis_table, outliers=outliers,
    )


#: Residual patterns a parameter stopped at its bound produces as well as the data's own faults.
_BOUND_MIMICS = frozenset({"turbulence", "misfit", "scale_error", "noise_floor", "coloured"})


def _beside_bounds(f: Finding, on_bound: dict[str, list[str]]) -> Finding:
    """A residual finding whose channels' parameters sit on a bound names them as a possible cause.

    A parameter the data push beyond its bound leaves exactly the residual it could not absorb: flow
    delays of 400 ms against bounds of +-300 ms leave coloured flow residuals common to every sensor,
    which read as turbulence; IMU biases beyond theirs leave kinematic misfits (planning study (c)).
    The finding keeps its severity; it now says the bound may be the cause, and to widen it before
    blaming the air or the sensor. ``on_bound``: maneuver id -> its state-equation parameters on a
    bound, ``"*"`` -> the time delays on a bound.
    """
    hit = [k for k in f.parameters if k in on_bound.get("*", ())] + list(on_bound.get(f.maneuver or "", ()))
    if f.code not in _BOUND_MIMICS or not hit:
        return f
    names = ", ".join(hit)
    return replace(
        f, message=f"{f.message}; or the bound{'s' if len(hit) > 1 else ''} of {names}, where "
        + ("the estimates stopped: the data push them beyond" if len(hit) > 1 else
           "the estimate stopped: the data push it beyond"),
        advice=f"if the range of {names} in the problem file is too narrow for this installation, widen "
        f"the bounds of {names} and estimate again (a delay or IMU bias beyond its bound leaves this "
        f"pattern too); if it stays: {f.advice}")


def _parameter_findings(problem, holds, unident, correlated, state, reason, opt, informs) -> list[Finding]:
    """Findings of the identifiability checks: held parameters (INFO when the data simply do not
    reach them, WARNING when a confounded set was anchored), parameters on a bound (WARNING),
    highly correlated pairs (INFO: their deviations already say it)."""
    ps = problem.parameters
    out = []
    # the screen holds one member of a confounded set at a time: overlapping sets are one finding
    groups: list[tuple[set[str], list[str]]] = []
    for h in holds:
        if h.kind != "unidentifiable":
            continue
        members = set(h.confounding.parameters)
        held = [ps.parameters[i].key for i in h.params]
        for g in groups:
            if g[0] & members:
                g[0].update(members)
                g[1].extend(held)
                break
        else:
            groups.append((members, held))
    for members, held in groups:
        names = sorted(members, key=ps.index)
        out.append(Finding(
            "unidentifiable", Severity.WARNING,
            f"the data cannot tell {', '.join(names[:10])}{' ...' if len(names) > 10 else ''} apart "
            f"(combinations of them leave every output unchanged): {', '.join(held)} "
            f"{'is' if len(held) == 1 else 'are'} held at the start value(s), the fewest that make the "
            "rest determined, whose estimates are then relative to them",
            "fix the one you know in the problem file, or fly maneuvers that excite them differently",
            parameters=tuple(names)))
    for h in holds:
        names = ", ".join(h.confounding.parameters[:12]) + (" ..." if len(h.params) > 12 else "")
        if h.kind == "unidentifiable":
            continue
        elif h.kind == "no_data":
            out.append(Finding("held", Severity.INFO, f"held at their start values, no data: {names} "
                               f"({h.confounding.detail.split(';')[0]})",
                               parameters=h.confounding.parameters))
        else:
            out.append(Finding("held", Severity.INFO, f"held at their start values, undetermined: {names} "
                               "(their Cramér-Rao deviation exceeds half their allowed range)",
                               "fly maneuvers that excite them, or fix them at known values",
                               parameters=h.confounding.parameters))
    for conf, _ in unident:
        out.append(Finding("unidentifiable", Severity.WARNING, conf.detail,
                           "fix one of them in the problem file", parameters=conf.parameters))
    for i, s in enumerate(state):
        if s == "on_bound":
            p = ps.parameters[i]
            # a calibration result (a table value, a bias, a delay, an IMU bias) on its bound is not a
            # measurement; a maneuver's nuisance scale or offset (k_h in level flight) is only noted
            nuisance = p.scope == "maneuver" and p.kind in ("scale", "bias")
            out.append(Finding("on_bound", Severity.INFO if nuisance else Severity.WARNING,
                               f"{p.key} is {reason[i]}",
                               "the data want it outside its physical range: check the data of the "
                               "channels it enters (units, signs, a fault) before widening the bounds",
                               parameters=(p.key,)))
    # a calibration parameter that trades against the initial conditions of every maneuver that
    # informs it is the confounding an engineer must not miss (a sideslip bias against the initial
    # sideslip): no maneuver separates the two but through weak kinematic couplings, and any
    # error of those goes into it
    calib = {p.key for p in ps if p.kind in ("bias", "scale", "table") and p.scope != "maneuver"}
    ics = {p.key for p in ps if p.kind == "initial_condition"}
    against: dict[str, list[str]] = {}
    for c in correlated:
        a, b = c.parameters
        if a in ics and b in calib:
            against.setdefault(b, []).append(a)
        elif b in ics and a in calib:
            against.setdefault(a, []).append(b)
        else:
            out.append(Finding("correlated", Severity.INFO, f"{' and '.join(c.parameters)}: {c.detail}",
                               parameters=c.parameters))
    man_of = {p.key: p.instance for p in ps if p.scope == "maneuver"}
    for key, partners in against.items():
        if not informs.get(key) or not informs[key] <= {man_of[k] for k in partners}:
            for k in partners:
                out.append(Finding("correlated", Severity.INFO, f"{k} and {key}: correlation above "
                                   f"{opt.correlation_warn}; the data barely separate them in that "
                                   "maneuver (other maneuvers do)", parameters=(k, key)))
            continue
        out.append(Finding(
            "confounded", Severity.WARNING,
            f"{key} is confounded with the initial condition(s) {', '.join(partners[:6])}"
            f"{' ...' if len(partners) > 6 else ''} of every maneuver that informs it (|correlation| > "
            f"{opt.correlation_warn}): the data separate the offset it adds to the flow angle from the "
            "maneuvers' own initial flow angle only through weak kinematic couplings, and any error "
            "there goes into it",
            "fly maneuvers that vary that flow angle (a steady-heading sideslip for a sideslip bias, "
            "a pull-up for an angle-of-attack bias), or fix it at a known value",
            parameters=(key, *partners)))
    return out


def _fit_traces(problem: Problem, ev: Evaluation, st: Structure):
    """The diagnostics' inputs: every channel of every maneuver at the estimate, and each
    maneuver's IMU inputs and reconstructed states."""
    from estimator.diagnostics import ChannelFit, ManeuverInputs

    ps = problem.parameters
    keys = ps.keys
    fits = []
    for ce in ev.channels:
        ch = problem.channels[ce.channel]
        for b, k in enumerate(ce.mans):
            m = problem.maneuvers[int(k)]
            r0, r1 = ce.rseg[b], ce.rseg[b + 1]
            rows = ce.rows[r0:r1]
            meas = np.asarray(m.measurements[ch.column], dtype=float)
            fin = np.isfinite(meas)
            # the channel model's own free parameters (not the state equations')
            params = tuple(dict.fromkeys(keys[i] for i in ce.colmap[b]
                                         if st.free[i] and ps.parameters[i].name not in STATE_PARAMS))
            fits.append(ChannelFit(
                maneuver=m.id, channel=ch.name, flow=ch.sensor is not None, t_s=m.t_s[rows],
                z=ce.z[r0:r1], y=ce.y[r0:r1], measured_t_s=m.t_s[fin], measured=meas[fin], unit=ch.unit,
                display_scale=ch.display_scale, display_unit=ch.display_unit, parameters=params))
    pos = {int(k): i for i, k in enumerate(ev.maneuvers)}
    col = {c.name: c.column for c in problem.channels}
    inputs = []
    for k, m in enumerate(problem.maneuvers):
        if k not in pos:
            continue
        X = ev.X[ev.seg[pos[k]]:ev.seg[pos[k] + 1]]
        eul = np.full((m.n, 3), np.nan)
        for j, name in enumerate(("phi", "theta", "psi")):
            c = col.get(name)
            if c is not None and c in m.measurements:
                eul[:, j] = m.measurements[c]
        inputs.append(ManeuverInputs(maneuver=m.id, t_s=m.t_s, accel_imu_mps2=m.accel_imu_mps2,
                                     omega_rps=m.omega_rps, states=X, euler_measured_rad=eul))
    return fits, inputs



def _covariance(N: NormalEquations, st: Structure, problem: Problem, opt: SolverOptions):
    """Undamped Cramér-Rao covariance of the global block and of each local block.

    Returns
    -------
    (S^-1, [cov_L_k], unidentifiable sets with the member to hold, correlated global-local pairs)
    """
    keys = problem.parameters.keys
    extra: dict = {}
    _, _, Sinv, Ainv = lm_solve(N, 0.0, opt.rank_rtol, extra)
    # rank checks: the Schur complement (globals) and each local block (undamped: lambda = 0)
    _, null = sym_inverse(extra["S"], opt.rank_rtol)
    unident = _confounded_sets(null, st.glob, problem, "global parameters")
    cov_L = []
    for k, Ai in enumerate(Ainv):
        idx = st.local_of_arr[k]
        if not idx.size:
            cov_L.append(np.zeros((0, 0)))
            continue
        unident += _confounded_sets(extra["null_L"][k], idx, problem, f"maneuver {problem.maneuvers[k].id}")
        B = Ai @ N.HGL[k].T
        cov_L.append(Ai + B @ Sinv @ B.T)
    # correlations across the blocks: Cov(local_k, global) = -A_k^-1 M_LkG S^-1. A per-maneuver
    # initial condition that trades against a fleet-wide bias is exactly the confounding an
    # engineer must see (SPEC §5), and it lives in these blocks, not in the global one
    thr = opt.correlation_warn
    sd_g = np.sqrt(np.maximum(np.diag(Sinv), 1e-300))
    gkeys = [keys[i] for i in st.glob]
    correlated = []
    for k, Ai in enumerate(Ainv):
        idx = st.local_of_arr[k]
        if not idx.size or not sd_g.size:
            continue
        cross = -(Ai @ N.HGL[k].T) @ Sinv
        sd_l = np.sqrt(np.maximum(np.diag(cov_L[k]), 1e-300))
        corr = cross / sd_l[:, None] / sd_g[None, :]
        for a, b in zip(*np.nonzero(np.abs(corr) > thr), strict=True):
            correlated.append(Confounding(
                parameters=(keys[idx[a]], gkeys[b]), kind="correlated",
                detail=(f"correlation {corr[a, b]:+.4f}: the data barely separate {keys[idx[a]]} "
                        f"from {gkeys[b]}; their individual values are uncertain"),
            ))
    return Sinv, cov_L, unident, correlated


def _high_correlations(corr: np.ndarray, keys: list[str], thr: float) -> list[Confounding]:
    out = []
    n = corr.shape[0]
    iu = np.triu_indices(n, 1)
    vals = corr[iu]
    for a, b, r in zip(iu[0], iu[1], vals, strict=True):
        if np.isfinite(r) and abs(r) > thr:
            out.append(Confounding(
                parameters=(keys[a], keys[b]), kind="correlated",
                detail=(f"correlation {r:+.4f}: the data barely separate {keys[a]} from {keys[b]}; "
                        "their individual values are uncertain even if their deviations look small"),
            ))
    return out


def _stats(problem: Problem, ev: Evaluation) -> tuple[ResidualStats, ...]:
    blocks = []
    for ce in ev.channels:
        e = ce.e
        for b, k in enumerate(ce.mans):
            blocks.append((int(k), ce.channel, e[ce.rseg[b]:ce.rseg[b + 1]]))
    out = []
    for k, c, e in sorted(blocks, key=lambda x: (x[0], x[1])):  # maneuver by maneuver
        out.append(ResidualStats(
            maneuver=problem.maneuvers[k].id, channel=problem.channels[c].name, n=int(e.size),
            mean=float(e.mean()), std=float(e.std()), rms=float(np.sqrt(np.mean(e * e))),
        ))
    return tuple(out)
