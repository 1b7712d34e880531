"""Every ``>>>`` example in the package's docstrings runs (none is skipped): modules are found by
walking the package, so an example added anywhere is run here."""

import doctest
import importlib
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "facebasis"
MODULES = sorted(".".join(p.relative_to(PACKAGE.parent).with_suffix("").parts).removesuffix(".__init__")
                 for p in PACKAGE.rglob("*.py") if ">>>" in p.read_text())


def test_there_are_examples_and_none_is_skipped():
    assert len(MODULES) >= 2, MODULES
    for name in MODULES:
        path = PACKAGE.parent / (name.replace(".", "/") + ".py")
        assert "doctest: +SKIP" not in path.read_text(), f"{name} skips a docstring example"


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0, result
