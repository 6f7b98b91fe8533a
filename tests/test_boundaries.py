"""The package boundaries, read from the source (no module is imported).

`estimator/` never imports `synth/`, JSBSim or `campaigns/`; `synth/` never imports `estimator/` or
`campaigns/`: they meet only through the dataset format, and `campaigns/` (with the CLI) joins them.
Shipped code never imports the tests, their helpers or test-only packages.

Every module of the four packages is parsed with :mod:`ast`; every import is collected — plain and
``from`` imports, relative ones resolved against the module's package, imports inside functions,
``try``/``if TYPE_CHECKING`` blocks, and ``importlib.import_module`` / ``__import__`` calls with a
literal name. A rule holds directly (the import line itself) and transitively (through the repository's
own modules, parent packages' ``__init__`` included: importing ``aircraft_models`` runs its
``__init__``, so if that imported ``synth``, ``estimator`` would import ``synth`` at run time too).

Inside ``estimator/`` the modules stand in layers (:data:`ESTIMATOR_LAYERS`, lowest first: the
kernels, the data types, io and the model, the estimation modules, the solver, the workflow, the
calibration and its report). Read from the same scan, every import counted (``TYPE_CHECKING`` and
function-level ones too), each to the module it names (a parent package's ``__init__`` is not an
edge here: it is what Python runs first, not what the module uses):

- no module imports from a layer above its own;
- no module imports another's private name (``from estimator.x import _y``, ``x._y`` on an
  imported module): a name used elsewhere is public where it is defined;
- no import cycle, through any number of modules.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
PACKAGES = ("estimator", "synth", "campaigns", "aircraft_models")

#: the tests' own modules (``tests/**/*.py``: helpers such as ``_campaigns``, ``conftest``, test files)
#: and the packages only the ``test`` extra installs
TEST_ONLY = frozenset({"tests", "conftest", "pytest", "_pytest", "hypothesis",
                       *(p.stem for p in (REPO / "tests").rglob("*.py"))})


@dataclass(frozen=True)
class Rule:
    """Modules under ``packages`` never import a module under any of ``forbidden``."""

    packages: tuple[str, ...]
    forbidden: frozenset[str]
    why: str
    #: (importing module, forbidden top-level name) pairs tolerated for now; each must still occur
    known: frozenset[tuple[str, str]] = frozenset()


RULES = (
    Rule(("estimator",), frozenset({"synth", "jsbsim", "campaigns"}),
         "estimator/ never imports synth/, JSBSim or campaigns/ (they meet only through the dataset format)"),
    Rule(("synth",), frozenset({"estimator", "campaigns"}),
         "synth/ never imports estimator/ or campaigns/ (they meet only through the dataset format)"),
    Rule(("aircraft_models",), frozenset({"estimator", "synth", "campaigns"}),
         "aircraft_models/ (the aircraft data and the TOML schema helper, aircraft_models/schema.py) never "
         "imports estimator/, synth/ or campaigns/: all three import it"),
    Rule(("estimator", "synth"), TEST_ONLY,
         "estimator/ and synth/ never import the tests, their helpers or test-only packages"),
    Rule(("campaigns", "aircraft_models"), TEST_ONLY,
         "shipped code never imports the tests, their helpers or test-only packages"),
)


@dataclass(frozen=True)
class Import:
    """One import of a module: the absolute name imported, where, and the statement as written."""

    target: str
    line: int
    statement: str


def _top(name: str) -> str:
    return name.split(".", 1)[0]


def _under(name: str, roots: frozenset[str]) -> bool:
    return _top(name) in roots


def imports_of(source: str, module: str, is_package: bool = False) -> list[Import]:
    """Every import in ``source``, the code of ``module`` (dotted name), relative ones made absolute.

    ``from a.b import c`` yields ``a.b.c`` (``c`` may be a submodule); calls of
    ``importlib.import_module`` / ``__import__`` with a literal first argument count as imports.
    """
    tree = ast.parse(source, filename=module)
    # the package a relative import starts from: the module itself for an __init__
    package = module.split(".") if is_package else module.split(".")[:-1]
    found: list[Import] = []

    def add(target: str, node: ast.AST) -> None:
        found.append(Import(target, node.lineno, ast.unparse(node)))

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                add(alias.name, node)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                # a relative import above the top package cannot run; resolved as far as it goes
                base = package[: max(len(package) - (node.level - 1), 0)]
                prefix = ".".join([*base, *([node.module] if node.module else [])])
            else:
                prefix = node.module or ""
            for alias in node.names:
                add(prefix if alias.name == "*" else f"{prefix}.{alias.name}".lstrip("."), node)
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant) \
                and isinstance(node.args[0].value, str):
            func = node.func
            name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", None)
            if name in ("import_module", "__import__"):
                add(node.args[0].value, node)
    return found


def _modules() -> dict[str, Path]:
    """Dotted name -> file of every module of the four packages."""
    out = {}
    for pkg in PACKAGES:
        for path in sorted((REPO / pkg).rglob("*.py")):
            parts = path.relative_to(REPO).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _graph(modules: dict[str, Path]) -> dict[str, list[Import]]:
    return {name: imports_of(path.read_text(encoding="utf-8"), name, path.name == "__init__.py")
            for name, path in modules.items()}


def _internal(target: str, modules: dict[str, Path]) -> list[str]:
    """The repository modules that importing ``target`` runs: its longest known prefix and parents."""
    parts = target.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts) + 1) if ".".join(parts[:i]) in modules]


def _where(name: str, imp: Import, modules: dict[str, Path]) -> str:
    return f"{modules[name].relative_to(REPO).as_posix()}:{imp.line}: `{imp.statement}`"


def violations(modules: dict[str, Path], graph: dict[str, list[Import]],
               rules: tuple[Rule, ...] = RULES) -> list[str]:
    """Every broken rule: direct imports by file and line, transitive ones with the chain of imports.

    A forbidden import is reported once, where it is written; the modules that only reach it through
    that line are not listed again. One that breaks no rule where it stands (a package under no rule
    of that kind) but is reached from a module under a rule is reported with the shortest chain.
    """
    direct, reached = [], {}
    for rule in rules:
        for name in sorted(m for m in modules if _top(m) in rule.packages):
            # breadth-first through the repository's modules; the first (shortest) path to each is kept
            chain: dict[str, list[tuple[str, Import]]] = {name: []}
            queue = [name]
            while queue:
                current = queue.pop(0)
                for imp in graph[current]:
                    if _under(imp.target, rule.forbidden):
                        if (current, _top(imp.target)) in rule.known:
                            continue
                        steps = [*chain[current], (current, imp)]
                        if len(steps) == 1:
                            direct.append((name, imp, rule))
                        else:
                            reached.setdefault((rule, current, imp), []).append((name, steps))
                        continue
                    for nxt in _internal(imp.target, modules):
                        if nxt not in chain:
                            chain[nxt] = [*chain[current], (current, imp)]
                            queue.append(nxt)

    def rel(name: str) -> str:
        return modules[name].relative_to(REPO).as_posix()

    problems = [f"{rel(name)} imports {imp.target}: {_where(name, imp, modules)}\n    rule: {rule.why}"
                for name, imp, rule in direct]
    written = {(name, imp) for name, imp, _ in direct}
    for (rule, site, imp), origins in reached.items():
        if (site, imp) in written:
            continue  # that import line is reported itself; fixing it fixes every module reaching it
        origins.sort(key=lambda o: (len(o[1]), o[0]))
        name, steps = origins[0]
        how = " -> ".join(_where(m, i, modules) for m, i in steps)
        also = [rel(n) for n, _ in origins[1:]]
        more = (f"\n    also reached from: {', '.join(also[:5])}{' ...' if len(also) > 5 else ''}"
                if also else "")
        problems.append(f"{rel(name)} imports, through the repository's modules, {imp.target}: {how}"
                        f"{more}\n    rule: {rule.why}")
    return sorted(problems)


# --------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tree():
    modules = _modules()
    return modules, _graph(modules)


@pytest.mark.slow
def test_every_module_keeps_the_boundaries(tree):
    problems = violations(*tree)
    assert not problems, "package boundaries broken:\n" + "\n".join(problems)


def test_the_scan_sees_every_package_and_its_imports(tree):
    """The boundary test could fail: the scan finds the modules and the imports that do cross."""
    modules, graph = tree
    assert {_top(m) for m in modules} == set(PACKAGES)
    assert len(modules) > 60
    targets = {name: {_top(i.target) for i in imps} for name, imps in graph.items()}
    assert "jsbsim" in targets["synth.flight"] | targets["synth.jsbsim_io"]
    assert {"estimator", "synth"} <= targets["campaigns.cli"]
    # relative imports are resolved against the package
    # `from .runner import run_montecarlo` in campaigns/montecarlo/__init__.py
    assert "campaigns.montecarlo.runner.run_montecarlo" in {i.target for i in graph["campaigns.montecarlo"]}


def test_known_exceptions_still_occur(tree):
    """A tolerated import that is gone must leave the list (the list only shrinks)."""
    modules, graph = tree
    for rule in RULES:
        for name, target in rule.known:
            assert target in {_top(i.target) for i in graph.get(name, [])}, \
                f"{name} no longer imports {target}: remove it from the rule's known exceptions"


SYNTHETIC = [
    # (module, is_package, source, forbidden target expected, its line)
    ("estimator.solver", False, "import synth\n", "synth", 1),
    ("estimator.solver", False, "import numpy as np, jsbsim\n", "jsbsim", 1),
    ("estimator.io.build", False, "from synth.campaign import fly_campaign\n",
     "synth.campaign.fly_campaign", 1),
    ("estimator.io.build", False, "def f():\n    from campaigns import truth\n    return truth\n",
     "campaigns.truth", 2),
    ("estimator.io.build", False, "try:\n    import jsbsim.x\nexcept ImportError:\n    pass\n",
     "jsbsim.x", 2),
    ("estimator.io.build", False,
     "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from synth import truth\n", "synth.truth", 3),
    ("estimator.io.build", False, "import importlib\nm = importlib.import_module('synth.flight')\n",
     "synth.flight", 2),
    ("estimator.io", True, "x = __import__('campaigns')\n", "campaigns", 1),
    # beyond the top package: cannot run, still resolved to the package it names
    ("synth.flight", False, "from ..estimator import solver\n", "estimator.solver", 1),
    ("synth.flight", False, "import numpy\nfrom _campaigns import TINY_CAMPAIGN\n",
     "_campaigns.TINY_CAMPAIGN", 2),
    ("synth.flight", False, "import pytest\n", "pytest", 1),
    ("estimator.model", False, "from tests import conftest\n", "tests.conftest", 1),
    # the schema helper every package imports imports none of them
    ("aircraft_models.schema", False, "from estimator.io.errors import DataError\n",
     "estimator.io.errors.DataError", 1),
    ("aircraft_models", True, "import numpy\nfrom synth.flight import fly_maneuver\n",
     "synth.flight.fly_maneuver", 2),
]


def _path(module: str, is_package: bool) -> Path:
    parts = module.split(".")
    return REPO.joinpath(*parts, "__init__.py") if is_package else REPO.joinpath(*parts).with_suffix(".py")


@pytest.mark.parametrize("module, is_package, source, target, line", SYNTHETIC)
def test_a_forbidden_import_is_named_with_file_line_and_rule(module, is_package, source, target, line):
    path = _path(module, is_package)
    problems = violations({module: path}, {module: imports_of(source, module, is_package)})
    assert len(problems) == 1, problems
    rel = path.relative_to(REPO).as_posix()
    assert f"{rel} imports {target}: {rel}:{line}: `" in problems[0], problems[0]
    assert "\n    rule: " in problems[0]


@pytest.mark.parametrize("module, is_package, source", [
    ("estimator.io.build", False, "from . import units\nfrom ..core import kinematics\nimport numpy\n"),
    ("estimator.io", True, "from .build import x\nfrom .. import model\n"),
    ("synth.flight", False, "import jsbsim\nfrom aircraft_models import load_fleet\n"),
    ("campaigns.cli", False, "import estimator\nimport synth\nimport jsbsim\n"),
    # a name that merely starts like a forbidden package is another package
    ("estimator.model", False, "import synthesis_tools\nimport campaigns_extra\n"),
])
def test_allowed_imports_pass(module, is_package, source):
    path = _path(module, is_package)
    assert violations({module: path}, {module: imports_of(source, module, is_package)}) == []


def test_relative_imports_resolve_against_the_package():
    got = [i.target for i in imports_of("from . import a\nfrom ..core import b\nfrom .x import *\n",
                                        "estimator.io.build")]
    assert got == ["estimator.io.a", "estimator.core.b", "estimator.io.x"]
    got = [i.target for i in imports_of("from . import a\nfrom .. import b\n", "estimator.io",
                                        is_package=True)]
    assert got == ["estimator.io.a", "estimator.b"]


def test_a_forbidden_import_through_another_package_is_caught():
    """estimator -> aircraft_models -> synth: each import allowed alone, the chain breaks the rule."""
    modules = {"estimator.model": REPO / "estimator" / "model.py",
               "aircraft_models": REPO / "aircraft_models" / "__init__.py",
               "aircraft_models.extra": REPO / "aircraft_models" / "extra.py"}
    graph = {"estimator.model": imports_of("import numpy\nfrom aircraft_models.extra import x\n",
                                           "estimator.model"),
             # the parent package's __init__ runs too: the forbidden import hides there
             "aircraft_models.extra": imports_of("X = 1\n", "aircraft_models.extra"),
             "aircraft_models": imports_of("\nfrom synth.flight import fly_maneuver\n", "aircraft_models",
                                           is_package=True)}
    # without the rule on aircraft_models itself, which would report the import line directly
    problems = violations(modules, graph, tuple(r for r in RULES if "aircraft_models" not in r.packages
                                                 or r.forbidden == TEST_ONLY))
    assert len(problems) == 1, problems
    assert problems[0].startswith("estimator/model.py imports, through the repository's modules, "
                                  "synth.flight.fly_maneuver: estimator/model.py:2: "), problems[0]
    assert "aircraft_models/__init__.py:2: `from synth.flight import fly_maneuver`" in problems[0]
    assert "rule: estimator/ never imports synth/" in problems[0]


def test_no_folder_of_the_tests_shadows_a_package():
    # tests/ is on the import path (pytest's pythonpath and its rootdir insertion for conftest.py):
    # a folder tests/<package>/ would be a namespace package that `import <package>` finds before
    # an editable install's finder does (plain `pytest`, a script adding tests/ to sys.path)
    shadowing = sorted(p.name for p in (REPO / "tests").iterdir() if p.is_dir() and p.name in PACKAGES)
    assert not shadowing, (f"tests/{shadowing[0]}/ shadows the package {shadowing[0]}: "
                           f"name it {shadowing[0]}_tests/")


# --------------------------------------------------------------------------------------------------
# the estimator's layers

#: The estimator's layers, lowest first, each with the modules (and packages: every module below
#: them) it holds; a module imports from its own layer and those below, never from one above.
ESTIMATOR_LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    # compiled and numerical kernels: arrays in, arrays out
    ("kernels", ("estimator.core",)),
    # what a problem, its options and a result are (no estimation code)
    ("data types", ("estimator.parameters", "estimator.problem", "estimator.declarations",
                    "estimator.options", "estimator.verdict", "estimator.finding_kinds",
                    "estimator.finding_groups", "estimator.result", "estimator.accuracy")),
    # reading flight data into a problem; the model of its channels and its normal equations
    # (and the maneuver finder, which io's flight reader and the problem file's checks use)
    ("io and model", ("estimator.io", "estimator.model", "estimator.normal_equations",
                      "estimator.calibrated", "estimator.start", "estimator.autopilot",
                      "estimator.extraction")),
    # the parts of an estimation: likelihoods, iterations, identifiability, deviations, diagnostics
    ("estimation", ("estimator.likelihood", "estimator.gauss_newton", "estimator.identifiability",
                    "estimator.uncertainty", "estimator.diagnostics", "estimator.filter_error",
                    "estimator.checks")),
    ("solver", ("estimator.solver",)),
    ("workflow", ("estimator.workflow",)),
    # the package's own __init__ (its public API) names everything, as the top does
    ("calibration and report", ("estimator.calibration", "estimator.report", "estimator.plots",
                                "estimator")),
)

#: (importing module, imported module) edges that break a layer or a cycle and are tolerated for
#: now: each must still occur (the set only shrinks). None left.
KNOWN_ESTIMATOR_EDGES: frozenset[tuple[str, str]] = frozenset()


def layer_of(module: str) -> int | None:
    """The index in :data:`ESTIMATOR_LAYERS` of ``module`` (its longest listed prefix; the package
    ``estimator`` itself only by its own name), None if no layer names it."""
    best: tuple[int, int] | None = None
    for i, (_, names) in enumerate(ESTIMATOR_LAYERS):
        for n in names:
            if module == n or (n != "estimator" and module.startswith(n + ".")):
                if best is None or len(n) > best[1]:
                    best = (i, len(n))
    return None if best is None else best[0]


def _is_private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


@dataclass(frozen=True)
class Edge:
    """One import between two estimator modules: the module it names (deepest known) and the line."""

    source: str
    target: str
    imp: Import


def estimator_edges(modules: dict[str, Path], graph: dict[str, list[Import]]) -> list[Edge]:
    """Every import of an estimator module by another, to the deepest module its name reaches (one
    edge per import line and module: ``from m import a, b`` is one)."""
    out: dict[tuple[str, str, int], Edge] = {}
    for name in sorted(m for m in modules if _top(m) == "estimator"):
        for imp in graph[name]:
            reached = _internal(imp.target, modules)
            if reached and _top(reached[-1]) == "estimator" and reached[-1] != name:
                out.setdefault((name, reached[-1], imp.line), Edge(name, reached[-1], imp))
    return list(out.values())


def layer_violations(modules: dict[str, Path], edges: list[Edge],
                     known: frozenset[tuple[str, str]] = KNOWN_ESTIMATOR_EDGES) -> list[str]:
    """An import from a layer above the importing module's, by file and line."""
    out = []
    for e in edges:
        a, b = layer_of(e.source), layer_of(e.target)
        if a is None or b is None or b <= a or (e.source, e.target) in known:
            continue
        out.append(f"{_where(e.source, e.imp, modules)}: {e.source} ({ESTIMATOR_LAYERS[a][0]}) imports "
                   f"{e.target} ({ESTIMATOR_LAYERS[b][0]}), a layer above its own")
    return out


def private_imports(modules: dict[str, Path], graph: dict[str, list[Import]]) -> list[str]:
    """Every private name an estimator module imports from another (``from estimator.x import _y``,
    or a private module), by file and line."""
    out = []
    for name in sorted(m for m in modules if _top(m) == "estimator"):
        for imp in graph[name]:
            reached = _internal(imp.target, modules)
            if not reached or _top(reached[-1]) != "estimator" or reached[-1] == name:
                continue
            if any(_is_private(part) for part in imp.target.split(".")):
                out.append(f"{_where(name, imp, modules)}: {name} imports the private name {imp.target}")
    return out


def private_attribute_uses(source: str, module: str, is_package: bool, modules: dict[str, Path]
                           ) -> list[tuple[int, str]]:
    """``(line, "m._y")`` for each private attribute read off an estimator module that ``module``
    imported as a name (``import estimator.x as m``, ``from estimator import x``)."""
    tree = ast.parse(source, filename=module)
    bound: dict[str, str] = {}  # local name -> estimator module
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.asname and alias.name in modules and _top(alias.name) == "estimator":
                    bound[alias.asname] = alias.name
        elif isinstance(node, ast.ImportFrom):
            for alias, imp in zip(node.names, imports_of(ast.unparse(node), module, is_package),
                                  strict=False):
                if imp.target in modules and _top(imp.target) == "estimator" and imp.target != module:
                    bound[alias.asname or alias.name] = imp.target
    return [(node.lineno, f"{node.value.id}.{node.attr}") for node in ast.walk(tree)
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
            and node.value.id in bound and _is_private(node.attr)]


def import_cycles(edges: list[Edge]) -> list[list[str]]:
    """The import cycles: each strongly connected set of modules (more than one), sorted."""
    succ: dict[str, set[str]] = {}
    for e in edges:
        succ.setdefault(e.source, set()).add(e.target)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles = []

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(succ.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in sorted(succ):
        if v not in index:
            visit(v)
    return sorted(cycles)


def _cycle_text(cycle: list[str], edges: list[Edge], modules: dict[str, Path]) -> str:
    inside = set(cycle)
    lines = [f"    {_where(e.source, e.imp, modules)}" for e in edges
             if e.source in inside and e.target in inside]
    return f"import cycle {' <-> '.join(cycle)}:\n" + "\n".join(lines)


@pytest.fixture(scope="module")
def edges(tree):
    modules, graph = tree
    known = KNOWN_ESTIMATOR_EDGES
    return [e for e in estimator_edges(modules, graph) if (e.source, e.target) not in known]


def test_every_estimator_module_has_a_layer(tree):
    modules, _ = tree
    loose = sorted(m for m in modules if _top(m) == "estimator" and layer_of(m) is None)
    assert not loose, f"add these to a layer of ESTIMATOR_LAYERS (tests/test_boundaries.py): {loose}"


def test_no_estimator_module_imports_from_a_layer_above(tree, edges):
    problems = layer_violations(tree[0], edges)
    assert not problems, ("estimator layers broken (ESTIMATOR_LAYERS, lowest first: "
                          + ", ".join(n for n, _ in ESTIMATOR_LAYERS) + "):\n" + "\n".join(problems))


@pytest.mark.slow
def test_no_estimator_module_imports_a_private_name_of_another(tree):
    modules, graph = tree
    problems = private_imports(modules, graph)
    for name, path in modules.items():
        if _top(name) == "estimator":
            for line, use in private_attribute_uses(path.read_text(encoding="utf-8"), name,
                                                    path.name == "__init__.py", modules):
                problems.append(f"{path.relative_to(REPO).as_posix()}:{line}: {name} reads {use}")
    assert not problems, ("a private name used across modules: make it public where it is defined, "
                          "or move it to the module that uses it:\n" + "\n".join(problems))


def test_the_estimator_has_no_import_cycle(tree, edges):
    cycles = import_cycles(edges)
    assert not cycles, "\n".join(_cycle_text(c, edges, tree[0]) for c in cycles)


def test_the_layer_scan_sees_the_estimators_imports(tree):
    """The layer tests could fail: the scan finds run-time, function-level and annotation-only edges."""
    found = {(e.source, e.target) for e in estimator_edges(*tree)}
    assert {("estimator.solver", "estimator.gauss_newton"),  # run time
            ("estimator.calibration", "estimator.plots"),  # inside a function
            ("estimator.uncertainty", "estimator.core.instrumental"),  # TYPE_CHECKING
            ("estimator.workflow", "estimator.io")} <= found  # a package's __init__ named itself
    assert len(found) > 150


def test_known_estimator_edges_still_occur(tree):
    """A tolerated edge that is gone must leave KNOWN_ESTIMATOR_EDGES (the set only shrinks)."""
    present = {(e.source, e.target) for e in estimator_edges(*tree)}
    gone = sorted(KNOWN_ESTIMATOR_EDGES - present)
    assert not gone, f"no longer imported: remove from KNOWN_ESTIMATOR_EDGES: {gone}"


def _scan(sources: dict[str, str]) -> tuple[dict[str, Path], dict[str, list[Import]], list[Edge]]:
    """Modules, import graph and estimator edges of hand-written sources (module -> code)."""
    modules = {m: _path(m, False) for m in sources}
    graph = {m: imports_of(src, m) for m, src in sources.items()}
    return modules, graph, estimator_edges(modules, graph)


@pytest.mark.parametrize("statement", [
    "from estimator.solver import estimate\n",
    "def f():\n    from estimator.solver import estimate\n    return estimate\n",
    "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from estimator.solver import SolverOptions\n",
])
def test_an_upward_import_is_named_with_its_layers(statement):
    modules, _, edges = _scan({"estimator.uncertainty": statement, "estimator.solver": ""})
    problems = layer_violations(modules, edges)
    assert len(problems) == 1, problems
    assert problems[0].startswith("estimator/uncertainty.py:"), problems[0]
    assert "estimator.uncertainty (estimation) imports estimator.solver (solver)" in problems[0]
    # tolerated while listed as known
    assert layer_violations(modules, edges, frozenset({("estimator.uncertainty", "estimator.solver")})) == []


def test_imports_down_or_across_a_layer_pass():
    modules, _, edges = _scan({
        "estimator.solver": "from estimator.gauss_newton import gauss_newton\nimport numpy\n",
        "estimator.gauss_newton": "from estimator.identifiability import has_data\n"
                                  "from estimator.core.kinematics import x\n",
        "estimator.identifiability": "", "estimator.core.kinematics": ""})
    assert layer_violations(modules, edges) == []
    assert layer_of("estimator.core.wind_filter") == 0 and layer_of("estimator.io.build") == 2
    assert layer_of("estimator") == len(ESTIMATOR_LAYERS) - 1 and layer_of("estimatorx") is None


def test_a_private_name_imported_from_another_module_is_caught():
    modules, graph, _ = _scan({
        "estimator.solver": "from estimator.identifiability import _screen, screen\n"
                            "from estimator.verdict import Status as _Status\n",
        "estimator.identifiability": "from estimator.identifiability import _x\n",  # its own: fine
        "estimator.verdict": ""})
    problems = private_imports(modules, graph)
    assert len(problems) == 1 and "imports the private name estimator.identifiability._screen" in problems[0]
    src = "import estimator.model as m\nfrom estimator import uncertainty\nm._inputs\nuncertainty._std_of\n" \
          "uncertainty.honest_std\nm.__doc__\n"
    modules = {m: _path(m, False) for m in ("estimator.solver", "estimator.model", "estimator.uncertainty")}
    assert private_attribute_uses(src, "estimator.solver", False, modules) == [
        (3, "m._inputs"), (4, "uncertainty._std_of")]


def test_an_import_cycle_is_found_through_type_checking_imports():
    _, _, edges = _scan({
        "estimator.solver": "from estimator.filter_error import F\n",
        "estimator.filter_error": "from estimator.uncertainty import u\n",
        "estimator.uncertainty": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                                 "    from estimator.filter_error import DelayCheck\n",
        "estimator.model": "from estimator.problem import P\n", "estimator.problem": ""})
    assert import_cycles(edges) == [["estimator.filter_error", "estimator.uncertainty"]]
    three = {"estimator.a": "from estimator.b import x\n", "estimator.b": "from estimator.c import y\n",
             "estimator.c": "def f():\n    from estimator.a import z\n"}
    assert import_cycles(_scan(three)[2]) == [["estimator.a", "estimator.b", "estimator.c"]]
