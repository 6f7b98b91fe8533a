"""Flight campaigns: a small TOML file says what to fly; this module flies it into a dataset.

A campaign file::

    name = "default"
    description = "five aircraft, Mach 0.3-0.9, every maneuver type, gear-down maneuvers"
    fleet = "fleet_default"          # shipped fleet name or path to a fleet TOML
    local_flow_truth = "local_flow_truth"   # optional: the local-flow truth model (aircraft_models/)
    adc_baseline = "adc_baseline"           # optional: the airdata computer's baseline model
    seed = 2026                      # master seed: turbulence and every error source derive from it
    common_rate_hz = 40.0            # the preprocessed common time base

    [environment]                    # defaults for every maneuver (synth.environment.Environment)
    planet = "flat"
    wind_ned_mps = [6.0, -4.0, 0.0]
    turbulence = "light"

    [errors]                         # synth.errors.ErrorConfig.from_dict
    preset = "typical"

    [errors.aircraft.PV1]            # optional per-aircraft overrides, merged into [errors]
    imu = { accel_bias_mps2 = [0.1, -0.05, 0.08] }

    [[flights]]                      # a block: every configuration x Mach x maneuver kind
    configurations = "all"           # or a list of configuration ids
    mach = [0.3, 0.5, 0.7, 0.9]
    maneuvers = ["pitch_doublet", "windup_turn"]   # or "all"
    altitude_m = 6000.0
    gear_down = false
    [flights.maneuver]               # optional extra ManeuverSpec fields for this block
    duration_s = 35.0

Every maneuver gets a stable index in file order, from which its seeds derive (turbulence:
master seed + index; every error source: ``default_rng([source seed, index * 64 + segment,
channel])``, :func:`synth.dataset.maneuver_key`), so the same file gives bit-identical data
whatever the number of worker processes, and a job's data do not depend on which other jobs ran:
an interrupted dataset completed with ``fly_campaign(..., resume=True)`` is byte-identical to an
uninterrupted one.
"""

from __future__ import annotations

import copy
import importlib.metadata
import json
import os
import platform
import sys
import tomllib
import traceback
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import as_completed
from dataclasses import dataclass, field
from pathlib import Path

from aircraft_models import Fleet, load_fleet
from aircraft_models.schema import check, unknown
from synth.dataset import (
    FORMAT,
    FORMAT_VERSION,
    RecordedPiece,
    _jsonable,
    airframe_manifest,
    damaged_manifest,
    dataset_status,
    job_entries,
    maneuver_file,
    maneuver_id,
    maneuver_key,
    prepare_directory,
    read_manifest_if_dataset,
    remove_temp_files,
    resume_command,
    write_maneuver,
    write_manifest,
)
from synth.environment import Environment
from synth.errors import ErrorConfig
from synth.flight import FlightError, fly_maneuver
from synth.instrument import instrument
from synth.local_flow import load_adc_baseline, load_local_flow_truth
from synth.maneuvers import MANEUVER_KINDS, ManeuverSpec
from synth.workers import worker_pool

CAMPAIGN_DIR = Path(__file__).resolve().parent.parent / "campaigns"
_TOP_KEYS = {
    "name", "description", "fleet", "seed", "common_rate_hz", "environment", "errors", "flights",
    "local_flow_truth", "adc_baseline",
}
_BLOCK_KEYS = {"configurations", "mach", "maneuvers", "altitude_m", "gear_down", "maneuver"}


class CampaignError(ValueError):
    """A campaign file that cannot be flown as written."""


def _deep_merge(base: Mapping, override: Mapping) -> dict:
    out = copy.deepcopy(dict(base))
    for k, v in override.items():
        if isinstance(v, Mapping) and isinstance(out.get(k), Mapping):
            out[k] = _deep_merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


@dataclass(frozen=True)
class Job:
    """One maneuver to fly: everything a worker process needs, as plain data."""

    index: int
    configuration_id: str
    maneuver: dict
    environment: dict
    errors: dict


@dataclass(frozen=True)
class Campaign:
    """A parsed campaign file. ``jobs`` lists the maneuvers in their stable order."""

    name: str
    description: str
    fleet: Fleet
    seed: int
    common_rate_hz: float
    jobs: tuple[Job, ...]
    source: str
    local_flow_truth: str = "local_flow_truth"
    adc_baseline: str = "adc_baseline"
    raw: dict = field(repr=False, default_factory=dict)


def resolve_campaign_path(name_or_path: str | Path) -> Path:
    """A campaign file path, or the name of one shipped in ``campaigns/`` (e.g. ``default``)."""
    p = Path(name_or_path)
    if p.is_file():
        return p
    shipped = CAMPAIGN_DIR / f"{p.name}.toml"
    if len(p.parts) == 1 and not p.suffix and shipped.exists():  # a bare name, never a mistyped path
        return shipped
    raise FileNotFoundError(
        f"{name_or_path}: no such campaign file, nor a campaign shipped in {CAMPAIGN_DIR} "
        f"(shipped: {sorted(q.stem for q in CAMPAIGN_DIR.glob('*.toml'))})"
    )


def parse_campaign(raw: Mapping, source: str = "<dict>") -> Campaign:
    """Validate a campaign mapping (as read from TOML) and expand it into jobs."""
    check(raw, sorted(_TOP_KEYS), source, CampaignError)
    fleet = load_fleet(raw.get("fleet", "fleet_default"))
    seed = int(raw.get("seed", 0))
    env_base = dict(raw.get("environment", {}))
    errors_raw = dict(raw.get("errors", {}))
    per_aircraft = errors_raw.pop("aircraft", {})
    bad = sorted(a for a in per_aircraft if a not in fleet.aircraft)
    if bad:
        raise unknown(bad, sorted(fleet.aircraft), f"{source}: [errors.aircraft]", CampaignError,
                      what="aircraft id")
    blocks = raw.get("flights", [])
    if not blocks:
        raise CampaignError(f"{source}: no [[flights]] block; add one (see campaigns/default.toml)")
    jobs: list[Job] = []
    for b, block in enumerate(blocks):
        where = f"{source}: flights[{b}]"
        check(block, sorted(_BLOCK_KEYS), where, CampaignError)
        configs = block.get("configurations", "all")
        configs = list(fleet.configurations) if configs == "all" else list(configs)
        for c in configs:
            fleet.configuration(c)  # raises with the list of known ids
        kinds = block.get("maneuvers", "all")
        kinds = list(MANEUVER_KINDS) if kinds == "all" else list(kinds)
        bad = [k for k in kinds if k not in MANEUVER_KINDS]
        if bad:
            raise unknown(bad, MANEUVER_KINDS, where, CampaignError, what="maneuver")
        machs = block.get("mach")
        if not machs:
            raise CampaignError(f"{where}: give `mach = [...]`, the Mach numbers to fly")
        extra = dict(block.get("maneuver", {}))
        for cid in configs:
            aircraft_id = fleet.configurations[cid].aircraft.id
            errors = _deep_merge(errors_raw, per_aircraft.get(aircraft_id, {}))
            for mach in machs:
                for kind in kinds:
                    spec = {
                        "kind": kind,
                        "mach": float(mach),
                        "altitude_m": float(block.get("altitude_m", 6000.0)),
                        "gear_down": bool(block.get("gear_down", False)),
                        **extra,
                    }
                    index = len(jobs)
                    env = dict(env_base)
                    # each maneuver its own turbulence realisation, reproducible from the master seed
                    env["turbulence_seed"] = int(env_base.get("turbulence_seed", seed)) + index
                    jobs.append(Job(index, cid, spec, env, errors))
    # validate every spec and error config up front: a typo fails before an hour of flying
    for job in jobs:
        try:
            ManeuverSpec.from_dict(job.maneuver)
            Environment.from_dict(job.environment)
            ErrorConfig.from_dict(job.errors, seed=seed)
        except (ValueError, KeyError, TypeError) as exc:
            raise CampaignError(f"{source}: maneuver {job.index} ({job.configuration_id}, "
                                f"{job.maneuver['kind']}, Mach {job.maneuver['mach']}): {exc}") from exc
    models = {k: str(raw.get(k, k)) for k in ("local_flow_truth", "adc_baseline")}
    try:
        load_local_flow_truth(models["local_flow_truth"])
        load_adc_baseline(models["adc_baseline"])
    except (FileNotFoundError, ValueError) as exc:
        raise CampaignError(f"{source}: {exc}") from None
    return Campaign(
        **models,
        name=str(raw.get("name", Path(source).stem)),
        description=str(raw.get("description", "")),
        fleet=fleet,
        seed=seed,
        common_rate_hz=float(raw.get("common_rate_hz", 40.0)),
        jobs=tuple(jobs),
        source=source,
        raw=dict(raw),
    )


def load_campaign(name_or_path: str | Path) -> Campaign:
    """Read and validate a campaign TOML file (path or shipped name)."""
    path = resolve_campaign_path(name_or_path)
    try:
        with open(path, "rb") as fh:
            raw = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise CampaignError(f"{path}: not valid TOML: {exc}") from None
    return parse_campaign(raw, source=str(path))


def software_versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for pkg in ("fpr-testbed", "jsbsim", "numpy", "scipy", "pandas", "pyarrow"):
        try:
            out[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out


@dataclass(frozen=True)
class JobResult:
    index: int
    entries: tuple[dict, ...]
    error: str | None = None
    elapsed_s: float = 0.0


# The worker state: set once per process so the fleet is not pickled with every job.
_WORKER: dict = {}


def _init_worker(fleet_source: str, out_dir: str, common_rate_hz: float, seed: int,
                 local_flow_truth: str, adc_baseline: str) -> None:
    """Load the worker state (in this process, or in each pool worker: :func:`worker_pool`)."""
    _WORKER.update(
        fleet=load_fleet(fleet_source), out_dir=Path(out_dir), rate=common_rate_hz, seed=seed,
        truth_model=load_local_flow_truth(local_flow_truth), adc=load_adc_baseline(adc_baseline),
    )


def _run_job(job: Job) -> JobResult:
    import time

    t0 = time.perf_counter()
    fleet: Fleet = _WORKER["fleet"]
    cfg = fleet.configuration(job.configuration_id)
    spec = ManeuverSpec.from_dict(job.maneuver)
    env = Environment.from_dict(job.environment)
    errors = ErrorConfig.from_dict(job.errors, seed=_WORKER["seed"])
    try:
        segments = fly_maneuver(spec, fleet.airframe, cfg.aircraft, env)
    except FlightError as exc:
        return JobResult(job.index, (), error=f"FlightError: {exc}", elapsed_s=time.perf_counter() - t0)
    except Exception as exc:  # a bug or JSBSim failure: keep the traceback, keep the campaign going
        return JobResult(
            job.index, (), error=f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}",
            elapsed_s=time.perf_counter() - t0,
        )
    entries = []
    for seg_no, truth in enumerate(segments):
        inst = instrument(truth, fleet.airframe, cfg, errors, maneuver_key=maneuver_key(job.index, seg_no),
                          common_rate_hz=_WORKER["rate"], truth_model=_WORKER["truth_model"],
                          adc_baseline=_WORKER["adc"])
        entry = RecordedPiece(job_index=job.index, segment=seg_no, n_segments=len(segments),
                              configuration=cfg, spec=spec, environment=env, truth=truth,
                              instrumented=inst, sample_rate_hz=_WORKER["rate"]).manifest_entry()
        write_maneuver(_WORKER["out_dir"] / entry["file"], inst.data, entry)
        entries.append(entry)
    return JobResult(job.index, tuple(entries), elapsed_s=time.perf_counter() - t0)


@dataclass(frozen=True)
class FlyResult:
    """What `fly_campaign` did: the dataset directory, its manifest, failures and timing.

    ``flown`` is the number of jobs flown by this call (less than the campaign's on a resume);
    ``notes`` what the user should know (a damaged file of an interrupted dataset, flown again).
    """

    out_dir: Path
    manifest: dict
    failures: tuple[tuple[Job, str], ...]
    wall_s: float
    flown: int = 0
    notes: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        return not self.failures


class FlyInterrupted(KeyboardInterrupt):
    """`fly_campaign` stopped by Ctrl-C (or a signal turned into KeyboardInterrupt): the dataset
    is left incomplete and can be completed with ``resume=True`` (``fpr fly --resume``)."""

    def __init__(self, out_dir: Path, n_done: int, n_jobs: int):
        self.out_dir, self.n_done, self.n_jobs = Path(out_dir), n_done, n_jobs
        super().__init__(
            f"interrupted: {n_done} of {n_jobs} maneuvers written to {out_dir}; resume with: "
            f"{resume_command(out_dir)}")

    def __str__(self) -> str:
        return str(self.args[0])


def _job_files(job: Job) -> list[str]:
    """The files a job writes: one per segment of its maneuver (see :func:`_run_job`)."""
    n = ManeuverSpec.from_dict(job.maneuver).n_segments
    return [maneuver_file(maneuver_id(job.index, k, n)) for k in range(n)]


def manifest_header(campaign: Campaign) -> dict:
    """Everything of the manifest but the flown maneuvers: the same before and after the flight,
    and for an interrupted run and its resumption (no time, no timing)."""
    return _jsonable({
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "campaign": {
            "name": campaign.name,
            "description": campaign.description,
            "source": campaign.source,
            "seed": campaign.seed,
            "definition": campaign.raw,
            "local_flow_truth": campaign.local_flow_truth,
            "adc_baseline": campaign.adc_baseline,
        },
        "software": software_versions(),
        "airframe": airframe_manifest(campaign.fleet.airframe),
        "fleet": {
            "source": campaign.fleet.source,
            "aircraft": {
                a.id: {
                    "installation_bias_rad": dict(a.installation_bias_rad),
                    "fuel_kg": a.fuel_kg,
                    "ballast_kg": a.ballast_kg,
                    "ballast_position_body_m": a.ballast_position_body_m.tolist(),
                }
                for a in campaign.fleet.aircraft.values()
            },
            "configurations": {
                c.id: {"aircraft": c.aircraft.id, "nose_sensor": c.nose_sensor, "sensors": list(c.sensors)}
                for c in campaign.fleet.configurations.values()
            },
        },
        "common_rate_hz": campaign.common_rate_hz,
        "jobs": [{"job_index": j.index, "configuration": j.configuration_id, "maneuver": j.maneuver,
                  "files": _job_files(j)} for j in campaign.jobs],
    })


def _normalized(obj):
    """``obj`` as it reads back from JSON (so a manifest and a fresh header compare equal)."""
    return json.loads(json.dumps(_jsonable(obj), sort_keys=True))


def _check_same_campaign(out_dir: Path, stored: Mapping, header: dict) -> None:
    """Refuse to resume ``out_dir`` with a campaign, fleet or software other than its own."""
    fresh = _normalized(header)
    legacy = stored.get("complete", True) is not False and "jobs" not in stored
    diffs = []
    for key, value in fresh.items():
        if key not in stored and legacy:  # a dataset written before the key existed
            continue
        old = stored.get(key)
        if old == value:
            continue
        if isinstance(old, dict) and isinstance(value, dict):
            sub = sorted(k for k in set(old) | set(value) if old.get(k) != value.get(k))
            if key == "software":
                sub = [f"{k} {old.get(k)} (dataset) vs {value.get(k)} (now)" for k in sub]
            diffs.append(f"{key}: {', '.join(sub)}")
        else:
            diffs.append(key)
    if diffs and _normalized(stored.get("campaign", {}).get("definition")) == fresh["campaign"]["definition"]:
        # the dataset's own campaign: resuming it again with the same command cannot help
        raise CampaignError(
            f"{out_dir}: cannot resume: the manifest differs from its own campaign as it reads today "
            f"in {'; '.join(diffs)}: the fleet or model files, or the software, changed since the "
            "dataset was started, or the manifest was edited. Resuming would mix the two: restore "
            f"what changed (or the manifest), or move {out_dir} aside and fly the campaign again "
            "into a new --out")
    if diffs:
        raise CampaignError(
            f"{out_dir}: cannot resume: the dataset was started with another campaign or software; "
            f"differences in {'; '.join(diffs)}. Resume with the dataset's own campaign "
            f"(`{resume_command(out_dir)}` reads it from the manifest), or fly this campaign into a "
            "new --out (or replace the dataset with --overwrite)")


def _clear_damaged(out_dir: Path, damaged: Sequence[tuple[str, str]]) -> list[str]:
    """Remove the damaged maneuver files of an interrupted dataset (:func:`synth.dataset.job_entries`:
    files of the names fpr fly writes there, for jobs it has not finished), so that their jobs are
    flown again and a failed flight leaves no damaged file behind; one note per file.

    Raises
    ------
    FileExistsError
        If one is a folder: not something fpr fly wrote, left alone.
    """
    folders = [rel for rel, _ in damaged if (out_dir / rel).is_dir() and not (out_dir / rel).is_symlink()]
    if folders:
        raise FileExistsError(
            f"{out_dir}: {', '.join(folders)}: a folder where `fpr fly` writes a maneuver file; "
            f"refusing to resume. Move it away and resume again: {resume_command(out_dir)}")
    notes = []
    for rel, why in damaged:
        (out_dir / rel).unlink()
        notes.append(f"{out_dir / rel}: damaged ({why}): removed, its maneuver is flown again "
                     "(fpr fly wrote this name)")
    return notes


def campaign_of_dataset(out_dir: str | Path) -> Campaign:
    """The campaign a dataset (complete or interrupted) was flown from, as its manifest records it.

    Raises
    ------
    FileNotFoundError
        If ``out_dir`` holds no dataset manifest.
    """
    out_dir = Path(out_dir)
    damage = damaged_manifest(out_dir)
    if damage is not None:
        raise CampaignError(f"cannot resume: {damage}")
    stored = read_manifest_if_dataset(out_dir)
    if stored is None or "definition" not in stored.get("campaign", {}):
        raise FileNotFoundError(
            f"{out_dir}: no dataset to resume (no {out_dir / 'manifest.json'} written by `fpr fly` "
            "with its campaign); give the campaign to fly it anew")
    camp = stored["campaign"]
    return parse_campaign(camp["definition"], source=str(camp.get("source", out_dir)))


def _reopen_interrupted(out_dir: Path, stored: Mapping) -> tuple[dict[int, list[dict]], list[str]]:
    """Make an interrupted dataset ready to be completed: (job index -> manifest entries of the jobs
    whose files are whole, notes on the damaged files removed)."""
    maneuvers = out_dir / "maneuvers"
    if maneuvers.is_symlink() or (maneuvers.exists() and not maneuvers.is_dir()):
        # through a link the resume would read and write outside the dataset
        raise FileExistsError(
            f"{maneuvers}: {'a link' if maneuvers.is_symlink() else 'not a folder'}, not the "
            "maneuvers/ folder `fpr fly` made; refusing to resume (nothing is read or written "
            f"through it). Put the dataset's own maneuvers/ folder back, or fly the campaign "
            "into a new --out")
    remove_temp_files(out_dir)
    maneuvers.mkdir(exist_ok=True)
    # each whole file carries its manifest entry: the finished jobs need not be flown again
    done, damaged = job_entries(out_dir, stored)
    return done, _clear_damaged(out_dir, damaged)


class _Progress:
    """Says each finished job: on a tqdm bar (``progress=True``) or by ``progress(done, total)``."""

    def __init__(self, campaign: Campaign, n_done: int, notes: Sequence[str],
                 progress: Callable[[int, int], None] | bool) -> None:
        self.n_done, self.total = n_done, len(campaign.jobs)
        self.callback = progress if callable(progress) else None
        self.bar = None
        if progress is True:
            from tqdm import tqdm

            self.bar = tqdm(total=self.total, initial=n_done, unit="maneuver",
                            desc=f"fly {campaign.name}", file=sys.stderr,
                            mininterval=0.5 if sys.stderr.isatty() else 10.0)
            for note in notes:
                self.bar.write(note, file=sys.stderr)

    def tick(self, res: JobResult) -> None:
        self.n_done += 1
        if self.bar is not None:
            self.bar.update(1)
            if res.error:
                self.bar.write(f"maneuver {res.index} failed: {res.error.splitlines()[0]}")
        elif self.callback is not None:
            self.callback(self.n_done, self.total)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


#: The default pool (``workers`` None or 0) has one worker per this many maneuvers to fly, or part
#: of it, at most one per CPU: a worker's start (the fork server's imports, each worker's JSBSim
#: model) costs about the CPU time of flying three or four maneuvers, which a small campaign does
#: not win back. Measured on 2 cores: 10 maneuvers fly in 4.0 s in this process, in 3.8-5.1 s and
#: twice the CPU time with two workers; 30 maneuvers in 12 s in this process, 7.5-8.0 s with two.
MANEUVERS_PER_DEFAULT_WORKER = 12


def pool_size(workers: int | None, n_jobs: int) -> int:
    """Worker processes that fly ``n_jobs`` maneuvers: ``workers`` (None or 0: the default pool,
    :data:`MANEUVERS_PER_DEFAULT_WORKER`), never more than the maneuvers; 1 flies them in this
    process."""
    if not workers:
        workers = min(os.cpu_count() or 1, -(-n_jobs // MANEUVERS_PER_DEFAULT_WORKER))
    return max(1, min(workers, n_jobs))


def _fly_jobs(campaign: Campaign, out_dir: Path, todo: Sequence[Job], workers: int | None,
              progress: _Progress) -> list[JobResult]:
    """Fly ``todo`` (in this process, or in a pool of :func:`pool_size` workers), each job writing
    its files.

    Raises
    ------
    FlyInterrupted
        On KeyboardInterrupt: the workers are stopped and their maneuvers left unwritten.
    """
    workers = pool_size(workers, len(todo))
    init_args = (campaign.fleet.source, str(out_dir), campaign.common_rate_hz, campaign.seed,
                 campaign.local_flow_truth, campaign.adc_baseline)
    results: list[JobResult] = []

    def _tick(res: JobResult) -> None:
        results.append(res)
        progress.tick(res)

    try:
        if workers == 1:
            _init_worker(*init_args)
            for job in todo:
                _tick(_run_job(job))
        elif todo:
            # the workers end with this process however it ends, and leave Ctrl-C to it: on an
            # interrupt (or an error) they are stopped at once, their maneuvers left unwritten
            with worker_pool(workers, _init_worker, init_args) as pool:
                for fut in as_completed([pool.submit(_run_job, job) for job in todo]):
                    _tick(fut.result())
    except KeyboardInterrupt:
        progress.close()
        remove_temp_files(out_dir)
        raise FlyInterrupted(out_dir, dataset_status(out_dir).n_done, len(campaign.jobs)) from None
    progress.close()
    return results


def _complete_manifest(campaign: Campaign, header: dict, done: Mapping[int, list[dict]],
                       results: Sequence[JobResult]) -> tuple[dict, tuple[tuple[Job, str], ...]]:
    """The finished dataset's manifest (entries in the campaign's job order, whether flown now or
    before an interruption) and the failures of the jobs flown now."""
    jobs = {j.index: j for j in campaign.jobs}
    flown = {r.index: r for r in results}
    entries = [e for j in campaign.jobs
               for e in (done[j.index] if j.index in done else flown[j.index].entries)]
    failures = tuple((jobs[r.index], r.error) for r in sorted(results, key=lambda r: r.index) if r.error)
    manifest = {
        **header,
        "complete": True,
        "maneuvers": entries,
        "failures": [
            {"job_index": j.index, "configuration": j.configuration_id, "maneuver": j.maneuver,
             "error": err}
            for j, err in failures
        ],
    }
    return manifest, failures


def fly_campaign(
    campaign: Campaign,
    out_dir: str | Path,
    *,
    workers: int | None = None,
    overwrite: bool = False,
    resume: bool = False,
    progress: Callable[[int, int], None] | bool = False,
) -> FlyResult:
    """Fly every maneuver of a campaign and write the dataset.

    Parameters
    ----------
    campaign : from :func:`load_campaign` (to resume: :func:`campaign_of_dataset`).
    out_dir : the dataset directory to create.
    workers : worker processes (default: one per :data:`MANEUVERS_PER_DEFAULT_WORKER`
        maneuvers, at most one per CPU; 1 flies in this process).
    overwrite : replace a dataset at ``out_dir`` (only the files it wrote are removed; a directory
        holding anything else is refused).
    resume : complete the interrupted dataset at ``out_dir``: fly only the jobs whose files are
        missing (refused if its manifest records another campaign); the result is byte-identical to
        an uninterrupted run. On a new or empty directory, fly the whole campaign.
    progress : show a tqdm progress bar (True) or call ``progress(done, total)``.

    Failed maneuvers (departure, controller could not hold its target) are listed in the
    manifest's ``failures`` and in the result; the others are still written.

    Raises
    ------
    FlyInterrupted
        On KeyboardInterrupt (Ctrl-C): the workers are stopped, the dataset stays incomplete and
        says so; the exception's message says how to resume.
    FileExistsError
        If ``out_dir`` cannot be used (see :func:`synth.dataset.prepare_directory`).
    CampaignError
        If ``resume`` and the dataset was started with another campaign.
    """
    import time

    if overwrite and resume:
        raise ValueError("overwrite and resume exclude each other: replace the dataset or complete it")
    t0 = time.perf_counter()
    out_dir = Path(out_dir)
    header = manifest_header(campaign)
    stored = read_manifest_if_dataset(out_dir) if resume and out_dir.is_dir() else None
    if resume and (damage := damaged_manifest(out_dir)) is not None:
        raise CampaignError(f"cannot resume: {damage}")
    done: dict[int, list[dict]] = {}
    notes: list[str] = []
    if stored is not None:
        # the manifest's own source label stays: the same file may be named another way today
        header["campaign"]["source"] = stored.get("campaign", {}).get("source", campaign.source)
        _check_same_campaign(out_dir, stored, header)
        if stored.get("complete", True) is not False:
            jobs = {j.index: j for j in campaign.jobs}
            failures = tuple((jobs[f["job_index"]], f["error"]) for f in stored.get("failures", [])
                             if f.get("job_index") in jobs)
            return FlyResult(out_dir, stored, failures, time.perf_counter() - t0, flown=0)
        done, notes = _reopen_interrupted(out_dir, stored)
    else:
        out_dir = prepare_directory(out_dir, overwrite=overwrite)
        # first, before any maneuver: at every moment the directory says it is an incomplete dataset
        write_manifest(out_dir, {**header, "complete": False, "maneuvers": [], "failures": []})
    todo = [j for j in campaign.jobs if j.index not in done]
    results = _fly_jobs(campaign, out_dir, todo, workers, _Progress(campaign, len(done), notes, progress))
    manifest, failures = _complete_manifest(campaign, header, done, results)
    # no wall-clock time or timing in the manifest: two identical campaigns, or an interrupted
    # one and its resumption, give the same bytes
    write_manifest(out_dir, manifest)
    return FlyResult(out_dir, _normalized(manifest), failures, time.perf_counter() - t0, flown=len(todo),
                     notes=tuple(notes))


def summarize(manifest: Mapping) -> str:
    """A short text summary of a dataset manifest: counts per kind, Mach, configuration."""
    import pandas as pd

    man = pd.DataFrame(manifest["maneuvers"])
    lines = [f"dataset: {len(man)} maneuver files, "
             f"{int(man['n_samples'].sum()) if len(man) else 0} samples, "
             f"{man['duration_s'].sum() if len(man) else 0:.0f} s of flight"]
    if len(man):
        tab = pd.crosstab(man["kind"], man["mach_nominal"].round(2), margins=True, margins_name="all")
        lines.append("maneuvers per kind and Mach:")
        lines.append(tab.to_string())
        lines.append("per configuration: " + ", ".join(
            f"{k} {v}" for k, v in man.groupby("configuration").size().items()))
        lines.append(f"gear-down maneuvers: {int(man['gear_down'].sum())}")
    if manifest.get("failures"):
        lines.append(f"FAILED: {len(manifest['failures'])} maneuver(s):")
        for f in manifest["failures"]:
            lines.append(f"  job {f['job_index']} {f['configuration']} {f['maneuver']['kind']} "
                         f"Mach {f['maneuver']['mach']}: {f['error'].splitlines()[0]}")
    return "\n".join(lines)


@dataclass(frozen=True)
class CampaignFlags:
    """A one-block campaign as command-line flags describe it (``fpr fly`` without a campaign file).

    ``["all"]``, as a command line gives it, means "all" for the configurations and the maneuvers.
    """

    configurations: Sequence[str] | str = "all"
    mach: Sequence[float] = (0.5,)
    maneuvers: Sequence[str] | str = "all"
    altitude_m: float = 6000.0
    gear_down: bool = False
    seed: int = 0
    errors_preset: str = "typical"
    planet: str = "flat"
    turbulence: str = "none"
    wind_ned_mps: Sequence[float] = (0.0, 0.0, 0.0)
    common_rate_hz: float = 40.0
    fleet: str = "fleet_default"

    def campaign(self) -> dict:
        """The campaign mapping (for :func:`parse_campaign`)."""
        configurations, maneuvers = self.configurations, self.maneuvers
        if configurations == "all" or list(configurations) == ["all"]:
            configurations = "all"
        if maneuvers == "all" or list(maneuvers) == ["all"]:
            maneuvers = "all"
        return {
            "name": "flags",
            "description": "campaign given by command-line flags",
            "fleet": self.fleet,
            "seed": self.seed,
            "common_rate_hz": self.common_rate_hz,
            "environment": {"planet": self.planet, "turbulence": self.turbulence,
                            "wind_ned_mps": list(self.wind_ned_mps)},
            "errors": {"preset": self.errors_preset},
            "flights": [{
                "configurations": configurations if configurations == "all" else list(configurations),
                "mach": list(self.mach),
                "maneuvers": maneuvers if maneuvers == "all" else list(maneuvers),
                "altitude_m": self.altitude_m,
                "gear_down": self.gear_down,
            }],
        }


def flags_campaign(**flags) -> dict:
    """A one-block campaign mapping built from command-line flags: ``flags`` are
    :class:`CampaignFlags`' fields (an unknown one is a TypeError)."""
    return CampaignFlags(**flags).campaign()
