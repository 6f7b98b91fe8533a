"""Benchmark: the estimator at the paper's scale — time to converge, iterations, peak memory.

    python campaigns/benchmarks/bench_estimate.py [--sizes 10 20 40 70 140] [--repeat 2]
                                                  [--method output_error|filter_error|both]
                                                  [--turbulence SIGMA_MPS]
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
  the time spent in the honest deviations (:func:`estimator.uncertainty.honest_std`; "-": none), the first
  run's wall time, the CPU time
  (the estimator uses two threads on a two-core machine), and the process's peak resident
  memory (problem data included).

Wall times are the best of ``--repeat`` runs in the same process (the machine may be shared),
with the first run reported beside them.

``--method`` chooses the estimation method (``SolverOptions.method``): the output-error one
(default), the filter-error one (the turbulent wind as Gauss-Markov states,
:mod:`estimator.filter_error`), or ``both``: each size then runs both methods, each in its own
process, on the same problem, and a line gives the filter-error / output-error wall-time ratio per
size against its target (at most 3x). ``--turbulence SIGMA`` flies the campaign in
turbulence of that intensity (m/s per NED component, Dryden scale length 533.4 m; each maneuver its
own draw, seeded by ``--seed`` and the maneuver's number; :func:`synthetic_fpr.synthetic_problem`);
the status line then records what each fit found of the turbulence (the filter-error fit's
estimated intensities). The filter-error fit's "coloured s" is its coloured-innovation
deviations' time (:func:`estimator.uncertainty.innovation_honest_std`).

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


#: Dryden scale length above 2000 ft (1750 ft), m: the turbulence of ``--turbulence``
DRYDEN_L_M = 533.4
METHODS = ("output_error", "filter_error")


def _turbulence(sigma_mps: float | None, seed: int) -> tuple[float, float, int] | None:
    return None if sigma_mps is None else (sigma_mps, DRYDEN_L_M, seed)


def _turbulence_note(result) -> str:
    """The fit's turbulence finding (the filter-error fit's estimated intensities), or ''."""
    msgs = [f.message for f in result.findings if f.code == "turbulence"]
    if not msgs:
        return ""
    more = f" (+{len(msgs) - 1} more turbulence findings)" if len(msgs) > 1 else ""
    return msgs[0] + more


def _run_one(n: int, repeat: int, seed: int, method: str = "output_error",
             turbulence_mps: float | None = None) -> dict:
    """One problem size, in this process: warm up, then time ``estimate`` (best of ``repeat``)."""
    sys.path.insert(0, str(HERE))
    import numpy as np
    from synthetic_fpr import synthetic_problem

    import estimator.filter_error as filter_error
    import estimator.solver as solver
    import estimator.uncertainty as uncertainty

    options = solver.SolverOptions(method=method)
    # load the kernels (a turbulent warm-up problem when the timed one is: the wind filter's too)
    solver.estimate(synthetic_problem(2, seed=seed + 1, turbulence=_turbulence(turbulence_mps, seed + 1)),
                    options)
    problem = synthetic_problem(n, seed=seed, turbulence=_turbulence(turbulence_mps, seed))
    rss_data = _peak_rss_mib()
    colored_s: list[float] = []
    inner = uncertainty.honest_std  # the name the solver's deviations (uncertainty._deviations) call

    def timed_colored(*a, **kw):
        t0 = time.perf_counter()
        out = inner(*a, **kw)
        colored_s.append(time.perf_counter() - t0)
        return out

    uncertainty.honest_std = timed_colored
    inner_fem = filter_error.innovation_honest_std  # the filter-error method's (the innovations')

    def timed_innovations(*a, **kw):
        t0 = time.perf_counter()
        out = inner_fem(*a, **kw)
        colored_s.append(time.perf_counter() - t0)
        return out

    filter_error.innovation_honest_std = timed_innovations
    walls, cpus, result = [], [], None
    for _ in range(repeat):
        r0 = resource.getrusage(resource.RUSAGE_SELF)
        t0 = time.perf_counter()
        n_colored = len(colored_s)
        result = solver.estimate(problem, options)
        if len(colored_s) == n_colored:  # no honest deviations (colored=False)
            colored_s.append(float("nan"))
        walls.append(time.perf_counter() - t0)
        r1 = resource.getrusage(resource.RUSAGE_SELF)
        cpus.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
    best = int(np.argmin(walls))
    return {
        "method": method,
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
        "verdict": result.verdict.name,
        "turbulence": _turbulence_note(result),
        "rss_data_mib": rss_data,
        "rss_peak_mib": _peak_rss_mib(),
    }


def _compile_probe(method: str = "output_error", turbulence_mps: float | None = None) -> dict:
    """Time the first ``estimate`` of a tiny problem (kernels compiled or loaded) and a second."""
    sys.path.insert(0, str(HERE))
    t0 = time.perf_counter()
    from synthetic_fpr import synthetic_problem

    import estimator.solver as solver

    t_import = time.perf_counter() - t0
    problem = synthetic_problem(2, seed=3, turbulence=_turbulence(turbulence_mps, 3))
    options = solver.SolverOptions(method=method)
    t0 = time.perf_counter()
    solver.estimate(problem, options)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    solver.estimate(problem, options)
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
    ap.add_argument("--method", choices=[*METHODS, "both"], default="output_error",
                    help="estimation method (SolverOptions.method); both: each size with each, on "
                         "the same problem, and their wall-time ratio")
    ap.add_argument("--turbulence", type=float, metavar="SIGMA", default=None,
                    help="fly the campaign in turbulence of this intensity, m/s (Dryden, L = 533.4 m); "
                         "default: calm air")
    ap.add_argument("--out", type=Path, default=HERE / "results" / "estimate.txt")
    ap.add_argument("--one", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--compile-probe", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.turbulence is not None and not a.turbulence > 0:
        ap.error(f"--turbulence must be a positive intensity in m/s, got {a.turbulence}")
    methods = list(METHODS) if a.method == "both" else [a.method]
    if a.one is not None:
        print(json.dumps(_run_one(a.one, a.repeat, a.seed, methods[0], a.turbulence)))
        return
    if a.compile_probe:
        print(json.dumps(_compile_probe(methods[0], a.turbulence)))
        return
    turb_args = [] if a.turbulence is None else ["--turbulence", repr(a.turbulence)]
    # the compile probe runs the method that uses the most kernels (filter error: the output-error
    # ones for its start and screen, and the wind filter's)
    probe_method = methods[-1]

    lines = ["Estimator benchmark (campaigns/benchmarks/bench_estimate.py)", ""]
    lines += _machine()
    air = ("calm air" if a.turbulence is None else
           f"turbulence: sigma {a.turbulence:g} m/s per NED component, Dryden L = {DRYDEN_L_M:g} m, "
           f"first-order Gauss-Markov, each maneuver its own draw (seed [{a.seed}, k]); the flow channels "
           "and the airspeed see V - C_bn dW, the IMU, attitude and altitudes the flight")
    lines.append("data: synthetic analytic flights (campaigns/benchmarks/synthetic_fpr.py), 32 Hz, "
                 f"30-40 s per maneuver, all tejas channels, white noise, {air}; SolverOptions "
                 f"(method={' and '.join(methods)}; otherwise default: staged start, honest "
                 "deviations, diagnostics)")
    probe = ["--compile-probe", "--method", probe_method, *turb_args]
    with tempfile.TemporaryDirectory() as cache:
        cold = _child(probe, {"NUMBA_CACHE_DIR": cache})
        warm = _child(probe, {"NUMBA_CACHE_DIR": cache})
    lines += [
        "",
        f"numba kernels (first estimate of a 2-maneuver problem minus the second one; {probe_method}):",
        f"  cold, empty cache: {cold['first_s'] - cold['second_s']:6.2f} s   (once per machine and "
        "estimator version: cache=True keeps the machine code on disk)",
        f"  from the cache:    {warm['first_s'] - warm['second_s']:6.2f} s   (once per process)",
        f"  import of estimator.solver: {warm['import_s']:.2f} s",
        "",
        f"per size: best of {a.repeat} runs, each size in its own process after a warm-up (no "
        "compilation in the timings)",
    ]
    head = (f"{'method':<13}{'maneuvers':>9}{'samples':>9}{'residuals':>10}{'free':>6}{'iter':>5}"
            f"{'wall s':>8}{'s/iter':>8}{'ms/maneuver':>12}{'coloured s':>11}{'first s':>8}{'CPU s':>7}"
            f"{'peak RSS MiB':>13}{'data MiB':>9}")
    lines += [head, "-" * len(head)]
    rows = []
    for n, method in [(n, m) for n in a.sizes for m in methods]:
        r = _child(["--one", str(n), "--repeat", str(a.repeat), "--seed", str(a.seed), "--method", method,
                    *turb_args])
        rows.append(r)
        colored = "-" if r["colored_s"] != r["colored_s"] else f"{r['colored_s']:.2f}"  # NaN: none
        lines.append(
            f"{r['method']:<13}{r['maneuvers']:>9}{r['samples']:>9}{r['residuals']:>10}{r['free']:>6}"
            f"{r['iterations']:>5}{r['wall_s']:>8.2f}{r['wall_s'] / r['iterations']:>8.3f}"
            f"{1e3 * r['wall_s'] / n:>12.1f}"
            f"{colored:>11}{r['first_s']:>8.2f}{r['cpu_s']:>7.2f}{r['rss_peak_mib']:>13.0f}"
            f"{r['rss_data_mib']:>9.0f}"
        )
        print(lines[-1], flush=True)
    lines += ["", "status per size: " + "; ".join(
        f"{r['maneuvers']}{'' if len(methods) == 1 and a.method == 'output_error' else ' ' + r['method']}: "
        f"{r['message'].split(';')[0]} ({r['estimated']} of {r['free']} free "
        "parameters estimated, the rest held as undetermined)"
        + (f"; verdict {r['verdict']}; turbulence finding: {r['turbulence'] or 'none'}"
           if a.turbulence is not None or r["method"] == "filter_error" else "")
        for r in rows)]
    if len(methods) == 2:
        wall = {(r["maneuvers"], r["method"]): r["wall_s"] for r in rows}
        ratios = [(n, wall[n, "filter_error"] / wall[n, "output_error"]) for n in a.sizes]
        lines += ["", "filter-error / output-error wall time (target: at most 3x): " + "; ".join(
            f"{n} maneuvers: {q:.2f}x ({'met' if q <= 3.0 else f'{q / 3.0:.2f} x the target'})"
            for n, q in ratios)]
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
