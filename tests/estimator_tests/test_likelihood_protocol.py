"""The solver chooses a likelihood once and never asks which it is (:mod:`estimator.likelihood`).

Both likelihoods implement every member of the :class:`~estimator.likelihood.Likelihood` protocol;
``estimator/solver.py`` (read with :mod:`ast`) names the method and the filter-error likelihood
only in the function that chooses, and tests no likelihood's type, attributes or method name
anywhere else. Fast: no estimation.
"""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import numpy as np
import pytest

import estimator.solver as solver
from estimator.filter_error import FilterErrorLikelihood
from estimator.likelihood import Likelihood, OutputErrorLikelihood
from estimator.options import SolverOptions

SOLVER = Path(solver.__file__)
#: the one function of the solver that chooses the likelihood
CHOOSER = "_likelihood"


def _protocol_members() -> set[str]:
    return {n for n, v in vars(Likelihood).items() if not n.startswith("_") and callable(v)}


@pytest.mark.parametrize("cls", [OutputErrorLikelihood, FilterErrorLikelihood])
def test_both_likelihoods_implement_the_protocol(cls):
    members = _protocol_members()
    assert {"evaluate", "stats", "relax", "cost", "normal", "before_iterations", "after_iterations",
            "screen_normal", "at_estimate", "deviations", "findings", "predictions",
            "result_fields"} <= members
    missing = sorted(m for m in members if not callable(getattr(cls, m, None)))
    assert not missing, f"{cls.__name__} lacks {missing}"
    for name in members:  # the same parameters, by name, as the protocol says
        want = list(inspect.signature(getattr(Likelihood, name)).parameters)
        got = list(inspect.signature(getattr(cls, name)).parameters)
        assert got == want, f"{cls.__name__}.{name}{got}: the protocol says {want}"


class _FakeModel:
    class problem:  # noqa: N801 - what the constructors read
        channels = ("a", "b")
        maneuvers = ()


def test_the_chooser_maps_each_method_to_its_likelihood():
    model = _FakeModel()
    oem = solver._likelihood(model, SolverOptions())
    assert type(oem) is OutputErrorLikelihood and isinstance(oem, Likelihood)
    fem = solver._likelihood(model, SolverOptions(method="filter_error", wind={"where": "all"}))
    assert type(fem) is FilterErrorLikelihood and isinstance(fem, Likelihood)
    assert fem.wind.where == "all" and np.array_equal(fem.windy, np.zeros(0, dtype=bool))


def _functions(tree: ast.Module) -> dict[str, ast.FunctionDef]:
    return {n.name: n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)}


def _asks_which(node: ast.AST) -> list[str]:
    """What in ``node`` asks which likelihood or method it is: ``.method``, a likelihood class's
    name, ``isinstance``/``hasattr``/``getattr``/``type`` of a likelihood."""
    out = []
    for n in ast.walk(node):
        if isinstance(n, ast.Attribute) and n.attr == "method":
            out.append(f"line {n.lineno}: .method")
        elif isinstance(n, ast.Name) and n.id in ("FilterErrorLikelihood", "OutputErrorLikelihood"):
            out.append(f"line {n.lineno}: {n.id}")
        elif (isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.args
              and n.func.id in ("isinstance", "hasattr", "getattr", "type")):
            # of a likelihood: a variable holding one (lik, likelihood) or a likelihood class
            if "lik" in ast.unparse(n.args[0]) or "Likelihood" in ast.unparse(n):
                out.append(f"line {n.lineno}: {ast.unparse(n)}")
    return out


def test_the_solver_asks_which_likelihood_only_where_it_chooses():
    tree = ast.parse(SOLVER.read_text(encoding="utf-8"))
    fns = _functions(tree)
    assert CHOOSER in fns, f"the chooser {CHOOSER} is gone from {SOLVER.name}: update this test"
    assert _asks_which(fns[CHOOSER]), "the chooser must be where the method is read"
    asks = {name: found for name, fn in fns.items() if name != CHOOSER and (found := _asks_which(fn))}
    assert not asks, f"{SOLVER.name} asks which likelihood it has outside {CHOOSER}: {asks}"


def test_the_check_finds_what_it_looks_for():
    src = ("def f(lik, opt, exc):\n    if isinstance(lik, FilterErrorLikelihood) or opt.method == 'x':\n"
           "        return hasattr(lik, 'noise')\n"
           "    return isinstance(opt.start, str), type(exc).__name__\n")
    found = sorted(_asks_which(ast.parse(src)))
    assert [f.split(":")[0] for f in found] == ["line 2", "line 2", "line 2", "line 3"], found
