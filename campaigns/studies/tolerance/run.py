"""Planning study (c), its runs: every distinct point's Monte Carlo run, each in one process,
resumable."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path

from campaigns.montecarlo import ScenarioError, parse_scenario, run_montecarlo
from campaigns.studies import scaffold
from campaigns.studies.tolerance.config import Point, StudyConfig, study_points


def _run_point(raw: dict, directory: str, replications: int) -> tuple[str, float, str, int]:
    """Run (or resume) one point's Monte Carlo in this process: (directory, wall s, error text,
    replications computed now)."""
    t0 = time.perf_counter()
    try:
        scenario = parse_scenario(raw, source=f"campaigns.studies.tolerance:{raw['name']}")
        report = run_montecarlo(scenario, directory, replications=replications, workers=1)
    except ScenarioError as exc:  # a maneuver that cannot be flown in this air: the point says so
        return directory, time.perf_counter() - t0, str(exc), 0
    return directory, time.perf_counter() - t0, "", len(report.ran)


def run_points(points: Sequence[Point], replications: int, workers: int,
               log: Callable[[str], None] = print) -> tuple[dict[Path, str], int]:
    """Run every distinct point's Monte Carlo (each in one process, ``workers`` at a time; the
    runs are resumable). Returns directory -> error text of the points that could not run, and
    the number of replications computed now."""
    unique: dict[Path, dict] = {}
    for p in points:
        unique.setdefault(p.directory, p.raw)
    # the reflown ones (turbulence) first: they are the longest
    order = sorted(unique, key=lambda d: unique[d]["environment"].get("turbulence", "none") == "none")
    errors: dict[Path, str] = {}
    ran = [0]

    def done(result: tuple[str, float, str, int]) -> None:
        directory, wall_s, error, n_ran = result
        note = f"  ERROR {error.splitlines()[0]}" if error else ""
        log(f"  {Path(directory).name}: {n_ran} replications in {wall_s:.1f} s{note}")
        ran[0] += n_ran
        if error:
            errors[Path(directory)] = error

    scaffold.run_in_processes(_run_point, [(unique[d], str(d), replications) for d in order], workers, done)
    return errors, ran[0]


def run(config: StudyConfig, out_dir: Path, replications: int, workers: int,
        log: Callable[[str], None] = print) -> tuple[int, dict[Path, str]]:
    """Run (or resume) the study into ``out_dir/points``: the replications computed now, and
    directory -> error text of the points that could not run (for :func:`~.analysis.collect`)."""
    points = study_points(config, out_dir)
    log(f"{len({q.directory for q in points})} distinct runs x {replications} replications into "
        f"{out_dir}/points")
    errors, n_ran = run_points(points, replications, workers, log)
    return n_ran, errors
