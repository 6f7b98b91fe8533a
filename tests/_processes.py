"""Finding a test's child processes and their descendants in ``/proc`` (Linux), with a guard
against reused process ids: a process is (pid, start time), and one of that pid started at
another time is another process."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

#: whether this system has the ``/proc`` these helpers read
HAVE_PROC = Path("/proc/self/stat").exists()


def proc_stat(pid: int) -> list[str] | None:
    """Fields 3 on of ``/proc/PID/stat`` (``[0]`` state, ``[1]`` ppid, ``[19]`` start time),
    None when there is no such process."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return text[text.rindex(")") + 2:].split()  # after the name, which may hold spaces


def descendants(pid: int) -> list[tuple[int, str]]:
    """(pid, start time) of every process below ``pid``: its children (pool workers under fork or
    spawn, a fork server, a resource tracker) and theirs (workers under forkserver)."""
    parent_of = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit() and (st := proc_stat(int(d.name))) is not None:
            parent_of[int(d.name)] = (int(st[1]), st[19])
    found, frontier = [], [pid]
    while frontier:
        p = frontier.pop()
        kids = [(c, start) for c, (pp, start) in parent_of.items() if pp == p]
        found += kids
        frontier += [c for c, _ in kids]
    return found


def alive(proc: tuple[int, str]) -> bool:
    """Whether the process (pid, start time) still runs (a zombie computes nothing)."""
    st = proc_stat(proc[0])
    return st is not None and st[19] == proc[1] and st[0] not in "ZX"


def left_after(procs: list[tuple[int, str]], seconds: float) -> list[tuple[int, str]]:
    """The processes (pid, start time) still running after up to ``seconds`` (returns as soon as
    none is)."""
    end = time.monotonic() + seconds
    while any(alive(p) for p in procs) and time.monotonic() < end:
        time.sleep(0.05)
    return [p for p in procs if alive(p)]


def reap(child: subprocess.Popen, procs: list[tuple[int, str]]) -> None:
    """After a kill test, passed or failed: end the child and every process of ``procs`` (pid,
    start time) it left, by pid."""
    if child.poll() is None:
        child.kill()
        child.wait()
    for p in procs:
        if alive(p):
            os.kill(p[0], signal.SIGKILL)


def ignores(pid: int, signum: int) -> bool:
    """Whether process ``pid`` ignores signal ``signum`` (its SigIgn mask in /proc)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("SigIgn:"):
            return bool(int(line.split()[1], 16) >> (signum - 1) & 1)
    raise AssertionError(f"no SigIgn in /proc/{pid}/status")


def sigint_default() -> None:
    """A ``preexec_fn``: Ctrl-C (SIGINT) at its default in the child, as in a terminal. A child
    inherits an ignored SIGINT (pytest started by nohup, in a script's background job, some CI),
    and Python then installs no KeyboardInterrupt handler: a test sending SIGINT would test
    nothing."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)


#: A sitecustomize that calls ``hold(module)`` (defined in the source it is given) on the module
#: ``NAME`` right after any process of the run imports it: the run, a fork server, the workers,
#: however they start; a process that never imports it (a resource tracker) starts as fast as it
#: would.
_PATCH_ON_IMPORT = """
import sys
from importlib.abc import MetaPathFinder
from importlib.machinery import PathFinder

NAME = {name!r}

{hold}

class Hook(MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name != NAME:
            return None
        spec = PathFinder.find_spec(name, path)
        run = spec.loader.exec_module

        def exec_module(module):
            run(module)
            hold(module)

        spec.loader.exec_module = exec_module
        return spec


sys.meta_path.insert(0, Hook())
"""


def patched_on_import_env(folder: Path, module: str, hold_source: str, **env: str) -> dict[str, str]:
    """The environment of a child process whose every Python process patches ``module`` on import
    with the function ``hold(module)`` that ``hold_source`` defines (its imports included): a
    sitecustomize written into ``folder`` (created) and put first on PYTHONPATH; ``env`` added."""
    folder.mkdir()
    (folder / "sitecustomize.py").write_text(_PATCH_ON_IMPORT.format(name=module, hold=hold_source))
    path = os.pathsep.join(p for p in (str(folder), os.environ.get("PYTHONPATH")) if p)
    return dict(os.environ, **env, PYTHONPATH=path)
