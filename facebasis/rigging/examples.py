"""Training inputs of ``facebasis rig``: a folder of expression meshes and a weights JSON file.

``WEIGHTS.json`` maps each example's file stem to its rough weights by shape name, e.g.
``{"ex00": {"jawOpen": 0.8, "mouthSmile_L": 0.5}}``; shapes not named start at 0.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import InputError, RigError, parameter_error
from ..jsonio import read_json
from ..geometry.meshio import MESH_SUFFIXES, read_mesh_like
from ..geometry.rig import Rig


def load_examples(folder: str | os.PathLike, template: Rig) -> tuple[tuple[str, ...], np.ndarray]:
    """Read every mesh of ``folder`` (sorted by name); each must have the template's topology."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"examples folder {folder}: expected a folder of meshes, found no such folder")
    files = sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES)
    if not files:
        raise InputError(f"examples folder {folder}: expected .obj/.ply training expressions, found none")
    names, meshes = [], []
    for p in files:
        V = read_mesh_like(p, template.n_vertices, template.faces, f"template {template.source}")
        names.append(p.stem)
        meshes.append(V)
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(f"examples folder {folder}: expected one mesh per name, found several for {dup}")
    return tuple(names), np.stack(meshes)


def parse_weights(obj, example_names, shape_names, source: str = "weights") -> np.ndarray:
    """Rough weights (m, k) from a ``{example: {shape: weight}}`` mapping, fully validated."""
    if not isinstance(obj, dict):
        raise InputError(f"{source}: expected a JSON object {{example: {{shape: weight}}}}, found {type(obj).__name__}")
    missing = [n for n in example_names if n not in obj]
    extra = [n for n in obj if n not in set(example_names)]
    if missing:
        raise InputError(f"{source}: expected weights for every example, found none for {missing}")
    if extra:
        raise InputError(f"{source}: found weights for examples that are not in the examples folder: {extra}")
    lookup = {s: i for i, s in enumerate(shape_names)}
    X = np.zeros((len(example_names), len(shape_names)))
    for j, ex in enumerate(example_names):
        row = obj[ex]
        if not isinstance(row, dict):
            raise InputError(f"{source}: {ex}: expected an object {{shape: weight}}, found {type(row).__name__}")
        unknown = [s for s in row if s not in lookup]
        if unknown:  # the nearest name of each when all are near (jawOpem -> jawOpen), else every name
            import difflib

            near = {s: difflib.get_close_matches(s, list(shape_names), n=1, cutoff=0.75) for s in unknown}
            hint = ("did you mean " + ", ".join(f"{near[s][0]!r} for {s!r}" for s in unknown) + "?"
                    if all(near.values()) else f"expected names of the template: {list(shape_names)}")
            raise RigError(f"{source}: {ex}: unknown blendshape names {unknown}; {hint}")
        for s, v in row.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                raise InputError(f"{source}: {ex}.{s}: expected a number in [0, 1], found {v!r}")
            if not 0.0 <= v <= 1.0:
                raise InputError(f"{source}: {ex}.{s}: expected a weight in [0, 1], found {v}")
            X[j, lookup[s]] = float(v)
    return X


def load_weights(path: str | os.PathLike, example_names, shape_names) -> np.ndarray:
    path = Path(path)
    obj = read_json(path, "a weights JSON file")
    return parse_weights(obj, example_names, shape_names, str(path))


def weights_to_json(X: np.ndarray, example_names, shape_names, drop_zero: bool = True) -> dict:
    """``{example: {shape: weight}}`` (the weights file format); zeros are omitted by default."""
    return {ex: {s: float(v) for s, v in zip(shape_names, row) if not (drop_zero and v == 0.0)}
            for ex, row in zip(example_names, np.asarray(X))}


def parse_pairs(specs) -> tuple[tuple[str, str], ...]:
    """``["mouthLeft:mouthRight", ...]`` -> pairs of names, in the order given.

    Every pair is kept; only an exact repeat of a pair (``A:B`` twice, or ``A:B`` and ``B:A``,
    the same constraint) is merged into its first occurrence."""
    pairs, seen = [], set()
    for spec in specs or ():
        parts = str(spec).split(":")
        if len(parts) != 2 or not all(p.strip() for p in parts):
            raise parameter_error("exclusive", "SHAPE_A:SHAPE_B", repr(spec))
        a, b = parts[0].strip(), parts[1].strip()
        key = frozenset((a, b))
        if key in seen:
            continue
        seen.add(key)
        pairs.append((a, b))
    return tuple(pairs)
