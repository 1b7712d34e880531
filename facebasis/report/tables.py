"""Tables of results as CSV and Markdown, written atomically: one writer for the run reports, the
studies and the benchmarks' reports."""

from __future__ import annotations

import csv
import io
from pathlib import Path

from ..atomic import atomic_write_bytes


def markdown_table(header, rows, floatfmt="{:.4g}") -> str:
    """A Markdown table; floats formatted with ``floatfmt``."""
    def cell(v):
        return floatfmt.format(v) if isinstance(v, float) else ("" if v is None else str(v))
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(cell(v) for v in r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def csv_table(header, rows) -> str:
    """CSV text with a header row (``None`` is an empty cell)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows(rows)
    return buf.getvalue()


def dict_rows(rows, columns) -> list[list]:
    """Rows of dicts as lists in ``columns`` order (a missing key is an empty cell)."""
    return [[r.get(c, "") for c in columns] for r in rows]


def write_dict_csv(path: Path, rows) -> Path:
    """Rows of dicts (the first row's keys are the columns) as CSV at ``path``, written atomically."""
    columns = list(rows[0])
    atomic_write_bytes(path, csv_table(columns, dict_rows(rows, columns)).encode())
    return Path(path)


def write_table(out: Path, name: str, header, rows, floatfmt="{:.4g}") -> list[Path]:
    """``name.csv`` and ``name.md`` in the folder ``out``; returns both paths."""
    out = Path(out)
    paths = [out / f"{name}.csv", out / f"{name}.md"]
    atomic_write_bytes(paths[0], csv_table(header, rows).encode())
    atomic_write_bytes(paths[1], markdown_table(header, rows, floatfmt).encode())
    return paths


__all__ = ["markdown_table", "csv_table", "dict_rows", "write_dict_csv", "write_table"]
