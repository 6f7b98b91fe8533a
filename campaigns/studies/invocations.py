"""What a study run cost and which code ran it: one record per invocation, kept beside its results.

A study is resumable (the same command again computes only the missing replications), so its
committed header must say what all its invocations cost together and which code each ran (other
engineers commit to the shared tree meanwhile). :class:`Invocation` takes the snapshot at the start
and appends the record at the end; :func:`invocations_text` writes the header's cost lines.

CPU time counts this process, its collected children and the workers of its pools
(:func:`synth.workers.workers_cpu_s`: under ``forkserver`` they are the fork server's children, which
``getrusage(RUSAGE_CHILDREN)`` never sees). Not counted: a pool worker's time since its last task
when it was killed, and the fork server's own start. Records written before the workers were
counted (no :data:`CPU_KEY`) state their CPU as "at least".
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from campaigns.machine import cpu_model, memory_gib
from synth.campaign import software_versions
from synth.dataset import atomic_write_bytes
from synth.workers import workers_cpu_s

#: The code every study runs, besides its own file: estimator, synthesizer, engine, truth.
STUDY_CODE = ("estimator", "synth", "aircraft_models", "campaigns/montecarlo", "campaigns/truth.py",
              "campaigns/studies/invocations.py", "campaigns/studies/scaffold.py",
              "campaigns/studies/common.py")
#: the log studies (a) and (b) kept before the scaffold (one JSON line per invocation: wall_s,
#: computed, replications, runs, code); read once, as the history of a new record
LEGACY_LOG = "invocations.jsonl"
#: a record's flag: its ``cpu_s`` includes the pool workers' time (older records missed it under
#: ``forkserver``, by up to the whole computation)
CPU_KEY = "cpu_includes_pool_workers"


def code_version(study_file: str | Path) -> str:
    """The working tree's commit, and whether the code a study runs differs from it.

    Parameters
    ----------
    study_file : the study's own module file (its changes count too).
    """
    root = Path(__file__).resolve().parent.parent.parent
    own = Path(study_file).resolve()
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                cwd=root, check=False).stdout.strip() or "?"
        rel = str(own.relative_to(root)) if own.is_relative_to(root) else str(own)
        dirty = subprocess.run(["git", "status", "--porcelain", "--", *STUDY_CODE, rel], capture_output=True,
                               text=True, cwd=root, check=False).stdout.strip()
    except OSError:
        return "?"
    return commit + (" with uncommitted changes to the code it runs" if dirty else "")


@dataclass
class Invocation:
    """One invocation of a study: started by the constructor, recorded by :meth:`finish`."""

    study_file: str | Path
    t0: float = field(default_factory=time.perf_counter)
    load0: float = field(default_factory=lambda: os.getloadavg()[0])
    started_utc: str = field(default_factory=lambda: datetime.now(UTC).isoformat(timespec="seconds"))
    code0: str = ""

    def __post_init__(self) -> None:
        self.code0 = code_version(self.study_file)

    def finish(self, log_path: Path, command: str, replications_run: int) -> list[dict[str, Any]]:
        """Append this invocation's record to ``log_path`` (atomically) and return every record.

        The record: start time, command, wall and CPU seconds (this process, its children and its
        pools' workers: the module's docstring says what is not counted), replications computed,
        load average at the start and the end, and the code (``start -> end`` when the tree moved
        meanwhile).
        """
        own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
        code1 = code_version(self.study_file)
        record = {"started_utc": self.started_utc, "command": command,
                  "wall_s": time.perf_counter() - self.t0,
                  "cpu_s": (own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime
                            + workers_cpu_s(not_in_children=True)), CPU_KEY: True,
                  "replications_run": replications_run, "load_start": self.load0,
                  "load_end": os.getloadavg()[0], "code_start": self.code0,
                  "code": code1 if code1 == self.code0 else f"{self.code0} -> {code1}"}
        records = json.loads(log_path.read_text()) if log_path.exists() else legacy_records(log_path.parent)
        records.append(record)
        atomic_write_bytes(log_path, (json.dumps(records, indent=1) + "\n").encode())
        return records


def legacy_records(out_dir: Path) -> list[dict[str, Any]]:
    """The invocations of ``out_dir/invocations.jsonl`` (:data:`LEGACY_LOG`) as records; what that log
    did not keep (CPU time, load, start time, command) is None."""
    path = out_dir / LEGACY_LOG
    if not path.exists():
        return []
    lines = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    return [{"started_utc": None, "command": None, "wall_s": e["wall_s"], "cpu_s": None,
             "replications_run": e["computed"], "load_start": None, "load_end": None,
             "code_start": e.get("code", "?"), "code": e.get("code", "?")} for e in lines]


def _num(value: float | None, spec: str) -> str:
    """A number of a record, '?' where the record does not have it (a legacy record)."""
    return "?" if value is None else format(value, spec)


def _total(invocations: Sequence[Mapping[str, Any]], key: str) -> float | None:
    values = [i[key] for i in invocations]
    return None if any(v is None for v in values) else sum(values)


def _cpu(invocations: Sequence[Mapping[str, Any]]) -> str:
    """The CPU seconds of these invocations together: '?' when a record does not have them, "at
    least" when a record's figure missed its pool workers (no :data:`CPU_KEY`)."""
    total = _num(_total(invocations, "cpu_s"), ".0f")
    return total if total == "?" or all(i.get(CPU_KEY) for i in invocations) else f"at least {total}"


def invocations_text(invocations: Sequence[Mapping[str, Any]]) -> list[str]:
    """The cost lines: this invocation, and every one when the study was resumed (the code each
    ran, at its start -> end when the shared tree moved meanwhile)."""
    now = invocations[-1]
    lines = [f"this invocation: wall {now['wall_s']:.0f} s, CPU {_cpu([now])} s in its processes and their "
             f"pool workers, "
             f"{now['replications_run']} replications computed; load average {now['load_start']:.1f} at "
             f"the start, {now['load_end']:.1f} at the end (other jobs share the machine)"]
    if len(invocations) > 1:
        lines.append(f"the replications were computed over {len(invocations)} invocations (resumed): wall "
                     f"{sum(i['wall_s'] for i in invocations):.0f} s, CPU "
                     f"{_cpu(invocations)} s, "
                     f"{sum(i['replications_run'] for i in invocations)} replications in all:")
        lines += [f"  {i.get('started_utc') or '?'}: {i['replications_run']} replications, wall "
                  f"{i['wall_s']:.0f} s, CPU {_cpu([i])} s, code {i['code']}"
                  for i in invocations]
    return lines


def machine_text(study_file: str | Path, code_at_start: str | None = None) -> str:
    """CPU model, cores, memory, software versions and the code's commit (at the start and the end
    of the run: other engineers commit to the shared tree meanwhile)."""
    gib = memory_gib()
    mem = "" if gib is None else f", {gib:.0f} GiB"
    versions = ", ".join(f"{k} {v}" for k, v in software_versions().items())
    end = code_version(study_file)
    code = end if code_at_start in (None, end) else f"{code_at_start} at the start, {end} at the end"
    return (f"machine: {cpu_model()}, {os.cpu_count()} cores{mem}; {versions}\n"
            f"code: {code} (the shared working tree)")
