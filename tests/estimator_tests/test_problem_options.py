"""The problem file's [solver]/[workflow]/[report] tables and the scenario's [estimator]: one mapping
of option names (CalibrationOptions.from_mapping) for the problem file, the CLI and Monte Carlo."""

from __future__ import annotations

import pickle

import pytest
from _problem_files import si_problem

import estimator.calibration as calibration
from campaigns.cli import main
from campaigns.montecarlo.scenario import ScenarioError, load_scenario, parse_scenario
from estimator.calibration import CalibrationOptions, calibrate
from estimator.io import DataError, load_problem
from estimator.solver import SolverOptions

OPTIONS = "[solver]\nmax_iterations = 7\n[workflow]\nreference_mach = 0.6\n[report]\nplots = false\n"


class _Stop(Exception):
    """Raised by the stubbed workflow: the options have been seen, no estimation is run."""


@pytest.fixture
def seen(monkeypatch):
    """The WorkflowOptions calibrate() hands to the workflow (which is not run)."""
    got = []

    def fake(problem, options):
        got.append(options)
        raise _Stop

    monkeypatch.setattr(calibration, "run_workflow", fake)
    return got


def test_problem_file_options_reach_the_workflow(tmp_path, seen):
    problem = load_problem(si_problem(tmp_path, extra=OPTIONS))
    assert dict(problem.options) == {"max_iterations": 7, "reference_mach": 0.6, "plots": False}
    with pytest.raises(TypeError):
        problem.options["max_iterations"] = 8  # read-only
    assert pickle.loads(pickle.dumps(problem.options)) == problem.options  # goes to worker processes
    with pytest.raises(_Stop):
        calibrate(problem)
    wf = seen[-1]
    assert (wf.solver.max_iterations, wf.reference_mach) == (7, 0.6)
    # a mapping given overrides the file's option, the others stay
    with pytest.raises(_Stop):
        calibrate(problem, {"max_iterations": 9})
    assert (seen[-1].solver.max_iterations, seen[-1].reference_mach) == (9, 0.6)
    # a problem file without the tables: the defaults
    (tmp_path / "plain").mkdir()
    plain = load_problem(si_problem(tmp_path / "plain"))
    assert dict(plain.options) == {}
    with pytest.raises(_Stop):
        calibrate(plain)
    assert seen[-1].solver == SolverOptions() and seen[-1].reference_mach is None


def test_cli_flags_override_the_problem_file(tmp_path, seen):
    path = si_problem(tmp_path, extra=OPTIONS)
    cases = [([], (7, 0.6, 0.05, "staged")),
             (["--max-iterations", "12", "--start", "given"], (12, 0.6, 0.05, "given")),
             (["--reference-mach", "0.7", "--max-mach-variation", "0.1"], (7, 0.7, 0.1, "staged"))]
    for flags, expected in cases:
        with pytest.raises(_Stop):
            main(["calibrate", str(path), "--out", str(tmp_path / "out"), *flags])
        wf = seen[-1]
        assert (wf.solver.max_iterations, wf.reference_mach, wf.max_mach_variation, wf.solver.start) \
            == expected, flags


def test_cli_without_flags_or_tables_keeps_the_defaults(tmp_path, seen):
    with pytest.raises(_Stop):
        main(["calibrate", str(si_problem(tmp_path)), "--out", str(tmp_path / "out")])
    assert seen[-1].solver == SolverOptions() and seen[-1].max_mach_variation == 0.05


@pytest.mark.parametrize("table, fragments", [
    ("[solver]\nmax_iteration = 7\n", ["[solver]", "'max_iteration'", "did you mean 'max_iterations'"]),
    ("[workflow]\nrefrence_mach = 0.6\n", ["[workflow]", "did you mean 'reference_mach'"]),
    ("[workflow]\nmax_iterations = 7\n", ["[workflow]", "belongs under [solver]"]),
    ("[solver]\nstart = \"sometimes\"\n", ["[solver]", "start"]),
])
def test_a_bad_option_names_the_file_the_table_and_the_close_match(tmp_path, table, fragments):
    path = si_problem(tmp_path, extra=table)
    with pytest.raises(DataError) as info:
        load_problem(path)
    msg = str(info.value)
    for f in [str(path), *fragments]:
        assert f in msg, f"{f!r} not in: {msg}"


# ------------------------------------------------------------------------------------ the scenario


def test_shipped_scenarios_give_the_options_they_gave_before():
    for name in ("mc_20maneuvers", "mc_20maneuvers_realistic"):
        est = load_scenario(name).estimator
        # before: SolverOptions(max_iterations=est.max_iterations, colored=est.colored), 40 and true
        assert est.solver == SolverOptions(max_iterations=40, colored=True)
        assert (est.max_iterations, est.colored) == (40, True)


def _scenario(estimator: dict) -> dict:
    raw = load_scenario("mc_20maneuvers").raw
    return {**raw, "estimator": {**raw["estimator"], **estimator}}


def test_scenario_estimator_goes_through_the_same_mapping():
    est = parse_scenario(_scenario({"max_iterations": 11, "solver": {"start": "both", "robust": True}})
                         ).estimator
    assert est.solver == CalibrationOptions.from_mapping(
        {"max_iterations": 11, "colored": True, "start": "both", "robust": True}).workflow.solver
    assert est.solver.start == ("staged", "given") and est.max_iterations == 11
    with pytest.raises(ScenarioError, match="did you mean 'max_iterations'"):
        parse_scenario({**_scenario({}), "estimator": {"solver": {"max_iteration": 3}}})
    with pytest.raises(ScenarioError, match="keep one"):
        parse_scenario(_scenario({"solver": {"max_iterations": 3}}))
