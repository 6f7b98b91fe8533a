r"""Channel models declared as data: a small expression language with exact first derivatives.

A calibration model is written as text, e.g. the paper's Table 1 / Eq. 7 (SPEC §5)::

    alpha_yl  = f1(alpha_s) + f2(alpha_t) * beta_s + b_l
    alpha_ysp = alpha_s + f3(z) + b_sa                 # z: the channel's own measurement
    beta_ynp  = f5(alpha_t) * (beta_s + b_n)
    beta_ybu  = beta_s + k_bu * beta_s + b_bu

Grammar: numbers, names, ``+ - * /``, unary minus, parentheses, and calls ``name(expr)`` of
piecewise-linear tables (or of ``sin``, ``cos``, ``tan``, ``atan``, ``exp``). Each name is a
*signal* (an array the caller provides: model signals that depend on the state, such as
``alpha_s``, or data signals, such as a measured channel) or a *parameter* (a scalar). Tables
are :class:`Table` objects: fixed breakpoints, free values.

Evaluation is forward-mode differentiation on whole arrays: every node returns its value and its
partial derivatives with respect to each parameter, each table value and each state-dependent
signal, so the estimator can chain ``dy/dx = dy/dsignal * dsignal/dx`` without finite differences.
A table's derivative with respect to its values is a hat function: at most two breakpoints touch a
sample, so it is stored sparsely as (left index, left weight, right weight).

The estimator evaluates a channel for all maneuvers at once, on their concatenated samples: a
parameter may then be an array (one value per sample: a per-aircraft bias over maneuvers of
several aircraft), and so may a table's values (``(N, K)``, one row per sample).
:meth:`Expression.value` evaluates without derivatives (the solver's trial steps), with the very
same arithmetic as the value of :meth:`Expression.evaluate`.
"""

from __future__ import annotations

import ast
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

_FUNCS = {
    "sin": (np.sin, np.cos),
    "cos": (np.cos, lambda x: -np.sin(x)),
    "tan": (np.tan, lambda x: 1.0 / np.cos(x) ** 2),
    "atan": (np.arctan, lambda x: 1.0 / (1.0 + x * x)),
    "exp": (np.exp, np.exp),
}


class ExpressionError(ValueError):
    """A channel model that cannot be parsed or evaluated; says where and how to fix it."""


@dataclass(frozen=True)
class Table:
    """A piecewise-linear table: values at fixed breakpoints, linear between, held beyond the ends.

    Attributes
    ----------
    name : table name used in expressions (``f1``).
    breakpoints : (K,) strictly increasing breakpoints, in the argument's SI unit (rad for angles).
    """

    name: str
    breakpoints: np.ndarray

    def __post_init__(self) -> None:
        bp = np.asarray(self.breakpoints, dtype=float)
        if bp.ndim != 1 or bp.size < 2 or np.any(np.diff(bp) <= 0):
            raise ExpressionError(
                f"table {self.name}: breakpoints must be at least two strictly increasing numbers, got {bp}"
            )
        object.__setattr__(self, "breakpoints", bp)

    def locate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Interpolation segment and weights: ``f(x) = (1-w) v[i] + w v[i+1]``.

        Beyond the ends the table is held constant (w clipped to [0, 1]) so that a table never
        extrapolates into an angle range no maneuver covered; ``inside`` marks samples with a slope.
        """
        bp = self.breakpoints
        i = np.clip(np.searchsorted(bp, x, side="right") - 1, 0, bp.size - 2)
        w_raw = (x - bp[i]) / (bp[i + 1] - bp[i])
        w = np.clip(w_raw, 0.0, 1.0)
        inside = (w_raw >= 0.0) & (w_raw <= 1.0)
        return i, w, inside

    def evaluate(self, values: np.ndarray, x: np.ndarray) -> np.ndarray:
        i, w, _ = self.locate(x)
        lo, hi = _node_values(values, i)
        return (1.0 - w) * lo + w * hi


def _node_values(values: np.ndarray, i: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Table values at segment ``i`` and ``i + 1``; ``values`` is (K,) or per sample (N, K)."""
    if values.ndim == 1:
        return values[i], values[i + 1]
    i = np.broadcast_to(i, values.shape[:1])
    rows = np.arange(values.shape[0])
    return values[rows, i], values[rows, i + 1]


@dataclass
class Dual:
    """A value with its derivatives (forward mode), all arrays broadcastable to the samples.

    ``dparam[name]`` : derivative w.r.t. a scalar parameter.
    ``dtable[name]`` : list of (index, coefficient) pairs: derivative w.r.t. table value
        ``values[index]`` is ``coefficient`` (arrays of samples), sparse hat functions.
    ``dsignal[name]`` : derivative w.r.t. a state-dependent signal.
    """

    value: np.ndarray
    dparam: dict[str, np.ndarray] = field(default_factory=dict)
    dtable: dict[str, list[tuple[np.ndarray, np.ndarray]]] = field(default_factory=dict)
    dsignal: dict[str, np.ndarray] = field(default_factory=dict)

    def scaled(self, factor) -> Dual:
        return Dual(
            self.value * factor,
            {k: v * factor for k, v in self.dparam.items()},
            {k: [(i, c * factor) for i, c in v] for k, v in self.dtable.items()},
            {k: v * factor for k, v in self.dsignal.items()},
        )


def _add(a: Dual, b: Dual, sign: float = 1.0) -> Dual:
    out = Dual(a.value + sign * b.value, dict(a.dparam), {k: list(v) for k, v in a.dtable.items()},
               dict(a.dsignal))
    for k, v in b.dparam.items():
        out.dparam[k] = out.dparam[k] + sign * v if k in out.dparam else sign * v
    for k, v in b.dtable.items():
        out.dtable.setdefault(k, []).extend((i, sign * c) for i, c in v)
    for k, v in b.dsignal.items():
        out.dsignal[k] = out.dsignal[k] + sign * v if k in out.dsignal else sign * v
    return out


def _has_d(a: Dual) -> bool:
    return bool(a.dparam or a.dtable or a.dsignal)


@dataclass(frozen=True)
class Expression:
    """A parsed channel model.

    Attributes
    ----------
    text : the source text.
    names : every bare name used (signals and parameters).
    tables : names called like functions that are not built-in functions.
    """

    text: str
    tree: ast.AST = field(repr=False)
    names: frozenset[str]
    tables: frozenset[str]

    def evaluate(
        self,
        signals: Mapping[str, np.ndarray],
        params: Mapping[str, float],
        tables: Mapping[str, tuple[Table, np.ndarray]],
        state_signals: frozenset[str] | set[str] = frozenset(),
        by_parameters: bool = True,
    ) -> Dual:
        """Evaluate with derivatives.

        Parameters
        ----------
        signals : name -> (N,) array (SI).
        params : name -> scalar value (SI), or (N,) values per sample.
        tables : name -> (Table, values (K,) or per sample (N, K)).
        state_signals : the signals to differentiate with respect to (they depend on the state).
        by_parameters : also by the parameters and table values (False: by ``state_signals``
            alone, for an iteration that needs no more; the value and those derivatives are the
            same operation for operation: a derivative's arithmetic never involves another's).

        Returns
        -------
        Dual with the value (N,) and the derivatives.
        """
        return _Evaluator(self, signals, params, tables, state_signals, by_parameters).visit(self.tree)

    def affine_in(self, free: frozenset[str] | set[str]) -> bool:
        """Is the model affine in ``free`` (parameter and table names), whatever the signals?

        Read off the tree, exactly: sums and negations of affine terms; a product with at most one
        factor that depends on ``free``; a quotient whose denominator does not; a function or a
        table whose argument does not (a table is linear in its own values). Then every
        derivative with respect to ``free`` is independent of their values, to the bit.
        """
        return _affine(self.tree, frozenset(free))

    def value(
        self,
        signals: Mapping[str, np.ndarray],
        params: Mapping[str, float | np.ndarray],
        tables: Mapping[str, tuple[Table, np.ndarray]],
    ) -> np.ndarray:
        """The value alone: what ``evaluate(...).value`` gives, operation for operation."""
        return _Evaluator(self, signals, params, tables, frozenset()).value(self.tree)


def _uses(node, free: frozenset[str]) -> bool:
    """Does the subtree name anything in ``free`` (a name, or a table called)?"""
    return any((isinstance(n, ast.Name) and n.id in free)
               or (isinstance(n, ast.Call) and n.func.id in free) for n in ast.walk(node))


def _affine(node, free: frozenset[str]) -> bool:
    """:meth:`Expression.affine_in` of a subtree."""
    if isinstance(node, (ast.Constant, ast.Name)):
        return True
    if isinstance(node, ast.UnaryOp):
        return _affine(node.operand, free)
    if isinstance(node, ast.Call):
        return not _uses(node.args[0], free)
    if isinstance(node, ast.BinOp):
        left, right = node.left, node.right
        if isinstance(node.op, (ast.Add, ast.Sub)):
            return _affine(left, free) and _affine(right, free)
        if isinstance(node.op, ast.Mult):
            return (_affine(left, free) and _affine(right, free)
                    and not (_uses(left, free) and _uses(right, free)))
        if isinstance(node.op, ast.Div):
            return _affine(left, free) and not _uses(right, free)
    return False


def parse(text: str, where: str = "model") -> Expression:
    """Parse a channel model; raises :class:`ExpressionError` naming ``where`` on bad syntax.

    Line breaks are spaces (a long model may span lines of a TOML multi-line string); a ``#``
    is refused (joined into one line, a comment would silently drop every term after it)."""
    if "#" in text:
        raise ExpressionError(f"{where}: {text!r} holds a '#': a model has no comments; put them in "
                              "TOML comments outside the model string")
    try:
        tree = ast.parse(" ".join(text.split()), mode="eval").body
    except SyntaxError as exc:
        raise ExpressionError(f"{where}: cannot parse {text!r}: {exc.msg}") from None
    names: set[str] = set()
    tables: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            if not isinstance(node.func, ast.Name) or len(node.args) != 1 or node.keywords:
                raise ExpressionError(f"{where}: in {text!r}, calls must be name(one argument)")
            if node.func.id not in _FUNCS:
                tables.add(node.func.id)
        elif isinstance(node, ast.Name):
            names.add(node.id)
        elif not isinstance(
            node,
            (ast.BinOp, ast.UnaryOp, ast.Constant, ast.Load, ast.Add, ast.Sub, ast.Mult, ast.Div,
             ast.USub, ast.UAdd),
        ):
            raise ExpressionError(
                f"{where}: {text!r} uses {type(node).__name__}; only numbers, names, + - * /, "
                "parentheses and table calls are allowed"
            )
    names -= tables | set(_FUNCS)
    return Expression(text=text, tree=tree, names=frozenset(names), tables=frozenset(tables))


class _Evaluator:
    def __init__(self, expr, signals, params, tables, state_signals, by_parameters=True):
        self.expr, self.signals, self.params = expr, signals, params
        self.tables, self.state_signals = tables, state_signals
        self.by_parameters = by_parameters

    def fail(self, msg: str):
        raise ExpressionError(f"model {self.expr.text!r}: {msg}")

    def visit(self, node) -> Dual:
        if isinstance(node, ast.Constant):
            if not isinstance(node.value, (int, float)):
                self.fail(f"constant {node.value!r} is not a number")
            return Dual(np.asarray(float(node.value)))
        if isinstance(node, ast.Name):
            n = node.id
            if n in self.signals:
                v = np.asarray(self.signals[n], dtype=float)
                if n in self.state_signals:
                    return Dual(v, dsignal={n: np.ones_like(v)})
                return Dual(v)
            if n in self.params:
                if not self.by_parameters:
                    return Dual(np.asarray(self.params[n], dtype=float))
                return Dual(np.asarray(self.params[n], dtype=float), dparam={n: np.asarray(1.0)})
            self.fail(f"unknown name {n!r}: neither a signal nor a parameter of this channel")
        if isinstance(node, ast.UnaryOp):
            a = self.visit(node.operand)
            return a.scaled(-1.0) if isinstance(node.op, ast.USub) else a
        if isinstance(node, ast.BinOp):
            a, b = self.visit(node.left), self.visit(node.right)
            if isinstance(node.op, ast.Add):
                return _add(a, b)
            if isinstance(node.op, ast.Sub):
                return _add(a, b, -1.0)
            if isinstance(node.op, ast.Mult):
                return _product(a, b)
            if isinstance(node.op, ast.Div):
                inv = Dual(1.0 / b.value)
                if _has_d(b):
                    inv = b.scaled(-1.0 / b.value**2)
                    inv.value = 1.0 / b.value
                return _product(a, inv)
        if isinstance(node, ast.Call):
            name = node.func.id
            arg = self.visit(node.args[0])
            if name in _FUNCS:
                f, df = _FUNCS[name]
                out = arg.scaled(df(arg.value)) if _has_d(arg) else Dual(arg.value)
                out.value = f(arg.value)
                return out
            if name not in self.tables:
                self.fail(f"unknown table {name!r}; declare it with its breakpoints")
            table, values = self.tables[name]
            x = np.asarray(arg.value, dtype=float)
            i, w, inside = table.locate(x)
            lo, hi = _node_values(values, i)
            val = (1.0 - w) * lo + w * hi
            slope = np.where(inside, (hi - lo) / np.diff(table.breakpoints)[i], 0.0)
            out = arg.scaled(slope) if _has_d(arg) else Dual(val)
            out.value = val
            if self.by_parameters:
                out.dtable.setdefault(name, []).extend([(i, 1.0 - w), (i + 1, w)])
            return out
        self.fail(f"unsupported element {ast.dump(node)}")

    def value(self, node) -> np.ndarray:
        """``visit(node).value`` without the derivatives; each operation as :meth:`visit` does it."""
        if isinstance(node, ast.Constant):
            if not isinstance(node.value, (int, float)):
                self.fail(f"constant {node.value!r} is not a number")
            return np.asarray(float(node.value))
        if isinstance(node, ast.Name):
            n = node.id
            if n in self.signals:
                return np.asarray(self.signals[n], dtype=float)
            if n in self.params:
                return np.asarray(self.params[n], dtype=float)
            self.fail(f"unknown name {n!r}: neither a signal nor a parameter of this channel")
        if isinstance(node, ast.UnaryOp):
            a = self.value(node.operand)
            return a * -1.0 if isinstance(node.op, ast.USub) else a
        if isinstance(node, ast.BinOp):
            a, b = self.value(node.left), self.value(node.right)
            if isinstance(node.op, ast.Add):
                return a + b
            if isinstance(node.op, ast.Sub):
                return a + -1.0 * b
            if isinstance(node.op, ast.Mult):
                return a * b
            if isinstance(node.op, ast.Div):
                return a * (1.0 / b)
        if isinstance(node, ast.Call):
            name = node.func.id
            arg = self.value(node.args[0])
            if name in _FUNCS:
                return _FUNCS[name][0](arg)
            if name not in self.tables:
                self.fail(f"unknown table {name!r}; declare it with its breakpoints")
            table, values = self.tables[name]
            i, w, _ = table.locate(np.asarray(arg, dtype=float))
            lo, hi = _node_values(values, i)
            return (1.0 - w) * lo + w * hi
        self.fail(f"unsupported element {ast.dump(node)}")


def _product(a: Dual, b: Dual) -> Dual:
    if not _has_d(a):
        out = b.scaled(a.value)
    elif not _has_d(b):
        out = a.scaled(b.value)
    else:
        out = _add(a.scaled(b.value), b.scaled(a.value))
    out.value = a.value * b.value
    return out


__all__ = ["Dual", "Expression", "ExpressionError", "Table", "parse"]
