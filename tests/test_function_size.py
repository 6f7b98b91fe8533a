"""Function size, read from the source (no module is imported).

The team's rule: a function past 100 lines is two, and no function takes more than 8 parameters;
a longer parameter list is bundled (a small frozen dataclass or namedtuple). Numba kernels are
exempt from the parameter rule only: they take plain arrays, which they receive in named bundles
where they can, but a jitted signature cannot always be shortened without copying.

Every ``.py`` file of ``estimator/``, ``synth/`` and ``campaigns/`` is parsed with :mod:`ast`;
every function and method is measured, nested ones included:

* length: ``end_lineno - lineno + 1`` of the ``def`` statement (its decorators not counted);
* parameters: positional-only, positional and keyword-only parameters, ``*args`` and ``**kwargs``
  one each; a method's first parameter ``self`` or ``cls`` is not counted.

Functions are named by module and ``__qualname__`` (``synth.campaign.fly_campaign``,
``estimator.core.sensitivity.Inputs.__init__``, ``pkg.mod.outer.<locals>.inner``).
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
PACKAGES = ("estimator", "synth", "campaigns")
MAX_LINES = 100
MAX_PARAMETERS = 8

#: numba's compiling decorators: a function decorated with one of them is a kernel
JIT_DECORATORS = frozenset({"jit", "njit", "vectorize", "guvectorize", "cfunc", "stencil", "generated_jit"})

#: Offenders being split: a function here must still offend (a fixed one fails the test until its
#: name is removed), and no name is ever added. Empty: every function meets the rules.
KNOWN: frozenset[str] = frozenset()


@dataclass(frozen=True)
class Function:
    """One ``def``: its qualified name, where it is, its length and parameter count."""

    name: str
    path: str
    line: int
    lines: int
    parameters: int
    jitted: bool

    def problems(self) -> list[str]:
        out = []
        if self.lines > MAX_LINES:
            out.append(f"{self.lines} lines (at most {MAX_LINES})")
        if self.parameters > MAX_PARAMETERS and not self.jitted:
            out.append(f"{self.parameters} parameters (at most {MAX_PARAMETERS})")
        return out

    def __str__(self) -> str:
        return f"{self.name} ({self.path}:{self.line}): {', '.join(self.problems())}"


def _numba_names(tree: ast.Module) -> tuple[set[str], set[str]]:
    """(names bound to numba's compiling decorators, names bound to the numba module) in a module."""
    decorators, modules = set(), set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module == "numba":
            decorators |= {a.asname or a.name for a in node.names if a.name in JIT_DECORATORS}
        elif isinstance(node, ast.Import):
            modules |= {a.asname or a.name for a in node.names if a.name == "numba"}
    return decorators, modules


def _is_jitted(fn: ast.FunctionDef | ast.AsyncFunctionDef, decorators: set[str], modules: set[str]) -> bool:
    for dec in fn.decorator_list:
        target = dec.func if isinstance(dec, ast.Call) else dec
        if isinstance(target, ast.Name) and target.id in decorators:
            return True
        if (isinstance(target, ast.Attribute) and target.attr in JIT_DECORATORS
                and isinstance(target.value, ast.Name) and target.value.id in modules):
            return True
    return False


def _parameter_count(fn: ast.FunctionDef | ast.AsyncFunctionDef, is_method: bool) -> int:
    args = fn.args
    positional = [a.arg for a in (*args.posonlyargs, *args.args)]
    n = len(positional) + len(args.kwonlyargs) + (args.vararg is not None) + (args.kwarg is not None)
    static = any(isinstance(d, ast.Name) and d.id == "staticmethod" for d in fn.decorator_list)
    if is_method and not static and positional and positional[0] in ("self", "cls"):
        n -= 1
    return n


def functions_of(source: str, module: str, path: str) -> list[Function]:
    """Every function and method in ``source`` (the code of ``module``), nested ones included."""
    tree = ast.parse(source)
    decorators, modules = _numba_names(tree)
    out: list[Function] = []

    def visit(node: ast.AST, prefix: str, in_class: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.ClassDef):
                visit(child, f"{prefix}{child.name}.", True)
            elif isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                qual = f"{prefix}{child.name}"
                out.append(Function(
                    f"{module}.{qual}", path, child.lineno, child.end_lineno - child.lineno + 1,
                    _parameter_count(child, in_class), _is_jitted(child, decorators, modules)))
                visit(child, f"{qual}.<locals>.", False)
            else:
                # statements (if/try/with) hold definitions too; they belong to the enclosing scope
                visit(child, prefix, in_class)

    visit(tree, "", False)
    return out


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


@pytest.fixture(scope="module")
def offenders() -> dict[str, Function]:
    found = {}
    for package in PACKAGES:
        for path in sorted((REPO / package).rglob("*.py")):
            rel = str(path.relative_to(REPO))
            for fn in functions_of(path.read_text(encoding="utf-8"), _module_name(path), rel):
                if fn.problems():
                    found[fn.name] = fn
    return found


@pytest.mark.slow
def test_no_function_is_too_long_or_takes_too_many_parameters(offenders):
    new = sorted(str(fn) for name, fn in offenders.items() if name not in KNOWN)
    assert not new, (
        "split these along what they do, or bundle their parameters (a frozen dataclass or "
        "namedtuple):\n  " + "\n  ".join(new))


def test_the_known_offenders_still_offend(offenders):
    fixed = sorted(KNOWN - set(offenders))
    assert not fixed, (
        "fixed (or renamed): remove from KNOWN in tests/test_function_size.py (a renamed offender "
        "is a new one, to be split, not listed):\n  " + "\n  ".join(fixed))


def test_only_estimator_is_known():
    assert all(name.startswith("estimator.") for name in KNOWN)


@pytest.mark.parametrize(("source", "want"), [
    # decorators are not counted; the body is
    ("@dec\n@dec2\ndef f(a):\n" + "    x = 1\n" * 99, [("m.f", 100, 1, False)]),
    ("def f(self, a, /, b, *c, d, **e):\n    pass\n", [("m.f", 2, 6, False)]),
    ("class C:\n    def f(self, a, b):\n        pass\n"
     "    @staticmethod\n    def g(self, a):\n        pass\n",
     [("m.C.f", 2, 2, False), ("m.C.g", 2, 2, False)]),
    ("def f(a):\n    def g(b, c):\n        pass\n    return g\n",
     [("m.f", 4, 1, False), ("m.f.<locals>.g", 2, 2, False)]),
    ("from numba import njit as jit_\nimport numba as nb\n"
     "@jit_(cache=True)\ndef k(a):\n    pass\n@nb.njit\ndef j(a):\n    pass\n"
     "@other.njit\ndef o(a):\n    pass\n",
     [("m.k", 2, 1, True), ("m.j", 2, 1, True), ("m.o", 2, 1, False)]),
    ("if True:\n    def f(a):\n        pass\n", [("m.f", 2, 1, False)]),
])
def test_functions_are_measured_as_the_rule_says(source, want):
    got = [(f.name, f.lines, f.parameters, f.jitted) for f in functions_of(source, "m", "m.py")]
    assert got == want


def test_a_jitted_kernel_is_exempt_from_the_parameter_rule_only():
    params = ", ".join(f"a{i}" for i in range(9))
    src = f"from numba import njit\n@njit\ndef k({params}):\n" + "    x = 1\n" * 100
    (fn,) = functions_of(src, "m", "m.py")
    assert fn.problems() == ["101 lines (at most 100)"]


#: The solver orchestrates (chooses the likelihood once, runs the rounds, builds the result); what
#: a method needs lives in its likelihood, the rest in the modules below it: a solver past this
#: has taken on a part of its own again
SOLVER_MAX_LINES = 400


def test_the_solver_stays_an_orchestrator():
    n = len((REPO / "estimator" / "solver.py").read_text(encoding="utf-8").splitlines())
    assert n <= SOLVER_MAX_LINES, (
        f"estimator/solver.py has {n} lines (at most {SOLVER_MAX_LINES}): move what grew into the "
        "module that owns it (a likelihood's hook, gauss_newton, identifiability, checks)")
