"""The package keeps its layout: imports run downward only, methods meet only through stated interfaces.

Every module of ``facebasis/`` is parsed (not imported) and each ``import`` / ``from ... import``
that names a facebasis module is resolved to the unit it belongs to. A unit may import only the
units listed for it in ``ALLOWED``; a new sub-package must be given its place here first.
"""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "facebasis"

BASE = {"base"}  # facebasis.errors, .atomic, .interrupt, .jsonio, .workers (worker processes), .progress (bars),
#                  .provenance (what made an output folder)
ALLOWED = {
    "base": BASE,
    "geometry": BASE | {"geometry"},
    "defaults": BASE | {"geometry", "defaults"},                 # generated built-in data
    "contact": BASE | {"geometry", "contact"},
    # stated interface: generation adds contact's virtual-edge energy to its basis step
    "rigging": BASE | {"geometry", "defaults", "contact", "rigging"},
    "capture": BASE | {"geometry", "defaults", "capture"},
    # stated interfaces: retarget reads capture's track file and uses rigging's weight model
    "retarget": BASE | {"geometry", "defaults", "rigging", "capture", "retarget"},
    "report": BASE | {"geometry", "defaults", "contact", "rigging", "capture", "retarget", "report"},
}
TOP = {"cli", "__init__", "defaults.demo"}   # the command line, the package's public API, the demo


def unit_of(module: str) -> str:
    """``facebasis.geometry.rig`` -> ``geometry``; errors/atomic/interrupt/jsonio/workers/progress -> base;
    entry points -> top."""
    parts = module.split(".")[1:]
    if not parts:
        return "top"
    if parts[0] in ("errors", "atomic", "interrupt", "jsonio", "workers", "progress", "provenance", "_version"):
        return "base"
    if parts[0] == "cli" or ".".join(parts[:2]) in TOP:
        return "top"
    return parts[0]


def module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def imported_modules(path: Path, text: str | None = None):
    """(line, absolute module name) of every facebasis import in ``path`` (or in ``text`` read as
    if it were that file)."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    tree = ast.parse(path.read_text() if text is None else text, str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "facebasis":
                    yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "facebasis":
                continue
            if node.module is None or target == "facebasis":  # from . import x / from facebasis import x
                for alias in node.names:
                    yield node.lineno, f"{target}.{alias.name}"
            else:
                yield node.lineno, target


MODULES = sorted(PACKAGE.rglob("*.py"))


def test_every_module_has_a_known_place():
    unknown = sorted({unit_of(module_name(p)) for p in MODULES} - set(ALLOWED) - {"top"})
    assert unknown == [], f"new units {unknown}: give them a row in ALLOWED"


def test_imports_run_downward_only():
    offences = []
    for path in MODULES:
        src_unit = unit_of(module_name(path))
        if src_unit == "top":
            continue
        for line, target in imported_modules(path):
            dst_unit = unit_of(target)
            if dst_unit not in ALLOWED[src_unit]:
                offences.append(f"{path.relative_to(PACKAGE.parent)}:{line} ({src_unit}) imports {target} ({dst_unit})")
    assert offences == []


def test_the_checker_sees_an_upward_import(tmp_path):
    """The check can fail: a geometry module importing rigging, relatively and absolutely."""
    fake = PACKAGE / "geometry" / "_layout_probe.py"
    lines = ["from ..rigging.certify import CertifiedWeightSolver", "import facebasis.contact.penetration",
             "from .. import report"]
    targets = [t for _, t in imported_modules(fake, "\n".join(lines))]
    assert targets == ["facebasis.rigging.certify", "facebasis.contact.penetration", "facebasis.report"]
    assert [unit_of(t) in ALLOWED["geometry"] for t in targets] == [False, False, False]


@pytest.mark.parametrize("name", ["Rig", "load_rig_folder", "write_rig_folder", "DeformationTransfer",
                                  "deformation_transfer", "FacebasisError", "InputError"])
def test_public_api_stays_at_the_top(name):
    import facebasis

    assert hasattr(facebasis, name)


def test_each_subpackage_states_its_method_and_modules():
    for init in sorted(PACKAGE.glob("*/__init__.py")):
        if init.parent.name == "cli":
            continue
        doc = ast.get_docstring(ast.parse(init.read_text())) or ""
        modules = sorted(p.stem for p in init.parent.glob("*.py") if p.stem != "__init__")
        missing = [m for m in modules if m not in doc]
        assert doc and not missing, f"{init}: docstring does not list {missing}"
