"""Build step (mkdocs-gen-files): the gallery page. Every ``examples/*.py`` is run (as CI's
tests/test_examples.py runs them) and the page shows its description, its code, what it printed and
the figures it wrote. An example that fails stops the build."""

import ast
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import mkdocs_gen_files

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = sorted(p for p in (ROOT / "examples").glob("*.py") if not p.name.startswith("_"))

lines = ["# Gallery", "",
         "Each example below runs in a few seconds on the built-in data; the figures and printed output "
         "were made by running it when these pages were built. Run one yourself with "
         "`python examples/NAME.py` (figures in `./example_output/NAME/`).", ""]
with tempfile.TemporaryDirectory() as tmp:
    env = dict(os.environ, FACEBASIS_EXAMPLES_OUT=tmp, PYTHONPATH=os.pathsep.join(
        [str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep), MPLBACKEND="Agg", FACEBASIS_PROGRESS="0")
    for script in EXAMPLES:
        doc = ast.get_docstring(ast.parse(script.read_text())) or script.stem
        title, _, body = doc.partition("\n\n")
        run = subprocess.run([sys.executable, script.name], cwd=script.parent, env=env, capture_output=True,
                             text=True, timeout=600)
        if run.returncode != 0:
            raise SystemExit(f"examples/{script.name} failed:\n{run.stderr[-2000:]}")
        lines += [f"## {script.stem.replace('_', ' ')}", "", title.replace("\n", " "), "", body, "",
                  f"```python title=\"examples/{script.name}\"", script.read_text().rstrip(), "```", "",
                  "Output:", "", "```text", run.stdout.rstrip().replace(tmp, "example_output"), "```", ""]
        for png in sorted((Path(tmp) / script.stem).glob("*.png")):
            rel = f"gallery/{script.stem}/{png.name}"
            with mkdocs_gen_files.open(rel, "wb") as fh:
                fh.write(png.read_bytes())
            lines += [f"![{script.stem}: {png.stem}]({rel})", ""]
with mkdocs_gen_files.open("gallery.md", "w") as fh:
    fh.write("\n".join(lines))
