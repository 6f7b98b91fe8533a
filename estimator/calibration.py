"""``calibrate(problem, options) -> Calibration``: the Mach-bin workflow and its report, as ``fpr calibrate``.

What a notebook does::

    from estimator import load_problem, calibrate

    cal = calibrate(load_problem("my_flight.toml"))
    cal.verdict                     # SUCCESS, SUCCESS_WITH_WARNINGS or FAILURE
    cal.to_pandas("table2")         # Table 2: 3 sigma of measurement - model per sensor and Mach
    cal.write("results/flight421")  # report.html and its CSV tables, as fpr calibrate writes them

The report written here is truth-free: it shows what the flight data say (Table 2 against the model,
the correction tables, the vane and installation biases, Figs. 3-8). A synthetic dataset's truth
sections (Table 2 against the truth, installation recovery, recovery.csv) are not the estimator's:
they plug in through ``write(..., truth=hook)`` (``campaigns.truth_report.truth_sections``), a
callable ``hook(workflow_result) -> TruthSections | None``.
"""

from __future__ import annotations

import dataclasses
import os
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from aircraft_models.schema import did_you_mean
from estimator.finding_groups import NOTE_CHARS, groups_frame
from estimator.options import CalibrationOptions
from estimator.options import option_tables as option_tables  # re-exported from its old home
from estimator.problem import Problem, ReadOnlyMapping
from estimator.report import (
    Banner,
    Section,
    accuracy_table_html,
    figure_bias_vs_mach,
    figure_crossplot,
    figure_table_updates,
    figure_time_history,
    time_history_maneuver,
    write_report,
)
from estimator.result import ReadOnlyTable
from estimator.verdict import Finding, Severity, Verdict
from estimator.workflow import RAD2DEG, Stage, WorkflowResult, run_workflow

# --------------------------------------------------------------------------------------------------
# the truth hook's answer


@dataclass(frozen=True)
class TruthSections:
    """What a truth hook adds to the report (``campaigns.truth_report`` makes it for synthetic data).

    Attributes
    ----------
    after_table2 : sections placed right after Table 2 (against the model).
    apportionment_tables, apportionment_csv : (title, frame) and (CSV name, frame) added to the vane
        bias apportionment section.
    crossplots : called with the stage the cross-plots show; returns more (caption, figure) pairs.
    final : sections placed at the end of the report.
    tables : the hook's tables by name, returned by :meth:`Calibration.write` (for printing).
    """

    after_table2: tuple[Section, ...] = ()
    apportionment_tables: tuple[tuple[str, pd.DataFrame], ...] = ()
    apportionment_csv: tuple[tuple[str, pd.DataFrame], ...] = ()
    crossplots: Callable[[Stage], list] | None = None
    final: tuple[Section, ...] = ()
    tables: Mapping[str, pd.DataFrame | None] = field(default_factory=dict)


TruthHook = Callable[[WorkflowResult], "TruthSections | None"]

# --------------------------------------------------------------------------------------------------
# the truth-free report

_LEVEL = {Verdict.SUCCESS: "success", Verdict.SUCCESS_WITH_WARNINGS: "warning", Verdict.FAILURE: "failure"}


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
    groups = wf.finding_groups()
    acting = [g.text() for g in groups if g.severity >= Severity.WARNING]
    notes = [g.text(note_chars=NOTE_CHARS) for g in groups if g.severity < Severity.WARNING]
    room = max(BANNER_LINES - len(acting), 0)
    shown = notes if len(notes) <= room else notes[:max(room - 1, 0)]
    more = len(notes) - len(shown)
    tail = (f"... {more} more note(s): the findings below Table 2, every one in findings.csv",) if more \
        else ()
    return Banner(_LEVEL[v], f"{v.name.replace('_', ' ')}: {v.text}", (*acting, *shown, *tail))


#: Lines of findings the report's banner shows (every failure and warning, then notes to fill it).
BANNER_LINES = 10


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


def _stages_table(wf: WorkflowResult) -> pd.DataFrame:
    return pd.DataFrame([{"step": s.name, "mach": s.mach, "gear": "down" if s.gear_down else "up",
                          "maneuvers": len(s.problem.maneuvers),
                          "free_parameters": int(s.problem.parameters.free_mask.sum()),
                          "iterations": s.result.iterations,
                          "verdict": s.result.verdict.name.replace("_", " ").lower(),
                          "failures": len(s.result.failures), "warnings": len(s.result.warnings),
                          "solver": s.result.message}
                         for s in wf.stages])


def _figure_stage(final, reference_mach: float | None):
    """The estimation the single-bin figures show: the bin nearest the reference Mach (the lower of
    two as near), or without one the middle bin."""
    if reference_mach is None:
        return sorted(final, key=lambda s: s.mach)[(len(final) - 1) // 2]
    return min(final, key=lambda s: (abs(s.mach - reference_mach), s.mach))


def workflow_tables(wf: WorkflowResult) -> dict[str, pd.DataFrame]:
    """The report's truth-free tables by CSV name (without ``.csv``), in the report's order.

    ``stages`` (the estimations, shown in the report, no CSV), ``maneuvers``, ``findings``,
    ``held_parameters`` and ``fit_quality`` (when not empty), and when a final estimation succeeded
    ``table2_model``, ``vane_biases``, ``installation_biases``, ``table_updates`` (when not empty),
    ``correction_table_<name>`` and ``correction_table_<name>_state``.
    """
    out = {"stages": _stages_table(wf), "maneuvers": wf.maneuvers, "findings": wf.findings_table(),
           "finding_groups": groups_frame(wf.finding_groups())}
    held, quality = _held_parameters(wf), _fit_quality(wf)
    if len(held):
        out["held_parameters"] = held
    if len(quality):
        out["fit_quality"] = quality
    if not any(st.result.success for st in wf.final):
        return out
    out["table2_model"] = wf.accuracy
    out["vane_biases"] = wf.vane_bias
    out["installation_biases"] = wf.installation.reset_index()
    upd = wf.table_updates()
    if not upd.empty:
        out["table_updates"] = upd
    for name, (values, states) in wf.correction_tables().items():
        out[f"correction_table_{name}"] = values.reset_index()
        out[f"correction_table_{name}_state"] = states.reset_index()
    return out


def _summary_section(wf: WorkflowResult, tab: Mapping[str, pd.DataFrame]) -> Section:
    """The findings and estimations: the maneuvers used per bin, the wall time, the verdict, the
    notes, the findings said once and the estimations."""
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
    tables = [("Findings, each said once (every finding, per maneuver, in findings.csv)",
               tab["finding_groups"]), ("Estimations", tab["stages"])]
    csvs = [("maneuvers.csv", tab["maneuvers"]), ("findings.csv", tab["findings"]),
            ("finding_groups.csv", tab["finding_groups"])]
    if "held_parameters" in tab:
        tables.append(("Parameters held (not estimated) or on a bound, and why", tab["held_parameters"]))
        csvs.append(("held_parameters.csv", tab["held_parameters"]))
    if "fit_quality" in tab:
        csvs.append(("fit_quality.csv", tab["fit_quality"]))
    return Section("Findings and estimations", summary, tables=tables, csv=csvs)


def _table2_section(wf: WorkflowResult, tab: Mapping[str, pd.DataFrame]) -> Section:
    """Table 2 against the model: 3 sigma of measurement minus model per sensor and Mach bin."""
    return Section(
        "Table 2: 3-sigma of measurement minus model",
        "Per sensor and Mach bin at the final estimate (installation biases fixed), 3 x rms about zero, "
        "with the calibration's own uncertainty added (3 sqrt(mean(e^2) + mean(s_cal^2)), s_cal its "
        "parameters' honest deviations propagated to the channel: what the residual cannot show; "
        "table2_model.csv gives both parts), against the desired accuracy (paper Table 2)"
        + "".join(f"; {r.sensor} below the usable angle of attack"
                  for r in wf.declarations.requirements.values() if r.low_alpha_only) + ".",
        tables=[("", accuracy_table_html(wf.accuracy, "3-sigma of measurement - model (deg)"))],
        csv=[("table2_model.csv", tab["table2_model"])])


def _apportionment_section(wf: WorkflowResult, tab: Mapping[str, pd.DataFrame], extra: TruthSections,
                           plots: bool) -> Section:
    """Fig. 4 and the vane-bias apportionment (paper §4.1)."""
    fig4 = []
    bias_text, bias_math = _mean_bias_label(wf.declarations.apportion.values())
    if plots and not wf.vane_bias.empty:
        vb = wf.vane_bias.copy()
        fig4.append((f"Fig. 4: average vane bias {bias_text} vs Mach per aircraft, fleet mean",
                     figure_bias_vs_mach(vb, reference_mach=float(wf.installation["mach"].iloc[0])
                                         if not wf.installation.empty else None, bias_label=bias_math)))
    tabs = [("Installation biases (deg), held for every Mach", tab["installation_biases"]),
            *extra.apportionment_tables]
    csvs = [("vane_biases.csv", tab["vane_biases"]), ("installation_biases.csv", tab["installation_biases"]),
            *extra.apportionment_csv]
    return Section("Vane bias apportionment (paper §4.1)",
                   f"Per Mach bin the fleet mean of {bias_text} is the correction model's update; "
                   "each aircraft's deviation from it is its mean installation bias.",
                   tables=tabs, figures=fig4, csv=csvs)


def _correction_section(wf: WorkflowResult, tab: Mapping[str, pd.DataFrame], plots: bool) -> Section:
    """Figs. 6 and 8 (the table updates) and the correction tables for the flight-control team."""
    figs, csvs = [], []
    if "table_updates" in tab:
        upd = tab["table_updates"]
        ident = (f" ({wf.identity_table} as {wf.identity_table}(x) - x)"
                 if wf.identity_table in set(upd["table"]) else "")
        if plots:
            figs.append((f"Figs. 6 and 8: correction-table updates vs breakpoint per Mach{ident}, gear "
                         "down dashed", figure_table_updates(upd)))
        csvs.append(("table_updates.csv", upd))
    csvs.extend((f"{name}.csv", frame) for name, frame in tab.items() if name.startswith("correction_table_"))
    return Section("Correction tables", "The updated tables, breakpoints x Mach, in "
                   "correction_table_<name>.csv (display units: deg for angle tables), from "
                   "the estimations whose verdict is a success only. A value the data did not "
                   "determine (held at its start value) or that sits on its bound is left empty; "
                   "correction_table_<name>_state.csv says which, cell by cell, and "
                   "table_updates.csv why, with the honest deviations (std) and the Cramér-Rao "
                   "ones (std_crb).",
                   figures=figs, csv=csvs)


def _alpha_limit_crossplot(wf: WorkflowResult, final: Sequence[Stage]) -> tuple[str, Any] | None:
    """Fig. 7: the alpha-limit channel's error against angle of attack over every Mach bin (None:
    no stage has its residuals)."""
    reqs, lim_ch = wf.declarations.requirements, wf.declarations.alpha_limit_channel
    pooled = [s.residuals[lim_ch] for s in final if lim_ch in s.residuals]
    if not pooled:
        return None
    a = np.concatenate([p.alpha_t_rad for p in pooled]) * RAD2DEG
    e = np.concatenate([p.e for p in pooled]) * RAD2DEG
    # no limit: the lowest judged alpha band misses the desired accuracy, or no band has
    # the samples to be judged (workflow.alpha_limit)
    judged = wf.alpha_limit_growth.get("passed", pd.Series(dtype=object)).notna().any()
    usable = (f"its usable range ends at alpha = {wf.alpha_limit_deg:g} deg"
              if wf.alpha_limit_deg is not None else
              "no usable range: its lowest judged alpha band already misses the desired "
              "accuracy" if judged else "no alpha band has enough samples to be judged")
    return (f"Fig. 7: {reqs[lim_ch].sensor} ({lim_ch}) error vs angle of attack, all Mach "
            f"bins; {usable}",
            figure_crossplot(a, e, reqs[lim_ch].sensor, "alpha (deg)",
                             "measurement - model (deg)", limit_deg=_desired_deg(reqs, lim_ch),
                             x_limit_deg=wf.alpha_limit_deg))


def _desired_deg(reqs: Mapping, name: str) -> float | None:
    """The channel's desired accuracy, deg (None: no requirement)."""
    return reqs[name].desired_deg if name in reqs else None


def _crossplot_section(wf: WorkflowResult, final: Sequence[Stage], ref: Stage, extra: TruthSections,
                       plots: bool) -> Section:
    """Figs. 5 and 7: the error cross-plots (Fig. 5 at the reference Mach ``ref``) and the alpha
    limit channel's error growth with alpha."""
    res = ref.residuals
    decl = wf.declarations
    reqs = decl.requirements
    figs = []
    lim_ch = decl.alpha_limit_channel
    if plots:
        for name in decl.crossplots:
            if name in res:
                r = res[name]
                figs.append((f"Fig. 5: {name} measurement - model vs model at Mach {ref.mach:.2f}",
                             figure_crossplot(r.y * RAD2DEG, r.e * RAD2DEG, f"{name}, Mach {ref.mach:.2f}",
                                              "model (deg)", "measurement - model (deg)",
                                              limit_deg=_desired_deg(reqs, name))))
        fig7 = _alpha_limit_crossplot(wf, final)
        if fig7 is not None:
            figs.append(fig7)
        if extra.crossplots is not None:
            figs.extend(extra.crossplots(ref))
    growth = ([(f"{reqs[lim_ch].sensor} ({lim_ch}): error growth with alpha", wf.alpha_limit_growth)]
              if lim_ch else [])
    return Section("Error cross-plots", "", figures=figs, tables=growth)


def build_report(wf: WorkflowResult, out_dir: Path, title: str, truth: TruthHook | None = None,
                 record: Callable[[Path], object] | None = None, plots: bool = True) -> dict:
    """Write ``out_dir/report.html`` and its CSV files; return the tables it printed from.

    ``truth`` adds the truth sections (:class:`TruthSections`); ``record`` is called with each
    file's path before it is written (e.g. :meth:`estimator.io.outdir.OutputFolder.record`, so the
    output folder lists what it holds); ``plots`` false draws no figure.

    Returns
    -------
    dict with ``accuracy`` (Table 2, model), ``report`` (the HTML path), and the truth hook's
    ``tables`` (``true_accuracy``, ``installation_recovery``, ``recovery``: None without truth).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    tab = workflow_tables(wf)
    # the first screen is the verdict (the banner), its findings and Table 2; the details follow
    summary_section = _summary_section(wf, tab)
    out: dict = {"accuracy": wf.accuracy, "true_accuracy": None, "installation_recovery": None,
                 "recovery": None}
    final = [st for st in wf.final if st.result.success]  # what Table 2 and the figures rest on
    if not final:
        out["report"] = write_report(out_dir, title, [summary_section], banner=verdict_banner(wf),
                                     record=record)
        return out
    sections = [_table2_section(wf, tab)]
    extra = truth(wf) if truth is not None else None
    if extra is None:
        extra = TruthSections()
    out.update(extra.tables)
    sections.extend(extra.after_table2)
    sections.append(summary_section)
    sections.append(_apportionment_section(wf, tab, extra, plots))
    sections.append(_correction_section(wf, tab, plots))
    # Figs. 5 and 7: error cross-plots; Fig. 3: a time-history match, at the reference Mach
    ref = _figure_stage(final, wf.reference_mach)
    sections.append(_crossplot_section(wf, final, ref, extra, plots))
    chans, mid, t = _time_history(ref, wf.declarations.time_history) if plots else ({}, None, None)
    if chans:
        sections.append(Section("Time-history match (paper Fig. 3)", f"Maneuver {mid}, Mach {ref.mach:.2f}",
                                figures=[(f"Fig. 3: {mid}", figure_time_history(mid, t, chans))]))
    sections.extend(extra.final)
    out["report"] = write_report(out_dir, title, sections, banner=verdict_banner(wf), record=record)
    return out


def _time_history(ref: Stage, channels: Sequence[str]):
    """Fig. 3's channels (measured, model, unit) on the shown maneuver's time base."""
    res = ref.residuals
    mid = time_history_maneuver(ref.problem.maneuvers)
    units = {c.name: (c.display_scale, c.display_unit) for c in ref.problem.channels}
    # channels fitted at different samples (a time-shifted channel loses its edges, an own-rate one
    # has its own) go onto the maneuver's time base, NaN where a channel has no sample
    t_all = next(m.t_s for m in ref.problem.maneuvers if m.id == mid)
    at = {}
    for name in channels:
        r = res.get(name)
        if r is not None and (r.maneuver == mid).any():
            at[name] = (r, r.maneuver == mid, np.searchsorted(t_all, r.t_s[r.maneuver == mid]))
    chans = {}
    t = None
    if at:
        lo = min(int(i[0]) for _, _, i in at.values())
        hi = max(int(i[-1]) for _, _, i in at.values()) + 1
        t = t_all[lo:hi]
        for name, (r, sel, idx) in at.items():
            scale, unit = units[name]
            z, y = np.full(t.shape, np.nan), np.full(t.shape, np.nan)
            z[idx - lo], y[idx - lo] = r.z[sel] * scale, r.y[sel] * scale
            chans[name] = (z, y, unit)
    return chans, mid, t


# --------------------------------------------------------------------------------------------------
# calibrate() and its result


@dataclass(frozen=True)
class Calibration:
    """The result of :func:`calibrate`: the workflow's estimations, the report's tables, the verdict.

    Immutable: the attributes cannot be set; :meth:`to_pandas` and :meth:`tables` return copies.

    Attributes
    ----------
    problem : the problem calibrated.
    options : the options used.
    workflow : the :class:`~estimator.workflow.WorkflowResult` (every estimation, the notes).
    """

    problem: Problem = field(repr=False)
    options: CalibrationOptions
    workflow: WorkflowResult = field(repr=False)
    _tables: Mapping[str, ReadOnlyTable] = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        # kept read-only (index included); every read hands out a new DataFrame
        object.__setattr__(self, "_tables", ReadOnlyMapping(
            {k: ReadOnlyTable.of(v, keep_index=True) for k, v in workflow_tables(self.workflow).items()}))

    @property
    def verdict(self) -> Verdict:
        """SUCCESS, SUCCESS_WITH_WARNINGS or FAILURE, of the whole workflow."""
        return self.workflow.verdict

    @property
    def findings(self) -> tuple[Finding, ...]:
        """The verdict's reasons (per channel, maneuver and time)."""
        return tuple(self.workflow.findings)

    @property
    def names(self) -> tuple[str, ...]:
        """The tables' names (the report's CSV names without ``.csv``; ``table2`` is ``table2_model``)."""
        return tuple(self._tables)

    def to_pandas(self, name: str) -> pd.DataFrame:
        """A copy of the report's table ``name`` (see :attr:`names`; ``"table2"``: Table 2 vs the model)."""
        key = "table2_model" if name == "table2" else name
        if key not in self._tables:
            raise KeyError(f"no table {name!r}" + did_you_mean(key, self._tables)
                           + f"; the tables: {', '.join(self._tables)}")
        return self._tables[key].to_pandas()

    def tables(self) -> dict[str, pd.DataFrame]:
        """Every table by name (copies)."""
        return {k: v.to_pandas() for k, v in self._tables.items()}

    def write(self, out_dir: str | os.PathLike, *, overwrite: bool = False, truth: TruthHook | None = None,
              title: str | None = None, protect: Iterable[str | os.PathLike] = (),
              tool: str = "estimator.calibrate") -> dict:
        """Write report.html, its CSV tables and figures into ``out_dir`` (listed as the tool's own).

        Parameters
        ----------
        out_dir : the output folder (:func:`estimator.io.outdir.prepare_output`): created when
            missing; an earlier run's files there are replaced only with ``overwrite``; a folder
            holding anything else, or one of the run's input files, is refused.
        truth : a truth hook adding the truth sections (``campaigns.truth_report.truth_sections``).
        title : the report's title (default "Flow-angle calibration: <problem source>").
        protect : more input paths never to remove (the problem's own files always are).
        tool : who writes, said in later refusals.

        Returns
        -------
        dict with ``report`` (the HTML path), ``accuracy`` (Table 2) and the truth hook's tables.
        """
        from estimator.io.outdir import input_paths, prepare_output

        out = Path(out_dir)
        protect = [*protect, *input_paths(self.problem)]
        title = title or f"Flow-angle calibration: {self.problem.source}"
        with prepare_output(out, overwrite=overwrite, tool=tool, protect=protect) as folder:
            return build_report(self.workflow, out, title, truth=truth, record=folder.record,
                                plots=self.options.plots)


def calibrate(problem: Problem, options: CalibrationOptions | Mapping[str, Any] | None = None, *,
              progress: Callable[[str], None] | None = None) -> Calibration:
    """Calibrate the sensors of ``problem`` by the Mach-bin workflow (paper §4), as ``fpr calibrate``.

    Parameters
    ----------
    problem : the flight data and models (:func:`estimator.io.load_problem`).
    options : :class:`CalibrationOptions` (used as given), or a flat mapping of option names
        (:meth:`CalibrationOptions.from_mapping`) that overrides the problem's own (its file's
        ``[workflow]``/``[solver]``/``[report]`` tables, ``problem.options``); None: the problem's
        own options, the defaults for the rest -- as ``fpr calibrate`` without flags.
    progress : called with a line of text as the workflow proceeds (e.g. ``print``).

    Returns
    -------
    Calibration : :meth:`Calibration.write` writes the report.
    """
    if options is None or isinstance(options, Mapping):
        options = CalibrationOptions.from_mapping({**problem.options, **(options or {})})
    wf = run_workflow(problem, dataclasses.replace(options.workflow, progress=progress))
    return Calibration(problem=problem, options=options, workflow=wf)


def write_estimation(problem: Problem, result, out_dir: str | os.PathLike, *, overwrite: bool = False,
                     plots: bool = True, extra_csv: Mapping[str, pd.DataFrame] | None = None,
                     protect: Iterable[str | os.PathLike] = (), tool: str = "estimator.estimate") -> Path:
    """Write one estimation's files into ``out_dir``, as ``fpr calibrate --single`` does.

    result.json (everything, the verdict first), parameters.csv, findings.csv, fit_quality.csv,
    residuals.csv, correlation.csv (:meth:`~estimator.result.EstimationResult.to_csv`), the figures
    (:func:`estimator.plots.save_standard_figures`) unless ``plots`` is false, and ``extra_csv``
    (file name -> table, e.g. a synthetic dataset's recovery.csv). The output folder is prepared
    and listed as :meth:`Calibration.write`'s. Returns ``out_dir``.
    """
    from estimator.io.outdir import input_paths, prepare_output

    out = Path(out_dir)
    protect = [*protect, *input_paths(problem)]
    with prepare_output(out, overwrite=overwrite, tool=tool, protect=protect) as folder:
        result.to_json(folder.record(out / "result.json"))
        result.to_csv(out, record=folder.record)
        for name, frame in (extra_csv or {}).items():
            frame.to_csv(folder.record(out / name))
        if plots:
            from estimator.plots import save_standard_figures

            save_standard_figures(problem, result, out, record=folder.record)
    return out
