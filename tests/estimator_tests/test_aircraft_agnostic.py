"""The estimator's code names no aircraft (issue 12, must-show 3): every channel, parameter and
sensor name a shipped model set declares (``estimator/models/*.toml``) lives in that TOML, never in
``estimator/**/*.py`` outside docstrings and comments.

The forbidden names are read from the model sets, so the list grows with them. A few declared names
are the estimator's own and stay allowed, each for a reason (:data:`GENERIC`).
"""

from __future__ import annotations

import ast
import re
import tomllib
from pathlib import Path

import pytest

from estimator.io.fprdataset import FPR_COLUMNS
from estimator.problem import STATE_PARAMS

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "estimator"
MODEL_SETS = sorted((PACKAGE / "models").glob("*.toml"))

#: Declared names that are not the aircraft's, with the reason each may appear in code.
GENERIC = {
    **{name: "a state-equation parameter (initial condition or IMU bias) of every model set: "
             "estimator.problem.STATE_PARAMS" for name in STATE_PARAMS},
    **{name: "a column of the FPR dataset format itself (INS attitude, air data, altitude): "
             "estimator.io.fprdataset.FPR_COLUMNS" for name in FPR_COLUMNS.values()},
}


def declared_names(path: Path) -> set[str]:
    """Every channel, column, sensor and parameter name a model set declares."""
    raw = tomllib.loads(path.read_text())
    names: set[str] = set(raw.get("parameter", {}))
    for ch in raw.get("channel", []):
        names |= {ch["name"], ch.get("column", ch["name"])}
        if "sensor" in ch:
            names.add(ch["sensor"])
    for sensor, parts in raw.get("sensor_midpoints", {}).items():
        names |= {sensor, *parts}
    return names


def forbidden_names() -> set[str]:
    return set().union(*(declared_names(p) for p in MODEL_SETS)) - set(GENERIC)


def aircraft_names_in(source: str, forbidden: set[str]) -> list[tuple[int, str]]:
    """(line, name) of each forbidden name in ``source``'s code: identifiers, and words of string
    literals (f-string parts included). Docstrings (every bare string statement) and comments
    (which the AST drops) do not count."""
    tree = ast.parse(source)
    docs = {id(n.value) for n in ast.walk(tree) if isinstance(n, ast.Expr)
            and isinstance(n.value, ast.Constant) and isinstance(n.value.value, str)}
    alternatives = "|".join(sorted(map(re.escape, forbidden), key=len, reverse=True))
    word = re.compile(rf"(?<![A-Za-z0-9_])({alternatives})(?![A-Za-z0-9_])")
    hits = []
    for n in ast.walk(tree):
        if isinstance(n, ast.Constant) and isinstance(n.value, str):
            found = [] if id(n) in docs else word.findall(n.value)
        elif isinstance(n, ast.Name):
            found = [n.id]
        elif isinstance(n, ast.Attribute):
            found = [n.attr]
        elif isinstance(n, ast.arg):
            found = [n.arg]
        elif isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            found = [n.name]
        elif isinstance(n, ast.keyword) and n.arg is not None:
            found = [n.arg]
        elif isinstance(n, ast.alias):
            found = [n.asname or n.name]
        else:
            continue
        hits += [(getattr(n, "lineno", 0), f) for f in found if f in forbidden]
    return sorted(set(hits))


def test_the_model_sets_declare_names_to_look_for():
    forbidden = forbidden_names()
    assert len(MODEL_SETS) >= 2, MODEL_SETS
    for path in MODEL_SETS:  # each model set contributes names of its own, not only generic ones
        assert declared_names(path) - set(GENERIC), path
    assert {"alpha_zl", "b_l", "f1", "vane_left", "side_probe_left", "alpha_v"} <= forbidden


def test_the_scan_finds_names_in_code_and_ignores_docstrings_and_comments():
    forbidden = {"alpha_zl", "b_l", "vane_left"}
    code = '''
"""Module docstring naming alpha_zl."""
X = "alpha_zl"                    # a string literal
def f(b_l):                       # an argument; comment: vane_left
    """Docstring: vane_left."""
    return obj.vane_left, f"{b_l} and alpha_zl_rad"
'''
    assert aircraft_names_in(code, forbidden) == [(3, "alpha_zl"), (4, "b_l"), (6, "b_l"), (6, "vane_left")]


@pytest.mark.parametrize("path", sorted(PACKAGE.rglob("*.py")), ids=lambda p: str(p.relative_to(ROOT)))
def test_estimator_code_names_no_aircraft(path):
    hits = aircraft_names_in(path.read_text(encoding="utf-8"), forbidden_names())
    assert not hits, (
        f"{path.relative_to(ROOT)} names model-set channels, parameters or sensors in code: "
        + ", ".join(f"line {line}: {name}" for line, name in hits)
        + ". Declare what the code needs in the model set (estimator/models/*.toml, read through "
        "estimator.io.modelset.Declarations) and read it from there; a name that is the estimator's "
        "own belongs in GENERIC with its reason")


def test_a_sensor_pairs_midpoint_is_the_model_sets_declaration():
    import numpy as np

    from estimator.io.modelset import declarations_of, parse_model_set, read_model_set, sensor_positions

    raw, source = read_model_set("tejas")
    decl = declarations_of(parse_model_set(raw, source)[0])
    assert decl.sensor_midpoints == {"side_probe": ("side_probe_left", "side_probe_right")}
    pos = {"side_probe_left": np.array([6.6, -0.5, 0.05]), "side_probe_right": np.array([6.6, 0.5, 0.05])}
    np.testing.assert_array_equal(sensor_positions(pos, decl)["side_probe"], [6.6, 0.0, 0.05])
    given = {**pos, "side_probe": np.array([6.0, 0.0, 0.0])}  # a position of its own wins
    np.testing.assert_array_equal(sensor_positions(given, decl)["side_probe"], [6.0, 0.0, 0.0])
    # without the declaration no Python derives it
    bare = declarations_of(parse_model_set({k: v for k, v in raw.items() if k != "sensor_midpoints"},
                                           source)[0])
    assert "side_probe" not in sensor_positions(pos, bare)
    # a misspelt sensor is refused with its close match
    with pytest.raises(ValueError, match=r"'side_prob' is not a sensor .*did you mean 'side_probe'"):
        parse_model_set({**raw, "sensor_midpoints": {"side_prob": ["a", "b"]}}, source)
    with pytest.raises(ValueError, match="two or more sensor names"):
        parse_model_set({**raw, "sensor_midpoints": {"side_probe": ["side_probe_left"]}}, source)
