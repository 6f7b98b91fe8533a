"""The ``fpr`` command line: where the synthesizer and the estimator meet.

    fpr fly CAMPAIGN.toml --out DIR     fly a campaign into a dataset
    fpr fly --mach 0.5 0.7 --maneuver pitch_doublet --out DIR      ... or one given by flags
    fpr demo                            fly the demo fleet campaign, calibrate it, write the report
                                        (and a light-turbulence block by the filter-error method)
    fpr show DIR                        summarise an existing dataset
    fpr calibrate PROBLEM.toml|DATASET  the Mach-bin calibration workflow and its report
                                        (--single: one estimation over all maneuvers)
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the command line imports what a command needs when it runs
    from synth.campaign import FlyResult

#: Exit status of ``fpr calibrate`` and ``fpr demo`` per verdict (2: bad input or usage).
EXIT_STATUS = {"SUCCESS": 0, "SUCCESS_WITH_WARNINGS": 3, "FAILURE": 1}

#: The errors a command reports as bad input (exit status 2, the message alone, no traceback)
INPUT_ERRORS = (FileNotFoundError, FileExistsError, ValueError, KeyError)


def exit_status(verdict) -> int:
    """The exit status that carries a verdict (:data:`EXIT_STATUS`)."""
    return EXIT_STATUS[verdict.name]

FLY_EPILOG = """\
A campaign TOML names the fleet, Mach numbers, maneuvers, errors and winds; see
campaigns/default.toml (the default campaign: five aircraft, seven configurations, Mach 0.3-0.9,
every maneuver type, gear-down maneuvers) and campaigns/demo.toml. Without a file, the flags
describe a one-block campaign.

The output directory holds manifest.json and maneuvers/mNNNN.parquet, one file per maneuver
(SHSS segments get mNNNNsK): measured channels and truth channels (prefix true_), SI units.
Load it with `synth.dataset.load_dataset(DIR)`; `fpr show DIR` summarises it.

The manifest is written first and says "complete": false until the last maneuver is in. An
interrupted run (Ctrl-C: exit status 130) is completed by `fpr fly --resume --out DIR`, which
reads the campaign from the manifest and flies only the missing maneuvers: the dataset is then
byte-identical to an uninterrupted run. --overwrite removes only the files fpr fly wrote there (the
manifest and the maneuver files it names); a directory holding anything else is refused.

Maneuvers that fail (the aircraft departs, a controller cannot hold its target) are reported and
listed in the manifest; the exit status is then 1. Exit status 2: bad input or usage.

--sortie [CONFIG] flies one configuration's maneuvers (default: the campaign's first) as one
continuous flight instead, in the campaign's order: trim at the first test point, then between
maneuvers a transition (speed change, climb or descent, gear, turn back to the test heading,
settle). It writes manifest.json (format fpr-sortie, with the maneuver boundaries as truth),
sortie.parquet (the common time base with the truth), streams/dru.parquet, streams/ins.parquet,
streams/dgps.parquet (each recorder's raw stream, one per sortie) and boundaries.csv. Load it with
`synth.dataset.load_sortie(DIR)`; its `.cut(ID)` cuts a maneuver out by its boundaries.

examples:
  fpr fly default --out data/default
  fpr fly --config PV1-NP PT1-BOOM --mach 0.4 0.6 --maneuver pitch_doublet shss --out data/small
  fpr fly --mach 0.3 --maneuver pitch_doublet --gear-down --altitude-m 1000 --out data/gear
  fpr fly --resume --out data/default       complete an interrupted run
  fpr fly default --sortie PV1-NP --out data/sortie-pv1   one whole sortie of configuration PV1-NP
"""


def _add_fly(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "fly",
        help="fly a campaign with JSBSim and write a flight-test dataset with the truth beside it",
        description="Fly a campaign of test maneuvers with JSBSim, inject sensor, recorder and IMU "
        "errors, and write the measured and true channels to a dataset directory.",
        epilog=FLY_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("campaign", nargs="?", help="campaign TOML file or shipped name "
                   "(default, demo); omit to describe the campaign with flags")
    p.add_argument("--out", required=True, type=Path,
                   help="dataset directory to create (new or empty; an existing dataset with "
                   "--overwrite or --resume)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--overwrite", action="store_true",
                      help="replace a dataset fpr fly wrote at --out (only its own files are "
                      "removed; a directory holding anything else is refused)")
    mode.add_argument("--resume", action="store_true",
                      help="complete the interrupted dataset at --out: fly only its missing "
                      "maneuvers (the campaign is read from its manifest; a campaign given too "
                      "must be the same)")
    p.add_argument("--workers", type=int, default=None,
                   help="worker processes (default: all CPUs, fewer for a small campaign, which "
                   "flies faster in this process or a few workers than a pool takes to start)")
    p.add_argument("--sortie", nargs="?", const="", default=None, metavar="CONFIG",
                   help="fly the maneuvers of one configuration (default: the campaign's first) as "
                   "one continuous sortie with transitions between them, one stream per recorder "
                   "and the maneuver boundaries as truth (see below); not with --resume")
    g = p.add_argument_group("campaign by flags (ignored when a campaign file is given)")
    g.add_argument("--config", nargs="+", default="all", metavar="ID",
                   help="fleet configuration ids, or all (default: all seven: PV1-NP PV2-NP "
                   "PV3-NP PT1-NP PT1-BOOM PT2-NP PT2-BOOM)")
    g.add_argument("--mach", nargs="+", type=float, default=[0.5], help="Mach numbers (0.3-0.9)")
    g.add_argument("--maneuver", nargs="+", default="all", metavar="KIND",
                   help="maneuver kinds, or all (the default): pitch_doublet 3211 pullup_pushover "
                   "roller_coaster windup_turn shss pullup_rudder_doublets level_accel level_decel")
    g.add_argument("--altitude-m", type=float, default=6000.0, help="trim altitude, m")
    g.add_argument("--gear-down", action="store_true", help="fly with the landing gear down")
    g.add_argument("--seed", type=int, default=0, help="master seed for errors and turbulence")
    g.add_argument("--errors", default="typical", choices=["typical", "none", "real_world"],
                   help="error preset: typical magnitudes (synth/errors.py), none (truth only), or "
                        "real_world (typical plus the realism level's instrument errors: docs/realism.md)")
    g.add_argument("--planet", default="flat", choices=["flat", "wgs84"],
                   help="flat non-rotating earth, or JSBSim's rotating WGS84 ellipsoid")
    g.add_argument("--turbulence", default="none", choices=["none", "light", "moderate", "severe"])
    g.add_argument("--wind-ned-mps", nargs=3, type=float, default=[0.0, 0.0, 0.0],
                   metavar=("N", "E", "D"), help="steady wind, NED, m/s")
    g.add_argument("--rate-hz", type=float, default=40.0, help="common time base, Hz")
    # the flags that describe a campaign and their defaults, as the parser has them: a resume
    # without a campaign file uses the dataset's own campaign unless one of them was changed
    p.set_defaults(campaign_flag_defaults={a.dest: a.default for a in g._group_actions})


def _fly(args: argparse.Namespace) -> int:
    from campaigns._signals import interrupt_status, sigterm_as_interrupt
    from synth.campaign import (
        CampaignFlags,
        FlyInterrupted,
        campaign_of_dataset,
        fly_campaign,
        load_campaign,
        parse_campaign,
        summarize,
    )

    if args.sortie is not None and args.resume:
        print("fpr fly: error: --sortie flies a whole sortie at once; --resume does not apply "
              "(fly it again with --overwrite)", file=sys.stderr)
        return 2
    flags_given = any(getattr(args, k) != v for k, v in args.campaign_flag_defaults.items())
    if args.campaign:
        campaign = load_campaign(args.campaign)
    elif args.resume and not flags_given:
        campaign = campaign_of_dataset(args.out)
    else:
        campaign = parse_campaign(
            CampaignFlags(
                configurations=args.config, mach=args.mach, maneuvers=args.maneuver,
                altitude_m=args.altitude_m, gear_down=args.gear_down, seed=args.seed,
                errors_preset=args.errors, planet=args.planet, turbulence=args.turbulence,
                wind_ned_mps=args.wind_ned_mps, common_rate_hz=args.rate_hz,
            ).campaign(),
            source="command-line flags",
        )
    if args.sortie is not None:
        return _fly_sortie(args, campaign)
    print(f"campaign {campaign.name!r}: {len(campaign.jobs)} maneuvers -> {args.out}"
          + (" (resuming)" if args.resume else ""))

    try:  # SIGTERM takes Ctrl-C's path: the workers are stopped, the resume command said
        with sigterm_as_interrupt():
            result = fly_campaign(campaign, args.out, workers=args.workers, overwrite=args.overwrite,
                                  resume=args.resume, progress=True)
    except KeyboardInterrupt as exc:
        print(f"fpr fly: {exc if isinstance(exc, FlyInterrupted) else 'interrupted'}", file=sys.stderr)
        return interrupt_status(exc)
    except (IsADirectoryError, NotADirectoryError, PermissionError) as exc:
        print(f"fpr fly: error: {exc}", file=sys.stderr)
        return 2
    print(summarize(result.manifest))
    if args.resume and result.flown == 0:
        print(f"{args.out}: the dataset was already complete; nothing to fly")
    else:
        print(f"wrote {args.out} in {result.wall_s:.1f} s"
              + (f" ({result.flown} maneuvers flown now)" if args.resume else ""))
    return 0 if result.ok else 1


def _fly_sortie(args: argparse.Namespace, campaign) -> int:
    from synth.flight import FlightError
    from synth.sortie import fly_sortie_campaign, sortie_jobs, summarize_sortie

    cid, jobs = sortie_jobs(campaign, args.sortie or None)
    print(f"campaign {campaign.name!r}: one sortie of configuration {cid}, {len(jobs)} maneuvers "
          f"-> {args.out}")
    try:
        result = fly_sortie_campaign(campaign, args.out, configuration=cid, overwrite=args.overwrite)
    except FlightError as exc:
        print(f"fpr fly: the sortie failed: {exc}", file=sys.stderr)
        return 1
    print(summarize_sortie(result.manifest))
    print(f"wrote {args.out} in {result.wall_s:.1f} s")
    return 0


def _demo(args: argparse.Namespace) -> int:
    import os

    from synth.campaign import load_campaign
    from synth.dataset import check_directory

    t0 = time.perf_counter()
    campaign = load_campaign("demo")
    turbulent = load_campaign("demo_turbulence")
    out = args.out
    report_dir, turb_out, turb_report = _demo_folders(out)
    # every folder is checked before anything is flown or removed: one holding anything fpr did
    # not write there is refused at once (an earlier demo's datasets and reports are replaced;
    # nothing else is touched)
    check_directory(out, overwrite=True)
    check_directory(turb_out, overwrite=True)
    _prepare_out(report_dir, True, "fpr demo", [out], check_only=True)
    _prepare_out(turb_report, True, "fpr demo", [turb_out], check_only=True)
    # the blocks are independent: with more than one worker the light-turbulence block (small,
    # mostly on one core) is flown and calibrated beside the calm one, in one more worker process,
    # its console text printed after the calm block's as if run after it; --workers 1: one after
    # the other, in this process
    beside = (args.workers or os.cpu_count() or 1) > 1
    try:
        codes = _demo_blocks(campaign, turbulent, out, args.workers, beside, t0)
    except KeyboardInterrupt:
        print(f"fpr demo: interrupted; {out} and {turb_out} may be incomplete, their reports not "
              "written; `fpr demo` again starts over", file=sys.stderr)
        return 130
    if isinstance(codes, int):
        return codes
    code, tcode = codes
    if tcode == 130:  # the turbulent flight interrupted (--workers 1), said on stderr
        return 130
    names = {v: k for k, v in EXIT_STATUS.items()}
    print(f"fpr demo: {time.perf_counter() - t0:.0f} s in all; the calm block (the paper's calibration, "
          f"the main job): {names.get(code, code)}; the light-turbulence block (the filter-error method, "
          f"experimental, a demonstration): {names.get(tcode, tcode)}; exit status: the calm block's, or "
          "a failure of either")
    # the main job's verdict: the turbulent block demonstrates an experimental method, its verdict
    # printed above with its own findings; but a failure there is never passed over as a success
    return EXIT_STATUS["FAILURE"] if tcode in (EXIT_STATUS["FAILURE"], 2) else code


def _demo_folders(out: Path) -> tuple[Path, Path, Path]:
    """The demo's folders beside its calm dataset ``out``: the calm report, the light-turbulence
    dataset and its report."""
    return (out.parent / f"{out.name}-report", out.parent / f"{out.name}-turbulence",
            out.parent / f"{out.name}-turbulence-report")


def _demo_blocks(campaign, turbulent, out: Path, workers: int | None, beside: bool,
                 t0: float) -> tuple[int, int] | int:
    """The demo's two blocks (:func:`_demo`), the calm one's dataset at ``out``: ``(calm exit
    status, turbulent exit status)``, or the demo's exit status where it ends early (the calm
    flight interrupted, 130, or failed, 1)."""
    import contextlib
    from concurrent.futures.process import BrokenProcessPool

    from synth.campaign import summarize
    from synth.workers import stop_pool, worker_pool

    report_dir, turb_out, turb_report = _demo_folders(out)

    with contextlib.ExitStack() as stack:
        pool = stack.enter_context(worker_pool(1)) if beside else None
        # the campaign as its definition (a parsed one holds read-only mappings, which do not pickle)
        block = (pool.submit(_turbulent_block, turbulent.raw, turbulent.source, turb_out, turb_report)
                 if pool is not None else None)
        print(f"fpr demo: flying the demo campaign ({len(campaign.jobs)} maneuvers, seven fleet "
              f"configurations) into {out}")
        result = _demo_fly(campaign, out, workers, progress=True)
        if isinstance(result, int) or not result.ok:
            if not isinstance(result, int):
                print(summarize(result.manifest))
            if pool is not None:
                stop_pool(pool)
                print(f"fpr demo: the light-turbulence block stopped with it ({turb_out} may be "
                      "incomplete)", file=sys.stderr)
            return result if isinstance(result, int) else EXIT_STATUS["FAILURE"]
        print(summarize(result.manifest))
        print(f"\ndataset written to {out} ({time.perf_counter() - t0:.1f} s). "
              "Load it with synth.dataset.load_dataset().")
        code = _block_calibration(out, report_dir, {})
        print(f"\nfpr demo: the light-turbulence block: {len(turbulent.jobs)} maneuvers of two "
              f"configurations in light turbulence into {turb_out}, calibrated by the filter-error "
              "method (the wind as estimated states; experimental)")
        if block is None:
            return code, _turbulent_run(turbulent, turb_out, turb_report, workers, progress=True)
        try:
            tcode, text, errors = block.result()
        except BrokenProcessPool:
            tcode, text, errors = EXIT_STATUS["FAILURE"], "", (
                "fpr demo: the light-turbulence block's process ended abruptly (out of memory, or "
                "killed); `fpr demo --workers 1` runs it in this process\n")
        print(text, end="")
        print(errors, end="", file=sys.stderr)
    return code, tcode


def _demo_fly(campaign, out: Path, workers: int | None, progress: bool) -> FlyResult | int:
    """Fly one of the demo's campaigns into ``out``: the :class:`~synth.campaign.FlyResult`, or 130
    when interrupted (said on stderr). An earlier dataset fpr wrote at ``out`` is replaced (its own
    files only); a directory holding anything else is refused, the message listing it."""
    from synth.campaign import FlyInterrupted, fly_campaign

    try:
        return fly_campaign(campaign, out, workers=workers, overwrite=True, progress=progress)
    except FlyInterrupted as exc:
        print(f"fpr demo: interrupted: {exc.n_done} of {exc.n_jobs} maneuvers written to {out}; "
              "`fpr demo` again starts over", file=sys.stderr)
        return 130


def _block_calibration(out: Path, report: Path, options: dict, model: str | None = None) -> int:
    """One of the demo's blocks calibrated as `fpr calibrate DATASET` runs it with ``options``
    (and ``--model``): the calm block with the workflow's defaults (the model set's reference
    Mach); the light-turbulence block by the filter-error method (the gusts as estimated states,
    which the output-error fit would take for sensor errors) with the INS velocities
    (``tejas_ins``). The report written; the exit status."""
    import warnings

    from estimator.io import problem_from_dataset

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        problem = problem_from_dataset(out, **({"model": model} if model else {}))
    return _workflow(problem, report, options, overwrite=True, tool="fpr demo", source=out)


def _turbulent_run(campaign, out: Path, report: Path, workers: int | None, progress: bool) -> int:
    """The demo's light-turbulence block flown and calibrated (:func:`_block_calibration`): the
    exit status, 130 when interrupted."""
    from synth.campaign import summarize

    result = _demo_fly(campaign, out, workers, progress)
    if isinstance(result, int):
        return result
    if not result.ok:
        print(summarize(result.manifest))
        return EXIT_STATUS["FAILURE"]
    return _block_calibration(out, report, {"method": "filter_error"}, model="tejas_ins")


def _turbulent_block(raw: dict, source: str, out: Path, report: Path) -> tuple[int, str, str]:
    """:func:`_turbulent_run` of the campaign defined by ``raw`` (read from ``source``) in a worker
    process beside the calm block: ``(exit status, its console text, its error text)``, printed
    after the calm block's. An error ends the block, not the demo: said in the error text as the
    command line says it (2: bad input), a traceback for anything else (1)."""
    import contextlib
    import io
    import traceback

    from synth.campaign import parse_campaign

    text, errors = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(text), contextlib.redirect_stderr(errors):
        try:
            code = _turbulent_run(parse_campaign(raw, source=source), out, report, 1, progress=False)
        except INPUT_ERRORS as exc:
            print(f"fpr demo: error: {exc}", file=sys.stderr)
            code = 2
        except Exception:
            print(f"fpr demo: the light-turbulence block failed:\n{traceback.format_exc()}",
                  file=sys.stderr)
            code = EXIT_STATUS["FAILURE"]
    return code, text.getvalue(), errors.getvalue()


def _show(args: argparse.Namespace) -> int:
    from synth.campaign import summarize
    from synth.dataset import (
        alpha_coverage,
        dataset_status,
        incomplete_message,
        load_dataset,
        load_sortie,
        read_manifest_if_dataset,
        read_sortie_manifest,
        written_entries,
    )

    if read_sortie_manifest(args.dataset) is not None:
        from synth.sortie import summarize_sortie

        print(summarize_sortie(load_sortie(args.dataset).manifest))
        return 0
    manifest = read_manifest_if_dataset(args.dataset)
    if manifest is not None and manifest.get("complete", True) is False:
        print(f"INCOMPLETE: {incomplete_message(args.dataset, dataset_status(args.dataset, manifest))}")
        print("written so far:")
        print(summarize({**manifest, "maneuvers": written_entries(args.dataset, manifest)}))
        return 1
    ds = load_dataset(args.dataset)
    print(summarize(ds.manifest))
    coverage = alpha_coverage(ds)
    if len(coverage):
        print("true angle of attack at the CG per nominal Mach, deg:")
        print(coverage.to_string(float_format=lambda v: f"{v:.2f}"))
    return 0


CALIBRATE_EPILOG = """\
PROBLEM.toml is a problem file: your flight data (CSV, text, Parquet, PX4 ULog or MATLAB; `fpr streams
LOG` lists a log's streams), column names (a log's: STREAM.FIELD paths) and units,
sensor positions, CG, the channel models and which parameters are free; see docs/user-guide.md
section "Problem files" and the problem-file schema in estimator/io/__init__.py. A dataset
directory written by `fpr fly` works too (then --kind, --config, --aircraft, --mach-min,
--mach-max and --gear pick maneuvers, and the recovery table compares each estimate with the
injected truth).

By default the Mach-bin calibration workflow runs (estimator/workflow.py): it needs a Mach signal
(map a `mach` column in the problem file; a dataset has one) and at least 3 maneuvers of steady
Mach in a bin; it writes report.html with its CSV tables. --single runs one estimation over all
selected maneuvers instead, with or without Mach.

Every estimation ends with a verdict: SUCCESS, SUCCESS WITH WARNINGS (read each warning) or
FAILURE (do not use the estimates), with its reasons per channel, maneuver and time: the fit is
judged against each channel's own noise floor (a wrong minimum, a stuck or dead channel, a unit
or sign error, outliers, turbulence), and every parameter the data do not determine is reported
as held or on a bound, with why. Exit status: 0 success, 3 success with warnings, 1 failure,
2 bad input or usage.

With --single, writes to --out: result.json (everything, the verdict first), parameters.csv
(estimates, Cramer-Rao and coloured-residual standard deviations, state: estimated / held /
on_bound / fixed and why), findings.csv (the verdict's reasons), fit_quality.csv (per maneuver and
channel), residuals.csv, correlation.csv, time_history_match.png (paper Fig. 3),
residual_crossplot_<channel>.png per flow-angle channel, and for synthetic datasets recovery.csv.

examples:
  fpr calibrate my_flight.toml --out results/flight421
  fpr calibrate my_flight.toml --single --out results/flight421-single
  fpr calibrate data/small --kind pitch_doublet shss --mach-min 0.55 --mach-max 0.65 --out res
"""


def _add_calibrate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "calibrate",
        help="estimate sensor calibrations by flight path reconstruction (output-error method)",
        description="Estimate IMU biases, time delays, flow-angle biases, scale factors and "
        "correction tables from many maneuvers at once by Flight Path Reconstruction and the "
        "Output Error Method.",
        epilog=CALIBRATE_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("source", type=Path, help="problem file (TOML) or dataset directory")
    p.add_argument("--out", type=Path, default=None,
                   help="results directory (default: fpr-out/calibrate-<name>)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the results of an earlier run in --out (only the files fpr wrote "
                   "there, as listed in its .fpr-written.json; a folder holding anything else is refused)")
    # the option flags default to None (not given): the problem file's [solver]/[workflow]/[report]
    # options then hold, and the library's defaults under them (the same as these flags' defaults)
    p.add_argument("--max-iterations", type=int, default=None,
                   help="Gauss-Newton iterations per estimation (default: the problem file's, else 40)")
    p.add_argument("--no-colored", action="store_true",
                   help="skip the coloured-residual (Morelli-Klein) standard deviations")
    p.add_argument("--no-plots", action="store_true", help="do not draw figures")
    p.add_argument("--verbose", action="store_true", help="one line per iteration")
    p.add_argument("--single", action="store_true",
                   help="one estimation over every selected maneuver instead of the Mach-bin workflow")
    p.add_argument("--robust", action="store_true",
                   help="exclude the residual outliers the diagnostics find and estimate again (each "
                   "excluded sample is reported)")
    p.add_argument("--method", choices=["output_error", "filter_error"], default=None,
                   help="output_error (calm air; the default) or filter_error: the turbulent wind as "
                   "estimated states (Kalman-filter innovations; for flights in turbulence)")
    p.add_argument("--start", choices=["staged", "given", "both"], default=None,
                   help="start: staged (attitude, then speed and height, then flow channels; the "
                   "default), given (the problem's start values), or both (the better verdict kept)")
    p.add_argument("--max-mach-variation", type=float, default=None,
                   help="workflow: leave out maneuvers whose Mach varies by more (default: the problem "
                   "file's, else 0.05)")
    p.add_argument("--reference-mach", type=float, default=None,
                   help="workflow: Mach of the installation biases (default: the problem file's "
                   "[workflow] reference_mach, else the model set's; Tejas 0.5)")
    g = p.add_argument_group("selecting maneuvers of a dataset")
    g.add_argument("--kind", nargs="+", help="maneuver kinds")
    g.add_argument("--config", nargs="+", help="configuration ids")
    g.add_argument("--aircraft", nargs="+", help="aircraft ids")
    g.add_argument("--mach-min", type=float, help="lowest mean Mach")
    g.add_argument("--mach-max", type=float, help="highest mean Mach")
    g.add_argument("--gear", choices=["up", "down"], help="gear position")
    g.add_argument("--free", nargs="+", default=[], metavar="PARAM",
                   help="free these parameter families (e.g. h0)")
    g.add_argument("--fix", nargs="+", default=[], metavar="PARAM",
                   help="fix these parameter families at their start values")
    g.add_argument("--model", default=None, metavar="MODEL_SET",
                   help="model set: a shipped name (tejas, the default; tejas_ins: with the INS ground "
                   "velocities and the steady wind per maneuver) or a TOML path")


def _calibrate(args: argparse.Namespace) -> int:
    import warnings

    from estimator.calibration import CalibrationOptions, write_estimation
    from estimator.finding_groups import verdict_text
    from estimator.io import DataWarning, load_problem, problem_from_dataset
    from estimator.solver import estimate

    src = args.source
    overrides = {**{n: {"free": True} for n in args.free}, **{n: {"free": False} for n in args.fix}}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DataWarning)
        if src.is_dir():
            select = {k: v for k, v in {
                "kind": args.kind, "configuration": args.config, "aircraft": args.aircraft,
                "mach_min": args.mach_min, "mach_max": args.mach_max,
                "gear_down": None if args.gear is None else args.gear == "down",
            }.items() if v is not None}
            problem = problem_from_dataset(src, select=select or None, overrides=overrides or None,
                                           **({"model": args.model} if args.model else {}))
        else:
            if overrides or args.model:
                print("fpr calibrate: --free/--fix/--model apply to datasets; edit the problem file's "
                      "model = ... and [parameter.*] tables instead", file=sys.stderr)
                return 2
            problem = load_problem(src)
    for w in caught:
        print(f"warning: {w.message}", file=sys.stderr)
    out = args.out or Path("fpr-out") / f"calibrate-{src.stem or src.name}"
    # the problem file's [solver]/[workflow]/[report] options, the flags given overriding them
    options = {**problem.options, **_calibration_options(args)}
    if not args.single:
        return _workflow(problem, out, options, overwrite=args.overwrite, source=src)
    tool, protect = "fpr calibrate --single", _inputs(problem, src)
    _prepare_out(out, args.overwrite, tool, protect, check_only=True)
    n_samples = sum(m.n for m in problem.maneuvers)
    print(f"{len(problem.maneuvers)} maneuvers, {n_samples} samples, {len(problem.channels)} "
          f"channels, {int(problem.parameters.free_mask.sum())} free parameters")
    # the same mapping of the flags as the workflow's
    chosen = CalibrationOptions.from_mapping(options)
    result = estimate(problem, chosen.workflow.solver)
    print(result.summary())
    truth = rec = None
    if any("dataset" in m.meta for m in problem.maneuvers):
        from campaigns.truth import recovery_table, true_parameters

        truth = true_parameters(problem, result.free_estimated)
        rec = recovery_table(result, truth)
    write_estimation(problem, result, out, overwrite=args.overwrite, plots=chosen.plots,
                     extra_csv=None if rec is None else {"recovery.csv": rec}, protect=protect, tool=tool)
    if rec is not None:
        shown = rec[rec["kind"].isin(["time_delay", "bias", "scale", "table"])]
        print("\nrecovery against the injected truth (calibration parameters; all in recovery.csv):")
        print(shown.to_string(float_format=lambda v: f"{v: .4g}"))
        print("model-structure error (rms of the best possible fit to the clean channels): " + ", ".join(
            f"{c} {v * 57.29578:.4f} deg" for c, v in truth.structure_rms.items()))
    print(f"\nresults in {out}")
    print(verdict_text(result.verdict, result.findings, max_lines=0))
    return exit_status(result.verdict)


def _prepare_out(out: Path, overwrite: bool, tool: str, protect: list[Path], check_only: bool = False):
    """``out`` made ready for a run's results (:func:`estimator.io.outdir.prepare_output`).

    Only the files fpr itself wrote there (its listing, ``.fpr-written.json``) are ever removed, and
    only with ``overwrite``; a folder holding anything else, or one of the run's inputs (``protect``),
    is refused with an ``OutputFolderError`` naming what is there (a ValueError: :func:`main` prints
    it, exit status 2). ``check_only`` raises the same refusals and changes nothing: called before
    the work, so that a refusal comes at once and an earlier run's results stay until new ones are
    ready to be written.
    """
    from estimator.io.outdir import check_output, prepare_output

    if check_only:
        return check_output(out, overwrite=overwrite, protect=protect)
    return prepare_output(out, overwrite=overwrite, tool=tool, protect=protect)


def _inputs(problem, *paths: Path) -> list[Path]:
    """The run's input files and folders (never removed from an output folder)."""
    from estimator.io.outdir import input_paths

    return [*paths, *input_paths(problem)]


def _fmt_table2(acc, title: str) -> str:
    """Table 2 as text: sensors x Mach, 3 sigma in deg, * where it misses the desired accuracy."""
    if acc is None or acc.empty:
        return f"{title}: no data"
    # a table without the column (the truth's Table 2) judges every cell
    judged = (acc if "judged" in acc else acc.assign(judged=True))["judged"].astype(bool)
    a = acc.assign(col=[f"M{m:.2f}{' down' if g == 'down' else ''}" for m, g in zip(acc["mach"], acc["gear"],
                                                                                    strict=True)],
                   cell=[f"{v:.3f}{'' if ok else '*' if j else '?'}" for v, ok, j in
                         zip(acc["three_sigma_deg"], acc["passed"], judged, strict=True)])
    t = a.pivot_table(index=["sensor", "desired_deg"], columns="col", values="cell", aggfunc="first",
                      sort=False)
    missed, unjudged = int((~acc["passed"] & judged).sum()), int((~judged).sum())
    verdict = "every sensor meets its desired accuracy" if acc["passed"].all() else ", ".join(
        [f"{missed} cell(s) miss it (*)"] * bool(missed) + [f"{unjudged} not judged (?)"] * bool(unjudged))
    return f"{title} (deg; desired = +- 3-sigma target): {verdict}\n{t.to_string()}"


def _calibration_options(args: argparse.Namespace) -> dict:
    """The ``fpr calibrate`` flags the user gave, as calibration option names
    (:meth:`CalibrationOptions.from_mapping`); a flag not given is left out, so that the problem
    file's option (or the default) holds."""
    given = {"max_mach_variation": args.max_mach_variation, "reference_mach": args.reference_mach,
             "max_iterations": args.max_iterations, "start": args.start,
             "colored": False if args.no_colored else None, "verbose": True if args.verbose else None,
             "robust": True if args.robust else None, "plots": False if args.no_plots else None,
             "method": args.method}
    return {k: v for k, v in given.items() if v is not None}


def _workflow(problem, out: Path, options: dict, *, overwrite: bool, tool: str = "fpr calibrate",
              source: Path | None = None) -> int:
    """The Mach-bin calibration workflow and its report: :func:`estimator.calibrate`, then
    :meth:`~estimator.calibration.Calibration.write` with the truth sections of a synthetic dataset."""
    from campaigns.truth_report import truth_sections
    from estimator.calibration import CalibrationOptions, calibrate
    from estimator.finding_groups import verdict_text

    # refused at once if --out holds anything but an earlier run's files (or those without
    # --overwrite); the earlier files are removed only when the new report is ready to be written
    protect = _inputs(problem, *([source] if source is not None else []))
    _prepare_out(out, overwrite, tool, protect, check_only=True)
    n_samples = sum(m.n for m in problem.maneuvers)
    print(f"{len(problem.maneuvers)} maneuvers, {n_samples} samples, {len(problem.channels)} channels: "
          "Mach-bin calibration workflow (paper §4)")
    cal = calibrate(problem, CalibrationOptions.from_mapping(options), progress=print)
    wf = cal.workflow
    print("\n".join(wf.notes))
    print(f"workflow done in {wf.elapsed_s:.0f} s; writing the report")
    tables = cal.write(out, overwrite=overwrite, truth=truth_sections, protect=protect, tool=tool)
    if not wf.final:
        print()
        print(verdict_text(wf.verdict, wf.finding_groups()))
        print(f"\nreport: {tables['report']}")
        return exit_status(wf.verdict)
    print()
    print(_fmt_table2(tables["accuracy"], "Table 2, measurement - model (3-sigma)"))
    if tables["true_accuracy"] is not None:
        print()
        print(_fmt_table2(tables["true_accuracy"], "Table 2 against the truth, calibrated - true flow angle"))
        ir = tables["installation_recovery"]
        if ir is not None and len(ir):
            colored = (f"{int((ir['z_colored'].abs() < 3).sum())} within 3 coloured-residual sigma"
                       if ir["z_colored"].notna().any() else
                       "no coloured-residual sigma (not computed: --no-colored, or undetermined)")
            print(f"\ninstallation biases vs truth: {int((ir['z'].abs() < 3).sum())} of {len(ir)} within "
                  f"3 Cramer-Rao sigma, {colored}; largest error {ir['error_deg'].abs().max():.4f} deg")
            print(ir[["aircraft", "vane", "estimate_deg", "truth_deg", "std_deg", "z", "std_colored_deg",
                      "z_colored"]].to_string(index=False, float_format=lambda v: f"{v: .4f}"))
        rec = tables["recovery"]
        if rec is not None and len(rec):
            summ = rec.assign(crb=rec["z_crb"].abs() < 3, colored=(rec["z_colored"].abs() < 3).where(
                rec["z_colored"].notna())).groupby("kind")[["crb", "colored"]].mean()
            print("\nrecovery: fraction of estimates within 3 Cramer-Rao / coloured-residual sigmas of "
                  "their truth")
            print(summ.to_string(float_format=lambda v: f"{v:.2f}"))
    print()
    print(verdict_text(wf.verdict, wf.finding_groups()))
    print(f"\nreport: {tables['report']}")
    return exit_status(wf.verdict)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fpr",
        description="Flow-angle sensor calibration by Flight Path Reconstruction: JSBSim testbed "
        "and estimator.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    _add_fly(sub)
    _add_calibrate(sub)
    d = sub.add_parser("demo", help="fly the demo fleet campaign, run the calibration workflow, "
                       "print Table 2 (model and truth) and the recovery summary, write the report; "
                       "then a light-turbulence block calibrated by the filter-error method")
    d.add_argument("--out", type=Path, default=Path("fpr-out/demo"),
                   help="where to write the demo dataset (default: fpr-out/demo); the report goes to "
                   "<out>-report, the light-turbulence block's dataset and report to <out>-turbulence "
                   "and <out>-turbulence-report. An earlier demo's datasets and reports are replaced; a "
                   "folder holding anything else is refused")
    d.add_argument("--workers", type=int, default=None,
                   help="worker processes flying the calm block (default: as fpr fly's); with more than one, "
                   "one more process flies and calibrates the light-turbulence block beside it, its "
                   "output printed after the calm block's; 1: both blocks in this process, one after "
                   "the other")
    show_help = ("summarise a dataset written by `fpr fly`: maneuvers per kind, Mach and "
                 "configuration, failures; an interrupted (incomplete) dataset is said to be one, with "
                 "the command that completes it (exit status 1)")
    s = sub.add_parser("show", help=show_help, description=show_help[0].upper() + show_help[1:] + ".")
    s.add_argument("dataset", type=Path, help="the dataset directory (fpr fly --out)")
    streams_help = ("list the streams of a flight log (a PX4 ULog's topics, a MATLAB file's structs): "
                    "fields, samples, time span, rate and dropouts, to write a problem file's [columns] "
                    "paths (STREAM.FIELD) from")
    st = sub.add_parser("streams", help=streams_help,
                        description=streams_help[0].upper() + streams_help[1:] + ".")
    st.add_argument("log", type=Path, help="the log file (.ulg, .mat)")
    st.add_argument("--format", choices=("ulog", "mat"), default=None,
                    help="the log's format (default: from the extension)")
    st.add_argument("--time-unit", default=None, metavar="UNIT",
                    help="the unit of the streams' stamps, e.g. s, ms, us (default: us for a ULog, s for "
                    "a MATLAB file; a MATLAB file of PX4 topics, as fpr export writes it, stamps in us)")
    ap_help = ("write a calibrated airspeed scale as the autopilot's parameter (PX4 ASPD_SCALE_1, "
               "ArduPilot ARSPD_RATIO) in the ground station's parameter-file format, from the result.json "
               "of fpr calibrate --single; refused (exit 1) when the verdict or the estimate says it must "
               "not be used")
    ap = sub.add_parser("autopilot", help=ap_help, description=ap_help[0].upper() + ap_help[1:] + ".")
    ap.add_argument("result", type=Path,
                    help="result.json, or the folder of fpr calibrate --single holding it")
    ap.add_argument("--autopilot", choices=("px4", "ardupilot"), required=True)
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--in-force", type=float, help="the parameter's value during the flight")
    src.add_argument("--log", type=Path, help="a PX4 ULog of the flight: the value in force read from it")
    ap.add_argument("--scale", required=True,
                    help="the model set's scale factor of the airspeed (the uav model set's: k_tas)")
    ap.add_argument("--name", default=None, help="the parameter's name (default ASPD_SCALE_1 / ARSPD_RATIO)")
    ap.add_argument("--out", type=Path, required=True,
                    help="the parameter file to write (.params for QGroundControl, .param for Mission "
                    "Planner); an existing file is never replaced")
    eh = ("write a whole sortie (fpr fly --sortie) as a PX4 log: a ULog (.ulg) or a MATLAB file (.mat), "
          "PX4's topic names and units, each recorder's stream on its own clock")
    ep = sub.add_parser("export", help=eh, description=eh[0].upper() + eh[1:] + ".")
    ep.add_argument("sortie", type=Path, help="the sortie directory")
    ep.add_argument("--out", type=Path, required=True,
                    help="the log to write (.ulg or .mat); an existing file is never replaced")
    mh = ("find the test maneuvers in a whole flight (a sortie of fpr fly --sortie, or the files of a "
          "problem file read whole) from its motion alone: kind, excitation start and end, the window "
          "for a calibration, speed and its drift, an excitation measure and a grade (keep / "
          "borderline / discard) with its reason; --out writes a problem file of them for fpr calibrate")
    mp = sub.add_parser("maneuvers", help=mh, description=mh[0].upper() + mh[1:] + ".")
    mp.add_argument("source", type=Path,
                    help="a sortie directory, or a problem file (.toml) whose [columns] map t, ax, ay, "
                    "az, p, q, r (and phi, psi, h, tas or mach: the more, the more kinds are found); its "
                    "[extraction] table sets the thresholds")
    mp.add_argument("--out", type=Path, default=None,
                    help="write a problem file (.toml) calibrating the maneuvers graded keep and "
                    "borderline (an existing file is never replaced)")
    mp.add_argument("--keep-only", action="store_true", help="with --out: leave the borderline ones out")
    mp.add_argument("--csv", type=Path, default=None, help="also write the table as CSV")
    xh = ("write a small flight to calibrate, as a user's would come: three maneuvers of a target drone "
          "(an AOA vane and a sideslip vane with biases, scale factors and delays) as CSV files, and "
          "the problem file that names them; then run fpr calibrate DIR/uav.toml")
    xp = sub.add_parser("example", help=xh, description=xh[0].upper() + xh[1:] + ".")
    xp.add_argument("out", type=Path, metavar="DIR",
                    help="the folder to write into (its example files must not exist)")
    xp.add_argument("--seed", type=int, default=12, help="the noise's and trajectories' seed (default 12)")
    from campaigns import montecarlo_cli

    montecarlo_cli.add_parser(sub)
    return parser


def _example(args: argparse.Namespace) -> int:
    from campaigns.example import write_example

    path = write_example(args.out, seed=args.seed)
    print(f"wrote {path} and its three CSV files; calibrate them with:\n  fpr calibrate {path}")
    return 0


def _autopilot(args: argparse.Namespace) -> int:
    from estimator.autopilot import (
        PARAMETERS,
        ExportRefused,
        from_result,
        in_force_from_ulog,
        write_mission_planner,
        write_qgc,
    )

    result = args.result / "result.json" if args.result.is_dir() else args.result
    if args.out.exists():
        print(f"fpr autopilot: error: {args.out} exists: choose another --out (it is never replaced)",
              file=sys.stderr)
        return 2
    name = args.name or PARAMETERS[args.autopilot]
    in_force = args.in_force if args.log is None else in_force_from_ulog(args.log, name)
    try:
        p = from_result(result, args.autopilot, in_force, args.scale, name)
    except ExportRefused as exc:
        print(f"fpr autopilot: refused: {exc}", file=sys.stderr)
        return 1
    (write_qgc if args.autopilot == "px4" else write_mission_planner)(args.out, [p])
    print(f"{p.name}: in force {p.in_force:.6g} -> {p.value:.6g} +- {p.std:.2g} ({p.scale_key} = "
          f"{p.k:.5g} +- {p.k_std:.2g}); written to {args.out}")
    return 0


def _export(args: argparse.Namespace) -> int:
    from synth.dataset import read_sortie_manifest
    from synth.export import PX4_TOPICS, write_sortie_log

    if args.out.exists():
        print(f"fpr export: error: {args.out} exists: choose another --out (it is never replaced)",
              file=sys.stderr)
        return 2
    if read_sortie_manifest(args.sortie) is None:
        print(f"fpr export: error: {args.sortie} is not a sortie (fpr fly CAMPAIGN --sortie --out DIR)",
              file=sys.stderr)
        return 2
    write_sortie_log(args.sortie, args.out)
    print(f"{args.out}: topics {', '.join(PX4_TOPICS)} (fpr streams {args.out} lists them)")
    return 0


def _maneuvers(args: argparse.Namespace) -> int:
    import pandas as pd

    from estimator.extraction import find_maneuvers
    from estimator.io.flight import found_problem, read_flights

    if args.out is not None and args.csv is not None and args.out.resolve() == args.csv.resolve():
        print("fpr maneuvers: error: --out and --csv name the same file; give two", file=sys.stderr)
        return 2
    for path in (args.out, args.csv):
        if path is not None and path.exists():
            print(f"fpr maneuvers: error: {path} exists: choose another name (it is never replaced)",
                  file=sys.stderr)
            return 2
    flights, options = read_flights(args.source)
    tables = [find_maneuvers(f.signals, options) for f in flights]
    shown = ["kind", "t_start_s", "t_end_s", "t_excitation_start_s", "t_excitation_end_s", "speed",
             "speed_variation", "excitation", "excitation_unit", "grade", "reason"]
    for table in tables:
        with pd.option_context("display.width", 250, "display.max_rows", None, "display.max_columns", None,
                               "display.max_colwidth", 80):
            df = table.to_pandas()
            print(df[shown].to_string(float_format=lambda v: f"{v:.3f}") if len(df) else "(none)")
        print(table.message)
    if args.csv is not None:
        pd.concat([t.to_pandas().assign(source=t.source) for t in tables]).to_csv(args.csv)
        print(f"table written to {args.csv}")
    if args.out is not None:
        args.out.write_text(found_problem(args.source, tables, args.out, borderline=not args.keep_only),
                            encoding="utf-8")
        print(f"problem file written to {args.out}: fpr calibrate {args.out}")
    return 0


def _streams(args: argparse.Namespace) -> int:
    import pandas as pd

    from estimator.io.logs import stream_table
    from estimator.io.units import get_unit

    factor = None
    if args.time_unit is not None:
        unit = get_unit(args.time_unit, "fpr streams --time-unit")
        if unit.dimension != "time":
            print(f"fpr streams: error: --time-unit {args.time_unit} is a unit of {unit.dimension}; give "
                  "one of time: s, ms, us", file=sys.stderr)
            return 2
        factor = unit.factor
    table = stream_table(args.log, args.format, time_factor_s=factor)
    with pd.option_context("display.width", 200, "display.max_rows", None, "display.max_columns", None):
        print(table.to_string(index=False, float_format=lambda v: f"{v:.3f}"))
    return 0


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from campaigns import montecarlo_cli

    handlers = {"fly": _fly, "demo": _demo, "show": _show, "calibrate": _calibrate, "streams": _streams,
                "autopilot": _autopilot, "maneuvers": _maneuvers, "export": _export, "example": _example,
                **dict.fromkeys(montecarlo_cli.COMMANDS, montecarlo_cli.run)}
    try:
        code = handlers[args.command](args)
        sys.stdout.flush()  # a reader that has gone is found here, not at exit
        return code
    except INPUT_ERRORS as exc:
        print(f"fpr {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # the reader of the output has gone (`fpr show DIR | head`): stop quietly, as `cat` does;
        # stdout now leads nowhere, so that the flush at exit does not fail again
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # 128 + SIGPIPE


if __name__ == "__main__":
    sys.exit(main())
