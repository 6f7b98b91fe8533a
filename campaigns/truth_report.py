"""The truth sections of a synthetic dataset's calibration report: the hook ``fpr calibrate`` plugs in.

:func:`truth_sections` is a truth hook of :meth:`estimator.calibration.Calibration.write`: for a
workflow run on a dataset written by ``fpr fly`` it adds Table 2 against the truth (after Table 2
against the model), the installation biases against the injected ones (to the apportionment
section), the calibrated-minus-true cross-plots and the recovery of every estimate
(:mod:`campaigns.workflow_truth`). For other data it adds nothing (returns None).
"""

from __future__ import annotations

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

    tacc, samples = true_accuracy(wf)
    inst = installation_recovery(wf)
    rec = recovery(wf)
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
    return TruthSections(after_table2=after, apportionment_tables=inst_tables, apportionment_csv=inst_csv,
                         crossplots=crossplots, final=final,
                         tables={"true_accuracy": tacc, "installation_recovery": inst, "recovery": rec})
