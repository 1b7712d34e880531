"""Blendshape rigs: a neutral mesh plus named per-vertex deltas in one topology.

A rig folder is a directory of meshes sharing one topology: a neutral (``neutral.obj`` by default,
or any name given, e.g. ICT-FaceKit's ``generic_neutral_mesh.obj``) and one mesh per blendshape,
named by its file stem (``jawOpen.obj``). Files matching any ``exclude`` glob are ignored, so an
ICT-FaceKit ``FaceXModel`` folder loads with ``exclude=("identity*",)``; a pattern matching no
file is an error (a typo would keep what it meant to leave out). Hidden files (``.name``, e.g.
macOS's ``._jawOpen.obj`` companions) are not meshes of the rig.
"""

from __future__ import annotations

import fnmatch
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from ..atomic import atomic_directory
from ..errors import RigError, TopologyError
from .meshio import MESH_SUFFIXES, read_mesh, read_mesh_like, write_mesh
from .mesh import validate_mesh, validate_vertices


@dataclass(frozen=True)
class Rig:
    """A delta blendshape rig.

    Attributes
    ----------
    neutral : (n, 3) float64, the rest face ``S0`` (or ``B0``)
    faces : (m, 3) int64
    names : tuple of k shape names
    deltas : (k, n, 3) float64, ``S_i - S0`` for each shape
    """

    neutral: np.ndarray
    faces: np.ndarray
    names: tuple[str, ...]
    deltas: np.ndarray
    source: str = field(default="rig", compare=False)

    def __post_init__(self):
        V, F = validate_mesh(self.neutral, self.faces, f"{self.source} neutral")
        D = np.ascontiguousarray(self.deltas, dtype=np.float64)
        names = tuple(str(s) for s in self.names)
        if D.ndim != 3 or D.shape[1:] != V.shape:
            raise TopologyError(
                f"{self.source}: expected deltas of shape (k, {len(V)}, 3), found {D.shape}"
            )
        if len(names) != len(D):
            raise RigError(f"{self.source}: expected {len(D)} shape names, found {len(names)}")
        if len(set(names)) != len(names):
            dup = sorted({s for s in names if names.count(s) > 1})
            raise RigError(f"{self.source}: expected unique shape names, found duplicates {dup}")
        if not np.isfinite(D).all():
            k = int(np.flatnonzero(~np.isfinite(D).all(axis=(1, 2)))[0])
            raise RigError(f"{self.source}: shape '{names[k]}' has NaN/inf deltas")
        object.__setattr__(self, "neutral", V)
        object.__setattr__(self, "faces", F)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "deltas", D)

    @property
    def n_vertices(self) -> int:
        return len(self.neutral)

    @property
    def n_shapes(self) -> int:
        return len(self.names)

    def index(self, names: Sequence[str], what: str = "shape names") -> np.ndarray:
        """Indices of ``names``; :class:`RigError` listing the unknown ones and the known ones."""
        lookup = {s: i for i, s in enumerate(self.names)}
        unknown = [s for s in names if s not in lookup]
        if unknown:
            raise RigError(
                f"{what}: unknown blendshape names {unknown}; expected names of {self.source}: "
                f"{list(self.names)}"
            )
        return np.array([lookup[s] for s in names], dtype=np.int64)

    def shape(self, name: str) -> np.ndarray:
        """Absolute positions ``S0 + S_i`` of one shape, (n, 3)."""
        return self.neutral + self.deltas[self.index([name])[0]]

    def evaluate(self, weights: np.ndarray) -> np.ndarray:
        """Positions ``S0 + sum_i w_i S_i`` for weights (k,) or (j, k) -> (n, 3) or (j, n, 3)."""
        w = np.asarray(weights, dtype=np.float64)
        if w.shape[-1] != self.n_shapes:
            raise RigError(f"weights: expected {self.n_shapes} per expression, found {w.shape[-1]}")
        return self.neutral + np.tensordot(w, self.deltas, axes=(-1, 0))

    def with_neutral(self, neutral: np.ndarray, deltas: np.ndarray, source: str | None = None) -> "Rig":
        """A rig of the same names and faces with another neutral and deltas."""
        return Rig(neutral, self.faces, self.names, deltas, source or self.source)


def _matches(p: Path, glob: str) -> bool:
    """An ``exclude`` glob matches a file by its name or its stem."""
    return fnmatch.fnmatch(p.name, glob) or fnmatch.fnmatch(p.stem, glob)


def _mesh_files(folder: Path, exclude: Sequence[str]) -> list[Path]:
    """Mesh files of ``folder`` by name, without hidden ones (``.name``: editors' and macOS's
    ``._name`` companions) and those matching an ``exclude`` glob."""
    return [p for p in sorted(folder.iterdir())
            if p.is_file() and p.suffix.lower() in MESH_SUFFIXES and not p.name.startswith(".")
            and not any(_matches(p, g) for g in exclude)]


def load_rig_folder(
    folder: str | os.PathLike,
    neutral: str = "neutral.obj",
    exclude: Sequence[str] = (),
) -> Rig:
    """Load a rig folder: the neutral and one blendshape per other mesh file (sorted by name).

    Raises
    ------
    RigError
        The folder or its neutral is missing, or it holds no blendshape.
    TopologyError
        A shape's vertex count or faces differ from the neutral's (the file is named).
    MeshError
        A file is unreadable, empty, has NaN/inf coordinates or bad indices; the neutral also has
        degenerate triangles.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise RigError(f"rig folder {folder}: expected a folder of meshes, found no such folder")
    neutral_path = folder / neutral
    every = _mesh_files(folder, ())  # the folder listed once
    if not neutral_path.is_file():
        raise RigError(
            f"rig folder {folder}: expected the neutral '{neutral}', found no such file "
            f"(mesh files there: {[p.name for p in every][:10]}); name it with --neutral"
        )
    unmatched = [g for g in exclude if not any(_matches(p, g) for p in every)]
    if unmatched:  # a typo would otherwise keep the meshes the user meant to leave out
        raise RigError(f"rig folder {folder}: expected every --exclude pattern to match a mesh file, found none for "
                       f"{', '.join(repr(g) for g in unmatched)} (mesh files there: {[p.name for p in every][:10]})")
    V0, F0 = read_mesh(neutral_path, check_degenerate=True)
    names, deltas = [], []
    for p in every:
        if any(_matches(p, g) for g in exclude) or p.resolve() == neutral_path.resolve():
            continue
        V = read_mesh_like(p, len(V0), F0, str(neutral_path))
        names.append(p.stem)
        deltas.append(V - V0)
    if not names:
        raise RigError(f"rig folder {folder}: expected blendshape meshes beside '{neutral}', found none")
    return Rig(V0, F0, tuple(names), np.stack(deltas), source=str(folder))


#: shape names that look like identity (face-shape) modes rather than expressions: ICT-FaceKit's
#: ``identity000``..``identity099``, and ``id_*`` / ``id<digits>`` spellings
IDENTITY_NAME = re.compile(r"^(identity|id_|id\d)", re.IGNORECASE)
#: more shapes than this in a folder gets a warning (a FACS/ARKit rig has 50-60 expressions)
MANY_SHAPES = 100


def rig_folder_warning(rig: Rig, option: str = "--exclude") -> str | None:
    """A one-line warning for a rig folder that is probably not only expressions, or None.

    Shape names that look like identity modes (:data:`IDENTITY_NAME`) are named (the first few and
    how many) with the ``option`` glob that leaves them out; otherwise a folder of more than
    :data:`MANY_SHAPES` shapes is said to be large. Solved as expressions, identity modes take
    every frame's face-shape difference (and the solve grows with the number of shapes).
    """
    ident = [n for n in rig.names if IDENTITY_NAME.match(n)]
    if ident:
        prefixes = sorted({IDENTITY_NAME.match(n).group(1).lower().rstrip("0123456789") for n in ident})
        globs = " ".join(f"{option} '{p}*'" for p in prefixes)
        shown = ", ".join(ident[:3]) + (f", ... ({len(ident)} of {rig.n_shapes} shapes)" if len(ident) > 3 else
                                          f" ({len(ident)} of {rig.n_shapes} shapes)")
        return (f"warning: rig folder {rig.source}: shape names that look like identity modes, not expressions: "
                f"{shown}; leave them out with {globs}")
    if rig.n_shapes > MANY_SHAPES:
        return (f"warning: rig folder {rig.source}: {rig.n_shapes} shapes (more than {MANY_SHAPES}), all solved as "
                f"expressions; leave out what is not one with {option} GLOB")
    return None


def write_rig_folder(out_dir: str | os.PathLike, rig: Rig, neutral_name: str | None = "neutral.obj") -> None:
    """Write ``<shape>.obj`` (absolute positions) for every shape, plus the neutral, atomically."""
    with atomic_directory(out_dir) as stage:
        write_shapes(stage, rig, neutral_name)


def write_shapes(stage: Path, rig: Rig, neutral_name: str | None = "neutral.obj") -> None:
    """Write a rig's meshes into an existing (staging) folder."""
    if neutral_name:
        write_mesh(stage / neutral_name, rig.neutral, rig.faces)
    for name, d in zip(rig.names, rig.deltas):
        write_mesh(stage / f"{name}.obj", rig.neutral + d, rig.faces)


def load_target_neutral(path: str | os.PathLike, template: Rig) -> np.ndarray:
    """Read a target neutral and check it matches the template's topology."""
    V = read_mesh_like(path, template.n_vertices, template.faces, f"template {template.source}",
                       check_degenerate=True)
    return validate_vertices(V, str(path))
