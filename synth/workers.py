"""Worker processes that end with their parent, whatever ends it.

A ``ProcessPoolExecutor`` worker outlives a parent killed by SIGTERM or SIGKILL: nothing tells it
the parent is gone, and it goes on flying maneuvers (about 140 MB each) for minutes. Pass
:func:`bind_to_parent` as the pool's initializer (or call it first in your own initializer)::

    ProcessPoolExecutor(initializer=bind_to_parent, initargs=(os.getpid(),))

Two mechanisms, because neither alone is enough:

- Linux: ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` — the kernel kills the worker the moment its parent
  dies (any cause). It fires when the parent's *thread* that forked the worker ends, which for a
  pool is the thread that submitted work: in this project always the main thread.
- Everywhere: a daemon thread that checks every ``poll_s`` whether the parent is still the one
  the worker was started by (``os.getppid()`` changes when the parent dies: the worker is
  re-parented to init or a subreaper) and ends the worker with ``os._exit``.

Ctrl-C needs neither: the terminal sends SIGINT to the whole foreground process group. A pool
that wants a clean stop (no traceback from every worker) ignores SIGINT in its workers and ends
them from the parent, as :func:`synth.campaign.fly_campaign` does; the public helpers for that::

    pool = ProcessPoolExecutor(max_workers=n, mp_context=pool_context(),
                               initializer=init_pool_worker, initargs=(os.getpid(),))
    try:
        ...                       # submit, wait, write the results
    except BaseException:         # KeyboardInterrupt (Ctrl-C), or an error writing a result
        stop_pool(pool)
        raise
    pool.shutdown(wait=True)

A worker ended by :func:`stop_pool` receives SIGTERM first (a handler set in the initializer may
clean up, e.g. remove scratch files, and exit), SIGKILL only if it has not ended after a timeout.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import multiprocessing
import os
import signal
import sys
import threading
from concurrent.futures import ProcessPoolExecutor

_PR_SET_PDEATHSIG = 1

#: exit status of a worker that ended because its parent was gone (128 + SIGKILL, as a shell says)
ORPHAN_EXIT_STATUS = 137


def bind_to_parent(parent_pid: int, poll_s: float = 1.0) -> None:
    """End this (worker) process when the process ``parent_pid`` ends.

    Parameters
    ----------
    parent_pid : the parent's process id, taken in the parent (``os.getpid()``) when the pool is
        created — not ``os.getppid()`` in the worker, which may already be init.
    poll_s : how often the watcher thread checks, s.
    """
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):  # no libc/prctl (e.g. musl without it): the thread remains
            pass
    if os.getppid() != parent_pid:  # the parent died before the line above took effect
        os._exit(ORPHAN_EXIT_STATUS)

    def _watch() -> None:
        while not _stop.wait(poll_s):
            if os.getppid() != parent_pid:
                os._exit(ORPHAN_EXIT_STATUS)

    _stop = threading.Event()
    threading.Thread(target=_watch, name="fpr-parent-watch", daemon=True).start()


def pool_context():
    """The multiprocessing context for a pool of :func:`bind_to_parent` workers: ``fork`` on Linux,
    so that the workers are children of the process that creates the pool (under a forkserver, the
    default from Python 3.14, the server would be their parent); None (the default) elsewhere."""
    return multiprocessing.get_context("fork") if sys.platform.startswith("linux") else None


def init_pool_worker(parent_pid: int) -> None:
    """A pool initializer: :func:`bind_to_parent`, SIGTERM at its default (end the worker), and SIGINT
    ignored — the terminal sends Ctrl-C to
    the whole process group, and the parent alone handles it (with :func:`stop_pool`), so no worker
    prints a traceback of its own.

    Parameters
    ----------
    parent_pid : ``os.getpid()`` of the process creating the pool, taken there.
    """
    bind_to_parent(parent_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # a forked worker inherits the parent's handlers: the CLI's SIGTERM handler would turn
    # stop_pool's SIGTERM into an exception inside the task instead of ending the worker
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


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
        pool.shutdown(wait=False, cancel_futures=True)
        for proc in procs:
            if proc.is_alive():
                proc.terminate()
        for proc in procs:
            proc.join(timeout=timeout_s)
            if proc.is_alive():
                proc.kill()
                proc.join(timeout=timeout_s)
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
