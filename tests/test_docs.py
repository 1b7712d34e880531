"""The README's commands are true (they parse with the real parser; the demo command runs with
--quick), the README stays short, and every generated include of the documentation resolves
(numbers are read from reports/, never typed by hand). The site itself is built by
`mkdocs build --strict` in .ci/run."""

import csv
import importlib.util
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"


def _hooks():
    spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "docs" / "hooks.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _bash_blocks(text):
    return re.findall(r"```bash\n(.*?)```", text, re.S)


def _commands(block):
    """Logical lines of a bash block (continuations joined), comments dropped."""
    joined = re.sub(r"\\\n\s*", " ", block)
    return [ln.split("  #")[0].strip() for ln in joined.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]


def test_readme_is_short_and_keeps_its_two_commands():
    text = README.read_text()
    assert len(text.splitlines()) <= 200
    blocks = _bash_blocks(text)
    assert blocks[0].strip() == ("python3 -m venv .venv && . .venv/bin/activate && pip install . && facebasis demo")
    assert blocks[1].strip() == ("python3 -m venv .venv && . .venv/bin/activate && pip install '.[test]' && "
                                 "python -m pytest -q tests")


def test_every_facebasis_command_of_the_readme_and_the_docs_parses():
    from facebasis.cli import build_parser

    parser = build_parser()
    pages = [README, *sorted((ROOT / "docs").rglob("*.md"))]
    seen = 0
    for page in pages:
        for block in _bash_blocks(page.read_text()):
            for line in _commands(block):
                for part in line.split("&&"):
                    argv = shlex.split(part.strip())
                    if argv[:1] != ["facebasis"] or argv[1:2] in (["-V"], ["--help"]):
                        continue
                    parser.parse_args(argv[1:])  # SystemExit on an unknown option or a missing argument
                    seen += 1
    assert seen >= 12


def test_readme_demo_command_runs(tmp_path):
    """`facebasis demo` as the README's first command runs it, shortened with --quick, into tmp."""
    line = _bash_blocks(README.read_text())[0].strip().split("&&")[-1].split()
    assert line == ["facebasis", "demo"]
    env = dict(os.environ, FACEBASIS_PROGRESS="0", MPLBACKEND="Agg",
               PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
    run = subprocess.run([sys.executable, "-m", "facebasis.cli", *line[1:], "--quick", "--out", "demo"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    for rel in ("rig/weights.json", "transfer", "capture/track.npz", "provenance.json", "summary.json"):
        assert (tmp_path / "demo" / rel).exists(), rel


def test_every_include_of_the_documentation_resolves():
    hooks = _hooks()
    calls = 0
    for page in sorted((ROOT / "docs").rglob("*.md")):
        text = page.read_text()
        calls += len(hooks.CALL.findall(text))
        out = hooks.render(text, str(page))  # raises on a missing file, column or row
        assert hooks.CALL.search(out) is None
    assert calls >= 8


def test_includes_quote_the_tables_and_fail_loudly():
    hooks = _hooks()
    path = "reports/ict/formulations.csv"
    with open(ROOT / path, newline="") as fh:
        rows = {r["method"]: r for r in csv.DictReader(fh)}
    got = hooks.render('{{ value("reports/ict/formulations.csv", "reached optimum", method="cancel-pairs") }}')
    assert got == rows["cancel-pairs"]["reached optimum"]
    table = hooks.render('{{ table("reports/ict/formulations.csv", columns=["method", "instances"]) }}')
    assert table.splitlines()[0] == "| method | instances |" and len(table.splitlines()) >= len(rows) + 2
    assert "`{{ table(" in hooks.render("`{{ table(...) }}` in a code span stays as it is")
    with pytest.raises(hooks.IncludeError, match="no column"):
        hooks.render('{{ value("reports/ict/formulations.csv", "no such column", method="certified") }}', "p.md")
    with pytest.raises(hooks.IncludeError, match="p.md: .*no such file"):
        hooks.render('{{ table("reports/none.csv") }}', "p.md")
    with pytest.raises(hooks.IncludeError, match="0 rows match"):
        hooks.render('{{ value("reports/ict/formulations.csv", "instances", method="nobody") }}', "p.md")
