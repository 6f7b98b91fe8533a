"""Read flight-data files (CSV, whitespace-separated text, Parquet) and pick their columns.

The reader returns the raw table; :mod:`estimator.io.assemble` does units and checks.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq

from estimator.io.errors import DataError

FORMATS = ("csv", "whitespace", "parquet")
_EXTENSIONS = {".csv": "csv", ".txt": "whitespace", ".dat": "whitespace", ".asc": "whitespace",
               ".parquet": "parquet", ".pq": "parquet"}


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
            f"(known: {sorted(_EXTENSIONS)}); add format = \"csv\" | \"whitespace\" | \"parquet\""
        )
    return _EXTENSIONS[ext]


def read_table(path: Path, fmt: str, header: bool = True, delimiter: str | None = None,
               skip_rows: int = 0) -> pd.DataFrame:
    """Read a whole data file.

    Parameters
    ----------
    path : the file.
    fmt : one of :data:`FORMATS`.
    header : text formats: the first line (after ``skip_rows``) names the columns. Without a
        header the columns are numbered 0, 1, 2, ...
    delimiter : csv only: the field separator (default ``,``).
    skip_rows : text formats: lines to skip before the header (or the data).

    Returns
    -------
    The table; columns are named by the header (stripped of blanks) or numbered from 0.
    """
    if not path.exists():
        raise DataError(f"{path}: no such data file; paths in [[files]] are relative to the problem file")
    try:
        if fmt == "parquet":
            df = pq.read_table(path).to_pandas()
        else:
            sep = r"\s+" if fmt == "whitespace" else (delimiter or ",")
            df = pd.read_csv(path, sep=sep, header=0 if header else None, skiprows=skip_rows,
                             skipinitialspace=True, engine="python" if fmt == "whitespace" else "c")
    except (OSError, ValueError, pd.errors.ParserError) as exc:
        raise DataError(f"{path}: cannot read it as {fmt}: {exc}; check format/header/delimiter") from None
    if header or fmt == "parquet":
        df.columns = [str(c).strip() for c in df.columns]
    if len(df) == 0:
        raise DataError(f"{path}: no data rows")
    return df


def pick_column(df: pd.DataFrame, source: str | int, canonical: str, path: Path, header: bool) -> pd.Series:
    """The source column for a canonical name, by name or by 0-based index.

    Raises
    ------
    DataError
        If the file has no such column; the message lists the columns it has.
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
    if source not in df.columns:
        shown = list(df.columns[:60]) + (["..."] if df.shape[1] > 60 else [])
        raise DataError(
            f"{path}: no column {source!r} (mapped to {canonical} under [columns]); the file has "
            f"columns {shown}; fix the name, or mark the column optional = true if this file "
            "legitimately lacks it"
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
