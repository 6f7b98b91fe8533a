"""Channel-model expressions: values and exact derivatives against finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimator.core.expressions import ExpressionError, Table, parse

TABLE_BP = np.radians([-10.0, -2.0, 6.0, 14.0, 22.0])


def _setup(seed=0, n=40):
    rng = np.random.default_rng(seed)
    signals = {
        "alpha_s": rng.uniform(-0.25, 0.45, n),
        "beta_s": rng.uniform(-0.1, 0.1, n),
        "alpha_t": rng.uniform(-0.2, 0.4, n),
        "z": rng.uniform(-0.2, 0.4, n),
    }
    params = {"b_l": 0.01, "k_bu": 0.05, "b_n": -0.003}
    tables = {
        "f1": (Table("f1", TABLE_BP), rng.normal(0, 0.05, TABLE_BP.size) + TABLE_BP),
        "f2": (Table("f2", TABLE_BP), rng.normal(0.3, 0.1, TABLE_BP.size)),
    }
    return signals, params, tables


MODELS = [
    "f1(alpha_s) + f2(alpha_t) * beta_s + b_l",
    "alpha_s + f1(z) + b_l",
    "f2(alpha_t) * (beta_s + b_n)",
    "beta_s + k_bu * beta_s + b_l",
    "(alpha_s - b_l) / (1 + k_bu) + sin(beta_s) * f2(alpha_s)",
    "-f1(alpha_s * 2) / 2",
]


@pytest.mark.parametrize("text", MODELS)
def test_by_the_state_signals_alone_is_the_same_arithmetic(text):
    # the implicit models' Newton iterations need d/dzhat alone: the value and the signals'
    # derivatives must be those of the full evaluation to the last bit
    signals, params, tables = _setup(seed=3)
    expr = parse(text)
    state = {"alpha_s", "beta_s", "alpha_t", "z"} & expr.names
    full = expr.evaluate(signals, params, tables, state)
    alone = expr.evaluate(signals, params, tables, state, by_parameters=False)
    assert np.array_equal(alone.value, full.value)
    assert not alone.dparam and not alone.dtable
    assert alone.dsignal.keys() == full.dsignal.keys() == state
    for name in state:
        assert np.array_equal(np.broadcast_to(alone.dsignal[name], full.value.shape),
                              np.broadcast_to(full.dsignal[name], full.value.shape)), name


@pytest.mark.parametrize("text", MODELS)
def test_derivatives_match_finite_differences(text):
    signals, params, tables = _setup()
    expr = parse(text)
    state = {"alpha_s", "beta_s", "alpha_t"} & expr.names
    d = expr.evaluate(signals, params, tables, state)
    h = 1e-7
    for name in params:
        if name not in expr.names:
            continue
        p2 = dict(params, **{name: params[name] + h})
        fd = (expr.evaluate(signals, p2, tables).value - d.value) / h
        assert np.allclose(np.broadcast_to(d.dparam[name], fd.shape), fd, atol=1e-6), name
    for name in state:
        s2 = dict(signals, **{name: signals[name] + h})
        fd = (expr.evaluate(s2, params, tables).value - d.value) / h
        # a table's slope jumps at breakpoints: FD across a breakpoint is not a derivative
        assert np.mean(np.isclose(d.dsignal[name], fd, atol=1e-5)) > 0.9, name
    for tname in expr.tables:
        table, values = tables[tname]
        for j in range(values.size):
            v2 = values.copy()
            v2[j] += h
            fd = (expr.evaluate(signals, params, dict(tables, **{tname: (table, v2)})).value - d.value) / h
            an = np.zeros_like(d.value)
            for idx, coef in d.dtable[tname]:
                an = an + np.where(idx == j, coef, 0.0)
            assert np.allclose(an, fd, atol=1e-6), (tname, j)


@settings(max_examples=30, deadline=None)
@given(x=st.floats(-0.5, 0.6), shift=st.floats(-0.2, 0.2))
def test_table_interpolates_and_holds_ends(x, shift):
    t = Table("f", TABLE_BP)
    values = TABLE_BP + shift
    y = t.evaluate(values, np.array([x]))[0]
    # an identity-plus-constant table reproduces x + shift inside, and holds the end values outside
    expected = np.clip(x, TABLE_BP[0], TABLE_BP[-1]) + shift
    assert y == pytest.approx(expected, abs=1e-12)


@pytest.mark.parametrize("text, message", [
    ("f1(alpha_s", "cannot parse"),
    ("alpha_s ** 2", "only numbers"),
    ("f1(alpha_s, beta_s)", "one argument"),
    ("lambda x: x", "only numbers"),
])
def test_bad_models_are_rejected(text, message):
    with pytest.raises(ExpressionError, match=message):
        parse(text, where="channel alpha_zl")


def test_unknown_name_is_named():
    signals, params, tables = _setup()
    with pytest.raises(ExpressionError, match="b_r"):
        parse("alpha_s + b_r").evaluate(signals, params, tables)


@pytest.mark.parametrize(("text", "free", "affine"), [
    ("f1(alpha_s) + f2(alpha_t) * beta_s + b_l", {"f1", "f2", "b_l"}, True),
    ("alpha_s + k_ba * alpha_s + b_ba", {"k_ba", "b_ba"}, True),
    ("f5(alpha_t) * (beta_s + b_n)", {"f5", "b_n"}, False),  # bilinear: b_n's column is f5's value
    ("f5(alpha_t) * (beta_s + b_n)", {"f5"}, True),  # b_n held: linear in the table
    ("f5(alpha_t) * (beta_s + b_n)", {"b_n"}, True),
    ("(b1 - b2) * (c1 - c2) * alpha_s + b1", {"b1", "b2", "c1", "c2"}, False),
    ("f(alpha_s + b)", {"b"}, False),  # a parameter inside a table's argument: a kink moves
    ("f(alpha_s + b)", {"f"}, True),
    ("z / k + b", {"b"}, True),
    ("z / k + b", {"k"}, False),
    ("(z + b) / 2", {"b"}, True),
    ("-sin(alpha_s) * k", {"k"}, True),
    ("sin(alpha_s * k)", {"k"}, False),
])
def test_affinity_is_read_off_the_tree(text, free, affine):
    assert parse(text).affine_in(free) is affine


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_an_affine_models_derivatives_do_not_move_with_its_parameters(seed):
    """What affine_in promises, to the bit: the derivatives at two random points are the same."""
    rng = np.random.default_rng(seed)
    expr = parse("f1(alpha_s) + f2(alpha_t) * beta_s + k * alpha_s + b")
    tab = Table("f", np.linspace(-0.2, 0.4, 6))
    sig = {n: rng.uniform(-0.3, 0.5, 50) for n in ("alpha_s", "alpha_t", "beta_s")}
    assert expr.affine_in({"f1", "f2", "k", "b"})
    duals = [expr.evaluate(sig, {"k": rng.normal(), "b": rng.normal()},
                           {n: (tab, rng.normal(size=6)) for n in ("f1", "f2")}) for _ in range(2)]
    for name in ("k", "b"):
        np.testing.assert_array_equal(np.broadcast_to(duals[0].dparam[name], 50),
                                      np.broadcast_to(duals[1].dparam[name], 50))
    for name in ("f1", "f2"):
        for (i0, c0), (i1, c1) in zip(duals[0].dtable[name], duals[1].dtable[name], strict=True):
            np.testing.assert_array_equal(i0, i1)
            np.testing.assert_array_equal(c0, c1)
