"""SIGTERM as an interrupt, for the commands that stop their workers and say how to resume.

``kill PID`` (SIGTERM) would end ``fpr fly`` or ``fpr montecarlo`` at once, without stopping their
worker processes cleanly or saying how far they got. Within :func:`sigterm_as_interrupt` it raises
:class:`Terminated`, a KeyboardInterrupt, so that it takes Ctrl-C's path; :func:`interrupt_status`
gives the exit status a shell expects of either (130 Ctrl-C, 143 SIGTERM).
"""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Iterator


class Terminated(KeyboardInterrupt):
    """SIGTERM, turned into an interrupt (:func:`sigterm_as_interrupt`)."""


def _on_sigterm(signum, frame) -> None:
    raise Terminated()


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM raises :class:`Terminated`; the previous handler is restored
    after it. Only the main thread may set a handler: elsewhere SIGTERM keeps its own."""
    try:
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    except ValueError:
        previous = None
    try:
        yield
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def interrupt_status(exc: BaseException) -> int:
    """The exit status of a command stopped by ``exc`` (a KeyboardInterrupt, or one raised while
    handling it, e.g. ``FlyInterrupted``): 143 (128 + SIGTERM) when SIGTERM caused it, else 130
    (128 + SIGINT)."""
    return 143 if isinstance(exc, Terminated) or isinstance(exc.__context__, Terminated) else 130
