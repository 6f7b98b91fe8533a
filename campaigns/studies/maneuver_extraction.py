"""Study: the maneuver finder (`fpr maneuvers`) on whole sorties, against the truth they record.

Each configuration of the default campaign (``campaigns/default.toml``) is flown as one sortie
(``fpr fly default --sortie CONFIG``): its 73 maneuvers, 89 pieces with the steady-heading
sideslips cut in three, with the transitions between test points (speed and height changes,
heading back, gear) that a real sortie has. The finder reads the motion only; the sortie records
where each maneuver's inputs acted (``t_excitation_start_s``/``t_excitation_end_s`` of its
boundaries). Per configuration and kind:

* found: a found maneuver overlaps the truth's excitation; kind right: it has the truth's kind;
* within 1 s: its excitation start and end within 1 s of the truth's (a steady-heading sideslip:
  its window's pieces against the truth's 30-40 s pieces);
* false: a found maneuver that overlaps no truth piece, and how many last longer than 10 s.

Then the calibration: one sortie (``--calibrate CONFIG``, default PV1-NP) calibrated by the
workflow twice, from the windows found (``fpr maneuvers --out``) and from the sortie's own
boundaries (``maneuvers = "boundaries"``), and Table 2 against the truth compared cell by cell.

Run (the sorties are kept in ``--out`` and reused)::

    python -m campaigns.studies.maneuver_extraction --out runs/extraction --results campaigns/studies/results

It writes ``maneuver_extraction.txt`` into ``--results`` (default: ``--out``).
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

CONFIGURATIONS = ("PV1-NP", "PV2-NP", "PV3-NP", "PT1-NP", "PT1-BOOM", "PT2-NP", "PT2-BOOM")


def fly(out: Path, config: str) -> Path:
    """The default campaign's sortie of ``config`` in ``out`` (flown unless already there)."""
    from synth.campaign import load_campaign
    from synth.dataset import read_sortie_manifest
    from synth.sortie import fly_sortie_campaign

    path = out / f"sortie_{config}"
    if read_sortie_manifest(path) is None:
        fly_sortie_campaign(load_campaign("default"), path, configuration=config, overwrite=path.exists())
    return path


def matched(truth: pd.DataFrame, found: pd.DataFrame) -> pd.DataFrame:
    """Per truth piece: the found maneuver overlapping its excitation most, its kind and the
    start and end errors, s (a sideslip piece: its window against the truth's piece)."""
    rows = []
    for tid, r in truth.iterrows():
        ov = found[(found.t_excitation_start_s < r.t_excitation_end_s)
                   & (found.t_excitation_end_s > r.t_excitation_start_s)]
        if not len(ov):
            rows.append((tid, r.kind, None, None, np.nan, np.nan))
            continue
        length = (np.minimum(ov.t_excitation_end_s, r.t_excitation_end_s)
                  - np.maximum(ov.t_excitation_start_s, r.t_excitation_start_s))
        best = ov.iloc[int(np.argmax(length))]
        if r.kind == "shss":
            d0, d1 = best.t_start_s - r.t_start_s, best.t_end_s - r.t_end_s
        else:
            d0 = best.t_excitation_start_s - r.t_excitation_start_s
            d1 = best.t_excitation_end_s - r.t_excitation_end_s
        rows.append((tid, r.kind, best.name, best.kind, d0, d1))
    return pd.DataFrame(rows, columns=["id", "kind", "found", "found_kind", "d_start_s", "d_end_s"])


def score(path: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The matches of one sortie's truth pieces and its false maneuvers."""
    from estimator.extraction import find_maneuvers
    from estimator.io.flight import read_flights
    from synth.dataset import load_sortie

    flights, options = read_flights(path)
    found = find_maneuvers(flights[0].signals, options).to_pandas()
    m = matched(load_sortie(path).boundaries, found)
    return m, found[~found.index.isin(m["found"].dropna())]


def per_kind(matches: pd.DataFrame) -> pd.DataFrame:
    """Counts and error statistics per kind, and the total."""
    m = matches.assign(found_ok=matches["found"].notna(), kind_ok=matches["found_kind"] == matches["kind"],
                       within=(matches["d_start_s"].abs() <= 1.0) & (matches["d_end_s"].abs() <= 1.0))

    def agg(g: pd.DataFrame) -> pd.Series:
        return pd.Series({"truth": len(g), "found": int(g.found_ok.sum()), "kind_right": int(g.kind_ok.sum()),
                          "within_1s": int(g.within.sum()),
                          "start_err_median_s": float(g.d_start_s.median()),
                          "start_err_max_abs_s": float(g.d_start_s.abs().max()),
                          "end_err_median_s": float(g.d_end_s.median()),
                          "end_err_max_abs_s": float(g.d_end_s.abs().max())})

    table = m.groupby("kind").apply(agg, include_groups=False)
    table.loc["all"] = agg(m)
    return table


def _problem(problem_file: Path):
    import warnings

    from estimator.io import load_problem

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the model set's boom channels: no boom on this aircraft
        return load_problem(problem_file)


def table2_against_truth(problem) -> pd.Series:
    """Table 2 against the truth of the workflow run on ``problem``."""
    from campaigns.workflow_truth import true_accuracy
    from estimator.workflow import run_workflow

    acc, _ = true_accuracy(run_workflow(problem))
    return acc.set_index(["sensor", "mach", "gear"])["three_sigma_deg"]


def calibration(out: Path, sortie: Path) -> tuple[pd.DataFrame, str]:
    """Table 2 against the truth from the sortie's boundaries and from the windows found for the
    same maneuvers (those the workflow's bins use with the boundaries: a window found shorter can
    hold a maneuver, a pull-up at Mach 0.3, whose boundaries' window the workflow leaves out for
    its Mach varying, and Table 2 would then be taken over other data)."""
    from estimator.extraction import find_maneuvers
    from estimator.io.flight import found_problem, read_flights
    from estimator.options import WorkflowOptions
    from estimator.workflow import assign_bins
    from synth.dataset import load_sortie

    truth_file = out / f"{sortie.name}_boundaries.toml"
    truth_file.write_text(f'[data]\ndataset = "{sortie.name}"\nmaneuvers = "boundaries"\n')
    truth_problem = _problem(truth_file)
    bins = assign_bins(truth_problem, WorkflowOptions())
    used = set(bins.loc[bins["used"], "id"])
    flights, options = read_flights(sortie)
    table = find_maneuvers(flights[0].signals, options)
    m = matched(load_sortie(sortie).boundaries, table.to_pandas())
    same = set(m.loc[m["id"].isin(used), "found"].dropna())
    kept = replace(table, maneuvers=tuple(x for x in table.maneuvers if x.id in same))
    found_file = out / f"{sortie.name}_found.toml"
    found_file.write_text(found_problem(sortie, [kept], found_file))
    found_problem_ = _problem(found_file)
    found, truth = table2_against_truth(found_problem_), table2_against_truth(truth_problem)
    t = pd.DataFrame({"boundaries_deg": truth, "found_deg": found})
    extra = len(table.kept()) - len(kept.maneuvers)
    note = (f"{len(used)} maneuvers in the boundaries' bins, the same {len(kept.maneuvers)} found; "
            f"{extra} more found ones are left out here: the workflow leaves their boundaries' windows out")
    return t.assign(ratio=t.found_deg / t.boundaries_deg), note


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True, help="folder of the sorties (kept and reused)")
    p.add_argument("--results", type=Path, default=None, help="where the table goes (default: --out)")
    p.add_argument("--configs", nargs="+", default=list(CONFIGURATIONS))
    p.add_argument("--calibrate", default="PV1-NP", help="the sortie calibrated both ways ('' for none)")
    args = p.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    results = args.results or args.out
    t0 = time.perf_counter()
    lines = [f"# python -m campaigns.studies.maneuver_extraction {' '.join(argv or sys.argv[1:])}",
             f"# {platform.node()} {platform.processor() or platform.machine()}, "
             f"python {platform.python_version()}",
             ""]
    all_m, rows = [], []
    for config in args.configs:
        m, false = score(fly(args.out, config))
        all_m.append(m)
        long = false[(false.t_excitation_end_s - false.t_excitation_start_s) > 10.0]
        rows.append({"configuration": config, "truth": len(m), "found": int(m["found"].notna().sum()),
                     "kind_right": int((m["found_kind"] == m["kind"]).sum()),
                     "within_1s": int(((m.d_start_s.abs() <= 1) & (m.d_end_s.abs() <= 1)).sum()),
                     "false": len(false), "false_over_10s": len(long)})
    per_config = pd.DataFrame(rows).set_index("configuration")
    per_config.loc["all"] = per_config.sum()
    lines += ["Per sortie (the default campaign's configurations): truth pieces, found, kind right, "
              "within 1 s, false maneuvers", per_config.to_string(), "",
              "Per kind, all sorties (errors: found - truth, s)",
              per_kind(pd.concat(all_m)).to_string(float_format=lambda v: f"{v:.2f}"), ""]
    if args.calibrate:
        t2, note = calibration(args.out, fly(args.out, args.calibrate))
        lines += [f"Table 2 against the truth (3 sigma, deg), sortie {args.calibrate}: the workflow on "
                  "the sortie's boundaries and on the windows found for the same maneuvers; ratio "
                  f"found / boundaries ({note})",
                  t2.to_string(float_format=lambda v: f"{v:.3f}"),
                  f"largest |ratio - 1|: {np.max(np.abs(t2.ratio - 1)):.3f}", ""]
    lines.append(f"# wall time {time.perf_counter() - t0:.0f} s")
    text = "\n".join(lines) + "\n"
    results.mkdir(parents=True, exist_ok=True)
    (results / "maneuver_extraction.txt").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
