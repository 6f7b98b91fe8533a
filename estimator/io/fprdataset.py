"""Read datasets written by ``fpr fly`` (manifest.json + maneuvers/*.parquet) without ``synth``.

The estimator must run on real flight data alone, so this module reads the documented format
(docs/user-guide.md, "The dataset format") with json and pyarrow directly.
"""

from __future__ import annotations

import json
import math
import shlex
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq

from aircraft_models.schema import check
from estimator.io.errors import DataError

FORMAT = "fpr-dataset"
#: The manifest format of a testbed sortie (``fpr fly --sortie``): one flight, one time base.
SORTIE_FORMAT = "fpr-sortie"
MANIFEST = "manifest.json"
#: The format's own columns, which every dataset has (time, IMU, INS attitude, air data, gear):
#: dataset column -> canonical name. Everything is SI already; units follow the name suffix. Any
#: other measured column is known by its name less its unit suffix (:func:`canonical_name`:
#: ``<channel>_rad`` -> ``<channel>``): which of those a problem reads is the model set's to say
#: (its channels and the data signals their models use), never a list here.
FPR_COLUMNS: dict[str, str] = {
    "t_s": "t",
    "ax_imu_mps2": "ax", "ay_imu_mps2": "ay", "az_imu_mps2": "az",
    "p_rps": "p", "q_rps": "q", "r_rps": "r",
    "phi_rad": "phi", "theta_rad": "theta", "psi_rad": "psi",
    "tas_mps": "tas", "h_baro_m": "h", "h_dgps_m": "h_dgps",
    "gear_down": "gear", "mach": "mach",
}
#: Columns of the truth (synthetic datasets): never read as data.
TRUTH_PREFIX = "true_"
_SUFFIX_UNITS = (("_mps2", "m/s^2"), ("_rps", "rad/s"), ("_rad", "rad"), ("_mps", "m/s"), ("_m", "m"),
                 ("_s", "s"))
#: Keys of a ``select`` table.
SELECT_KEYS = ("kind", "configuration", "aircraft", "mach_min", "mach_max", "gear_down", "ids")


def column_unit(column: str) -> str:
    """SI unit of a dataset column from its name suffix (``gear_down`` and ``mach``: "1")."""
    for suffix, unit in _SUFFIX_UNITS:
        if column.endswith(suffix):
            return unit
    return "1"


def canonical_name(column: str) -> str:
    """The canonical name of a dataset column: the format's own (:data:`FPR_COLUMNS`), else the
    column's name less its unit suffix (``<channel>_rad`` -> ``<channel>``; no suffix: itself)."""
    if column in FPR_COLUMNS:
        return FPR_COLUMNS[column]
    for suffix, _ in _SUFFIX_UNITS:
        if column.endswith(suffix) and len(column) > len(suffix):
            return column[: -len(suffix)]
    return column


def dataset_columns(names: Iterable[str], available: Iterable[str]) -> dict[str, str]:
    """The columns of ``available`` to read as data: column -> canonical name.

    Parameters
    ----------
    names : canonical names wanted besides the format's own columns (a model set's channels and
        the data signals their models read).
    available : the dataset's columns (a maneuver file's, or a manifest entry's ``channel_units``).

    Returns
    -------
    The format's own columns present (in :data:`FPR_COLUMNS`' order), then every other non-truth
    column whose canonical name (:func:`canonical_name`) is one of ``names`` (in ``available``'s).
    """
    have, wanted = list(available), set(names)
    own = {c: FPR_COLUMNS[c] for c in FPR_COLUMNS if c in have}
    return own | {c: canonical_name(c) for c in have if c not in FPR_COLUMNS
                  and not c.startswith(TRUTH_PREFIX) and canonical_name(c) in wanted}


def dataset_column(canonical: str, available: Iterable[str]) -> str:
    """The column of ``available`` holding the canonical name ``canonical`` (the inverse of
    :func:`canonical_name`); ``canonical`` itself when none does."""
    return next((c for c in available if not c.startswith(TRUTH_PREFIX) and canonical_name(c) == canonical),
                canonical)


def read_manifest(path: str | Path) -> tuple[Path, dict]:
    """The dataset directory and its parsed manifest."""
    path = Path(path)
    if path.name == MANIFEST:
        path = path.parent
    mpath = path / MANIFEST
    if not mpath.exists():
        raise DataError(
            f"{mpath}: no manifest; a dataset written by `fpr fly` is a directory holding "
            f"{MANIFEST} and maneuvers/*.parquet. Check [data] dataset = ... (relative to the problem file)"
        )
    try:
        manifest = json.loads(mpath.read_text())
    except json.JSONDecodeError as exc:
        raise DataError(f"{mpath}: not valid JSON ({exc}); the dataset is damaged") from None
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        got = manifest.get("format") if isinstance(manifest, dict) else type(manifest).__name__
        if got == SORTIE_FORMAT:
            where = shlex.quote(str(path))
            raise DataError(f"{path}: a whole sortie, not a dataset of maneuvers: find its maneuvers "
                            f"first, then calibrate them: fpr maneuvers {where} --out found.toml; "
                            "fpr calibrate found.toml")
        raise DataError(f"{mpath}: format is {got!r}, expected {FORMAT!r}")
    if manifest.get("complete", True) is False:
        # `fpr fly` writes the manifest first, "complete": false, and says "complete": true when
        # the last maneuver is in; how far it got is fpr's to judge (`fpr show`), not the reader's
        where = shlex.quote(str(path))
        raise DataError(
            f"{path}: incomplete dataset: its manifest says \"complete\": false (`fpr fly` was "
            f"interrupted, or is still running); complete it with: fpr fly --resume --out {where} "
            f"(`fpr show {where}` says how far it got)")
    if not manifest.get("maneuvers"):
        raise DataError(f"{mpath}: the manifest lists no maneuvers")
    return path, manifest


def sortie_manifest(directory: Path) -> dict | None:
    """The parsed manifest of a sortie directory, else None (not a sortie)."""
    mpath = Path(directory) / MANIFEST
    if not mpath.is_file():
        return None
    try:
        manifest = json.loads(mpath.read_text())
    except json.JSONDecodeError as exc:
        raise DataError(f"{mpath}: not valid JSON ({exc}); the sortie is damaged") from None
    return manifest if isinstance(manifest, dict) and manifest.get("format") == SORTIE_FORMAT else None


def _as_list(v) -> list:
    return list(v) if isinstance(v, (list, tuple)) else [v]


def select_entries(manifest: Mapping, select: Mapping | None, where: str) -> list[dict]:
    """Manifest entries that pass every criterion of ``select``.

    Parameters
    ----------
    manifest : the parsed manifest.
    select : ``kind``, ``configuration``, ``aircraft``, ``ids`` (a value or a list each),
        ``mach_min``, ``mach_max`` (on the entry's ``mach_mean``), ``gear_down`` (bool).
    where : for messages.
    """
    entries = list(manifest["maneuvers"])
    select = check(select or {}, SELECT_KEYS, where, DataError, what="select key")
    for key, field in (("kind", "kind"), ("configuration", "configuration"), ("aircraft", "aircraft"),
                       ("ids", "id")):
        if key in select:
            wanted = [str(x) for x in _as_list(select[key])]
            have = sorted({str(e.get(field)) for e in manifest["maneuvers"]})
            missing = [w for w in wanted if w not in have]
            if missing:
                shown = have if len(have) <= 30 else have[:30] + ["..."]
                raise DataError(
                    f"{where}: select {key} = {missing} matches nothing in the dataset; it has {shown}"
                )
            entries = [e for e in entries if str(e.get(field)) in wanted]
    lo = float(select.get("mach_min", -math.inf))
    hi = float(select.get("mach_max", math.inf))
    entries = [e for e in entries if lo <= float(e.get("mach_mean", np.nan)) <= hi
               or (lo == -math.inf and hi == math.inf)]
    if "gear_down" in select:
        entries = [e for e in entries if bool(e.get("gear_down")) == bool(select["gear_down"])]
    if not entries:
        raise DataError(
            f"{where}: the selection {select} leaves no maneuvers (the dataset has "
            f"{len(manifest['maneuvers'])}); widen it"
        )
    return entries


def read_maneuver(directory: Path, entry: Mapping, names: Iterable[str]) -> pd.DataFrame:
    """The data columns of one maneuver, by their names in the file: the format's own and those
    holding the canonical ``names`` (:func:`dataset_columns`)."""
    path = directory / entry["file"]
    if not path.exists():
        raise DataError(f"{path}: maneuver {entry['id']} listed in the manifest but its file is missing")
    wanted = dataset_columns(names, pq.read_schema(path).names)
    return pq.read_table(path, columns=list(wanted)).to_pandas()


def dataset_sensors(manifest: Mapping) -> dict[str, np.ndarray]:
    """Sensor positions from the manifest's airframe (a model set's midpoint sensors are added when
    the problem is built: :func:`~estimator.io.modelset.sensor_positions`)."""
    table = manifest.get("airframe", {}).get("positions_body_m", {})
    return {k: np.asarray(v, dtype=float) for k, v in table.items()}


def load_truth(problem_or_dataset, maneuver_id: str) -> pd.DataFrame:
    """The truth of one maneuver of a dataset: ``t_s`` and every ``true_*`` column.

    Parameters
    ----------
    problem_or_dataset : a :class:`~estimator.problem.Problem` whose maneuvers came from a
        dataset (their ``meta`` holds ``dataset`` and ``file``), or a dataset directory.
    maneuver_id : the maneuver id (manifest ``id``).
    """
    if isinstance(problem_or_dataset, (str, Path)):
        directory, manifest = read_manifest(problem_or_dataset)
        entry = next((e for e in manifest["maneuvers"] if e["id"] == maneuver_id), None)
        if entry is None:
            raise DataError(f"{directory}: no maneuver {maneuver_id!r} in the manifest")
    else:
        man = {m.id: m for m in problem_or_dataset.maneuvers}
        if maneuver_id not in man:
            raise DataError(
                f"{problem_or_dataset.source}: no maneuver {maneuver_id!r} (have {sorted(man)[:20]})"
            )
        meta = man[maneuver_id].meta
        if "dataset" not in meta:
            raise DataError(
                f"{problem_or_dataset.source}: maneuver {maneuver_id} came from {man[maneuver_id].source}, "
                "not from an fpr dataset; only synthetic datasets carry the truth"
            )
        directory, entry = Path(meta["dataset"]), meta
    path = directory / entry["file"]
    names = [n for n in pq.read_schema(path).names if n == "t_s" or n.startswith("true_")]
    truth = pq.read_table(path, columns=names).to_pandas()
    if "sortie_window_s" in entry:  # a maneuver cut out of a whole sortie
        t0, t1 = entry["sortie_window_s"]
        truth = truth[(truth["t_s"] >= t0 - 1e-9) & (truth["t_s"] <= t1 + 1e-9)].reset_index(drop=True)
    return truth
