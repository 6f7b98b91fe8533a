"""Fly one scripted test maneuver in JSBSim and return its true flight history.

:func:`fly_maneuver` builds the FDM (:mod:`synth.jsbsim_io`), loads the aircraft's fuel and ballast,
trims at the requested Mach, altitude and gear, applies the :class:`~synth.environment.Environment`
(wind, turbulence, gust), lets the aircraft settle, then lets the maneuver's controller
(:mod:`synth.maneuvers`) fly while every truth signal is recorded at the simulation rate.

Failure policy: a departure (alpha beyond 30 deg, |beta| > 15 deg, NaN, below 100 m above
ground, Mach outside 0.25-0.95, load factor above 9.5), a controller that cannot hold its target,
or a failed trim raises :class:`FlightError`, whose message names the maneuver, Mach, altitude,
the time in the run, what went wrong, and what to try. No partial or silently bad data is returned.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import jsbsim
import numpy as np

from aircraft_models import Aircraft, Airframe
from synth import jsbsim_io as io
from synth.environment import Environment
from synth.maneuvers import ManeuverFailure, ManeuverSpec, TrimPoint, make_controller
from synth.truth import TruthTrajectory

#: hands-off flight between trim (and wind/turbulence onset) and the start of recording, s
SETTLE_S = 2.0

ALPHA_LIMITS_RAD = (math.radians(-12.0), math.radians(30.0))
BETA_LIMIT_RAD = math.radians(15.0)
MIN_AGL_M = 100.0
MACH_LIMITS = (0.25, 0.95)
NZ_LIMIT = 9.5
#: departure checks run every this many steps (and once on the whole record at the end)
_CHECK_EVERY = 6


class FlightError(RuntimeError):
    """The maneuver could not be flown as specified; the message says why and what to try."""


def describe_spec(spec: ManeuverSpec) -> str:
    """The maneuver and its test point in words, for messages: "windup_turn at Mach 0.40, 6000 m"."""
    start = f" (from Mach {spec.trim_mach:.2f})" if spec.trim_mach != spec.mach else ""
    return f"{spec.kind} at Mach {spec.mach:.2f}{start}, {spec.altitude_m:.0f} m" + (
        ", gear down" if spec.gear_down else ""
    )


def _trim(fdm: jsbsim.FGFDMExec, spec: ManeuverSpec) -> dict[str, float]:
    advice = (
        "try another Mach/altitude pair (the f16 trims from Mach 0.3 to 0.9; with gear down "
        "prefer Mach <= 0.5 below 3 km)"
    )
    try:
        res = io.trim(fdm)
    except RuntimeError as exc:
        raise FlightError(f"{describe_spec(spec)}: {exc}; {advice}") from None
    # do_trim can return without an exception on a trim that ended on a control limit; the
    # residual accelerations and the Mach tell whether the state really is an equilibrium
    if (
        abs(res["udot_mps2"]) > 0.15
        or abs(res["wdot_mps2"]) > 0.15
        or abs(res["qdot_rps2"]) > 0.01
        or abs(res["mach"] - spec.trim_mach) > 0.005
    ):
        raise FlightError(
            f"{describe_spec(spec)}: trim did not converge (residuals {res}); {advice}"
        )
    return res


def _departure(si_row) -> str | None:
    C = io.COL
    alpha, beta = si_row[C["alpha_rad"]], si_row[C["beta_rad"]]
    if not all(math.isfinite(v) for v in si_row):
        return "the state became NaN/infinite"
    if not (ALPHA_LIMITS_RAD[0] <= alpha <= ALPHA_LIMITS_RAD[1]):
        return f"departed: alpha {math.degrees(alpha):.1f} deg outside -12..30 deg"
    if abs(beta) > BETA_LIMIT_RAD:
        return f"departed: |beta| {math.degrees(abs(beta)):.1f} deg exceeds 15 deg"
    if si_row[C["h_agl_m"]] < MIN_AGL_M:
        return f"descended to {si_row[C['h_agl_m']]:.0f} m above ground (limit {MIN_AGL_M:.0f} m)"
    mach = si_row[C["mach"]]
    if not (MACH_LIMITS[0] <= mach <= MACH_LIMITS[1]):
        return f"Mach {mach:.3f} left {MACH_LIMITS[0]}..{MACH_LIMITS[1]}"
    nz = -si_row[C["fz_n"]] / (si_row[C["mass_kg"]] * si_row[C["g_mps2"]])
    if nz > NZ_LIMIT:
        return f"load factor {nz:.1f} exceeds {NZ_LIMIT}"
    return None


def _first_departure(si: np.ndarray) -> int | None:
    """Index of the first sample of an SI buffer that :func:`_departure` would flag, or None."""
    C = io.COL
    nz = -si[:, C["fz_n"]] / (si[:, C["mass_kg"]] * si[:, C["g_mps2"]])
    with np.errstate(invalid="ignore"):
        bad = (
            ~np.all(np.isfinite(si), axis=1)
            | (si[:, C["alpha_rad"]] < ALPHA_LIMITS_RAD[0])
            | (si[:, C["alpha_rad"]] > ALPHA_LIMITS_RAD[1])
            | (np.abs(si[:, C["beta_rad"]]) > BETA_LIMIT_RAD)
            | (si[:, C["h_agl_m"]] < MIN_AGL_M)
            | (si[:, C["mach"]] < MACH_LIMITS[0])
            | (si[:, C["mach"]] > MACH_LIMITS[1])
            | (nz > NZ_LIMIT)
        )
    idx = np.flatnonzero(bad)
    return int(idx[0]) if idx.size else None


def _reinit_with_wind(fdm: jsbsim.FGFDMExec, reader: io.SampleReader, wind_ned_mps) -> None:
    """Restart from the trimmed air-relative state with the earth velocity shifted by the wind.

    JSBSim's trim re-initializes the winds from its IC, and in 1.3.3 the IC takes airspeed as
    ground speed + wind where the atmosphere model uses ground speed - wind (measured: an IC Mach
    0.6 in an 11 m/s tailwind flies at Mach 0.53). So the aircraft is trimmed in still air and
    restarted here with the same attitude and air-relative velocity and with ground velocity =
    air velocity + wind.
    """
    x = reader.read_si()
    C = io.COL
    phi, th, psi = x[C["phi_rad"]], x[C["theta_rad"]], x[C["psi_rad"]]
    cph, sph, cth, sth, cps, sps = (math.cos(phi), math.sin(phi), math.cos(th), math.sin(th),
                                    math.cos(psi), math.sin(psi))
    ned_to_body = np.array([
        [cth * cps, cth * sps, -sth],
        [sph * sth * cps - cph * sps, sph * sth * sps + cph * cps, sph * cth],
        [cph * sth * cps + sph * sps, cph * sth * sps - sph * cps, cph * cth],
    ])
    v_air = x[[C["u_air_mps"], C["v_air_mps"], C["w_air_mps"]]]
    v_body = v_air + ned_to_body @ np.asarray(wind_ned_mps, dtype=float)
    io.set_body_velocity_ic(fdm, v_body, (phi, th, psi))
    fdm.run_ic()
    io.set_wind_ned(fdm, wind_ned_mps)


def trim_point(x_si) -> TrimPoint:
    """The :class:`TrimPoint` of an SI state row (indexed by ``jsbsim_io.COL``): where a
    maneuver's controller starts from."""
    C = io.COL
    return TrimPoint(
        mach=float(x_si[C["mach"]]),
        altitude_m=float(x_si[C["h_m"]]),
        heading_rad=float(x_si[C["psi_rad"]]),
        alpha_rad=float(x_si[C["alpha_rad"]]),
        theta_rad=float(x_si[C["theta_rad"]]),
        throttle_cmd_norm=float(x_si[C["throttle_cmd_norm"]]),
        tas_mps=float(x_si[C["tas_mps"]]),
    )


def start_flight(
    spec: ManeuverSpec, airframe: Airframe, aircraft: Aircraft, env: Environment, dt_s: float
) -> tuple[jsbsim.FGFDMExec, io.SampleReader, TrimPoint, dict]:
    """Build the FDM, load the aircraft, trim at ``spec``'s test point, apply ``env`` (wind,
    turbulence) and fly hands-off for :data:`SETTLE_S`.

    Returns
    -------
    The FDM, its sample reader, the trim point and the trim's facts for the metadata.

    Raises
    ------
    FlightError
        If the mass cannot be loaded or the trim fails.
    """
    where = describe_spec(spec)
    fdm, frame = io.create_fdm(airframe.jsbsim_model, env.planet, dt_s, airframe.reference_point)
    fdm["simulation/randomseed"] = env.turbulence_seed
    try:
        io.set_mass(fdm, frame, aircraft.fuel_kg, aircraft.ballast_kg,
                    aircraft.ballast_position_body_m)
    except ValueError as exc:
        raise FlightError(f"{where}: aircraft {aircraft.id}: {exc}") from None
    io.set_initial_conditions(
        fdm,
        latitude_rad=env.latitude_rad,
        longitude_rad=env.longitude_rad,
        altitude_m=spec.altitude_m,
        heading_rad=spec.heading_rad,
        mach=spec.trim_mach,
    )
    io.start_engines(fdm)
    io.set_gear(fdm, spec.gear_down)
    fdm.run_ic()
    trim_residuals = _trim(fdm, spec)
    reader = io.SampleReader(fdm, frame)
    x_trim = reader.read_si()
    C = io.COL
    trim = trim_point(x_trim)
    trim_meta = {
        "mach": trim.mach, "altitude_m": trim.altitude_m, "heading_rad": trim.heading_rad,
        "alpha_rad": trim.alpha_rad, "theta_rad": trim.theta_rad,
        "throttle_cmd_norm": trim.throttle_cmd_norm,
        "elevator_pos_rad": float(x_trim[C["elevator_pos_rad"]]),
        "mass_kg": float(x_trim[C["mass_kg"]]),
        "r_cg_body_m": [float(x_trim[C[f"cg_{a}_m"]]) for a in "xyz"],
        "gear_pos_norm": float(x_trim[C["gear_pos_norm"]]),
        "residuals": {k: float(v) for k, v in trim_residuals.items()},
    }
    wind_entry = env.wind_ned_mps
    vertical = env.vertical_wind_ned_mps(np.zeros(1))
    if vertical is not None:
        # the aircraft has been flying in the moving air mass: restarted with its trimmed
        # air-relative state in the steady wind plus the vertical motion's first value, it starts
        # without a transient (the settling flies it held; fly_maneuver lets it vary from t = 0)
        wind_entry = tuple(float(x) for x in np.asarray(env.wind_ned_mps) + vertical[0])
    if any(wind_entry):
        _reinit_with_wind(fdm, reader, wind_entry)
    if env.turbulence != "none":
        io.set_turbulence(fdm, severity=env.turbulence_severity,
                          windspeed_at_20ft_mps=env.turbulence_w20_mps)
    settle_steps = int(round(SETTLE_S / dt_s))
    for _ in range(settle_steps):
        fdm.run()

    return fdm, reader, trim, trim_meta


def fly_controller(
    fdm: jsbsim.FGFDMExec,
    reader: io.SampleReader,
    controller,
    n: int,
    dt_s: float,
    advice: str,
    on_step=None,
    *,
    finish: bool = True,
) -> np.ndarray:
    """Let ``controller`` fly ``n`` samples (``n - 1`` steps) from the FDM's current state.

    Departures (:func:`_departure`) and the controller's own checks are tested on the way and on the
    whole record at the end, then ``controller.finish`` judges the run. ``on_step(i)`` (optional) is
    called at each sample before the inputs are set (the gust's onset). The FDM is left at the last
    sample's state, so a following leg starts where this one ends. ``finish=False`` leaves the
    judgement to the caller (a sortie records a maneuver that missed its goal and flies on).

    Returns
    -------
    (n, channels) SI samples (``jsbsim_io.COL``), the first the state on entry.

    Raises
    ------
    ManeuverFailure
        With the time since entry, what went wrong and ``advice``.
    """
    t_s = np.arange(n) * dt_s
    raw = np.empty((n, reader.n_channels))
    setters = io.InputSetter(fdm)
    scale, offset = reader.scale, reader.offset
    read_raw = reader.read_raw
    run = fdm.run
    for i in range(n):
        row = read_raw()
        raw[i] = row
        # plain floats: the controllers' scalar math is several times faster than on numpy
        x = (raw[i] * scale + offset).tolist()
        t = i * dt_s
        if i % _CHECK_EVERY == 0:
            msg = _departure(x)
            if msg is not None:
                raise ManeuverFailure(msg, t, advice)
            controller.check(t, x)
        if on_step is not None:
            on_step(i)
        if i < n - 1:
            setters.set(*controller.inputs(t, x))
            if not run():
                raise ManeuverFailure("JSBSim stopped the run", t, "check the JSBSim log")
    si = reader.to_si(raw)
    # the per-step checks sample every few steps; departures must not slip between them
    k = _first_departure(si)
    if k is not None:
        raise ManeuverFailure(_departure(si[k]) or "departed", float(t_s[k]), advice)
    if finish:
        controller.finish(si, t_s)
    return si


def segment_bounds(n: int, n_segments: int) -> list[tuple[int, int]]:
    """The sample ranges ``[lo, hi)`` of the ``n_segments`` recorded pieces of an ``n``-sample run
    (SHSS; one piece otherwise): equal lengths, neighbours sharing no sample, the last one ends
    with the run."""
    bounds = np.linspace(0, n - 1, n_segments + 1).round().astype(int)
    return [(int(bounds[k]), int(bounds[k + 1]) + (1 if k == n_segments - 1 else 0))
            for k in range(n_segments)]


def fly_maneuver(
    spec: ManeuverSpec,
    airframe: Airframe,
    aircraft: Aircraft,
    env: Environment,
    *,
    dt_s: float = 1.0 / 120.0,
    added_wind: Callable[[np.ndarray], np.ndarray] | None = None,
) -> list[TruthTrajectory]:
    """Fly ``spec`` with ``aircraft`` in ``env`` and return its truth.

    Parameters
    ----------
    spec : the maneuver (kind, Mach, altitude, gear, excitation).
    airframe : which JSBSim model flies and its reference point (body-axis origin).
    aircraft : fuel (split equally between the two internal tanks) and ballast of the tail.
    env : planet, steady wind, turbulence and its seed, gust.
    dt_s : simulation step, s (default 1/120 s).
    added_wind : ``t_s`` (n,) -> (n, 3) wind, NED, m/s, added to ``env``'s steady wind and set at
        every step, so that the aircraft flies through it (a turbulence model of a study's own;
        None: none). The truth's wind is the steady wind plus it at every sample but the first,
        the state on entry, which has the steady wind: start the history at zero. ``env``'s slow
        vertical air motion (:class:`~synth.environment.VerticalAirMotion`, the realism level) is
        flown the same way, added to it; the state on entry has its first value (it is there
        from the trim on, see :func:`start_flight`).

    Returns
    -------
    One :class:`TruthTrajectory` per recorded piece: one, except SHSS, which returns its
    ``spec.n_segments`` pieces, each with ``t_s`` starting at 0, ``meta['segment'] = i`` and
    ``meta['segment_start_s']`` its start within the run.

    Raises
    ------
    FlightError
        If the trim fails, the aircraft departs, or the controller cannot hold its target.
    """
    where = describe_spec(spec)
    fdm, reader, trim, trim_meta = start_flight(spec, airframe, aircraft, env, dt_s)
    controller = make_controller(spec, trim, dt_s)
    n = int(round(spec.duration_s / dt_s)) + 1
    t_s = np.arange(n) * dt_s
    gust_step = (
        int(round(env.gust.start_s / dt_s)) if env.gust is not None else -1
    )
    if env.gust is not None and gust_step >= n:
        raise FlightError(
            f"{where}: gust start_s {env.gust.start_s} s is after the end of the "
            f"{spec.duration_s} s maneuver; start it earlier"
        )

    extra = None if added_wind is None else np.asarray(added_wind(t_s), dtype=float)
    if extra is not None and extra.shape != (n, 3):
        raise ValueError(f"{where}: added_wind must return an (n, 3) NED wind for the {n} steps, "
                         f"got shape {extra.shape}")
    vertical = env.vertical_wind_ned_mps(t_s)
    if vertical is not None:
        extra = vertical if extra is None else vertical + extra
    steady = np.asarray(env.wind_ned_mps, dtype=float)

    def on_step(i: int) -> None:  # the added wind, and the gust at its step
        if extra is not None:  # the step from sample i flies in the wind of sample i + 1
            io.set_wind_ned(fdm, steady + extra[min(i + 1, n - 1)])
        if i == gust_step:
            io.start_cosine_gust(fdm, amplitude_mps=env.gust.amplitude_mps,
                                 direction_ned=env.gust.direction_ned,
                                 duration_s=env.gust.duration_s)

    try:
        si = fly_controller(fdm, reader, controller, n, dt_s, departure_advice(spec), on_step)
    except ManeuverFailure as exc:
        raise FlightError(
            f"{where} (aircraft {aircraft.id}), t = {exc.t_s:.2f} s into "
            f"the maneuver: {exc.what}. Try: {exc.advice}."
        ) from None

    # meta holds only facts that the inputs determine (no wall time, no paths): datasets written
    # from it must be bit-identical for one seed
    meta_common = {
        "maneuver": spec.to_dict(),
        "environment": env.to_dict(),
        "trim": trim_meta,
        "controller": dict(controller.notes),
        "jsbsim_version": io.JSBSIM_VERSION,
        "jsbsim_model": airframe.jsbsim_model,
        "airframe": airframe.name,
        "aircraft": aircraft.id,
        "fuel_kg": aircraft.fuel_kg,
        "ballast_kg": aircraft.ballast_kg,
        "ballast_position_body_m": [float(v) for v in aircraft.ballast_position_body_m],
        "dt_s": dt_s,
        "settle_s": SETTLE_S,
        "n_segments": spec.n_segments,
    }
    out = []
    n_seg = spec.n_segments
    for k, (lo, hi) in enumerate(segment_bounds(n, n_seg)):
        meta = dict(meta_common, segment=k, segment_start_s=float(t_s[lo]))
        out.append(io.to_truth(si[lo:hi], t_s[lo:hi] - t_s[lo], planet=env.planet, meta=meta))
    return out


def departure_advice(spec: ManeuverSpec) -> str:
    """What to change when this kind of maneuver departs or loses its target (for messages)."""
    if spec.kind in ("pitch_doublet", "3211", "roller_coaster", "pullup_rudder_doublets"):
        return "lower delta_nz, or fly faster / higher"
    if spec.kind == "pullup_pushover":
        return "reduce nz_max or raise nz_min, or fly faster / higher"
    if spec.kind == "windup_turn":
        return "lower alpha_max_rad, or fly higher / at lower Mach"
    if spec.kind == "shss":
        return "reduce beta_rad"
    return "reduce delta_mach or fly higher"
