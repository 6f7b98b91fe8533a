"""The truth projection's least squares from row blocks (campaigns/truth.py ``solve_blocks``)
against ``np.linalg.lstsq`` of the whole matrix: the same solution, the same live columns and the
same rank decision, blocks of every awkward shape included (no rows, no columns, fewer rows than
columns, rank-deficient inside a block, columns no block touches, an all-zero column)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from campaigns.truth import solve_blocks


def _dense(blocks, n_columns):
    """``(solution, live columns, condition number of the live columns)`` of the whole matrix."""
    rows = sum(A.shape[0] for _, A, _ in blocks)
    M = np.zeros((rows, n_columns))
    b = np.zeros(rows)
    r = 0
    for columns, A, bb in blocks:
        M[r:r + A.shape[0], columns] = A
        b[r:r + A.shape[0]] = bb
        r += A.shape[0]
    live = (M != 0.0).any(axis=0)
    x, _, rank, sv = np.linalg.lstsq(M[:, live], b, rcond=None)
    return x, live, (sv[0] / sv[rank - 1] if rank else 1.0)


def _check(blocks, n_columns):
    x, live = solve_blocks(blocks, n_columns)
    x_ref, live_ref, cond = _dense(blocks, n_columns)
    np.testing.assert_array_equal(live, live_ref)
    # two factorizations of the same least-squares problem differ by round-off, amplified by the
    # condition number of what the rank cut kept: eps x cond relative to the solution, 100x margin
    scale = max(1.0, float(np.abs(x_ref).max()) if x_ref.size else 1.0)
    tol = max(1e-10, 100.0 * np.finfo(float).eps * cond) * scale
    np.testing.assert_allclose(x, x_ref, rtol=0, atol=tol)


def test_awkward_blocks_give_the_whole_matrixs_solution():
    rng = np.random.default_rng(3)
    n = 9  # columns 7 and 8 touched by no block; column 6 only by zeros
    dup = rng.normal(size=(30, 1))
    blocks = [
        (np.array([0, 1, 2]), rng.normal(size=(40, 3)), rng.normal(size=40)),
        (np.array([], dtype=int), np.zeros((25, 0)), rng.normal(size=25)),  # no free column
        (np.array([3, 4]), np.zeros((0, 2)), np.zeros(0)),  # no rows
        (np.array([2, 3, 4, 5]), rng.normal(size=(2, 4)), rng.normal(size=2)),  # fewer rows
        (np.array([4, 5]), np.hstack([dup, 2.0 * dup]), rng.normal(size=30)),  # rank-deficient
        (np.array([0, 6]), np.hstack([rng.normal(size=(10, 1)), np.zeros((10, 1))]), rng.normal(size=10)),
    ]
    _check(blocks, n)
    x, live = solve_blocks(blocks, n)
    assert live.tolist() == [True] * 6 + [False] * 3


def test_no_block_and_no_column_are_an_empty_solution():
    x, live = solve_blocks([], 4)
    assert x.size == 0 and not live.any()
    x, live = solve_blocks([(np.array([], dtype=int), np.zeros((5, 0)), np.ones(5))], 2)
    assert x.size == 0 and not live.any()


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n_blocks=st.integers(1, 6), n_columns=st.integers(1, 8))
def test_random_blocks_give_the_whole_matrixs_solution(seed, n_blocks, n_columns):
    rng = np.random.default_rng(seed)
    blocks = []
    for _ in range(n_blocks):
        k = int(rng.integers(0, n_columns + 1))
        columns = np.sort(rng.choice(n_columns, size=k, replace=False))
        rows = int(rng.integers(0, 12))
        A = rng.normal(size=(rows, k)) * (rng.random((rows, k)) < 0.8)
        blocks.append((columns, A, rng.normal(size=rows)))
    _check(blocks, n_columns)


@pytest.mark.parametrize("delta", [2e-14, 2e-12])
def test_the_rank_cut_is_the_whole_matrixs(delta):
    """Two columns equal but for ``delta`` of noise: their singular-value ratio about delta / 2, on
    either side of the whole matrix's rank cut (eps x 200 rows = 4.4e-14); the stack of the two
    blocks' factors has 4 rows, whose own default cut (8.9e-16) would keep the first pair apart
    (a solution of about 1e14) where the whole matrix merges it."""
    rng = np.random.default_rng(5)
    a, noise = rng.normal(size=(200, 1)), rng.normal(size=(200, 1))
    A = np.hstack([a, a + delta * noise])
    b = rng.normal(size=200)
    blocks = [(np.array([0, 1]), A[:100], b[:100]), (np.array([0, 1]), A[100:], b[100:])]
    _check(blocks, 2)
    x, _ = solve_blocks(blocks, 2)
    assert (np.abs(x).max() < 10.0) == (delta < 1e-13), x  # merged: a minimum-norm, small solution


def test_factors_a_caller_has_give_the_same_solution():
    rng = np.random.default_rng(8)
    blocks = [(np.array([0, 2]), rng.normal(size=(30, 2)), rng.normal(size=30)),
              (np.array([1, 2]), rng.normal(size=(20, 2)), rng.normal(size=20))]
    plain = solve_blocks(blocks, 3)
    kept = solve_blocks(blocks, 3, [np.linalg.qr(blocks[0][1]), None])
    np.testing.assert_array_equal(plain[0], kept[0])
    np.testing.assert_array_equal(plain[1], kept[1])


def test_each_maneuvers_truth_is_read_once_per_cache(tiny_dataset, monkeypatch):
    """truths_of: one read per maneuver for every problem sharing a cache (a report's stages),
    the same frames as read directly; without a cache, a read each time."""
    import warnings

    import campaigns.truth as truth_module
    from estimator.io import load_truth, problem_from_dataset

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        problem = problem_from_dataset(tiny_dataset)
    reads = []

    def counted(p, mid):
        reads.append(mid)
        return load_truth(p, mid)

    monkeypatch.setattr(truth_module, "load_truth", counted)
    cache: dict = {}
    first = truth_module.truths_of(problem, cache)
    again = truth_module.truths_of(problem, cache)
    ids = [m.id for m in problem.maneuvers]
    assert reads == ids and list(first) == ids
    assert all(again[i] is first[i] for i in ids)
    for i in ids:
        pd.testing.assert_frame_equal(first[i], load_truth(problem, i))
    truth_module.truths_of(problem)
    assert reads == ids + ids
