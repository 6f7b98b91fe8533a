"""Identifiability: which free parameters the data determine, and what to do with the rest.

:func:`screen` holds, at their start values, the parameters no sample depends on (a table
breakpoint beyond the flown range), one member of each combination the data cannot separate (a
free table offset beside free biases) and, judged loosely, those whose Cramér-Rao deviation exceeds
half their allowed range (bounds). :func:`covariance` is the undamped Cramér-Rao covariance with
its rank checks and the correlated global-local pairs; :func:`parameter_states` says what each
parameter ended as (estimated, on a bound, held and why, fixed) and :func:`parameter_findings`
turns the holds, bounds and correlations into findings. Used by :mod:`estimator.solver` before the
iterations and at the solution.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from estimator.core.kinematics import rotation_ned_to_body
from estimator.model import Evaluation
from estimator.normal_equations import NormalEquations, Structure, build_normal, lm_solve, sym_inverse
from estimator.problem import Problem
from estimator.result import Confounding
from estimator.uncertainty import Covariance, std_of
from estimator.verdict import Finding, Severity

if TYPE_CHECKING:
    from estimator.options import SolverOptions

#: A steady crosswind and a sideslip offset common to an aircraft's sensors. A steady wind ``W``
#: (per maneuver, or hidden in its free initial velocities) adds ``-W . e_y / V`` to every sensor's
#: sideslip (``e_y`` the body y-axis in NED), an offset ``b`` adds ``b``. Within a maneuver the
#: two are told apart by how far ``e_y`` turns in the horizontal plane (heading changes; bank
#: only shortens it) and by the airspeed's changes (``W . e_y / V`` varies with ``V``, a few per
#: cent in a pitch doublet), a weak coupling that any error in the airspeed's model (its delay, the
#: along-body gusts) turns into an offset. Below this rms turn of ``e_y``'s horizontal part about
#: its mean (rad; about a heading sweep of +-10 deg) in every maneuver that informs them, only that
#: coupling separates them. Measured: wind-up turns 27 deg rms; pitch doublets, 3211s, roller
#: coasters, rudder doublets and steady-heading sideslips 0.02-1.1 deg (calm air and light
#: turbulence). On two aircraft's pitch doublets and 3211s in a 7-m/s wind the sideslip offsets
#: came out 0.15-0.3 deg off at 3-5 Cramér-Rao deviations in calm air, and at 13-20 by the
#: filter-error method in light turbulence (the review of 34822f8).
CROSSWIND_TURN_MIN_RAD = 0.1


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
class Hold:
    """Parameters held at their start values by the identifiability screen, and why."""

    params: tuple[int, ...]
    kind: str  # "no_data", "unidentifiable" or "undetermined"
    confounding: Confounding


def screen(problem: Problem, st: Structure, evals: Evaluation, R: np.ndarray, opt: SolverOptions,
            loose: bool, normal=None) -> tuple[Structure, list[Hold]]:
    """Hold the parameters the data do not determine; returns the new structure and the holds.

    Parameters no sample depends on (a table breakpoint beyond the flown range, a bias of a sensor
    an aircraft does not carry) and combinations the data cannot separate (one member per null
    direction) are held. With ``loose``, so is a parameter whose Cramér-Rao deviation exceeds half
    its allowed range (a pressure-altitude scale in level flight). Judged away from the solution,
    where ``R`` holds the residuals of a wrong trajectory, the deviations are inflated: the
    estimation therefore judges every requested parameter again at its solution. ``normal``: a
    function of the structure giving the normal equations to judge by (the filter-error method's,
    whose wind states leave a parameter less determined than the output-error residuals say);
    None: the output-error ones of ``evals`` and ``R``.
    """
    ps = problem.parameters
    keys = ps.keys
    holds: list[Hold] = []
    for _ in range(12):
        if not st.free.any():
            break
        N = build_normal(st, evals, R) if normal is None else normal(st)
        no_data = st.free & ~has_data(N, st, opt.min_support_samples)
        if no_data.any():
            held = tuple(int(i) for i in np.nonzero(no_data)[0])
            holds.append(Hold(held, "no_data", Confounding(
                parameters=tuple(keys[i] for i in held), kind="no_data",
                detail=(f"fewer than {opt.min_support_samples} samples depend on these parameters "
                        "(e.g. a table breakpoint outside the flown range, or a sensor this aircraft "
                        "does not carry); held at their start values"))))
            st = Structure(problem, st.free & ~no_data)
            continue
        cov_G, cov_L, unident, _ = covariance(N, st, problem, opt)
        if unident:
            free = st.free.copy()
            for conf, hold in unident:
                free[hold] = False
                holds.append(Hold((hold,), "unidentifiable", conf))
            st = Structure(problem, free)
            continue
        if loose:
            std = std_of(st, cov_G, cov_L, len(keys))
            width = st.hi - st.lo
            bad = st.free & np.isfinite(width) & (std > 0.5 * width)
            if bad.any():
                held = tuple(int(i) for i in np.nonzero(bad)[0])
                holds.append(Hold(held, "undetermined", Confounding(
                    parameters=tuple(keys[i] for i in held), kind="undetermined",
                    detail=("the data barely depend on these parameters: at the solution their "
                            "Cramér-Rao deviation exceeds half their allowed range (bounds); held at "
                            "their start values"))))
                st = Structure(problem, st.free & ~bad)
                continue
        break
    return st, holds


def has_data(N: NormalEquations, st: Structure, min_support: int) -> np.ndarray:
    """(P,) the free parameters some information and at least ``min_support`` samples depend on."""
    info = np.zeros(st.free.size)
    info[st.glob] = np.diag(N.HGG)
    for k, idx in enumerate(st.local_of_arr):
        info[idx] = np.diag(N.HLL[k])
    return st.free & (info > 0.0) & (N.support >= min_support)


def covariance(N: NormalEquations, st: Structure, problem: Problem, opt: SolverOptions) -> Covariance:
    """Undamped Cramér-Rao covariance of the global block and of each local block.

    Returns
    -------
    :class:`Covariance`: S^-1, [cov_L_k], unidentifiable sets with the member to hold, correlated
    global-local pairs
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
    return Covariance(Sinv, cov_L, unident, correlated)


def high_correlations(corr: np.ndarray, keys: list[str], thr: float) -> list[Confounding]:
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


def maneuver_nuisance(p) -> bool:
    """Is parameter ``p`` a maneuver's nuisance scale or offset (``k_h`` in level flight), whose
    bound is only noted, not a calibration result whose bound is a warning?"""
    return p.scope == "maneuver" and p.kind in ("scale", "bias")


def parameter_states(problem: Problem, theta: np.ndarray, start: np.ndarray, st: Structure,
                      holds: list[Hold], unresolved: np.ndarray, unident: list, opt: SolverOptions
                      ) -> tuple[list[str], list[str]]:
    """What each parameter is at the estimate: "fixed", "held" (why), "unidentifiable", "on_bound"
    or "estimated"; returns the states and their reasons, one per parameter."""
    ps = problem.parameters
    requested = ps.free_mask
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
    return state, reason


def parameter_findings(problem, holds, unident, correlated, state, reason, opt, informs) -> list[Finding]:
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
            out.append(Finding("held", Severity.NOTE, f"held at their start values, no data: {names} "
                               f"({h.confounding.detail.split(';')[0]})",
                               parameters=h.confounding.parameters))
        else:
            out.append(Finding("held", Severity.NOTE, f"held at their start values, undetermined: {names} "
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
            nuisance = maneuver_nuisance(p)
            out.append(Finding("on_bound", Severity.NOTE if nuisance else Severity.WARNING,
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
            out.append(Finding("correlated", Severity.NOTE, f"{' and '.join(c.parameters)}: {c.detail}",
                               parameters=c.parameters))
    man_of = {p.key: p.instance for p in ps if p.scope == "maneuver"}
    for key, partners in against.items():
        if not informs.get(key) or not informs[key] <= {man_of[k] for k in partners}:
            for k in partners:
                out.append(Finding("correlated", Severity.NOTE, f"{k} and {key}: correlation above "
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


def lateral_axis_turn_rad(euler_rad: np.ndarray) -> float:
    """How far the body y-axis turns in the horizontal plane over a maneuver: the rms distance of
    its horizontal part (north, east) from their mean, rad (about the rms heading change about
    the mean heading, wings level).

    Parameters
    ----------
    euler_rad : (n, 3) roll, pitch, heading (3-2-1), rad.
    """
    if euler_rad.shape[0] < 2:
        return 0.0
    e_y = rotation_ned_to_body(euler_rad)[:, 1, :2]  # row 1 of C_bn: the body y-axis in NED
    return float(np.sqrt(np.mean(np.sum((e_y - e_y.mean(axis=0)) ** 2, axis=1))))


def crosswind_findings(problem: Problem, evals: Evaluation, st: Structure,
                        informs: dict[str, set[str]]) -> list[Finding]:
    """A WARNING per set of free sideslip offsets (biases of any scope but a maneuver's in the
    channels that measure ``beta_s`` or ``flank_s``) linked through the maneuvers that inform
    them, when none of those maneuvers turns (:data:`CROSSWIND_TURN_MIN_RAD`): each maneuver's
    steady crosswind then trades with an offset common to the sensors it carries. One turning
    maneuver anchors every offset of its set (it fixes its sensors' offsets, and through them the
    crosswind of every maneuver that shares a sensor with it). Judged as if each maneuver's steady
    wind were free (in its initial velocities or a steady-wind parameter, as in the shipped model
    sets); a set informed by a maneuver the evaluation does not cover is not judged."""
    ps = problem.parameters
    lateral = [c for c in problem.channels if c.measures in ("beta_s", "flank_s")]
    keys = [prm.key for i, prm in enumerate(ps)
            if st.free[i] and prm.kind == "bias" and prm.scope != "maneuver"
            and any(prm.name in c.expression.names for c in lateral) and informs.get(prm.key)]
    if not keys:
        return []
    # the sets: offsets linked by a maneuver that informs both (union-find over the keys)
    parent = {k: k for k in keys}

    def root(k: str) -> str:
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    first: dict[str, str] = {}
    for k in keys:
        for m in informs[k]:
            if m in first:
                parent[root(k)] = root(first[m])
            else:
                first[m] = k
    sets: dict[str, list[str]] = {}
    for k in keys:
        sets.setdefault(root(k), []).append(k)
    pos = {problem.maneuvers[k].id: i for i, k in enumerate(evals.maneuvers)}
    turn: dict[str, float] = {}
    out = []
    for members in sets.values():
        mans = sorted(set().union(*(informs[k] for k in members)))
        if not mans or any(m not in pos for m in mans):
            continue
        for m in mans:
            if m not in turn:
                i = pos[m]
                turn[m] = lateral_axis_turn_rad(evals.X[evals.seg[i]:evals.seg[i + 1], 3:6])
        if max(turn[m] for m in mans) >= CROSSWIND_TURN_MIN_RAD:
            continue
        widest = max(mans, key=turn.__getitem__)
        owners = sorted({ps[k].instance for k in members} - {""})
        who = f" of {', '.join(owners)}" if owners else ""
        out.append(Finding(
            "crosswind_confounded", Severity.WARNING,
            f"the sideslip offsets{who} ({', '.join(members)}) are told from each maneuver's steady "
            f"crosswind only through weak couplings: in none of the {len(mans)} maneuver(s) that "
            f"inform them does the aircraft's lateral axis turn by more than "
            f"{np.degrees(CROSSWIND_TURN_MIN_RAD):.1f} deg rms in the horizontal plane (the most: "
            f"{widest}, {np.degrees(turn[widest]):.2f} deg), so a steady crosswind of 1 m/s reads as "
            "a common sideslip offset of about 0.3 deg at 200 m/s and only the airspeed's changes "
            "within the maneuvers tell the two apart; an error in the airspeed's model (its delay, "
            "turbulence along the body axis) then goes into the offsets, which their deviations "
            "do not include",
            "fly a maneuver that turns the heading (a windup turn, a heading change of 20 deg or "
            "more) with these sensors, or fix the sideslip offsets at known values",
            parameters=tuple(members), value=float(np.degrees(turn[widest]))))
    return out
