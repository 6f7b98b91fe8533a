"""Problem files and flight frames the reader tests write: the constants and builders that
tests/estimator_tests/test_io.py, test_input_safety.py, test_problem_options.py and
tests/aircraft_models_tests/test_schema.py share."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from estimator.io import DataError, load_problem

G = 9.80665
KT = 1852.0 / 3600.0
FT = 0.3048
DEG = math.pi / 180.0
RATE_HZ = 40.0

SENSORS = """
[sensors]
imu = [1.80, 0.10, 0.20]
vane_left = [6.20, -0.45, 0.25]
vane_right_in = [244.094488, 17.716535, 9.842520]
side_probe_left = [6.60, -0.52, 0.05]
side_probe_right = [6.60, 0.52, 0.05]

[aircraft.PV1]
r_cg_body_m = [0.33, 0.0, 0.13]
"""

SI_COLUMNS = """
[columns]
t = { column = "time", unit = "s" }
ax = { column = "ax", unit = "m/s^2" }
ay = { column = "ay", unit = "m/s^2" }
az = { column = "az", unit = "m/s^2" }
p = { column = "p", unit = "rad/s" }
q = { column = "q", unit = "rad/s" }
r = { column = "r", unit = "rad/s" }
phi = { column = "phi", unit = "rad" }
theta = { column = "theta", unit = "rad" }
psi = { column = "psi", unit = "rad" }
tas = { column = "tas", unit = "m/s" }
h = { column = "h", unit = "m" }
alpha_zl = { column = "alpha_zl", unit = "rad" }
alpha_zr = { column = "alpha_zr", unit = "rad" }
gear = { column = "gear", unit = "1" }
mach = { column = "mach", unit = "1" }
"""

#: column -> (unit in the "engineering" file, factor to SI)
ENG_UNITS = {
    "time": ("s", 1.0), "ax": ("g", G), "ay": ("g", G), "az": ("g", G),
    "p": ("deg/s", DEG), "q": ("deg/s", DEG), "r": ("deg/s", DEG),
    "phi": ("deg", DEG), "theta": ("deg", DEG), "psi": ("deg", DEG), "tas": ("kt", KT),
    "h": ("ft", FT), "alpha_zl": ("deg", DEG), "alpha_zr": ("deg", DEG), "gear": ("1", 1.0),
    "mach": ("1", 1.0),
}


def flight_frame(duration_s: float = 60.0, t0_s: float = 100.0, seed: int = 0, phi_amp_rad: float = 0.3,
                 theta_amp_rad: float = 0.05, theta_w_rps: float = 0.7) -> pd.DataFrame:
    """A smooth, plausible flight record in SI units, uniformly sampled at RATE_HZ.

    The body rates follow from the Euler angles by the Euler kinematics (the import checks that).
    """
    rng = np.random.default_rng(seed)
    t = t0_s + np.arange(int(round(duration_s * RATE_HZ)) + 1) / RATE_HZ
    tau = t - t0_s
    s = np.sin(0.7 * tau)
    phi, phi_dot = phi_amp_rad * np.sin(0.5 * tau), 0.5 * phi_amp_rad * np.cos(0.5 * tau)
    theta = 0.06 + theta_amp_rad * np.sin(theta_w_rps * tau)
    theta_dot = theta_amp_rad * theta_w_rps * np.cos(theta_w_rps * tau)
    psi, psi_dot = 1.0 + 0.002 * tau, np.full(len(t), 0.002)
    return pd.DataFrame({
        "time": t,
        "ax": 0.4 + 0.3 * s, "ay": 0.1 * s, "az": -G - 2.0 * s,
        "p": phi_dot - psi_dot * np.sin(theta),
        "q": theta_dot * np.cos(phi) + psi_dot * np.cos(theta) * np.sin(phi),
        "r": -theta_dot * np.sin(phi) + psi_dot * np.cos(theta) * np.cos(phi),
        "phi": phi, "theta": theta, "psi": psi,
        "tas": 150.0 + 3.0 * s, "h": 6000.0 + 20.0 * s,
        "alpha_zl": 0.07 + 0.03 * s + rng.normal(0, 1e-4, len(t)),
        "alpha_zr": 0.07 + 0.03 * s + rng.normal(0, 1e-4, len(t)),
        "gear": np.zeros(len(t)), "mach": (150.0 + 3.0 * s) / 310.0,
    })


def write_problem(tmp_path, body: str, name: str = "problem.toml") -> str:
    path = tmp_path / name
    path.write_text(f'title = "test"\n{body}')
    return path


def si_problem(tmp_path, frame: pd.DataFrame | None = None, files: str | None = None, extra: str = ""):
    """A CSV in SI units and the problem file that reads it."""
    frame = flight_frame() if frame is None else frame
    frame.to_csv(tmp_path / "flight.csv", index=False)
    files = files or '[[files]]\npath = "flight.csv"\naircraft = "PV1"\n'
    return write_problem(tmp_path, f'channels = ["phi","theta","psi","tas","h","alpha_zl","alpha_zr"]\n'
                         f"{extra}{SENSORS}{SI_COLUMNS}{files}")


def one_range(mid: str, t_start_s: float, t_end_s: float) -> str:
    """[[files]] entry: one maneuver of flight.csv."""
    return (f'[[files]]\npath = "flight.csv"\n'
            f'maneuvers = [{{ id = "{mid}", t_start_s = {t_start_s}, t_end_s = {t_end_s} }}]\n')


def raises(path, *fragments):
    """load_problem(path) fails with a DataError whose message contains every fragment."""
    with pytest.raises(DataError) as info:
        load_problem(path)
    msg = str(info.value)
    for f in fragments:
        assert f in msg, f"{f!r} not in: {msg}"
    return msg
