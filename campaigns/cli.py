"""The ``fpr`` command line: where the synthesizer and the estimator meet.

    fpr fly CAMPAIGN.toml --out DIR     fly a campaign into a dataset
    fpr fly --mach 0.5 0.7 --maneuver pitch_doublet --out DIR      ... or one given by flags
    fpr demo                            fly the small demo campaign and summarise it
    fpr show DIR                        summarise an existing dataset
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

FLY_EPILOG = """\
A campaign TOML names the fleet, Mach numbers, maneuvers, errors and winds; see
campaigns/default.toml (the default campaign: five aircraft, seven configurations, Mach 0.3-0.9,
every maneuver type, gear-down maneuvers) and campaigns/demo.toml. Without a file, the flags
describe a one-block campaign.

The output directory holds manifest.json and maneuvers/mNNNN.parquet, one file per maneuver
(SHSS segments get mNNNNsK): measured channels and truth channels (prefix true_), SI units.
Load it with `synth.dataset.load_dataset(DIR)`.

Maneuvers that fail (the aircraft departs, a controller cannot hold its target) are reported and
listed in the manifest; the exit status is then 1.

examples:
  fpr fly default --out data/default
  fpr fly --config PV1-NP PT1-BOOM --mach 0.4 0.6 --maneuver pitch_doublet shss --out data/small
  fpr fly --mach 0.3 --maneuver pitch_doublet --gear-down --altitude-m 1000 --out data/gear
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
    p.add_argument("--out", required=True, type=Path, help="dataset directory to create")
    p.add_argument("--overwrite", action="store_true", help="replace an existing dataset at --out")
    p.add_argument("--workers", type=int, default=None, help="worker processes (default: all CPUs)")
    g = p.add_argument_group("campaign by flags (ignored when a campaign file is given)")
    g.add_argument("--config", nargs="+", default="all", metavar="ID",
                   help="fleet configuration ids (default: all seven)")
    g.add_argument("--mach", nargs="+", type=float, default=[0.5], help="Mach numbers (0.3-0.9)")
    g.add_argument("--maneuver", nargs="+", default="all", metavar="KIND",
                   help="maneuver kinds (default: all); see synth.maneuvers.MANEUVER_KINDS")
    g.add_argument("--altitude-m", type=float, default=6000.0, help="trim altitude, m")
    g.add_argument("--gear-down", action="store_true", help="fly with the landing gear down")
    g.add_argument("--seed", type=int, default=0, help="master seed for errors and turbulence")
    g.add_argument("--errors", default="typical", choices=["typical", "none"],
                   help="error preset: SPEC §6 typical magnitudes, or none (truth only)")
    g.add_argument("--planet", default="flat", choices=["flat", "wgs84"],
                   help="flat non-rotating earth, or JSBSim's rotating WGS84 ellipsoid")
    g.add_argument("--turbulence", default="none", choices=["none", "light", "moderate", "severe"])
    g.add_argument("--wind-ned-mps", nargs=3, type=float, default=[0.0, 0.0, 0.0],
                   metavar=("N", "E", "D"), help="steady wind, NED, m/s")
    g.add_argument("--rate-hz", type=float, default=40.0, help="common time base, Hz")


def _fly(args: argparse.Namespace) -> int:
    from synth.campaign import flags_campaign, fly_campaign, load_campaign, parse_campaign, summarize

    if args.campaign:
        campaign = load_campaign(args.campaign)
    else:
        campaign = parse_campaign(
            flags_campaign(
                configurations=args.config, mach=args.mach, maneuvers=args.maneuver,
                altitude_m=args.altitude_m, gear_down=args.gear_down, seed=args.seed,
                errors_preset=args.errors, planet=args.planet, turbulence=args.turbulence,
                wind_ned_mps=args.wind_ned_mps, common_rate_hz=args.rate_hz,
            ),
            source="command-line flags",
        )
    print(f"campaign {campaign.name!r}: {len(campaign.jobs)} maneuvers -> {args.out}")
    result = fly_campaign(campaign, args.out, workers=args.workers, overwrite=args.overwrite,
                          progress=True)
    print(summarize(result.manifest))
    print(f"wrote {args.out} in {result.wall_s:.1f} s")
    return 0 if result.ok else 1


def _demo(args: argparse.Namespace) -> int:
    from synth.campaign import fly_campaign, load_campaign, summarize

    t0 = time.perf_counter()
    campaign = load_campaign("demo")
    out = args.out
    print(f"fpr demo: flying the demo campaign ({len(campaign.jobs)} maneuvers, seven fleet "
          f"configurations) into {out}")
    result = fly_campaign(campaign, out, workers=args.workers, overwrite=True, progress=True)
    print(summarize(result.manifest))
    print(f"\ndataset written to {out} ({time.perf_counter() - t0:.1f} s). "
          "Load it with synth.dataset.load_dataset().")
    return 0 if result.ok else 1


def _show(args: argparse.Namespace) -> int:
    from synth.campaign import summarize
    from synth.dataset import load_dataset

    ds = load_dataset(args.dataset)
    print(summarize(ds.manifest))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fpr",
        description="Flow-angle sensor calibration by Flight Path Reconstruction: JSBSim testbed "
        "and estimator.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    _add_fly(sub)
    d = sub.add_parser("demo", help="fly the small demo campaign and print a summary")
    d.add_argument("--out", type=Path, default=Path("fpr-out/demo"),
                   help="where to write the demo dataset (default: fpr-out/demo; replaced)")
    d.add_argument("--workers", type=int, default=None, help="worker processes (default: all CPUs)")
    s = sub.add_parser("show", help="summarise a dataset written by `fpr fly`")
    s.add_argument("dataset", type=Path)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    handlers = {"fly": _fly, "demo": _demo, "show": _show}
    try:
        return handlers[args.command](args)
    except (FileNotFoundError, FileExistsError, ValueError, KeyError) as exc:
        print(f"fpr {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
