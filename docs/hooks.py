"""MkDocs hook: pages quote the numbers of reports/ through generated includes, never by hand.

In a page's Markdown (not in code blocks):

* ``{{ table("reports/ict/formulations.csv", columns=["method", "reached optimum"], digits=3) }}``
  renders a CSV (or a JSON list of objects) as a Markdown table; ``where={"column": "value"}``
  keeps matching rows, ``rename={"old": "new"}`` renames columns;
* ``{{ value("reports/ict/formulations.csv", "reached optimum", method="equality") }}`` is one cell
  (the row where every keyword matches; exactly one must), ``digits=`` formats a number;
  ``{{ value("reports/x.json", "a.b") }}`` reads a JSON path;
* ``{{ include("reports/contact/contact.md") }}`` inlines a Markdown file written by a benchmark
  (its first ``#`` title dropped, headings moved down one level).

Paths are relative to the repository root. A missing file, column or row stops the build with the
page and the call named (``mkdocs build --strict`` fails), so a renamed table cannot leave a stale
number behind. :func:`render` is importable without MkDocs (tests use it).
"""

from __future__ import annotations

import ast
import csv
import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CALL = re.compile(r"(?<!`)\{\{\s*(table|value|include)\((.*?)\)\s*\}\}", re.S)
FENCE = re.compile(r"^(```|~~~)")


class IncludeError(Exception):
    pass


def _args(text: str):
    call = ast.parse(f"f({text})", mode="eval").body
    args = [ast.literal_eval(a) for a in call.args]
    kwargs = {k.arg: ast.literal_eval(k.value) for k in call.keywords}
    return args, kwargs


def _rows(path: str) -> list[dict]:
    p = ROOT / path
    if not p.is_file():
        raise IncludeError(f"{path}: no such file")
    if p.suffix == ".json":
        data = json.loads(p.read_text())
        if isinstance(data, dict):
            data = data.get("rows", [data])
        return [dict(r) for r in data]
    with p.open(newline="") as fh:
        return list(csv.DictReader(fh))


def _fmt(v, digits: int | None) -> str:
    if v is None:
        return ""
    if isinstance(v, str):
        try:
            f = float(v)
        except ValueError:
            return v
        if digits is None or v.strip().lstrip("-").isdigit():
            return v
        v = f
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, (int, float)) and digits is not None and not (isinstance(v, int)):
        return f"{v:.{digits}g}"
    return str(v)


def _match(rows, where):
    return [r for r in rows if all(str(r.get(k)) == str(v) for k, v in where.items())]


def table(path, columns=None, where=None, digits=4, rename=None) -> str:
    rows = _match(_rows(path), where or {})
    if not rows:
        raise IncludeError(f"{path}: no row matches {where}")
    cols = list(columns or rows[0].keys())
    missing = [c for c in cols if c not in rows[0]]
    if missing:
        raise IncludeError(f"{path}: no column {missing} (columns: {list(rows[0])})")
    names = [(rename or {}).get(c, c) for c in cols]
    esc = lambda s: str(s).replace("|", "\\|")  # noqa: E731
    out = ["| " + " | ".join(map(esc, names)) + " |", "|" + "---|" * len(cols)]
    out += ["| " + " | ".join(esc(_fmt(r[c], digits)) for c in cols) + " |" for r in rows]
    return "\n".join(out) + f"\n\n*Table: `{path}`.*"


def value(path, column, digits=None, **where) -> str:
    p = ROOT / path
    if p.suffix == ".json" and not where:
        if not p.is_file():
            raise IncludeError(f"{path}: no such file")
        v = json.loads(p.read_text())
        for key in column.split("."):
            try:
                v = v[int(key)] if isinstance(v, list) else v[key]
            except (KeyError, IndexError, ValueError, TypeError):
                raise IncludeError(f"{path}: no key {column}") from None
        return _fmt(v, digits)
    rows = _match(_rows(path), where)
    if len(rows) != 1:
        raise IncludeError(f"{path}: {len(rows)} rows match {where}, expected exactly one")
    if column not in rows[0]:
        raise IncludeError(f"{path}: no column {column!r} (columns: {list(rows[0])})")
    return _fmt(rows[0][column], digits)


def include(path) -> str:
    p = ROOT / path
    if not p.is_file():
        raise IncludeError(f"{path}: no such file")
    lines = p.read_text().splitlines()
    if lines and lines[0].startswith("# "):
        lines = lines[1:]
    lines = ["#" + ln if ln.startswith("#") else ln for ln in lines]
    return "\n".join(lines).strip() + f"\n\n*From `{path}`.*"


def render(markdown: str, where: str = "page") -> str:
    """``markdown`` with every call replaced (code blocks left as they are)."""
    out, fenced, block = [], False, []

    def flush():
        text = "\n".join(block)

        def sub(m):
            try:
                args, kwargs = _args(m.group(2))
                return str({"table": table, "value": value, "include": include}[m.group(1)](*args, **kwargs))
            except IncludeError as exc:
                raise IncludeError(f"{where}: {m.group(0)!r}: {exc}") from None
            except (SyntaxError, ValueError, TypeError) as exc:
                raise IncludeError(f"{where}: {m.group(0)!r}: {exc}") from None

        out.append(CALL.sub(sub, text))
        block.clear()

    for line in markdown.split("\n"):
        if FENCE.match(line.lstrip()):
            if not fenced:
                flush()
                fenced = True
                out.append(line)
                continue
            fenced = False
            out.append(line)
            continue
        (out if fenced else block).append(line)
    flush()
    return "\n".join(out)


def on_page_markdown(markdown, page, config, files):  # MkDocs hook
    from mkdocs.exceptions import PluginError

    try:
        return render(markdown, page.file.src_uri)
    except IncludeError as exc:
        raise PluginError(str(exc)) from None
