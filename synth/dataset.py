"""The flight-test dataset format: one directory per campaign, Parquet per maneuver, a manifest.

Layout::

    CAMPAIGN_DIR/
        manifest.json          what was flown, on which aircraft, every injected value, seeds,
                               software versions
        maneuvers/
            m0000.parquet      one maneuver: column ``t_s`` (s, common time base), the measured
            m0001.parquet      channels (``alpha_zl_rad``, ``q_rps``, ...) and the truth
            ...                channels (prefix ``true_``), SI units, names end in their unit

The manifest is JSON (``format = "fpr-dataset"``, ``format_version = 1``). Its ``maneuvers`` list
has one entry per Parquet file with: ``id``, ``file``, ``configuration``, ``aircraft``,
``nose_sensor``, ``kind``, ``segment``, ``mach_nominal``, ``mach_mean``, ``mach_min``,
``mach_max``, ``altitude_m``, ``gear_down``, ``duration_s``, ``n_samples``, ``sample_rate_hz``,
``r_cg_body_m_mean``, ``g_mps2_mean`` (gravity JSBSim used), ``environment``, ``injected``
(every injected error value, SI), ``channel_units`` and ``own_rate_columns`` (measured columns
kept at their recorder's own, slower samples: empty between them, e.g. the 10 Hz DGPS height on a
40 Hz base). The same entry is stored in each
Parquet file's key-value metadata under ``fpr.maneuver`` so a single file stays self-describing.

Files are written to a temporary name and renamed into place, so an interrupted run never leaves
a truncated file behind; an existing dataset is never overwritten unless asked.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

FORMAT = "fpr-dataset"
FORMAT_VERSION = 1
MANIFEST = "manifest.json"
METADATA_KEY = b"fpr.maneuver"


def _jsonable(obj):
    """Convert numpy scalars/arrays and tuples in ``obj`` to plain JSON types."""
    if isinstance(obj, Mapping):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def _atomic_write_bytes(path: Path, payload: bytes) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(payload)
        # mkstemp makes the file private (0600); a dataset file gets the usual permissions
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_maneuver(path: Path, data: pd.DataFrame, entry: Mapping) -> None:
    """Write one maneuver's table atomically, its manifest entry in the file metadata.

    Parameters
    ----------
    path : target ``.parquet`` file.
    data : the maneuver's channels, column ``t_s`` first.
    entry : the maneuver's manifest entry (JSON-serialisable after :func:`_jsonable`).
    """
    table = pa.Table.from_pandas(data, preserve_index=False)
    meta = dict(table.schema.metadata or {})
    meta[METADATA_KEY] = json.dumps(_jsonable(entry), sort_keys=True).encode()
    table = table.replace_schema_metadata(meta)
    sink = pa.BufferOutputStream()
    # no statistics-dependent or time-dependent fields: the same data give the same bytes
    pq.write_table(table, sink, compression="zstd", write_statistics=False)
    _atomic_write_bytes(path, sink.getvalue().to_pybytes())


def write_manifest(directory: Path, manifest: Mapping) -> Path:
    """Write ``manifest.json`` atomically; returns its path."""
    path = Path(directory) / MANIFEST
    text = json.dumps(_jsonable(manifest), indent=1, sort_keys=True) + "\n"
    _atomic_write_bytes(path, text.encode())
    return path


def prepare_directory(directory: Path, overwrite: bool = False) -> Path:
    """Create a campaign directory, refusing to clobber an existing dataset.

    Raises
    ------
    FileExistsError
        If ``directory`` already holds files and ``overwrite`` is false.
    """
    directory = Path(directory)
    if directory.exists() and any(directory.iterdir()):
        if not overwrite:
            raise FileExistsError(
                f"{directory}: directory exists and is not empty; choose another --out or pass "
                "--overwrite to replace it (its current contents will be deleted)"
            )
        try:
            is_dataset = json.loads((directory / MANIFEST).read_text()).get("format") == FORMAT
        except (OSError, ValueError):
            is_dataset = False
        if not is_dataset:
            raise FileExistsError(
                f"{directory}: not an fpr dataset (no {MANIFEST} of format {FORMAT!r}); refusing to "
                "delete it even with --overwrite. Choose an empty or new directory."
            )
        shutil.rmtree(directory)
    (directory / "maneuvers").mkdir(parents=True, exist_ok=True)
    return directory


@dataclass(frozen=True)
class Dataset:
    """A campaign directory opened for reading.

    Attributes
    ----------
    path : campaign directory.
    manifest : the parsed ``manifest.json``.
    """

    path: Path
    manifest: dict

    @property
    def index(self) -> pd.DataFrame:
        """One row per maneuver: id, configuration, aircraft, kind, Mach, gear, duration, file."""
        cols = [
            "id", "configuration", "aircraft", "nose_sensor", "kind", "segment", "mach_nominal",
            "mach_mean", "mach_min", "mach_max", "altitude_m", "gear_down", "duration_s",
            "n_samples", "file",
        ]
        rows = [{c: m.get(c) for c in cols} for m in self.manifest["maneuvers"]]
        return pd.DataFrame(rows, columns=cols).set_index("id")

    def entry(self, maneuver_id: str) -> dict:
        for m in self.manifest["maneuvers"]:
            if m["id"] == maneuver_id:
                return m
        raise KeyError(
            f"{self.path}: no maneuver {maneuver_id!r}; the manifest lists "
            f"{len(self.manifest['maneuvers'])} (see Dataset.index)"
        )

    def load(self, maneuver_id: str) -> pd.DataFrame:
        """The maneuver's channels as a DataFrame (column ``t_s`` plus channels)."""
        return pd.read_parquet(self.path / self.entry(maneuver_id)["file"])

    def __iter__(self) -> Iterator[tuple[dict, pd.DataFrame]]:
        for m in self.manifest["maneuvers"]:
            yield m, pd.read_parquet(self.path / m["file"])

    def __len__(self) -> int:
        return len(self.manifest["maneuvers"])


def load_dataset(path: str | Path) -> Dataset:
    """Open a campaign directory written by ``fpr fly``.

    Parameters
    ----------
    path : the campaign directory (or its ``manifest.json``).
    """
    path = Path(path)
    if path.name == MANIFEST:
        path = path.parent
    mpath = path / MANIFEST
    if not mpath.exists():
        raise FileNotFoundError(
            f"{mpath}: no manifest; is {path} a dataset written by `fpr fly`? "
            "A dataset directory holds manifest.json and maneuvers/*.parquet"
        )
    manifest = json.loads(mpath.read_text())
    if manifest.get("format") != FORMAT:
        raise ValueError(f"{mpath}: format is {manifest.get('format')!r}, expected {FORMAT!r}")
    if manifest.get("format_version", 0) > FORMAT_VERSION:
        raise ValueError(
            f"{mpath}: format_version {manifest['format_version']} is newer than this software "
            f"reads ({FORMAT_VERSION}); upgrade fpr-testbed"
        )
    missing = [m["file"] for m in manifest.get("maneuvers", []) if not (path / m["file"]).exists()]
    if missing:
        raise FileNotFoundError(
            f"{path}: the manifest lists {len(missing)} maneuver file(s) that are missing, e.g. "
            f"{missing[0]}; the dataset is incomplete (re-run `fpr fly` into a new directory)"
        )
    return Dataset(path=path, manifest=manifest)


def read_maneuver_metadata(path: str | Path) -> dict:
    """The manifest entry stored inside one maneuver's Parquet file."""
    meta = pq.read_schema(path).metadata or {}
    if METADATA_KEY not in meta:
        raise ValueError(f"{path}: no fpr.maneuver metadata; not written by fpr")
    return json.loads(meta[METADATA_KEY])
