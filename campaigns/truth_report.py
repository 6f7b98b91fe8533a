"""The truth sections of a synthetic dataset's calibration report: the hook ``fpr calibrate`` plugs in.

:func:`truth_sections` is a truth hook of :meth:`estimator.calibration.Calibration.write`: for a
workflow run on a dataset written by ``fpr fly`` it adds Table 2 against the truth (after Table 2
against the model), the installation biases against the injected ones (to the apportionment
section), the calibrated-minus-true cross-plots and the recovery of every estimate
(:mod:`campaigns.workflow_truth`). For other data it adds nothing (returns None).
"""

from __future__ import annotations

import numpy as np

from estimator.calibration import TruthSections
from estimator.report import Section, accuracy_table_html, figure_crossplot
from estimator.workflow import RAD2DEG, WorkflowResult


def has_truth(wf: WorkflowResult) -> bool:
    """Every final estimation's maneuvers come from a synthetic dataset (which holds the truth)."""
    return all("dataset" in m.meta for st in wf.final for m in st.problem.maneuvers)


def truth_sections(wf: WorkflowResult) -> TruthSections | None:
    """The report's truth sections for ``wf``, or None when its data are not a synthetic dataset."""
    if not has_truth(wf):
        return None
    from campaigns.workflow_truth import installation_recovery, recovery, true_accuracy

    truth_cache: dict = {}  # each maneuver's truth read once for the three tables
    tacc, samples = true_accuracy(wf, truth_cache)
    inst = installation_recovery(wf, truth_cache)
    rec = recovery(wf, truth_cache)
    truth_cache.clear()
    after = (Section(
        "Table 2 against the truth: calibrated channel minus true flow angle at the sensor",
        "What the paper could not measure: each measurement run back through its estimated "
        "calibration model, minus the true flow angle at the sensor (at the time the sensor saw it).",
        tables=[("", accuracy_table_html(tacc, "3-sigma of calibrated - true (deg)"))],
        csv=[("table2_truth.csv", tacc)]),)
    inst_tables, inst_csv = (), ()
    if inst is not None and len(inst):
        inst_tables = (("Installation biases against the truth", inst),)
        inst_csv = (("installation_recovery.csv", inst),)
    reqs = wf.declarations.requirements

    def crossplots(ref) -> list:
        figs = []
        s = samples.get((ref.mach, "up"), {}) if samples else {}
        for name in wf.declarations.truth_crossplots:
            if name in s:
                d = s[name]
                figs.append((f"{name}: calibrated - true vs true angle at Mach {ref.mach:.2f} (truth)",
                             figure_crossplot(d["true_rad"].to_numpy() * RAD2DEG,
                                              d["error_rad"].to_numpy() * RAD2DEG,
                                              f"{name} against the truth", "true angle (deg)",
                                              "calibrated - true (deg)",
                                              limit_deg=reqs[name].desired_deg if name in reqs else None)))
        return figs

    final = ()
    if rec is not None and len(rec):
        summ = rec.assign(within3_crb=rec["z_crb"].abs() < 3, within3_colored=rec["z_colored"].abs() < 3
                          ).groupby("kind")[["within3_crb", "within3_colored"]].mean()
        final = (Section("Recovery: estimates against their injected truth",
                         "Fraction within 3 Cramér-Rao / coloured-residual standard deviations "
                         "per kind; every estimate in recovery.csv.",
                         tables=[("Within 3 sigma", summ.reset_index()), ("All", rec.reset_index())],
                         csv=[("recovery.csv", rec.reset_index())]),)
    final = final + _wind_sections(wf)
    return TruthSections(after_table2=after, apportionment_tables=inst_tables, apportionment_csv=inst_csv,
                         crossplots=crossplots, final=final,
                         tables={"true_accuracy": tacc, "installation_recovery": inst, "recovery": rec})


#: Maneuvers whose wind history the report draws, per estimation.
WIND_FIGURES = 3


def _wind_sections(wf: WorkflowResult) -> tuple[Section, ...]:
    """The filter-error wind against the truth (nothing for output-error results)."""
    import pandas as pd

    from campaigns.workflow_truth import wind_errors
    from estimator.report import figure_wind_history

    tables, figures = [], []
    for st in (*wf.final, *wf.gear_down):
        if st.problem is None or st.result.wind_history is None:
            continue
        table, series = wind_errors(st.problem, st.result)
        if not len(table):
            continue
        tables.append(table.assign(mach=st.mach, gear="down" if st.gear_down else "up", stage=st.name))
        for mid in list(series)[:WIND_FIGURES]:
            s = series[mid]
            figures.append((f"{mid} (Mach {st.mach:.2f}, {st.name}): estimated wind against the truth, "
                            "means removed", figure_wind_history(mid, s["t_s"], s["estimated"], s["std"],
                                                                 s["truth"])))
    if not tables:
        return ()
    allt = pd.concat(tables, ignore_index=True)
    pooled = allt.groupby("axis")[["rms_error_mps", "true_std_mps", "est_std_mps"]].apply(
        lambda g: np.sqrt((g ** 2).mean())).reindex(["north", "east", "down"])
    with np.errstate(invalid="ignore", divide="ignore"):
        over = (pooled["rms_error_mps"] / pooled["est_std_mps"]).replace([np.inf, -np.inf], np.nan)
    # calm maneuvers (no wind states: estimate and deviation zero) leave nothing to compare
    ratio_text = ""
    if over.notna().any():
        worst = over.idxmax()
        ratio_text = (" The smoother's deviation is conditional on the estimated parameters and the "
                      f"wind model; here the rms error is {over[worst]:.1f} times it at most ({worst})"
                      + (": read the wind history's deviations as lower bounds." if over[worst] > 2.0
                         else "."))
    return (Section(
        "Wind: the filter-error method's turbulence against the truth",
        "Each maneuver's smoothed turbulent wind against JSBSim's, both with the maneuver's mean "
        "removed (the free initial velocities absorb the mean wind). rms per axis over every "
        "maneuver (pooled), beside the true wind's own rms and the smoother's deviation." + ratio_text,
        tables=[("Pooled over the maneuvers, m/s", pooled.reset_index()), ("Per maneuver", allt)],
        figures=figures, csv=[("wind_recovery.csv", allt)]),)
