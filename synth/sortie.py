"""Whole sorties: one continuous flight per configuration, its test points flown in sequence.

A real calibration campaign does not fly each maneuver from its own trim: the aircraft takes off,
climbs to the first test point, flies the maneuvers there, moves on to the next Mach and altitude,
and so on; the recorders run throughout, and the maneuvers are cut out of the recorded streams
afterwards (extraction). :func:`fly_sortie` flies that in one JSBSim run:

* trim at the first maneuver's test point (as :func:`synth.flight.fly_maneuver` does, wind and
  turbulence applied, :data:`synth.flight.SETTLE_S` hands-off), then the first maneuver at once;
* before every further maneuver a :class:`Transition` leg: gear up first if the next point is
  gear-up; to a faster point the speed change first (level, at the present altitude), then the
  climb or descent at the new Mach; to a slower point the climb or descent first (at the present
  Mach), then the speed change; gear down last; the heading brought back to the maneuver's
  ``heading_rad`` all along (bank up to 30 deg); then held until Mach, altitude, heading, bank and
  climb rate have been steady for :attr:`Transition.steady_s`;
* each maneuver flown by its own controller (:mod:`synth.maneuvers`) starting from the state the
  transition left (its trim point is that state), so the maneuvers are those of the per-maneuver
  datasets, flown from a settled rather than a trimmed state;
* one truth for the whole sortie, instrumented once (:func:`synth.instrument.instrument`): every
  recorder's delays, clock offset, biases and noise are continuous through it.

The transition laws (:class:`Transition`): elevator through the f16 FCS's load-factor command on a
climb-rate loop (climb rate commanded from the altitude error, at most
:attr:`Transition.climb_rate_mps`), throttle on a Mach loop (including afterburner) with the Mach
command ramped at :attr:`Transition.mach_rate_per_s`, aileron on a bank loop commanded from the
heading error, rudder neutral.

Not modelled yet: take-off, landing and the climb to the first test point; fuel burn (frozen:
the mass and CG stay the aircraft's fuel load, as in a per-maneuver run; a whole configuration of
the default campaign is more flight than one tankful, a real campaign flies it in several
sorties); the speedbrake; a discrete gust (refused); the order a pilot would fly the test points
and maneuvers in (the campaign's file order is flown), heading changes between test points
other than back to the maneuvers' heading (the sortie flies a straight line, about 1500 km for
the default campaign's first configuration, on a flat earth; on ``wgs84`` its latitude changes);
ceilings and airspace. A maneuver that was flown but missed its goal
(:meth:`synth.maneuvers.Controller.finish`, e.g. a wind-up turn short of its alpha) is kept and
marked in its boundary's ``missed``; a departure, a lost target during a maneuver or a transition
not settled in :attr:`Transition.max_s` fails the whole sortie with a
:class:`~synth.flight.FlightError` naming it. The pitch trim a maneuver starts from is the one the
transition left (stick force trimmed out), not JSBSim's trim of that test point, so a maneuver
that uses full aft stick (wind-up turn) can reach a little more or less than its per-maneuver run.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from aircraft_models import Aircraft, Airframe
from synth import jsbsim_io as io
from synth.campaign import Campaign, CampaignError, Job, manifest_header
from synth.dataset import (
    BOUNDARY_COLUMNS,
    SORTIE_FILES,
    SORTIE_FORMAT,
    SORTIE_FORMAT_VERSION,
    _jsonable,
    maneuver_id,
    maneuver_key,
    prepare_sortie_directory,
    write_sortie,
)
from synth.environment import Environment
from synth.errors import ErrorConfig
from synth.flight import (
    FlightError,
    departure_advice,
    describe_spec,
    fly_controller,
    segment_bounds,
    start_flight,
    trim_point,
)
from synth.instrument import instrument
from synth.local_flow import load_adc_baseline, load_local_flow_truth
from synth.maneuvers import (
    DEG_TO_RAD,
    Controller,
    ManeuverFailure,
    ManeuverSpec,
    TrimPoint,
    make_controller,
    wrap_angle_rad,
)
from synth.truth import TruthTrajectory

_C = io.COL
_TRANSITION_ADVICE = ("fly the test points in an order with smaller steps between them (the f16 "
                      "flies Mach 0.3 only low down), or lower Transition.climb_rate_mps")

class Transition(Controller):
    """The pilot between two test points: to ``spec``'s trim Mach, altitude, heading and gear.

    Stages (``self.stage``): ``"mach"`` and ``"altitude"`` in the order the module docstring
    gives, ``"gear"`` (the caller lowers the gear: :func:`fly_sortie`), ``"settle"``; ``done``
    once steady.
    """

    #: largest commanded climb or descent rate, m/s
    climb_rate_mps = 15.0
    #: rate of the Mach command's ramp, 1/s
    mach_rate_per_s = 0.01
    #: how long everything must stay within the settle tolerances, s
    steady_s = 5.0
    #: longest transition before it is declared failed, s
    max_s = 1200.0
    lead_in_s = 0.0

    def __init__(self, spec: ManeuverSpec, start: TrimPoint, dt_s: float, gear_down_now: bool):
        super().__init__(spec, start, dt_s)
        self.target_mach = spec.trim_mach
        self.target_h_m = spec.altitude_m
        self.psi_cmd_rad = spec.heading_rad
        stages = (["mach", "altitude"] if self.target_mach > start.mach else ["altitude", "mach"])
        self.raise_gear = gear_down_now and not spec.gear_down
        self.stages = stages + (["gear"] if spec.gear_down and not gear_down_now else []) + ["settle"]
        self.stage = self.stages[0]
        self.h_cmd_m = start.altitude_m
        self.mach_ramp = start.mach
        self.t_s = 0.0
        self._steady_s = 0.0
        self._nz_int = 0.0
        self.elevator_cmd_norm = 0.0
        self.done = False

    def _next_stage(self) -> None:
        self.stage = self.stages[self.stages.index(self.stage) + 1]

    def _advance(self, x) -> None:
        """Move to the next stage when this one's target is reached."""
        if self.stage == "mach" and abs(x[_C["mach"]] - self.target_mach) < 0.005:
            self._next_stage()
        elif self.stage == "altitude" and abs(x[_C["h_m"]] - self.target_h_m) < 20.0:
            self._next_stage()
        elif self.stage == "gear" and x[_C["gear_pos_norm"]] > 0.999:
            self._next_stage()
        reached = self.stages.index(self.stage)
        if reached >= self.stages.index("altitude"):
            self.h_cmd_m = self.target_h_m
        if reached >= self.stages.index("mach"):  # before: the present Mach is held
            step = self.mach_rate_per_s * self.dt_s
            self.mach_ramp += max(-step, min(step, self.target_mach - self.mach_ramp))
        self.mach_cmd = self.mach_ramp
        if self.stage == "settle":
            steady = (abs(x[_C["mach"]] - self.target_mach) < 0.003
                      and abs(x[_C["h_m"]] - self.target_h_m) < 10.0
                      and abs(wrap_angle_rad(self.psi_cmd_rad - x[_C["psi_rad"]])) < 1.0 * DEG_TO_RAD
                      and abs(x[_C["phi_rad"]]) < 1.0 * DEG_TO_RAD
                      and abs(self.hdot_mps(x)) < 0.5)
            self._steady_s = self._steady_s + self.dt_s if steady else 0.0
            self.done = self._steady_s >= self.steady_s

    def inputs(self, t_s, x):
        self._advance(x)
        self.t_s += self.dt_s
        phi = x[_C["phi_rad"]]
        phi_cmd = self.bank_for_heading(x, limit_rad=30 * DEG_TO_RAD)
        hdot_cmd = max(-self.climb_rate_mps,
                       min(self.climb_rate_mps, 0.2 * (self.h_cmd_m - x[_C["h_m"]])))
        err = hdot_cmd - self.hdot_mps(x)
        # the stick trim, in load factor (integral of the climb-rate error, i.e. of the altitude
        # error): the pitch trim was set at the previous test point, and the FCS's load-factor law
        # is a steady-state approximation; without it a standing altitude error remains
        self._nz_int = max(-1.5, min(1.5, self._nz_int + 0.02 * err * self.dt_s))
        dnz = max(-1.5, min(1.5, 0.05 * err)) + self._nz_int + (1.0 / math.cos(phi) - 1.0)
        self.elevator_cmd_norm = max(-1.0, min(1.0, self.stick(dnz, x)))
        return (self.elevator_cmd_norm, self.aileron_for_bank(phi_cmd, x), 0.0,
                self.throttle_for_mach(x, 0.0, 1.0), 0.0)

    def check(self, t_s, x):
        if self.t_s > self.max_s:
            raise ManeuverFailure(
                f"not settled after {self.max_s:.0f} s (stage {self.stage}: Mach "
                f"{x[_C['mach']]:.3f} of {self.target_mach:.3f}, altitude {x[_C['h_m']]:.0f} of "
                f"{self.target_h_m:.0f} m, heading {math.degrees(x[_C['psi_rad']]):.1f} deg)",
                self.t_s, "order the test points so that neighbours are closer, or check that the "
                "f16 can fly the next point (Mach 0.3 needs a low altitude)")


@dataclass(frozen=True)
class FlownSortie:
    """One sortie as flown: its truth and where each maneuver and transition lies in it.

    Attributes
    ----------
    truth : the whole sortie at the simulation rate, ``t_s`` from 0 at the first maneuver's start.
    boundaries : one dict per recorded maneuver piece (SHSS: per segment, as the per-maneuver
        dataset splits it): ``id``, ``job_index``, ``segment``, ``kind``, ``mach`` (nominal),
        ``altitude_m`` (nominal), ``gear_down``, ``t_start_s``, ``t_end_s`` (first and last
        sample), ``missed`` (why the maneuver missed its goal, :meth:`Controller.finish`; empty if
        it did not).
    transitions : one dict per transition leg: ``to`` (the next maneuver's id), ``t_start_s``,
        ``t_end_s``, ``stages``.
    """

    truth: TruthTrajectory
    boundaries: tuple[dict, ...]
    transitions: tuple[dict, ...]


class _Tape:
    """The sortie's legs as recorded, end to end: a leg's first sample is the previous leg's last."""

    def __init__(self) -> None:
        self.pieces: list[np.ndarray] = []
        self.n_total = 0  # samples recorded so far

    @property
    def next_start(self) -> int:
        """Index of the next leg's first sample (the last one's end)."""
        return max(self.n_total - 1, 0)

    def record(self, si: np.ndarray) -> int:
        """Append a leg; its start index."""
        start = self.next_start
        self.pieces.append(si if not self.pieces else si[1:])
        self.n_total = start + len(si)
        return start


@dataclass(frozen=True)
class _SortieRun:
    """The JSBSim run a sortie is flown in, and what it has recorded so far."""

    fdm: object
    reader: object
    dt_s: float
    aircraft_id: str
    tape: _Tape


def _check_sortie_environment(env: Environment) -> None:
    """Refuse the air a whole sortie cannot model: what is drawn or timed per maneuver."""
    if env.gust is not None:
        raise FlightError("sortie: a discrete gust is not modelled in a whole sortie (its start_s "
                          "is relative to one maneuver); remove [environment.gust]")
    if env.vertical_air_motion is not None:
        raise FlightError("sortie: the slow vertical air motion is drawn per maneuver, not for a "
                          "whole sortie; remove [environment] vertical_air_motion, or fly the "
                          "campaign without --sortie")


def _fly_transition(run: _SortieRun, spec: ManeuverSpec, gear_down: bool, chunk: int, to_id: str) -> dict:
    """Fly from where the last maneuver ended to ``spec``'s test point (recorded, in chunks of
    ``chunk`` samples until it has settled); the transition's boundaries (to ``to_id``)."""
    fdm, reader, dt_s, tape = run.fdm, run.reader, run.dt_s, run.tape
    start_state = trim_point(reader.read_si())
    leg = Transition(spec, start_state, dt_s, gear_down)
    t0 = tape.next_start * dt_s
    if leg.raise_gear:
        io.set_gear(fdm, False)
    try:
        while not leg.done:
            if leg.stage == "gear":
                io.set_gear(fdm, True)
            tape.record(fly_controller(fdm, reader, leg, chunk, dt_s, _TRANSITION_ADVICE))
    except ManeuverFailure as exc:
        raise FlightError(
            f"sortie (aircraft {run.aircraft_id}): transition to {to_id} ({describe_spec(spec)}), "
            f"t = {t0 + exc.t_s:.1f} s into the sortie: {exc.what}. Try: {exc.advice}."
        ) from None
    # the pilot trims the stick force out: the maneuvers' stick programmes are increments
    # from a trimmed stick (the f16 FCS adds stick and pitch trim before anything else)
    io.add_pitch_trim(fdm, leg.elevator_cmd_norm)
    return {"to": to_id, "t_start_s": t0, "t_end_s": (tape.n_total - 1) * dt_s, "stages": list(leg.stages)}


def _fly_test_point(run: _SortieRun, spec: ManeuverSpec, trim, job_index: int, n_seg: int) -> list[dict]:
    """Fly and record one maneuver from its trimmed test point; its pieces' boundaries."""
    dt_s = run.dt_s
    controller = make_controller(spec, trim, dt_s)
    n = int(round(spec.duration_s / dt_s)) + 1
    try:
        si = fly_controller(run.fdm, run.reader, controller, n, dt_s, departure_advice(spec), finish=False)
    except ManeuverFailure as exc:
        t_in = run.tape.next_start * dt_s
        raise FlightError(
            f"sortie (aircraft {run.aircraft_id}): maneuver {maneuver_id(job_index, 0, n_seg)} "
            f"({describe_spec(spec)}), t = {exc.t_s:.2f} s into it ({t_in + exc.t_s:.1f} s into the "
            f"sortie): {exc.what}. Try: {exc.advice}."
        ) from None
    start = run.tape.record(si)
    # a maneuver that missed its goal (e.g. a wind-up turn short of its alpha) was still flown
    # and recorded, as in a real sortie: the boundaries say so, the flight goes on
    try:
        controller.finish(si, np.arange(n) * dt_s)
        missed = ""
    except ManeuverFailure as exc:
        missed = f"{exc.what} (t = {exc.t_s:.2f} s into it; try: {exc.advice})"
    # the truth an extraction is judged by: when the pilot's inputs act, cut to each piece
    ex0, ex1 = controller.excitation_s(si, np.arange(n) * dt_s)
    return [{
        "id": maneuver_id(job_index, k, n_seg), "job_index": job_index, "segment": k,
        "kind": spec.kind, "mach": spec.mach, "altitude_m": spec.altitude_m,
        "gear_down": bool(spec.gear_down), "t_start_s": (start + lo) * dt_s,
        "t_end_s": (start + hi - 1) * dt_s, "missed": missed,
        "t_excitation_start_s": start * dt_s + max(ex0, lo * dt_s),
        "t_excitation_end_s": start * dt_s + min(ex1, (hi - 1) * dt_s),
    } for k, (lo, hi) in enumerate(segment_bounds(n, n_seg))]


def fly_sortie(
    specs: Sequence[ManeuverSpec],
    ids: Sequence[tuple[int, int]],
    airframe: Airframe,
    aircraft: Aircraft,
    env: Environment,
    *,
    dt_s: float = 1.0 / 120.0,
    chunk_s: float = 1.0,
) -> FlownSortie:
    """Fly ``specs`` in sequence in one JSBSim run (module docstring).

    Parameters
    ----------
    specs : the maneuvers, in flight order.
    ids : per maneuver its ``(job_index, n_segments)``, naming its pieces as
        :func:`synth.dataset.maneuver_id` does.
    airframe, aircraft, env : as for :func:`synth.flight.fly_maneuver` (no gust).
    dt_s : simulation step, s.
    chunk_s : a transition is flown in chunks of this length until it has settled, s.

    Raises
    ------
    FlightError
        If the trim, a maneuver or a transition fails; the message names the maneuver (or the
        transition to it), the time in the sortie, what went wrong and what to try.
    """
    if not specs:
        raise ValueError("fly_sortie: no maneuvers to fly")
    _check_sortie_environment(env)
    fdm, reader, trim, trim_meta = start_flight(specs[0], airframe, aircraft, env, dt_s)
    # the fuel load stays the aircraft's (as in a per-maneuver run): a whole campaign's
    # configuration is more flight than one tankful, and its engine would flame out
    io.freeze_fuel(fdm)
    run = _SortieRun(fdm, reader, dt_s, aircraft.id, _Tape())
    boundaries, transitions = [], []
    gear_down = specs[0].gear_down
    chunk = int(round(chunk_s / dt_s)) + 1
    for m, spec in enumerate(specs):
        job_index, n_seg = ids[m]
        if m > 0:
            transitions.append(_fly_transition(run, spec, gear_down, chunk, maneuver_id(job_index, 0, n_seg)))
            gear_down = spec.gear_down
            trim = trim_point(reader.read_si())
        boundaries += _fly_test_point(run, spec, trim, job_index, n_seg)
    si = np.concatenate(run.tape.pieces)
    t_s = np.arange(len(si)) * dt_s
    meta = {
        "sortie": True,
        "environment": env.to_dict(),
        "first_trim": trim_meta,
        "jsbsim_version": io.JSBSIM_VERSION,
        "jsbsim_model": airframe.jsbsim_model,
        "airframe": airframe.name,
        "aircraft": aircraft.id,
        "dt_s": dt_s,
    }
    truth = io.to_truth(si, t_s, planet=env.planet, meta=meta)
    return FlownSortie(truth, tuple(boundaries), tuple(transitions))


@dataclass(frozen=True)
class SortieResult:
    """What :func:`fly_sortie_campaign` wrote: the directory, its manifest, the wall time."""

    out_dir: Path
    manifest: dict
    wall_s: float


def sortie_jobs(campaign: Campaign, configuration: str | None = None) -> tuple[str, list[Job]]:
    """The configuration flown (default: the campaign's first) and its jobs in file order.

    Raises
    ------
    CampaignError
        If the campaign flies no maneuver in ``configuration`` (the message lists those it flies).
    """
    flown = list(dict.fromkeys(j.configuration_id for j in campaign.jobs))
    cid = configuration or flown[0]
    jobs = [j for j in campaign.jobs if j.configuration_id == cid]
    if not jobs:
        raise CampaignError(f"{campaign.source}: no maneuver of configuration {cid!r} to fly as a "
                            f"sortie; the campaign flies {', '.join(flown)}")
    return cid, jobs


def fly_sortie_campaign(
    campaign: Campaign,
    out_dir: str | Path,
    *,
    configuration: str | None = None,
    overwrite: bool = False,
) -> SortieResult:
    """Fly one configuration's maneuvers of ``campaign`` as one sortie and write the dataset.

    Parameters
    ----------
    campaign : from :func:`synth.campaign.load_campaign`.
    out_dir : the sortie directory to create (:data:`synth.dataset.SORTIE_FILES`).
    configuration : the configuration id (default: the first the campaign flies).
    overwrite : replace a sortie written there earlier (only its own files are removed).

    The maneuvers are flown in the campaign's job order; the seeds are the per-maneuver run's
    of the first job (turbulence: its ``turbulence_seed``; the errors: :func:`synth.dataset.
    maneuver_key` of its index, segment 0), so the same file gives the same bytes.

    Raises
    ------
    FlightError
        If the sortie cannot be flown (the message names the maneuver or transition and time).
    CampaignError
        If the configuration flies nothing in ``campaign``.
    FileExistsError
        If ``out_dir`` cannot be used (:func:`synth.dataset.prepare_sortie_directory`).
    """
    import time

    t0 = time.perf_counter()
    cid, jobs = sortie_jobs(campaign, configuration)
    fleet = campaign.fleet
    cfg = fleet.configuration(cid)
    specs = [ManeuverSpec.from_dict(j.maneuver) for j in jobs]
    env = Environment.from_dict(jobs[0].environment)
    errors = ErrorConfig.from_dict(jobs[0].errors, seed=campaign.seed)
    out_dir = prepare_sortie_directory(Path(out_dir), overwrite=overwrite)
    flown = fly_sortie(specs, [(j.index, s.n_segments) for j, s in zip(jobs, specs, strict=True)],
                       fleet.airframe, cfg.aircraft, env)
    key = maneuver_key(jobs[0].index, 0)
    rate = campaign.common_rate_hz
    inst = instrument(flown.truth, fleet.airframe, cfg, errors, maneuver_key=key,
                      common_rate_hz=rate,
                      truth_model=load_local_flow_truth(campaign.local_flow_truth),
                      adc_baseline=load_adc_baseline(campaign.adc_baseline))
    header = manifest_header(campaign)
    truth = flown.truth
    manifest = {
        **header,
        "format": SORTIE_FORMAT,
        "format_version": SORTIE_FORMAT_VERSION,
        "complete": True,
        "jobs": [{"job_index": j.index, "configuration": j.configuration_id, "maneuver": j.maneuver}
                 for j in jobs],
        "sortie": {
            "configuration": cid,
            "aircraft": cfg.aircraft.id,
            "nose_sensor": cfg.nose_sensor,
            "sensors": list(cfg.sensors),
            "maneuver_key": key,
            "sample_rate_hz": rate,
            "duration_s": truth.duration_s,
            "n_samples": int(len(inst.data)),
            "n_maneuvers": len(jobs),
            "mach_min": float(np.min(truth.mach)),
            "mach_max": float(np.max(truth.mach)),
            "altitude_min_m": float(np.min(truth.h_m)),
            "altitude_max_m": float(np.max(truth.h_m)),
            # the weight and balance a calibration takes as known (fuel frozen: one CG)
            "r_cg_body_m_mean": np.mean(truth.r_cg_body_m, axis=0).tolist(),
            "g_mps2_mean": float(np.mean(truth.g_mps2)),
            "environment": env.to_dict(),
            "flight_meta": truth.meta,
            "injected": inst.injected,
            "channel_units": inst.channel_units,
            "own_rate_columns": list(inst.own_rate_columns),
            "files": dict(SORTIE_FILES),
            "boundaries": list(flown.boundaries),
            "transitions": list(flown.transitions),
        },
    }
    write_sortie(out_dir, manifest, inst.data, inst.streams)
    return SortieResult(out_dir, json.loads(json.dumps(_jsonable(manifest))), time.perf_counter() - t0)


def summarize_sortie(manifest: Mapping) -> str:
    """A short text description of a whole-sortie manifest: the flight, its maneuvers in order."""
    s = manifest["sortie"]
    lines = [
        f"whole sortie: configuration {s['configuration']} (aircraft {s['aircraft']}), "
        f"{s['n_maneuvers']} maneuvers ({len(s['boundaries'])} recorded pieces), "
        f"{len(s['transitions'])} transitions, {s['duration_s']:.0f} s of flight, "
        f"{s['n_samples']} samples at {s['sample_rate_hz']:g} Hz",
        f"Mach {s['mach_min']:.3f}-{s['mach_max']:.3f}, altitude {s['altitude_min_m']:.0f}-"
        f"{s['altitude_max_m']:.0f} m; streams: " + ", ".join(
            f"{k} ({v})" for k, v in s["files"].items()),
        "maneuver boundaries (truth; cut with synth.dataset.load_sortie(DIR).cut(id)):",
    ]
    table = pd.DataFrame(s["boundaries"], columns=list(BOUNDARY_COLUMNS)).set_index("id")
    lines.append(table.to_string(float_format=lambda v: f"{v:.3f}"))
    return "\n".join(lines)
