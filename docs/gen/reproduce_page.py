"""Build step (mkdocs-gen-files): the page listing every figure and table of reports/ with the
command, data and script that make it, from problems.reproduce's entries (the same list
`python -m problems.reproduce --list` prints)."""

import sys
from pathlib import Path

import mkdocs_gen_files

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # this checkout's facebasis and problems

from problems import reproduce

lines = ["# Reproducing every figure and table", "",
         "Generated from `problems/reproduce.py` when these pages were built. "
         "`python -m problems.reproduce --list` prints the same list; `python -m problems.reproduce ID` "
         "(or `all`) regenerates an entry in place under `reports/`. Data: `ict` is "
         "`../shared/data/ict/ict_face.npz`, `video` the two webcam clips in `../shared/data/video/`, "
         "`detect` the `[detect]` extra (dlib); an entry whose data is missing is skipped with one line.", "",
         "| entry | what | command | data | files |", "|---|---|---|---|---|"]
files = reproduce.report_files()
for r in reproduce.RECIPES:
    mine = [p for p in files if r in reproduce.owners(p)]
    cmd = "<br>".join(f"`{c.replace('{python}', 'python')}`" for c in r.commands) or f"archived: {r.archived}"
    lines.append(f"| `{r.id}` | {r.what} | {cmd} | {', '.join(r.data) or 'none'} | "
                 f"{len(mine)} files: " + ", ".join(f"`{p}`" for p in mine[:6]) + (" ..." if len(mine) > 6 else "") + " |")
notes = [p for p in files if reproduce.is_note(p)]
lines += ["", "Written by hand (analyses that quote the tables, not regenerated): "
          + ", ".join(f"`reports/{p}`" for p in notes) + "."]
with mkdocs_gen_files.open("reproduce.md", "w") as fh:
    fh.write("\n".join(lines).replace("|", "|") + "\n")
