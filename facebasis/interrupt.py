"""Interrupts that native solvers cannot swallow.

IPOPT (through CasADi) turns a ``KeyboardInterrupt`` raised inside it into the status
``NonIpopt_Exception_Thrown`` and returns as if it had merely failed; a caller that recovers from
solver failures would then go on and finish the run. :func:`interruptible` records every SIGINT
that arrives while native code runs and raises ``KeyboardInterrupt`` as soon as that code returns,
whatever it did with the exception.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from typing import Iterator


@contextlib.contextmanager
def interruptible() -> Iterator[None]:
    """Run the block; if SIGINT arrived during it, raise ``KeyboardInterrupt`` when it ends.

    The interrupt is still delivered inside the block as usual (so CasADi can stop IPOPT early);
    it is only made impossible to lose. Outside the main thread signals cannot be handled here and
    the block runs unchanged.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    seen = []
    previous = signal.getsignal(signal.SIGINT)

    def handler(signum, frame):
        seen.append(signum)
        if callable(previous):
            previous(signum, frame)
        else:
            raise KeyboardInterrupt

    signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if seen:
        raise KeyboardInterrupt


@contextlib.contextmanager
def deferred_interrupts() -> Iterator[None]:
    """Hold SIGINT back while the block runs (a few renames that must not be cut in half); an
    interrupt that arrived meanwhile is delivered when the block ends."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)
