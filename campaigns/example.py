"""A small flight to calibrate, as a user's would come: CSV files and a problem file.

``fpr example DIR`` writes it (:func:`write_example`); ``fpr calibrate DIR/uav.toml`` calibrates it.
The aircraft is ``estimator/models/uav_example.toml``'s jet target drone: an angle-of-attack vane
and a sideslip vane on a nose boom (each with a bias and a scale factor, and a time delay), a
pitot-static airspeed, an INS attitude and a height; the files hold the IMU in deg/s and m/s^2,
the angles in deg, one maneuver each, with a time column. The flight is the analytic one of
:mod:`campaigns.analytic_flight` (states and IMU inputs that satisfy the state equations exactly),
so every error in the files is one put there: the injected calibration below, white noise on each
channel and constant IMU biases.

By default three maneuvers of 14 s at 50 Hz (about 2,100 samples, seven channels) of one aircraft
at 500 m (Mach 0.44: the model set's reference Mach bin 0.4). The second-aircraft test
(``tests/estimator_tests/test_second_aircraft.py``) makes a fleet of three with the same pieces.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from campaigns.analytic_flight import analytic
from synth.airdata_computer import GAMMA, ISA_LAPSE_KPM, ISA_T0_K, R_AIR_JPKGK

D2R = math.pi / 180.0
RATE_HZ = 50.0
IMU_M = np.array([0.1, 0.0, 0.05])      # the IMU sits at the CG: the analytic specific force is the CG's
SENSORS_M = {"aoa_vane": np.array([1.6, -0.25, 0.05]), "sideslip_vane": np.array([1.9, 0.0, -0.10])}
#: the injected calibration (deg where angles): installation biases per aircraft, the fleet offset,
#: the scale factors and the time delays (s)
B_A_DEG = {"U1": 0.4, "U2": -0.2, "U3": 0.1}
B_B_DEG = {"U1": -0.3, "U2": 0.25, "U3": 0.0}
C_A_DEG = 0.3
K_A, K_B = 0.05, -0.04
TAU_S = {"tas": 0.05, "a": 0.04, "b": 0.02}
#: each channel's white noise, SI (rad for the angles, m/s, m)
NOISE_SI = {"phi": 0.03 * D2R, "theta": 0.03 * D2R, "psi": 0.03 * D2R, "tas": 0.2, "h": 1.0,
            "alpha_v": 0.05 * D2R, "beta_v": 0.05 * D2R}

PROBLEM = """title = "{title}"
model = "uav_example"

[sensors]
imu = [{imu}]
aoa_vane = [{aoa}]
sideslip_vane = [{aos}]

{aircraft}
[columns]
t = {{ column = "time", unit = "s" }}
ax = {{ column = "AX", unit = "m/s^2" }}
ay = {{ column = "AY", unit = "m/s^2" }}
az = {{ column = "AZ", unit = "m/s^2" }}
p = {{ column = "P", unit = "deg/s" }}
q = {{ column = "Q", unit = "deg/s" }}
r = {{ column = "R", unit = "deg/s" }}
phi = {{ column = "PHI", unit = "deg" }}
theta = {{ column = "THETA", unit = "deg" }}
psi = {{ column = "PSI", unit = "deg" }}
tas = {{ column = "TAS", unit = "m/s" }}
h = {{ column = "HGT", unit = "m" }}
alpha_v = {{ column = "AOA", unit = "deg" }}
beta_v = {{ column = "AOS", unit = "deg" }}
mach = {{ column = "MACH", unit = "1" }}

{files}"""


def speed_of_sound_mps(h_m: np.ndarray) -> np.ndarray:
    """The standard atmosphere's speed of sound below 11 km, m/s, at altitude ``h_m`` (m)."""
    return np.sqrt(GAMMA * R_AIR_JPKGK * (ISA_T0_K - ISA_LAPSE_KPM * np.asarray(h_m, dtype=float)))


def _flow_at(states: np.ndarray, omega_rps: np.ndarray, sensor: str) -> tuple[np.ndarray, np.ndarray]:
    """alpha and flank (rad) at a sensor: V + omega x (r_sensor - r_cg), the CG at the IMU."""
    v = states[:, :3] + np.cross(omega_rps, SENSORS_M[sensor] - IMU_M)
    return np.arctan2(v[:, 2], v[:, 0]), np.arctan2(v[:, 1], v[:, 0])


def uav_maneuver(rng: np.random.Generator, h0_m: float, t0_s: float, aircraft: str,
                 duration_s: float = 20.0) -> tuple[pd.DataFrame, float]:
    """One maneuver's file contents and its true mean Mach.

    Parameters
    ----------
    rng : draws the trajectory's amplitudes, the noise and the IMU biases.
    h0_m : the starting altitude, m.
    t0_s : the phase of the analytic trajectory, s (a maneuver of its own).
    aircraft : ``U1``, ``U2`` or ``U3`` (its installation biases, :data:`B_A_DEG`, :data:`B_B_DEG`).
    duration_s : the record's length, s (at :data:`RATE_HZ`).

    Returns
    -------
    The file's columns (time in s, IMU in m/s^2 and deg/s, angles in deg, TAS in m/s, height in m,
    Mach), and the maneuver's mean Mach.
    """
    amp = {k: rng.uniform(0.6, 1.2) * base for k, base in
           (("au", 5.0), ("av", 3.0), ("aw", 4.0), ("aphi", 0.5), ("ath", 0.2))}
    inputs, states = analytic(amp)
    t = np.arange(int(round(duration_s * RATE_HZ)) + 1) / RATE_HZ
    tt = t + t0_s
    acc, om = inputs(tt)
    x = states(tt, h0_m)

    def at(tau):  # the flow and speed a sensor saw tau earlier
        return states(tt - tau, h0_m), inputs(tt - tau)[1]

    xa, oma = at(TAU_S["a"])
    xb, omb = at(TAU_S["b"])
    xt, _ = at(TAU_S["tas"])
    alpha_a, _ = _flow_at(xa, oma, "aoa_vane")
    _, flank_b = _flow_at(xb, omb, "sideslip_vane")
    tas = np.linalg.norm(x[:, :3], axis=1)
    clean = {
        "phi": x[:, 3], "theta": x[:, 4], "psi": x[:, 5], "h": x[:, 6],
        "tas": np.linalg.norm(xt[:, :3], axis=1),
        "alpha_v": (1 + K_A) * alpha_a + (C_A_DEG + B_A_DEG[aircraft]) * D2R,
        "beta_v": (1 + K_B) * flank_b + B_B_DEG[aircraft] * D2R,
    }
    meas = {k: v + NOISE_SI[k] * rng.standard_normal(v.shape) for k, v in clean.items()}
    imu_bias = rng.normal(0.0, [0.05, 0.05, 0.05, 0.002, 0.002, 0.002])
    mach = tas / speed_of_sound_mps(x[:, 6])
    df = pd.DataFrame({
        "time": t,
        "AX": acc[:, 0] + imu_bias[0], "AY": acc[:, 1] + imu_bias[1], "AZ": acc[:, 2] + imu_bias[2],
        "P": (om[:, 0] + imu_bias[3]) / D2R, "Q": (om[:, 1] + imu_bias[4]) / D2R,
        "R": (om[:, 2] + imu_bias[5]) / D2R,
        "PHI": meas["phi"] / D2R, "THETA": meas["theta"] / D2R, "PSI": meas["psi"] / D2R,
        "TAS": meas["tas"], "HGT": meas["h"], "AOA": meas["alpha_v"] / D2R, "AOS": meas["beta_v"] / D2R,
        "MACH": mach,
    })
    return df, float(mach.mean())


def write_problem_file(path: Path, files: list[tuple[str, str]], title: str, exclusive: bool = False
                       ) -> Path:
    """The problem file naming ``files`` (``(csv name, aircraft)``, relative to it) with the
    drone's sensor positions, CG and column map; returns ``path`` (``exclusive``: refused if it
    exists)."""
    fmt = ", ".join
    aircraft = dict.fromkeys(ac for _, ac in files)
    text = PROBLEM.format(
        title=title, imu=fmt(map(str, IMU_M)), aoa=fmt(map(str, SENSORS_M["aoa_vane"])),
        aos=fmt(map(str, SENSORS_M["sideslip_vane"])),
        aircraft="".join(f"[aircraft.{ac}]\nr_cg_body_m = [{fmt(map(str, IMU_M))}]\n" for ac in aircraft),
        files="\n".join(f'[[files]]\npath = "{name}"\naircraft = "{ac}"\n' for name, ac in files))
    with open(path, "x" if exclusive else "w") as f:
        f.write(text)
    return path


#: The example's maneuver files and everything :func:`write_example` writes (never replacing a file).
EXAMPLE_CSV = tuple(f"U1_{k}.csv" for k in range(3))
EXAMPLE_FILES = ("uav.toml", *EXAMPLE_CSV)


def write_example(folder: str | Path, seed: int = 12, duration_s: float = 14.0) -> Path:
    """Write the small example (module docstring) into ``folder``; returns its problem file.

    Parameters
    ----------
    folder : created if missing; an existing file of :data:`EXAMPLE_FILES` there is refused (the
        example never overwrites a user's file).
    seed : the random generator's seed (the same seed writes the same bytes).
    duration_s : each maneuver's length, s.
    """
    out = Path(folder)
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"{out} is a file; give a folder (new or existing) for the example")
    taken = [n for n in EXAMPLE_FILES if (out / n).exists() or (out / n).is_symlink()]
    if taken:
        raise FileExistsError(f"{out}: {', '.join(taken)} already exist(s); the example writes only "
                              "into a folder without them: give another folder, or remove them")
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    files = []
    for k, name in enumerate(EXAMPLE_CSV):
        df, _ = uav_maneuver(rng, 500.0, t0_s=7.0 * k + 3.0, aircraft="U1", duration_s=duration_s)
        df.to_csv(out / name, index=False, mode="x")  # "x": never through a file that appeared since
        files.append((name, "U1"))
    title = "Example: a target drone's vanes, three maneuvers (fpr example)"
    return write_problem_file(out / "uav.toml", files, title, exclusive=True)
