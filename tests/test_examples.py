"""Every examples/*.py runs on the built-in data and writes the figures it says (the documentation's
gallery runs them again at build time)."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = sorted(p for p in (ROOT / "examples").glob("*.py") if not p.name.startswith("_"))


def test_there_are_examples():
    assert len(EXAMPLES) >= 3


@pytest.mark.parametrize("script", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_runs_and_writes_its_figures(script, tmp_path):
    env = dict(os.environ, FACEBASIS_EXAMPLES_OUT=str(tmp_path), MPLBACKEND="Agg", FACEBASIS_PROGRESS="0",
               PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
    run = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    figures = list((tmp_path / script.stem).glob("*.png"))
    assert figures and all(f.stat().st_size > 5000 for f in figures), figures
    assert "figure:" in run.stdout
