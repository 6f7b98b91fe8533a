"""Read flight-data files (CSV, whitespace-separated text, Parquet) and pick their columns.

The reader returns the raw table; :mod:`estimator.io.assemble` does units and checks.
"""

from __future__ import annotations

import csv
import re
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq

from aircraft_models.schema import did_you_mean
from estimator.io.errors import DataError, close_match, warn
from estimator.io.logs import LOG_EXTENSIONS, LOG_FORMATS

#: Tables (one time base, columns by name or index) and logs (streams: :mod:`estimator.io.logs`).
FORMATS = ("csv", "whitespace", "parquet", *LOG_FORMATS)
_EXTENSIONS = {".csv": "csv", ".txt": "whitespace", ".dat": "whitespace", ".asc": "whitespace",
               ".parquet": "parquet", ".pq": "parquet", **LOG_EXTENSIONS}


def infer_format(path: Path, fmt: str | None, where: str) -> str:
    """The file format: ``fmt`` if given, else from the extension."""
    if fmt is not None:
        if fmt not in FORMATS:
            raise DataError(f"{where}: format = {fmt!r} is not one of {FORMATS}")
        return fmt
    ext = path.suffix.lower()
    if ext not in _EXTENSIONS:
        raise DataError(
            f"{where}: cannot tell the format of {path.name} from its extension {ext!r} "
            f"(known: {sorted(_EXTENSIONS)}); add format = \"csv\" | \"whitespace\" | \"parquet\" | "
            "\"ulog\" | \"mat\""
        )
    return _EXTENSIONS[ext]


def check_data_path(path: Path, fmt: str | None = None) -> None:
    """The data file must exist, be a file and (text) not be empty; the message says what to fix."""
    if not path.exists():
        here = [q.name for q in path.parent.iterdir()] if path.parent.is_dir() else []
        near = did_you_mean(path.name, here)
        raise DataError(f"{path}: no such data file{near}"
                        + "; check path under its [[files]] entry: paths are relative to the problem "
                        "file's folder")
    if path.is_dir():
        inside = sorted(q.name for q in path.iterdir() if q.suffix.lower() in _EXTENSIONS)[:10]
        raise DataError(f"{path}: is a directory (a folder), not a data file; give the file's path under "
                        "its [[files]] entry" + (f" (data files in it: {inside})" if inside else ""))
    if fmt != "parquet" and path.stat().st_size == 0:
        raise DataError(f"{path}: the file is empty (0 bytes); check that path names the right file, or "
                        "export the data again")


def read_table(path: Path, fmt: str, header: bool | None = True, delimiter: str | None = None,
               skip_rows: int = 0, named_columns: Sequence[str] = (), encoding: str | None = None,
               decimal: str | None = None) -> pd.DataFrame:
    """Read a whole data file.

    Parameters
    ----------
    path : the file, already checked with :func:`check_data_path` (the problem-file reader does
        that before it infers the format from the extension, so that a missing file or a folder
        is named as such).
    fmt : one of :data:`FORMATS`.
    header : text formats: the first line (after ``skip_rows``) names the columns (None: the
        default, True). Without a header the columns are numbered 0, 1, 2, ... A header is checked
        against the first line (:func:`first_line_kind`): a first line of numbers is data, read as
        such with a :class:`DataWarning` when every column is taken by index, an error naming the
        fix when some are taken by name; a first line of names read with ``header = false`` is an
        error.
    delimiter : csv only: the field separator (default ``,``).
    skip_rows : text formats: lines to skip before the header (or the data).
    named_columns : the source columns the problem takes by name (for the header check).
    encoding : text formats: the file's text encoding (default UTF-8).
    decimal : text formats: the decimal mark (default ``.``; ``,`` for a European export).

    Returns
    -------
    The table; columns are named by the header (stripped of blanks) or numbered from 0. Header
    names that occur more than once are in ``df.attrs["duplicate_names"]`` (name -> indices).
    """
    explicit = header is not None
    header = True if header is None else header
    sep = r"\s+" if fmt == "whitespace" else (delimiter or ",")
    names: list[str] = []
    try:
        if fmt == "parquet":
            df = pq.read_table(path).to_pandas()
        else:
            header, names = _check_header(path, fmt, sep, header, explicit, skip_rows, named_columns,
                                          encoding)
            df = pd.read_csv(path, sep=sep, header=0 if header else None, skiprows=skip_rows,
                             skipinitialspace=True, engine="python" if fmt == "whitespace" else "c",
                             encoding=encoding or "utf-8", decimal=decimal or ".")
    except DataError:
        raise
    except UnicodeError as exc:
        raise DataError(_encoding_message(path, encoding, exc)) from None
    except (OSError, ValueError, pd.errors.ParserError) as exc:
        hint = "" if fmt == "parquet" else _layout_hint(path, fmt, delimiter, skip_rows, encoding)
        raise DataError(f"{path}: cannot read it as {fmt}: {str(exc).strip()}; "
                        + (hint or "check format, header, delimiter and skip_rows under its [[files]] "
                           "entry")) from None
    if header or fmt == "parquet":
        df.columns = [str(c).strip() for c in df.columns]
    if fmt == "csv" and df.shape[1] == 1:
        hint = _layout_hint(path, fmt, delimiter, skip_rows, encoding)
        if hint:
            raise DataError(f"{path}: every line reads as a single column; {hint}")
    if header and names:
        stripped = [n.strip() for n in names]
        df.attrs["duplicate_names"] = {n: [i for i, m in enumerate(stripped) if m == n]
                                       for n in set(stripped) if n and stripped.count(n) > 1}
    if len(df) == 0:
        raise DataError(f"{path}: no data rows" + (" after the header line" if header else "")
                        + "; check that path names the right file"
                        + (f" and that skip_rows = {skip_rows} is right" if skip_rows else ""))
    return df


#: Field separators a text export may use instead of the declared one.
_SEPARATORS = {",": "\",\"", ";": "\";\"", "\t": "\"\\t\"", "|": "\"|\""}


def _layout_hint(path: Path, fmt: str, delimiter: str | None, skip_rows: int,
                 encoding: str | None) -> str:
    """What to set when a text file does not parse as declared: the delimiter its lines use (and
    a decimal comma), or the number of title lines before the table (the lines before the first
    one with the usual field count)."""
    try:
        with open(path, encoding=encoding or "utf-8", errors="replace", newline="") as fh:
            lines = [line.rstrip("\r\n") for _, line in zip(range(200), fh, strict=False)]
    except OSError:
        return ""
    body = [ln for ln in lines[skip_rows:] if ln.strip()]
    if not body:
        return ""
    hints = []
    sep = delimiter or ","
    if fmt == "csv":
        tail = body[len(body) // 4:]  # the table, past any title lines

        def steady(s: str) -> bool:
            counts = {ln.count(s) for ln in tail}
            return len(counts) == 1 and min(counts) > 0

        other = next((s for s in _SEPARATORS if s != sep and steady(s)
                      and (not steady(sep) or sep not in body[0])), None)
        if other is not None:
            hints.append(f"its lines are separated by {_SEPARATORS[other]}: set delimiter = "
                         f"{_SEPARATORS[other]}")
            if other != "," and any(re.search(r"\d,\d", ln) for ln in tail):
                hints.append("its numbers have a decimal comma: set decimal = \",\" too")
            sep = other
        fields = [len(next(csv.reader([ln], delimiter=sep))) if ln.strip() else 0 for ln in lines]
    else:
        fields = [len(ln.split()) for ln in lines]
    used = [f for f in fields if f]
    usual = max(set(used), key=used.count)
    first = next(i for i, f in enumerate(fields) if f == usual)
    if first > skip_rows:
        hints.append(f"the table starts at line {first + 1} ({usual} fields; the lines before it "
                     f"have {sorted(set(fields[:first]) - {0})}): set skip_rows = {first}")
    return "; ".join(hints)


def _encoding_message(path: Path, encoding: str | None, exc: UnicodeError) -> str:
    with open(path, "rb") as fh:
        head = fh.read(4)
    guess = ("utf-16" if head[:2] in (b"\xff\xfe", b"\xfe\xff") else
             "latin-1" if (encoding or "utf-8").replace("-", "").lower() == "utf8" else "utf-8")
    return (f"{path}: cannot decode it as {encoding or 'UTF-8'} text ({exc.reason} at byte "
            f"{getattr(exc, 'start', '?')}); give its encoding under this [[files]] entry, e.g. "
            f"encoding = \"{guess}\" (common: \"utf-8\", \"latin-1\", \"cp1252\", \"utf-16\")")


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def first_line_kind(cells: Sequence[str]) -> str:
    """``"numbers"`` if every non-empty cell of a line parses as a number, ``"names"`` if none
    does, else ``"mixed"`` (also for an empty line)."""
    full = [c.strip() for c in cells if c.strip()]
    numbers = sum(_is_number(c) for c in full)
    if full and numbers == len(full):
        return "numbers"
    return "names" if full and numbers == 0 else "mixed"


def _check_header(path: Path, fmt: str, sep: str, header: bool, explicit: bool, skip_rows: int,
                  named_columns: Sequence[str], encoding: str | None) -> tuple[bool, list[str]]:
    """Whether the file is to be read with a header, after checking the first lines against it,
    and the first line's cells."""
    try:
        head = pd.read_csv(path, sep=sep, header=None, skiprows=skip_rows, nrows=3, dtype=str,
                           skipinitialspace=True, keep_default_na=False, encoding=encoding or "utf-8",
                           engine="python" if fmt == "whitespace" else "c")
    except UnicodeError:
        raise
    except (ValueError, pd.errors.ParserError):
        return header, []  # ragged first lines: the full read says what is wrong, if anything
    if len(head) == 0:
        return header, []
    first = [str(c) for c in head.iloc[0]]
    second = first_line_kind([str(c) for c in head.iloc[1]]) if len(head) > 1 else "mixed"
    kind = first_line_kind(first)
    shown = ", ".join(first[:6]) + (", ..." if len(first) > 6 else "")
    line = "the first line" + (f" after skip_rows = {skip_rows}" if skip_rows else "")
    given = "header = true" + ("" if explicit else " (the default)")
    if header and kind == "numbers":
        if named_columns:
            raise DataError(
                f"{path}: read with {given}, but {line} is numbers ({shown}), not column names: "
                f"the file has no header, so columns {list(named_columns)[:5]} cannot be found by "
                "name. Set header = false under its [[files]] entry and give each column under "
                "[columns] by its 0-based column index (e.g. t = { column = 0, unit = \"s\" })"
            )
        warn(f"{path}: read with {given}, but {line} is numbers ({shown}), not column names: it is "
             "read as the first data row (every column is taken by index). Set header = false under "
             "its [[files]] entry to say so")
        return False, first
    if header and len(head) > 2 and first_line_kind([str(c) for c in head.iloc[2]]) == "numbers":
        cells = [str(c).strip() for c in head.iloc[1] if str(c).strip()]
        if cells and sum(not _is_number(c) for c in cells) > len(cells) / 2:
            shown2 = ", ".join(cells[:6]) + (", ..." if len(cells) > 6 else "")
            raise DataError(
                f"{path}: the line after the header holds text ({shown2}), not numbers, and the "
                "data start on the next one: a units row? Remove that line from the file (the units "
                "are declared under [columns])"
            )
    if not header and kind == "names" and second == "numbers":
        raise DataError(
            f"{path}: read with header = false, but {line} looks like column names ({shown}) and the "
            "next one is numbers: set header = true (the default) to read it as the header, or "
            f"skip_rows = {skip_rows + 1} to skip it"
        )
    return header, first


def pick_column(df: pd.DataFrame, source: str | int, canonical: str, path: Path, header: bool,
                taken: Iterable[str] = ()) -> pd.Series:
    """The source column for a canonical name, by name or by 0-based index.

    ``taken``: the file's columns mapped to other canonical names; a missing column's "did you
    mean" never offers one of them (following it would feed one sensor with another's data).

    Raises
    ------
    DataError
        If the file has no such column (the message lists the columns it has), or more than one
        column of that name.
    """
    if isinstance(source, bool) or not isinstance(source, (str, int)):
        raise DataError(f"{path}: column for {canonical} must be a name or a 0-based index, got {source!r}")
    if isinstance(source, int):
        if not 0 <= source < df.shape[1]:
            raise DataError(
                f"{path}: {canonical} is mapped to column index {source}, but the file has "
                f"{df.shape[1]} columns (indices 0 to {df.shape[1] - 1}); fix the index under [columns]"
            )
        return df.iloc[:, source]
    if not header and isinstance(df.columns[0], (int, np.integer)):
        raise DataError(
            f"{path}: {canonical} is mapped to column {source!r} by name, but the file is read "
            "without a header (header = false), so its columns have no names; give the 0-based "
            "column index instead, or set header = true"
        )
    twins = df.attrs.get("duplicate_names", {}).get(source)
    if twins:
        raise DataError(
            f"{path}: {len(twins)} columns are named {source!r} (0-based indices {twins}), and "
            f"{canonical} is mapped to that name under [columns]: which one is meant cannot be told. "
            f"Give the column by its index instead (column = {twins[0]}), or rename one in the file"
        )
    if source not in df.columns:
        shown = list(df.columns[:60]) + (["..."] if df.shape[1] > 60 else [])
        free = [str(c) for c in df.columns if str(c) not in set(taken)]
        # a name that differs only in case is the likeliest meaning; else the closest free one
        near = next((c for c in free if c.casefold() == str(source).casefold()), None) or close_match(
            source, free)
        raise DataError(
            f"{path}: no column {source!r} (mapped to {canonical} under [columns])"
            + (f"; did you mean {near!r}?" if near else "") + f"; the file has columns {shown}; fix "
            "the name, or mark the column optional = true if this file legitimately lacks it"
        )
    return df[source]


def numeric(series: pd.Series) -> tuple[np.ndarray, np.ndarray]:
    """Values as float, and a mask of cells that were present but not numbers (text, ``N/A``)."""
    if series.dtype == bool:
        return series.to_numpy(dtype=float), np.zeros(len(series), dtype=bool)
    if pd.api.types.is_numeric_dtype(series.dtype):
        return series.to_numpy(dtype=float, na_value=np.nan), np.zeros(len(series), dtype=bool)
    coerced = pd.to_numeric(series, errors="coerce")
    bad = coerced.isna().to_numpy() & series.notna().to_numpy()
    return coerced.to_numpy(dtype=float, na_value=np.nan), bad
