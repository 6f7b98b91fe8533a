"""The calibration report of a workflow run: Table 2 (model and truth), Figs. 3-8, CSV tables.

Joins the estimator's workflow (:mod:`estimator.workflow`), its renderer (:mod:`estimator.report`)
and, for synthetic datasets, the truth (:mod:`campaigns.workflow_truth`). What it shows of the
aircraft (Table 2's rows, the channels of the figures, the apportioned bias families) is what the
model set declares (``[requirements]``, ``[report]``, ``[workflow]``: the workflow's
``declarations``); no channel name is written here.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd

from estimator.report import (
    Banner,
    Section,
    accuracy_table_html,
    figure_bias_vs_mach,
    figure_crossplot,
    figure_table_updates,
    figure_time_history,
    write_report,
)
from estimator.verdict import Verdict, reasons
from estimator.workflow import RAD2DEG, WorkflowResult

_LEVEL = {Verdict.SUCCESS: "success", Verdict.SUCCESS_WITH_WARNINGS: "warning", Verdict.FAILURE: "failure"}
#: Fig. 3 shows a maneuver of these kinds if the reference bin has one (the paper's pitch doublet).
TIME_HISTORY_KINDS = ("pitch_doublet", "3211")


def _mean_bias_label(families) -> tuple[str, str]:
    """The apportioned biases' mean as plain text and as matplotlib math: "(b_l + b_r)/2"."""
    names = list(families)
    if len(names) == 1:
        text = names[0]
    else:
        text = f"({' + '.join(names)})/{len(names)}"
    math = re.sub(r"_(\w+)", r"_{\1}", text)
    return text, f"${math}$"


def verdict_banner(wf: WorkflowResult) -> Banner:
    """The workflow's verdict and its failures and warnings (most severe first), for the report's top."""
    v = wf.verdict
    return Banner(_LEVEL[v], f"{v.name.replace('_', ' ')}: {v.text}",
                  tuple(f.text() for f in reasons(wf.findings)))


def _held_parameters(wf: WorkflowResult) -> pd.DataFrame:
    """Parameters a stage held or left on a bound, with the reason."""
    frames = []
    for st in wf.stages:
        df = st.result.to_pandas()
        df = df[df["state"].isin(["held", "on_bound"])]
        if len(df):
            frames.append(df[["kind", "state", "value_display", "display_unit", "reason"]].assign(
                stage=st.name, mach=st.mach, gear="down" if st.gear_down else "up"))
    return pd.concat(frames).reset_index() if frames else pd.DataFrame()


def _fit_quality(wf: WorkflowResult) -> pd.DataFrame:
    """The fit-quality diagnostics of every stage (one row per stage, maneuver and channel)."""
    frames = [st.result.diagnostics.assign(stage=st.name, mach=st.mach,
                                           gear="down" if st.gear_down else "up")
              for st in wf.stages if st.result.diagnostics is not None and len(st.result.diagnostics)]
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def _figure_stage(final, reference_mach: float | None):
    """The estimation the single-bin figures show: the bin nearest the reference Mach (the lower of
    two as near), or without one the middle bin."""
    if reference_mach is None:
        return sorted(final, key=lambda s: s.mach)[(len(final) - 1) // 2]
    return min(final, key=lambda s: (abs(s.mach - reference_mach), s.mach))


def _has_truth(wf: WorkflowResult) -> bool:
    return all("dataset" in m.meta for st in wf.final for m in st.problem.maneuvers)


def build_report(wf: WorkflowResult, out_dir: Path, title: str, truth: bool | None = None,
                 record: Callable[[Path], object] | None = None) -> dict:
    """Write ``out_dir/report.html`` and its CSV files; return the tables it printed from.

    ``record`` is called with each file's path before it is written (e.g.
    :meth:`estimator.io.outdir.OutputFolder.record`, so the output folder lists what it holds).

    Returns
    -------
    dict with ``accuracy`` (Table 2, model), ``true_accuracy`` and ``installation_recovery`` and
    ``recovery`` (None without truth), ``report`` (the HTML path).
    """
    truth = _has_truth(wf) if truth is None else truth
    out_dir.mkdir(parents=True, exist_ok=True)
    sections = []
    used = wf.maneuvers[wf.maneuvers["used"]]
    counts = used.groupby(["bin", "gear_down"]).size()
    per_bin = ", ".join(f"M{b:.2f} gear {'down' if g else 'up'}: {n}" for (b, g), n in counts.items())
    summary = (
        f"{len(wf.maneuvers)} maneuvers from {wf.maneuvers['aircraft'].nunique()} aircraft; "
        f"{len(used)} used in {len(counts)} Mach bins ({per_bin}). "
        f"Workflow wall time {wf.elapsed_s:.0f} s. Verdict: {wf.verdict.name.replace('_', ' ').lower()} "
        f"({wf.verdict.text}).\n"
        + "\n".join(wf.notes)
    )
    stages = pd.DataFrame([{"step": s.name, "mach": s.mach, "gear": "down" if s.gear_down else "up",
                            "maneuvers": len(s.problem.maneuvers),
                            "free_parameters": int(s.problem.parameters.free_mask.sum()),
                            "iterations": s.result.iterations,
                            "verdict": s.result.verdict.name.replace("_", " ").lower(),
                            "failures": len(s.result.failures), "warnings": len(s.result.warnings),
                            "solver": s.result.message}
                           for s in wf.stages])
    findings = wf.findings_table()
    held = _held_parameters(wf)
    quality = _fit_quality(wf)
    tables = [("Estimations", stages), ("Failures and warnings", findings)]
    csvs = [("maneuvers.csv", wf.maneuvers), ("findings.csv", findings)]
    if len(held):
        tables.append(("Parameters held (not estimated) or on a bound, and why", held))
        csvs.append(("held_parameters.csv", held))
    if len(quality):
        csvs.append(("fit_quality.csv", quality))
    sections.append(Section("Summary and verdict", summary, tables=tables, csv=csvs))
    final = [st for st in wf.final if st.result.success]  # what Table 2 and the figures rest on
    if not final:
        out = {"accuracy": wf.accuracy, "true_accuracy": None, "installation_recovery": None,
               "recovery": None}
        out["report"] = write_report(out_dir, title, sections, banner=verdict_banner(wf), record=record)
        return out
    sections.append(Section(
        "Table 2: 3-sigma of measurement minus model",
        "Per sensor and Mach bin at the final estimate (installation biases fixed), 3 x rms about zero, "
        "against the desired accuracy (paper Table 2)"
        + "".join(f"; {r.sensor} below the usable angle of attack"
                  for r in wf.declarations.requirements.values() if r.low_alpha_only) + ".",
        tables=[("", accuracy_table_html(wf.accuracy, "3-sigma of measurement - model (deg)"))],
        csv=[("table2_model.csv", wf.accuracy)]))
    out: dict = {"accuracy": wf.accuracy, "true_accuracy": None, "installation_recovery": None,
                 "recovery": None}
    samples = {}
    if truth:
        from campaigns.workflow_truth import installation_recovery, recovery, true_accuracy

        tacc, samples = true_accuracy(wf)
        inst = installation_recovery(wf)
        rec = recovery(wf)
        out.update(true_accuracy=tacc, installation_recovery=inst, recovery=rec)
        sections.append(Section(
            "Table 2 against the truth: calibrated channel minus true flow angle at the sensor",
            "What the paper could not measure: each measurement run back through its estimated "
            "calibration model, minus the true flow angle at the sensor (at the time the sensor saw it).",
            tables=[("", accuracy_table_html(tacc, "3-sigma of calibrated - true (deg)"))],
            csv=[("table2_truth.csv", tacc)]))
    # Fig. 4 and the apportionment
    fig4 = []
    decl = wf.declarations
    bias_text, bias_math = _mean_bias_label(decl.apportion.values())
    if not wf.vane_bias.empty:
        vb = wf.vane_bias.copy()
        fig4.append((f"Fig. 4: average vane bias {bias_text} vs Mach per aircraft, fleet mean",
                     figure_bias_vs_mach(vb, reference_mach=float(wf.installation["mach"].iloc[0])
                                         if not wf.installation.empty else None, bias_label=bias_math)))
    tabs = [("Installation biases (deg), held for every Mach", wf.installation.reset_index())]
    csvs = [("vane_biases.csv", wf.vane_bias), ("installation_biases.csv", wf.installation.reset_index())]
    if truth and out["installation_recovery"] is not None and len(out["installation_recovery"]):
        tabs.append(("Installation biases against the truth", out["installation_recovery"]))
        csvs.append(("installation_recovery.csv", out["installation_recovery"]))
    sections.append(Section("Vane bias apportionment (paper §4.1)",
                            f"Per Mach bin the fleet mean of {bias_text} is the correction model's update; "
                            "each aircraft's deviation from it is its mean installation bias.",
                            tables=tabs, figures=fig4, csv=csvs))
    # Figs. 6 and 8: table updates, and the tables for the flight-control team
    upd = wf.table_updates()
    figs, csvs = [], []
    if not upd.empty:
        ident = (f" ({wf.identity_table} as {wf.identity_table}(x) - x)"
                 if wf.identity_table in set(upd["table"]) else "")
        figs.append((f"Figs. 6 and 8: correction-table updates vs breakpoint per Mach{ident}, gear down "
                     "dashed", figure_table_updates(upd)))
        csvs.append(("table_updates.csv", upd))
    for name, (values, states) in wf.correction_tables().items():
        csvs.append((f"correction_table_{name}.csv", values.reset_index()))
        csvs.append((f"correction_table_{name}_state.csv", states.reset_index()))
    sections.append(Section("Correction tables", "The updated tables, breakpoints x Mach, in "
                             "correction_table_<name>.csv (display units: deg for angle tables), from "
                             "the estimations whose verdict is a success only. A value the data did not "
                             "determine (held at its start value) or that sits on its bound is left empty; "
                             "correction_table_<name>_state.csv says which, cell by cell, and "
                             "table_updates.csv why, with the honest deviations (std) and the Cramér-Rao "
                             "ones (std_crb).",
                             figures=figs, csv=csvs))
    # Figs. 5 and 7: error cross-plots; Fig. 3: a time-history match, at the reference Mach
    ref = _figure_stage(final, wf.reference_mach)
    res = ref.residuals
    reqs = decl.requirements

    def limit(name: str) -> float | None:
        return reqs[name].desired_deg if name in reqs else None

    figs = []
    for name in decl.crossplots:
        if name in res:
            r = res[name]
            figs.append((f"Fig. 5: {name} measurement - model vs model at Mach {ref.mach:.2f}",
                         figure_crossplot(r.y * RAD2DEG, r.e * RAD2DEG, f"{name}, Mach {ref.mach:.2f}",
                                          "model (deg)", "measurement - model (deg)", limit_deg=limit(name))))
    lim_ch = decl.alpha_limit_channel
    pooled = [s.residuals[lim_ch] for s in final if lim_ch in s.residuals]
    if pooled:
        a = np.concatenate([p.alpha_t_rad for p in pooled]) * RAD2DEG
        e = np.concatenate([p.e for p in pooled]) * RAD2DEG
        figs.append((f"Fig. 7: {reqs[lim_ch].sensor} ({lim_ch}) error vs angle of attack, all Mach bins; "
                     f"its usable range ends at alpha = {wf.alpha_limit_deg} deg",
                     figure_crossplot(a, e, reqs[lim_ch].sensor, "alpha (deg)", "measurement - model (deg)",
                                      limit_deg=limit(lim_ch), x_limit_deg=wf.alpha_limit_deg)))
    if samples:
        s = samples.get((ref.mach, "up"), {})
        for name in decl.truth_crossplots:
            if name in s:
                d = s[name]
                figs.append((f"{name}: calibrated - true vs true angle at Mach {ref.mach:.2f} (truth)",
                             figure_crossplot(d["true_rad"].to_numpy() * RAD2DEG,
                                              d["error_rad"].to_numpy() * RAD2DEG,
                                              f"{name} against the truth", "true angle (deg)",
                                              "calibrated - true (deg)", limit_deg=limit(name))))
    growth = ([(f"{reqs[lim_ch].sensor} ({lim_ch}): error growth with alpha", wf.alpha_limit_growth)]
              if lim_ch else [])
    sections.append(Section("Error cross-plots", "", figures=figs, tables=growth))
    mid = next((m.id for m in ref.problem.maneuvers if m.meta.get("kind") in TIME_HISTORY_KINDS),
               ref.problem.maneuvers[0].id)
    units = {c.name: (c.display_scale, c.display_unit) for c in ref.problem.channels}
    # channels fitted at different samples (a time-shifted channel loses its edges, an own-rate one
    # has its own) go onto the maneuver's time base, NaN where a channel has no sample
    t_all = next(m.t_s for m in ref.problem.maneuvers if m.id == mid)
    at = {}
    for name in decl.time_history:
        r = res.get(name)
        if r is not None and (r.maneuver == mid).any():
            at[name] = (r, r.maneuver == mid, np.searchsorted(t_all, r.t_s[r.maneuver == mid]))
    chans = {}
    if at:
        lo = min(int(i[0]) for _, _, i in at.values())
        hi = max(int(i[-1]) for _, _, i in at.values()) + 1
        t = t_all[lo:hi]
        for name, (r, sel, idx) in at.items():
            scale, unit = units[name]
            z, y = np.full(t.shape, np.nan), np.full(t.shape, np.nan)
            z[idx - lo], y[idx - lo] = r.z[sel] * scale, r.y[sel] * scale
            chans[name] = (z, y, unit)
    if chans:
        sections.append(Section("Time-history match (paper Fig. 3)", f"Maneuver {mid}, Mach {ref.mach:.2f}",
                                figures=[(f"Fig. 3: {mid}", figure_time_history(mid, t, chans))]))
    if truth and out["recovery"] is not None and len(out["recovery"]):
        rec = out["recovery"]
        summ = rec.assign(within3_crb=rec["z_crb"].abs() < 3, within3_colored=rec["z_colored"].abs() < 3
                          ).groupby("kind")[["within3_crb", "within3_colored"]].mean()
        sections.append(Section("Recovery: estimates against their injected truth",
                                "Fraction within 3 Cramér-Rao / coloured-residual standard deviations "
                                "per kind; every estimate in recovery.csv.",
                                tables=[("Within 3 sigma", summ.reset_index()), ("All", rec.reset_index())],
                                csv=[("recovery.csv", rec.reset_index())]))
    out["report"] = write_report(out_dir, title, sections, banner=verdict_banner(wf), record=record)
    return out
