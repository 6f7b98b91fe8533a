"""Pool workers end with the process that made the pool, whatever the start method and however
that process ends (issue 11): :mod:`synth.workers`."""

from __future__ import annotations

import multiprocessing
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from _processes import HAVE_PROC, descendants, left_after, proc_stat, reap

from synth import workers
from synth.workers import worker_pool

HERE = Path(__file__).resolve().parent  # this file's folder: a child process imports test_workers
TESTS = HERE.parent  # tests/: the helpers (_processes)
ROOT = TESTS.parent

linux_only = pytest.mark.skipif(not HAVE_PROC, reason="reads /proc")


def _hold(directory: str) -> None:
    """A pool task: say which worker runs it (a file named by its pid), then stay busy."""
    Path(directory, str(os.getpid())).touch()
    time.sleep(120)


_PARENT = """\
import os, sys, time
sys.path[:0] = [{here!r}, {tests!r}]
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from synth.workers import init_pool_worker
from test_workers import _hold

if __name__ == "__main__":
    pool = ProcessPoolExecutor(2, mp_context=multiprocessing.get_context({method!r}),
                               initializer=init_pool_worker, initargs=(os.getpid(),))
    for _ in range(2):
        pool.submit(_hold, {held!r})
    time.sleep(120)
"""


@linux_only
@pytest.mark.parametrize("method", [m for m in ("fork", "spawn", "forkserver")
                                    if m in multiprocessing.get_all_start_methods()])
@pytest.mark.slow
def test_workers_end_within_5_s_of_a_sigkill_of_the_pools_process(tmp_path, short_tmp, method):
    held = tmp_path / "held"
    held.mkdir()
    script = tmp_path / "parent.py"
    script.write_text(_PARENT.format(here=str(HERE), tests=str(TESTS), method=method, held=str(held)))
    # TMPDIR: multiprocessing's own folder (the fork server's socket), which a killed parent leaves
    proc = subprocess.Popen([sys.executable, str(script)], cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, start_new_session=True,
                            env=dict(os.environ, TMPDIR=str(short_tmp)))
    below: list[tuple[int, str]] = []
    try:
        deadline = time.monotonic() + 60.0
        while len(list(held.iterdir())) < 2:  # both workers bound and busy
            assert proc.poll() is None, proc.stderr.read().decode()
            assert time.monotonic() < deadline, "the workers did not start within 60 s"
            time.sleep(0.02)
        below = descendants(proc.pid)
        pids = {int(p.name) for p in held.iterdir()}
        assert pids <= {p for p, _ in below}, (pids, below)
        os.kill(proc.pid, signal.SIGKILL)  # the pool's process alone; nothing tells the workers
        proc.wait(timeout=10)
        # the workers, and under forkserver/spawn the server and resource tracker too
        assert not left_after(below, 5.0), f"{method}: processes outlived their parent by 5 s"
    finally:
        reap(proc, below)
        proc.stderr.close()


@linux_only
def test_a_reused_pid_or_a_zombie_is_not_the_pools_process():
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        start = workers._start_time(child.pid)
        assert start is not None
        assert not workers._parent_gone(child.pid, start, direct=False)
        # the same id started at another time is another process
        assert workers._parent_gone(child.pid, start + 1, direct=False)
        child.kill()
        deadline = time.monotonic() + 10.0
        while proc_stat(child.pid)[0] != "Z":  # killed, its status not collected yet: a zombie
            assert time.monotonic() < deadline
            time.sleep(0.01)
        assert workers._parent_gone(child.pid, start, direct=False)
    finally:
        child.kill()
        child.wait()
    assert workers._parent_gone(child.pid, start, direct=False)


def _fail_on(x: int) -> int:
    if x == 1:
        raise ValueError("task 1 failed")
    return x


def test_worker_pool_runs_tasks_and_stops_its_workers_on_an_exception():
    with worker_pool(2) as pool:
        assert list(pool.map(_fail_on, [0, 2, 3])) == [0, 2, 3]
    with pytest.raises(ValueError, match="task 1 failed"):
        with worker_pool(2) as pool:
            futures = [pool.submit(_fail_on, x) for x in range(3)]
            procs = list(pool._processes.values())
            for f in futures:
                f.result()
    for p in procs:
        assert not p.is_alive()


def test_a_stopped_pool_leaves_no_manager_thread_for_the_exit_hook(monkeypatch):
    """CPython 3.11's exit hook writes to a pool manager's wake-up pipe, unlocked, while a still
    running manager may be closing it: a Ctrl-C'd ``fpr fly`` printed "OSError: Bad file
    descriptor" at exit (CI, 1cfbfc4). :func:`stop_pool` waits for the manager to end. The
    manager is slowed as it winds up, so that a stop that does not wait is caught every time."""
    import concurrent.futures.process as cfp

    wind_up = cfp._ExecutorManagerThread.join_executor_internals

    def slow_wind_up(self):
        time.sleep(0.5)
        wind_up(self)

    monkeypatch.setattr(cfp._ExecutorManagerThread, "join_executor_internals", slow_wind_up)
    with pytest.raises(KeyboardInterrupt):
        with worker_pool(2) as pool:
            for _ in range(4):
                pool.submit(time.sleep, 30)
            manager = pool._executor_manager_thread
            time.sleep(0.2)  # the workers have started their tasks
            raise KeyboardInterrupt
    assert manager is not None and not manager.is_alive(), "the manager thread outlives stop_pool"


def test_sigterm_takes_ctrl_cs_path_in_the_commands():
    from campaigns._signals import Terminated, interrupt_status, sigterm_as_interrupt

    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(Terminated) as caught:
        with sigterm_as_interrupt():
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5)  # the handler raises at the next bytecode; never reached
    assert signal.getsignal(signal.SIGTERM) is before  # restored
    assert interrupt_status(caught.value) == 143
    # an interrupt raised while handling it (FlyInterrupted, MonteCarloInterrupted) carries it
    try:
        try:
            raise Terminated()
        except KeyboardInterrupt:
            raise KeyboardInterrupt("interrupted: 1 of 3 written") from None
    except KeyboardInterrupt as exc:
        assert interrupt_status(exc) == 143
    assert interrupt_status(KeyboardInterrupt()) == 130
