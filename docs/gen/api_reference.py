"""Build step (mkdocs-gen-files): one API page per module, found by walking the package.

No module is listed by hand: a module that moves between files, or a new one, gets its page at the
next build. Private modules (a name starting with ``_``) and ``__main__`` are left out.
"""

from pathlib import Path

import mkdocs_gen_files

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "facebasis"

nav = mkdocs_gen_files.Nav()
for path in sorted(PACKAGE.rglob("*.py")):
    module = path.relative_to(ROOT).with_suffix("")
    parts = tuple(module.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    if any(p.startswith("_") for p in parts) or parts[-1] == "__main__":
        continue
    doc = Path("reference", *parts).with_suffix(".md") if len(parts) > 1 else Path("reference", "index.md")
    if path.name == "__init__.py" and len(parts) > 1:
        doc = Path("reference", *parts, "index.md")
    nav[parts] = doc.relative_to("reference").as_posix()
    with mkdocs_gen_files.open(doc, "w") as fh:
        fh.write(f"# `{'.'.join(parts)}`\n\n::: {'.'.join(parts)}\n")
    mkdocs_gen_files.set_edit_path(doc, Path("..", path.relative_to(ROOT)).as_posix())

with mkdocs_gen_files.open("reference/SUMMARY.md", "w") as fh:
    fh.writelines(nav.build_literate_nav())
