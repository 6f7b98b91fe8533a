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
40 Hz base); :func:`manifest_entry` builds it, :func:`maneuver_id` names the maneuver and
:func:`maneuver_key` gives its seed key. The same entry is stored in each Parquet file's key-value
metadata under ``fpr.maneuver`` so a single file stays self-describing.

The manifest is written first, before any maneuver, with ``complete = false``, the campaign
definition and the planned ``jobs`` (each with the ``files`` it will write); it is rewritten with
``complete = true`` and the ``maneuvers`` entries when the last maneuver is in. Files are written to a
temporary name and renamed into place, so a present maneuver file is a whole one: at every moment the
dataset says whether it is complete and which jobs are done (:func:`dataset_status`), and an
interrupted one can be completed (``fpr fly --resume``). A manifest without ``complete`` (written
before that key existed) is a complete dataset.

A directory is only ever cleared of what the tool wrote there (:func:`prepare_directory`):
``manifest.json``, the maneuver files its manifest names (``maneuvers/mNNNN[sK].parquet``) and the
tool's own temporary files; a directory holding anything else is refused, the message listing it.

A whole sortie (``fpr fly --sortie``, :mod:`synth.sortie`) is a directory of its own, format
``fpr-sortie``: ``manifest.json`` (its ``sortie`` block: configuration, injected errors, the
maneuver ``boundaries`` and the ``transitions``), ``sortie.parquet`` (the common time base with the
truth, as a maneuver file has it), ``streams/{dru,ins,dgps}.parquet`` (each recorder's raw stream,
``t_s`` its stamps) and ``boundaries.csv``; :func:`write_sortie` writes it, :func:`load_sortie`
reads it and :meth:`Sortie.cut` cuts a maneuver out by its boundaries.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

if TYPE_CHECKING:  # annotations only: the format module imports nothing that flies or instruments
    from aircraft_models import Airframe, Configuration
    from synth.environment import Environment
    from synth.instrument import InstrumentedManeuver
    from synth.maneuvers import ManeuverSpec
    from synth.truth import TruthTrajectory

FORMAT = "fpr-dataset"
FORMAT_VERSION = 1
MANIFEST = "manifest.json"
METADATA_KEY = b"fpr.maneuver"
#: The maneuver files the tool writes, relative to the dataset directory (job index, SHSS segment).
MANEUVER_FILE_RE = re.compile(r"maneuvers/m\d{4,}(?:s\d+)?\.parquet")
#: The tool's temporary files (:func:`atomic_write_bytes`: ``.NAME.RANDOM.tmp`` beside ``NAME``).
_TEMP_RE = re.compile(r"\.(?:m\d{4,}(?:s\d+)?\.parquet|manifest\.json)\.[A-Za-z0-9_]+\.tmp")
#: Names shown in a refusal before "and N more".
_MAX_SHOWN = 12
#: Seed keys per job (:func:`maneuver_key`): far more segments than any maneuver has (an SHSS
#: run of at most 300 s in pieces of at least 25 s has 12).
SEGMENTS_PER_JOB = 64


class IncompleteDatasetError(ValueError):
    """A dataset whose `fpr fly` was interrupted: the message says how much is there and how to
    complete it."""


def _jsonable(obj):
    """Convert numpy scalars/arrays and tuples in ``obj`` to plain JSON types."""
    if isinstance(obj, Mapping):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        # through _jsonable again: a numpy NaN becomes None like a Python one, so an entry read back
        # from a Parquet file's metadata gives the same manifest bytes as the entry itself
        return _jsonable(obj.item())
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def atomic_write_bytes(path: Path, payload: bytes) -> None:
    """Write ``payload`` to ``path`` through a temporary file beside it (``.NAME.RANDOM.tmp``) and an
    atomic rename: a reader or a killed run never sees half a file. Permissions follow the umask."""
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
    atomic_write_bytes(path, sink.getvalue().to_pybytes())


def write_manifest(directory: Path, manifest: Mapping) -> Path:
    """Write ``manifest.json`` atomically; returns its path."""
    path = Path(directory) / MANIFEST
    text = json.dumps(_jsonable(manifest), indent=1, sort_keys=True) + "\n"
    atomic_write_bytes(path, text.encode())
    return path


def maneuver_key(job_index: int, segment: int) -> int:
    """The seed key of one recorded maneuver: ``job_index * 64 + segment``.

    Every random draw of channel ``c`` of the maneuver uses ``default_rng([source seed, key, c])``
    (:func:`synth.errors.channel_rng`), so a maneuver's noise does not depend on which other
    maneuvers are flown, nor on the number of workers.

    Parameters
    ----------
    job_index : the maneuver's index in its campaign (file order, from 0).
    segment : the recorded piece of the maneuver (0 except for the SHSS pieces), 0-63.

    Raises
    ------
    ValueError
        If ``job_index`` is negative or ``segment`` is outside 0-63 (two maneuvers would share a key).
    """
    if job_index < 0:
        raise ValueError(f"maneuver_key: job index {job_index} is negative; a campaign numbers its "
                         "maneuvers from 0 in file order")
    if not 0 <= segment < SEGMENTS_PER_JOB:
        raise ValueError(f"maneuver_key: segment {segment} of job {job_index} is outside "
                         f"0-{SEGMENTS_PER_JOB - 1}: the seed layout job_index * {SEGMENTS_PER_JOB} + "
                         f"segment has {SEGMENTS_PER_JOB} keys per job; record the maneuver in fewer "
                         "pieces (SHSS: a longer segment_s)")
    return job_index * SEGMENTS_PER_JOB + segment


def maneuver_id(job_index: int, segment: int, n_segments: int) -> str:
    """The id of one recorded maneuver: ``m0004`` (one piece) or ``m0004s1`` (piece 1 of several)."""
    return f"m{job_index:04d}" + (f"s{segment}" if n_segments > 1 else "")


def maneuver_file(maneuver_id: str) -> str:
    """The maneuver's file, relative to the dataset directory (:data:`MANEUVER_FILE_RE`)."""
    return f"maneuvers/{maneuver_id}.parquet"


def airframe_manifest(airframe: Airframe) -> dict:
    """The manifest's ``airframe`` block: name, JSBSim model, reference point, sensor positions."""
    return {
        "name": airframe.name,
        "jsbsim_model": airframe.jsbsim_model,
        "reference_point": airframe.reference_point,
        "positions_body_m": {k: v.tolist() for k, v in airframe.positions_body_m.items()},
    }


@dataclass(frozen=True)
class RecordedPiece:
    """One recorded maneuver piece, everything its manifest entry is made of.

    Attributes
    ----------
    job_index, segment, n_segments : the maneuver's job, its piece and the job's number of pieces.
    configuration : the aircraft configuration flown (:class:`aircraft_models.Configuration`).
    spec, environment : what was flown, in which air.
    truth : the piece's truth (:class:`synth.truth.TruthTrajectory`).
    instrumented : its recorded channels (:func:`synth.instrument.instrument`).
    sample_rate_hz : the dataset's common time base, Hz.
    """

    job_index: int
    segment: int
    n_segments: int
    configuration: Configuration
    spec: ManeuverSpec
    environment: Environment
    truth: TruthTrajectory
    instrumented: InstrumentedManeuver
    sample_rate_hz: float

    def manifest_entry(self) -> dict:
        """The piece's manifest entry (the keys listed in this module's docstring)."""
        configuration, spec, truth = self.configuration, self.spec, self.truth
        mid = maneuver_id(self.job_index, self.segment, self.n_segments)
        data = self.instrumented.data
        mach = truth.mach
        return {
            "id": mid,
            "file": maneuver_file(mid),
            "job_index": self.job_index,
            "configuration": configuration.id,
            "aircraft": configuration.aircraft.id,
            "nose_sensor": configuration.nose_sensor,
            "sensors": list(configuration.sensors),
            "kind": spec.kind,
            "segment": self.segment,
            "n_segments": self.n_segments,
            "mach_nominal": spec.mach,
            "mach_mean": float(np.mean(mach)),
            "mach_min": float(np.min(mach)),
            "mach_max": float(np.max(mach)),
            "altitude_m": spec.altitude_m,
            "gear_down": bool(spec.gear_down),
            "duration_s": float(data["t_s"].iloc[-1] - data["t_s"].iloc[0]),
            "n_samples": int(len(data)),
            "sample_rate_hz": self.sample_rate_hz,
            "r_cg_body_m_mean": np.mean(truth.r_cg_body_m, axis=0).tolist(),
            "g_mps2_mean": float(np.mean(truth.g_mps2)),
            "maneuver": spec.to_dict(),
            "environment": self.environment.to_dict(),
            "injected": self.instrumented.injected,
            "channel_units": self.instrumented.channel_units,
            "own_rate_columns": list(self.instrumented.own_rate_columns),
            "flight_meta": {k: v for k, v in truth.meta.items() if k != "spec"},
        }


def manifest_entry(**piece) -> dict:
    """The manifest entry of one recorded maneuver: ``piece`` are :class:`RecordedPiece`'s fields,
    by keyword (an unknown or missing one is a TypeError)."""
    return RecordedPiece(**piece).manifest_entry()


def resume_command(directory: str | Path) -> str:
    """The shell command that completes the interrupted dataset at ``directory``."""
    return f"fpr fly --resume --out {shlex.quote(str(directory))}"


def read_manifest_if_dataset(directory: str | Path) -> dict | None:
    """The parsed manifest of an fpr dataset at ``directory`` (complete or not), else None."""
    return _read_manifest_of_format(directory, FORMAT)


def _read_manifest_of_format(directory: str | Path, fmt: str) -> dict | None:
    """The parsed ``manifest.json`` at ``directory`` if it is of format ``fmt``, else None."""
    try:
        manifest = json.loads((Path(directory) / MANIFEST).read_text())
    except (OSError, ValueError):
        return None
    return manifest if isinstance(manifest, dict) and manifest.get("format") == fmt else None


def planned_files(manifest: Mapping) -> list[str]:
    """Every maneuver file a dataset's manifest says the tool writes (planned jobs and entries),
    relative to the dataset directory; names outside the tool's own pattern are never included."""
    names: list[str] = []
    for job in manifest.get("jobs") or []:
        if isinstance(job, Mapping) and isinstance(job.get("files"), list):
            names.extend(job["files"])
    for entry in manifest.get("maneuvers") or []:
        if isinstance(entry, Mapping):
            names.append(entry.get("file"))
    return list(dict.fromkeys(n for n in names if isinstance(n, str) and MANEUVER_FILE_RE.fullmatch(n)))


@dataclass(frozen=True)
class DatasetStatus:
    """How far a dataset is: planned jobs (maneuvers to fly) and those whose every file is there.

    Attributes
    ----------
    complete : the manifest says the run ended (``complete`` true or absent).
    n_jobs : planned jobs (for a manifest without ``jobs``: its maneuver entries).
    done : indices of the jobs whose every file is there and whole (atomic writes: a file is
        whole unless something else damaged it; its footer is read to make sure).
    damaged : (file, what is wrong) of each planned file that is there but is not a whole maneuver
        file of its job (unreadable, truncated, another job's, a link): its job is not done, and
        ``fpr fly --resume`` flies it again (the tool wrote that name).
    """

    complete: bool
    n_jobs: int
    done: tuple[int, ...]
    damaged: tuple[tuple[str, str], ...] = ()

    @property
    def n_done(self) -> int:
        return len(self.done)


def _file_state(directory: Path, rel: str, job_index: int) -> tuple[dict | None, str | None]:
    """(its manifest entry, None) when ``rel`` is a whole maneuver file of job ``job_index``;
    (None, what is wrong) when it is there but damaged; (None, None) when it is not there."""
    path = directory / rel
    if path.is_symlink():
        return None, "a link, not a file fpr fly wrote"
    if not path.exists():
        return None, None
    if not path.is_file():
        return None, "not a file"
    try:
        entry = read_maneuver_metadata(path)
    except (OSError, ValueError, pa.ArrowException) as exc:  # truncated, overwritten, foreign
        return None, str(exc).removeprefix(f"{path}: ").removesuffix("; the file is damaged")
    if entry.get("job_index") != job_index or entry.get("file") != rel:
        return None, (f"holds maneuver {entry.get('id')!r} of job {entry.get('job_index')}, "
                      f"not job {job_index}'s")
    return entry, None


def _edited(directory: Path, what: str) -> str:
    return (f"{directory / MANIFEST}: {what}: the manifest is not as `fpr fly` wrote it (edited or "
            f"damaged). Restore it, or move {directory} aside and fly the campaign again into a new "
            "--out")


def planned_jobs(directory: str | Path, manifest: Mapping) -> list[tuple[int, list[str]]]:
    """(job index, files) of every job an incomplete dataset's manifest plans.

    Raises
    ------
    ValueError
        Naming the manifest and the job, when one is not as `fpr fly` writes it (no ``files``
        list, no ``job_index``): a hand-edited or damaged manifest.
    """
    directory = Path(directory)
    jobs = manifest.get("jobs")
    if not isinstance(jobs, list):
        raise ValueError(_edited(directory, "its planned \"jobs\" are not a list"))
    out = []
    for k, job in enumerate(jobs):
        job = job if isinstance(job, Mapping) else {}
        index, files = job.get("job_index"), job.get("files")
        if not isinstance(index, int) or isinstance(index, bool):
            raise ValueError(_edited(directory, f"planned job {k} has no job_index"))
        if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
            raise ValueError(_edited(directory, f"planned job {k} (job_index {index}) has no list of "
                                                "\"files\""))
        out.append((index, files))
    return out


def damaged_manifest(directory: str | Path) -> str | None:
    """What is wrong with ``directory``'s ``manifest.json`` when it is there but cannot be read
    (truncated, not JSON), and what to do; None when it reads (or is not there)."""
    path = Path(directory) / MANIFEST
    if not path.is_file():
        return None
    try:
        json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        return (f"{path}: cannot be read ({exc}): the manifest is damaged, and the dataset's "
                f"campaign and progress are in it. Restore it (from a backup), or move {directory} "
                "aside and fly the campaign again into a new --out")
    return None


def job_entries(directory: str | Path, manifest: Mapping) -> tuple[dict[int, list[dict]],
                                                                 list[tuple[str, str]]]:
    """The finished jobs of a dataset with planned ``jobs`` (an incomplete one), read from their
    files, and the damaged files.

    Returns
    -------
    done : job index -> the manifest entries of its files (each file's own copy), for every job
        whose every file is there and whole.
    damaged : (file, what is wrong) of every planned file that is there but not whole
        (:class:`DatasetStatus`).
    """
    directory = Path(directory)
    done: dict[int, list[dict]] = {}
    damaged: list[tuple[str, str]] = []
    for index, files in planned_jobs(directory, manifest):
        entries = []
        for rel in files:
            if not MANEUVER_FILE_RE.fullmatch(rel):  # never a name outside the tool's own
                break
            entry, why = _file_state(directory, rel, index)
            if why is not None:
                damaged.append((rel, why))
            if entry is None:
                break
            entries.append(entry)
        else:
            done[index] = entries
    return done, damaged


def dataset_status(directory: str | Path, manifest: Mapping | None = None) -> DatasetStatus:
    """Whether the dataset at ``directory`` is complete, which planned jobs are done and which of
    their files are damaged (every present file's footer is read)."""
    directory = Path(directory)
    manifest = read_manifest_if_dataset(directory) if manifest is None else manifest
    if manifest is None:
        raise FileNotFoundError(
            f"{directory / MANIFEST}: no manifest of format {FORMAT!r}; is {directory} a dataset "
            "written by `fpr fly`?")
    complete = manifest.get("complete", True) is not False
    jobs = manifest.get("jobs")
    if jobs is None:  # a manifest written before planned jobs were recorded: always a complete run
        return DatasetStatus(complete, len(manifest.get("maneuvers", [])),
                             tuple(range(len(manifest.get("maneuvers", [])))))
    done, damaged = job_entries(directory, manifest)
    return DatasetStatus(complete, len(jobs), tuple(done), tuple(damaged))


def damaged_message(directory: str | Path, damaged: Sequence[tuple[str, str]]) -> str:
    """The damaged files of an incomplete dataset, named, and what the resume does with them."""
    shown = "; ".join(f"{Path(directory) / rel} ({why})" for rel, why in damaged[:_MAX_SHOWN])
    more = f"; ... and {len(damaged) - _MAX_SHOWN} more" if len(damaged) > _MAX_SHOWN else ""
    return (f"{len(damaged)} damaged maneuver file(s), not counted as written: {shown}{more}; "
            "`fpr fly --resume` flies them again (fpr fly wrote these names: they are replaced)")


def incomplete_message(directory: str | Path, status: DatasetStatus) -> str:
    """What an incomplete dataset is and how to complete it (for errors and `fpr show`)."""
    return (f"{directory}: incomplete dataset: {status.n_done} of {status.n_jobs} maneuvers written "
            "(`fpr fly` was interrupted, or is still running); complete it with: "
            f"{resume_command(directory)}"
            + (f". {damaged_message(directory, status.damaged)}" if status.damaged else ""))


def written_entries(directory: str | Path, manifest: Mapping) -> list[dict]:
    """The manifest entries of an incomplete dataset's finished jobs, read from their files (a
    damaged file's job is not finished: :func:`job_entries`)."""
    done, _ = job_entries(directory, manifest)
    return [e for index, _ in planned_jobs(directory, manifest) if index in done for e in done[index]]


def _listing(names: list[str]) -> str:
    shown = ", ".join(names[:_MAX_SHOWN])
    return shown + (f", ... and {len(names) - _MAX_SHOWN} more" if len(names) > _MAX_SHOWN else "")


def dataset_contents(directory: str | Path) -> tuple[list[Path], list[str]]:
    """Split a directory's contents into what `fpr fly` wrote there and everything else.

    Returns
    -------
    own : paths the tool wrote: ``manifest.json`` (of format ``fpr-dataset``), the maneuver files
        its manifest names, the tool's temporary files (not ``maneuvers/`` itself).
    foreign : everything else, relative names (a directory ends in ``/``). Without a dataset
        manifest everything is foreign but an empty ``maneuvers/``.
    """
    directory = Path(directory)
    manifest = read_manifest_if_dataset(directory)
    ours = set(planned_files(manifest)) if manifest is not None else set()
    own: list[Path] = []
    foreign: list[str] = []

    def plain_file(p: Path) -> bool:  # never follow a link or take a directory as the tool's file
        return p.is_file() and not p.is_symlink()

    for p in sorted(directory.iterdir()):
        if p.name == "maneuvers" and p.is_dir() and not p.is_symlink():
            for q in sorted(p.iterdir()):
                rel = f"maneuvers/{q.name}"
                if plain_file(q) and (rel in ours or (manifest is not None and _TEMP_RE.fullmatch(q.name))):
                    own.append(q)
                else:
                    foreign.append(rel + ("/" if q.is_dir() else ""))
        elif manifest is not None and plain_file(p) and (p.name == MANIFEST or _TEMP_RE.fullmatch(p.name)):
            own.append(p)
        else:
            foreign.append(p.name + ("/" if p.is_dir() else ""))
    return own, foreign


def remove_temp_files(directory: str | Path) -> None:
    """Remove the tool's temporary files left by a killed run (a dataset directory only)."""
    directory = Path(directory)
    if read_manifest_if_dataset(directory) is None:
        return
    for folder in (directory, directory / "maneuvers"):
        if folder.is_dir() and not folder.is_symlink():
            for p in folder.iterdir():
                if _TEMP_RE.fullmatch(p.name) and p.is_file() and not p.is_symlink():
                    p.unlink()


def check_directory(directory: Path, overwrite: bool = False) -> list[Path]:
    """The refusals of :func:`prepare_directory`, with nothing changed: the files it would remove
    (an earlier dataset's own, with ``overwrite``), so that a command writing several datasets can
    refuse before it writes any.

    Raises
    ------
    FileExistsError
        As :func:`prepare_directory`.
    """
    directory = Path(directory)
    if directory.exists() and not directory.is_dir():
        raise FileExistsError(
            f"{directory}: is a file, not a directory; --out names the dataset directory to create "
            "(a new or empty one)")
    if not (directory.is_dir() and any(directory.iterdir())):
        return []
    own, foreign = dataset_contents(directory)
    manifest = read_manifest_if_dataset(directory)
    if manifest is None:
        if foreign:
            raise FileExistsError(
                f"{directory}: not an fpr dataset (no {MANIFEST} of format {FORMAT!r}) and not "
                f"empty: it holds {_listing(foreign)}; refusing to write into it or delete "
                "anything, even with --overwrite. Choose an empty or new directory.")
    elif foreign:
        raise FileExistsError(
            f"{directory}: holds {len(foreign)} item(s) `fpr fly` did not write: "
            f"{_listing(foreign)}; refusing to touch them (--overwrite removes only a dataset's "
            "own files). Move them away or choose another --out.")
    elif not overwrite:
        status = dataset_status(directory, manifest)
        what = "a complete dataset" if status.complete else \
            f"an incomplete dataset ({status.n_done} of {status.n_jobs} maneuvers written)"
        raise FileExistsError(
            f"{directory}: holds {what}; pass --overwrite to replace it (only the dataset's own "
            "files are removed)" + ("" if status.complete else
                                     f", complete it with: {resume_command(directory)}")
            + ", or choose another --out")
    return own


def prepare_directory(directory: Path, overwrite: bool = False) -> Path:
    """Create a dataset directory (and its ``maneuvers/``), never touching a file the tool did not
    write.

    With ``overwrite``, an earlier dataset there is removed: exactly the files its manifest says
    the tool wrote (:func:`dataset_contents`), nothing else; the directory itself stays.

    Raises
    ------
    FileExistsError
        If ``directory`` is a file; if it holds a dataset and ``overwrite`` is false; if it holds
        anything the tool did not write (the message lists it), whatever ``overwrite``
        (:func:`check_directory`).
    """
    directory = Path(directory)
    own = check_directory(directory, overwrite)
    if own:
        # the manifest last: until the end the directory stays recognisably a dataset
        for p in sorted(own, key=lambda p: p.name == MANIFEST):
            p.unlink()
    try:
        (directory / "maneuvers").mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError) as exc:
        raise FileExistsError(
            f"{directory}: cannot create the dataset directory ({exc.strerror}: {exc.filename}); "
            "a part of the path is a file or maneuvers/ is not a directory. Choose another --out"
        ) from None
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


def copy_with_edits(base: str | Path, dest: str | Path, edits: Mapping) -> Path:
    """A copy of the dataset ``base`` at ``dest`` (which must not exist) with
    ``edits[maneuver id](DataFrame) -> DataFrame`` applied to its maneuver files, each manifest
    entry (also in the file's metadata) kept: a fault injected into a flown dataset."""
    import shutil

    dest = Path(dest)
    shutil.copytree(base, dest)
    ds = load_dataset(dest)
    for mid, edit in edits.items():
        entry = ds.entry(mid)
        write_maneuver(dest / entry["file"], edit(ds.load(mid)), entry)
    return dest


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
    try:
        manifest = json.loads(mpath.read_text())
    except ValueError as exc:
        raise ValueError(f"{mpath}: not valid JSON ({exc}); the manifest is damaged. Restore it (from a "
                         f"backup), or move {path} aside and fly the campaign again into a new --out"
                         ) from None
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        got = manifest.get("format") if isinstance(manifest, dict) else type(manifest).__name__
        hint = "; it is a whole sortie: open it with load_sortie" if got == SORTIE_FORMAT else ""
        raise ValueError(f"{mpath}: format is {got!r}, expected {FORMAT!r}{hint}")
    if manifest.get("format_version", 0) > FORMAT_VERSION:
        raise ValueError(
            f"{mpath}: format_version {manifest['format_version']} is newer than this software "
            f"reads ({FORMAT_VERSION}); upgrade fpr-testbed"
        )
    if manifest.get("complete", True) is False:
        raise IncompleteDatasetError(incomplete_message(path, dataset_status(path, manifest)))
    missing = [m["file"] for m in manifest.get("maneuvers", []) if not (path / m["file"]).exists()]
    if missing:
        raise FileNotFoundError(
            f"{path}: the manifest lists {len(missing)} maneuver file(s) that are missing, e.g. "
            f"{missing[0]}; the dataset is damaged (fly it again: `fpr fly ... --overwrite`)"
        )
    return Dataset(path=path, manifest=manifest)


def alpha_coverage(dataset: Dataset) -> pd.DataFrame:
    """The true angle of attack at the CG that each nominal Mach of ``dataset`` covers.

    Reads only the truth column ``true_alpha_cg_rad`` of each maneuver file.

    Returns
    -------
    One row per nominal Mach (index ``mach_nominal``, rounded to 0.01, ascending):
    ``n_maneuvers`` (files), ``alpha_min_deg`` and ``alpha_max_deg`` over all of them.
    """
    rows = []
    for m in dataset.manifest["maneuvers"]:
        alpha_rad = pd.read_parquet(dataset.path / m["file"], columns=["true_alpha_cg_rad"])
        a_deg = np.degrees(alpha_rad["true_alpha_cg_rad"].to_numpy())
        rows.append((round(float(m["mach_nominal"]), 2), float(a_deg.min()), float(a_deg.max())))
    per_file = pd.DataFrame(rows, columns=["mach_nominal", "alpha_min_deg", "alpha_max_deg"])
    return per_file.groupby("mach_nominal").agg(
        n_maneuvers=("alpha_min_deg", "size"), alpha_min_deg=("alpha_min_deg", "min"),
        alpha_max_deg=("alpha_max_deg", "max"))


def read_maneuver_metadata(path: str | Path) -> dict:
    """The manifest entry stored inside one maneuver's Parquet file.

    Raises
    ------
    ValueError
        Naming the file, when it is not a readable Parquet file (truncated, overwritten) or holds
        no entry of fpr's.
    """
    try:
        meta = pq.read_schema(path).metadata or {}
    except pa.ArrowException as exc:  # pyarrow's message does not name the file
        raise ValueError(f"{path}: not a readable Parquet file ({exc}); the file is damaged") from None
    if METADATA_KEY not in meta:
        raise ValueError(f"{path}: no fpr.maneuver metadata; not written by fpr")
    try:
        entry = json.loads(meta[METADATA_KEY])
    except ValueError as exc:
        raise ValueError(f"{path}: its fpr.maneuver metadata is not valid JSON ({exc}); the file "
                         "is damaged") from None
    if not isinstance(entry, dict):
        raise ValueError(f"{path}: its fpr.maneuver metadata is not an entry; the file is damaged")
    return entry


# ------------------------------------------------------------------ whole sorties

#: The manifest format of a whole-sortie dataset (``fpr fly --sortie``; :mod:`synth.sortie`).
SORTIE_FORMAT = "fpr-sortie"
SORTIE_FORMAT_VERSION = 1
#: Its files, relative to the directory: the preprocessed common time base (measured channels
#: and truth, as a maneuver file has them), each recorder's raw stream, the maneuver boundaries.
SORTIE_FILES = {
    "data": "sortie.parquet",
    "dru": "streams/dru.parquet",
    "ins": "streams/ins.parquet",
    "dgps": "streams/dgps.parquet",
    "boundaries": "boundaries.csv",
}
#: The columns of a sortie's boundary table, in order.
BOUNDARY_COLUMNS = ("id", "job_index", "segment", "kind", "mach", "altitude_m", "gear_down",
                    "t_start_s", "t_end_s", "missed", "t_excitation_start_s", "t_excitation_end_s")


def read_sortie_manifest(directory: str | Path) -> dict | None:
    """The parsed manifest of a whole-sortie dataset at ``directory``, else None."""
    return _read_manifest_of_format(directory, SORTIE_FORMAT)


def prepare_sortie_directory(directory: Path, overwrite: bool = False) -> Path:
    """Create a whole-sortie dataset directory; with ``overwrite``, remove an earlier sortie's own
    files (:data:`SORTIE_FILES` and the manifest) and nothing else.

    Raises
    ------
    FileExistsError
        If ``directory`` is a file, holds a sortie and ``overwrite`` is false, or holds anything
        else (listed), whatever ``overwrite``.
    """
    directory = Path(directory)
    if directory.exists() and not directory.is_dir():
        raise FileExistsError(f"{directory}: is a file, not a directory; --out names the sortie "
                              "directory to create (a new or empty one)")
    own = {directory / MANIFEST, *(directory / f for f in SORTIE_FILES.values())}
    if directory.is_dir():
        present = [p for p in directory.rglob("*") if not p.is_dir() or p.is_symlink()]
        foreign = sorted(str(p.relative_to(directory)) for p in present if p not in own)
        if foreign:
            raise FileExistsError(
                f"{directory}: holds {len(foreign)} item(s) a whole-sortie `fpr fly --sortie` did "
                f"not write: {_listing(foreign)}; refusing to touch them. Choose an empty or new --out")
        if present and read_sortie_manifest(directory) is None:
            raise FileExistsError(f"{directory}: not a whole-sortie dataset (no {MANIFEST} of format "
                                  f"{SORTIE_FORMAT!r}); choose an empty or new --out")
        if present and not overwrite:
            raise FileExistsError(f"{directory}: holds a whole-sortie dataset; pass --overwrite to "
                                  "replace it (only its own files are removed), or choose another --out")
        for p in sorted(present, key=lambda p: p.name == MANIFEST):  # the manifest last
            p.unlink()
    (directory / "streams").mkdir(parents=True, exist_ok=True)
    return directory


def write_sortie(directory: Path, manifest: Mapping, data: pd.DataFrame,
                 streams: Mapping[str, pd.DataFrame]) -> Path:
    """Write a whole-sortie dataset into a prepared directory (:func:`prepare_sortie_directory`).

    Parameters
    ----------
    directory : the dataset directory.
    manifest : format :data:`SORTIE_FORMAT`; ``manifest["sortie"]["boundaries"]`` the maneuver
        boundaries (dicts with :data:`BOUNDARY_COLUMNS`), also written as ``boundaries.csv``.
    data : the preprocessed common time base (``t_s`` first, measured and ``true_*`` columns).
    streams : recorder (``dru``, ``ins``, ``dgps``) -> its raw stream (``t_s`` = its stamps).

    Returns
    -------
    The manifest's path (written last: a directory with a manifest holds a whole sortie).
    """
    entry = {k: v for k, v in manifest["sortie"].items() if k != "boundaries"}
    write_maneuver(directory / SORTIE_FILES["data"], data, entry)
    for name, frame in streams.items():
        write_maneuver(directory / SORTIE_FILES[name], frame, {"recorder": name, **entry})
    table = pd.DataFrame(manifest["sortie"]["boundaries"], columns=list(BOUNDARY_COLUMNS))
    atomic_write_bytes(directory / SORTIE_FILES["boundaries"],
                       table.to_csv(index=False, float_format="%.6f").encode())
    return write_manifest(directory, manifest)


@dataclass(frozen=True)
class Sortie:
    """A whole-sortie dataset opened for reading (:func:`load_sortie`).

    Attributes
    ----------
    path : the directory.
    manifest : the parsed ``manifest.json`` (``manifest["sortie"]``: configuration, boundaries,
        transitions, injected errors, channel units, ...).
    """

    path: Path
    manifest: dict

    @property
    def boundaries(self) -> pd.DataFrame:
        """The truth boundaries, one row per recorded maneuver piece, indexed by its id
        (columns :data:`BOUNDARY_COLUMNS`; times in the sortie's ``t_s``, first and last sample)."""
        return pd.DataFrame(self.manifest["sortie"]["boundaries"],
                            columns=list(BOUNDARY_COLUMNS)).set_index("id")

    @property
    def transitions(self) -> pd.DataFrame:
        """The transition legs between maneuvers: ``to``, ``t_start_s``, ``t_end_s``, ``stages``."""
        return pd.DataFrame(self.manifest["sortie"]["transitions"],
                            columns=["to", "t_start_s", "t_end_s", "stages"])

    def load(self, stream: str = "data") -> pd.DataFrame:
        """The common time base (``"data"``) or one recorder's raw stream (``"dru"``, ``"ins"``,
        ``"dgps"``; ``t_s`` = its own stamps)."""
        if stream not in SORTIE_FILES or stream == "boundaries":
            raise KeyError(f"{self.path}: no stream {stream!r}; choose one of "
                           f"{[k for k in SORTIE_FILES if k != 'boundaries']}")
        return pd.read_parquet(self.path / SORTIE_FILES[stream])

    def cut(self, maneuver_id: str, stream: str | pd.DataFrame = "data") -> pd.DataFrame:
        """The samples of ``stream`` (a name for :meth:`load`, or a frame already loaded) within
        the maneuver's truth boundaries: what a campaign's extraction cuts out of the recording.
        ``t_s`` stays the sortie's time."""
        bounds = self.boundaries
        if maneuver_id not in bounds.index:
            raise KeyError(f"{self.path}: no maneuver {maneuver_id!r} in the sortie; it has "
                           f"{_listing(list(bounds.index))}")
        row = bounds.loc[maneuver_id]
        frame = self.load(stream) if isinstance(stream, str) else stream
        t = frame["t_s"].to_numpy()
        eps = 1e-9  # the boundaries are simulation-step times, the stamps grid times
        keep = (t >= row["t_start_s"] - eps) & (t <= row["t_end_s"] + eps)
        return frame.loc[keep].reset_index(drop=True)


def load_sortie(path: str | Path) -> Sortie:
    """Open a whole-sortie dataset written by ``fpr fly --sortie``.

    Raises
    ------
    FileNotFoundError
        If there is no sortie manifest, or one of its files is missing.
    """
    path = Path(path)
    if path.name == MANIFEST:
        path = path.parent
    manifest = read_sortie_manifest(path)
    if manifest is None:
        raise FileNotFoundError(
            f"{path / MANIFEST}: no whole-sortie manifest (format {SORTIE_FORMAT!r}); is {path} a "
            "sortie written by `fpr fly --sortie`? (a per-maneuver dataset: load_dataset)")
    if manifest.get("format_version", 0) > SORTIE_FORMAT_VERSION:
        raise ValueError(f"{path / MANIFEST}: format_version {manifest['format_version']} is newer "
                         f"than this software reads ({SORTIE_FORMAT_VERSION}); upgrade fpr-testbed")
    missing = [f for f in SORTIE_FILES.values() if not (path / f).exists()]
    if missing:
        raise FileNotFoundError(f"{path}: the sortie's file(s) {', '.join(missing)} are missing; the "
                                "dataset is damaged (fly it again: `fpr fly ... --sortie --overwrite`)")
    return Sortie(path=path, manifest=manifest)
