"""Injected instrumentation errors, as data.

Every error the instrumentation half of ``synth`` injects is an explicit value here (not a
distribution): biases, scale factors, noise standard deviations, quantization steps, delays,
recorder rates and clock offsets, on/off switches for the local-flow truth, the airdata computer's
baseline mismatch, the fleet's installation biases and the nose-probe high-AOA irregularity, and one
seed per random source. Campaigns draw values; this module only holds and checks them.

The realism level (:class:`RealismErrors`, ``[realism]``; preset ``real_world``) adds the slow,
correlated imperfections of real installations; it is off unless asked for (docs/realism.md).

Units are SI and radians inside (SPEC §2). At the dict/TOML edge a key may instead carry an edge
unit, converted here and nowhere else:

========================  ===========================  ===========
field suffix (SI)         accepted edge suffix          factor
========================  ===========================  ===========
``_rad``                  ``_deg``                     pi / 180
``_rps``                  ``_deg_s``                   pi / 180
``_rad_per_rad``          ``_deg_per_deg``             1
``_s``                    ``_ms``                      1e-3
``_per_rad``              ``_per_deg``                 180 / pi
========================  ===========================  ===========

Dict / TOML form (``ErrorConfig.from_dict``; ``to_dict`` writes the SI form)::

    preset = "typical"              # start from "none" (default), "typical" or "real_world"
    local_flow = true               # local-flow truth model on (off: sensors see free stream)
    baseline_mismatch = true        # ADC tables from the nominal model (off: ADC inverts the truth)
    installation_biases = true      # add the fleet's per-aircraft installation biases
    nose_probe_irregularity = true  # deterministic irregular nose-probe error at high AOA

    [imu]                           # IMU on the DRU: specific force and rates, body axes
    accel_bias_mps2 = [0.1, -0.08, 0.15]
    gyro_bias_deg_s = [0.2, -0.3, 0.15]
    accel_noise_mps2 = 0.02         # std per axis
    gyro_noise_deg_s = 0.01
    accel_quant_mps2 = 0.005        # quantization step (0 = none)
    gyro_quant_deg_s = 0.005
    delay_ms = 0.0                  # extra lag of the IMU channels on the DRU

    [ins]                           # INS Euler angles and NED velocities (INS recorder)
    euler_bias_deg = [0.0, 0.0, 0.0]
    euler_noise_deg = 0.03
    velocity_bias_mps = [0.0, 0.0, 0.0]
    velocity_noise_mps = 0.05

    [airdata]                       # impact pressure, static pressure, total temperature (DRU)
    qc_bias_pa = 0.0
    qc_noise_pa = 15.0
    ps_noise_pa = 10.0
    tt_noise_k = 0.2

    [dgps]
    h_noise_m = 0.3

    [sensors.vane_left]             # one table per flow-angle sensor (aircraft_models.ALL_SENSORS)
    scale = 0.0                     # output = (1 + scale) * sensed
    noise_deg = 0.07                # vanes: angle noise and quantization
    quant_deg = 0.05
    delay_ms = 30.0
    [sensors.side_probe_left]
    noise_pa = 20.0                 # probes: pressure noise and quantization
    quant_pa = 1.0
    [sensors.nose_probe]
    high_alpha_noise_deg_per_deg = 0.02   # extra angle-noise std per unit AOA above the onset
    high_alpha_onset_deg = 10.0

    [recorders.dru]                 # dru, ins, dgps; rate_hz absent = ideal (on the common base)
    rate_hz = 64.0
    delay_ms = 20.0                 # latency: the value stamped t is the signal at t - delay
    clock_offset_ms = 0.0           # the recorder's clock reads true time + offset

    [channel_delays_ms]             # extra lag of single non-flow channels, by column name
    phi_rad = 40.0

    [realism]                       # the realism level (docs/realism.md); each source 0 = off
    ins_attitude_sigma_deg = [0.1, 0.1, 0.2]   # INS attitude: Gauss-Markov per axis
    ins_attitude_tau_s = [30.0, 30.0, 60.0]
    accel_scale = [8e-4, -6e-4, 1e-3]          # IMU scale factors, non-orthogonality, mounting
    gyro_nonorthogonality_rad = [-2.5e-4, 3e-4, 2e-4]
    imu_mounting_rad = [1e-3, -8e-4, 1.2e-3]
    static_error_c0 = 0.004                    # static source: dPp/qc = c0 + c_alpha alpha + c M^2
    static_error_c_alpha_per_deg = 0.0014
    static_error_c_mach2 = 0.012
    static_lag_ms = 300.0                      # pneumatic lags of the static and total lines
    total_lag_ms = 100.0
    gnss_velocity_rate_hz = 5.0                # INS velocities: GNSS fixes held between them
    gnss_velocity_latency_ms = 60.0

    [seeds]                         # one integer per random source
    imu_noise = 11

``from_dict(d, seed=S)`` derives every seed not given in ``[seeds]`` from the master seed ``S``.
Random draws for maneuver ``k`` use ``np.random.default_rng([seed_source, k, channel_index])``
(see :func:`channel_rng`), so the same seeds give bit-identical data and maneuvers differ.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from types import MappingProxyType
from typing import Any

import numpy as np

from aircraft_models import ALL_SENSORS
from aircraft_models.schema import SUFFIXES, Key, check, did_you_mean, unknown

Vec3 = tuple[float, float, float]
_ZERO3: Vec3 = (0.0, 0.0, 0.0)

#: Sensors whose output is an angle (noise and quantization in rad); the others are pressure probes.
VANE_SENSORS = ("vane_left", "vane_right", "boom_alpha_vane", "boom_beta_upper_vane",
                "boom_beta_lower_vane")
PROBE_SENSORS = ("side_probe_left", "side_probe_right", "nose_probe")
RECORDERS = ("dru", "ins", "dgps")

#: Non-flow channels that may carry an extra per-channel delay (``channel_delays_s``), and the
#: recorder each is on. Flow sensors take their delay from ``sensors.<name>.delay_s``.
DIRECT_CHANNELS: Mapping[str, str] = MappingProxyType({
    "ax_imu_mps2": "dru", "ay_imu_mps2": "dru", "az_imu_mps2": "dru",
    "p_rps": "dru", "q_rps": "dru", "r_rps": "dru",
    "qc_pa": "dru", "ps_pa": "dru", "tt_k": "dru", "gear_down": "dru",
    "phi_rad": "ins", "theta_rad": "ins", "psi_rad": "ins",
    "vn_mps": "ins", "ve_mps": "ins", "vd_mps": "ins",
    "h_dgps_m": "dgps",
})

#: Random sources, each with its own seed (only append: a master seed derives them in this order).
SEED_SOURCES = ("imu_noise", "vane_noise", "probe_noise", "nose_probe_irregularity", "ins_noise",
                "airdata_noise", "dgps_noise", "ins_attitude")
#: The seeds of the realism level's random sources: left out of :meth:`ErrorConfig.flat` (the
#: injected values stored with the data) while the realism level is off, so that datasets without
#: it stay byte-identical to those written before it existed.
REALISM_SEED_SOURCES = ("ins_attitude",)


def _vec3(value: Any, where: str) -> Vec3:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{where}: expected three finite numbers [x, y, z], got {value!r}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def _check_nonneg(obj: Any, where: str) -> None:
    """Noise, quantization and rates must be finite and >= 0."""
    for f in fields(obj):
        v = getattr(obj, f.name)
        if isinstance(v, float) and not math.isfinite(v):
            raise ValueError(f"{where}.{f.name} = {v!r} is not finite")
        if any(k in f.name for k in ("noise", "quant")) and isinstance(v, float) and v < 0:
            raise ValueError(f"{where}.{f.name} = {v} must be >= 0 (a standard deviation or step)")


@dataclass(frozen=True)
class ImuErrors:
    """IMU errors (recorded on the DRU). Body axes x fwd / y right / z down.

    Attributes
    ----------
    accel_bias_mps2 : (3,) accelerometer bias, m/s^2, added to the specific force at the IMU.
    gyro_bias_rps : (3,) gyro bias, rad/s, added to p, q, r.
    accel_noise_mps2, gyro_noise_rps : white-noise std per axis per recorded sample.
    accel_quant_mps2, gyro_quant_rps : quantization step (0 = none).
    delay_s : lag of every IMU channel on top of the DRU's latency, s.
    """

    accel_bias_mps2: Vec3 = _ZERO3
    gyro_bias_rps: Vec3 = _ZERO3
    accel_noise_mps2: float = 0.0
    gyro_noise_rps: float = 0.0
    accel_quant_mps2: float = 0.0
    gyro_quant_rps: float = 0.0
    delay_s: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "accel_bias_mps2", _vec3(self.accel_bias_mps2, "imu.accel_bias_mps2"))
        object.__setattr__(self, "gyro_bias_rps", _vec3(self.gyro_bias_rps, "imu.gyro_bias_rps"))
        _check_nonneg(self, "imu")


@dataclass(frozen=True)
class InsErrors:
    """INS errors (INS recorder): Euler angles (phi, theta, psi) and NED inertial velocity.

    Attributes
    ----------
    euler_bias_rad : (3,) bias of phi, theta, psi, rad.
    euler_noise_rad : noise std of each Euler angle, rad.
    velocity_bias_mps : (3,) bias of vn, ve, vd, m/s.
    velocity_noise_mps : noise std of each velocity component, m/s.
    """

    euler_bias_rad: Vec3 = _ZERO3
    euler_noise_rad: float = 0.0
    velocity_bias_mps: Vec3 = _ZERO3
    velocity_noise_mps: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "euler_bias_rad", _vec3(self.euler_bias_rad, "ins.euler_bias_rad"))
        object.__setattr__(self, "velocity_bias_mps",
                           _vec3(self.velocity_bias_mps, "ins.velocity_bias_mps"))
        _check_nonneg(self, "ins")


@dataclass(frozen=True)
class AirdataErrors:
    """Errors of the pressure and temperature transducers (DRU): qc = pt - ps, ps, total temp.

    TAS, Mach and pressure altitude are computed from these measured values, so they inherit them.
    """

    qc_bias_pa: float = 0.0
    qc_noise_pa: float = 0.0
    qc_quant_pa: float = 0.0
    ps_bias_pa: float = 0.0
    ps_noise_pa: float = 0.0
    ps_quant_pa: float = 0.0
    tt_bias_k: float = 0.0
    tt_noise_k: float = 0.0
    delay_s: float = 0.0

    def __post_init__(self) -> None:
        _check_nonneg(self, "airdata")


@dataclass(frozen=True)
class DgpsErrors:
    """Post-processed DGPS geometric height errors (DGPS recorder)."""

    h_bias_m: float = 0.0
    h_noise_m: float = 0.0

    def __post_init__(self) -> None:
        _check_nonneg(self, "dgps")


def _check_small(values: Vec3 | float, limit: float, where: str) -> None:
    if np.any(np.abs(np.asarray(values, dtype=float)) > limit):
        raise ValueError(f"{where} = {values!r}: the small-error model holds up to {limit} in magnitude")


@dataclass(frozen=True)
class RealismErrors:
    """The realism level: slow, correlated imperfections of real installations (opt-in).

    Each source is switched by its magnitude (all zero: off, the default; :meth:`typical` gives
    every one at its typical value; the physics and the sources of the numbers are in
    ``docs/realism.md``). Body axes x fwd / y right / z down.

    Attributes
    ----------
    ins_attitude_sigma_rad : (3,) std of the INS attitude error of phi, theta, psi, rad: a
        stationary first-order Gauss-Markov process per axis (an aided INS's filter error),
        drawn per maneuver from ``seeds.ins_attitude``. 0: off.
    ins_attitude_tau_s : (3,) its correlation times, s (used where the sigma is > 0).
    accel_scale, gyro_scale : (3,) scale-factor errors per axis (1): the triad outputs
        ``(1 + s_i)`` times its axis' input.
    accel_nonorthogonality_rad, gyro_nonorthogonality_rad : (3,) the triad's non-orthogonality,
        rad: ``(m_yx, m_zx, m_zy)``, the y axis tilted towards x, the z axis towards x and towards y
        (the triad's frame is that of its x axis and x-y plane).
    imu_mounting_rad : (3,) small rotation of the IMU case from the body axes (about x, y, z),
        rad, common to both triads. A triad measures ``(I + diag(s)) (I + N) (I - [d x]) x_body``
        (:meth:`imu_matrix`).
    static_error_c0, static_error_c_alpha_per_rad, static_error_c_mach2 : static-source position
        error ``dPp / qc = c0 + c_alpha alpha + c_mach2 M^2`` (1, 1/rad, 1) added to the static
        pressure at the port (true alpha and Mach); the pitot's total pressure has none, so the
        impact pressure the ADC measures is ``qc - dPp``. 0: off.
    static_lag_s, total_lag_s : first-order pneumatic lag of the static and the total-pressure
        line to the airdata computer's transducers, s. 0: off.
    gnss_velocity_rate_hz : the INS's NED velocity channels are a GNSS velocity of this fix rate,
        held between fixes on the INS stream, Hz. 0: off (the INS's own velocity).
    gnss_velocity_latency_s : a fix reaches the INS this long after its time of validity, s.
    """

    ins_attitude_sigma_rad: Vec3 = _ZERO3
    ins_attitude_tau_s: Vec3 = (30.0, 30.0, 60.0)
    accel_scale: Vec3 = _ZERO3
    gyro_scale: Vec3 = _ZERO3
    accel_nonorthogonality_rad: Vec3 = _ZERO3
    gyro_nonorthogonality_rad: Vec3 = _ZERO3
    imu_mounting_rad: Vec3 = _ZERO3
    static_error_c0: float = 0.0
    static_error_c_alpha_per_rad: float = 0.0
    static_error_c_mach2: float = 0.0
    static_lag_s: float = 0.0
    total_lag_s: float = 0.0
    gnss_velocity_rate_hz: float = 0.0
    gnss_velocity_latency_s: float = 0.05

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(f.default, tuple):
                object.__setattr__(self, f.name, _vec3(v, f"realism.{f.name}"))
            elif isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"realism.{f.name} = {v!r}: expected one finite number")
            else:
                object.__setattr__(self, f.name, float(v))
        if min(self.ins_attitude_sigma_rad) < 0:
            raise ValueError(f"realism.ins_attitude_sigma_rad = {self.ins_attitude_sigma_rad} must be "
                             ">= 0 (standard deviations)")
        if any(s > 0 and not t > 0 for s, t in zip(self.ins_attitude_sigma_rad, self.ins_attitude_tau_s,
                                                  strict=True)):
            raise ValueError(f"realism.ins_attitude_tau_s = {self.ins_attitude_tau_s} must be > 0 where "
                             "ins_attitude_sigma_rad is > 0 (a correlation time)")
        for name in ("static_lag_s", "total_lag_s", "gnss_velocity_rate_hz", "gnss_velocity_latency_s"):
            if getattr(self, name) < 0:
                raise ValueError(f"realism.{name} = {getattr(self, name)} must be >= 0 (0: off)")
        for name in ("accel_scale", "gyro_scale"):
            _check_small(getattr(self, name), 0.1, f"realism.{name}")
        for name in ("accel_nonorthogonality_rad", "gyro_nonorthogonality_rad", "imu_mounting_rad"):
            _check_small(getattr(self, name), 0.1, f"realism.{name}")
        for name in ("static_error_c0", "static_error_c_mach2"):
            _check_small(getattr(self, name), 0.2, f"realism.{name}")
        _check_small(self.static_error_c_alpha_per_rad, 1.0, "realism.static_error_c_alpha_per_rad")

    @classmethod
    def typical(cls) -> RealismErrors:
        """Every source at its typical value (docs/realism.md gives the physics and sources).

        INS attitude 0.1 / 0.1 / 0.2 deg with 30 / 30 / 60 s; IMU scale factors 0.4-1.0e-3,
        non-orthogonality 0.2-0.3 mrad, mounting 0.8-1.2 mrad; static-source error 0.4 % of qc
        + 0.08 / rad alpha + 1.2 % M^2; pneumatic lags 0.3 s static, 0.1 s total; GNSS velocity
        5 Hz with 60 ms latency.
        """
        mrad = 1e-3
        return cls(
            ins_attitude_sigma_rad=(math.radians(0.1), math.radians(0.1), math.radians(0.2)),
            ins_attitude_tau_s=(30.0, 30.0, 60.0),
            accel_scale=(8e-4, -6e-4, 1.0e-3),
            gyro_scale=(-1.0e-3, 7e-4, 4e-4),
            accel_nonorthogonality_rad=(0.3 * mrad, -0.2 * mrad, 0.25 * mrad),
            gyro_nonorthogonality_rad=(-0.25 * mrad, 0.3 * mrad, 0.2 * mrad),
            imu_mounting_rad=(1.0 * mrad, -0.8 * mrad, 1.2 * mrad),
            static_error_c0=0.004,
            static_error_c_alpha_per_rad=0.08,
            static_error_c_mach2=0.012,
            static_lag_s=0.3,
            total_lag_s=0.1,
            gnss_velocity_rate_hz=5.0,
            gnss_velocity_latency_s=0.06,
        )

    @property
    def ins_attitude(self) -> bool:
        """The INS attitude error is on."""
        return any(self.ins_attitude_sigma_rad)

    @property
    def imu_matrix_errors(self) -> bool:
        """An IMU scale factor, non-orthogonality or mounting error is on."""
        return any(any(getattr(self, n)) for n in ("accel_scale", "gyro_scale", "accel_nonorthogonality_rad",
                                                   "gyro_nonorthogonality_rad", "imu_mounting_rad"))

    @property
    def static_source_error(self) -> bool:
        """The static-source position error is on."""
        return bool(self.static_error_c0 or self.static_error_c_alpha_per_rad or self.static_error_c_mach2)

    @property
    def gnss_velocity(self) -> bool:
        """The INS velocities are held GNSS fixes."""
        return self.gnss_velocity_rate_hz > 0.0

    def imu_matrix(self, triad: str) -> np.ndarray:
        """(3, 3) ``I + M`` of the accelerometer (``"accel"``) or gyro (``"gyro"``) triad: it
        measures ``(I + M) x`` for the body-axis vector x (scale, non-orthogonality, mounting)::

            I + M = (I + diag(s)) (I + N) (I - [d x])
            N = [[0, 0, 0], [m_yx, 0, 0], [m_zx, m_zy, 0]],   [d x] the cross-product matrix of d
        """
        if triad not in ("accel", "gyro"):
            raise ValueError(f"imu_matrix: triad {triad!r} is 'accel' or 'gyro'")
        s = getattr(self, f"{triad}_scale")
        m_yx, m_zx, m_zy = getattr(self, f"{triad}_nonorthogonality_rad")
        dx, dy, dz = self.imu_mounting_rad
        n = np.array([[0.0, 0.0, 0.0], [m_yx, 0.0, 0.0], [m_zx, m_zy, 0.0]])
        cross = np.array([[0.0, -dz, dy], [dz, 0.0, -dx], [-dy, dx, 0.0]])
        return (np.eye(3) + np.diag(s)) @ (np.eye(3) + n) @ (np.eye(3) - cross)


@dataclass(frozen=True)
class FlowSensorErrors:
    """Transduction errors of one flow-angle sensor.

    Vanes (``VANE_SENSORS``) use ``noise_rad``/``quant_rad``; pressure probes (``PROBE_SENSORS``)
    use ``noise_pa``/``quant_pa`` on their differential pressure, so their angle noise grows as the
    dynamic pressure falls. The nose probe alone has the high-AOA noise, whose angle std is
    ``high_alpha_noise_rad_per_rad * max(0, alpha - high_alpha_onset_rad)`` (paper §4.2).

    Attributes
    ----------
    scale : scale-factor error; a vane outputs (1 + scale) * sensed angle, a probe
        (1 + scale) * differential pressure.
    delay_s : lag of this sensor's raw channel on top of the DRU's latency, s.
    """

    scale: float = 0.0
    noise_rad: float = 0.0
    quant_rad: float = 0.0
    noise_pa: float = 0.0
    quant_pa: float = 0.0
    high_alpha_noise_rad_per_rad: float = 0.0
    high_alpha_onset_rad: float = 0.0
    delay_s: float = 0.0

    def check(self, sensor: str) -> None:
        where = f"sensors.{sensor}"
        _check_nonneg(self, where)
        if sensor in VANE_SENSORS and (self.noise_pa or self.quant_pa):
            raise ValueError(f"{where}: a vane has angle noise; use noise_deg/quant_deg, not _pa")
        if sensor in PROBE_SENSORS and (self.noise_rad or self.quant_rad):
            raise ValueError(f"{where}: a pressure probe has pressure noise; use noise_pa/quant_pa "
                             "(the angle noise then follows from the dynamic pressure)")
        if sensor != "nose_probe" and self.high_alpha_noise_rad_per_rad:
            raise ValueError(f"{where}: high_alpha_noise applies to the nose probe only")
        if self.high_alpha_noise_rad_per_rad < 0:
            raise ValueError(f"{where}.high_alpha_noise_rad_per_rad must be >= 0")


@dataclass(frozen=True)
class RecorderErrors:
    """One recorder (DRU, INS or DGPS).

    Attributes
    ----------
    rate_hz : sample rate, Hz; ``None`` = an ideal recorder that samples exactly on the common
        time base (so resampling is the identity).
    delay_s : latency; the sample stamped t holds the signal at (t - clock_offset_s) - delay_s.
    clock_offset_s : the recorder's clock reads true time + offset.
    """

    rate_hz: float | None = None
    delay_s: float = 0.0
    clock_offset_s: float = 0.0

    def check(self, name: str) -> None:
        if self.rate_hz is not None and not (math.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise ValueError(f"recorders.{name}.rate_hz = {self.rate_hz!r} must be > 0 "
                             "(or absent for an ideal recorder)")
        for f in ("delay_s", "clock_offset_s"):
            if not math.isfinite(getattr(self, f)):
                raise ValueError(f"recorders.{name}.{f} must be finite")


@dataclass(frozen=True)
class Seeds:
    """One seed per random source (see :data:`SEED_SOURCES`)."""

    imu_noise: int = 101
    vane_noise: int = 102
    probe_noise: int = 103
    nose_probe_irregularity: int = 104
    ins_noise: int = 105
    airdata_noise: int = 106
    dgps_noise: int = 107
    ins_attitude: int = 108

    @classmethod
    def from_master(cls, master: int) -> Seeds:
        """Derive every source's seed from one master seed (stable, documented order)."""
        state = np.random.SeedSequence(int(master)).generate_state(len(SEED_SOURCES))
        return cls(**{s: int(v) for s, v in zip(SEED_SOURCES, state, strict=True)})


def channel_rng(seed: int, maneuver_key: int, channel_index: int) -> np.random.Generator:
    """The generator for one channel of one maneuver: ``default_rng([seed, key, channel])``."""
    return np.random.default_rng([int(seed), int(maneuver_key), int(channel_index)])


def _default_sensors() -> Mapping[str, FlowSensorErrors]:
    return MappingProxyType({s: FlowSensorErrors() for s in ALL_SENSORS})


def _default_recorders() -> Mapping[str, RecorderErrors]:
    return MappingProxyType({r: RecorderErrors() for r in RECORDERS})


_SWITCHES = ("local_flow", "baseline_mismatch", "installation_biases", "nose_probe_irregularity")
_GROUPS = ("imu", "ins", "airdata", "dgps", "realism")
#: the keys of an errors block (module docstring); the two channel-delay spellings are converted below
_ERROR_KEYS = {"preset": Key(), **{s: Key(bool) for s in _SWITCHES}, **dict.fromkeys(_GROUPS, Key()),
               **dict.fromkeys(("sensors", "recorders", "channel_delays_s", "channel_delays_ms", "seeds"),
                               Key())}
#: the units whose edge spelling a field accepts, by its SI suffix: _deg_per_deg, _deg, _deg_s, _ms
#: (the longer suffix first: a ``_rad_per_rad`` field is no ``_rad`` one)
_EDGE_UNITS = ("rad/rad", "rad", "rad/s", "s")


@dataclass(frozen=True)
class ErrorConfig:
    """Every injected instrumentation error of a maneuver (SI, radians).

    ``ErrorConfig()`` equals :meth:`none`. See the module docstring for the dict/TOML form.
    """

    local_flow: bool = False
    baseline_mismatch: bool = False
    installation_biases: bool = False
    nose_probe_irregularity: bool = False
    imu: ImuErrors = field(default_factory=ImuErrors)
    ins: InsErrors = field(default_factory=InsErrors)
    airdata: AirdataErrors = field(default_factory=AirdataErrors)
    dgps: DgpsErrors = field(default_factory=DgpsErrors)
    sensors: Mapping[str, FlowSensorErrors] = field(default_factory=_default_sensors)
    recorders: Mapping[str, RecorderErrors] = field(default_factory=_default_recorders)
    channel_delays_s: Mapping[str, float] = field(default_factory=lambda: MappingProxyType({}))
    seeds: Seeds = field(default_factory=Seeds)
    realism: RealismErrors = field(default_factory=RealismErrors)

    def __post_init__(self) -> None:
        bad = sorted(set(self.sensors) - set(ALL_SENSORS))
        if bad:
            raise unknown(bad, ALL_SENSORS, "sensors", what="sensor")
        sensors = {s: self.sensors.get(s, FlowSensorErrors()) for s in ALL_SENSORS}
        for s, e in sensors.items():
            e.check(s)
        object.__setattr__(self, "sensors", MappingProxyType(sensors))
        bad = sorted(set(self.recorders) - set(RECORDERS))
        if bad:
            raise unknown(bad, RECORDERS, "recorders", what="recorder")
        recorders = {r: self.recorders.get(r, RecorderErrors()) for r in RECORDERS}
        for r, e in recorders.items():
            e.check(r)
        object.__setattr__(self, "recorders", MappingProxyType(recorders))
        bad = sorted(set(self.channel_delays_s) - set(DIRECT_CHANNELS))
        if bad:
            msg = unknown(bad, sorted(DIRECT_CHANNELS), "channel_delays", what="channel")
            raise ValueError(f"{msg} (a flow sensor's delay is sensors.<name>.delay_s)")
        delays = {k: float(v) for k, v in self.channel_delays_s.items()}
        if not all(math.isfinite(v) for v in delays.values()):
            raise ValueError(f"channel_delays: every delay must be finite, got {delays}")
        object.__setattr__(self, "channel_delays_s", MappingProxyType(delays))

    # ------------------------------------------------------------------ presets
    @classmethod
    def none(cls) -> ErrorConfig:
        """Everything off, ideal recorders: each channel carries the truth at its sensor.

        One true effect remains: the side-probe pair's sideslip ``beta_zsp_rad`` is not
        ``true_beta_sp_rad`` (the free-stream sideslip at the pair's mean position). A roll rate
        gives the two probes, at y = +-Y, opposite local alpha, which the canted port pair
        (cant c) reads as sideslip: to first order -Y (p + r tan alpha) cos(alpha) cos(beta)^2 /
        (u tan c), up to 0.085 deg in the default campaign's maneuvers. This is physics, not an
        error; the estimator models it as ``k_spr (p + r tan alpha_s) / tas_t`` (k_spr about
        -Y / tan c). Its angle of attack ``alpha_zsp_rad`` is exact to second order.
        """
        return cls()

    @classmethod
    def typical(cls) -> ErrorConfig:
        """SPEC §6 typical magnitudes, every switch on, DRU 64 Hz / INS 50 Hz / DGPS 10 Hz."""
        d2r = math.pi / 180.0
        vane = dict(noise_rad=0.07 * d2r, quant_rad=0.05 * d2r)
        probe = dict(noise_pa=20.0, quant_pa=1.0)
        sensors = {
            "vane_left": FlowSensorErrors(delay_s=0.030, **vane),
            "vane_right": FlowSensorErrors(delay_s=0.045, **vane),
            "side_probe_left": FlowSensorErrors(delay_s=0.080, **probe),
            "side_probe_right": FlowSensorErrors(delay_s=0.080, **probe),
            "nose_probe": FlowSensorErrors(delay_s=0.060, high_alpha_noise_rad_per_rad=0.02,
                                           high_alpha_onset_rad=10.0 * d2r, **probe),
            "boom_alpha_vane": FlowSensorErrors(scale=0.01, delay_s=0.020, **vane),
            "boom_beta_upper_vane": FlowSensorErrors(scale=-0.015, delay_s=0.020, **vane),
            "boom_beta_lower_vane": FlowSensorErrors(scale=0.012, delay_s=0.020, **vane),
        }
        return cls(
            local_flow=True,
            baseline_mismatch=True,
            installation_biases=True,
            nose_probe_irregularity=True,
            imu=ImuErrors(
                accel_bias_mps2=(0.10, -0.08, 0.15),
                gyro_bias_rps=(0.2 * d2r, -0.3 * d2r, 0.15 * d2r),
                accel_noise_mps2=0.02,
                gyro_noise_rps=0.01 * d2r,
                accel_quant_mps2=0.005,
                gyro_quant_rps=0.005 * d2r,
            ),
            ins=InsErrors(euler_noise_rad=0.03 * d2r, velocity_noise_mps=0.05),
            airdata=AirdataErrors(qc_noise_pa=15.0, ps_noise_pa=10.0, tt_noise_k=0.2),
            dgps=DgpsErrors(h_noise_m=0.3),
            sensors=MappingProxyType(sensors),
            recorders=MappingProxyType({
                "dru": RecorderErrors(rate_hz=64.0, delay_s=0.020, clock_offset_s=0.0),
                "ins": RecorderErrors(rate_hz=50.0, delay_s=0.0, clock_offset_s=0.030),
                "dgps": RecorderErrors(rate_hz=10.0, delay_s=0.0, clock_offset_s=-0.050),
            }),
            channel_delays_s=MappingProxyType({"phi_rad": 0.010, "theta_rad": 0.010,
                                               "psi_rad": 0.010}),
        )

    @classmethod
    def real_world(cls) -> ErrorConfig:
        """:meth:`typical` plus every source of the realism level at its typical value
        (:meth:`RealismErrors.typical`; docs/realism.md). The slow vertical air motion is the
        environment's (``[environment] vertical_air_motion``), not an instrumentation error."""
        return dataclasses.replace(cls.typical(), realism=RealismErrors.typical())

    # ------------------------------------------------------------------ dict form
    def to_dict(self) -> dict:
        """Nested plain dict in SI key names (TOML/JSON-ready; ``rate_hz`` omitted when ideal)."""
        out: dict[str, Any] = {
            "local_flow": self.local_flow,
            "baseline_mismatch": self.baseline_mismatch,
            "installation_biases": self.installation_biases,
            "nose_probe_irregularity": self.nose_probe_irregularity,
        }
        for group in ("imu", "ins", "airdata", "dgps", "seeds"):
            out[group] = _plain(getattr(self, group))
        out["sensors"] = {s: _plain(e) for s, e in self.sensors.items()}
        out["recorders"] = {r: _plain(e) for r, e in self.recorders.items()}
        out["channel_delays_s"] = dict(self.channel_delays_s)
        if self.realism != RealismErrors():  # absent while off: the form written before it existed
            out["realism"] = _plain(self.realism)
        return out

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], *, seed: int | None = None) -> ErrorConfig:
        """Build from the nested dict/TOML form (see the module docstring).

        Parameters
        ----------
        d : mapping; ``preset`` ("none", the default, "typical" or "real_world") is the starting
            point, every other key overrides it. Edge units (``_deg``, ``_deg_s``, ``_ms``,
            ``_per_deg``) are converted to SI.
        seed : master seed; every source seed not given in ``d["seeds"]`` derives from it. Without
            it, seeds not given keep the preset's.

        Raises
        ------
        ValueError
            On an unknown key (the message lists the valid ones) or a bad value.
        """
        d = check(d, _ERROR_KEYS, "errors")
        preset = d.pop("preset", "none")
        presets = {"none": cls.none, "typical": cls.typical, "real_world": cls.real_world}
        if preset not in presets:
            raise ValueError(f"errors.preset = {preset!r}{did_you_mean(str(preset), presets)}; "
                             f"valid: {sorted(presets)}")
        base = presets[preset]()
        changes: dict[str, Any] = {}
        for s in _SWITCHES:
            if s in d:
                changes[s] = d[s]
        for g in _GROUPS:
            if g in d:
                changes[g] = _update(getattr(base, g), d[g], f"errors.{g}")
        if "sensors" in d:
            sensors = dict(base.sensors)
            for s, sd in _mapping(d["sensors"], "errors.sensors").items():
                if s not in ALL_SENSORS:
                    raise unknown([s], ALL_SENSORS, "errors.sensors", what="sensor")
                sensors[s] = _update(sensors[s], sd, f"errors.sensors.{s}")
            changes["sensors"] = MappingProxyType(sensors)
        if "recorders" in d:
            recorders = dict(base.recorders)
            for r, rd in _mapping(d["recorders"], "errors.recorders").items():
                if r not in RECORDERS:
                    raise unknown([r], RECORDERS, "errors.recorders", what="recorder")
                recorders[r] = _update(recorders[r], rd, f"errors.recorders.{r}")
            changes["recorders"] = MappingProxyType(recorders)
        if "channel_delays_s" in d and "channel_delays_ms" in d:
            raise ValueError("errors: give channel_delays_s or channel_delays_ms, not both")
        for key, factor in (("channel_delays_s", 1.0), ("channel_delays_ms", 1e-3)):
            if key in d:
                delays = dict(base.channel_delays_s)
                delays.update({k: float(v) * factor
                               for k, v in _mapping(d[key], f"errors.{key}").items()})
                changes["channel_delays_s"] = MappingProxyType(delays)
        seeds = Seeds.from_master(seed) if seed is not None else base.seeds
        if "seeds" in d:
            seeds = _update(seeds, d["seeds"], "errors.seeds")
        changes["seeds"] = seeds
        return dataclasses.replace(base, **changes)

    # ------------------------------------------------------------------ one-at-a-time
    def with_values(self, values: Mapping[str, Any]) -> ErrorConfig:
        """Copy with some values replaced, by dotted SI path.

        Example: ``cfg.with_values({"imu.accel_bias_mps2": (0.1, 0, 0),
        "sensors.vane_left.delay_s": 0.05, "recorders.ins.clock_offset_s": 0.02})``.
        """
        nested: dict[str, Any] = {}
        for path, value in values.items():
            parts = path.split(".")
            node = nested
            for p in parts[:-1]:
                node = node.setdefault(p, {})
            node[parts[-1]] = list(value) if isinstance(value, tuple) else value
        d = self.to_dict()
        _deep_update(d, nested, "errors")
        return ErrorConfig.from_dict(d)

    @classmethod
    def with_only(cls, path: str, value: Any = None) -> ErrorConfig:
        """Every error off but one: ``path`` (dotted SI, as in :meth:`with_values`) set to
        ``value``, or to its :meth:`typical` value when ``value`` is None (a ``realism.`` path:
        its :meth:`real_world` value). Recorders stay ideal unless ``path`` names a recorder
        field. For tests of one error source at a time.
        """
        if value is None:
            node: Any = cls.real_world().to_dict()
            for p in path.split("."):
                if not isinstance(node, Mapping) or p not in node:
                    raise ValueError(f"with_only: no typical value at {path!r}")
                node = node[p]
            value = node
        return cls.none().with_values({path: value})

    # ------------------------------------------------------------------ bookkeeping
    def flat(self) -> dict[str, float | list]:
        """Flat SI names as stored with the data: ``imu.accel_bias_mps2``,
        ``vane_left.noise_rad``, ``dru.delay_s``, ``seeds.imu_noise``, switches as 0.0/1.0."""
        d = self.to_dict()
        out: dict[str, float | list] = {}
        for k in ("local_flow", "baseline_mismatch", "installation_biases",
                  "nose_probe_irregularity"):
            out[k] = float(d[k])
        realism = "realism" in d
        for g in ("imu", "ins", "airdata", "dgps", "seeds", *(("realism",) if realism else ())):
            for k, v in d[g].items():
                if g == "seeds" and k in REALISM_SEED_SOURCES and not realism:
                    continue  # stored only with the realism level (module docstring)
                out[f"{g}.{k}"] = v
        for s, sd in d["sensors"].items():
            for k, v in sd.items():
                out[f"{s}.{k}"] = v
        for r, rd in d["recorders"].items():
            for k, v in rd.items():
                out[f"{r}.{k}"] = v
        for k, v in d["channel_delays_s"].items():
            out[f"channel_delay.{k}_s"] = v
        return out


# ---------------------------------------------------------------------- helpers
def _plain(obj: Any) -> dict:
    out = {}
    for f in fields(obj):
        v = getattr(obj, f.name)
        if v is None:
            continue
        out[f.name] = list(v) if isinstance(v, tuple) else v
    return out


def _mapping(value: Any, where: str) -> Mapping:
    if not isinstance(value, Mapping):
        raise ValueError(f"{where} must be a table/dict, got {type(value).__name__}")
    return value


def _edge_unit(name: str) -> str | None:
    """The SI unit of field ``name`` whose edge-unit spelling it accepts (:data:`_EDGE_UNITS`)."""
    if _per_rad(name):  # a coefficient per radian is no angle: its edge spelling is _per_deg
        return None
    return next((u for u in _EDGE_UNITS if name.endswith(SUFFIXES[u][0][0])), None)


def _per_rad(name: str) -> bool:
    """A coefficient per radian (``static_error_c_alpha_per_rad``), not a ``_rad_per_rad`` ratio."""
    return name.endswith("_per_rad") and not name.endswith("_rad_per_rad")


def _update(obj: Any, d: Any, where: str) -> Any:
    """``dataclasses.replace(obj, ...)`` from a dict whose keys may carry edge units."""
    d = _mapping(d, where)
    # the schema's spellings, converted here as before (a quoted number stays accepted)
    alias = {key: (f.name, factor) for f in fields(obj)
             for key, factor in Key(unit=_edge_unit(f.name)).spellings(f.name).items()}
    # per degree -> per radian: x / deg = x * (180 / pi) / rad
    alias.update({f.name[: -len("_per_rad")] + "_per_deg": (f.name, 180.0 / math.pi)
                  for f in fields(obj) if _per_rad(f.name)})
    changes: dict[str, Any] = {}
    for key, value in d.items():
        if key not in alias:
            raise unknown([key], alias, where)
        name, factor = alias[key]
        if name in changes:
            raise ValueError(f"{where}: {name} given twice (as {key!r} and another unit)")
        if isinstance(value, bool) or value is None:
            raise ValueError(f"{where}.{key}: expected a number, got {value!r}")
        try:
            if isinstance(value, (list, tuple, np.ndarray)):
                changes[name] = tuple(float(x) * factor for x in np.ravel(value))
            elif isinstance(getattr(obj, name), int) and not isinstance(getattr(obj, name), bool):
                if isinstance(value, float) and not value.is_integer():
                    raise ValueError("an integer is required")
                changes[name] = int(value)
            else:
                changes[name] = float(value) * factor
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{where}.{key}: bad value {value!r} ({exc})") from None
    return dataclasses.replace(obj, **changes)


def _deep_update(base: dict, new: Mapping, where: str) -> None:
    for k, v in new.items():
        if isinstance(v, Mapping) and isinstance(base.get(k), dict):
            _deep_update(base[k], v, f"{where}.{k}")
        else:
            base[k] = v
