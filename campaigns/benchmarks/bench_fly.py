"""Benchmark: flying and instrumenting maneuvers — maneuvers per second and peak memory.

    python campaigns/benchmarks/bench_fly.py [--out campaigns/benchmarks/results/fly.txt]

Measures, for each maneuver kind at Mach 0.6 (one process): wall time to fly with JSBSim, to
instrument, and to write; then a whole mixed campaign with 1 and with all worker processes, in
maneuvers per second; peak resident memory of this process (which flies the 1-worker campaign) and
of the largest pool worker (each worker reports its own: :func:`synth.workers.workers_peak_rss_mib`;
under ``forkserver`` the workers are not this process's children, so ``RUSAGE_CHILDREN`` never
sees them). Timing never decides a test; the result table is committed so changes in speed are
visible in review.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import jsbsim

from aircraft_models import load_fleet
from synth.campaign import fly_campaign, parse_campaign
from synth.environment import Environment
from synth.errors import ErrorConfig
from synth.flight import fly_maneuver
from synth.instrument import instrument
from synth.maneuvers import MANEUVER_KINDS, ManeuverSpec
from synth.workers import peak_rss_mib, workers_peak_rss_mib

HERE = Path(__file__).resolve().parent


def per_kind(lines: list[str]) -> None:
    fleet = load_fleet()
    cfg = fleet.configuration("PT1-BOOM")
    env = Environment.from_dict({"planet": "flat", "turbulence": "light", "turbulence_seed": 1})
    errors = ErrorConfig.typical()
    lines.append("per maneuver kind, Mach 0.6, 6000 m, one process (wall s)")
    lines.append(f"{'kind':<24}{'segments':>9}{'flown s':>9}{'fly':>8}{'x real':>8}{'instrument':>12}")
    for kind in MANEUVER_KINDS:
        spec = ManeuverSpec.from_dict({"kind": kind, "mach": 0.6, "altitude_m": 6000.0})
        t0 = time.perf_counter()
        segs = fly_maneuver(spec, fleet.airframe, cfg.aircraft, env)
        t1 = time.perf_counter()
        for k, truth in enumerate(segs):
            instrument(truth, fleet.airframe, cfg, errors, maneuver_key=k)
        t2 = time.perf_counter()
        flown = sum(s.duration_s for s in segs)
        lines.append(f"{kind:<24}{len(segs):>9}{flown:>9.0f}{t1 - t0:>8.2f}{flown / (t1 - t0):>8.0f}"
                     f"{t2 - t1:>12.3f}")


def campaign(lines: list[str], n_mach: int, workers_list: list[int]) -> None:
    # Mach 0.4-0.7 at 6000 m: conditions every maneuver kind flies (Mach 0.3 belongs lower down)
    machs = [0.4, 0.5, 0.6, 0.7, 0.8][:n_mach]
    raw = {
        "name": "bench", "seed": 1, "fleet": "fleet_default",
        "environment": {"planet": "flat", "turbulence": "light", "wind_ned_mps": [5.0, 0.0, 0.0]},
        "errors": {"preset": "typical"},
        "flights": [{"configurations": ["PV1-NP", "PT1-BOOM"], "mach": machs, "maneuvers": "all",
                     "altitude_m": 6000.0}],
    }
    camp = parse_campaign(raw, source="benchmark")
    lines.append("")
    lines.append(f"campaign: {len(camp.jobs)} maneuvers (2 configurations x {n_mach} Mach x "
                 f"{len(MANEUVER_KINDS)} kinds), fly + instrument + write Parquet")
    lines.append(f"{'workers':>8}{'files':>7}{'wall s':>9}{'maneuvers/s':>13}{'files/s':>9}")
    for workers in workers_list:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            res = fly_campaign(camp, Path(tmp) / "ds", workers=workers)
            wall = time.perf_counter() - t0
            nfiles = len(res.manifest["maneuvers"])
            lines.append(f"{workers:>8}{nfiles:>7}{wall:>9.1f}{len(camp.jobs) / wall:>13.2f}"
                         f"{nfiles / wall:>9.2f}")
            for job, err in res.failures:
                lines.append(f"  failed: {job.configuration_id} {job.maneuver['kind']} Mach "
                             f"{job.maneuver['mach']}: {err.splitlines()[0][:120]}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=HERE / "results" / "fly.txt")
    ap.add_argument("--n-mach", type=int, default=4, help="Mach numbers in the campaign part")
    args = ap.parse_args()
    lines = [
        "fpr benchmark: fly + instrument",
        f"machine: {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}, "
        f"jsbsim {jsbsim.__version__}",
        "load average at start: " + " ".join(f"{v:.2f}" for v in os.getloadavg())
        + " (other work on the 2 cores slows the 2-worker case most)",
        "",
    ]
    per_kind(lines)
    campaign(lines, args.n_mach, sorted({1, os.cpu_count() or 1}))
    lines.append("")
    lines.append(f"peak RSS: this process {peak_rss_mib():.0f} MiB, "
                 f"largest worker {workers_peak_rss_mib():.0f} MiB")
    lines.append("load average at end: " + " ".join(f"{v:.2f}" for v in os.getloadavg()))
    text = "\n".join(lines) + "\n"
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(f"written to {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
