"""Read a problem file (TOML) into a :class:`Problem`; the schema is in :mod:`estimator.io`."""

from __future__ import annotations

import codecs
import dataclasses
import re
import tomllib
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path

import numpy as np

from aircraft_models.schema import SUFFIXES, Key, check, did_you_mean
from estimator.extraction import ExtractionOptions
from estimator.io.assemble import DIMENSIONS, REQUIRED, ManeuverRequest, SourceTable, held_samples
from estimator.io.build import StateEquations, StateSetup, build_problem
from estimator.io.dataset_problem import load_dataset_maneuvers, load_sortie_maneuvers
from estimator.io.errors import DataError
from estimator.io.fprdataset import sortie_manifest
from estimator.io.logs import LOG_FORMATS, log_frame
from estimator.io.modelset import DEFAULT_MODEL_SET, OWN_SIGNALS, merge_model_set, read_model_set
from estimator.io.plausibility import Ranges, parse_ranges
from estimator.io.positions import check_positions, positions_of
from estimator.io.tables import check_data_path, infer_format, numeric, pick_column, read_table
from estimator.io.units import get_unit
from estimator.options import CalibrationOptions, option_tables
from estimator.parameters import ParameterSpec
from estimator.problem import STATE_SIGNALS, ChannelSpec, Problem

TOP_KEYS = ("title", "g_mps2", "lever_arm", "model", "channels", "resample_hz", "sensors", "aircraft",
            "columns", "files", "data", "parameter", "channel", "workflow", "solver", "report",
            "positions_checked", "plausible", "extraction")
#: the CG, in m (or r_cg_body_in, r_cg_body_ft)
_CG_KEYS = {"r_cg_body_m": Key(unit="m")}
FILE_KEYS = {**dict.fromkeys(("path", "format", "header", "delimiter", "decimal", "skip_rows", "encoding",
                              "aircraft", "configuration", "maneuvers", "resample_hz", "columns",
                              "offsets_s"), Key()),
             **_CG_KEYS}
MANEUVER_KEYS = {**dict.fromkeys(("id", "t_start_s", "t_end_s", "configuration"), Key()), **_CG_KEYS}
COLUMN_KEYS = ("column", "unit", "optional", "own_rate")
_DECIMAL_COMMA = re.compile(r"^[+-]?\d+,\d+([eE][+-]?\d+)?$")


def column_names(channels: Sequence[ChannelSpec], specs: Sequence[ParameterSpec]) -> dict[str, list[str]]:
    """The canonical names ``[columns]`` may map, by kind: the estimator's inputs, the model set's
    channels (their measurement columns) and the data signals its models read (``gear``, ``mach``).
    """
    params = {s.name for s in specs}
    chan_cols = [c.column for c in channels]
    signals = set(DIMENSIONS) - set(REQUIRED) - set(chan_cols)
    for c in channels:
        signals |= set(c.expression.names) - STATE_SIGNALS - OWN_SIGNALS - params - set(chan_cols)
    return {"inputs": list(REQUIRED), "channels": list(dict.fromkeys(chan_cols)),
            "data signals": sorted(signals)}


def _check_names(table: Mapping, valid: Mapping[str, list[str]], where: str) -> None:
    known = [n for names in valid.values() for n in names]
    for name in table:
        if name not in known:
            listing = "; ".join(f"{k}: {' '.join(v)}" for k, v in valid.items())
            raise DataError(
                f"{where}: {name!r} is not a name the estimator or the model set knows"
                + did_you_mean(name, known) + f"; valid names: {listing}. Fix the "
                "name (a data signal of your own is mapped once a [[channel]] model uses it)"
            )


def _number(v, key: str, where: str, what: str) -> float | None:
    """A number from the problem file (None stays None)."""
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise DataError(f"{where}: {key} = {v!r} must be a number ({what}), without quotes")
    return float(v)


def _vector(v, where: str) -> np.ndarray:
    if (not isinstance(v, list) or len(v) != 3
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
        raise DataError(f"{where}: must be [x, y, z] (three numbers, body axes x fwd, y right, "
                        f"z down), got {v!r}")
    return np.asarray(v, dtype=float)


def parse_positions(table: Mapping, where: str) -> dict[str, np.ndarray]:
    """``name = [x, y, z]`` in metres, or ``name_in``/``name_ft`` in inches/feet (``name_m`` too)."""
    out: dict[str, np.ndarray] = {}
    for key, v in table.items():
        name, factor = key, 1.0
        for suffix, f in SUFFIXES["m"]:
            if key.endswith(suffix):
                name, factor = key[: -len(suffix)], f
                break
        if name in out:
            raise DataError(f"{where}: position of {name!r} given twice (as {key} and in another unit); "
                            "keep one")
        out[name] = _vector(v, f"{where}: {key}") * factor
    return out


def _cg(d: Mapping, where: str) -> np.ndarray | None:
    """The CG of a table checked against :data:`_CG_KEYS` (converted to m there), or None."""
    v = d.get("r_cg_body_m")
    return None if v is None else _vector(v, f"{where}: r_cg_body_m")


def _column_specs(table: Mapping, where: str, valid: Mapping[str, list[str]] | None = None
                  ) -> dict[str, dict]:
    if not isinstance(table, Mapping):
        raise DataError(f"{where}: must be a table of name = {{ column = ..., unit = ... }}, got {table!r}")
    if valid is not None:
        _check_names(table, valid, where)
    out = {}
    for name, spec in table.items():
        w = f"{where}.{name}"
        if not isinstance(spec, Mapping):
            raise DataError(f"{w}: must be a table {{ column = \"NAME\" or index, unit = \"...\" }}, "
                            f"got {spec!r}")
        check(spec, COLUMN_KEYS, w, DataError)
        for flag in ("optional", "own_rate"):
            if not isinstance(spec.get(flag, False), bool):
                raise DataError(f"{w}: {flag} = {spec[flag]!r} must be true or false (no quotes)")
        if "column" not in spec or "unit" not in spec:
            raise DataError(f"{w}: needs column (name or 0-based index) and unit, e.g. "
                            f"{name} = {{ column = \"{name.upper()}\", unit = \"deg\" }}")
        out[name] = dict(spec)
    return out


def _check_decimal_comma(cells: np.ndarray, bad: np.ndarray, label: str, path: Path, entry: Mapping) -> None:
    """Text cells that are numbers with a decimal comma ("1,52"): name the ``decimal`` key."""
    if entry.get("decimal", ".") == ",":
        return
    shown = [str(c).strip() for c in cells[bad][:50]]
    if sum(bool(_DECIMAL_COMMA.match(c)) for c in shown) > len(shown) / 2:
        raise DataError(
            f"{path}: {label} holds numbers with a decimal comma ({shown[0]!r} in data row "
            f"{int(np.flatnonzero(bad)[0])}); set decimal = \",\" under its [[files]] entry (and the "
            "delimiter its fields are separated by, e.g. delimiter = \";\")")


def _read_file(entry: Mapping, columns: Mapping[str, dict], base: Path, where: str) -> SourceTable:
    path = (base / entry["path"]).resolve() if not Path(entry["path"]).is_absolute() else Path(entry["path"])
    check_data_path(path, entry.get("format"))
    fmt = infer_format(path, entry.get("format"), where)
    header = entry.get("header")
    if header is not None and not isinstance(header, bool):
        raise DataError(f"{where}: header = {header!r} must be true or false (no quotes)")
    skip = entry.get("skip_rows", 0)
    if isinstance(skip, bool) or not isinstance(skip, int) or skip < 0:
        raise DataError(f"{where}: skip_rows = {skip!r} must be a whole number of lines, 0 or more")
    encoding = entry.get("encoding")
    if encoding is not None:
        try:
            codecs.lookup(str(encoding))
        except LookupError:
            raise DataError(f"{where}: encoding = {encoding!r} is not a text encoding Python knows; e.g. "
                            "\"utf-8\", \"latin-1\", \"cp1252\", \"utf-16\"") from None
    for key in ("delimiter", "decimal"):
        if key in entry and (not isinstance(entry[key], str) or len(entry[key]) != 1):
            raise DataError(f"{where}: {key} = {entry[key]!r} must be one character in quotes, e.g. "
                            f"{key} = \"{';' if key == 'delimiter' else ','}\"")
    table_keys = sorted(k for k in ("header", "delimiter", "decimal", "skip_rows", "encoding") if k in entry)
    if fmt in LOG_FORMATS and table_keys:
        raise DataError(f"{where}: {table_keys} are for text tables; a {fmt} log has none: remove them")
    if fmt not in LOG_FORMATS and "offsets_s" in entry:
        raise DataError(f"{where}: offsets_s is for a log's streams (ulog, mat); a {fmt} table has one "
                        "time base: remove it")
    if fmt in LOG_FORMATS:
        df, header = _read_log(path, fmt, entry, columns, where), True
    else:
        named = [spec["column"] for spec in columns.values() if isinstance(spec["column"], str)]
        df = read_table(path, fmt, header=header, delimiter=entry.get("delimiter"), skip_rows=skip,
                        named_columns=named, encoding=None if encoding is None else str(encoding),
                        decimal=entry.get("decimal"))
        header = header is not False and not all(isinstance(c, (int, np.integer)) for c in df.columns)
    values, bad, text, units, labels = {}, {}, {}, {}, {}
    for name, spec in columns.items():
        src = spec["column"]
        present = (isinstance(src, int) and 0 <= src < df.shape[1]) or (
            isinstance(src, str) and src in df.columns)
        if spec.get("optional", False) and not present:
            continue
        series = pick_column(df, src, name, path, header,
                             taken=[str(s["column"]) for n, s in columns.items() if n != name])
        values[name], bad[name] = numeric(series)
        if bad[name].any():
            text[name] = series.to_numpy()
            _check_decimal_comma(text[name], bad[name], f"{name} (column {src!r})", path, entry)
        units[name] = spec["unit"]
        labels[name] = f"{name} (column {src!r})"
    own = frozenset(n for n, spec in columns.items() if spec.get("own_rate", False) and n in values)
    for name in own:
        values[name] = held_samples(values[name])
    holes = {name: df.attrs.get("holes", {}).get(spec["column"], []) for name, spec in columns.items()
             if name in values and spec["column"] in df.attrs.get("holes", {})}
    return SourceTable(path=path, values=values, not_numeric=bad, raw_text=text, units=units, labels=labels,
                       own_rate=own, holes=holes)


def _read_log(path: Path, fmt: str, entry: Mapping, columns: Mapping[str, dict], where: str):
    """A log's columns on the time base of its ``t`` column's stream (:func:`log_frame`), with
    the entry's declared clock offsets (``offsets_s = { STREAM = seconds }``)."""
    offsets = entry.get("offsets_s", {})
    if not isinstance(offsets, Mapping) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)
            for v in offsets.values()):
        raise DataError(f"{where}: offsets_s = {offsets!r} must be a table of stream = seconds, e.g. "
                        "offsets_s = { vehicle_gps_position = -0.2 } (added to that stream's stamps)")
    t_unit = columns.get("t", {}).get("unit", "s")
    factor = get_unit(t_unit, f"{where}: t").factor
    return log_frame(path, fmt, columns, where, offsets_s={str(k): float(v) for k, v in offsets.items()},
                     time_factor_s=factor)


def _file_pairs(raw: Mapping, base: Path, where: str, valid: Mapping[str, list[str]],
                plausible: Ranges | None = None
                ) -> list[tuple[SourceTable, ManeuverRequest]]:
    aircraft = raw.get("aircraft", {})
    cgs = {}
    for ac, d in aircraft.items():
        if not isinstance(d, Mapping):
            raise DataError(f"{where}: [aircraft.{ac}] must be a table with r_cg_body_m = [x, y, z]")
        w = f"{where}: [aircraft.{ac}]"
        cgs[ac] = _cg(check(d, _CG_KEYS, w, DataError), w)
    pairs = []
    for entry, w, table in _file_tables(raw, base, where, valid):
        if "aircraft" in entry:
            ac = str(entry["aircraft"])
        elif len(cgs) == 1:
            ac = next(iter(cgs))
        elif not cgs:
            ac = "aircraft"
        else:
            raise DataError(f"{w}: say which aircraft flew it: aircraft = one of {sorted(cgs)}")
        file_cg = _cg(entry, w)
        if ac not in cgs and file_cg is None:
            raise DataError(f"{w}: no CG for aircraft {ac!r}: add [aircraft.{ac}] r_cg_body_m = [x, y, z] "
                            "(or r_cg_body_m under this [[files]] entry or its maneuvers)")
        rate = _number(entry.get("resample_hz", raw.get("resample_hz")), "resample_hz", w, "Hz, e.g. 40.0")
        if "maneuvers" in entry and not entry["maneuvers"]:
            raise DataError(f"{w}: maneuvers = [] lists none; list the maneuvers (id, t_start_s, "
                            "t_end_s), or remove the key to take the whole file as one maneuver")
        mans = entry.get("maneuvers") or [{"id": Path(entry["path"]).stem}]
        for j, man in enumerate(mans):
            mw = f"{w} maneuvers[{j}]"
            if not isinstance(man, Mapping) or "id" not in man:
                raise DataError(f"{mw}: each maneuver needs id = \"...\" (and t_start_s, t_end_s)")
            man = check(man, MANEUVER_KEYS, mw, DataError)
            cg = _cg(man, mw)
            cg = cg if cg is not None else file_cg if file_cg is not None else cgs[ac]
            t0 = _number(man.get("t_start_s"), "t_start_s", mw, "s, in the file's time base")
            t1 = _number(man.get("t_end_s"), "t_end_s", mw, "s, in the file's time base")
            pairs.append((table, ManeuverRequest(
                id=str(man["id"]), t_start_s=None if t0 is None else float(t0),
                t_end_s=None if t1 is None else float(t1), aircraft=ac,
                configuration=str(man.get("configuration", entry.get("configuration", ac))),
                r_cg_body_m=cg, resample_hz=None if rate is None else float(rate),
                meta={"file": str(table.path), "t_start_s": t0, "t_end_s": t1},
                plausible=dict(plausible or {}),
            )))
    return pairs


def _file_tables(raw: Mapping, base: Path, where: str, valid: Mapping[str, list[str]]
                 ) -> Iterator[tuple[dict, str, SourceTable]]:
    """Each ``[[files]]`` entry checked, how messages name it, and its data read whole (the
    ``[columns]`` and the entry's own), in the file's units."""
    files = raw.get("files")
    if not files:
        raise DataError(f"{where}: no data: add [[files]] entries (path = ...) or [data] dataset = ...")
    global_cols = _column_specs(raw.get("columns", {}), f"{where}: [columns]", valid)
    for i, entry in enumerate(files):
        entry = check(entry, FILE_KEYS, f"{where}: [[files]] #{i + 1}", DataError)
        if "path" not in entry:
            raise DataError(f"{where}: [[files]] #{i + 1}: needs path = \"...\" (relative to the "
                            "problem file)")
        w = f"{where}: [[files]] {entry['path']}"
        cols = {**global_cols, **_column_specs(entry.get("columns", {}), f"{w} columns", valid)}
        yield dict(entry), w, _read_file(entry, cols, base, w)


def read_whole_files(path: Path, raw: Mapping) -> list[tuple[dict, SourceTable]]:
    """Each ``[[files]]`` entry of the parsed problem file ``raw`` (at ``path``) with its data read
    whole, in the file's units (its ``maneuvers`` not cut: the maneuver finder reads a flight)."""
    where = str(path)
    raw_model, msource = read_model_set(raw.get("model", DEFAULT_MODEL_SET), path.resolve().parent)
    chans, specs, _ = merge_model_set(raw_model, raw.get("parameter"), raw.get("channel"), msource, where)
    return [(entry, table) for entry, _, table in
            _file_tables(raw, path.resolve().parent, where, column_names(chans, specs))]


def parse_options(raw: Mapping, where: str) -> dict:
    """The ``[workflow]``, ``[solver]`` and ``[report]`` tables as one flat mapping of option names.

    Each table holds only its own options (``[solver]``: the fields of
    :class:`~estimator.options.SolverOptions`; ``[workflow]``: those of
    :class:`~estimator.options.WorkflowOptions`; ``[report]``: ``plots``), checked here and then
    by :meth:`~estimator.options.CalibrationOptions.from_mapping`, the one mapping the CLI uses too.
    """
    tables = option_tables()
    flat: dict = {}
    for name, valid in tables.items():
        table = raw.get(name, {})
        if not isinstance(table, Mapping):
            raise DataError(f"{where}: [{name}] must be a table of option = value, got {table!r}")
        for key in table:
            if key not in valid:
                other = next((t for t, v in tables.items() if key in v), None)
                raise DataError(
                    f"{where}: [{name}] {key!r} is not a {name} option"
                    + (f" (it belongs under [{other}])" if other else did_you_mean(key, valid))
                    + f"; valid: {', '.join(valid)}")
        flat.update(table)
    try:
        CalibrationOptions.from_mapping(flat)
    except (TypeError, ValueError) as exc:
        raise DataError(f"{where}: [workflow]/[solver]/[report]: {exc}") from None
    return flat


def load_problem(path: str | Path) -> Problem:
    """Read a problem file (TOML; schema in :mod:`estimator.io`) and the data it points at.

    Raises
    ------
    DataError
        For anything wrong in the file or the data; the message names the file, channel, column,
        maneuver and time and says how to fix it.
    """
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            raw = tomllib.load(fh)
    except FileNotFoundError:
        raise DataError(f"{path}: no such problem file") from None
    except tomllib.TOMLDecodeError as exc:
        raise DataError(f"{path}: not valid TOML: {exc}; fix the syntax there (an unclosed quote or "
                        "bracket, a missing = or comma, text without quotes?)") from None
    except IsADirectoryError:
        raise DataError(f"{path}: is a folder; give the problem file (TOML), or the dataset folder to "
                        "fpr calibrate directly") from None
    where = str(path)
    check(raw, TOP_KEYS, where, DataError)
    options = parse_options(raw, where)
    try:  # the maneuver finder's thresholds (fpr maneuvers): checked here too, never ignored
        ExtractionOptions.from_mapping(raw.get("extraction", {}), f"{where}: [extraction]")
    except ValueError as exc:
        raise DataError(str(exc)) from None
    base = path.resolve().parent
    raw_model, msource = read_model_set(raw.get("model", DEFAULT_MODEL_SET), base)
    chans, specs, declared = merge_model_set(raw_model, raw.get("parameter"), raw.get("channel"),
                                             msource, where)
    sensors = parse_positions(raw.get("sensors", {}), f"{where}: [sensors]")
    checked = raw.get("positions_checked", False)
    if not isinstance(checked, bool):
        raise DataError(f"{where}: positions_checked = {checked!r} must be true or false (no quotes)")
    # a CG or sensor position in the wrong unit (inches under a metre key), before any data is read
    check_positions(positions_of(raw, path.read_text(encoding="utf-8", errors="replace")), where, checked)
    data = raw.get("data")
    if data is not None:
        check(data, ("dataset", "select", "maneuvers"), f"{where}: [data]", DataError)
        # a dataset of fpr fly is the testbed's aircraft: its plausible ranges are the built-in ones
        clash = [k for k in ("files", "columns", "aircraft", "plausible") if k in raw]
        if clash:
            raise DataError(f"{where}: [data] dataset = ... reads everything from the dataset; "
                            f"remove {clash}")
        if "dataset" not in data:
            raise DataError(f"{where}: [data] needs dataset = \"path/to/dataset\"")
        ds = Path(data["dataset"])
        ds = ds if ds.is_absolute() else base / ds
        if sortie_manifest(ds) is not None:  # a whole sortie, cut by the given windows
            if "maneuvers" not in data or "select" in data:
                raise DataError(f"{where}: [data] dataset = {str(ds)!r} is a whole sortie: say which "
                                "maneuvers with maneuvers = [...] (fpr maneuvers writes them) or "
                                "maneuvers = \"boundaries\" (the sortie's own record); no select")
            pairs, pos = load_sortie_maneuvers(ds, data["maneuvers"], chans, where=f"{where}: [data]")
        else:
            if "maneuvers" in data:
                raise DataError(f"{where}: [data] maneuvers = ... is for a whole sortie; a dataset of "
                                "maneuvers is chosen with select = { ... }")
            pairs, pos = load_dataset_maneuvers(ds, data.get("select"), chans)
        sensors = {**pos, **sensors}
    else:
        # the aircraft's plausible ranges: the model set's, then the problem file's
        valid = column_names(chans, specs)
        named = sorted({n for names in valid.values() for n in names} | {"accel"})
        plausible = {**parse_ranges(raw_model.get("plausible", {}), f"{where} (model set {msource})", named),
                     **parse_ranges(raw.get("plausible", {}), where, named)}
        pairs = _file_pairs(raw, base, where, valid, plausible)
    if "imu" not in sensors:
        raise DataError(f"{where}: [sensors] needs imu = [x, y, z], the accelerometer position (body axes, "
                        "m from the reference point): the lever-arm correction depends on it")
    default = StateEquations()
    g = raw.get("g_mps2", default.g_mps2)
    if isinstance(g, bool) or not isinstance(g, (int, float)):
        raise DataError(f"{where}: g_mps2 must be a number (m/s^2), got {g!r}")
    setup = StateSetup(sensors=sensors, imu_position_body_m=sensors["imu"],
                       equations=StateEquations(float(g), raw.get("lever_arm", default.lever_arm)))
    problem = build_problem(pairs, chans, specs, user_declared=declared,
                            explicit_channels=raw.get("channels"), setup=setup, source=where)
    return dataclasses.replace(problem, options=options) if options else problem
