"""The CPU time and peak memory of a pool's workers reach the process that made the pool,
whatever the start method: :func:`synth.workers.workers_cpu_s`,
:func:`synth.workers.workers_peak_rss_mib`. Under ``forkserver`` (the project's start method on
Linux) the workers are the fork server's children, so ``getrusage(RUSAGE_CHILDREN)`` misses them:
a study's header said "CPU 14 s" for 682 s of two busy cores, and the fly benchmark's "largest
worker" peak memory would have been the fork server's.
"""

from __future__ import annotations

import multiprocessing
import os
import time

import pytest

from synth import workers
from synth.workers import peak_rss_mib, worker_pool, workers_cpu_s, workers_peak_rss_mib

#: CPU seconds each task burns: a count that misses the workers falls short by at least twice this
BUSY_S = 0.1
#: ... in the test that a count takes each worker once: twice would overshoot by the workers' CPU,
#: at least 2 x ONCE_BUSY_S, which must stand well clear of that test's tolerance (0.25 s and 10 %)
ONCE_BUSY_S = 0.25
METHODS = [m for m in ("forkserver", "fork", "spawn") if m in multiprocessing.get_all_start_methods()]
#: MiB a task allocates and touches
ALLOC_MIB = 200
#: MiB a worker's peak may grow between a task measuring it and the worker reporting it
REPORT_SLACK_MIB = 8


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


def _rss_now_mib() -> float | None:
    """This process's resident memory now, MiB (Linux's ``/proc``; None elsewhere)."""
    try:
        with open("/proc/self/statm") as fh:
            pages = int(fh.read().split()[1])
    except OSError:
        return None
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def _allocate(mib: int) -> float:
    """A pool task: allocate ``mib`` MiB and touch every page (``numpy.ones`` writes them); returns
    this worker's peak resident memory after it, MiB."""
    import numpy as np

    now_mib = _rss_now_mib()
    block = np.ones(mib * 1024 * 1024 // 8)
    after_mib = peak_rss_mib()
    # the pages were touched, not merely reserved: the peak rose above the memory in use before
    # by (nearly) all of them (the peak before may already stand higher, e.g. from imports; the
    # kernel's counters lag by a few pages)
    assert now_mib is None or after_mib - now_mib >= 0.95 * mib - 1.0, (now_mib, after_mib)
    del block
    return after_mib


@pytest.mark.slow
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


@pytest.mark.parametrize("method", METHODS)
def test_the_workers_peak_memory_reaches_the_pools_process(monkeypatch, method):
    monkeypatch.setattr(workers, "pool_context", lambda: multiprocessing.get_context(method))
    # this test's workers alone: not an earlier test's pools
    monkeypatch.setattr(workers, "_pools_peak_rss_done_kib", 0.0)
    assert workers_peak_rss_mib() == 0.0
    with worker_pool(2) as pool:
        peaks_mib = [f.result() for f in [pool.submit(_allocate, ALLOC_MIB), pool.submit(_allocate, 0)]]
        # each task's peak is reported as soon as it ends, before the pool closes; the largest
        # worker's, not a sum over workers
        assert max(peaks_mib) >= ALLOC_MIB
        assert max(peaks_mib) <= workers_peak_rss_mib() <= max(peaks_mib) + REPORT_SLACK_MIB
    # the workers' exit reports keep the largest
    assert workers_peak_rss_mib() >= max(peaks_mib)


def test_a_studys_record_counts_its_pool_workers(tmp_path):
    """The CPU time a study's header states includes its pool's workers; an older record, which
    missed them, says "at least"."""
    from campaigns.studies import invocations
    from campaigns.studies.invocations import CPU_KEY, Invocation, invocations_text

    start = workers_cpu_s()
    own = time.process_time()  # this process's CPU so far: part of the record too
    invocation = Invocation(invocations.__file__)
    with worker_pool(2) as pool:
        used = sum(f.result() for f in [pool.submit(_busy, BUSY_S), pool.submit(_busy, BUSY_S)])
    assert workers_cpu_s() - start >= used >= 2 * BUSY_S
    records = invocation.finish(tmp_path / "log.json", "a command", 2)
    assert records[-1][CPU_KEY] and records[-1]["cpu_s"] >= own + used
    old = {**records[-1], "cpu_s": 14.0}
    del old[CPU_KEY]
    lines = invocations_text([old, records[-1]])
    assert lines[0].startswith("this invocation: wall ")
    now_s = records[-1]["cpu_s"]
    assert f"CPU {now_s:.0f} s in its processes and their pool workers, 2 replications" in lines[0]
    assert f"CPU at least {14 + now_s:.0f} s, 4 replications in all:" in lines[1]
    assert ", CPU at least 14 s, code " in lines[2] and f", CPU {now_s:.0f} s, code " in lines[3]


@pytest.mark.slow
@pytest.mark.parametrize("method", METHODS)
def test_children_and_workers_together_count_each_worker_once(method, monkeypatch):
    # A study adds RUSAGE_CHILDREN and workers_cpu_s(not_in_children=True): under fork/spawn the
    # workers are this process's children (in RUSAGE_CHILDREN once reaped), under forkserver not;
    # either way their CPU must be counted once, not twice (nor not at all).
    import resource

    monkeypatch.setattr(workers, "pool_context", lambda: multiprocessing.get_context(method))

    def total() -> float:
        ch = resource.getrusage(resource.RUSAGE_CHILDREN)
        return ch.ru_utime + ch.ru_stime + workers_cpu_s(not_in_children=True)

    before, all_before = total(), workers_cpu_s()
    with worker_pool(2) as pool:
        measured = sum(pool.map(_busy, [ONCE_BUSY_S, ONCE_BUSY_S]))
    counted = total() - before
    workers_s = workers_cpu_s() - all_before  # every worker's own report, start-up included
    assert measured <= counted + 0.05, f"{method}: counted {counted:.2f} s < the tasks' {measured:.2f} s"
    # once: what RUSAGE_CHILDREN adds for reaped workers is what they reported themselves (their
    # exit after the last report costs little); twice would be ~2 x workers_s
    assert abs(counted - workers_s) < 0.1 * workers_s + 0.25, (
        f"{method}: counted {counted:.2f} s, the workers reported {workers_s:.2f} s")
