"""``fpr montecarlo`` and ``fpr montecarlo-summary``: Monte Carlo campaigns from the command line.

Wired into ``fpr`` (campaigns/cli.py) by :func:`add_parser` and :func:`run`; also runs alone::

    python -m campaigns.montecarlo_cli montecarlo mc_20maneuvers --out runs/mc20 --workers 2
    python -m campaigns.montecarlo_cli montecarlo-summary runs/mc20
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

#: the subcommands this module adds (``run`` handles all of them)
COMMANDS = ("montecarlo", "montecarlo-summary")

MONTECARLO_EPILOG = """\
A scenario TOML is a campaign file (fleet, maneuvers, Mach numbers, errors, winds; see
campaigns/default.toml) plus `replications = N`, the master `seed`, [draw] (error distributions,
winds, turbulence) and [estimator] (model set, channels, which parameters are free); see
campaigns/mc_20maneuvers.toml and campaigns/montecarlo/scenario.py.

Replication k draws its errors, noise and winds from (seed, k): the results do not depend on the
number of workers or on the executor. Maneuvers whose flight does not change between replications
are flown once (OUT/flights/) and only re-instrumented.

OUT/replications/rNNNNN.parquet holds one replication (every estimate beside its truth, its
Cramer-Rao and coloured deviations, z-scores; per channel the 3-sigma of the residuals and of
the calibrated channel against the true flow angle); a failed replication leaves
rNNNNN.failed.json with its error instead. Interrupted? Run the same command again: finished
replications are skipped, and the files end the same, byte for byte, as an uninterrupted run's
(wall times go to OUT/timings.csv). Nothing in OUT is ever unpickled or executed (an old
flights/*.pkl cache is ignored and the flight flown again), and the run removes nothing but its
own temporary files and its replications' scratch datasets (OUT/.scratch/, gone at the end; a
killed run's are removed by the next): anything else in OUT (notes, plots, subfolders) is left
alone and not taken for a result. Ctrl-C stops the workers and says how many replications are
written (exit 130); the same command resumes.

At the end: summary.txt, summary_parameters.csv, summary_families.csv, summary_channels.csv and
summary.png in OUT (or --summary-dir), listed in .fpr-summary.json there: a later summary replaces
those files only while they are unchanged; a file of one of these names that the summary did not
write (or that was edited since) is never replaced: the command is refused at once, naming it.

examples:
  fpr montecarlo mc_20maneuvers --out runs/mc20
  fpr montecarlo my_scenario.toml --out runs/mine --replications 20 --workers 2
  fpr montecarlo mc_20maneuvers --out runs/mc20 --scheduler tcp://10.0.0.5:8786
  fpr montecarlo-summary runs/mc20
"""


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Add ``montecarlo`` and ``montecarlo-summary`` to the ``fpr`` subcommands."""
    p = subparsers.add_parser(
        "montecarlo",
        help="run a Monte Carlo campaign: N replications of a scenario, each estimated and compared "
        "with the truth (resumable; local processes or a Dask cluster)",
        description="Run (or resume) a Monte Carlo campaign: every replication draws new errors, "
        "noise and winds, re-instruments the shared flights, estimates the calibration and compares "
        "every estimate with its injected truth.",
        epilog=MONTECARLO_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("scenario", help="scenario TOML file, or the name of one shipped in campaigns/ "
                   "(mc_20maneuvers)")
    p.add_argument("--out", required=True, type=Path,
                   help="output directory (created; an existing one of the same scenario is resumed)")
    p.add_argument("--replications", type=int, default=None, metavar="N",
                   help="number of replications (default: the scenario's `replications`)")
    p.add_argument("--workers", type=int, default=None,
                   help="local worker processes (default: all CPUs; 1 runs in this process)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run on the Dask distributed cluster at ADDRESS (e.g. tcp://host:8786) "
                   "instead of local processes")
    p.add_argument("--retry-failed", action="store_true",
                   help="run again the replications that failed in an earlier run")
    p.add_argument("--no-summary", action="store_true", help="do not summarise at the end")
    p.add_argument("--summary-dir", type=Path, default=None, metavar="DIR",
                   help="write the summary files into DIR instead of OUT (created when missing)")
    p.set_defaults(mc_command="montecarlo")
    s = subparsers.add_parser(
        "montecarlo-summary",
        help="summarise a Monte Carlo output directory (bias, RMSE, scatter / Cramer-Rao; accuracies)",
        description="Summarise the replications of a Monte Carlo output directory: per parameter "
        "bias, RMSE, Monte Carlo scatter against the mean Cramer-Rao and coloured-residual "
        "deviations; per channel the distribution of 3-sigma accuracies; failures. Writes "
        "summary.txt, summary_*.csv and summary.png into the directory (or --summary-dir), replacing "
        "only the files an earlier summary wrote there (listed in .fpr-summary.json), unchanged: a "
        "file of one of those names that the summary did not write, or that was edited since, is "
        "never replaced (the command is refused, naming it; exit status 2).",
    )
    s.add_argument("out", type=Path, help="the --out directory of `fpr montecarlo`")
    s.add_argument("--replications", type=int, default=None, metavar="N",
                   help="summarise replications 0..N-1 only (default: every file present)")
    s.add_argument("--all-kinds", action="store_true",
                   help="list every parameter (initial conditions, IMU biases) one by one in the text")
    s.add_argument("--summary-dir", type=Path, default=None, metavar="DIR",
                   help="write the summary files into DIR instead of OUT (created when missing)")
    s.set_defaults(mc_command="montecarlo-summary")


def run(args: argparse.Namespace) -> int:
    """Run the subcommand parsed by :func:`add_parser`; returns the exit status (0 ok, 1 some
    replications failed or the run is incomplete, 130 interrupted by Ctrl-C, 143 by SIGTERM)."""
    from campaigns._signals import interrupt_status, sigterm_as_interrupt
    from campaigns.montecarlo import MonteCarloInterrupted, load_scenario, run_montecarlo
    from campaigns.montecarlo.runner import finished_replications, read_state
    from campaigns.montecarlo.summary import check_summary_files, write_summary

    summary_dir = args.summary_dir or args.out
    if args.mc_command == "montecarlo-summary":
        read_state(args.out)  # a clear error when OUT is not a Monte Carlo directory
        text, written = write_summary(args.out, summary_dir, replications=args.replications,
                                      all_kinds=args.all_kinds, tool="fpr montecarlo-summary",
                                      advice="or write the summary elsewhere with --summary-dir DIR")
        print(text)
        print(f"\nwritten into {summary_dir}: {', '.join(p.name for p in written)}")
        return 0
    advice = "write the summary elsewhere with --summary-dir DIR, or skip it with --no-summary"
    if not args.no_summary:
        # refused now, not after the replications: the summary never replaces a user's file
        check_summary_files(summary_dir, tool="fpr montecarlo", advice=advice)
    scenario = load_scenario(args.scenario)
    n = args.replications or scenario.replications
    where = f"Dask scheduler {args.scheduler}" if args.scheduler else \
        f"{args.workers or 'all'} local worker(s)"
    print(f"scenario {scenario.name!r} ({scenario.source}): {len(scenario.campaign.jobs)} maneuvers, "
          f"{len(scenario.fixed_jobs)} flown once and re-instrumented, {n} replications, "
          f"{len(scenario.distributions)} drawn error/wind values -> {args.out} on {where}")
    try:  # SIGTERM takes Ctrl-C's path: the workers are stopped, how far it got is said
        with sigterm_as_interrupt():
            report = run_montecarlo(scenario, args.out, replications=args.replications,
                                    workers=args.workers, scheduler=args.scheduler,
                                    retry_failed=args.retry_failed, progress=True)
    except KeyboardInterrupt as exc:  # MonteCarloInterrupted, or an interrupt before the replications
        stopped = isinstance(exc, MonteCarloInterrupted)
        print(f"fpr montecarlo: {exc if stopped else 'interrupted; run the same command again to resume'}",
              file=sys.stderr)
        return interrupt_status(exc)
    print(report.text())
    if not args.no_summary:
        print()
        print(write_summary(args.out, summary_dir, replications=n, tool="fpr montecarlo",
                            advice=advice)[0])
    have = finished_replications(args.out)
    complete = all(k in have for k in range(n))
    return 0 if complete and not report.failed else 1


def main(argv: list[str] | None = None) -> int:
    """Stand-alone entry point: ``python -m campaigns.montecarlo_cli montecarlo ...``."""
    parser = argparse.ArgumentParser(prog="python -m campaigns.montecarlo_cli")
    add_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    try:
        return run(args)
    except (FileNotFoundError, FileExistsError, ValueError, KeyError) as exc:
        print(f"fpr {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
