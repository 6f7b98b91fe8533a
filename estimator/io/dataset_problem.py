"""A :class:`Problem` from a dataset written by ``fpr fly`` (the same checks as a problem file)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from estimator.io.assemble import ManeuverRequest, SourceTable
from estimator.io.build import StateEquations, StateSetup, build_problem
from estimator.io.errors import DataError
from estimator.io.fprdataset import (
    FPR_COLUMNS,
    canonical_name,
    column_unit,
    dataset_sensors,
    read_maneuver,
    read_manifest,
    select_entries,
    sortie_manifest,
)
from estimator.io.modelset import DEFAULT_MODEL_SET, OWN_SIGNALS, merge_model_set, read_model_set
from estimator.io.tables import numeric
from estimator.problem import STATE_SIGNALS, ChannelSpec, Problem


def data_names(channels: Iterable[ChannelSpec]) -> set[str]:
    """The canonical names a problem of these channels reads from a dataset besides the format's
    own columns: each channel's measurement and every data signal its model reads."""
    names = set()
    for c in channels:
        names |= {c.column} | (set(c.expression.names) - STATE_SIGNALS - OWN_SIGNALS)
    return names


def load_dataset_maneuvers(path: str | Path, select: Mapping | None = None,
                           channels: Iterable[ChannelSpec] = ()
                           ) -> tuple[list[tuple[SourceTable, ManeuverRequest]], dict[str, np.ndarray]]:
    """The selected maneuvers of a dataset as (table, request) pairs, and the sensor positions.

    Parameters
    ----------
    path : the dataset directory (or its manifest.json).
    select : which maneuvers (:func:`~estimator.io.fprdataset.select_entries`); None: all.
    channels : the model set's channels: besides the format's own columns (time, IMU, attitude,
        air data, gear), the columns holding their measurements and the data signals their models
        read are read (:func:`data_names`); none: the format's own columns only.

    Each request's ``meta`` is the manifest entry plus ``dataset`` (the directory) so that
    :func:`~estimator.io.fprdataset.load_truth` finds the truth (``true_*`` columns, never read here).
    """
    directory, manifest = read_manifest(path)
    entries = select_entries(manifest, select, str(directory))
    names = data_names(channels)
    pairs = []
    for e in entries:
        df = read_maneuver(directory, e, names)
        file = directory / e["file"]
        canon = {c: canonical_name(c) for c in df.columns}
        values, bad, text = {}, {}, {}
        for col in df.columns:
            values[canon[col]], bad[canon[col]] = numeric(df[col])
            if bad[canon[col]].any():
                text[canon[col]] = df[col].to_numpy()
        table = SourceTable(
            path=file, values=values, not_numeric=bad, raw_text=text,
            units={canon[c]: column_unit(c) for c in df.columns},
            labels={canon[c]: f"{canon[c]} (column {c!r})" for c in df.columns},
            own_rate=frozenset(canon[c] for c in e.get("own_rate_columns", ()) if c in df.columns),
        )
        if e.get("r_cg_body_m_mean") is None:
            raise DataError(f"{directory}: manifest entry {e['id']} has no r_cg_body_m_mean (the CG)")
        aircraft = str(e.get("aircraft") or "aircraft")
        pairs.append((table, ManeuverRequest(
            id=str(e["id"]), t_start_s=None, t_end_s=None, aircraft=aircraft,
            configuration=str(e.get("configuration") or aircraft),
            r_cg_body_m=np.asarray(e["r_cg_body_m_mean"], dtype=float),
            meta={**e, "dataset": str(directory)},
        )))
    return pairs, dataset_sensors(manifest)


def _windows(maneuvers, where: str) -> list[tuple[str, float, float]]:
    """``(id, t_start_s, t_end_s)`` of a ``maneuvers = [...]`` list (unique ids, start < end)."""
    if not isinstance(maneuvers, list) or not maneuvers:
        raise DataError(f"{where}: maneuvers must be a list of {{ id = \"...\", t_start_s = ..., "
                        "t_end_s = ... } (as fpr maneuvers writes it), or \"boundaries\"")
    out, seen = [], set()
    for j, m in enumerate(maneuvers):
        ok = isinstance(m, Mapping) and set(m) == {"id", "t_start_s", "t_end_s"} and all(
            isinstance(m[k], (int, float)) and not isinstance(m[k], bool) for k in ("t_start_s", "t_end_s"))
        if not ok or not m["t_start_s"] < m["t_end_s"] or str(m["id"]) in seen:
            raise DataError(f"{where}: maneuvers[{j}] = {m!r}: needs id (unique), t_start_s < t_end_s (s)")
        seen.add(str(m["id"]))
        out.append((str(m["id"]), float(m["t_start_s"]), float(m["t_end_s"])))
    return out


def load_sortie_maneuvers(path: str | Path, maneuvers, channels: Iterable[ChannelSpec] = (), *,
                          where: str | None = None
                          ) -> tuple[list[tuple[SourceTable, ManeuverRequest]], dict[str, np.ndarray]]:
    """Maneuvers cut out of a testbed sortie (``fpr fly --sortie``) by their windows, as
    (table, request) pairs, and the sensor positions.

    Parameters
    ----------
    path : the sortie directory.
    maneuvers : ``[{id, t_start_s, t_end_s}, ...]`` in the sortie's time (what ``fpr maneuvers``
        writes), or ``"boundaries"``: the sortie's own record of where each maneuver was flown.
    channels : the model set's channels (which columns are read, as :func:`load_dataset_maneuvers`).
    where : how messages name the request (default: the sortie directory).
    """
    directory = Path(path)
    manifest = sortie_manifest(directory)
    if manifest is None:
        raise DataError(f"{directory}: not a sortie (fpr fly --sortie)")
    s = manifest["sortie"]
    where = f"{where or directory}: maneuvers"
    if "r_cg_body_m_mean" not in s:
        raise DataError(f"{directory}: the sortie's manifest has no weight and balance "
                        "(r_cg_body_m_mean): it was flown by an older fpr; fly it again")
    boundaries = maneuvers == "boundaries"
    if boundaries:
        maneuvers = [{"id": b["id"], "t_start_s": b["t_start_s"], "t_end_s": b["t_end_s"]}
                     for b in s["boundaries"]]
    windows = _windows(maneuvers, where)
    file = directory / s["files"]["data"]
    present = pq.read_schema(file).names
    wanted = [c for c in present if not c.startswith("true_")
              and (c in FPR_COLUMNS or canonical_name(c) in data_names(channels))]
    df = pq.read_table(file, columns=wanted).to_pandas()
    if boundaries:  # the flight's record, in the truth's time: within the recorders' span
        t = df["t_s"].to_numpy()
        windows = [(m, max(t0, float(t[0])), min(t1, float(t[-1]))) for m, t0, t1 in windows]
    values, bad = {}, {}
    for col in df.columns:
        values[canonical_name(col)], bad[canonical_name(col)] = numeric(df[col])
    table = SourceTable(path=file, values=values, not_numeric=bad,
                        units={canonical_name(c): column_unit(c) for c in df.columns},
                        labels={canonical_name(c): f"{canonical_name(c)} (column {c!r})" for c in df.columns},
                        own_rate=frozenset(canonical_name(c) for c in s.get("own_rate_columns", ())
                                           if c in df.columns))
    keep = ("configuration", "aircraft", "nose_sensor", "sensors", "g_mps2_mean", "environment", "injected")
    pairs = [(table, ManeuverRequest(
        id=mid, t_start_s=t0, t_end_s=t1, aircraft=str(s["aircraft"]), configuration=str(s["configuration"]),
        r_cg_body_m=np.asarray(s["r_cg_body_m_mean"], dtype=float),
        meta={**{k: s[k] for k in keep if k in s}, "dataset": str(directory), "file": s["files"]["data"],
              "sortie_window_s": [t0, t1]},
    )) for mid, t0, t1 in windows]
    return pairs, dataset_sensors(manifest)


#: The default state equations: standard gravity, the IMU-point lever arm.
EARTH = StateEquations()


def problem_from_dataset(
    path: str | Path,
    select: Mapping | None = None,
    model: str | Path = DEFAULT_MODEL_SET,
    channels: Sequence[str] | None = None,
    overrides: Mapping[str, Mapping] | None = None,
    *,
    extra_channels: Sequence[Mapping] | None = None,
    sensors: Mapping[str, Sequence[float]] | None = None,
    equations: StateEquations = EARTH,
) -> Problem:
    """The estimation problem of (a selection of) an ``fpr fly`` dataset.

    Parameters
    ----------
    path : the dataset directory (or its manifest.json).
    select : which maneuvers: ``kind``, ``configuration``, ``aircraft``, ``ids`` (value or list),
        ``mach_min``, ``mach_max`` (on the mean Mach), ``gear_down`` (bool). None: all.
    model : model set, a shipped name (default: the paper's, ``tejas``) or a TOML path.
    channels : channel names to use; None: every channel of the model set with data.
    overrides : parameter name -> keys as in ``[parameter.NAME]`` (e.g. ``{"b_l": {"free": False}}``).
    extra_channels : channel tables as in ``[[channel]]``.
    sensors : sensor positions (body axes, m) added to or replacing the manifest's airframe ones.
    equations : gravity and the lever-arm formulation of the state equations
        (:class:`~estimator.io.build.StateEquations`; default: 9.80665 m/s^2, "imu_point").
    """
    raw, msource = read_model_set(model)
    chans, specs, declared = merge_model_set(raw, overrides, extra_channels, msource, str(path))
    pairs, pos = load_dataset_maneuvers(path, select, chans)
    pos.update({k: np.asarray(v, dtype=float) for k, v in (sensors or {}).items()})
    if "imu" not in pos:
        raise DataError(f"{path}: the manifest's airframe has no imu position; "
                        "pass sensors={'imu': [x, y, z]}")
    setup = StateSetup(sensors=pos, imu_position_body_m=pos["imu"], equations=equations)
    return build_problem(pairs, chans, specs, user_declared=declared, explicit_channels=channels,
                         setup=setup, source=str(path))
