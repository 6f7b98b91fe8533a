"""Run a Monte Carlo scenario into an output directory, locally or on a Dask cluster, resumably.

Layout of the output directory::

    OUT/montecarlo.json            format, scenario (as read) and its hash, N, software versions
    OUT/scenario.toml              a copy of the scenario file (when it came from one)
    OUT/flights/j0007.npz          truth of each maneuver flown once (reused by every replication;
                                   NumPy arrays + JSON, :mod:`campaigns.montecarlo.flight_cache`)
    OUT/replications/r00042.parquet         one finished replication (ReplicationResult.to_pandas,
                                            its scalars in the file metadata under fpr.montecarlo)
    OUT/replications/r00043.failed.json     one failed replication: status, error text, seeds
    OUT/timings.csv                one line per replication run: its wall time in the worker, when
                                   and where it finished (appended; the only file that differs
                                   between two runs of the same replications)
    OUT/.scratch/r00042-XXXXXXXX/  while replication 42 runs (local processes): its scratch
                                   dataset; removed at the end of the run, or, after a kill, at the
                                   start of the next (a Dask worker uses its own temporary folder)

Every file is written to a temporary name and renamed into place, by the one process that runs
the campaign (workers return results; they never write), so an interrupted run leaves whole files
only. Running the same command again skips the replications that have a file (a failed one too,
unless ``retry_failed``) and ends with exactly one file per replication. A replication's file holds
only what its inputs decide (no wall time, host or date: those go to ``timings.csv``), so an
interrupted and resumed run ends with the same bytes as an uninterrupted one. An output directory
made from another scenario (its hash differs) is refused. The hash covers the scenario's own
tables, not the files it names (fleet, local-flow truth, model set) nor the code: after changing
those, start a new directory rather than resume, or the run mixes results of both. A lock
(``OUT/.lock``) keeps two runs out of one directory.

Nothing in the directory is ever unpickled, eval'd or exec'd: a run folder may come from anyone.
A flight cache of an older version (``flights/j0007.pkl``) is ignored, said so, and flown again.
The run removes only what it wrote itself: its own temporary files and scratch datasets
(``.scratch/rNNNNN-XXXXXXXX/``) left by a killed run, and the failure record of a replication that
now succeeded; anything else in the folder is left alone
(there is no overwrite mode: a new run goes to a new or empty directory).

Ctrl-C (or SIGTERM, through ``fpr montecarlo``) stops the run: the worker processes ignore SIGINT
(no traceback from each of them), the run cancels what has not started, stops the workers (each
removes its replication's scratch dataset on its way out), keeps every replication already written
and raises :class:`MonteCarloInterrupted`, which says how many are written and that the same
command resumes.

Before a run resumes, every replication file present is checked to belong to this run (its
metadata names this scenario's hash and its own index); one that does not — a file of another
scenario copied in, a user's file of such a name — is refused by name, never counted as done. A
``timings.csv`` that this module did not start (another header) is refused too, not appended to.

Executors: local processes (:class:`concurrent.futures.ProcessPoolExecutor`, the default),
in-process (``workers=1``, for debugging and tests), or a Dask distributed cluster
(``scheduler=ADDRESS`` or a :class:`dask.distributed.Client`). Replication ``k``'s results do not
depend on the executor: everything it draws derives from ``(seed, k)``.
"""

from __future__ import annotations

import contextlib
import csv
import fcntl
import io
import json
import os
import re
import shutil
import signal
import socket
import sys
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, wait
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from synth.campaign import software_versions
from synth.dataset import atomic_write_bytes
from synth.flight import FlightError
from synth.truth import TruthTrajectory
from synth.workers import worker_pool

from .flight_cache import flight_bytes, flight_file, read_flight
from .replication import (
    SCRATCH_NAME,
    Models,
    ReplicationResult,
    failure_record,
    fly,
    remove_scratch_directories,
    run_replication_safely,
    scratch_in,
    set_scratch_root,
)
from .scenario import Scenario, ScenarioError, parse_scenario, scenario_hash, with_replications

FORMAT = "fpr-montecarlo"
FORMAT_VERSION = 1
STATE_FILE = "montecarlo.json"
METADATA_KEY = b"fpr.montecarlo"
TIMINGS_FILE = "timings.csv"
TIMINGS_COLUMNS = ("replication", "ok", "elapsed_s", "finished_utc", "host", "executor")
_REP = "replications"
_FLIGHTS = "flights"
#: the replications' scratch datasets while they run (removed at the end of a run, and a killed
#: run's at the start of the next)
SCRATCH_DIR = ".scratch"
#: the files this module writes (the temporary names of a killed run are ``.NAME.XXXXXXXX.tmp``)
_OWN_NAMES = {_REP: re.compile(r"r(\d{5})\.(parquet|failed\.json)"),
              _FLIGHTS: re.compile(r"j(\d{4})\.npz"),
              "": re.compile(r"(montecarlo\.json|scenario\.toml)")}


# ---------------------------------------------------------------------------- files


def replication_file(out_dir: Path, index: int, failed: bool = False) -> Path:
    """The file of replication ``index`` (finished or failed)."""
    name = f"r{index:05d}.failed.json" if failed else f"r{index:05d}.parquet"
    return Path(out_dir) / _REP / name


def finished_replications(out_dir: Path) -> dict[int, str]:
    """Replication index -> "ok" or "failed", from the files present (a finished result wins
    over a failure record of the same index)."""
    out: dict[int, str] = {}
    rep = Path(out_dir) / _REP
    if not rep.is_dir():
        return out
    for p in rep.iterdir():
        m = _OWN_NAMES[_REP].fullmatch(p.name)
        if m is None:  # not a file of ours (a user's note, a temporary file): left alone
            continue
        if m.group(2) == "parquet":
            out[int(m.group(1))] = "ok"
        else:
            out.setdefault(int(m.group(1)), "failed")
    return out


def write_replication(out_dir: Path, result: ReplicationResult) -> Path:
    """Write one replication's file atomically (and drop an earlier failure record of it).

    The file holds only what the replication's inputs decide: the same replication gives the same
    bytes in any run (its wall time goes to :func:`append_timing`)."""
    if not result.ok:
        path = replication_file(out_dir, result.index, failed=True)
        atomic_write_bytes(path, failure_record(result).encode())
        return path
    table = pa.Table.from_pandas(result.to_pandas(), preserve_index=False)
    meta = dict(table.schema.metadata or {})
    meta[METADATA_KEY] = json.dumps(result.meta(), sort_keys=True).encode()
    sink = pa.BufferOutputStream()
    # no statistics: the same table gives the same bytes (as synth.dataset.write_maneuver)
    pq.write_table(table.replace_schema_metadata(meta), sink, compression="zstd", write_statistics=False)
    path = replication_file(out_dir, result.index)
    atomic_write_bytes(path, sink.getvalue().to_pybytes())
    replication_file(out_dir, result.index, failed=True).unlink(missing_ok=True)
    return path


def read_replication(path: Path) -> ReplicationResult:
    """Read a replication file (finished ``.parquet`` or ``.failed.json``)."""
    path = Path(path)
    if path.name.endswith(".failed.json"):
        return ReplicationResult.from_meta(json.loads(path.read_text()))
    table = pq.read_table(path)
    raw = (table.schema.metadata or {}).get(METADATA_KEY)
    if raw is None:
        raise ValueError(f"{path}: no {METADATA_KEY.decode()} metadata; not a replication file written "
                         "by `fpr montecarlo` (remove it from the replications/ directory)")
    return ReplicationResult.from_pandas(table.to_pandas(), json.loads(raw))


def append_timing(out_dir: Path, result: ReplicationResult, executor: str = "") -> None:
    """Append replication ``result``'s wall time (and when and where it finished) to
    ``OUT/timings.csv``: timings are kept apart from the replication files, which stay
    bit-identical between runs. One ``write`` per line, so a killed run leaves whole lines (a torn
    last line is skipped by :func:`read_timings`)."""
    path = Path(out_dir) / TIMINGS_FILE
    row = io.StringIO()
    writer = csv.writer(row, lineterminator="\n")
    if not path.exists() or path.stat().st_size == 0:  # empty: a run killed between open and write
        writer.writerow(TIMINGS_COLUMNS)
    writer.writerow([result.index, int(result.ok), repr(float(result.elapsed_s)),
                     datetime.now(UTC).isoformat(timespec="seconds"), socket.gethostname(), executor])
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        os.write(fd, row.getvalue().encode())
    finally:
        os.close(fd)


def read_timings(out_dir: Path) -> dict[int, float]:
    """Replication index -> its wall time in the worker, s, from ``OUT/timings.csv`` (the last
    line of a replication run more than once); empty without the file."""
    path = Path(out_dir) / TIMINGS_FILE
    out: dict[int, float] = {}
    if not path.is_file():
        return out
    with open(path, newline="") as fh:
        for row in csv.DictReader(fh):
            try:
                out[int(row["replication"])] = float(row["elapsed_s"])
            except (KeyError, TypeError, ValueError):  # a line torn by a kill: that timing is lost
                continue
    return out


def with_timings(out_dir: Path, results: Iterable[ReplicationResult]) -> list[ReplicationResult]:
    """``results`` with ``elapsed_s`` taken from the run's ``timings.csv`` where it has a line."""
    times = read_timings(out_dir)
    return [replace(r, elapsed_s=times[r.index]) if r.index in times else r for r in results]


def read_state(out_dir: Path) -> dict:
    """The run's ``montecarlo.json``."""
    path = Path(out_dir) / STATE_FILE
    if not path.exists():
        raise FileNotFoundError(f"{path}: no {STATE_FILE}; is {out_dir} the --out directory of "
                                "`fpr montecarlo`?")
    try:
        state = json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not a state file `fpr montecarlo` wrote ({exc}); is {out_dir} the "
                         "--out directory of `fpr montecarlo`? Choose another --out") from None
    if not isinstance(state, dict) or state.get("format") != FORMAT:
        found = state.get("format") if isinstance(state, dict) else type(state).__name__
        raise ValueError(f"{path}: format {found!r}, expected {FORMAT!r}: not a state file "
                         f"`fpr montecarlo` wrote; choose another --out")
    return state


def scenario_of(out_dir: Path) -> Scenario:
    """The scenario an output directory was made from (as stored in its ``montecarlo.json``)."""
    state = read_state(out_dir)
    return parse_scenario(state["scenario"], source=state.get("source", str(out_dir)))


def own_temporary_files(out_dir: Path) -> list[Path]:
    """The temporary files a killed run of this module left in ``out_dir`` (never whole files):
    ``.NAME.XXXXXXXX.tmp`` beside a file NAME of ours. Nothing else matches, so a user's own
    ``.something.tmp`` is never touched."""
    out = []
    for sub, own in _OWN_NAMES.items():
        d = Path(out_dir) / sub
        if not d.is_dir():
            continue
        for p in d.glob(".*.tmp"):
            m = re.fullmatch(r"\.(.+)\.[a-z0-9_]{8}\.tmp", p.name)  # mkstemp's 8 random characters
            if m is not None and own.fullmatch(m.group(1)) and p.is_file():
                out.append(p)
    return sorted(out)


def _replication_meta(path: Path) -> dict | None:
    """The metadata a replication file carries (:meth:`ReplicationResult.meta`), None when the file
    is not one this module writes (unreadable, no metadata, a link or a folder)."""
    if path.is_symlink() or not path.is_file():
        return None
    try:
        if path.name.endswith(".failed.json"):
            meta = json.loads(path.read_text(encoding="utf-8"))
        else:  # the footer only: no table is read
            meta = json.loads((pq.read_schema(path).metadata or {})[METADATA_KEY])
    except Exception:  # noqa: BLE001 (whatever a stranger's file makes a reader raise: not ours)
        return None
    return meta if isinstance(meta, dict) else None


def foreign_files(out_dir: Path, scenario_hash: str) -> list[str]:
    """Files in a run folder that carry a name this module writes but that it did not write for
    this run: replication files whose metadata does not name ``scenario_hash`` and their own index
    (another scenario's, a user's), and a ``timings.csv`` that does not start with this module's
    header. Relative POSIX paths; empty when the folder holds only its own files of those names."""
    out_dir = Path(out_dir)
    out = []
    rep = out_dir / _REP
    for p in sorted(rep.iterdir()) if rep.is_dir() else ():
        m = _OWN_NAMES[_REP].fullmatch(p.name)
        if m is None:
            continue  # not a name of ours: left alone, never read
        meta = _replication_meta(p)
        if meta is None or meta.get("scenario_hash") != scenario_hash or meta.get("replication") != \
                int(m.group(1)):
            out.append(f"{_REP}/{p.name}")
    timings = out_dir / TIMINGS_FILE
    if timings.is_symlink() or (timings.exists() and not timings.is_file()):
        out.append(TIMINGS_FILE)
    elif timings.exists() and timings.stat().st_size:
        with open(timings, "rb") as fh:
            first = fh.readline().rstrip(b"\r\n")
        if first != ",".join(TIMINGS_COLUMNS).encode():
            out.append(TIMINGS_FILE)
    return out


def _refuse_foreign(out_dir: Path, scenario: Scenario) -> None:
    found = foreign_files(out_dir, scenario.hash)
    if found:
        shown = ", ".join(found[:10]) + (f" and {len(found) - 10} more" if len(found) > 10 else "")
        raise ScenarioError(
            f"{out_dir}: {shown} carr{'ies' if len(found) == 1 else 'y'} the name of a file of this "
            f"run but {'was' if len(found) == 1 else 'were'} not written by it (another scenario's "
            "replication, or not written by `fpr montecarlo`); the run neither counts such a file as "
            f"done nor writes over it. Move {'it' if len(found) == 1 else 'them'} out of {out_dir} "
            "and run the same command again")


def prepare_output(scenario: Scenario, out_dir: Path) -> Path:
    """Create the output directory, or check that an existing one holds this scenario's run.

    Raises
    ------
    ScenarioError
        The directory holds a run of another scenario, or something that is not a run, or files
        with the names of this run's results that it did not write (:func:`foreign_files`).
    """
    out_dir = Path(out_dir)
    state_path = out_dir / STATE_FILE
    if out_dir.exists() and not out_dir.is_dir():
        raise ScenarioError(f"{out_dir} exists and is not a folder; choose another --out")
    if out_dir.exists() and any(out_dir.iterdir()):
        if not state_path.exists():
            held = sorted(p.name + ("/" if p.is_dir() else "") for p in out_dir.iterdir())
            shown = ", ".join(held[:10]) + (f" and {len(held) - 10} more" if len(held) > 10 else "")
            raise ScenarioError(f"{out_dir}: not empty and not a Monte Carlo output (no {STATE_FILE}; "
                                f"it holds {shown}); a run never writes among files it did not make: "
                                "choose a new or empty --out directory")
        state = read_state(out_dir)
        if state.get("scenario_hash") != scenario.hash:
            raise ScenarioError(
                f"{out_dir}: made from another scenario ({state.get('source')}, hash "
                f"{str(state.get('scenario_hash'))[:12]}) than {scenario.source} "
                f"(hash {scenario.hash[:12]}); "
                "results of two scenarios must not mix. Choose another --out, delete the directory to "
                f"start over, or resume it with the scenario it was made from ({out_dir / 'scenario.toml'})")
        _refuse_foreign(out_dir, scenario)  # before anything is written
        scratch = out_dir / SCRATCH_DIR
        if scratch.is_symlink() or (scratch.exists() and not scratch.is_dir()):
            raise ScenarioError(
                f"{scratch}: {'a link' if scratch.is_symlink() else 'not a folder'}, not the scratch "
                "folder `fpr montecarlo` makes there for its replications' data; nothing is written "
                "through it. Move it out of the folder and run the same command again")
    (out_dir / _REP).mkdir(parents=True, exist_ok=True)
    (out_dir / _FLIGHTS).mkdir(parents=True, exist_ok=True)
    for p in own_temporary_files(out_dir):  # leftovers of a run killed while writing
        p.unlink(missing_ok=True)
    src = Path(scenario.source)
    if src.is_file() and not (out_dir / "scenario.toml").exists():
        atomic_write_bytes(out_dir / "scenario.toml", src.read_bytes())
    state = {"format": FORMAT, "format_version": FORMAT_VERSION, "name": scenario.name,
             "source": scenario.source, "scenario_hash": scenario.hash,
             "replications": scenario.replications, "scenario": scenario.raw,
             "software": software_versions()}
    atomic_write_bytes(state_path, (json.dumps(state, indent=1, sort_keys=True, default=str) + "\n").encode())
    return out_dir


# ---------------------------------------------------------------------------- worker side

#: per worker process: the parsed scenario and its models, and the truths read from a cache
_PROCESS: dict = {}


@dataclass(frozen=True)
class ScenarioPayload:
    """What a worker needs to rebuild the scenario: its raw tables (small, picklable; the parsed
    Scenario holds read-only mappings that do not pickle)."""

    raw: dict
    source: str

    @property
    def key(self) -> str:
        return scenario_hash(self.raw) + self.source


@dataclass(frozen=True)
class FlightCache:
    """The truths of the maneuvers flown once: job index -> segments. One object, so Dask scatters
    it as one piece of data to every worker."""

    truths: Mapping[int, tuple[TruthTrajectory, ...]]


def _worker_scenario(payload: ScenarioPayload) -> tuple[Scenario, Models]:
    if _PROCESS.get("key") != payload.key:
        scenario = parse_scenario(payload.raw, source=payload.source)
        _PROCESS.update(key=payload.key, scenario=scenario, models=Models.of(scenario), truths={})
    return _PROCESS["scenario"], _PROCESS["models"]


def _load_truths(source: str | FlightCache | Mapping, jobs: Iterable[int]) -> Mapping[int, tuple]:
    if isinstance(source, FlightCache):
        return source.truths
    if isinstance(source, Mapping):
        return source
    # read once per process, then kept: the same flights serve every replication (keyed by the
    # file, so that two run folders read in one process never lend each other their flights)
    cache = _PROCESS.setdefault("truths", {})
    out = {}
    for j in jobs:
        path = flight_file(source, j)
        if path not in cache:
            cache[path] = read_flight(path)
        out[j] = cache[path]
    return out


def fly_task(payload: ScenarioPayload, job_index: int) -> tuple[int, tuple | None, str | None]:
    """Fly one maneuver that every replication shares: (job index, truth segments, error)."""
    scenario, _ = _worker_scenario(payload)
    md = scenario.draw(0).maneuvers[job_index]
    try:
        return job_index, fly(scenario, md), None
    except FlightError as exc:
        return job_index, None, f"FlightError: {exc}"


def replication_task(payload: ScenarioPayload, index: int,
                     truths: str | FlightCache | Mapping) -> ReplicationResult:
    """Run replication ``index`` in a worker (failures come back as failed results)."""
    scenario, models = _worker_scenario(payload)
    cached = _load_truths(truths, (j.index for j in scenario.fixed_jobs))
    return run_replication_safely(scenario, index, cached, models)


# ---------------------------------------------------------------------------- the run


class MonteCarloInterrupted(KeyboardInterrupt):
    """:func:`run_montecarlo` stopped by Ctrl-C (or a signal turned into KeyboardInterrupt): the
    replications written so far are kept, and running the same command again resumes."""

    def __init__(self, out_dir: Path, n_written: int, n_replications: int):
        self.out_dir, self.n_written, self.n_replications = Path(out_dir), n_written, n_replications
        super().__init__(
            f"interrupted: {n_written} of {n_replications} replications written to {out_dir}; run "
            "the same command again to resume")

    def __str__(self) -> str:
        return str(self.args[0])


@dataclass(frozen=True)
class RunReport:
    """What :func:`run_montecarlo` did.

    Attributes
    ----------
    out_dir : the output directory.
    requested : N.
    ran : replications computed by this call.
    skipped : replications already finished before it.
    failed : indices (of 0..N-1) whose file is a failure record.
    flights_flown : maneuvers flown for the shared truth cache by this call.
    wall_s : wall time of the call, s.
    executor : "in-process", "processes(N)" or "dask(ADDRESS)".
    notes : what the user should know about the folder (an ignored old pickle cache).
    """

    out_dir: Path
    requested: int
    ran: tuple[int, ...]
    skipped: int
    failed: tuple[int, ...]
    flights_flown: int
    wall_s: float
    executor: str
    notes: tuple[str, ...] = ()

    @property
    def complete(self) -> bool:
        """Every replication 0..N-1 has a file."""
        have = finished_replications(self.out_dir)
        return all(k in have for k in range(self.requested))

    def text(self) -> str:
        per = f", {self.wall_s / len(self.ran):.1f} s per replication" if self.ran else ""
        lines = [f"{self.out_dir}: {len(self.ran)} replications run now, {self.skipped} already done, "
                 f"{self.requested} requested; {self.flights_flown} shared flights flown; "
                 f"{self.executor}; wall {self.wall_s:.1f} s{per}", *self.notes]
        if self.failed:
            lines.append(f"failed replications ({len(self.failed)}): {list(self.failed)[:20]} "
                         f"(records in {self.out_dir / _REP}/rNNNNN.failed.json)")
        return "\n".join(lines)


class RunLock:
    """An exclusive lock on the output directory for the duration of a run."""

    def __init__(self, out_dir: Path):
        self.path = Path(out_dir) / ".lock"

    def __enter__(self) -> RunLock:
        self.fh = open(self.path, "a")  # noqa: SIM115 (held until __exit__)
        try:
            fcntl.flock(self.fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self.fh.close()
            raise ScenarioError(f"{self.path.parent}: another `fpr montecarlo` is running into this "
                                "directory; wait for it or stop it before resuming") from None
        return self

    def __exit__(self, *exc) -> None:
        fcntl.flock(self.fh, fcntl.LOCK_UN)
        self.fh.close()


def _progress_bar(total: int, initial: int, desc: str, progress):
    if progress is not True:
        return None
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, unit="replication", desc=desc, file=sys.stderr,
                mininterval=0.5 if sys.stderr.isatty() else 10.0)


def run_montecarlo(
    scenario: Scenario,
    out_dir: str | Path,
    *,
    replications: int | None = None,
    workers: int | None = None,
    scheduler=None,
    indices: Sequence[int] | None = None,
    retry_failed: bool = False,
    progress: bool | Callable[[int, int], None] = False,
) -> RunReport:
    """Run (or resume) a Monte Carlo scenario into ``out_dir``.

    Parameters
    ----------
    scenario : from :func:`~campaigns.montecarlo.load_scenario`.
    out_dir : the output directory (created; an existing one must hold this scenario's run).
    replications : N, overriding the scenario's.
    workers : local worker processes (default: the number of CPUs; 1 runs everything in this
        process). Ignored with ``scheduler``.
    scheduler : a Dask scheduler address (``tcp://host:8786``) or a ``dask.distributed.Client``
        to run the replications on that cluster instead.
    indices : run only these replications (default: every one of 0..N-1 without a file).
    retry_failed : run again the replications whose file is a failure record.
    progress : a tqdm progress bar (True) or a callback ``progress(done, total)``.

    Returns
    -------
    RunReport
    """
    t0 = time.perf_counter()
    scenario = with_replications(scenario, replications)
    n = scenario.replications
    out_dir = prepare_output(scenario, Path(out_dir))
    with RunLock(out_dir):
        have = finished_replications(out_dir)
        wanted = range(n) if indices is None else sorted(set(int(i) for i in indices))
        bad = [i for i in wanted if not 0 <= i < n]
        if bad:
            raise ScenarioError(f"replications {bad} are outside 0..{n - 1}")
        todo = [k for k in wanted if k not in have or (retry_failed and have[k] == "failed")]
        notes = _ignored_pickles(scenario, out_dir, todo)
        n_workers = workers or os.cpu_count() or 1
        # for timings.csv (the report's label names the Dask scheduler's address too)
        label = "dask" if scheduler is not None else "in-process" if n_workers == 1 else \
            f"processes({n_workers})"
        payload = ScenarioPayload(raw=scenario.raw, source=scenario.source)
        bar = _progress_bar(len(todo), 0, f"monte carlo {scenario.name} ({len(wanted) - len(todo)} done "
                            "before)", progress)
        done = [0]

        def record(res: ReplicationResult) -> None:
            write_replication(out_dir, res)
            append_timing(out_dir, res, label)
            done[0] += 1
            if bar is not None:
                bar.update(1)
                if not res.ok:
                    bar.write(f"replication {res.index} failed: {res.message.splitlines()[0]}")
            elif callable(progress):
                progress(done[0], len(todo))

        clear_scratch(out_dir)  # a killed run's scratch data (nothing else runs here: the lock)
        try:
            if scheduler is not None:
                flown, executor = _run_dask(scenario, payload, out_dir, todo, scheduler, record)
            elif n_workers == 1:
                flown, executor = _run_in_process(scenario, out_dir, todo, record)
            else:
                flown, executor = _run_processes(scenario, payload, out_dir, todo, n_workers, record)
        except KeyboardInterrupt:
            if bar is not None:
                bar.close()
                bar = None
            have = finished_replications(out_dir)
            raise MonteCarloInterrupted(out_dir, sum(k in have for k in range(n)), n) from None
        finally:
            if bar is not None:
                bar.close()
            clear_scratch(out_dir)  # the workers have ended: what is left there is abandoned
        final = finished_replications(out_dir)
    return RunReport(out_dir=out_dir, requested=n, ran=tuple(todo), skipped=len(wanted) - len(todo),
                     failed=tuple(k for k in range(n) if final.get(k) == "failed"),
                     flights_flown=flown, wall_s=time.perf_counter() - t0, executor=executor,
                     notes=notes)


def _scratch_folder(out_dir: Path) -> Path:
    """``OUT/.scratch/``, created: where the local replications write their scratch datasets."""
    folder = Path(out_dir) / SCRATCH_DIR
    folder.mkdir(exist_ok=True)
    return folder


def clear_scratch(out_dir: Path) -> None:
    """Remove the replications' scratch datasets from ``OUT/.scratch/`` (a killed run's, or this
    run's at its end): only folders of the names :mod:`.replication` makes there
    (``rNNNNN-XXXXXXXX``), never a link; ``.scratch/`` itself when nothing else is left in it."""
    folder = Path(out_dir) / SCRATCH_DIR
    if folder.is_symlink() or not folder.is_dir():
        return
    for p in folder.iterdir():
        if SCRATCH_NAME.fullmatch(p.name) and p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
    with contextlib.suppress(OSError):  # not empty: something of someone else's, left alone
        folder.rmdir()


def _missing_flights(scenario: Scenario, out_dir: Path, todo: Sequence[int]) -> list[int]:
    if not todo:
        return []
    return [j.index for j in scenario.fixed_jobs if not flight_file(out_dir / _FLIGHTS, j.index).exists()]


def _ignored_pickles(scenario: Scenario, out_dir: Path, todo: Sequence[int]) -> tuple[str, ...]:
    """One note per pickle in ``flights/`` (an older version's cache, or planted): never loaded,
    left where it is; the flight is flown again when a replication needs it."""
    missing = set(_missing_flights(scenario, out_dir, todo))
    notes = []
    for p in sorted((out_dir / _FLIGHTS).glob("*.pkl")):
        m = re.fullmatch(r"j(\d{4})\.pkl", p.name)
        again = "; the flight is flown again" if m and int(m.group(1)) in missing else ""
        notes.append(f"ignoring {_FLIGHTS}/{p.name}: pickle files are never loaded{again}")
    return tuple(notes)


def _store_flights(scenario: Scenario, out_dir: Path,
                   outcomes: Iterable[tuple[int, tuple | None, str | None]]) -> int:
    """Write the flown truths to the cache; a maneuver that cannot be flown stops the campaign
    (every replication would lack it), with every such maneuver named."""
    errors, n = [], 0
    for job_index, segments, error in outcomes:
        if error is not None:
            job = scenario.campaign.jobs[job_index]
            errors.append(f"  maneuver {job_index} ({job.configuration_id}, {job.maneuver['kind']}, "
                          f"Mach {job.maneuver['mach']}): {error}")
            continue
        atomic_write_bytes(flight_file(out_dir / _FLIGHTS, job_index), flight_bytes(segments))
        n += 1
    if errors:
        raise ScenarioError(f"{scenario.source}: {len(errors)} maneuver(s) cannot be flown, so no "
                            "replication could use them; change or remove them in [[flights]]:\n"
                            + "\n".join(errors))
    return n


def _run_in_process(scenario, out_dir, todo, record) -> tuple[int, str]:
    payload = ScenarioPayload(raw=scenario.raw, source=scenario.source)
    flown = _store_flights(scenario, out_dir, (fly_task(payload, j)
                                               for j in _missing_flights(scenario, out_dir, todo)))
    cache = str(out_dir / _FLIGHTS)
    with scratch_in(_scratch_folder(out_dir)):
        for k in todo:
            record(replication_task(payload, k, cache))
    return flown, "in-process"


def _on_worker_sigterm(signum, frame) -> None:
    # the run stops this worker (stop_pool): its replication is abandoned, so is its scratch data
    remove_scratch_directories()
    os._exit(128 + signum)


def _init_pool_worker(scratch: str) -> None:
    """Pool initializer (after :func:`synth.workers.init_pool_worker`): the worker puts its scratch
    datasets in the run folder's ``scratch`` folder and removes them when the run stops it
    (SIGTERM)."""
    set_scratch_root(scratch)
    signal.signal(signal.SIGTERM, _on_worker_sigterm)


def _run_processes(scenario, payload, out_dir, todo, workers, record) -> tuple[int, str]:
    cache = str(out_dir / _FLIGHTS)
    # the workers end with this process, however it ends (a kill leaves no orphan computing on);
    # on Ctrl-C or an error writing a file, what has not started is cancelled and the running
    # workers are ended now (their replications are lost; every file written so far is whole)
    with worker_pool(workers, _init_pool_worker, (str(_scratch_folder(out_dir)),)) as pool:
        missing = _missing_flights(scenario, out_dir, todo)
        flown = _store_flights(scenario, out_dir,
                               pool.map(fly_task, [payload] * len(missing), missing))
        pending = {pool.submit(replication_task, payload, k, cache) for k in todo}
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in finished:
                record(fut.result())
    return flown, f"processes({workers})"


def _run_dask(scenario, payload, out_dir, todo, scheduler, record) -> tuple[int, str]:
    try:
        from dask.distributed import Client, as_completed
    except ImportError:  # pragma: no cover - dask is a dependency; a broken install says so
        raise ScenarioError("--scheduler needs dask.distributed: python -m pip install "
                            "\"dask[distributed]\"") from None
    own = not isinstance(scheduler, Client)
    client = Client(scheduler) if own else scheduler
    try:
        missing = _missing_flights(scenario, out_dir, todo)
        flights = client.map(fly_task, [payload] * len(missing), missing, pure=False)
        flown = _store_flights(scenario, out_dir, (f.result() for f in as_completed(flights)))
        if not todo:
            return flown, f"dask({client.scheduler.address})"
        fixed = [j.index for j in scenario.fixed_jobs]
        truths = FlightCache({j: read_flight(flight_file(out_dir / _FLIGHTS, j)) for j in fixed})
        # the workers need not see this directory: the truths travel to each of them once
        shared = client.scatter(truths, broadcast=True)
        futures = [client.submit(replication_task, payload, k, shared, pure=False) for k in todo]
        index_of = {f.key: k for f, k in zip(futures, todo, strict=True)}
        for fut in as_completed(futures):
            try:
                res = fut.result()
            except Exception as exc:  # the worker died or the task could not run there
                res = ReplicationResult(index=index_of[fut.key], ok=False, status=-1,
                                        message=f"dask: {type(exc).__name__}: {exc}",
                                        noise_seed=scenario.draw(index_of[fut.key]).noise_seed,
                                        scenario_hash=scenario.hash)
            record(res)
        return flown, f"dask({client.scheduler.address})"
    finally:
        if own:
            client.close()
