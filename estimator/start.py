r"""A staged, data-driven start: the order in which the estimator frees its unknowns.

Why. The output-error cost of flight path reconstruction is far from quadratic when the IMU biases
are large: a gyro bias of 1 deg/s integrates to 30 deg of attitude error over a 30-s maneuver,
the reconstructed trajectory is then nothing like the flight, and Gauss-Newton from zero biases
lands in a wrong minimum (attitude residuals of degrees). But the state equations are a cascade
(SPEC §3; Jategaonkar 2006, §10.2 on flight path reconstruction, which fits the same cascade)::

    phi, theta, psi  <-  gyros (p, q, r) - gyro biases,  phi0, theta0, psi0
    u, v, w, h       <-  accelerometers - accelerometer biases, the attitude,  u0, v0, w0, h0
    flow angles      <-  u, v, w (and the rates), the channels' calibration models

so each level can be fitted on its own channels with the level above held at its estimate, where
every sub-problem is nearly linear:

1. **attitude** — the Euler-angle channels alone; free: ``phi0, theta0, psi0`` and the gyro biases
   ``dp, dq, dr``. The attitude kinematics do not depend on the velocities.
2. **speed and height** — adds the other channels without a flow sensor (TAS, pressure altitude,
   DGPS height, ...); free: ``u0, w0`` and the longitudinal accelerometer biases ``dax, daz``, and
   those channels' own parameters (the altitude scale ``k_h``, the DGPS offset). ``v0`` and ``day``
   move the sideslip, which speed and height hardly see: they wait for stage 3.
3. **flow** — every channel; free: everything but the time shifts (``v0``, ``day`` and the
   flow-channel biases, scales and tables join).

The full estimation, time shifts included, starts from the last stage. Each stage starts from the
previous one's estimate, and ends at convergence or, earlier, where its quadratic model turns poor
near its minimum (a step that achieved under a tenth of the decrease the model predicted, that under
one log-likelihood unit: :func:`estimator.gauss_newton.gauss_newton`'s ``end_where_poor``): the
premise of a nearly linear sub-problem no longer holds there, and the crawl along weakly determined
directions that would follow is the estimation's to take. A stage whose channels are those of the
next one, or that frees nothing, is skipped. Which channels and parameters belong where follows from
the model set (a channel's flow sensor, the state signals its model uses, the parameter families it
names), so a user's own channels are staged without code.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator.problem import STATE_SIGNALS, ChannelSpec, Problem

#: State-equation parameter families freed in each stage (the cascade of the module docstring).
ATTITUDE_STATE = ("phi0", "theta0", "psi0", "dp", "dq", "dr")
SPEED_STATE = ("u0", "w0", "dax", "daz")
#: Parameter kinds held until the full estimation.
LAST_KINDS = ("time_delay",)


@dataclass(frozen=True)
class StartStage:
    """One stage of the staged start.

    Attributes
    ----------
    name : "attitude", "speed and height" or "flow".
    channels : indices into ``Problem.channels`` fitted in the stage.
    free : (P,) the parameters the stage estimates (a subset of the problem's free ones).
    """

    name: str
    channels: tuple[int, ...]
    free: np.ndarray


def is_attitude_channel(ch: ChannelSpec) -> bool:
    """A channel without a flow sensor whose model uses only the Euler angles (phi, theta, psi)."""
    used = ch.expression.names & STATE_SIGNALS
    return ch.sensor is None and bool(used) and used <= {"phi", "theta", "psi"}


def _channel_families(problem: Problem, ch: ChannelSpec) -> set[str]:
    """Parameter families a channel's model names (tables included), without its time shift."""
    specs = problem.parameters.specs
    names = {n for n in ch.expression.names if n in specs} | set(ch.expression.tables)
    return {n for n in names if n != ch.delay and specs[n].kind not in LAST_KINDS}


def staged_plan(problem: Problem, free: np.ndarray) -> list[StartStage]:
    """The stages (module docstring) for a problem whose free parameters are ``free`` ((P,) bool)."""
    ps = problem.parameters
    chans = problem.channels
    attitude = tuple(i for i, c in enumerate(chans) if is_attitude_channel(c))
    kinematic = tuple(i for i, c in enumerate(chans) if c.sensor is None)
    every = tuple(range(len(chans)))
    family = np.array([p.name for p in ps])
    kinds = np.array([p.kind for p in ps])

    def families(idx: tuple[int, ...]) -> set[str]:
        out: set[str] = set()
        for i in idx:
            out |= _channel_families(problem, chans[i])
        return out

    plan = [
        ("attitude", attitude, set(ATTITUDE_STATE)),
        ("speed and height", kinematic, set(ATTITUDE_STATE) | set(SPEED_STATE) | families(kinematic)),
        ("flow", every, None),
    ]
    stages: list[StartStage] = []
    for name, idx, fams in plan:
        if not idx:
            continue
        if fams is None:  # every family but the last kinds
            mask = free & ~np.isin(kinds, LAST_KINDS)
        else:
            mask = free & np.isin(family, sorted(fams))
        if not mask.any():
            continue
        stages.append(StartStage(name, idx, mask))
    # a stage that fits the same channels as the next one is subsumed by it
    out = [s for k, s in enumerate(stages) if k + 1 == len(stages) or s.channels != stages[k + 1].channels]
    # the last stage is the full estimation itself when it frees everything
    if out and out[-1].channels == every and np.array_equal(out[-1].free, free):
        out.pop()
    return out
