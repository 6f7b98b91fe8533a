"""Worker processes that end with their parent, whatever ends it.

A ``ProcessPoolExecutor`` worker outlives a parent killed by SIGTERM or SIGKILL: nothing tells it
the parent is gone, and it goes on flying maneuvers (about 140 MB each) for minutes. A pool made
by :func:`worker_pool` ties each worker's life to the process that made the pool, leaves Ctrl-C to
that process and, on any exception (Ctrl-C included), ends the workers at once::

    with worker_pool(n, initializer=my_init, initargs=(...)) as pool:
        for fut in as_completed([pool.submit(task, x) for x in xs]):
            ...                   # write the results

The pieces, for a pool built by hand: :func:`pool_context` (the start method),
:func:`init_pool_worker` (the initializer, or the first call of your own) and :func:`stop_pool`::

    pool = ProcessPoolExecutor(max_workers=n, mp_context=pool_context(),
                               initializer=init_pool_worker, initargs=(os.getpid(),))
    try:
        ...                       # submit, wait, write the results
    except BaseException:         # KeyboardInterrupt (Ctrl-C), or an error writing a result
        stop_pool(pool)
        raise
    pool.shutdown(wait=True)

:func:`bind_to_parent` (called by :func:`init_pool_worker`) watches the process that made the pool
— its id given by that process, ``os.getpid()`` — whatever the start method: under ``fork`` and
``spawn`` it is the worker's parent, under ``forkserver`` (Python 3.14's default on Linux) the
server is. Two mechanisms:

- Linux, when the pool's process is the worker's parent: ``prctl(PR_SET_PDEATHSIG, SIGKILL)``,
  the kernel kills the worker the moment its parent dies (any cause). It fires when the parent's
  *thread* that started the worker ends, which for a pool is the thread that submitted work: in
  this project always the main thread.
- Everywhere: a daemon thread that checks every ``poll_s`` that the pool's process still exists
  and is the same process (on Linux its start time, read at bind time, tells a reused process id
  apart, and a zombie counts as ended), and ends the worker with ``os._exit`` otherwise.

Ctrl-C needs neither: the terminal sends SIGINT to the whole foreground process group. The workers
ignore it (:func:`init_pool_worker`, so that no worker prints a traceback of its own) and the
process that made the pool stops them (:func:`stop_pool`): SIGTERM first (a handler set in the
initializer may clean up, e.g. remove scratch files, and exit), SIGKILL only if a worker has not
ended after a timeout.

CPU time and memory: under ``forkserver`` the workers are the fork server's children, not this
process's, so ``getrusage(RUSAGE_CHILDREN)`` never sees them. A :func:`worker_pool`'s workers add
their CPU time, and their peak resident memory, to counters shared with the pool's process after
every task and when they exit; :func:`workers_cpu_s` and :func:`workers_peak_rss_mib` read them,
whatever the start method.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from multiprocessing import util

try:
    import resource
except ImportError:  # not POSIX (Windows): no peak memory to report
    resource = None

_PR_SET_PDEATHSIG = 1

#: exit status of a worker that ended because its parent was gone (128 + SIGKILL, as a shell says)
ORPHAN_EXIT_STATUS = 137


def _proc_stat(pid: int) -> list[str] | None:
    """Fields 3 on of ``/proc/PID/stat`` (state, ppid, ...; ``[19]`` is the start time in clock
    ticks since boot), None when there is no such process or no ``/proc``."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            text = fh.read().decode("ascii", "replace")
    except OSError:
        return None
    return text[text.rindex(")") + 2:].split()  # after the name, which may hold spaces and ")"


def _start_time(pid: int) -> int | None:
    """The start time of process ``pid`` (clock ticks since boot; Linux), None when unknown."""
    st = _proc_stat(pid)
    try:
        return int(st[19]) if st is not None else None
    except (IndexError, ValueError):
        return None


def _parent_gone(parent_pid: int, start: int | None, direct: bool) -> bool:
    """Whether the process ``parent_pid`` the worker was bound to has ended.

    ``start`` : its start time taken at bind time (Linux; None elsewhere): a process of that id
    started at another time is another process (the id was reused). ``direct`` : it was the
    worker's parent at bind time, so ``os.getppid()`` changing says it ended (the worker was
    re-parented), reuse-proof on any POSIX system.
    """
    if direct and os.getppid() != parent_pid:
        return True
    try:
        os.kill(parent_pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:  # the id now belongs to another user's process: ours has ended
        return True
    except OSError:  # no way to ask (not POSIX): rely on the other checks
        pass
    if start is not None:
        st = _proc_stat(parent_pid)
        # a zombie has ended (its own parent has not yet collected its status)
        if st is None or st[0] in ("Z", "X") or _start_time(parent_pid) != start:
            return True
    return False


def bind_to_parent(parent_pid: int, poll_s: float = 1.0) -> None:
    """End this (worker) process when the process ``parent_pid`` ends, whatever the start method.

    Parameters
    ----------
    parent_pid : the id of the process that makes the pool, taken there (``os.getpid()``) — not
        ``os.getppid()`` in the worker, which is the fork server under ``forkserver``, or already
        init if that process has died.
    poll_s : how often the watcher thread checks, s.
    """
    direct = os.getppid() == parent_pid
    if direct and sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):  # no libc/prctl (e.g. musl without it): the thread remains
            pass
    start = _start_time(parent_pid)
    mine = _start_time(os.getpid())
    # the process that made the pool started before this worker: a later start time means the id
    # was already reused by another process when we looked (the pool's process had ended)
    if start is not None and mine is not None and start > mine:
        os._exit(ORPHAN_EXIT_STATUS)
    if _parent_gone(parent_pid, start, direct):  # it ended before the lines above took effect
        os._exit(ORPHAN_EXIT_STATUS)

    def _watch() -> None:
        while not _stop.wait(poll_s):
            if _parent_gone(parent_pid, start, direct):
                os._exit(ORPHAN_EXIT_STATUS)

    _stop = threading.Event()
    threading.Thread(target=_watch, name="fpr-parent-watch", daemon=True).start()


def pool_context():
    """The multiprocessing context of the project's pools: ``forkserver`` on Linux (the default
    from Python 3.14 on, taken on every version: a worker forked from a fresh server, not from a
    parent running pyarrow's and BLAS's threads, which ``fork`` copies in whatever state they
    are — Python 3.12 and later warn of it); the platform's default (None) elsewhere. The pool's
    tasks and initializer must be importable functions (they are pickled to the workers)."""
    if sys.platform.startswith("linux") and "forkserver" in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("forkserver")
    return None


def init_pool_worker(parent_pid: int) -> None:
    """A pool initializer: :func:`bind_to_parent`, SIGTERM at its default (end the worker), and
    SIGINT ignored — the terminal sends Ctrl-C to the whole process group, and the pool's process
    alone handles it (with :func:`stop_pool`), so no worker prints a traceback of its own.

    Parameters
    ----------
    parent_pid : ``os.getpid()`` of the process creating the pool, taken there.
    """
    bind_to_parent(parent_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # a forked worker inherits the parent's handlers: the CLI's SIGTERM handler would turn
    # stop_pool's SIGTERM into an exception inside the task instead of ending the worker
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


# ------------------------------------------------------------------ CPU time and memory of the workers

#: in a worker: the pool's shared counters (a synchronized ``Array('d', 2)``: CPU seconds, and the
#: largest peak resident memory of its workers in KiB), and the part of this worker's CPU time
#: already added to them
_worker_counters = None
_worker_cpu_reported_s = 0.0

#: the counters' places in the shared array
_CPU_S, _PEAK_RSS_KIB = 0, 1

#: in the process that makes pools: CPU seconds and the largest peak RSS (KiB) of the workers of
#: its finished pools (and the CPU of those whose workers were not its children: forkserver), and
#: the counters of the pools still open
_pools_cpu_done_s = 0.0
_pools_cpu_done_not_children_s = 0.0
_pools_peak_rss_done_kib = 0.0
_pools_open: list = []
_pools_lock = threading.Lock()


#: how long a process waits for a pool's counters, s: a worker killed while adding to them leaves
#: their lock taken, and a lost count is better than a hang
_COUNTERS_LOCK_TIMEOUT_S = 2.0


def _own_cpu_s() -> float:
    """This process's CPU time (every thread) and its ended, collected children's, s."""
    t = os.times()
    return time.process_time() + t.children_user + t.children_system


def peak_rss_mib() -> float:
    """This process's peak resident memory so far, MiB (0 where the platform cannot say)."""
    if resource is None:
        return 0.0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    # ru_maxrss is bytes on macOS, KiB on Linux and the other BSDs
    return peak / (1024.0 * 1024.0 if sys.platform == "darwin" else 1024.0)


def _report_worker() -> None:
    """In a worker: add the CPU time spent since the last report (the initializer's, then each
    task's) to the pool's counter, and raise its peak memory to this worker's if larger."""
    global _worker_cpu_reported_s
    if _worker_counters is None:
        return
    now = _own_cpu_s()
    peak_kib = peak_rss_mib() * 1024.0
    lock = _worker_counters.get_lock()
    if lock.acquire(timeout=_COUNTERS_LOCK_TIMEOUT_S):
        try:
            counters = _worker_counters.get_obj()
            counters[_CPU_S] += now - _worker_cpu_reported_s
            counters[_PEAK_RSS_KIB] = max(counters[_PEAK_RSS_KIB], peak_kib)
        finally:
            lock.release()
        _worker_cpu_reported_s = now


def _read_counters(counters) -> tuple[float, float]:
    """A pool's counters: its workers' CPU s and largest peak RSS KiB (read without their lock if
    a killed worker left the lock taken)."""
    lock = counters.get_lock()
    if not lock.acquire(timeout=_COUNTERS_LOCK_TIMEOUT_S):
        return counters[_CPU_S], counters[_PEAK_RSS_KIB]
    try:
        return counters[_CPU_S], counters[_PEAK_RSS_KIB]
    finally:
        lock.release()


def _run_counted(fn: Callable[..., object], /, *args, **kwargs) -> object:
    """In a worker: ``fn(*args, **kwargs)``, then its CPU time and the worker's peak memory to the
    pool's counters (a task's is counted as soon as it ends, even if the worker is killed later)."""
    try:
        return fn(*args, **kwargs)
    finally:
        _report_worker()


def _init_bound(parent_pid: int, counters, initializer: Callable[..., object] | None,
                initargs: tuple) -> None:
    """:func:`worker_pool`'s initializer: :func:`init_pool_worker`, the counters (the rest of the
    worker's CPU time and memory, since its last task, is added when it exits normally), then the
    caller's own initializer."""
    global _worker_counters, _worker_cpu_reported_s
    init_pool_worker(parent_pid)
    # the worker's clock starts at 0 (fork resets it; spawn starts a new process): its start counts
    _worker_counters, _worker_cpu_reported_s = counters, 0.0
    util.Finalize(None, _report_worker, exitpriority=0)
    if initializer is not None:
        initializer(*initargs)


def workers_cpu_s(not_in_children: bool = False) -> float:
    """CPU seconds of every :func:`worker_pool` worker this process has made so far, whatever the
    start method: each worker adds its time after every task and when it exits normally.

    ``not_in_children=True``: only what ``getrusage(RUSAGE_CHILDREN)`` does not already hold — the
    workers of finished ``forkserver`` pools (the fork server's children, not ours) and of pools
    still open (not yet reaped); a finished ``fork``/``spawn`` pool's workers were this process's
    children, reaped at its shutdown, and are in ``RUSAGE_CHILDREN``. Add it to that to count each
    worker once.

    Not counted: a worker's time since its last task when it was killed (:func:`stop_pool`, an
    out-of-memory kill), the fork server's own (its start, once per process), and pools built by
    hand rather than by :func:`worker_pool`.
    """
    with _pools_lock:
        done = _pools_cpu_done_not_children_s if not_in_children else _pools_cpu_done_s
        return done + sum(_read_counters(c)[_CPU_S] for c in _pools_open)


def workers_peak_rss_mib() -> float:
    """The largest peak resident memory of any :func:`worker_pool` worker this process has made
    so far, MiB, whatever the start method (0 before the first task ends): each worker reports
    its own peak (``getrusage(RUSAGE_SELF).ru_maxrss``) after every task and when it exits
    normally. Under ``forkserver`` ``getrusage(RUSAGE_CHILDREN)`` never sees the workers.

    Not counted: a worker's growth since its last task when it was killed (:func:`stop_pool`, an
    out-of-memory kill), the fork server, and pools built by hand rather than by
    :func:`worker_pool`. Under ``fork`` a worker's peak includes the pages it shares with this
    process at the fork.
    """
    with _pools_lock:
        peaks_kib = [_read_counters(c)[_PEAK_RSS_KIB] for c in _pools_open]
        return max([_pools_peak_rss_done_kib, *peaks_kib]) / 1024.0


class _CountingPool(ProcessPoolExecutor):
    """A ``ProcessPoolExecutor`` whose tasks add their CPU time and peak memory to the pool's
    counters (:func:`_run_counted`); ``map`` goes through ``submit`` too."""

    def submit(self, fn: Callable[..., object], /, *args, **kwargs) -> Future:
        return super().submit(_run_counted, fn, *args, **kwargs)


@contextlib.contextmanager
def worker_pool(max_workers: int, initializer: Callable[..., object] | None = None,
                initargs: Sequence = ()) -> Iterator[ProcessPoolExecutor]:
    """A process pool whose workers end with this process and leave Ctrl-C to it.

    Its context is :func:`pool_context`; each worker runs :func:`init_pool_worker` and then
    ``initializer(*initargs)`` (an importable function: it is pickled to the worker). On leaving
    the block normally the pool is shut down after its tasks; on any exception (Ctrl-C, an error
    writing a result) it is stopped at once (:func:`stop_pool`) and the exception goes on. The
    workers' CPU time counts in :func:`workers_cpu_s`, their peak memory in
    :func:`workers_peak_rss_mib`.

    Parameters
    ----------
    max_workers : worker processes.
    initializer, initargs : a per-worker initializer of the caller's, and its arguments.
    """
    global _pools_cpu_done_s, _pools_cpu_done_not_children_s, _pools_peak_rss_done_kib
    ctx = pool_context() or multiprocessing.get_context()
    # fork/spawn workers are this process's children, reaped at shutdown (RUSAGE_CHILDREN has them)
    not_children = ctx.get_start_method() == "forkserver"
    counters = ctx.Array("d", 2)  # zeros: _CPU_S, _PEAK_RSS_KIB
    with _pools_lock:
        _pools_open.append(counters)
    try:
        pool = _CountingPool(max_workers=max_workers, mp_context=ctx, initializer=_init_bound,
                             initargs=(os.getpid(), counters, initializer, tuple(initargs)))
        try:
            yield pool
        except BaseException:
            stop_pool(pool)
            raise
        pool.shutdown(wait=True)  # joins the workers: their exit reports are in
    finally:
        with _pools_lock:
            _pools_open.remove(counters)
            cpu_s, peak_kib = _read_counters(counters)
            _pools_cpu_done_s += cpu_s
            if not_children:
                _pools_cpu_done_not_children_s += cpu_s
            _pools_peak_rss_done_kib = max(_pools_peak_rss_done_kib, peak_kib)


def stop_pool(pool: ProcessPoolExecutor, timeout_s: float = 5.0) -> None:
    """Stop a pool now: cancel the tasks that have not started and end the running workers
    (SIGTERM, then SIGKILL for a worker still running after ``timeout_s``). Results of the tasks
    they were running are lost.

    A second Ctrl-C while the workers are being stopped is ignored (in the main thread): the stop
    completes, and the interrupt that led here goes on.
    """
    try:
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread: signals are the main thread's
        previous = None
    try:
        # the pool's own process table: the public API has no way to end running tasks
        procs = list((getattr(pool, "_processes", None) or {}).values())
        manager = getattr(pool, "_executor_manager_thread", None)  # shutdown forgets it
        pool.shutdown(wait=False, cancel_futures=True)
        for proc in procs:
            if proc.is_alive():
                proc.terminate()
        for proc in procs:
            proc.join(timeout=timeout_s)
            if proc.is_alive():
                proc.kill()
                proc.join(timeout=timeout_s)
        # The pool's manager thread closes its wake-up pipe as it ends. Left running, it races
        # concurrent.futures' exit hook, which writes to that pipe unlocked (CPython 3.11:
        # "OSError: Bad file descriptor" printed at exit after Ctrl-C). Its workers are gone, so
        # it ends at once: wait for it here.
        if manager is not None and manager.is_alive():
            manager.join(timeout=timeout_s)
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
