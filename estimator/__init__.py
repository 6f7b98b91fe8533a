"""Flow-angle sensor calibration by flight path reconstruction and the output-error method.

What a notebook imports, from the package itself::

    from estimator import load_problem, estimate, SolverOptions, EstimationResult

    problem = load_problem("flight421.toml")            # your files, described by a problem file
    result = estimate(problem, SolverOptions())         # one estimation over all maneuvers
    print(result.summary())                             # the verdict first, then the estimates
    result.to_pandas()                                  # one row per parameter
    result.to_json("result.json")
    EstimationResult.from_json("result.json")           # the same result, read back

    from estimator import calibrate
    cal = calibrate(problem)                            # the Mach-bin workflow of fpr calibrate
    cal.to_pandas("table2")                             # Table 2, as table2_model.csv
    cal.write("results/flight421")                      # report.html and its CSVs, as fpr calibrate

Every name of ``__all__`` is loaded on first use (a module ``__getattr__``): ``import estimator``
itself loads neither NumPy nor the compiled kernels. The rest of the package — the model, the
normal equations, the kernels of :mod:`estimator.core`, the readers of :mod:`estimator.io` — is
internal: import it from its module when you need it, knowing that it may change.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

#: The public API: name -> the module that defines it.
_API = {
    # reading flight data into a problem
    "load_problem": "estimator.io",
    "problem_from_dataset": "estimator.io",
    "StateEquations": "estimator.io",
    "load_model_set": "estimator.io.modelset",
    "DataError": "estimator.io",
    "DataWarning": "estimator.io",
    "Problem": "estimator.problem",
    # one estimation
    "estimate": "estimator.solver",
    "SolverOptions": "estimator.options",
    "EstimationResult": "estimator.result",
    # what to make of it
    "Status": "estimator.verdict",
    "Verdict": "estimator.verdict",
    "Finding": "estimator.verdict",
    "Severity": "estimator.verdict",
    # the Mach-bin workflow
    "run_workflow": "estimator.workflow",
    "WorkflowOptions": "estimator.options",
    "WorkflowResult": "estimator.workflow",
    # the workflow and its report, as fpr calibrate does it
    "calibrate": "estimator.calibration",
    "Calibration": "estimator.calibration",
    "CalibrationOptions": "estimator.options",
    "write_estimation": "estimator.calibration",
}

__all__ = [  # = the keys of _API (a literal, so that linters see what is exported)
    "Calibration", "CalibrationOptions", "DataError", "DataWarning", "EstimationResult", "Finding",
    "Problem", "Severity", "SolverOptions", "StateEquations", "Status", "Verdict", "WorkflowOptions",
    "WorkflowResult",
    "calibrate", "estimate", "load_model_set", "load_problem", "problem_from_dataset", "run_workflow",
    "write_estimation",
]

if TYPE_CHECKING:  # what type checkers and editors see; at run time __getattr__ loads them
    from estimator.calibration import Calibration, calibrate, write_estimation
    from estimator.io import DataError, DataWarning, StateEquations, load_problem, problem_from_dataset
    from estimator.io.modelset import load_model_set
    from estimator.options import CalibrationOptions, SolverOptions, WorkflowOptions
    from estimator.problem import Problem
    from estimator.result import EstimationResult
    from estimator.solver import estimate
    from estimator.verdict import Finding, Severity, Status, Verdict
    from estimator.workflow import WorkflowResult, run_workflow


def __getattr__(name: str):
    module = _API.get(name)
    if module is None:
        raise AttributeError(f"module 'estimator' has no attribute {name!r}; the public API is "
                             f"{', '.join(__all__)} (the rest: import it from its module)")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # loaded once
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
