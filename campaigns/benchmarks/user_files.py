"""A flown dataset as a user's files: one CSV in engineering units and its problem file.

The bad-input benchmark (``bad_inputs.py``) starts its corpus from these files, and the tests of
``fpr calibrate``, of unit faults and of output folders write theirs with the same functions: a user's
column names and units (:data:`USER_COLUMNS`), the problem file's layout (:func:`problem_text`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from estimator.io.units import UNITS


def _per_si(unit: str) -> float:
    """Written value per SI value in ``unit``: the reader's own factor (:data:`estimator.io.units.UNITS`),
    so that a file written here reads back to the same SI values."""
    return 1.0 / UNITS[unit].factor


#: written unit per SI unit: deg per rad, kt per m/s, ft per m; and standard gravity, m/s^2 per g
DEG, KT, FT = _per_si("deg"), _per_si("kt"), _per_si("ft")
G0 = UNITS["g"].factor

#: canonical name -> (CSV column, dataset column, factor from SI to the written unit, unit, extra spec)
USER_COLUMNS = {
    "ax": ("AX", "ax_imu_mps2", 1.0 / G0, "g", ""), "ay": ("AY", "ay_imu_mps2", 1.0 / G0, "g", ""),
    "az": ("AZ", "az_imu_mps2", 1.0 / G0, "g", ""),
    "p": ("P", "p_rps", DEG, "deg/s", ""), "q": ("Q", "q_rps", DEG, "deg/s", ""),
    "r": ("R", "r_rps", DEG, "deg/s", ""),
    "phi": ("PHI", "phi_rad", DEG, "deg", ""), "theta": ("THETA", "theta_rad", DEG, "deg", ""),
    "psi": ("PSI", "psi_rad", DEG, "deg", ""), "tas": ("TAS", "tas_mps", KT, "kt", ""),
    "h": ("HP", "h_baro_m", FT, "ft", ""),
    "h_dgps": ("GPS_ALT", "h_dgps_m", FT, "ft", ", own_rate = true"),
    "alpha_zl": ("AOA_L", "alpha_zl_rad", DEG, "deg", ""),
    "alpha_zr": ("AOA_R", "alpha_zr_rad", DEG, "deg", ""),
    "alpha_zsp": ("AOA_SP", "alpha_zsp_rad", DEG, "deg", ""),
    "beta_zsp": ("AOSS_SP", "beta_zsp_rad", DEG, "deg", ""),
    "mach": ("MACH", "mach", 1.0, "1", ""), "gear": ("GEAR", "gear_down", 1.0, "1", ""),
}
#: The IMU and the PV1 nose-probe aircraft's air-data sensors
PV1_SENSORS = ("imu", "vane_left", "vane_right", "side_probe_left", "side_probe_right")


def column_line(name: str, column: Sequence) -> str:
    """The problem file's ``[columns]`` line of channel ``name``: ``column`` as in :data:`USER_COLUMNS`
    (only the CSV column, unit and extra spec are read: a ``(column, unit)`` pair also does)."""
    csv, unit, extra = (column[0], column[1], "") if len(column) == 2 else (column[0], column[3], column[4])
    return f'{name} = {{ column = "{csv}", unit = "{unit}"{extra} }}'


def problem_text(channels: Sequence[str], sensors: Mapping[str, Sequence[float]],
                 r_cg_body_m: Sequence[float], columns: Mapping[str, Sequence], files: str,
                 title: str | None = None, model: str | None = "tejas", tail: str = "") -> str:
    """A problem file for aircraft PV1.

    ``sensors``: name -> position, m; ``columns``: channel -> column (:func:`column_line`), after
    the time column ``Time`` in s unless ``columns`` maps ``t``; ``files``: the ``[[files]]`` table's
    lines; ``title``, ``model``: omitted when None; ``tail``: appended (e.g. ``[parameter.h0]``).
    """
    head = [f'title = "{title}"'] if title is not None else []
    head += [f'model = "{model}"'] if model is not None else []
    head += ["channels = [" + ", ".join(f'"{c}"' for c in channels) + "]"]
    time = [] if "t" in columns else ['t = { column = "Time", unit = "s" }']
    return "\n".join([
        *head, "", "[sensors]", *(f"{k} = {v}" for k, v in sensors.items()), "",
        "[aircraft.PV1]", f"r_cg_body_m = {r_cg_body_m}", "",
        "[columns]", *time, *(column_line(k, c) for k, c in columns.items()), "",
        "[[files]]", files, ""]) + tail


@dataclass(frozen=True)
class CsvLayout:
    """How :func:`write_user_files` lays out the CSV and its ``[[files]]`` entry.

    ``name``, ``float_format``: the CSV's name and number format (None: full precision);
    ``t_first_s``: maneuver id -> the recorder time of its first sample, s; None: 1000 s for the
    first, then 100 s after the previous one ends (a gap outside every time range);
    ``time_format``: format of the maneuvers' time ranges in the problem file; ``configuration``:
    the file's configuration, if any.
    """

    name: str = "flight.csv"
    float_format: str | None = None
    t_first_s: Mapping[str, float] | None = None
    time_format: str = ".6f"
    configuration: str | None = None


def write_user_files(dataset_dir: Path, dest: Path, columns: Mapping[str, Sequence], channels: Sequence[str],
                     title: str, *, sensors: Sequence[str] = PV1_SENSORS, tail: str = "",
                     layout: CsvLayout | None = None) -> Path:
    """Every maneuver of a flown dataset in one CSV, ``dest/<layout.name>``, and ``dest/problem.toml``.

    Parameters
    ----------
    dataset_dir : the flown dataset (aircraft PV1).
    dest : a new folder, made here.
    columns : channel -> (CSV column, dataset column, factor from SI, unit, extra spec), as
        :data:`USER_COLUMNS`: each written as ``SI value * factor`` and declared in ``unit``.
    channels : the problem's fitted channels.
    title : the problem's title.
    sensors : the sensors whose positions (the dataset's) the problem declares.
    tail : text appended to the problem file.
    layout : the CSV's name, number and time formats, time ranges and configuration (None: the
        defaults of :class:`CsvLayout`).

    Returns
    -------
    The problem file's path.
    """
    from synth.dataset import load_dataset

    layout = layout or CsvLayout()
    ds = load_dataset(dataset_dir)
    frames, ranges, t0 = [], [], 1000.0
    for entry, df in ds:
        start = t0 if layout.t_first_s is None else layout.t_first_s[entry["id"]]
        t = df["t_s"].to_numpy() - df["t_s"].iloc[0] + start
        cols = {c[0]: df[c[1]].to_numpy(dtype=float) * c[2] for c in columns.values()}
        frames.append(pd.DataFrame({"Time": t, **cols}))
        ranges.append((entry["id"], t[0], t[-1]))
        t0 = t[-1] + 100.0
    dest.mkdir(parents=True)
    pd.concat(frames).to_csv(dest / layout.name, index=False, float_format=layout.float_format)
    pos = ds.manifest["airframe"]["positions_body_m"]
    tf = layout.time_format
    mans = ",\n  ".join(f'{{ id = "{i}", t_start_s = {a:{tf}}, t_end_s = {b:{tf}} }}' for i, a, b in ranges)
    files = "\n".join([f'path = "{layout.name}"', 'aircraft = "PV1"',
                       *([f'configuration = "{layout.configuration}"'] if layout.configuration else []),
                       f"maneuvers = [\n  {mans},\n]"])
    problem = dest / "problem.toml"
    problem.write_text(problem_text(channels, {k: pos[k] for k in sensors},
                                    ds.manifest["maneuvers"][0]["r_cg_body_m_mean"], columns, files, title,
                                    tail=tail))
    return problem
