"""Worker processes that stop with their parent and print nothing.

Every process pool of the package (the contact solver's shapes, the geodesic searches) passes
:func:`worker_init` as its ``initializer``. A worker then

- ignores SIGINT: Ctrl-C reaches the whole process group, and the parent alone handles it (it stops
  and terminates the pool), so no worker prints a ``KeyboardInterrupt`` traceback;
- takes SIGTERM and SIGHUP with the default action (a silent exit): ``Pool.terminate`` sends
  SIGTERM, and a forked worker must not inherit the parent's handler that turns it into an
  exception (and a traceback);
- dies with its parent: on Linux the kernel sends it SIGKILL when the parent dies, even by SIGKILL
  (``prctl(PR_SET_PDEATHSIG)`` through ctypes); elsewhere a daemon thread checks every 0.5 s
  whether the parent is still the one that started it and ends the worker with ``os._exit`` (no
  ``BrokenPipeError`` traceback from a result sent to a dead parent).
"""

from __future__ import annotations

import os
import signal
import sys
import threading

_PR_SET_PDEATHSIG = 1


def _die_with_parent_linux(parent: int) -> bool:
    """Ask the kernel for SIGKILL when the parent dies; False if prctl is unavailable."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) != 0:
            return False
    except (OSError, AttributeError):
        return False
    if os.getppid() != parent:  # the parent died before prctl took effect
        os._exit(1)
    return True


def _watch_parent(parent: int, period: float = 0.5) -> None:
    """Portable fallback: end the process once its parent is gone (it is re-parented)."""
    import time

    def watch():
        while os.getppid() == parent:
            time.sleep(period)
        os._exit(1)

    threading.Thread(target=watch, name="facebasis-parent-watch", daemon=True).start()


def worker_init(parent: int | None = None) -> None:
    """Initializer of every worker process (see the module's docstring). ``parent``: the pool
    owner's process id (default: this process's parent, right for forked pool workers)."""
    parent = os.getppid() if parent is None else int(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for name in ("SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), signal.SIG_DFL)
    if not (sys.platform.startswith("linux") and _die_with_parent_linux(parent)):
        _watch_parent(parent)


def fork_pool(processes: int):
    """A ``multiprocessing`` pool of ``processes`` forked workers set up by :func:`worker_init`."""
    import multiprocessing as mp

    return mp.get_context("fork").Pool(processes, initializer=worker_init, initargs=(os.getpid(),))


__all__ = ["worker_init", "fork_pool"]


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity), the default size of every worker pool."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1
