"""Interrupts that native solvers cannot swallow, and termination signals handled like Ctrl-C.

IPOPT (through CasADi) turns a ``KeyboardInterrupt`` raised inside it into the status
``NonIpopt_Exception_Thrown`` and returns as if it had merely failed; a caller that recovers from
solver failures would then go on and finish the run. :func:`interruptible` records every stop
signal (SIGINT, SIGTERM, SIGHUP) that arrives while native code runs and raises it again as soon as
that code returns, whatever it did with the exception.

SIGTERM (what ``kill``, systemd, Docker and job schedulers send) and SIGHUP (the terminal closed)
are turned into :class:`Terminated`, a ``KeyboardInterrupt``, by :func:`install_stop_handlers`
(the command line calls it at start): every clean-up written for Ctrl-C (staging folders removed,
the old output kept) runs for them too, and the command exits with ``128 + signal number`` (130
for SIGINT, 143 for SIGTERM, 129 for SIGHUP), the status a shell reports for a process killed by
that signal. A signal that was ignored when the process started (``nohup`` ignores SIGHUP, a
background job of a non-interactive shell ignores SIGINT) stays ignored, as Unix programs do.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from typing import Iterator

#: the signals that stop a run the way Ctrl-C does
STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n))


class Terminated(KeyboardInterrupt):
    """A stop signal other than SIGINT (SIGTERM, SIGHUP) delivered to the process; ``signum``."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = int(signum)


def signal_number(exc: BaseException) -> int:
    """The signal an interrupt came from: :attr:`Terminated.signum`, else SIGINT."""
    return getattr(exc, "signum", int(signal.SIGINT))


def _raise_terminated(signum, frame):
    raise Terminated(signum)


def install_stop_handlers() -> dict:
    """Make SIGTERM and SIGHUP raise :class:`Terminated` in the main thread (SIGINT already raises
    ``KeyboardInterrupt``). A signal ignored at start (``nohup``, background jobs) is left ignored.
    Returns the handlers replaced, ``{signal: handler}``, for the caller to put back."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    global _FORK_HOOK
    replaced = {}
    for sig in STOP_SIGNALS:
        if sig == signal.SIGINT:
            continue
        if signal.getsignal(sig) == signal.SIG_DFL:
            replaced[sig] = signal.signal(sig, _raise_terminated)
    if not _FORK_HOOK and hasattr(os, "register_at_fork"):  # a forked child (a pool worker) is ended by
        os.register_at_fork(after_in_child=_default_in_child)  # SIGTERM silently, as before
        _FORK_HOOK = True
    return replaced


_FORK_HOOK = False


def _default_in_child() -> None:
    for sig in STOP_SIGNALS:
        if sig != signal.SIGINT and signal.getsignal(sig) is _raise_terminated:
            try:
                signal.signal(sig, signal.SIG_DFL)
            except ValueError:  # pragma: no cover - forked from a thread Python does not call main
                pass


def _handled(sig) -> bool:
    """A signal whose current handler is Python code (raising an exception), so it can be recorded."""
    return callable(signal.getsignal(sig))


@contextlib.contextmanager
def interruptible() -> Iterator[None]:
    """Run the block; if a stop signal arrived during it, raise its exception when the block ends.

    The interrupt is still delivered inside the block as usual (so CasADi can stop IPOPT early);
    it is only made impossible to lose. Signals with no Python handler (the default action kills the
    process; an ignored one does nothing) are left alone. Outside the main thread signals cannot be
    handled here and the block runs unchanged.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    seen = []
    previous = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS if _handled(sig)}

    def handler(signum, frame):
        seen.append(signum)
        previous[signum](signum, frame)

    for sig in previous:
        signal.signal(sig, handler)
    try:
        yield
    finally:
        for sig, h in previous.items():
            signal.signal(sig, h)
    if seen:
        raise KeyboardInterrupt if seen[0] == signal.SIGINT else Terminated(seen[0])


@contextlib.contextmanager
def deferred_interrupts() -> Iterator[None]:
    """Hold the stop signals (SIGINT, SIGTERM, SIGHUP) back while the block runs (a few renames that
    must not be cut in half); one that arrived meanwhile is delivered when the block ends.

    The signals' handlers are swapped for one that only records them (a signal mask would not do:
    it holds a signal back from this thread only, and the kernel hands a process's signal to any
    other thread that does not block it, a BLAS or tqdm thread, whose Python handler then runs in
    the main thread at once). A signal whose action was the default (SIGTERM outside the command
    line) is sent again with that action once the block ends; an ignored one stays ignored.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    seen = []
    previous = {}

    def record(signum, frame):
        seen.append(signum)

    try:
        for sig in STOP_SIGNALS:
            h = signal.getsignal(sig)
            if h not in (signal.SIG_IGN, None):
                previous[sig] = h
                signal.signal(sig, record)
        yield
    finally:
        for sig, h in previous.items():
            signal.signal(sig, h)
        if seen:  # delivered now, also when the block raised (the interrupt then carries that error)
            first = seen[0]
            h = previous[first]
            if callable(h):
                h(first, None)
            else:  # the default action (end the process), as if the signal came now
                os.kill(os.getpid(), first)
