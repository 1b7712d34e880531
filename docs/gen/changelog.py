"""Build step (mkdocs-gen-files): the changelog page is CHANGELOG.md itself, and every figure under
reports/ is published beside the pages that show it (reports/<folder>/<name>.png)."""

from pathlib import Path

import mkdocs_gen_files

ROOT = Path(__file__).resolve().parents[2]

with mkdocs_gen_files.open("changelog.md", "w") as fh:
    fh.write((ROOT / "CHANGELOG.md").read_text())
for png in sorted((ROOT / "reports").rglob("*.png")):
    with mkdocs_gen_files.open(png.relative_to(ROOT).as_posix(), "wb") as fh:
        fh.write(png.read_bytes())
