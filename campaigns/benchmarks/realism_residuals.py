"""Benchmark: the kinematic channels' residuals at the realism level, against real recorded flights.

    python campaigns/benchmarks/realism_residuals.py --out runs/realism_residuals [--workers 2]
        [--results campaigns/benchmarks/results/realism_residuals.txt] [--no-sources]

Real recorded flights of good quality show kinematic-channel residuals (attitude, heading,
airspeed, height) of 2-20 x their white-noise floor, with lag-1 autocorrelations of 0.86-0.99
(SPEC §6); a testbed flight with the typical errors of SPEC §6 alone fits at its floor, white. The
realism level (docs/realism.md) adds the imperfections real installations have, each from physics
and typical flight-test instrumentation -- not tuned to any ratio. This benchmark reports what it
gives.

1. It flies ``campaigns/realism.toml`` (the realism level: ``real_world`` errors, slow vertical
   air motion) and the same campaign with the realism level off (``preset = "typical"``, no
   vertical air motion: the same maneuvers, seeds and steady wind), and with ``--sources`` (the
   default) once per realism source alone on top of ``typical``; the datasets are kept in
   ``--out`` and reused (a complete dataset of the same campaign is not flown again).
2. It estimates each as a user does: ``problem_from_dataset`` with one Mach bin's maneuvers
   (the workflow's unit, SPEC §8: 18 maneuvers per bin), ``estimate(problem, SolverOptions())``
   with the default options, for the paper's model set ``tejas`` and for ``tejas_ins`` (which also
   fits the INS velocities).
3. From each result's fit-quality table (``result.diagnostics``: one row per maneuver and
   channel) it tabulates per kinematic channel: the residual's ratio to the channel's white-noise
   floor (median and range over the maneuvers), its lag-1 autocorrelation (range) and rms in
   display units, realism level beside typical beside the real flights' figures.
4. Table 2 against the truth (:func:`campaigns.workflow_truth.calibrated_errors`: each calibrated
   flow channel through its estimated model minus the true flow angle at its sensor), 3 sigma per
   sensor and Mach bin of the ``tejas`` estimation, against the model set's desired accuracy: are
   the calibrated sensors still within it? (One estimation per bin, not the workflow's apportioned
   biases; the nose probe judged below alpha 10 deg, its high-AOA onset.) With ``--sources``, the
   same per source alone, and for the static-source error and the whole realism level once more
   without the wind-up turns (banked flight turns a height error into a sideslip error).

Each estimation's verdict, its failure and warning findings (by code) and the import's data
warnings are listed with it. Wall time about 5 minutes on two cores (22 estimations of 12-18
maneuvers, 7 datasets of 36 maneuver files flown once and then reused).

The printed text is committed as ``campaigns/benchmarks/results/realism_residuals.txt``.
"""

from __future__ import annotations

import argparse
import copy
import math
import os
import platform
import sys
import time
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(ROOT))

from campaigns.machine import cpu_model, memory_gib  # noqa: E402
from synth.campaign import fly_campaign, parse_campaign, software_versions  # noqa: E402
from synth.errors import RealismErrors  # noqa: E402

CAMPAIGN = ROOT / "campaigns" / "realism.toml"
MACH_BINS = (0.5, 0.7)
MACH_HALF_WIDTH = 0.05
MODELS = ("tejas", "tejas_ins")
#: kinematic channels of the fit-quality table, in print order, and the real flights' ratio
KINEMATIC = ("phi", "theta", "psi", "tas", "h", "h_dgps", "vn", "ve", "vd")
REAL_RATIO = {"phi": "2.6-5.8", "theta": "6-8", "psi": "2.3-14.6", "tas": "2.7-5.5", "h": "22 (4.2 m)",
              "h_dgps": "22 (4.2 m)"}
REAL_FLIGHTS = ("real recorded flights (textbook transport aircraft and fighter data-compatibility "
                "cases): height 4.2 m rms at 22 x floor; airspeed 2.7-5.5 x; pitch 6-8 x; heading "
                "2.3-14.6 x; bank 2.6-5.8 x; lag-1 autocorrelation 0.86-0.99 everywhere")
#: each realism source alone: the [errors.realism] fields it switches on (typical values), or the
#: environment's vertical air motion
SOURCES = {
    "INS attitude (filter)": ("ins_attitude_sigma_rad", "ins_attitude_tau_s"),
    "IMU scale/misalignment": ("accel_scale", "gyro_scale", "accel_nonorthogonality_rad",
                               "gyro_nonorthogonality_rad", "imu_mounting_rad"),
    "static error + lag": ("static_error_c0", "static_error_c_alpha_per_rad", "static_error_c_mach2",
                           "static_lag_s", "total_lag_s"),
    "GNSS velocity held": ("gnss_velocity_rate_hz", "gnss_velocity_latency_s"),
    "vertical air motion": (),
}
#: the nose probe's Table 2 is judged at low AOA (SPEC §8): below its high-AOA onset (typical errors)
NOSE_PROBE_ALPHA_MAX_DEG = 10.0


def variants(raw: dict, sources: bool) -> dict[str, dict]:
    """Dataset name -> campaign mapping: the realism level, typical, and each source alone."""
    out = {"realism": raw}
    off = copy.deepcopy(raw)
    off["errors"] = {"preset": "typical"}
    off["environment"].pop("vertical_air_motion", None)
    off["name"] = "realism_typical"
    out["typical"] = off
    if sources:
        typ = RealismErrors.typical()
        for k, (label, names) in enumerate(SOURCES.items()):
            v = copy.deepcopy(off)
            v["name"] = f"realism_source{k}"
            v["description"] = f"typical errors plus one realism source: {label}"
            if names:
                v["errors"]["realism"] = {n: (list(getattr(typ, n)) if isinstance(getattr(typ, n), tuple)
                                              else getattr(typ, n)) for n in names}
            else:
                vam = raw["environment"]["vertical_air_motion"]
                v["environment"]["vertical_air_motion"] = copy.deepcopy(vam)
            out[f"source{k}"] = v
    return out


def fly(name: str, raw: dict, out: Path, workers: int) -> tuple[Path, float]:
    """Fly (or reuse) one variant's dataset; its directory and the wall time spent flying, s."""
    camp = parse_campaign(raw, source=f"{CAMPAIGN.relative_to(ROOT)} ({name})")
    res = fly_campaign(camp, out / name, workers=workers, resume=True)
    if res.failures:
        raise SystemExit(f"{out / name}: {len(res.failures)} maneuvers failed to fly: {res.failures[0][1]}")
    return out / name, res.wall_s


def estimate_bins(path: Path, model: str, kinds: list[str] | None = None
                  ) -> tuple[pd.DataFrame, list[dict], dict]:
    """One estimation per Mach bin (of the maneuvers of ``kinds``; None: all): the kinematic rows
    of the fit-quality tables, a line per run, and the (problem, result) per bin."""
    from estimator import SolverOptions, estimate, problem_from_dataset

    rows, runs, fits = [], [], {}
    for mach in MACH_BINS:
        select = {"mach_min": mach - MACH_HALF_WIDTH, "mach_max": mach + MACH_HALF_WIDTH}
        if kinds is not None:
            select["kind"] = kinds
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            problem = problem_from_dataset(path, select=select, model=model)
        # the import's data warnings, by what they say (the maneuver and column names left out)
        said: dict[str, int] = {}
        for w in caught:
            gist = str(w.message).split(": ", 2)[-1]
            gist = gist.split(" (")[0] if "holds each value" not in gist else (
                "a channel holds each value for several rows (the held GNSS velocity)")
            said[gist] = said.get(gist, 0) + 1
        t0 = time.perf_counter()
        result = estimate(problem, SolverOptions())
        wall = time.perf_counter() - t0
        fq = result.diagnostics
        fq = fq[fq["channel"].isin(KINEMATIC)].assign(mach=mach)
        rows.append(fq)
        bad = {}
        for f in result.findings:
            if f.severity.name in ("FAILURE", "WARNING"):
                bad[(f.severity.name, f.code)] = bad.get((f.severity.name, f.code), 0) + 1
        runs.append({"mach": mach, "maneuvers": len(problem.maneuvers), "verdict": result.verdict.name,
                     "status": result.status.name, "wall_s": wall,
                     "findings": ", ".join(f"{s.lower()} {c} x{n}" for (s, c), n in sorted(bad.items())),
                     "data_warnings": "; ".join(f"{n} x {g}" for g, n in said.items())})
        fits[mach] = (problem, result)
    return pd.concat(rows, ignore_index=True), runs, fits


def _range(x: pd.Series, fmt: str) -> str:
    return f"{x.min():{fmt}}-{x.max():{fmt}}"


def channel_summary(fq: pd.DataFrame) -> pd.DataFrame:
    """Per channel: ratio median and range, rho1 median and range, rms (display units) median and
    range, floor median, the display unit and the number of maneuver-channels."""
    out = []
    for ch in KINEMATIC:
        d = fq[(fq["channel"] == ch) & np.isfinite(fq["ratio"])]
        if d.empty:
            continue
        out.append({"channel": ch, "unit": str(d["display_unit"].iloc[0]), "n": len(d),
                    "ratio_med": d["ratio"].median(), "ratio_rng": _range(d["ratio"], ".2f"),
                    "rho1_med": d["rho1"].median(), "rho1_rng": _range(d["rho1"], ".2f"),
                    "rms_med": d["rms_display"].median(), "rms_rng": _range(d["rms_display"], ".3g"),
                    "floor_med": d["noise_floor_display"].median()})
    return pd.DataFrame(out).set_index("channel")


def comparison_table(real: pd.DataFrame, typ: pd.DataFrame) -> list[str]:
    head = (f"{'channel':8s} {'unit':5s} | {'realism level: ratio med [range]':34s} {'rho1 med [range]':19s} "
            f"{'rms med [range]':22s} {'floor':7s} | {'typical: ratio med [range]':28s} "
            f"{'rho1 [range]':19s} {'rms med':8s} | real ratio")
    lines = [head, "-" * len(head)]
    for ch in real.index:
        r = real.loc[ch]
        t = typ.loc[ch] if ch in typ.index else None
        line = (f"{ch:8s} {r['unit']:5s} | {r['ratio_med']:6.2f} [{r['ratio_rng']:>11s}]{'':15s} "
                f"{r['rho1_med']:5.2f} [{r['rho1_rng']:>10s}] {r['rms_med']:8.3g} [{r['rms_rng']:>11s}] "
                f"{r['floor_med']:7.3g} | ")
        if t is not None:
            line += (f"{t['ratio_med']:6.2f} [{t['ratio_rng']:>11s}]{'':9s} {t['rho1_med']:5.2f} "
                     f"[{t['rho1_rng']:>10s}] {t['rms_med']:8.3g} | ")
        else:
            line += f"{'':28s} {'':19s} {'':8s} | "
        line += REAL_RATIO.get(ch, "-")
        lines.append(line)
    return lines


def truth_table(fits: dict, model_raw: dict) -> list[str]:
    """Table 2 against the truth of one dataset's tejas estimations, per sensor and Mach bin."""
    from campaigns.workflow_truth import calibrated_errors
    from estimator.accuracy import three_sigma

    req = model_raw.get("requirements", {})
    rows = []
    for mach, (problem, result) in fits.items():
        for ch, df in calibrated_errors(problem, result).items():
            if ch not in req:
                continue
            e = df["error_rad"].to_numpy() * 180.0 / math.pi
            if req[ch].get("low_alpha_only"):
                e = e[df["alpha_t_rad"].to_numpy() * 180.0 / math.pi < NOSE_PROBE_ALPHA_MAX_DEG]
            rows.append((req[ch]["sensor"], ch, mach, three_sigma(e), float(np.mean(e)),
                         float(req[ch]["desired_3sigma_deg"])))
    return rows


def _code_state() -> str:
    """The commit and which top-level folders have uncommitted changes (read-only git queries)."""
    import subprocess

    def git(*a: str) -> str:
        try:
            return subprocess.run(["git", *a], cwd=ROOT, capture_output=True, text=True, check=True).stdout
        except (OSError, subprocess.CalledProcessError):
            return ""

    head = git("rev-parse", "--short", "HEAD").strip() or "?"
    dirty = sorted({line[3:].split("/")[0] for line in git("status", "--porcelain").splitlines() if line})
    return head + (f" with uncommitted changes in {', '.join(dirty)}" if dirty else " (clean tree)")


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="folder for the datasets (reused when complete)")
    ap.add_argument("--workers", type=int, default=None, help="worker processes for flying")
    ap.add_argument("--results", default=None, help="also write the printed text to this file")
    ap.add_argument("--no-sources", action="store_true", help="skip the one-source-at-a-time datasets")
    return ap


class _Say:
    """The report: printed as it goes, and kept for ``--results``."""

    def __init__(self) -> None:
        self.lines: list[str] = []

    def __call__(self, s: str = "") -> None:
        print(s, flush=True)
        self.lines.append(s)


def _say_header(say: _Say, argv: list[str] | None, raw: dict) -> None:
    """What was run, where, on which code, and how each dataset is estimated."""
    sw = software_versions()
    mem = memory_gib()
    given = argv if argv is not None else sys.argv[1:]
    cmd = "python campaigns/benchmarks/realism_residuals.py " + " ".join(given)
    say("Realism level: kinematic-channel residuals against real recorded flights "
        "(campaigns/benchmarks/realism_residuals.py)")
    say()
    say(f"command: {cmd}")
    say(f"machine: {cpu_model()}, {os.cpu_count()} cores, "
        f"{'?' if mem is None else f'{mem:.1f} GiB'}; {platform.system()} {platform.release()}")
    say(f"python {sw['python']}, fpr-testbed {sw['fpr-testbed']}, jsbsim {sw['jsbsim']}, "
        f"numpy {sw['numpy']}, scipy {sw['scipy']}, pandas {sw['pandas']}")
    say(f"code: {_code_state()}")
    say(f"load average at start: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    say(f"campaign: {CAMPAIGN.relative_to(ROOT)}: {raw['description']}")
    say("estimation: problem_from_dataset(dataset, select=Mach bin +-0.05, model=...), "
        "estimate(problem, SolverOptions()) (default options), one per Mach bin (0.5, 0.7)")
    say()


def _say_model(say: _Say, model: str, summaries: dict, runs: dict) -> None:
    """One model set's residuals, realism level beside typical beside the real flights, and its
    estimations' verdicts."""
    say()
    say("=" * 150)
    say(f"model set {model}" + (" (the paper's; the INS velocities not fitted)" if model == "tejas" else
                                " (also fits the INS NED velocities, with a steady wind per maneuver)"))
    say(f"against {REAL_FLIGHTS}")
    say("ratio: rms(residual) / white-noise floor per maneuver and channel (median [min-max] over the "
        "maneuvers); rho1: lag-1 autocorrelation of the residual at 40 Hz; rms, floor: display units")
    say("(the real flights' height floor is 4.2 m / 22 = 0.19 m; this testbed's is its static "
        "transducer's typical 10 Pa of noise, about 1.3 m at 6 km: compare the rms too)")
    say()
    for line in comparison_table(channel_summary(summaries[("realism", model)]),
                                 channel_summary(summaries[("typical", model)])):
        say(line)
    say()
    for name in ("realism", "typical"):
        for r in runs[(name, model)]:
            say(f"  {name:8s} Mach {r['mach']}: {r['maneuvers']} maneuvers, verdict {r['verdict']}, "
                f"{r['status']}, {r['wall_s']:.1f} s; findings: {r['findings'] or 'no warnings'}"
                + (f"; import's data warnings: {r['data_warnings']}" if r["data_warnings"] else ""))


def _say_sources(say: _Say, datasets: dict, summaries: dict, runs: dict) -> dict:
    """Each realism source alone on top of typical: its residuals and verdicts; its fits by source."""
    say()
    say("=" * 150)
    say("each realism source alone on top of typical (model set tejas, both Mach bins): "
        "ratio median / rho1 median per channel")
    src_rows, src_fits = {}, {}
    for k, label in enumerate(SOURCES):
        fq, r, f = estimate_bins(datasets[f"source{k}"], "tejas")
        src_rows[label] = (channel_summary(fq), r)
        src_fits[label] = f
    chans = [c for c in KINEMATIC if c in src_rows[next(iter(SOURCES))][0].index]
    head = f"{'source':24s} | " + " ".join(f"{c:>12s}" for c in chans) + " | verdicts (Mach 0.5, 0.7)"
    say(head)
    say("-" * len(head))
    for label, (s, r) in [("typical (none)", (channel_summary(summaries[("typical", "tejas")]),
                                              runs[("typical", "tejas")])),
                          *src_rows.items(),
                          ("realism level (all)", (channel_summary(summaries[("realism", "tejas")]),
                                                   runs[("realism", "tejas")]))]:
        cells = " ".join(f"{s.loc[c, 'ratio_med']:5.2f} / {s.loc[c, 'rho1_med']:4.2f}" for c in chans)
        say(f"{label:24s} | {cells} | {', '.join(x['verdict'].lower() for x in r)}")
    return src_fits


def _say_truth(say: _Say, fits: dict, model_raw: dict) -> list:
    """Table 2 against the truth per sensor and Mach bin, realism level beside typical; its rows."""
    say()
    say("=" * 150)
    say(f"Table 2 against the truth (model set tejas, one estimation per Mach bin): 3 sigma of the "
        f"calibrated channel minus the true flow angle at its sensor, deg (nose probe: alpha < "
        f"{NOSE_PROBE_ALPHA_MAX_DEG:.0f} deg)")
    t_real = truth_table(fits[("realism", "tejas")], model_raw)
    t_typ = {(r[1], r[2]): r for r in truth_table(fits[("typical", "tejas")], model_raw)}
    head = (f"{'sensor':28s} {'channel':10s} {'Mach':>4s} | {'realism: 3 sigma (mean)':>24s} | "
            f"{'typical: 3 sigma (mean)':>24s} | desired | realism within")
    say(head)
    say("-" * len(head))
    for sensor, ch, mach, s3, mean, desired in sorted(t_real, key=lambda r: (r[1], r[2])):
        ty = t_typ.get((ch, mach))
        tcell = f"{ty[3]:.3f} ({ty[4]:+.3f})" if ty else "-"
        say(f"{sensor:28s} {ch:10s} {mach:4.1f} | {f'{s3:.3f} ({mean:+.3f})':>24s} | {tcell:>24s} | "
            f"{desired:7.2f} | {'yes' if s3 <= desired else 'NO'}")
    return t_real


def _say_truth_per_source(say: _Say, datasets: dict, fits: dict, src_fits: dict, t_real: list,
                          model_raw: dict) -> None:
    """Table 2 against the truth per realism source alone, and without the wind-up turns."""
    say()
    say("Table 2 against the truth per realism source alone (model set tejas): the larger 3 sigma of "
        "the two Mach bins, deg, and its mean error; * = beyond the desired accuracy")
    chans = sorted({r[1] for r in t_real})
    head = f"{'source':38s} | " + " ".join(f"{c:>16s}" for c in chans)
    say(head)
    say("-" * len(head))
    # the wind-up turns left out: banked at 65-78 deg, their height rate carries the lateral
    # velocity (h' = ... - v cos(theta) sin(phi)), so a height error becomes a sideslip error
    gentle = ["pitch_doublet", "3211", "shss"]
    _, static_runs, src_fits["static error + lag, no wind-up turns"] = estimate_bins(
        datasets["source2"], "tejas", gentle)
    _, realism_runs, no_windup = estimate_bins(datasets["realism"], "tejas", gentle)
    for label, fit in [("typical (none)", fits[("typical", "tejas")]), *src_fits.items(),
                       ("realism level (all)", fits[("realism", "tejas")]),
                       ("realism, no wind-up turns", no_windup)]:
        worst = {}
        for _, ch, _, s3, mean, desired in truth_table(fit, model_raw):
            if ch not in worst or s3 > worst[ch][0]:
                worst[ch] = (s3, mean, desired)
        cells = " ".join(
            f"{worst[c][0]:6.3f} ({worst[c][1]:+.3f}){'*' if worst[c][0] > worst[c][2] else ' '}"
            if c in worst else f"{'-':>16s}" for c in chans)
        say(f"{label:38s} | {cells}")
    say("the estimations without the wind-up turns:")
    for label, rr in (("static error + lag", static_runs), ("realism level", realism_runs)):
        for r in rr:
            say(f"  {label:18s} Mach {r['mach']}: {r['maneuvers']} maneuvers, verdict {r['verdict']}; "
                f"findings: {r['findings'] or 'no warnings'}")


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    t_start = time.perf_counter()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(CAMPAIGN, "rb") as fh:
        raw = tomllib.load(fh)
    from estimator.io.modelset import read_model_set

    say = _Say()
    _say_header(say, argv, raw)
    datasets = {}
    fly_wall = 0.0
    for name, v in variants(raw, not args.no_sources).items():
        path, wall = fly(name, v, out, args.workers)
        datasets[name] = path
        fly_wall += wall
    say(f"datasets in {out} (flown or reused in {fly_wall:.0f} s)")

    est_wall = time.perf_counter()
    summaries, runs, fits = {}, {}, {}
    for name in ("realism", "typical"):
        for model in MODELS:
            fq, r, f = estimate_bins(datasets[name], model)
            summaries[(name, model)] = fq
            runs[(name, model)] = r
            fits[(name, model)] = f
    for model in MODELS:
        _say_model(say, model, summaries, runs)
    src_fits = {} if args.no_sources else _say_sources(say, datasets, summaries, runs)
    model_raw = read_model_set("tejas")[0]
    t_real = _say_truth(say, fits, model_raw)
    if not args.no_sources:
        _say_truth_per_source(say, datasets, fits, src_fits, t_real, model_raw)
    est_wall = time.perf_counter() - est_wall
    say()
    say(f"wall time: {time.perf_counter() - t_start:.0f} s (flying {fly_wall:.0f} s, estimating and "
        f"tabulating {est_wall:.0f} s); load average at the end: "
        f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    if args.results:
        Path(args.results).write_text("\n".join(say.lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
