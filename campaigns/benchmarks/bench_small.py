"""Benchmark: the whole ``fpr calibrate`` process of a small flight, as a user runs it.

    python campaigns/benchmarks/bench_small.py [--repeat 3] [--out campaigns/benchmarks/results/small.txt]

The flight is the shipped example (``fpr example``, :mod:`campaigns.example`: three maneuvers of a
target drone, 2,103 samples at 50 Hz, seven channels, CSV files and a problem file). Timed, each as
its own process from the shell's point of view (``subprocess``, wall time, best of ``--repeat`` after
one warm-up run that also fills the numba cache):

- ``fpr calibrate uav.toml`` with the default outputs (the workflow, its CSV tables, report.html
  with its figures);
- the same with ``--no-plots``;
- the floor no code of the project can go below: the interpreter alone, and the interpreter
  importing the libraries the process uses (numpy, pandas, numba, scipy's linear algebra and FFT,
  matplotlib's Agg canvas).

Also written: where one default run spends its time (from a profile of the same command in this
process: imports, numba's cache, the estimations, the report's figures). Timing never decides a
test; the table is committed so changes are visible in review.
"""

from __future__ import annotations

import argparse
import contextlib
import cProfile
import os
import pstats
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]

LIBRARIES = ("import numpy, pandas, numba, scipy.linalg, scipy.fft, matplotlib.figure, "
             "matplotlib.backends.backend_agg")


def _wall(cmd: list[str], cwd: Path, repeat: int) -> tuple[float, float, int]:
    """(best, first) wall time of ``cmd`` over a warm-up and ``repeat`` runs, and its exit status."""
    times, code = [], 0
    for _ in range(repeat + 1):
        t0 = time.perf_counter()
        out = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=False)
        times.append(time.perf_counter() - t0)
        code = out.returncode
        if code not in (0, 3):  # 3: success with warnings
            raise RuntimeError(f"{' '.join(cmd)} failed ({code}):\n{out.stderr[-2000:]}")
    return min(times[1:]), times[0], code


def _profile(folder: Path) -> list[str]:
    """Where one default ``fpr calibrate`` spends its time: profiled in a fresh process (nothing
    imported yet), as a user's run starts."""
    out = subprocess.run([sys.executable, __file__, "--profile-child", str(folder)], cwd=ROOT,
                         capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise RuntimeError(f"the profiled run failed:\n{out.stderr[-2000:]}")
    return out.stdout.splitlines()


def _profile_child(folder: Path) -> None:
    """Print where ``fpr calibrate`` spends its time (cumulative seconds of a profile)."""
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    from campaigns.cli import main

    with open(os.devnull, "w") as quiet, contextlib.redirect_stdout(quiet):
        main(["calibrate", str(folder / "uav.toml"), "--out", str(folder / "profiled"), "--overwrite"])
    prof.disable()
    total = time.perf_counter() - t0
    stats = pstats.Stats(prof).stats
    cum: dict[str, float] = {}
    for (path, _, name), (_, _, _, ct, _) in stats.items():
        key = f"{Path(path).name}:{name}"
        cum[key] = max(cum.get(key, 0.0), ct)
    parts = [("imports (first import of every module)", "<frozen importlib._bootstrap>:_find_and_load"),
             ("numba kernels loaded from the cache", "dispatcher.py:_compile_for_args"),
             ("the estimations (estimate)", "solver.py:estimate"),
             ("the report (CSV tables, figures, report.html)", "calibration.py:write"),
             ("  of it the figures' PNGs (matplotlib savefig)", "figure.py:savefig"),
             ("    of them the constrained layout", "layout_engine.py:execute")]
    print(f"one default run under the profiler: {total:.2f} s (the profiler adds to it); cumulative:")
    for label, key in parts:
        print(f"  {label:52s} {cum.get(key, 0.0):6.2f} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--profile-child", type=Path, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    if args.profile_child is not None:
        _profile_child(args.profile_child)
        return
    from campaigns.example import write_example

    fpr = [sys.executable, "-m", "campaigns.cli"]
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        write_example(folder)
        problem = str(folder / "uav.toml")
        load = os.getloadavg()
        cal = [*fpr, "calibrate", problem, "--overwrite", "--out"]
        runs = [("fpr calibrate uav.toml (default outputs)", [*cal, str(folder / "a")]),
                ("fpr calibrate uav.toml --no-plots", [*cal, str(folder / "b"), "--no-plots"]),
                ("python -c pass (the interpreter alone)", [sys.executable, "-c", "pass"]),
                ("python -c 'import numpy, pandas, numba, scipy, matplotlib' (the libraries alone)",
                 [sys.executable, "-c", LIBRARIES])]
        rows = [(label, _wall(cmd, ROOT, args.repeat)) for label, cmd in runs]
        profile = _profile(folder)
    lines = ["Small-flight benchmark (campaigns/benchmarks/bench_small.py)", "",
             "data: the shipped example (fpr example: 3 maneuvers, 2,103 samples at 50 Hz, 7 channels, "
             "CSV files and a problem file)",
             f"load average at start: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; best of {args.repeat} "
             "runs after a warm-up run", "",
             f"{'command':82s} {'best s':>7s} {'first s':>8s} exit"]
    for label, (best, first, code) in rows:
        lines.append(f"{label:82s} {best:7.2f} {first:8.2f} {code:4d}")
    lines.append(f"(the libraries: {LIBRARIES[7:]})")
    lines += ["", *profile]
    text = "\n".join(lines) + "\n"
    print(text, end="")
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)


if __name__ == "__main__":
    main()
