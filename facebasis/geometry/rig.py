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
from ..errors import NamedText, RigError, TopologyError, named_params
from .meshio import MESH_SUFFIXES, read_mesh, read_mesh_like, write_mesh
from .mesh import validate_mesh, validate_vertices
from .objlayout import read_obj_layout


#: the parameter a rig folder's errors name (the command line writes ``--exclude``)
_EXCLUDE = {"exclude": "exclude"}


@dataclass(frozen=True)
class Rig:
    """A delta blendshape rig.

    Attributes
    ----------
    neutral : (n, 3) float64, the rest face ``S0`` (or ``B0``)
    faces : (m, 3) int64
    names : tuple of k shape names
    deltas : (k, n, 3) float64, ``S_i - S0`` for each shape
    source : where the rig came from (for messages)
    layout : the template OBJ's layout, or None (see :mod:`facebasis.geometry.objlayout`)
    """

    neutral: np.ndarray
    faces: np.ndarray
    names: tuple[str, ...]
    deltas: np.ndarray
    source: str = field(default="rig", compare=False)
    #: the neutral OBJ's own layout (:class:`~facebasis.geometry.objlayout.ObjLayout`: UVs, normals,
    #: materials, groups, polygons) for writing shapes as the template was written; None: plain
    layout: object = field(default=None, compare=False, repr=False)

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

    def index(self, names: Sequence[str], what: str = "shape names", params: dict | None = None,
              named: dict | None = None) -> np.ndarray:
        """Indices of ``names``; :class:`RigError` naming the unknown ones with the nearest known name
        of each (``jawOpem``: did you mean ``jawOpen``?), or the known ones when none is near.
        ``params`` ({placeholder: parameter name}) makes it a structured error whose ``what`` names a
        caller's parameter (:class:`facebasis.errors.FacebasisError`); without it, ``named`` ({placeholder:
        parameter name}) are the ``{name}`` placeholders in ``what`` (``"{exclusive}"``) of the same message."""
        import difflib

        lookup = {s: i for i, s in enumerate(self.names)}
        unknown = [s for s in names if s not in lookup]
        if unknown:
            near = {s: difflib.get_close_matches(s, self.names, n=1, cutoff=0.75) for s in unknown}
            if all(near.values()):
                hint = "; did you mean " + ", ".join(f"{near[s][0]!r} for {s!r}" for s in unknown) + "?"
            else:
                shown = list(self.names[:12]) + (["..."] if self.n_shapes > 12 else [])
                hint = f"; expected names of {self.source} ({self.n_shapes}): {', '.join(shown)}"
            if params:
                raise RigError(what=what, expected=f"names of {self.source}'s {self.n_shapes} shapes",
                               found=f"unknown blendshape names {unknown}", note=hint, params=params)
            raise RigError(f"{what}: unknown blendshape names {unknown}{hint}", params=named)
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
        return Rig(neutral, self.faces, self.names, deltas, source or self.source, self.layout)


def _matches(p: Path, glob: str) -> bool:
    """An ``exclude`` glob matches a file by its name or its stem."""
    return fnmatch.fnmatch(p.name, glob) or fnmatch.fnmatch(p.stem, glob)


def _mesh_files(folder: Path, exclude: Sequence[str], excluded_later: Sequence[str] = ()) -> list[Path]:
    """Mesh files of ``folder`` by name, without hidden ones (``.name``: editors' and macOS's
    ``._name`` companions) and those matching an ``exclude`` glob. A mesh name that is a symbolic
    link leading nowhere (or in a loop) is a :class:`RigError` naming it, not a shape dropped."""
    named = [p for p in sorted(folder.iterdir())
             if p.suffix.lower() in MESH_SUFFIXES and not p.name.startswith(".")
             and not any(_matches(p, g) for g in exclude)]
    broken = [p for p in named if p.is_symlink() and not p.exists()
              and not any(_matches(p, g) for g in excluded_later)]
    if broken:
        shown = ", ".join(f"{p.name} -> {os.readlink(p)}" for p in broken[:3])
        raise RigError(f"rig folder {folder}: expected every mesh file to be readable, found "
                       f"{len(broken)} symbolic link{'s' if len(broken) > 1 else ''} leading nowhere ({shown}"
                       f"{' and more' if len(broken) > 3 else ''}); restore the target or remove the link, or "
                       "leave it out with {exclude}", params=_EXCLUDE)
    return [p for p in named if p.is_file()]


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
    every = _mesh_files(folder, (), exclude)  # the folder listed once
    if not neutral_path.is_file():
        raise RigError(
            f"rig folder {folder}: expected the neutral '{neutral}', found no such file "
            f"(mesh files there: {[p.name for p in every][:10]}); name it with {{neutral}}",
            params={"neutral": "neutral"}
        )
    unmatched = [g for g in exclude if not any(_matches(p, g) for p in every)]
    if unmatched:  # a pattern may match a broken link left out on purpose
        links = [p for p in folder.iterdir() if p.is_symlink() and not p.exists()]
        unmatched = [g for g in unmatched if not any(_matches(p, g) for p in links)]
    if unmatched:  # a typo would otherwise keep the meshes the user meant to leave out
        raise RigError(f"rig folder {folder}: expected every {{exclude}} pattern to match a mesh file, found none for "
                       f"{', '.join(repr(g) for g in unmatched)} (mesh files there: {[p.name for p in every][:10]})",
                       params=_EXCLUDE)
    V0, F0 = read_mesh(neutral_path, check_degenerate=True)
    names, deltas = [], []
    from ..progress import progress

    for p in progress(every, desc=f"reading {folder}"):
        if any(_matches(p, g) for g in exclude) or p.resolve() == neutral_path.resolve():
            continue
        V = read_mesh_like(p, len(V0), F0, str(neutral_path))
        names.append(p.stem)
        deltas.append(V - V0)
    if not names:
        raise RigError(f"rig folder {folder}: expected blendshape meshes beside '{neutral}', found none")
    layout = read_obj_layout(neutral_path)
    if layout is not None and not layout.matches(len(V0), F0):
        layout = None  # pragma: no cover - both read the same file the same way
    return Rig(V0, F0, tuple(names), np.stack(deltas), source=str(folder), layout=layout)


#: shape names that look like identity (face-shape) modes rather than expressions: ICT-FaceKit's
#: ``identity000``..``identity099``, and ``id_*`` / ``id<digits>`` spellings
IDENTITY_NAME = re.compile(r"^(identity|id_|id\d)", re.IGNORECASE)
#: more shapes than this in a folder gets a warning (a FACS/ARKit rig has 50-60 expressions)
MANY_SHAPES = 100


def rig_folder_warning(rig: Rig, option: str = "{exclude}") -> str | None:
    """A one-line warning for a rig folder that is probably not only expressions, or None.

    Shape names that look like identity modes (:data:`IDENTITY_NAME`) are named (the first few and
    how many) with the ``option`` glob that leaves them out (a :class:`facebasis.errors.NamedText`:
    the command line writes ``{exclude}`` as ``--exclude``); otherwise a folder of more than
    :data:`MANY_SHAPES` shapes is said to be large. Solved as expressions, identity modes take
    every frame's face-shape difference (and the solve grows with the number of shapes).
    """
    ident = [n for n in rig.names if IDENTITY_NAME.match(n)]
    if ident:
        prefixes = sorted({IDENTITY_NAME.match(n).group(1).lower().rstrip("0123456789") for n in ident})
        globs = " ".join(f"{option} '{p}*'" for p in prefixes)
        shown = ", ".join(ident[:3]) + (f", ... ({len(ident)} of {rig.n_shapes} shapes)" if len(ident) > 3 else
                                          f" ({len(ident)} of {rig.n_shapes} shapes)")
        return NamedText(f"warning: rig folder {rig.source}: shape names that look like identity modes, not "
                         f"expressions: {shown}; leave them out with {globs}", named_params(option))
    if rig.n_shapes > MANY_SHAPES:
        return NamedText(f"warning: rig folder {rig.source}: {rig.n_shapes} shapes (more than {MANY_SHAPES}), all "
                         f"solved as expressions; leave out what is not one with {option} GLOB", named_params(option))
    return None


def write_rig_folder(out_dir: str | os.PathLike, rig: Rig, neutral_name: str | None = "neutral.obj",
                     layout=None) -> list[str]:
    """Write ``<shape>.obj`` (absolute positions) for every shape, plus the neutral, atomically
    (see :func:`write_shapes`); returns the side files the layout names but the template lacks."""
    with atomic_directory(out_dir) as stage:
        return write_shapes(stage, rig, neutral_name, layout)


def write_shapes(stage: Path, rig: Rig, neutral_name: str | None = "neutral.obj", layout=None) -> list[str]:
    """Write a rig's meshes into an existing (staging) folder.

    With a layout (``layout``, else the rig's own, :attr:`Rig.layout`) of the rig's topology every
    OBJ is the template's file with its positions (and normals) replaced, and the template's MTL
    files and textures are copied beside them (:mod:`facebasis.geometry.objlayout`); without one
    the plain ``v``/``f`` OBJ of :func:`~facebasis.geometry.obj.obj_bytes`. Returns the MTL files
    and textures the template names but lacks (nothing to copy)."""
    from ..atomic import atomic_write_bytes
    from ..progress import progress
    from .objlayout import copy_side_files

    layout = layout if layout is not None else rig.layout
    if layout is not None and not layout.matches(rig.n_vertices, rig.faces):
        layout = None  # another topology: plain files
    if layout is None:
        if neutral_name:
            write_mesh(stage / neutral_name, rig.neutral, rig.faces)
        for name, d in progress(zip(rig.names, rig.deltas), total=rig.n_shapes, desc="writing shapes"):
            write_mesh(stage / f"{name}.obj", rig.neutral + d, rig.faces)
        return []
    if neutral_name and not neutral_name.lower().endswith(".obj"):
        write_mesh(stage / neutral_name, rig.neutral, rig.faces)
    elif neutral_name:
        atomic_write_bytes(stage / neutral_name, layout.obj_bytes(rig.neutral))
    for name, d in progress(zip(rig.names, rig.deltas), total=rig.n_shapes, desc="writing shapes"):
        atomic_write_bytes(stage / f"{name}.obj", layout.obj_bytes(rig.neutral + d))
    return copy_side_files(layout, stage)


def load_target_neutral(path: str | os.PathLike, template: Rig) -> np.ndarray:
    """Read a target neutral and check it matches the template's topology."""
    V = read_mesh_like(path, template.n_vertices, template.faces, f"template {template.source}",
                       check_degenerate=True)
    return validate_vertices(V, str(path))
