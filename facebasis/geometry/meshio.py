"""Reading and writing meshes (OBJ, PLY) with vertex order preserved exactly.

OBJ goes through the package's own vectorised reader and writer (:mod:`facebasis.geometry.obj`;
a rig's later shapes reuse the ``f`` lines parsed once): any OBJ an artist or scanner writes (groups,
materials, ``vt``/``vn``, n-gons, comments), the file's vertex order always, and the faces and
bytes trimesh would give where trimesh keeps the vertices. PLY goes through trimesh with
``process=False, maintain_order=True``: no vertex is merged, dropped or reordered. A quad
``a b c d`` becomes ``(a, b, c), (c, d, a)`` (in an all-quad file the first halves of all quads,
then the second halves). OBJ output keeps 10 decimals; binary PLY output stores float32
coordinates.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..atomic import atomic_write_bytes
from ..errors import MeshError, TopologyError
from .mesh import same_topology, validate_mesh
from .obj import obj_bytes, read_obj

MESH_SUFFIXES = (".obj", ".ply")


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
    path = Path(path)
    name = str(path)
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise MeshError(f"{name}: expected a mesh file ending in .obj or .ply, found '{path.suffix}'")
    if not path.is_file():
        raise MeshError(f"{name}: expected a mesh file, found {'a folder' if path.is_dir() else 'no such file'}")
    if path.stat().st_size == 0:
        raise MeshError(f"{name}: expected a mesh, found an empty file")
    if path.suffix.lower() == ".obj":
        V, F = read_obj(path)
    else:
        V, F = _read_with_trimesh(path)
    if len(V) == 0 or len(F) == 0:
        raise MeshError(
            f"{name}: expected vertices and faces, found {len(V)} vertices and {len(F)} faces"
        )
    return validate_mesh(V, F, name, check_degenerate=check_degenerate)


def _read_with_trimesh(path: Path) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    try:
        mesh = trimesh.load(path, process=False, maintain_order=True, force="mesh")
    except Exception as exc:  # trimesh raises many types for corrupt files
        raise MeshError(f"{path}: unreadable mesh file ({type(exc).__name__}: {exc})") from exc
    if not isinstance(mesh, trimesh.Trimesh):
        raise MeshError(f"{path}: expected one triangle mesh, found {type(mesh).__name__}")
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


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
    """Serialise a mesh as OBJ or PLY bytes (vertex order kept, 10 decimals in OBJ)."""
    suffix = suffix.lower()
    if suffix == ".obj":
        return obj_bytes(V, F)
    if suffix == ".ply":
        import trimesh

        mesh = trimesh.Trimesh(vertices=np.asarray(V, float), faces=np.asarray(F, np.int64), process=False)
        return trimesh.exchange.ply.export_ply(mesh, encoding="binary", include_attributes=False)
    raise MeshError(f"expected an output suffix .obj or .ply, found '{suffix}'")


def write_mesh(path: str | os.PathLike, V: np.ndarray, F: np.ndarray) -> None:
    """Write a mesh to ``path`` (format from the suffix), atomically."""
    path = Path(path)
    atomic_write_bytes(path, mesh_bytes(V, F, path.suffix))
