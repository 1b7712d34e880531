"""Reading and writing meshes (OBJ, PLY) through trimesh, with vertex order preserved exactly.

trimesh is called with ``process=False, maintain_order=True``: no vertex is merged, dropped or
reordered, and texture seams do not split vertices. A quad ``a b c d`` always becomes
``(a, b, c), (c, d, a)``; trimesh lists the first halves of all quads, then the second halves, so
the face order of a quad file is deterministic but not the file's polygon order. For OBJ the vertex
count is checked against the file's own ``v`` lines, so a silent reorder or drop can never pass.
OBJ output keeps 10 significant digits; binary PLY output stores float32 coordinates.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..atomic import atomic_write_bytes
from ..errors import MeshError, TopologyError
from .mesh import same_topology, validate_mesh

MESH_SUFFIXES = (".obj", ".ply")


def _count_obj_vertices(path: Path) -> int:
    n = 0
    with open(path, "rb") as fh:
        for line in fh:
            if line.startswith(b"v ") or line.startswith(b"v\t"):
                n += 1
    return n


def read_mesh(path: str | os.PathLike, *, check_degenerate: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Read an OBJ or PLY triangle/polygon mesh.

    Parameters
    ----------
    path : path to a ``.obj`` or ``.ply`` file
    check_degenerate : also reject zero-area / near-degenerate triangles

    Returns
    -------
    V : (n, 3) float64, in file order
    F : (m, 3) int64, polygons fanned from their first vertex

    Raises
    ------
    MeshError
        Missing, empty or unreadable file, unsupported suffix, no faces, or any check of
        :func:`facebasis.geometry.mesh.validate_mesh`; the message names the file.
    """
    import trimesh

    path = Path(path)
    name = str(path)
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise MeshError(f"{name}: expected a mesh file ending in .obj or .ply, found '{path.suffix}'")
    if not path.is_file():
        raise MeshError(f"{name}: expected a mesh file, found no such file")
    if path.stat().st_size == 0:
        raise MeshError(f"{name}: expected a mesh, found an empty file")
    try:
        mesh = trimesh.load(path, process=False, maintain_order=True, force="mesh")
    except Exception as exc:  # trimesh raises many types for corrupt files
        raise MeshError(f"{name}: unreadable mesh file ({type(exc).__name__}: {exc})") from exc
    if not isinstance(mesh, trimesh.Trimesh):
        raise MeshError(f"{name}: expected one triangle mesh, found {type(mesh).__name__}")
    V = np.asarray(mesh.vertices, dtype=np.float64)
    F = np.asarray(mesh.faces, dtype=np.int64)
    if len(V) == 0 or len(F) == 0:
        raise MeshError(
            f"{name}: expected vertices and faces, found {len(V)} vertices and {len(F)} faces"
        )
    if path.suffix.lower() == ".obj":
        n_file = _count_obj_vertices(path)
        if n_file != len(V):
            raise MeshError(
                f"{name}: expected the {n_file} vertices of the file in order, found {len(V)} after "
                "loading (the file references vertices that do not exist or the loader reordered them)"
            )
    return validate_mesh(V, F, name, check_degenerate=check_degenerate)


def read_mesh_like(path: str | os.PathLike, n_vertices: int, F_ref: np.ndarray, ref_name: str, *,
                   check_degenerate: bool = False) -> np.ndarray:
    """Read a mesh that must have the topology of a reference (``n_vertices`` vertices, faces
    ``F_ref`` in the same order); returns its vertices (n, 3).

    Raises :class:`TopologyError` naming ``path`` and ``ref_name`` with the expected and found
    vertex count, or the first differing face (:func:`~facebasis.geometry.mesh.same_topology`).
    """
    V, F = read_mesh(path, check_degenerate=check_degenerate)
    if len(V) != n_vertices:
        raise TopologyError(f"{path}: expected {n_vertices} vertices as in {ref_name}, found {len(V)}")
    same_topology(F_ref, F, str(path), ref_name)
    return V


def mesh_bytes(V: np.ndarray, F: np.ndarray, suffix: str = ".obj") -> bytes:
    """Serialise a mesh as OBJ or PLY bytes (vertex order kept, 10 significant digits in OBJ)."""
    import trimesh

    mesh = trimesh.Trimesh(vertices=np.asarray(V, float), faces=np.asarray(F, np.int64), process=False)
    suffix = suffix.lower()
    if suffix == ".obj":
        text = trimesh.exchange.obj.export_obj(
            mesh, include_normals=False, include_color=False, include_texture=False, digits=10,
            header=None,
        )
        return text.encode()
    if suffix == ".ply":
        return trimesh.exchange.ply.export_ply(mesh, encoding="binary", include_attributes=False)
    raise MeshError(f"expected an output suffix .obj or .ply, found '{suffix}'")


def write_mesh(path: str | os.PathLike, V: np.ndarray, F: np.ndarray) -> None:
    """Write a mesh to ``path`` (format from the suffix), atomically."""
    path = Path(path)
    atomic_write_bytes(path, mesh_bytes(V, F, path.suffix))
