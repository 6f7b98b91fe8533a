"""The scaffold every planning study stands on: its command line, its runs, its invocation record,
its results files.

A study declares itself as a :class:`Study` (its name, sizes, and four functions of its own: run,
analyse, report, plot; a table for the CSV when it writes one) and its ``main`` is
``scaffold.main(STUDY, argv)``. The scaffold parses the shared arguments (``--out``, ``--results``,
``--replications``, ``--workers``, ``--size``), records the invocation
(:mod:`campaigns.studies.invocations`: cost and code, kept beside the runs so that a resumed study
states what all its invocations cost), and writes ``NAME.txt``, ``NAME.csv`` (when the study has a
table) and ``NAME.png`` into ``--results``. It also holds what the studies' own parts share: running
Monte Carlo scenarios one after the other (:func:`run_scenarios`) or tasks in worker processes
(:func:`run_in_processes`), the report's header (:func:`header_lines`) and its number and paragraph
formatting (:func:`fmt`, :func:`paragraph`).
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
import textwrap
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from campaigns.montecarlo import parse_scenario, run_montecarlo
from campaigns.studies.invocations import Invocation, invocations_text, machine_text
from synth.workers import worker_pool

Log = Callable[[str], None]
#: one record per invocation (:class:`~campaigns.studies.invocations.Invocation`)
Invocations = Sequence[Mapping[str, Any]]


@dataclass(frozen=True)
class Study:
    """What a study is to the scaffold.

    Attributes
    ----------
    name : ``python -m campaigns.studies.NAME``; its results are ``NAME.txt`` / ``.csv`` / ``.png``.
    file : the study's code (a module file or its package folder): its uncommitted changes count
        in the code version of the invocation record.
    description : the command's help.
    sizes : size name -> configuration (an object with ``replications``, the default N); ``full``
        is the committed study.
    unit : what one Monte Carlo run of the study is ("set", "variant", "point", "scale").
    workers_help, size_help : the help of ``--workers`` and ``--size``.
    run : ``(config, out_dir, replications, workers, log) -> (replications computed now, outcome)``;
        resumable; ``outcome`` is passed to ``analyse`` (what the run knows that the files do not).
    analyse : ``(config, out_dir, replications, outcome) -> analysis``.
    report : ``(analysis, config, replications, command, invocations) -> text``.
    plot : ``(analysis, config, path, replications) -> path``.
    table : ``analysis -> DataFrame`` written as ``NAME.csv`` (None: no CSV).
    """

    name: str
    file: str | Path
    description: str
    sizes: Mapping[str, Any]
    unit: str
    workers_help: str
    size_help: str
    run: Callable[[Any, Path, int, int, Log], tuple[int, Any]]
    analyse: Callable[[Any, Path, int, Any], Any]
    report: Callable[[Any, Any, int, str, Invocations], str]
    plot: Callable[[Any, Any, Path, int], Path]
    table: Callable[[Any], pd.DataFrame] | None = None

    @property
    def module(self) -> str:
        return f"campaigns.studies.{self.name}"

    @property
    def invocations_file(self) -> str:
        """The invocation record's name in the work directory."""
        return f"{self.name}_invocations.json"

    @property
    def outputs(self) -> list[str]:
        return [f"{self.name}.txt", *([f"{self.name}.csv"] if self.table is not None else []),
                f"{self.name}.png"]


@dataclass(frozen=True)
class Arguments:
    """The parsed command line: work and results directories, N, worker processes, the size's
    configuration and the command as typed (for the report's header)."""

    out: Path
    results: Path
    replications: int
    workers: int
    size: str
    config: Any
    command: str


def parse_arguments(study: Study, argv: Sequence[str] | None = None) -> Arguments:
    """Parse a study's command line (``sys.argv[1:]`` when ``argv`` is None)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    p = argparse.ArgumentParser(prog=f"python -m {study.module}", description=study.description)
    p.add_argument("--out", required=True, type=Path, help=f"work directory (each {study.unit}'s run)")
    p.add_argument("--results", type=Path, default=None,
                   help=f"where {' / '.join(study.outputs)} go (default: --out)")
    defaults = ", ".join(f"{k} {c.replications}" for k, c in study.sizes.items())
    p.add_argument("--replications", type=int, default=None, metavar="N",
                   help=f"replications per {study.unit} (default: {defaults})")
    p.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1), help=study.workers_help)
    p.add_argument("--size", choices=sorted(study.sizes), default="full", help=study.size_help)
    args = p.parse_args(argv)
    config = study.sizes[args.size]
    n = config.replications if args.replications is None else args.replications
    if n < 1:
        p.error(f"--replications must be at least 1 (it is {n})")
    return Arguments(out=args.out, results=args.results or args.out, replications=n, workers=args.workers,
                     size=args.size, config=config, command=f"python -m {study.module} " + shlex.join(argv))


def log_stderr(text: str) -> None:
    """Progress of a study: to stderr, so that stdout carries the report alone."""
    print(text, file=sys.stderr, flush=True)


def main(study: Study, argv: Sequence[str] | None = None) -> int:
    """Run (or resume) a study and write its results; returns the exit status (0).

    The invocation is recorded in ``OUT/<name>_invocations.json`` after the runs and the analysis
    (which may fly maneuvers too), before the report that states its cost.
    """
    args = parse_arguments(study, argv)
    args.results.mkdir(parents=True, exist_ok=True)
    args.out.mkdir(parents=True, exist_ok=True)
    invocation = Invocation(study.file)
    computed, outcome = study.run(args.config, args.out, args.replications, args.workers, log_stderr)
    analysis = study.analyse(args.config, args.out, args.replications, outcome)
    invocations = invocation.finish(args.out / study.invocations_file, args.command, computed)
    text = study.report(analysis, args.config, args.replications, args.command, invocations)
    write_results(study, args.results, text, analysis,
                  lambda path: study.plot(analysis, args.config, path, args.replications))
    print(text)
    return 0


def write_results(study: Study, results: Path, text: str, analysis: Any, plot: Callable[[Path], Any]) -> None:
    """``NAME.txt``, ``NAME.csv`` (a study with a table) and ``NAME.png`` into ``results``."""
    (results / f"{study.name}.txt").write_text(text)
    if study.table is not None:
        study.table(analysis).to_csv(results / f"{study.name}.csv", index=False)
    plot(results / f"{study.name}.png")


# ---------------------------------------------------------------------------- running


def run_scenarios(runs: Sequence[tuple[str, dict]], out_dir: Path, replications: int, workers: int,
                  log: Log = log_stderr) -> int:
    """Run (or resume) each Monte Carlo scenario into ``out_dir/runs/NAME``, one after the other,
    each with ``workers`` processes. Returns the number of replications computed (not already on
    disk)."""
    computed = 0
    for k, (name, raw) in enumerate(runs):
        scenario = parse_scenario(raw, source=f"{raw['name']} (built by campaigns.studies)")
        report = run_montecarlo(scenario, out_dir / "runs" / name, replications=replications, workers=workers)
        computed += len(report.ran)
        log(f"[{k + 1}/{len(runs)}] {report.text()}")
    return computed


def monte_carlo_runs(members: Callable[[Any], Iterable[Any]], scenario: Callable[[Any, Any, int], dict]
                     ) -> Callable[[Any, Path, int, int, Log], tuple[int, None]]:
    """A :attr:`Study.run` of one Monte Carlo run per member of the configuration (each with a
    ``name``: its directory ``OUT/runs/NAME``), with :func:`run_scenarios`.

    Parameters
    ----------
    members : configuration -> its members (maneuver sets, variants...).
    scenario : ``(member, configuration, replications) ->`` the member's scenario mapping.
    """

    def run(config: Any, out_dir: Path, replications: int, workers: int, log: Log) -> tuple[int, None]:
        runs = [(m.name, scenario(m, config, replications)) for m in members(config)]
        return run_scenarios(runs, out_dir, replications, workers, log), None

    return run


def run_in_processes(task: Callable[..., Any], calls: Iterable[tuple], workers: int,
                     done: Callable[[Any], None]) -> None:
    """``task(*call)`` for every call, ``workers`` at a time in worker processes (1: in this process,
    in order); ``done`` receives each result in this process as it comes. The workers end with this
    process (Ctrl-C stops them)."""
    calls = list(calls)
    if workers <= 1:
        for call in calls:
            done(task(*call))
        return
    if not calls:
        return
    with worker_pool(workers) as pool:
        futures = [pool.submit(task, *call) for call in calls]
        for fut in as_completed(futures):
            done(fut.result())


# ---------------------------------------------------------------------------- the report


def header_lines(title: str, command: str, study_file: str | Path, size_line: str,
                 invocations: Invocations) -> list[str]:
    """The report's head: the title paragraph, the command, machine and code, the study's size and
    what its invocations cost; an empty line after."""
    return [*paragraph(title), f"$ {command}",
            *machine_text(study_file, invocations[-1].get("code_start")).splitlines(),
            size_line, *invocations_text(invocations), ""]


def fmt(v: float | None, spec: str = ".3g") -> str:
    """A number for the tables ('-' when missing)."""
    return "-" if v is None or not np.isfinite(v) else format(v, spec)


def paragraph(text: str, width: int = 108) -> list[str]:
    """``text`` wrapped, then an empty line."""
    return [*textwrap.wrap(text, width=width), ""]
