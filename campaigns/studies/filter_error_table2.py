"""Study: Table 2 under the filter-error method, measurement - model against the truth, over seeds.

Table 2 from the data alone (``estimator.accuracy.three_sigma``) is::

    T_model = 3 sqrt(max(mean(e^2) - mean(s_w^2), 0) + mean(s_cal^2))

the residual against the model plus the wind the other sensors give, the left-out wind's variance
taken out, and the calibration's *expected* error variance ``s_cal^2`` (its honest covariance
propagated to the channel) added: the residual cannot see the calibration's own error. Table 2
against the truth holds the one error this flight's calibration *happened* to have. Each is split
here into its two parts, with the calibrated channel rerun at the true parameters:

- the sensor's part: ``sqrt(T_model^2/9 - mean(s_cal^2))`` against the truth's error with the true
  calibration (noise and model structure), 3 sigma;
- the calibration's part: ``3 sqrt(mean(s_cal^2))``, expected, against ``3 rms(x(theta_hat) -
  x(theta_true))``, the realized one (``x`` the calibrated channel).

One flight gives one draw of the realized part; over seeds, its root mean square is what the
expected part must match if the deviations are honest. The demo's light-turbulence block
(``campaigns/demo_turbulence.toml``) flown with seeds ``SEED0, SEED0 + 1, ...`` (each seed draws
the turbulence and every injected error anew) and calibrated as ``fpr demo`` does (``fpr calibrate
DATASET --method filter_error --model tejas_ins``).

Run: ``python -m campaigns.studies.filter_error_table2 --out /tmp/fe_t2 --seeds 24 --results
campaigns/studies/results`` (65-90 s per seed on two cores; resumable: a seed already done in
``--out`` is read back).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd

#: the demo's light-turbulence block's seed (campaigns/demo_turbulence.toml)
SEED0 = 14001
RAD2DEG = 180.0 / math.pi


def fly(out: Path, seed: int) -> Path:
    """The demo's light-turbulence block flown with ``seed`` into ``out/seed_<seed>`` (once)."""
    from synth.campaign import fly_campaign, load_campaign
    from synth.dataset import read_manifest_if_dataset

    path = out / f"seed_{seed}"
    if not (read_manifest_if_dataset(path) or {}).get("complete", False):
        campaign = dataclasses.replace(load_campaign("demo_turbulence"), seed=seed)
        res = fly_campaign(campaign, path, workers=2, overwrite=path.exists())
        if not res.ok:
            raise RuntimeError(f"seed {seed}: the flight failed: {res.manifest.get('failures')}")
    return path


def cells(path: Path, seed: int) -> pd.DataFrame:
    """Per Table 2 cell (sensor, Mach bin, gear): Table 2 from the data and against the truth, each
    split into the sensor's and the calibration's part (module docstring), deg; whether Table 2
    judges it, and its largest share of calibration variance along a parameter on or near its
    bound."""
    from campaigns.workflow_truth import true_accuracy
    from estimator.calibration import calibrate
    from estimator.io import problem_from_dataset

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        problem = problem_from_dataset(path, model="tejas_ins")
    calib = calibrate(problem, {"method": "filter_error"})
    wf = calib.workflow
    said = sorted({f"{f.severity.name} {f.code}" for f in calib.findings if f.severity.name != "NOTE"})
    (path.parent / f"findings_{seed}.txt").write_text(
        f"{calib.verdict.name}\n" + "\n".join(f"{f.severity.name}: {f.message}" for f in calib.findings
                                             if f.severity.name != "NOTE") + "\n")
    model, rows = wf.accuracy, []
    if model.empty:  # no Table 2: the verdict says why
        return pd.DataFrame([{"seed": seed, "cell": "(none)", "verdict": calib.verdict.name,
                              "said": "; ".join(said)}])
    truth, _ = true_accuracy(wf)
    for st in (*wf.final, *wf.gear_down):
        gear = "down" if st.gear_down else "up"
        mine = model[(model.mach == st.mach) & (model.gear == gear)]
        if len(mine):
            rows += [{"seed": seed, **r, "verdict": calib.verdict.name, "said": "; ".join(said)}
                     for r in _stage_cells(wf, st, mine, truth)]
    return pd.DataFrame(rows)


def _stage_cells(wf, st, mine: pd.DataFrame, truth: pd.DataFrame) -> list[dict]:
    """The cells of one stage (``mine``: its rows of Table 2 from the data; ``truth``: Table 2
    against the truth), each split into its parts (module docstring), deg."""
    from campaigns.truth import true_parameters
    from campaigns.workflow_truth import calibrated_errors
    from estimator.workflow import bound_shares

    limit = wf.alpha_limit_deg
    tv = true_parameters(st.problem, st.result.free_estimated).values
    at_truth = np.array([tv.get(k, v) if math.isfinite(tv.get(k, math.nan)) else v
                         for k, v in zip(st.result.parameters.keys, st.result.values, strict=True)])
    hat = calibrated_errors(st.problem, st.result)
    # calibrated_errors reads the result's values only
    true = calibrated_errors(st.problem, SimpleNamespace(values=at_truth))
    out = []
    for _, r in mine.iterrows():
        name = r.channel
        tr = truth[(truth.channel == name) & (truth.mach == st.mach) & (truth.gear == r.gear)]
        if name not in hat or not len(tr):
            continue
        low = wf.declarations.requirements[name].low_alpha_only and limit is not None
        h, t, res = hat[name], true[name], st.residuals[name]
        keep = h["alpha_t_rad"].to_numpy() * RAD2DEG < limit if low else np.ones(len(h), dtype=bool)
        e_hat = h["error_rad"].to_numpy()[keep] * RAD2DEG
        e_true = t["error_rad"].to_numpy()[keep] * RAD2DEG
        # Table 2's own samples (the residual's layout) for the share along a bound parameter
        keep_r = res.alpha_t_rad * RAD2DEG < limit if low else None
        cal_var = np.square(res.calibration_sd * RAD2DEG)
        shares = bound_shares(res, keep_r, cal_var if keep_r is None else cal_var[keep_r])
        cal = float(r.calibration_sd_deg)
        out.append({"cell": f"{r.sensor}, M{st.mach:.2f}{' down' if st.gear_down else ''}",
                    "model_deg": float(r.three_sigma_deg), "truth_deg": float(tr.three_sigma_deg.iloc[0]),
                    "model_sensor_deg": 3 * math.sqrt(max((r.three_sigma_deg / 3) ** 2 - cal ** 2, 0.0)),
                    "truth_sensor_deg": 3 * float(np.sqrt(np.mean(e_true ** 2))),
                    "cal_expected_deg": 3 * cal,
                    "cal_realized_deg": 3 * float(np.sqrt(np.mean((e_hat - e_true) ** 2))),
                    "judged": bool(r.judged),
                    "bound_share": max(shares.values(), default=0.0),
                    "bound_parameter": max(shares, key=shares.get) if shares else ""})
    return out


def agreement(df: pd.DataFrame) -> pd.Series:
    """Is a Table 2 cell from the data within 30 % or 0.05 deg of the truth's?"""
    return ((df.model_deg - df.truth_deg).abs() <= np.maximum(0.3 * df.truth_deg, 0.05))


def summary(all_cells: pd.DataFrame) -> pd.DataFrame:
    """Per cell, over seeds: the root mean square of each column (the expectation of a 3-sigma
    figure's square is what a 3-sigma figure predicts), the cells within 30 % or 0.05 deg, and the
    calibration's realized / expected error over the seeds where Table 2 judges the cell."""
    cols = ["model_deg", "truth_deg", "model_sensor_deg", "truth_sensor_deg", "cal_expected_deg",
            "cal_realized_deg"]
    g = all_cells.assign(agree=agreement(all_cells)).groupby("cell", sort=False)
    out = g[cols].apply(lambda x: np.sqrt((x ** 2).mean()))
    out["model/truth"] = out.model_deg / out.truth_deg
    out["cal realized/expected"] = out.cal_realized_deg / out.cal_expected_deg
    # the same over the cells Table 2 judges (a cell along a bound parameter is not: its deviation
    # is truncated, and it is not passed)
    judged = all_cells[all_cells.judged.astype(bool)].groupby("cell", sort=False)
    out["judged"] = judged.size().reindex(out.index).fillna(0).astype(int)
    out["judged realized/expected"] = judged.apply(
        lambda x: math.sqrt((x.cal_realized_deg ** 2).mean() / (x.cal_expected_deg ** 2).mean()))
    out["cells_agreeing"] = g.agree.sum().astype(int).astype(str) + " of " + g.agree.size().astype(str)
    return out


def _worst(cells: pd.DataFrame) -> str:
    """The largest truth / model of ``cells`` and its sensor ("" without cells)."""
    if not len(cells):
        return ""
    w = cells.iloc[int(np.argmax(cells.truth_deg / cells.model_deg))]
    return f"{w.truth_deg / w.model_deg:.2f} ({w.cell})"


def per_seed(all_cells: pd.DataFrame) -> pd.DataFrame:
    """Per seed: verdict, the kinds of its warnings and failures, the cells agreeing, the worst
    optimism (truth / model) and where, over every cell and over the cells Table 2 judges, and the
    cells it does not judge (a parameter on its bound truncates their deviation)."""
    rows = []
    for seed, g in all_cells.groupby("seed"):
        ok = g[g.cell != "(none)"]
        judged = ok[ok.judged.astype(bool)] if "judged" in ok else ok
        rows.append({"seed": seed, "verdict": g.verdict.iloc[0],
                     "cells_within": f"{int(agreement(ok).sum())} of {len(ok)}" if len(ok) else "no Table 2",
                     "worst_truth/model": _worst(ok), "worst_judged": _worst(judged),
                     "not_judged": ", ".join(ok.cell[~ok.cell.isin(judged.cell)]),
                     "said": g.said.iloc[0] if isinstance(g.said.iloc[0], str) else ""})
    return pd.DataFrame(rows).set_index("seed")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="where the flights and per-seed tables go")
    ap.add_argument("--seeds", type=int, default=24, help="how many seeds from the demo's")
    ap.add_argument("--results", type=Path, help="write filter_error_table2.txt there")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    frames = []
    for seed in range(SEED0, SEED0 + args.seeds):
        f = args.out / f"cells_{seed}.csv"
        if not f.exists():
            cells(fly(args.out, seed), seed).to_csv(f, index=False)
        frames.append(pd.read_csv(f))
        print(f"seed {seed} done ({time.perf_counter() - t0:.0f} s)", flush=True)
    allc = pd.concat(frames, ignore_index=True)
    ok = allc[allc.cell != "(none)"]
    pd.set_option("display.width", 200)
    text = "\n".join([
        f"# python -m campaigns.studies.filter_error_table2 --out {args.out} --seeds {args.seeds}"
        + (f" --results {args.results}" if args.results else ""),
        "",
        f"The demo's light-turbulence block (seed {SEED0}), measurement - model against the truth, per cell "
        "(deg, 3 sigma; within: 30 % or 0.05 deg):",
        allc[allc.seed == SEED0].assign(within=agreement(allc[allc.seed == SEED0]))
        .drop(columns=["seed", "verdict", "said"]).set_index("cell").round(3).to_string(),
        "",
        f"Over {args.seeds} seeds ({SEED0}-{SEED0 + args.seeds - 1}; {ok.seed.nunique()} converged), root "
        "mean square per cell:",
        summary(ok).round(3).to_string(),
        "",
        "Truth / model per cell and seed (above 1: the data call the cell better than it is):",
        ok.assign(r=ok.truth_deg / ok.model_deg).pivot(index="cell", columns="seed", values="r")
        .round(2).to_string(),
        "",
        "The largest share of each cell's calibration variance along a parameter on or near its bound "
        "(Table 2 does not judge a cell at 0.25 or more; 0: no such parameter):",
        ok.pivot(index="cell", columns="seed", values="bound_share").round(3).to_string(),
        "",
        "Per seed: the verdict, what it warned of, the cells within 30 % or 0.05 deg of the truth's, the "
        "largest truth / model (a cell the data call better than it is), among every cell and among the "
        "cells Table 2 judges, and the cells it does not judge:",
        per_seed(allc).to_string(),
        "",
    ])
    print(text)
    if args.results:
        (args.results / "filter_error_table2.txt").write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
