"""Progress bars on stderr for long loops over shapes (reading, transferring, writing a rig).

A bar appears only once its loop has run :data:`DELAY` seconds (tqdm's ``delay``), so ordinary
rigs of tens of shapes print nothing; a 5,000-shape rig shows where it is instead of staying silent
for minutes. The bar is erased when its loop ends (``leave=False``) and never writes a newline, so
a command's own output and its one-line ``error:`` are unchanged. ``FACEBASIS_PROGRESS=0`` turns
bars off.
"""

from __future__ import annotations

import os
import sys

#: seconds a loop runs before its bar appears
DELAY = 1.0


def progress(iterable=None, total: int | None = None, desc: str = "", unit: str = "shape"):
    """``tqdm(iterable)`` on stderr with :data:`DELAY`; ``bar.update(n)`` works without an iterable."""
    import shutil

    from tqdm import tqdm

    return tqdm(iterable, total=total, desc=desc, unit=unit, delay=DELAY, leave=False, file=sys.stderr,
                ncols=shutil.get_terminal_size((80, 24)).columns or 80,  # a pty of width 0 would show nothing
                mininterval=0.5 if sys.stderr.isatty() else 10.0,
                disable=os.environ.get("FACEBASIS_PROGRESS", "1") == "0")


__all__ = ["progress", "DELAY"]
