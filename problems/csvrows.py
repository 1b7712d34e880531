"""Rows of a benchmark (dicts with the same keys) as CSV bytes: floats at 5 significant digits."""

from __future__ import annotations

import csv
import io


def csv_bytes(rows: list) -> bytes:
    """CSV of ``rows`` (non-empty list of dicts, the first one's keys as the header)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, list(rows[0]), lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (f"{v:.5g}" if isinstance(v, float) else v) for k, v in r.items()})
    return buf.getvalue().encode()
