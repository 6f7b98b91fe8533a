"""``estimator.calibrate`` is what ``fpr calibrate`` does: the same tables, numbers and report sections.

Two ``fpr calibrate`` runs of the same dataset write byte-identical CSV files (the solver, the
coloured-residual deviations included, is deterministic on one machine), so the library's CSVs are
compared byte for byte with the command's.
"""

from __future__ import annotations

import dataclasses
import re
import warnings
from pathlib import Path

import pandas as pd
import pytest

from estimator import Calibration, CalibrationOptions, calibrate, problem_from_dataset

pytestmark = pytest.mark.slow


def _sections(report: Path) -> list[str]:
    """The report's section headings and figure captions, in order."""
    return re.findall(r"<h2[^>]*>([^<]*)|<figcaption>([^<]*)", report.read_text())


@pytest.fixture(scope="module")
def runs(tiny_dataset, tmp_path_factory):
    from campaigns.cli import main
    from campaigns.truth_report import truth_sections

    root = tmp_path_factory.mktemp("calibrate-api")
    cli_out = root / "cli"
    # without figures: they are drawn by the same code for both (tests/estimator_tests/test_outdir.py
    # draws them), and three reports' figures would be most of this module's time
    code = main(["calibrate", str(tiny_dataset), "--no-plots", "--out", str(cli_out)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        problem = problem_from_dataset(tiny_dataset)
    cal = calibrate(problem, CalibrationOptions(plots=False))
    lib_out, free_out = root / "lib", root / "lib-truth-free"
    written = cal.write(lib_out, truth=truth_sections)
    cal.write(free_out)
    return code, cli_out, cal, lib_out, free_out, written


def test_the_library_writes_what_the_command_writes(runs):
    code, cli_out, cal, lib_out, _, written = runs
    assert code in (0, 3)
    assert written["report"] == lib_out / "report.html"
    cli_csv = sorted(p.name for p in cli_out.glob("*.csv"))
    assert cli_csv == sorted(p.name for p in lib_out.glob("*.csv"))
    assert {"table2_model.csv", "table2_truth.csv", "recovery.csv", "installation_biases.csv"} <= set(cli_csv)
    for name in cli_csv:
        assert (cli_out / name).read_bytes() == (lib_out / name).read_bytes(), name
    assert _sections(cli_out / "report.html") == _sections(lib_out / "report.html")


def test_the_tables_are_the_csv_files(runs):
    _, cli_out, cal, _, _, _ = runs
    t2, csv = cal.to_pandas("table2"), pd.read_csv(cli_out / "table2_model.csv")
    assert list(t2["sensor"]) == list(csv["sensor"])
    for col in ("mach", "three_sigma_deg", "desired_deg"):
        assert t2[col].to_numpy() == pytest.approx(csv[col].to_numpy(), rel=1e-12), col
    for name in cal.names:
        if name != "stages":
            assert (cli_out / f"{name}.csv").exists(), name
    with pytest.raises(KeyError, match="did you mean 'table2_model'"):
        cal.to_pandas("table2_modl")


def test_without_the_truth_hook_the_report_is_truth_free(runs):
    _, _, _, lib_out, free_out, _ = runs
    names = {p.name for p in free_out.glob("*.csv")}
    assert names == {p.name for p in lib_out.glob("*.csv")} - {
        "table2_truth.csv", "installation_recovery.csv", "recovery.csv"}
    page = (free_out / "report.html").read_text()
    assert "against the truth" not in page and "Recovery" not in page


def test_a_calibration_is_immutable(runs):
    _, _, cal, lib_out, _, _ = runs
    assert isinstance(cal, Calibration)
    with pytest.raises(dataclasses.FrozenInstanceError):
        cal.workflow = None
    t = cal.to_pandas("table2")
    t.iloc[0, t.columns.get_loc("three_sigma_deg")] = 99.0
    assert cal.to_pandas("table2")["three_sigma_deg"].iloc[0] != 99.0
    with pytest.raises(TypeError):
        cal._tables["table2_model"] = t
    # an output folder holding the earlier run is refused without overwrite, replaced with it
    with pytest.raises(ValueError, match="overwrite"):
        cal.write(lib_out)


def test_options_from_one_flat_mapping():
    opt = CalibrationOptions.from_mapping({"max_iterations": 7, "reference_mach": 0.6, "start": "both",
                                           "plots": False})
    assert opt.workflow.solver.max_iterations == 7 and opt.workflow.reference_mach == 0.6
    assert opt.workflow.solver.start == ("staged", "given") and opt.plots is False
    assert CalibrationOptions.from_mapping({}) == CalibrationOptions()
    with pytest.raises(ValueError, match="'max_iteration' \\(did you mean 'max_iterations'\\?\\)"):
        CalibrationOptions.from_mapping({"max_iteration": 3})
    with pytest.raises(dataclasses.FrozenInstanceError):
        opt.plots = True


def test_one_estimation_writes_what_the_single_command_writes(tiny_dataset, tmp_path):
    from campaigns.cli import main
    from campaigns.truth import recovery_table, true_parameters
    from estimator import estimate, write_estimation

    cli_out, lib_out = tmp_path / "cli", tmp_path / "lib"
    assert main(["calibrate", str(tiny_dataset), "--single", "--no-plots", "--out", str(cli_out)]) in (0, 3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        problem = problem_from_dataset(tiny_dataset)
    result = estimate(problem, CalibrationOptions().workflow.solver)
    rec = recovery_table(result, true_parameters(problem, result.free_estimated))
    write_estimation(problem, result, lib_out, plots=False, extra_csv={"recovery.csv": rec})
    names = sorted(p.name for p in cli_out.glob("*.csv"))
    assert "recovery.csv" in names and names == sorted(p.name for p in lib_out.glob("*.csv"))
    for name in names:
        assert (cli_out / name).read_bytes() == (lib_out / name).read_bytes(), name
