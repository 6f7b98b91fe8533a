"""A whole flight read for the maneuver finder (:mod:`estimator.extraction`): from a testbed
sortie (``fpr fly --sortie``) or from the files of a problem file, read whole.

A sortie directory (manifest format ``fpr-sortie``) holds the flight on one time base in
``sortie.parquet``, columns named as in a dataset (:data:`~estimator.io.fprdataset.FPR_COLUMNS`);
the truth (``true_*``) is never read. A problem file's ``[[files]]`` are read as ``fpr calibrate``
reads them (its ``[columns]``, units, log streams and clock offsets; t, ax, ay, az, p, q, r
required), each whole, its ``maneuvers`` ignored; its ``[extraction]`` table sets the finder's
thresholds.
"""

from __future__ import annotations

import os
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import pyarrow.parquet as pq
import tomli_w

from estimator.extraction import ExtractionOptions, FlightSignals, ManeuverTable
from estimator.io.errors import DataError
from estimator.io.fprdataset import MANIFEST, SORTIE_FORMAT, dataset_column, sortie_manifest
from estimator.io.problemfile import read_whole_files
from estimator.io.units import to_si

#: FlightSignals field -> canonical channel name (a problem file's; a sortie's column is the
#: dataset format's for it, :func:`~estimator.io.fprdataset.dataset_column`)
_FIELDS = {"az_mps2": "az", "q_rps": "q", "ay_mps2": "ay", "p_rps": "p", "r_rps": "r", "phi_rad": "phi",
           "psi_rad": "psi", "h_m": "h", "mach": "mach", "tas_mps": "tas"}


@dataclass(frozen=True)
class FlightFile:
    """One recorded flight to search: its signals, and how a problem file names its data.

    Attributes
    ----------
    signals : the motion, SI (:class:`~estimator.extraction.FlightSignals`).
    path : the data file (a sortie's ``sortie.parquet``, a problem file's ``[[files]] path``).
    entry : the problem file's ``[[files]]`` entry it came from (empty for a sortie).
    """

    signals: FlightSignals
    path: Path
    entry: dict


def read_sortie_flight(directory: str | Path) -> FlightFile:
    """The whole flight of a testbed sortie directory (its truth never read)."""
    directory = Path(directory)
    manifest = sortie_manifest(directory)
    if manifest is None:
        raise DataError(f"{directory}: not a sortie (no {MANIFEST} of format {SORTIE_FORMAT!r}); "
                        "a sortie is written by `fpr fly CAMPAIGN --sortie --out DIR`")
    path = directory / manifest["sortie"]["files"]["data"]
    if not path.is_file():
        raise DataError(f"{path}: the sortie's data file is missing; fly the sortie again")
    names = pq.read_schema(path).names
    column = {f: dataset_column(canonical, names) for f, canonical in _FIELDS.items()}
    column = {f: c for f, c in column.items() if c in names}
    df = pq.read_table(path, columns=["t_s", *column.values()]).to_pandas()
    values = {f: df[c].to_numpy(dtype=float) for f, c in column.items()}
    return FlightFile(FlightSignals(t_s=df["t_s"].to_numpy(dtype=float), source=str(directory), **values),
                      path, {})


def _signals(table, where: str) -> FlightSignals:
    """FlightSignals of a problem file's source table (its values in the file's units)."""
    values = {}
    for field_name, name in _FIELDS.items():
        if name in table.values:
            label = f"{where}: {table.labels[name]}"
            values[field_name] = to_si(table.values[name], table.units[name], label)
    own = frozenset(f for f, name in _FIELDS.items() if name in table.own_rate)
    return FlightSignals(t_s=table.t_s, source=where, own_rate=own, **values)


def read_problem_flights(path: str | Path) -> tuple[list[FlightFile], ExtractionOptions]:
    """Every ``[[files]]`` of a problem file read whole, and its ``[extraction]`` thresholds."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DataError(f"{path}: no such problem file") from None
    except tomllib.TOMLDecodeError as exc:
        raise DataError(f"{path}: not valid TOML: {exc}") from None
    try:
        options = ExtractionOptions.from_mapping(raw.get("extraction", {}), f"{path}: [extraction]")
    except ValueError as exc:
        raise DataError(str(exc)) from None
    flights = [FlightFile(_signals(table, f"{path}: [[files]] {entry['path']}"), table.path, entry)
               for entry, table in read_whole_files(path, raw)]
    return flights, options


def read_flights(source: str | Path) -> tuple[list[FlightFile], ExtractionOptions]:
    """The flights of ``source``: a sortie directory, or a problem file (TOML) whose files are
    read whole; and the thresholds (the problem file's ``[extraction]``, else the defaults)."""
    source = Path(source)
    if source.is_dir():
        return [read_sortie_flight(source)], ExtractionOptions()
    if source.suffix.lower() == ".toml":
        return read_problem_flights(source)
    raise DataError(f"{source}: give a sortie directory (fpr fly --sortie) or a problem file (.toml) "
                    "whose [columns] map the log's t, ax, ay, az, p, q, r (and phi, psi, h, tas or "
                    "mach: the more, the more kinds are found)")


def _rebased(path: str, base: Path, out_dir: Path) -> str:
    """``path`` (relative to ``base`` unless absolute) relative to ``out_dir`` where it can be."""
    p = Path(path)
    p = p if p.is_absolute() else (base / p).resolve()
    try:
        return Path(os.path.relpath(p, out_dir.resolve())).as_posix()
    except ValueError:  # another drive
        return str(p)


def found_problem(source: str | Path, tables: Sequence[ManeuverTable], out: str | Path,
                  borderline: bool = True) -> str:
    """The TOML text of a problem file that calibrates the maneuvers found in ``source``.

    Parameters
    ----------
    source : what :func:`read_flights` read: a sortie directory (the file reads it with
        ``[data] dataset``, the windows as its ``maneuvers``) or a problem file (a copy of it,
        each ``[[files]]`` entry's ``maneuvers`` replaced by the windows found in that file).
    tables : one :class:`~estimator.extraction.ManeuverTable` per flight, in ``read_flights``'s order.
    out : where the file will be written (relative paths are made relative to its folder).
    borderline : include the maneuvers graded borderline (those graded keep always are).

    A file in which none is kept is left out. Raises ValueError when none is kept at all.
    """
    source, out_dir = Path(source), Path(out).parent
    kept = [t.problem_maneuvers(borderline, prefix=f"f{i}" if len(tables) > 1 else "")
            for i, t in enumerate(tables)]
    if not any(kept):
        raise ValueError(f"{source}: no maneuver graded keep{' or borderline' * borderline} to write; "
                         "read the table's reasons, or set the thresholds in [extraction]")
    if source.is_dir():
        return tomli_w.dumps({
            "title": f"maneuvers found in {source.name} by fpr maneuvers",
            "data": {"dataset": _rebased(str(source), Path.cwd(), out_dir), "maneuvers": kept[0]}})
    raw = tomllib.loads(source.read_text(encoding="utf-8"))
    base = source.resolve().parent
    files = []
    for entry, windows in zip(raw["files"], kept, strict=True):
        if windows:  # a file with nothing to calibrate is left out (an empty list is refused)
            entry["path"] = _rebased(entry["path"], base, out_dir)
            entry["maneuvers"] = windows
            files.append(entry)
    raw["files"] = files
    model = raw.get("model")
    if isinstance(model, str) and model.endswith(".toml"):
        raw["model"] = _rebased(model, base, out_dir)
    return tomli_w.dumps(raw)
