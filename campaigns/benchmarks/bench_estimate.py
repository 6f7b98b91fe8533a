"""Benchmark: the estimator at the paper's scale — time to converge, iterations, peak memory.

    python campaigns/benchmarks/bench_estimate.py [--sizes 10 20 40 70 140] [--repeat 2]
                                                  [--out campaigns/benchmarks/results/estimate.txt]

The paper estimates 60-70 maneuvers of 30-40 s at once (~80,000 samples, ~1000 free parameters
counting each maneuver's initial conditions and IMU biases; SPEC §8). This benchmark builds such
problems from analytic flights (:mod:`synthetic_fpr`, next to this file: no JSBSim, generated in
memory in about a second; 32 Hz so that 70 maneuvers of 30-40 s make ~80,000 samples; every
channel of the ``tejas`` model set; five aircraft, three with the nose probe and two with the
boom; 13 free initial conditions and IMU biases plus the pressure-altitude scale per maneuver)
and runs :func:`estimator.solver.estimate` with the default options: staged start, honest
deviations (cross-channel residual spectrum, IMU noise as process noise) and fit-quality
diagnostics included. Reported:

- the machine (CPU, cores, memory, library versions);
- the numba compile time of the estimator's kernels, cold (empty cache) and loading them from
  the on-disk cache (``cache=True``): paid once per machine, and once per process respectively,
  and excluded from the timings below (each size runs in its own process after a warm-up);
- per problem size: maneuvers, samples, channel samples (residuals), free parameters, iterations,
  wall time to converge (everything ``estimate`` does: staged start, screening, iterations,
  Cramér-Rao and honest deviations, diagnostics, result), time per iteration, time per maneuver,
  the time spent in the honest deviations (:func:`estimator.uncertainty.honest_std`), the first
  run's wall time, the CPU time
  (the estimator uses two threads on a two-core machine), and the process's peak resident
  memory (problem data included).

Wall times are the best of ``--repeat`` runs in the same process (the machine may be shared),
with the first run reported beside them.
Timing never decides a test; the result table is committed so changes in speed are visible in
review.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]


def _peak_rss_mib() -> float:
    # ru_maxrss is KiB on Linux
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _run_one(n: int, repeat: int, seed: int) -> dict:
    """One problem size, in this process: warm up, then time ``estimate`` (best of ``repeat``)."""
    sys.path.insert(0, str(HERE))
    import numpy as np
    from synthetic_fpr import synthetic_problem

    import estimator.solver as solver
    import estimator.uncertainty as uncertainty

    solver.estimate(synthetic_problem(2, seed=seed + 1), solver.SolverOptions())  # load kernels
    problem = synthetic_problem(n, seed=seed)
    rss_data = _peak_rss_mib()
    colored_s: list[float] = []
    inner = uncertainty.honest_std  # the name the solver's deviations (uncertainty._deviations) call

    def timed_colored(*a, **kw):
        t0 = time.perf_counter()
        out = inner(*a, **kw)
        colored_s.append(time.perf_counter() - t0)
        return out

    uncertainty.honest_std = timed_colored
    walls, cpus, result = [], [], None
    for _ in range(repeat):
        r0 = resource.getrusage(resource.RUSAGE_SELF)
        t0 = time.perf_counter()
        result = solver.estimate(problem, solver.SolverOptions())
        walls.append(time.perf_counter() - t0)
        r1 = resource.getrusage(resource.RUSAGE_SELF)
        cpus.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
    best = int(np.argmin(walls))
    return {
        "maneuvers": n,
        "samples": int(sum(m.n for m in problem.maneuvers)),
        "residuals": int(sum(r.n for r in result.residuals)),
        "free": int(problem.parameters.free_mask.sum()),
        "estimated": int(result.free_estimated.sum()),
        "iterations": result.iterations,
        "wall_s": walls[best],
        "first_s": walls[0],
        "cpu_s": cpus[best],
        "colored_s": colored_s[best],
        "status": result.status,
        "message": result.message,
        "rss_data_mib": rss_data,
        "rss_peak_mib": _peak_rss_mib(),
    }


def _compile_probe() -> dict:
    """Time the first ``estimate`` of a tiny problem (kernels compiled or loaded) and a second."""
    sys.path.insert(0, str(HERE))
    t0 = time.perf_counter()
    from synthetic_fpr import synthetic_problem

    import estimator.solver as solver

    t_import = time.perf_counter() - t0
    problem = synthetic_problem(2, seed=3)
    t0 = time.perf_counter()
    solver.estimate(problem, solver.SolverOptions())
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    solver.estimate(problem, solver.SolverOptions())
    second = time.perf_counter() - t0
    return {"import_s": t_import, "first_s": first, "second_s": second}


def _child(args: list[str], env: dict | None = None) -> dict:
    out = subprocess.run([sys.executable, __file__, *args], capture_output=True, text=True,
                         env={**os.environ, **(env or {})}, cwd=ROOT, check=False)
    if out.returncode != 0:
        raise RuntimeError(f"benchmark child {args} failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _machine() -> list[str]:
    import numba
    import numpy
    import scipy

    from campaigns.machine import cpu_model, memory_gib

    cpu = cpu_model()
    gib = memory_gib()
    mem = "?" if gib is None else f"{gib:.1f} GiB"
    blas = "?"
    try:
        cfg = numpy.show_config(mode="dicts")
        b = cfg["Build Dependencies"]["blas"]
        blas = f"{b.get('name', '?')} {b.get('version', '')}".strip()
    except Exception:  # noqa: BLE001 - only a label in the report
        pass
    return [
        f"machine: {cpu}, {os.cpu_count()} cores, {mem} memory; {platform.system()} {platform.release()}",
        f"python {platform.python_version()}, numpy {numpy.__version__} ({blas}), scipy {scipy.__version__}, "
        f"numba {numba.__version__}",
        f"load average at start: {' '.join(f'{x:.2f}' for x in os.getloadavg())}",
    ]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10, 20, 40, 70, 140])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", type=Path, default=HERE / "results" / "estimate.txt")
    ap.add_argument("--one", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--compile-probe", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.one is not None:
        print(json.dumps(_run_one(a.one, a.repeat, a.seed)))
        return
    if a.compile_probe:
        print(json.dumps(_compile_probe()))
        return

    lines = ["Estimator benchmark (campaigns/benchmarks/bench_estimate.py)", ""]
    lines += _machine()
    lines.append("data: synthetic analytic flights (campaigns/benchmarks/synthetic_fpr.py), 32 Hz, "
                 "30-40 s per maneuver, all tejas channels, white noise; default SolverOptions "
                 "(staged start, honest deviations, diagnostics)")
    with tempfile.TemporaryDirectory() as cache:
        cold = _child(["--compile-probe"], {"NUMBA_CACHE_DIR": cache})
        warm = _child(["--compile-probe"], {"NUMBA_CACHE_DIR": cache})
    lines += [
        "",
        "numba kernels (first estimate of a 2-maneuver problem minus the second one):",
        f"  cold, empty cache: {cold['first_s'] - cold['second_s']:6.2f} s   (once per machine and "
        "estimator version: cache=True keeps the machine code on disk)",
        f"  from the cache:    {warm['first_s'] - warm['second_s']:6.2f} s   (once per process)",
        f"  import of estimator.solver: {warm['import_s']:.2f} s",
        "",
        f"per size: best of {a.repeat} runs, each size in its own process after a warm-up (no "
        "compilation in the timings)",
    ]
    head = (f"{'maneuvers':>9}{'samples':>9}{'residuals':>10}{'free':>6}{'iter':>5}{'wall s':>8}"
            f"{'s/iter':>8}{'ms/maneuver':>12}{'coloured s':>11}{'first s':>8}{'CPU s':>7}"
            f"{'peak RSS MiB':>13}{'data MiB':>9}")
    lines += [head, "-" * len(head)]
    rows = []
    for n in a.sizes:
        r = _child(["--one", str(n), "--repeat", str(a.repeat), "--seed", str(a.seed)])
        rows.append(r)
        lines.append(
            f"{r['maneuvers']:>9}{r['samples']:>9}{r['residuals']:>10}{r['free']:>6}{r['iterations']:>5}"
            f"{r['wall_s']:>8.2f}{r['wall_s'] / r['iterations']:>8.3f}{1e3 * r['wall_s'] / n:>12.1f}"
            f"{r['colored_s']:>11.2f}{r['first_s']:>8.2f}{r['cpu_s']:>7.2f}{r['rss_peak_mib']:>13.0f}"
            f"{r['rss_data_mib']:>9.0f}"
        )
        print(lines[-1], flush=True)
    lines += ["", "status per size: " + "; ".join(
        f"{r['maneuvers']}: {r['message'].split(';')[0]} ({r['estimated']} of {r['free']} free "
        "parameters estimated, the rest held as undetermined)" for r in rows)]
    lines += ["", "wall s: best of the runs, everything estimate() does (screening, iterations, "
              "Cramér-Rao and honest deviations, diagnostics, result; the staged start's iterations "
              "not counted in iter); s/iter, ms/maneuver: from it; coloured s: the honest deviations' "
              "part of it (cross-channel residual spectrum, IMU noise as process noise); first s: "
              "the first run in the process, "
              "which also pays for the operating system handing out its memory page by page "
              "(slow on this virtual machine); CPU s: user + system time of the best run, both "
              "threads (less sensitive to other jobs than wall time); peak RSS: the benchmark "
              "process, problem data and imported libraries included (data MiB: before estimating)",
              f"load average at the end: {' '.join(f'{x:.2f}' for x in os.getloadavg())} (a shared "
              "machine: other jobs slow the timings)"]
    text = "\n".join(lines) + "\n"
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
