import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from problems.ict import ict_available  # noqa: E402


def grid_sheet(nx=6, ny=5, z=0.0, size=1.0):
    """A flat triangulated sheet in the plane z, (V, F)."""
    xs, ys = np.meshgrid(np.linspace(0, size, nx), np.linspace(0, size * 0.8, ny), indexing="xy")
    V = np.stack([xs.ravel(), ys.ravel(), np.full(xs.size, z)], 1)
    idx = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return V, F


def bumpy_sheet(nx=8, ny=7, seed=0):
    V, F = grid_sheet(nx, ny)
    rng = np.random.default_rng(seed)
    V = V.copy()
    V[:, 2] = 0.2 * np.sin(3 * V[:, 0]) * np.cos(2 * V[:, 1]) + 0.01 * rng.standard_normal(len(V))
    return V, F


@pytest.fixture
def sheet():
    return bumpy_sheet()


requires_ict = pytest.mark.skipif(not ict_available(), reason="ICT data not found at ../shared/data/ict")


def write_rig_inputs(root, pp, n_iterations=None):
    """Write a person problem as `facebasis rig` inputs under ``root``: ``template/`` (rig folder),
    ``target.obj``, ``examples/<name>.obj`` and ``weights.json`` (rough weights by shape name)."""
    import json

    from facebasis.geometry.meshio import write_mesh
    from facebasis.geometry.rig import write_rig_folder

    p = pp.problem
    write_rig_folder(root / "template", p.template)
    write_mesh(root / "target.obj", p.target_neutral, p.template.faces)
    (root / "examples").mkdir()
    for name, T in zip(p.example_names, p.examples):
        write_mesh(root / "examples" / f"{name}.obj", T, p.template.faces)
    weights = {n: {s: float(v) for s, v in zip(p.template.names, row) if v > 0}
               for n, row in zip(p.example_names, p.initial_weights)}
    (root / "weights.json").write_text(json.dumps(weights))
    return root
