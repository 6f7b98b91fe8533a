"""The CPU time of a pool's workers reaches the process that made the pool, whatever the start
method: :func:`synth.workers.workers_cpu_s`. Under ``forkserver`` (the project's start method on
Linux) the workers are the fork server's children, so ``getrusage(RUSAGE_CHILDREN)`` misses them
and a study's header said "CPU 14 s" for 682 s of two busy cores.
"""

from __future__ import annotations

import multiprocessing
import time

import pytest

from synth import workers
from synth.workers import worker_pool, workers_cpu_s

#: CPU seconds each task burns
BUSY_S = 0.5
METHODS = [m for m in ("forkserver", "fork", "spawn") if m in multiprocessing.get_all_start_methods()]


def _busy(seconds: float, fail: bool = False) -> float:
    """A pool task: burn ``seconds`` of this process's CPU; returns the CPU it measured, s (or
    raises with it, ``fail``)."""
    t0 = time.process_time()
    x = 0
    while time.process_time() - t0 < seconds:
        x += 1
    used = time.process_time() - t0
    if fail:
        raise RuntimeError(repr(used))
    return used


@pytest.mark.parametrize("method", METHODS)
def test_the_workers_cpu_time_reaches_the_pools_process(monkeypatch, method):
    monkeypatch.setattr(workers, "pool_context", lambda: multiprocessing.get_context(method))
    before = workers_cpu_s()
    with worker_pool(2) as pool:
        futures = [pool.submit(_busy, BUSY_S), pool.submit(_busy, BUSY_S, fail=True)]
        used = futures[0].result()
        with pytest.raises(RuntimeError) as failed:  # a failed task's CPU counts too
            futures[1].result()
        used += float(failed.value.args[0])
        # each task's CPU is counted when it ends, before the pool closes
        assert workers_cpu_s() - before >= used
    # the busy loops' CPU, measured in the workers, is the lower bound (startup comes on top)
    assert used >= 2 * BUSY_S
    assert workers_cpu_s() - before >= used

