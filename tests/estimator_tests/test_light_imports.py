"""What reading a problem file loads: the readers and the data types, never the estimation.

The options a problem file's ``[workflow]``/``[solver]``/``[report]`` tables hold are checked by
:mod:`estimator.options` (a data-type module), so :func:`estimator.io.load_problem` runs without
the workflow, the solver or matplotlib (each checked in a fresh interpreter, through
``sys.modules``).
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from _problem_files import si_problem

#: modules reading a problem file must not load (the estimation, its workflow and the report's plots)
#: and scipy's signal processing (the maneuver finder's peak search: half a second to import)
HEAVY = ("estimator.workflow", "estimator.solver", "estimator.calibration", "estimator.filter_error",
         "estimator.report", "matplotlib", "scipy.signal")
OPTIONS = "[solver]\nmax_iterations = 7\nmethod = \"filter_error\"\n[workflow]\nreference_mach = 0.6\n" \
          "[report]\nplots = false\n"


def _loaded_after(code: str) -> list[str]:
    """The modules of HEAVY (or below them) loaded after running ``code`` in a fresh interpreter."""
    probe = (f"{code}\nimport sys, json\n"
             f"print(json.dumps(sorted(m for m in sys.modules if m.startswith({HEAVY!r}))))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_reading_a_problem_file_loads_neither_the_solver_nor_the_workflow_nor_matplotlib(tmp_path):
    path = si_problem(tmp_path, extra=OPTIONS)
    code = ("from estimator.io import load_problem\n"
            f"p = load_problem({str(path)!r})\n"
            "assert dict(p.options)['max_iterations'] == 7, p.options")
    assert _loaded_after(code) == []


def test_the_options_load_no_estimation_code():
    code = ("from estimator import CalibrationOptions, SolverOptions, WorkflowOptions\n"
            "from estimator.options import DiagnosticOptions, WindOptions, option_tables\n"
            "CalibrationOptions.from_mapping({'method': 'filter_error', 'wind': {'where': 'all'}})\n"
            "assert 'solver' in option_tables()")
    assert _loaded_after(code) == []


def test_the_options_keep_their_old_homes():
    """Code that imported an options class from the module it lived in still gets the same class."""
    from estimator import CalibrationOptions, SolverOptions, WorkflowOptions, options
    from estimator.calibration import CalibrationOptions as from_calibration
    from estimator.calibration import option_tables
    from estimator.diagnostics import DiagnosticOptions
    from estimator.filter_error import DRYDEN_SCALE_LENGTH_M, WindOptions
    from estimator.io.modelset import Declarations, InitialConditionSources, Requirement
    from estimator.solver import SolverOptions as from_solver
    from estimator.workflow import WorkflowOptions as from_workflow

    assert from_solver is SolverOptions is options.SolverOptions
    assert from_workflow is WorkflowOptions is options.WorkflowOptions
    assert from_calibration is CalibrationOptions is options.CalibrationOptions
    assert option_tables is options.option_tables
    assert DiagnosticOptions is options.DiagnosticOptions and WindOptions is options.WindOptions
    assert DRYDEN_SCALE_LENGTH_M == options.DRYDEN_SCALE_LENGTH_M
    from estimator import declarations
    assert (Declarations, InitialConditionSources, Requirement) == (
        declarations.Declarations, declarations.InitialConditionSources, declarations.Requirement)


@pytest.mark.slow
def test_the_calibration_front_loads_matplotlib_only_to_draw():
    """``calibrate`` and the report's tables need no matplotlib: a run without plots (``--no-plots``,
    ``[report] plots = false``, a Monte Carlo worker) does not pay for importing it; drawing a
    figure imports it."""
    code = "import estimator.calibration, estimator.report, estimator.workflow, estimator.plots"
    assert not [m for m in _loaded_after(code) if m.startswith("matplotlib")]
    drawn = _loaded_after(code + "\nimport pandas as pd\nfrom estimator.report import figure_bias_vs_mach\n"
                          "figure_bias_vs_mach(pd.DataFrame({'mach': [0.5], 'aircraft': ['A'], "
                          "'mean_bias_deg': [0.1], 'std_deg': [0.01]}))")
    assert "matplotlib" in drawn
