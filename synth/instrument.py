"""Instrumentation: what the aircraft's sensors and recorders record of a true flight history.

Pipeline (SPEC §6, paper Eq. 2 and §3), for one maneuver
--------------------------------------------------------
1. Flow at each sensor from the exact rigid-body air velocity ``V + omega x (r_s - r_cg)``
   (:mod:`synth.local_flow`), its free-stream alpha, beta, flank.
2. Local-flow truth per sensor type (upwash, sidewash, gear, nose-probe irregularity) and the
   installation bias of the aircraft: the angle each sensor physically senses, at the truth rate.
3. Recorders (:mod:`synth.recorders`): each channel sampled at its recorder's stamps, lagged by
   the recorder's latency and clock offset plus the channel's delay, interpolated from the truth.
4. Transduction (:mod:`synth.sensors`): vanes output the angle (scale, noise, quantization);
   probes output Pa1 - Pa2 / Pb1 - Pb2 by the hemispherical-head law with pressure noise;
   IMU, INS, pressures, temperature and DGPS height with their biases and noise.
5. The airdata computer (:mod:`synth.airdata_computer`), on the DRU's samples: Mach, TAS and
   pressure altitude from the measured pressures; the baseline corrections f_v, f_sp, f_np.
6. Preprocessing: every recorder's stream resampled by its own stamps onto one common time base
   (the overlap of all streams), with the truth interpolated beside it at true time.

Use :func:`instrument`; :func:`channel_response` evaluates the noise-free calibration relationship
(what the estimator's tables f1..f5 should find).

The realism level (opt-in, docs/realism.md) acts on the continuous signals of stages 3-4 (IMU
matrices, static-source error and pneumatic lags) and on the INS (attitude drift, held GNSS
velocity): :func:`_realism_signals`, :func:`_ins_attitude_errors`, :func:`_record_ins_dgps`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import pandas as pd

from aircraft_models import ALL_SENSORS, Airframe, Configuration
from aircraft_models.schema import unknown
from synth.airdata_computer import (
    AirdataComputer,
    build_airdata_computer,
    impact_pressure_pa,
    mach_from_pressures,
    pressure_altitude_m,
    tas_from_mach_mps,
    total_temperature_k,
)
from synth.errors import PROBE_SENSORS, RECORDERS, ErrorConfig, channel_rng
from synth.local_flow import (
    LocalFlowModel,
    TableGrid,
    air_velocity_at_sensor_body_mps,
    flow_angles_rad,
    irregularity_rad,
    load_adc_baseline,
    load_local_flow_truth,
)
from synth.processes import (
    first_order_lag,
    gauss_markov,
    hold_fix_times_s,
    static_source_error_ratio,
)
from synth.recorders import (
    allowed_stamp_interval_s,
    average_at,
    grid_in_interval_s,
    resample_hold,
    resample_linear,
    sample_at,
)
from synth.sensors import imu_specific_force_body_mps2, ned_velocity_mps, transduce
from synth.truth import TruthTrajectory

#: The raw channel each flow sensor records (vanes: angle, probes: differential pressure).
SENSOR_RAW_CHANNEL: Mapping[str, str] = {
    "vane_left": "alpha_lm_rad",
    "vane_right": "alpha_rm_rad",
    "side_probe_left": "dp_alpha_lsp_pa",
    "side_probe_right": "dp_alpha_rsp_pa",
    "nose_probe": "dp_beta_np_pa",
    "boom_alpha_vane": "alpha_zb_rad",
    "boom_beta_upper_vane": "beta_zbu_rad",
    "boom_beta_lower_vane": "beta_zbl_rad",
}

#: Each calibrated channel and the truth column it estimates (the true flow angle at its sensor).
CHANNEL_TRUTH: Mapping[str, str] = {
    "alpha_zl_rad": "true_alpha_vane_left_rad",
    "alpha_zr_rad": "true_alpha_vane_right_rad",
    "alpha_zsp_rad": "true_alpha_sp_rad",
    "beta_zsp_rad": "true_beta_sp_rad",
    "beta_znp_rad": "true_beta_nose_probe_rad",
    "alpha_zb_rad": "true_alpha_boom_alpha_vane_rad",
    "beta_zbu_rad": "true_flank_boom_beta_upper_vane_rad",
    "beta_zbl_rad": "true_flank_boom_beta_lower_vane_rad",
}

_IMU_COLUMNS = ("ax_imu_mps2", "ay_imu_mps2", "az_imu_mps2", "p_rps", "q_rps", "r_rps")
_AIRDATA_COLUMNS = ("qc_pa", "ps_pa", "tt_k")
_INS_COLUMNS = ("phi_rad", "theta_rad", "psi_rad", "vn_mps", "ve_mps", "vd_mps")
#: Stable index of every random channel (part of its generator's seed): never reorder, only append.
_RNG_INDEX = {name: i for i, name in enumerate(
    (*_IMU_COLUMNS, *_AIRDATA_COLUMNS, *_INS_COLUMNS, "h_dgps_m", *ALL_SENSORS,
     "nose_probe_high_alpha"))}


@dataclass(frozen=True)
class InstrumentedManeuver:
    """What the recorders captured of one maneuver, preprocessed, with the truth beside it.

    Attributes
    ----------
    data : one row per common-time-base sample: ``t_s``, measured channels, raw sensor outputs
        and ``true_*`` columns (see :func:`instrument`).
    injected : every injected value, SI, flat names (``imu.accel_bias_mps2``,
        ``vane_left.installation_bias_rad``, ``dru.delay_s``, ``seeds.imu_noise``,
        ``time_shift_s.<column>`` = total lag of a measured column against the truth, ...).
    channel_units : column -> unit.
    streams : recorder -> its raw stream (``t_s`` = its stamps) before resampling.
    own_rate_columns : measured columns kept at their own, slower samples: empty (NaN) between
        them, because their recorder's stamps lie on the common time base (see :func:`instrument`).
    """

    data: pd.DataFrame
    injected: dict[str, float | list]
    channel_units: dict[str, str]
    streams: dict[str, pd.DataFrame] = field(default_factory=dict)
    own_rate_columns: tuple[str, ...] = ()


# ------------------------------------------------------------------ sensing kernels (shared)


def _side_sign(airframe: Airframe, sensor: str) -> float:
    y = float(airframe.position(sensor)[1])
    if y == 0.0:
        raise ValueError(f"airframe {airframe.name!r}: {sensor} sits at y = 0; a fuselage-side "
                         "sensor needs its side (y < 0 left, y > 0 right) in positions_body_m")
    return math.copysign(1.0, y)


def _sensed_local_rad(sensor: str, model: LocalFlowModel, side_sign: float, alpha_rad, beta_rad,
                      flank_rad, mach, gear) -> dict[str, np.ndarray]:
    """The local angle(s) a sensor senses for the free-stream angles at its position.

    Returns ``{"sensed": ...}`` plus the intermediate local angles for the truth columns.
    """
    if sensor in ("vane_left", "vane_right"):
        loc = model.vane_local_alpha_rad(alpha_rad, beta_rad, mach, gear, side_sign)
        return {"sensed": loc, "local_alpha": loc}
    if sensor in ("side_probe_left", "side_probe_right"):
        a_loc, b_loc = model.side_probe_local_rad(alpha_rad, beta_rad, mach, gear)
        theta = model.side_probe_port_angle_rad(a_loc, b_loc, side_sign)
        return {"sensed": theta, "local_alpha": a_loc, "local_beta": b_loc, "port_angle": theta}
    if sensor == "nose_probe":
        loc = model.nose_probe_local_flank_rad(alpha_rad, beta_rad, flank_rad, mach, None)
        return {"sensed": loc, "local_flank": loc}
    if sensor == "boom_alpha_vane":
        loc = model.boom_local_alpha_rad(alpha_rad, mach)
        return {"sensed": loc, "local_alpha": loc}
    loc = model.boom_local_flank_rad(sensor, alpha_rad, flank_rad, mach)
    return {"sensed": loc, "local_flank": loc}


class FlowModels(NamedTuple):
    """The local-flow truth and the ADC's baseline (its nominal model and table grid): loaded once
    by a caller that evaluates many channels; each None is loaded (:mod:`synth.local_flow`)."""

    truth_model: LocalFlowModel | None = None
    adc_baseline: tuple[LocalFlowModel, TableGrid] | None = None


def _models(errors: ErrorConfig, truth_model: LocalFlowModel | None,
            adc_baseline: tuple[LocalFlowModel, TableGrid] | None
            ) -> tuple[LocalFlowModel, LocalFlowModel, AirdataComputer]:
    """(truth model, model the sensors see, airdata computer) for the error switches."""
    truth_model = truth_model or load_local_flow_truth()
    nominal, grid = adc_baseline or load_adc_baseline()
    sensing = truth_model if errors.local_flow else truth_model.without_local_flow()
    adc = build_airdata_computer(nominal if errors.baseline_mismatch else sensing, grid)
    return truth_model, sensing, adc


def channel_response(
    channel: str,
    alpha_rad: np.ndarray,
    beta_rad: np.ndarray,
    mach: np.ndarray,
    gear_down: float | np.ndarray = 0.0,
    *,
    local_flow: bool = True,
    baseline_mismatch: bool = True,
    models: FlowModels | None = None,
) -> np.ndarray:
    """The noise-free calibration relationship of one ADC output channel.

    Every flow sensor is taken ideal (no installation bias, scale, noise, quantization, delay)
    and to see the same free-stream ``alpha_rad``, ``beta_rad`` at its position (no rotation);
    the value returned is what the ADC outputs on that channel (with its tables, so including
    interpolation error). The nose-probe irregularity is excluded (it is not a function an
    estimator can find). This is the "true table" the estimator should recover; e.g. at Mach M
    the paper's ``f1(alpha) = channel_response("alpha_zl_rad", alpha, 0, M)`` and
    ``f2(alpha) ~ d channel_response("alpha_zl_rad", alpha, beta, M) / d beta`` (opposite signs
    left and right: the vane sidewash coupling is antisymmetric).

    Parameters
    ----------
    channel : one of :data:`CHANNEL_TRUTH`'s keys (``alpha_zl_rad``, ..., ``beta_zbl_rad``).
    alpha_rad, beta_rad : free-stream angle of attack and aerodynamic sideslip at the sensor, rad.
    mach : free-stream Mach number (also taken as the ADC's measured Mach).
    gear_down : gear position 0..1 for the truth; the ADC's flag is ``gear_down >= 0.5``.
    local_flow, baseline_mismatch : the :class:`~synth.errors.ErrorConfig` switches.
    models : the local-flow truth and the ADC's baseline to use (loaded when None, or each None).

    Returns
    -------
    The channel's value, rad (beta channels of the boom: the flank-angle measurement).
    """
    if channel not in CHANNEL_TRUTH:
        raise unknown([channel], CHANNEL_TRUTH, "channel_response", what="channel")
    switches = ErrorConfig(local_flow=local_flow, baseline_mismatch=baseline_mismatch)
    models = models or FlowModels()
    _, sensing, adc = _models(switches, models.truth_model, models.adc_baseline)
    alpha, beta, mach, gear = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in
                                                    (alpha_rad, beta_rad, mach, gear_down)))
    flank = np.arctan2(np.sin(beta), np.cos(beta) * np.cos(alpha))
    flag = (gear >= 0.5).astype(float)

    def sensed(sensor: str, sign: float = 1.0) -> np.ndarray:
        return _sensed_local_rad(sensor, sensing, sign, alpha, beta, flank, mach, gear)["sensed"]

    def vane(sign: float) -> np.ndarray:
        return adc.f_v(sensed("vane_left" if sign < 0 else "vane_right", sign), mach, flag)

    if channel in ("alpha_zl_rad", "alpha_zr_rad"):
        return vane(-1.0 if channel == "alpha_zl_rad" else 1.0)
    if channel in ("alpha_zsp_rad", "beta_zsp_rad"):
        law = sensing.side_probe_pressure
        lsp, rsp = (adc.side_probe_angle_rad(law.dp_pa(sensed(s, sg), 1.0, mach), 1.0, mach)
                    for s, sg in (("side_probe_left", -1.0), ("side_probe_right", 1.0)))
        a, b = adc.f_sp(lsp, rsp, mach, flag)
        return a if channel == "alpha_zsp_rad" else b
    if channel == "beta_znp_rad":
        dp = sensing.nose_probe_pressure.dp_pa(sensed("nose_probe"), 1.0, mach)
        return adc.f_np(adc.nose_probe_flank_rad(dp, 1.0, mach), vane(-1.0), vane(1.0), mach)
    sensor = {"alpha_zb_rad": "boom_alpha_vane", "beta_zbu_rad": "boom_beta_upper_vane",
              "beta_zbl_rad": "boom_beta_lower_vane"}[channel]
    return sensed(sensor)


# ------------------------------------------------------------------ instrument


def _check_truth(truth: TruthTrajectory, common_rate_hz: float) -> None:
    t = truth.t_s
    if truth.n_samples < 2 or np.any(np.diff(t) <= 0):
        raise ValueError("instrument: truth.t_s needs >= 2 strictly increasing samples")
    if not (math.isfinite(common_rate_hz) and common_rate_hz > 0):
        raise ValueError(f"instrument: common_rate_hz = {common_rate_hz!r} must be > 0")
    bad = np.flatnonzero(~(truth.mach < 1.0))
    if bad.size:
        raise ValueError(f"instrument: truth.mach = {truth.mach[bad[0]]:.3f} at t = {t[bad[0]]:.3f} s;"
                         " the airdata and local-flow models are subsonic (Mach < 1)")


def _units(column: str) -> str:
    if column in ("t_s",) or column.startswith("time_shift"):
        return "s"
    if column in ("mach", "true_mach", "true_gear_pos_norm"):
        return "1"
    if column == "gear_down":
        return "bool"
    for suffix, unit in (("_rps2", "rad/s^2"), ("_rps", "rad/s"), ("_rad", "rad"),
                         ("_mps2", "m/s^2"), ("_mps", "m/s"), ("_kgpm3", "kg/m^3"), ("_kg", "kg"),
                         ("_pa", "Pa"), ("_k", "K"), ("_m", "m")):
        if column.endswith(suffix):
            return unit
    raise AssertionError(f"no unit for column {column!r}")  # every column name carries its unit


def instrument(
    truth: TruthTrajectory,
    airframe: Airframe,
    configuration: Configuration,
    errors: ErrorConfig,
    *,
    maneuver_key: int = 0,
    common_rate_hz: float = 40.0,
    truth_model: LocalFlowModel | None = None,
    adc_baseline: tuple[LocalFlowModel, TableGrid] | None = None,
) -> InstrumentedManeuver:
    """Record a true flight history as the aircraft's sensors and recorders would, preprocessed.

    Parameters
    ----------
    truth : the flown maneuver at the simulation rate (SI, body axes, origin at the reference point).
    airframe : sensor, IMU and INS positions.
    configuration : which sensors are fitted and the aircraft's installation biases.
    errors : every injected error (:class:`~synth.errors.ErrorConfig`).
    maneuver_key : index of the maneuver in its campaign; every random draw of channel ``c`` uses
        ``default_rng([seed_source, maneuver_key, c])``.
    common_rate_hz : rate of the common time base, Hz.
    truth_model, adc_baseline : override the shipped local-flow truth / ADC baseline models.

    Returns
    -------
    InstrumentedManeuver
        ``data`` columns: ``t_s``; measured ``ax_imu_mps2 ay_imu_mps2 az_imu_mps2 p_rps q_rps
        r_rps phi_rad theta_rad psi_rad vn_mps ve_mps vd_mps tas_mps h_baro_m mach h_dgps_m
        gear_down`` and the calibrated flow channels present (``alpha_zl_rad alpha_zr_rad
        alpha_zsp_rad beta_zsp_rad`` + ``beta_znp_rad`` or ``alpha_zb_rad beta_zbu_rad
        beta_zbl_rad``); raw ``alpha_lm_rad alpha_rm_rad dp_alpha_lsp_pa dp_alpha_rsp_pa
        alpha_lsp_rad alpha_rsp_rad [dp_beta_np_pa flank_np_rad] qc_pa ps_pa tt_k``; and the
        ``true_*`` columns (CG state, the INS point's NED velocity ``true_{vn,ve,vd}_ins_mps``,
        winds, Euler angles, forces, CG position, atmosphere, and
        per sensor ``true_{alpha,beta,flank}_<sensor>_rad`` and ``true_local_*_<sensor>_rad``;
        ``true_alpha_sp_rad``/``true_beta_sp_rad`` at the side probes' mean position;
        ``true_clean_<channel>`` for each calibrated flow channel: its value with every
        deterministic error and no noise, quantization or delay).
        ``psi`` is continuous (unwrapped) within the maneuver. A recorder slower than the
        common base whose stamps are common-base times (DGPS at 10 Hz on 40 Hz) keeps its own
        samples: its columns are NaN between them (listed in ``own_rate_columns``); faster or
        unaligned streams are interpolated linearly in their stamps.

    Notes
    -----
    The stages, in order (module docstring): :func:`_flow_at_sensors` (flow and local-flow truth
    at each sensor), :func:`_continuous_signals` (what the other raw channels see),
    :func:`_plan_recorders` (stamps, lags, common time base), :func:`_record_imu_airdata` and
    :func:`_record_flow_transducers` (the DRU: IMU, airdata, gear and flow-sensor transducers),
    :func:`_air_data_computer` (the ADC on the DRU's samples), :func:`_clean_channels` (the
    noise-free calibrated channels), :func:`_record_ins_dgps`, :func:`_to_common_base`
    (preprocessing), :func:`_truth_columns` and :func:`_injected`. Every random channel draws from
    its own generator (``channel_rng``), so the stages' order does not change a draw.
    """
    _check_truth(truth, common_rate_hz)
    truth_model, sensing, adc = _models(errors, truth_model, adc_baseline)
    sensors = configuration.sensors
    euler = truth.euler_rad.copy()
    euler[:, 2] = np.unwrap(euler[:, 2])
    qc_true = impact_pressure_pa(truth.mach, truth.p_static_pa)

    flow = _flow_at_sensors(truth, airframe, configuration, errors, truth_model, sensing)
    direct, f_imu, v_ned, v_ins_ned = _continuous_signals(truth, airframe, euler, qc_true)
    # the realism level (off: the same arrays, untouched): the IMU triads' matrices and the
    # pitot-static system's position error and lags act on the continuous signals
    direct, ports, realism_injected = _realism_signals(truth, errors, direct, qc_true)
    rec = _plan_recorders(truth.t_s, sensors, errors, direct, common_rate_hz)

    def rng(seed: int, name: str) -> np.random.Generator:
        return channel_rng(seed, maneuver_key, _RNG_INDEX[name])

    dru = _record_imu_airdata(truth, errors, direct, rec, rng)
    dru.update(_record_flow_transducers(truth, sensors, errors, flow, sensing, qc_true, rec, rng))
    _air_data_computer(dru, truth, sensors, errors, adc, ports, rec, rng)
    clean_cols = _clean_channels(truth, sensors, errors, flow, sensing, adc, qc_true)
    attitude_error = _ins_attitude_errors(errors, rec, rng)
    if attitude_error:
        realism_injected["realism.ins_attitude_error_mean_rad"] = [
            float(np.mean(attitude_error[c])) for c in _INS_COLUMNS[:3]]
    ins, dgps = _record_ins_dgps(truth, errors, direct, rec, rng, attitude_error)

    streams = {"dru": dru, "ins": ins, "dgps": dgps}
    common, own_rate = _to_common_base(streams, rec, common_rate_hz)
    columns: dict[str, np.ndarray] = {"t_s": rec.t_common_s}
    columns.update({c: common[c] for c in _MEASURED_ORDER if c in common})
    tr = _truth_columns(truth, euler, qc_true, f_imu, v_ned, v_ins_ned, flow, clean_cols)
    for c, v in tr.items():
        columns[c] = sample_at(truth.t_s, v, rec.t_common_s)
    data = pd.DataFrame(columns)

    injected = _injected(errors, maneuver_key, common_rate_hz, sensors, flow.bias_rad, rec, columns)
    injected.update(realism_injected)
    units = {c: _units(c) for c in columns}
    stream_frames = {r: pd.DataFrame({"t_s": rec.stamps[r], **cols}) for r, cols in streams.items()}
    return InstrumentedManeuver(data=data, injected=injected, channel_units=units,
                                streams=stream_frames, own_rate_columns=tuple(own_rate))


# ------------------------------------------------------------------ the stages of instrument()

#: The measured columns of :func:`instrument`'s data, in order (those present).
_MEASURED_ORDER = (
    "ax_imu_mps2", "ay_imu_mps2", "az_imu_mps2", "p_rps", "q_rps", "r_rps",
    "phi_rad", "theta_rad", "psi_rad", "vn_mps", "ve_mps", "vd_mps",
    "tas_mps", "h_baro_m", "mach", "h_dgps_m", "gear_down",
    "alpha_zl_rad", "alpha_zr_rad", "alpha_zsp_rad", "beta_zsp_rad", "beta_znp_rad",
    "alpha_zb_rad", "beta_zbu_rad", "beta_zbl_rad",
    "alpha_lm_rad", "alpha_rm_rad", "alpha_lsp_rad", "alpha_rsp_rad",
    "dp_alpha_lsp_pa", "dp_alpha_rsp_pa", "dp_beta_np_pa", "flank_np_rad",
    "qc_pa", "ps_pa", "tt_k",
)


@dataclass(frozen=True)
class _SensorFlow:
    """The flow at each fitted sensor, at the truth rate (angles in rad).

    Attributes
    ----------
    sensed : sensor -> the angle it physically senses (local flow, irregularity, installation bias).
    free : sensor -> its free-stream (alpha, beta, flank) from the rigid-body air velocity there.
    bias_rad : sensor -> the installation bias injected (0 with the switch off).
    truth_cols : ``true_{alpha,beta,flank}_<sensor>_rad`` and ``true_local_*_<sensor>_rad``.
    alpha_sp_rad, beta_sp_rad : free-stream alpha and beta at the side probes' mean position.
    """

    sensed: dict[str, np.ndarray]
    free: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]
    bias_rad: dict[str, float]
    truth_cols: dict[str, np.ndarray]
    alpha_sp_rad: np.ndarray
    beta_sp_rad: np.ndarray


def _flow_at_sensors(truth: TruthTrajectory, airframe: Airframe, configuration: Configuration,
                     errors: ErrorConfig, truth_model: LocalFlowModel, sensing: LocalFlowModel
                     ) -> _SensorFlow:
    """Stages 1-2: the free-stream flow at each sensor and the angle it senses (local-flow truth,
    nose-probe irregularity, installation bias), at the truth rate, rad.

    Raises ValueError when the flow at a sensor comes from behind.
    """
    t, r_cg, mach, gear = truth.t_s, truth.r_cg_body_m, truth.mach, truth.gear_pos_norm
    truth_cols: dict[str, np.ndarray] = {}
    sensed: dict[str, np.ndarray] = {}
    free: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    bias_rad: dict[str, float] = {}
    for s in configuration.sensors:
        v_s = air_velocity_at_sensor_body_mps(truth.v_air_body_mps, truth.omega_body_rps,
                                              airframe.position(s), r_cg)
        reverse = np.flatnonzero(v_s[:, 0] <= 0.0)
        if reverse.size:
            raise ValueError(f"instrument: the flow at {s} comes from behind (u = "
                             f"{v_s[reverse[0], 0]:.2f} m/s) at t = {t[reverse[0]]:.3f} s")
        a, b, f = flow_angles_rad(v_s)
        free[s] = (a, b, f)
        sign = _side_sign(airframe, s) if s in ("vane_left", "vane_right", "side_probe_left",
                                                  "side_probe_right") else 1.0
        loc = _sensed_local_rad(s, sensing, sign, a, b, f, mach, gear)
        if s == "nose_probe" and errors.nose_probe_irregularity:
            irr = irregularity_rad(a, b, truth_model.nose_probe_irregularity,
                                   errors.seeds.nose_probe_irregularity)
            loc = {"sensed": loc["sensed"] + irr, "local_flank": loc["local_flank"] + irr}
        bias_rad[s] = (float(configuration.aircraft.installation_bias_rad[s])
                       if errors.installation_biases else 0.0)
        sensed[s] = loc.pop("sensed") + bias_rad[s]
        truth_cols[f"true_alpha_{s}_rad"] = a
        truth_cols[f"true_beta_{s}_rad"] = b
        truth_cols[f"true_flank_{s}_rad"] = f
        for k, v in loc.items():
            truth_cols[f"true_{k}_{s}_rad"] = v
    r_sp = 0.5 * (airframe.position("side_probe_left") + airframe.position("side_probe_right"))
    a_sp, b_sp, _ = flow_angles_rad(air_velocity_at_sensor_body_mps(
        truth.v_air_body_mps, truth.omega_body_rps, r_sp, r_cg))
    return _SensorFlow(sensed, free, bias_rad, truth_cols, a_sp, b_sp)


def _continuous_signals(truth: TruthTrajectory, airframe: Airframe, euler: np.ndarray,
                        qc_true: np.ndarray
                        ) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray]:
    """The continuous signal behind each non-flow raw channel, at the truth rate.

    Returns ``(direct, f_imu, v_ned, v_ins_ned)``: raw column -> its true signal (SI, the
    column's unit); the specific force at the IMU, m/s^2 (n, 3); the NED velocity of the CG and
    of the INS point, ``v_cg + omega x (r_ins - r_cg)`` rotated to NED, m/s (n, 3): the INS
    measures the latter; its Euler angles are the body's (one attitude for every point of a rigid
    body). ``euler`` in rad with psi unwrapped, ``qc_true`` in Pa.
    """
    r_imu_cg = airframe.position("imu") - truth.r_cg_body_m
    f_imu = imu_specific_force_body_mps2(truth.specific_force_cg_body_mps2, truth.omega_body_rps,
                                         truth.omega_dot_body_rps2, r_imu_cg)
    v_ned = ned_velocity_mps(truth.v_body_mps, euler)
    # one rigid-body transport for every point velocity: the one the flow at the sensors uses
    # (earth- and air-relative velocities differ by the wind, the same at every point)
    v_ins_ned = ned_velocity_mps(air_velocity_at_sensor_body_mps(
        truth.v_body_mps, truth.omega_body_rps, airframe.position("ins"), truth.r_cg_body_m), euler)
    tt_true = total_temperature_k(truth.t_static_k, truth.mach)
    direct = {
        "ax_imu_mps2": f_imu[:, 0], "ay_imu_mps2": f_imu[:, 1], "az_imu_mps2": f_imu[:, 2],
        "p_rps": truth.omega_body_rps[:, 0], "q_rps": truth.omega_body_rps[:, 1],
        "r_rps": truth.omega_body_rps[:, 2],
        "qc_pa": qc_true, "ps_pa": truth.p_static_pa, "tt_k": tt_true, "gear_down": truth.gear_pos_norm,
        "phi_rad": euler[:, 0], "theta_rad": euler[:, 1], "psi_rad": euler[:, 2],
        "vn_mps": v_ins_ned[:, 0], "ve_mps": v_ins_ned[:, 1], "vd_mps": v_ins_ned[:, 2],
        "h_dgps_m": truth.h_m,
    }
    return direct, f_imu, v_ned, v_ins_ned


def _realism_signals(truth: TruthTrajectory, errors: ErrorConfig, direct: dict[str, np.ndarray],
                     qc_true: np.ndarray
                     ) -> tuple[dict[str, np.ndarray], tuple[np.ndarray, np.ndarray], dict[str, list]]:
    """The realism level on the continuous signals, at the truth rate (docs/realism.md).

    * IMU: each triad measures ``(I + M) x`` (:meth:`~synth.errors.RealismErrors.imu_matrix`:
      scale factors, non-orthogonality, mounting), before its bias and noise.
    * Pitot-static system: the static port senses ``ps + dPp``, ``dPp = qc (c0 + c_alpha alpha +
      c_mach2 M^2)`` (true alpha at the CG, true Mach; :func:`synth.processes.static_source_error_ratio`),
      the pitot the true total pressure ``pt = ps + qc``; the static and total lines lag them to the
      ADC's transducers (:func:`synth.processes.first_order_lag`): ``ps_pa = L_s(ps + dPp)``,
      ``qc_pa = L_t(pt) - L_s(ps + dPp)``. Pressure altitude, Mach and TAS follow from them.

    Returns
    -------
    ``direct`` (a new dict when changed), the impact and static pressure at the ports (Pa; the
    probes' normalising pressures: position error, no line lag) and the realism values to add to
    the injected ones (the triads' matrices ``I + M``, row-major). Off: the inputs themselves.
    """
    real = errors.realism
    ports = (qc_true, truth.p_static_pa)
    extra: dict[str, list] = {}
    if not (real.imu_matrix_errors or real.static_source_error or real.static_lag_s or real.total_lag_s):
        return direct, ports, extra
    direct = dict(direct)
    if real.imu_matrix_errors:
        for triad, cols in (("accel", _IMU_COLUMNS[:3]), ("gyro", _IMU_COLUMNS[3:])):
            m = real.imu_matrix(triad)
            sensed = np.stack([direct[c] for c in cols], axis=1) @ m.T
            direct.update({c: sensed[:, i] for i, c in enumerate(cols)})
            extra[f"realism.{triad}_matrix"] = [float(v) for v in m.ravel()]
    if not (real.static_source_error or real.static_lag_s or real.total_lag_s):
        return direct, ports, extra
    ps_port = truth.p_static_pa
    dp_port = np.zeros_like(qc_true)
    if real.static_source_error:
        dp_port = qc_true * static_source_error_ratio(
            truth.alpha_rad, truth.mach, real.static_error_c0, real.static_error_c_alpha_per_rad,
            real.static_error_c_mach2)
        ps_port = truth.p_static_pa + dp_port
    pt_port = truth.p_static_pa + qc_true  # a pitot senses the total pressure within +-20 deg
    ps_line = first_order_lag(truth.t_s, ps_port, real.static_lag_s)
    direct["ps_pa"] = ps_line
    direct["qc_pa"] = first_order_lag(truth.t_s, pt_port, real.total_lag_s) - ps_line
    return direct, (qc_true - dp_port, ps_port), extra


@dataclass(frozen=True)
class _RecorderPlan:
    """When each recorder samples each channel (times in s).

    Attributes
    ----------
    t_s : the truth's time, s.
    recorders : recorder -> its settings (rate, latency, clock offset).
    lag_s : recorder -> {raw channel (column name, or sensor name for a flow sensor): its lag
        behind true time on that recorder's clock (latency + group/sensor/channel delay)}.
    stamps : recorder -> its sample stamps (the common base for an ideal recorder).
    t_common_s : the common time base (the overlap of all streams).
    imu_window_s : the interval an IMU sample averages (0: an ideal recorder samples).
    """

    t_s: np.ndarray
    recorders: Mapping
    lag_s: dict[str, dict[str, float]]
    stamps: dict[str, np.ndarray]
    t_common_s: np.ndarray
    imu_window_s: float

    def at(self, r: str, channel: str, signal: np.ndarray) -> np.ndarray:
        """``signal`` (truth rate) as recorder ``r`` samples ``channel``."""
        return sample_at(self.t_s, signal,
                         self.stamps[r] - self.recorders[r].clock_offset_s - self.lag_s[r][channel])

    def imu_at(self, channel: str, signal: np.ndarray) -> np.ndarray:
        """An IMU channel: interval means (strapdown increments) over the DRU's sample interval."""
        if self.imu_window_s == 0.0:
            return self.at("dru", channel, signal)
        return average_at(self.t_s, signal,
                          self.stamps["dru"] - self.recorders["dru"].clock_offset_s
                          - self.lag_s["dru"][channel], self.imu_window_s)


def _plan_recorders(t: np.ndarray, sensors, errors: ErrorConfig, direct: dict[str, np.ndarray],
                    common_rate_hz: float) -> _RecorderPlan:
    """Stage 3: each recorder's lags per channel, its stamps and the common time base (s).

    Raises ValueError when a recorder records fewer than 2 samples or the streams barely overlap.
    """
    rec = errors.recorders
    chd = errors.channel_delays_s
    group_delay = {**{c: errors.imu.delay_s for c in _IMU_COLUMNS},
                   **{c: errors.airdata.delay_s for c in _AIRDATA_COLUMNS}}
    plan: dict[str, dict[str, float]] = {r: {} for r in RECORDERS}
    for c in direct:
        r = "dru" if c in (*_IMU_COLUMNS, *_AIRDATA_COLUMNS, "gear_down") else (
            "ins" if c in _INS_COLUMNS else "dgps")
        plan[r][c] = rec[r].delay_s + group_delay.get(c, 0.0) + chd.get(c, 0.0)
    for s in sensors:
        plan["dru"][s] = rec["dru"].delay_s + errors.sensors[s].delay_s
    # an IMU sample averages the interval before its stamp: it needs truth that far back
    window_lag = {c: plan["dru"][c] + (1.0 / rec["dru"].rate_hz if rec["dru"].rate_hz else 0.0)
                  for c in _IMU_COLUMNS}
    real = errors.realism
    # a held GNSS velocity fix can be up to its latency and one fix interval older than the sample
    hold_lag = ([plan["ins"][c] + real.gnss_velocity_latency_s + 1.0 / real.gnss_velocity_rate_hz
                 for c in _INS_COLUMNS[3:]] if real.gnss_velocity else [])
    t0, t1 = float(t[0]), float(t[-1])
    intervals = {}
    for r in RECORDERS:
        lags = list(plan[r].values()) + (list(window_lag.values()) if r == "dru" else []) + (
            hold_lag if r == "ins" else [])
        lo, hi = allowed_stamp_interval_s(t0, t1, rec[r].clock_offset_s, lags)
        if rec[r].rate_hz is not None:
            stamps = grid_in_interval_s(lo, hi, rec[r].rate_hz)
            if len(stamps) < 2:
                raise ValueError(f"instrument: recorder {r} at {rec[r].rate_hz} Hz records fewer "
                                 f"than 2 samples of this {t1 - t0:.2f} s maneuver with lags up to "
                                 f"{max(plan[r].values()):.3f} s; lower its delays or fly longer")
            intervals[r] = (stamps, float(stamps[0]), float(stamps[-1]))
        else:
            intervals[r] = (None, lo, hi)
    lo = max(v[1] for v in intervals.values())
    hi = min(v[2] for v in intervals.values())
    t_common = grid_in_interval_s(lo, hi, common_rate_hz)
    if len(t_common) < 2:
        raise ValueError(f"instrument: the recorders' streams overlap on [{lo:.3f}, {hi:.3f}] s only; "
                         "reduce delays/clock offsets or fly a longer maneuver")
    stamps = {r: (v[0] if v[0] is not None else t_common) for r, v in intervals.items()}
    # a real IMU outputs interval means (strapdown increments) over its own sample interval; an
    # ideal recorder (no rate) samples the true signal
    imu_window_s = 1.0 / rec["dru"].rate_hz if rec["dru"].rate_hz is not None else 0.0
    return _RecorderPlan(t, rec, plan, stamps, t_common, imu_window_s)


def _record_imu_airdata(truth: TruthTrajectory, errors: ErrorConfig, direct: dict[str, np.ndarray],
                        rec: _RecorderPlan, rng) -> dict[str, np.ndarray]:
    """Stage 4 on the DRU, its own instruments: the IMU, airdata (qc, ps in Pa, tt in K; Mach, TAS in
    m/s, pressure altitude in m from them) and gear flag, at the DRU's stamps. Returns column ->
    samples, in the stream's column order."""
    seeds = errors.seeds
    dru: dict[str, np.ndarray] = {}
    imu = errors.imu
    for i, c in enumerate(_IMU_COLUMNS):
        accel = i < 3
        dru[c] = transduce(
            rec.imu_at(c, direct[c]),
            bias=(imu.accel_bias_mps2 if accel else imu.gyro_bias_rps)[i % 3],
            noise_std=imu.accel_noise_mps2 if accel else imu.gyro_noise_rps,
            quant_step=imu.accel_quant_mps2 if accel else imu.gyro_quant_rps,
            rng=rng(seeds.imu_noise, c))
    ad = errors.airdata
    for c, bias, noise, quant in (("qc_pa", ad.qc_bias_pa, ad.qc_noise_pa, ad.qc_quant_pa),
                                  ("ps_pa", ad.ps_bias_pa, ad.ps_noise_pa, ad.ps_quant_pa),
                                  ("tt_k", ad.tt_bias_k, ad.tt_noise_k, 0.0)):
        dru[c] = transduce(rec.at("dru", c, direct[c]), bias=bias, noise_std=noise, quant_step=quant,
                           rng=rng(seeds.airdata_noise, c))
    mach_m = mach_from_pressures(dru["qc_pa"], dru["ps_pa"])
    dru["mach"] = mach_m
    dru["tas_mps"] = tas_from_mach_mps(mach_m, dru["tt_k"])
    dru["h_baro_m"] = pressure_altitude_m(dru["ps_pa"])
    dru["gear_down"] = (rec.at("dru", "gear_down", truth.gear_pos_norm) >= 0.5)
    return dru


def _record_flow_transducers(truth: TruthTrajectory, sensors, errors: ErrorConfig, flow: _SensorFlow,
                             sensing: LocalFlowModel, qc_true: np.ndarray, rec: _RecorderPlan,
                             rng) -> dict[str, np.ndarray]:
    """Stage 4 on the DRU, the flow sensors' transducers (vanes: rad; probes: Pa), at the DRU's
    stamps. Returns raw column -> samples, in the configuration's sensor order."""
    seeds = errors.seeds
    raw_cols: dict[str, np.ndarray] = {}
    for s in sensors:
        e = errors.sensors[s]
        raw = SENSOR_RAW_CHANNEL[s]
        theta = rec.at("dru", s, flow.sensed[s])
        if s not in PROBE_SENSORS:
            raw_cols[raw] = transduce(theta, scale=e.scale, noise_std=e.noise_rad,
                                      quant_step=e.quant_rad, rng=rng(seeds.vane_noise, s))
            continue
        qc_s, m_s = rec.at("dru", s, qc_true), rec.at("dru", s, truth.mach)
        law = sensing.side_probe_pressure if s != "nose_probe" else sensing.nose_probe_pressure
        if s == "nose_probe" and e.high_alpha_noise_rad_per_rad > 0.0:
            alpha_s = rec.at("dru", s, flow.free[s][0])
            std = e.high_alpha_noise_rad_per_rad * np.maximum(alpha_s - e.high_alpha_onset_rad, 0.0)
            theta = theta + std * rng(seeds.probe_noise, "nose_probe_high_alpha").standard_normal(
                theta.shape)
        raw_cols[raw] = transduce(law.dp_pa(theta, qc_s, m_s), scale=e.scale, noise_std=e.noise_pa,
                                  quant_step=e.quant_pa, rng=rng(seeds.probe_noise, s))
    return raw_cols


def _air_data_computer(dru: dict[str, np.ndarray], truth: TruthTrajectory, sensors,
                       errors: ErrorConfig, adc: AirdataComputer, ports: tuple[np.ndarray, np.ndarray],
                       rec: _RecorderPlan, rng) -> None:
    """Stage 5: the airdata computer on the DRU's samples (paper Eq. 2); adds the calibrated flow
    channels (rad) and the probes' angles to ``dru`` in place. ``ports``: the impact and static
    pressure at the pitot-static ports (Pa, truth rate; the true ones without the realism level's
    static-source error), which the probes' normalising pressures are."""
    seeds = errors.seeds
    ad = errors.airdata
    mach_m = dru["mach"]
    gear_m = dru["gear_down"].astype(float)

    # A probe's angle is dp / qc: the impact pressure it is normalised by must lag as the probe's
    # differential pressure does, or the probe's delay is no delay of its channel (SPEC §2, §6:
    # y(t - tau)) but an error alpha * (d ln qc / dt) * (tau_probe - tau_qc) -- 0.004 deg in a
    # pull-up with an 80 ms probe lag, 8 Cramer-Rao sigmas of the side-probe AOA bias. The ADC's
    # airdata for each probe are therefore its qc and ps transducers' samples at the probe's lag
    # (the same transducers: same bias and noise realisation as qc_pa, ps_pa), as when the probe's
    # pressures and its normalising pressure share one pneumatic path and transducer frame.
    # With the realism level, the static-source position error is the port's, so the probes'
    # normalising pressures have it too; the ADC lines' pneumatic lag is not theirs (their path's
    # lag is the probe's delay): docs/realism.md.
    qc_port, ps_port = ports

    def probe_airdata(s: str) -> tuple[np.ndarray, np.ndarray]:
        qc_s = transduce(rec.at("dru", s, qc_port), bias=ad.qc_bias_pa, noise_std=ad.qc_noise_pa,
                         quant_step=ad.qc_quant_pa, rng=rng(seeds.airdata_noise, "qc_pa"))
        ps_s = transduce(rec.at("dru", s, ps_port), bias=ad.ps_bias_pa,
                         noise_std=ad.ps_noise_pa, quant_step=ad.ps_quant_pa,
                         rng=rng(seeds.airdata_noise, "ps_pa"))
        return qc_s, mach_from_pressures(qc_s, ps_s)

    # the vanes' Mach argument stays the ADC's own (a lag mismatch there costs only
    # df_v/dM * dM/dt * dtau)
    dru["alpha_zl_rad"] = adc.f_v(dru["alpha_lm_rad"], mach_m, gear_m)
    dru["alpha_zr_rad"] = adc.f_v(dru["alpha_rm_rad"], mach_m, gear_m)
    qc_l, mach_l = probe_airdata("side_probe_left")
    qc_r, mach_r = probe_airdata("side_probe_right")
    dru["alpha_lsp_rad"] = adc.side_probe_angle_rad(dru["dp_alpha_lsp_pa"], qc_l, mach_l)
    dru["alpha_rsp_rad"] = adc.side_probe_angle_rad(dru["dp_alpha_rsp_pa"], qc_r, mach_r)
    dru["alpha_zsp_rad"], dru["beta_zsp_rad"] = adc.f_sp(dru["alpha_lsp_rad"], dru["alpha_rsp_rad"],
                                                         0.5 * (mach_l + mach_r), gear_m)
    if "nose_probe" in sensors:
        qc_n, mach_n = probe_airdata("nose_probe")
        dru["flank_np_rad"] = adc.nose_probe_flank_rad(dru["dp_beta_np_pa"], qc_n, mach_n)
        dru["beta_znp_rad"] = adc.f_np(dru["flank_np_rad"], dru["alpha_zl_rad"],
                                       dru["alpha_zr_rad"], mach_n)


def _clean_channels(truth: TruthTrajectory, sensors, errors: ErrorConfig, flow: _SensorFlow,
                    sensing: LocalFlowModel, adc: AirdataComputer, qc_true: np.ndarray
                    ) -> dict[str, np.ndarray]:
    """The clean calibrated channels at the truth rate, rad: ``true_clean_<channel>`` -> values.

    Every deterministic error (local flow, installation bias, scale, the ADC's tables), no noise,
    no quantization, no delay, true Mach and impact pressure: what an ideal recorder of this
    airdata system would show, the truth a calibration model is fitted to without the noise it
    must average out.
    """
    mach, gear = truth.mach, truth.gear_pos_norm
    clean: dict[str, np.ndarray] = {}
    gear_t = (gear >= 0.5).astype(float)
    for s in sensors:
        e = errors.sensors[s]
        raw = SENSOR_RAW_CHANNEL[s]
        if s not in PROBE_SENSORS:
            clean[raw] = transduce(flow.sensed[s], scale=e.scale)
            continue
        law = sensing.side_probe_pressure if s != "nose_probe" else sensing.nose_probe_pressure
        clean[raw] = transduce(law.dp_pa(flow.sensed[s], qc_true, mach), scale=e.scale)
    clean["alpha_zl_rad"] = adc.f_v(clean["alpha_lm_rad"], mach, gear_t)
    clean["alpha_zr_rad"] = adc.f_v(clean["alpha_rm_rad"], mach, gear_t)
    a_l = adc.side_probe_angle_rad(clean["dp_alpha_lsp_pa"], qc_true, mach)
    a_r = adc.side_probe_angle_rad(clean["dp_alpha_rsp_pa"], qc_true, mach)
    clean["alpha_zsp_rad"], clean["beta_zsp_rad"] = adc.f_sp(a_l, a_r, mach, gear_t)
    if "nose_probe" in sensors:
        flank_np = adc.nose_probe_flank_rad(clean["dp_beta_np_pa"], qc_true, mach)
        clean["beta_znp_rad"] = adc.f_np(flank_np, clean["alpha_zl_rad"], clean["alpha_zr_rad"], mach)
    return {f"true_clean_{c}": v for c, v in clean.items() if c.startswith(("alpha_z", "beta_z"))}


def _ins_attitude_errors(errors: ErrorConfig, rec: _RecorderPlan, rng) -> dict[str, np.ndarray]:
    """The realism level's INS attitude errors at the INS stamps, rad: Euler column -> a stationary
    first-order Gauss-Markov process (:func:`synth.processes.gauss_markov`), one generator per
    axis from ``seeds.ins_attitude``; empty when off."""
    real = errors.realism
    if not real.ins_attitude:
        return {}
    t = rec.stamps["ins"]
    return {c: gauss_markov(t, sigma, tau, rng(errors.seeds.ins_attitude, c))
            for c, sigma, tau in zip(_INS_COLUMNS[:3], real.ins_attitude_sigma_rad, real.ins_attitude_tau_s,
                                     strict=True)}


def _record_ins_dgps(truth: TruthTrajectory, errors: ErrorConfig, direct: dict[str, np.ndarray],
                     rec: _RecorderPlan, rng, attitude_error: Mapping[str, np.ndarray]
                     ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Stage 4 on the INS (Euler angles, rad; NED velocity, m/s) and the DGPS (height, m), at
    their recorders' stamps; returns the two streams, column -> samples.

    ``attitude_error``: Euler column -> the INS filter's attitude error at the INS stamps, rad
    (the realism level; empty: none). With the realism level's GNSS velocity on, each velocity
    sample is the latest GNSS fix that has reached the INS (:func:`synth.processes.hold_fix_times_s`),
    its bias and noise the fix's (one noise draw per fix)."""
    seeds = errors.seeds
    ins_e = errors.ins
    real = errors.realism
    ins: dict[str, np.ndarray] = {}
    for i, c in enumerate(_INS_COLUMNS):
        euler_ch = i < 3
        bias = (ins_e.euler_bias_rad if euler_ch else ins_e.velocity_bias_mps)[i % 3]
        noise = ins_e.euler_noise_rad if euler_ch else ins_e.velocity_noise_mps
        if not euler_ch and real.gnss_velocity:
            t_true = rec.stamps["ins"] - rec.recorders["ins"].clock_offset_s - rec.lag_s["ins"][c]
            t_fix, held = np.unique(hold_fix_times_s(t_true, real.gnss_velocity_rate_hz,
                                                     real.gnss_velocity_latency_s), return_inverse=True)
            fixes = transduce(sample_at(truth.t_s, direct[c], t_fix), bias=bias, noise_std=noise,
                              rng=rng(seeds.ins_noise, c))
            ins[c] = fixes[held]
            continue
        x = rec.at("ins", c, direct[c])
        if c in attitude_error:
            x = x + attitude_error[c]
        ins[c] = transduce(x, bias=bias, noise_std=noise, rng=rng(seeds.ins_noise, c))
    dgps = {"h_dgps_m": transduce(rec.at("dgps", "h_dgps_m", truth.h_m), bias=errors.dgps.h_bias_m,
                                  noise_std=errors.dgps.h_noise_m, rng=rng(seeds.dgps_noise, "h_dgps_m"))}
    return ins, dgps


def _to_common_base(streams: dict[str, dict[str, np.ndarray]], rec: _RecorderPlan,
                    common_rate_hz: float) -> tuple[dict[str, np.ndarray], list[str]]:
    """Stage 6: every recorder's stream onto the common time base by its own stamps; returns
    column -> samples on ``rec.t_common_s`` and the columns kept at their own, slower samples."""
    t_common = rec.t_common_s
    common: dict[str, np.ndarray] = {}
    own_rate: list[str] = []
    for r, cols in streams.items():
        on_grid = _stamps_on_grid(rec.stamps[r], t_common, common_rate_hz)
        for c, v in cols.items():
            if v.dtype == bool:
                common[c] = resample_hold(rec.stamps[r], v, t_common)
            elif on_grid is not None:
                # a slow stream whose stamps are common-base times stays at its own samples:
                # interpolating it between them would low-pass it, which an estimator reads as
                # a small extra delay; it fits the samples where they are instead
                common[c] = np.full(t_common.shape, np.nan)
                common[c][on_grid[1]] = v[on_grid[0]]
                own_rate.append(c)
            else:
                common[c] = resample_linear(rec.stamps[r], v, t_common)
    return common, own_rate


def _truth_columns(truth: TruthTrajectory, euler: np.ndarray, qc_true: np.ndarray, f_imu: np.ndarray,
                   v_ned: np.ndarray, v_ins_ned: np.ndarray, flow: _SensorFlow,
                   clean_cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The ``true_*`` columns at the truth rate (SI, units in their names), to be sampled at true
    time = the common base, no delay. ``v_ned``: the CG's NED velocity (``true_{vn,ve,vd}_mps``);
    ``v_ins_ned``: the INS point's (``true_{vn,ve,vd}_ins_mps``, what the INS measures)."""
    r_cg = truth.r_cg_body_m
    return {
        "true_alpha_cg_rad": truth.alpha_rad, "true_beta_cg_rad": truth.beta_rad,
        "true_tas_mps": truth.tas_mps, "true_mach": truth.mach,
        "true_u_air_mps": truth.v_air_body_mps[:, 0], "true_v_air_mps": truth.v_air_body_mps[:, 1],
        "true_w_air_mps": truth.v_air_body_mps[:, 2],
        "true_u_mps": truth.v_body_mps[:, 0], "true_v_mps": truth.v_body_mps[:, 1],
        "true_w_mps": truth.v_body_mps[:, 2],
        "true_vn_mps": v_ned[:, 0], "true_ve_mps": v_ned[:, 1], "true_vd_mps": v_ned[:, 2],
        "true_vn_ins_mps": v_ins_ned[:, 0], "true_ve_ins_mps": v_ins_ned[:, 1],
        "true_vd_ins_mps": v_ins_ned[:, 2],
        "true_wind_n_mps": truth.wind_ned_mps[:, 0], "true_wind_e_mps": truth.wind_ned_mps[:, 1],
        "true_wind_d_mps": truth.wind_ned_mps[:, 2],
        "true_phi_rad": euler[:, 0], "true_theta_rad": euler[:, 1], "true_psi_rad": euler[:, 2],
        "true_h_m": truth.h_m, "true_h_pressure_m": pressure_altitude_m(truth.p_static_pa),
        "true_p_rps": truth.omega_body_rps[:, 0], "true_q_rps": truth.omega_body_rps[:, 1],
        "true_r_rps": truth.omega_body_rps[:, 2],
        "true_pdot_rps2": truth.omega_dot_body_rps2[:, 0],
        "true_qdot_rps2": truth.omega_dot_body_rps2[:, 1],
        "true_rdot_rps2": truth.omega_dot_body_rps2[:, 2],
        "true_ax_cg_mps2": truth.specific_force_cg_body_mps2[:, 0],
        "true_ay_cg_mps2": truth.specific_force_cg_body_mps2[:, 1],
        "true_az_cg_mps2": truth.specific_force_cg_body_mps2[:, 2],
        "true_ax_imu_mps2": f_imu[:, 0], "true_ay_imu_mps2": f_imu[:, 1],
        "true_az_imu_mps2": f_imu[:, 2],
        "true_r_cg_x_m": r_cg[:, 0], "true_r_cg_y_m": r_cg[:, 1], "true_r_cg_z_m": r_cg[:, 2],
        "true_mass_kg": truth.mass_kg, "true_gear_pos_norm": truth.gear_pos_norm,
        "true_p_static_pa": truth.p_static_pa, "true_t_static_k": truth.t_static_k,
        "true_rho_kgpm3": truth.rho_kgpm3, "true_qbar_pa": truth.qbar_pa, "true_qc_pa": qc_true,
        "true_alpha_sp_rad": flow.alpha_sp_rad, "true_beta_sp_rad": flow.beta_sp_rad,
        **flow.truth_cols,
        **clean_cols,
    }


def _injected(errors: ErrorConfig, maneuver_key: int, common_rate_hz: float, sensors,
              bias_rad: dict[str, float], rec: _RecorderPlan, columns: Mapping[str, np.ndarray]
              ) -> dict[str, float | list]:
    """What was injected, flat names, SI: the errors, the recorders' rates (Hz), the installation
    biases (rad) and each measured column's total lag behind the truth (``time_shift_s.<column>``)."""
    recs = rec.recorders
    injected: dict[str, float | list] = dict(errors.flat())
    injected["maneuver_key"] = float(maneuver_key)
    injected["common_rate_hz"] = float(common_rate_hz)
    for r in RECORDERS:
        injected[f"{r}.rate_hz"] = float(recs[r].rate_hz if recs[r].rate_hz is not None
                                         else common_rate_hz)
    for s in sensors:
        injected[f"{s}.installation_bias_rad"] = bias_rad[s]
    shift = {c: recs[r].clock_offset_s + lag for r in RECORDERS for c, lag in rec.lag_s[r].items()}
    for c in _IMU_COLUMNS:  # an interval mean lags by half its interval
        shift[c] += 0.5 * rec.imu_window_s
    real = errors.realism
    if real.gnss_velocity:  # a held fix: its latency and, on average, half a fix interval
        for c in _INS_COLUMNS[3:]:
            shift[c] += real.gnss_velocity_latency_s + 0.5 / real.gnss_velocity_rate_hz
    # a first-order lag delays what changes slowly by its time constant (the lag mismatch of
    # qc = L_t(pt) - L_s(ps) in a climb is an error, not a delay)
    if real.static_lag_s or real.total_lag_s:
        shift["ps_pa"] += real.static_lag_s
        shift["qc_pa"] += real.total_lag_s
    sources = {"alpha_zl_rad": "vane_left", "alpha_zr_rad": "vane_right",
               "alpha_lsp_rad": "side_probe_left", "alpha_rsp_rad": "side_probe_right",
               "beta_znp_rad": "nose_probe", "flank_np_rad": "nose_probe",
               "mach": "qc_pa", "tas_mps": "qc_pa", "h_baro_m": "ps_pa",
               **{raw: s for s, raw in SENSOR_RAW_CHANNEL.items()}}
    for c in columns:
        if c in shift:
            injected[f"time_shift_s.{c}"] = shift[c]
        elif c in sources and sources[c] in shift:
            injected[f"time_shift_s.{c}"] = shift[sources[c]]
    if "side_probe_left" in shift:
        for c in ("alpha_zsp_rad", "beta_zsp_rad"):
            injected[f"time_shift_s.{c}"] = 0.5 * (shift["side_probe_left"]
                                                   + shift["side_probe_right"])
    return injected


def _stamps_on_grid(stamps_s: np.ndarray, t_common_s: np.ndarray, common_rate_hz: float
                    ) -> tuple[np.ndarray, np.ndarray] | None:
    """For a stream slower than the common base whose stamps are common-base times: the indices
    of its stamps inside the common span and of the common samples they fall on; else None."""
    if len(stamps_s) < 2 or np.median(np.diff(stamps_s)) * common_rate_hz < 1.5:
        return None
    k = np.rint(stamps_s * common_rate_hz)
    if np.max(np.abs(stamps_s * common_rate_hz - k)) > 1e-6:
        return None
    j = (k - round(t_common_s[0] * common_rate_hz)).astype(np.int64)
    inside = np.flatnonzero((j >= 0) & (j < len(t_common_s)))
    return inside, j[inside]
