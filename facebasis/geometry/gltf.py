"""Interchange: a rig as glTF 2.0 (``.glb`` binary or ``.gltf`` JSON + ``.bin``) that tools take as it is.

* **Units.** glTF's unit is the metre (glTF 2.0 specification, section 3.4 "Coordinate System and
  Units"). Positions and morph-target deltas are scaled from the source unit (``unit``: ``cm``
  (default: ICT-FaceKit's rigs and the package's built-in face are in centimetres), ``m`` or ``mm``)
  to metres; the source unit and the factor are recorded in ``asset.extras``
  (``sourceUnit``, ``metresPerSourceUnit``).
* **Normals.** ``NORMAL`` of the rest mesh and, per morph target, the change of the normals
  (``NORMAL`` of the target = normal of the shape minus normal of the neutral, as the specification
  defines target attributes), all area-weighted (:func:`~facebasis.geometry.objlayout.layout_normals`),
  so that a renderer needs to recompute nothing and no seam shows where UVs split vertices.
* **UVs and materials** of a template OBJ (its :class:`~facebasis.geometry.objlayout.ObjLayout`):
  glTF vertices are the distinct (``v``, ``vt``, ``vn``) corners of the OBJ's faces (a vertex on a
  UV seam is split, its positions and deltas copied), ``TEXCOORD_0`` = (u, 1 - v) (glTF's UV origin
  is the image's top left, OBJ's its bottom left), one primitive per ``usemtl`` material, each a
  metallic-roughness material from the MTL's ``Kd``/``d`` and its ``map_Kd`` texture (PNG or JPEG:
  embedded in a ``.glb``, copied beside a ``.gltf`` and referenced by name). Without a layout: one
  primitive, one plain material, no UVs.
* **Container by extension**: ``.glb`` is the binary container; ``.gltf`` is the JSON with a
  ``<stem>.bin`` buffer beside it; any other suffix is an error, and so is a missing parent folder
  (raised by :func:`check_gltf_path` before any work).

Morph targets keep their names in ``mesh.extras.targetNames`` (read by Blender, three.js, game
engines); default weights are 0.

**Writer.** The package's own buffer builder (:class:`GltfBuffer`), not pygltflib (a test
dependency that reads the files back in the tests): on the 53-shape ICT rig the two write the same
binary buffer (sizes within a few hundred bytes of JSON), but pygltflib's dataclass-to-JSON
serialisation and its per-accessor objects make it slower (``python -m problems.bench_gltf``
compares them), and the builder adds no run-time dependency.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np

from ..atomic import atomic_write_bytes
from ..errors import InputError, named_params
from .rig import Rig

_FLOAT, _UINT = 5126, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963

#: metres per source unit
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
#: the source unit when none is given: ICT-FaceKit's rigs and the built-in face are in centimetres
DEFAULT_UNIT = "cm"
GLTF_SUFFIXES = (".glb", ".gltf")
_MIME = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg"}


def unit_scale(unit: str, what: str = "{unit}") -> float:
    """Metres per ``unit`` (``cm``, ``m`` or ``mm``); :class:`InputError` for anything else (``what``
    names it, a ``{name}`` placeholder for a library parameter, see :mod:`facebasis.errors`)."""
    if unit not in UNITS:
        raise InputError(what=what, expected=f"one of {', '.join(UNITS)} (the source unit)", found=repr(unit),
                         params=named_params(what))
    return UNITS[unit]


def check_gltf_path(path, what: str = "path") -> Path:
    """A glTF output path: suffix ``.glb`` or ``.gltf`` and an existing parent folder, else
    :class:`InputError` naming the option and the path."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"output file {path}: expected a file name, found a folder")  # as every command says it
    if path.suffix.lower() not in GLTF_SUFFIXES:
        raise InputError(f"{what} {path}: expected a file ending in .glb (binary glTF) or .gltf (JSON + .bin), "
                         f"found {path.suffix or 'no suffix'!r}")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"{what} {path}: expected an existing folder {parent}, found "
                         f"{'a file' if parent.exists() else 'no such folder'}")
    return path


class GltfBuffer:
    """One binary buffer of accessors, built in order (4-byte aligned views)."""

    def __init__(self):
        self.chunks, self.views, self.accessors = [], [], []
        self.offset = 0

    def view(self, raw: bytes, target: int | None = None) -> int:
        pad = (-len(raw)) % 4
        self.chunks.append(raw + b"\0" * pad)
        v = {"buffer": 0, "byteOffset": self.offset, "byteLength": len(raw)}
        if target is not None:
            v["target"] = target
        self.views.append(v)
        self.offset += len(raw) + pad
        return len(self.views) - 1

    def add(self, data: np.ndarray, kind: str, target: int | None = None, minmax=False) -> int:
        """An accessor of ``data`` (float32 or uint32; (count,) for SCALAR, (count, c) otherwise);
        ``minmax``: True to store its bounds, or the bounds (lo, hi) already computed."""
        data = np.ascontiguousarray(data)
        component = _UINT if data.dtype == np.uint32 else _FLOAT
        count = int(data.size if kind == "SCALAR" else len(data))
        acc = {"bufferView": self.view(data.tobytes(), target), "componentType": component, "count": count,
               "type": kind}
        if minmax is True:
            d2 = data.reshape(count, -1)
            minmax = d2.min(0), d2.max(0)
        if minmax is not False:
            acc["min"] = [float(v) for v in minmax[0]]
            acc["max"] = [float(v) for v in minmax[1]]
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def binary(self) -> bytes:
        return b"".join(self.chunks)


# ---------------------------------------------------------------------- the mesh
def _corner_keys(layout, F):
    """glTF vertices of a layout: the distinct (v, vt, vn) corners -> (vertex of each glTF vertex,
    uv index or None, normal slot, triangles (m, 3) in glTF vertices)."""
    m = len(F)
    key = F.ravel().astype(np.int64)
    uvi = layout.face_uv.ravel() if layout is not None and layout.face_uv is not None else None
    nvi = layout.face_normal.ravel() if layout is not None and layout.face_normal is not None else None
    if uvi is not None:
        key = key * (len(layout.uv) + 1) + (uvi + 1)
    if nvi is not None:
        key = key * (len(layout.normals) + 1) + (nvi + 1)
    if uvi is None and nvi is None:
        return None
    uniq, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    gv = F.ravel()[first]
    return (gv, None if uvi is None else uvi[first], None if nvi is None else nvi[first],
            inverse.reshape(m, 3).astype(np.uint32))


def _gl_normals(V, F, layout, split):
    """Area-weighted normals (g, 3) (or (k, g, 3) for positions (k, n, 3)) at the glTF vertices."""
    from .objlayout import layout_normals

    if split is not None and split[2] is not None:
        N = layout_normals(V, F, layout.face_normal, layout.normals, np.float32)
        slot = split[2]
        out = N[..., np.maximum(slot, 0), :]
        if (slot < 0).any():  # corners without vn: their vertex normal
            per_v = layout_normals(V, F, dtype=np.float32)
            out[..., slot < 0, :] = per_v[..., split[0][slot < 0], :]
        return out
    N = layout_normals(V, F, dtype=np.float32)
    return N if split is None else N[..., split[0], :]


def gltf_document(neutral, faces, targets, names, *, unit: str = DEFAULT_UNIT, layout=None, name: str = "face",
                  weights=None, animation: dict | None = None, normals: bool = True, extras: dict | None = None,
                  embed_images: bool = True):
    """The glTF JSON document and binary buffer of a morph-target mesh.

    Parameters
    ----------
    neutral : (n, 3) rest positions (source unit); faces : (m, 3) triangles
    targets : (k, n, 3) morph-target deltas (source unit); names : k target names
    unit : the source unit (``cm``, ``m``, ``mm``); everything written is in metres
    layout : the template OBJ's :class:`~facebasis.geometry.objlayout.ObjLayout` (UVs, normals
        slots, materials) of this topology, or None
    weights : (k,) default morph weights (0 when None)
    animation : None or a dict with ``times`` (T,) seconds and any of ``weights`` (T, k),
        ``rotation`` (T, 4) unit quaternions (x, y, z, w), ``translation`` (T, 3) metres, and
        ``name``: one glTF animation of node 0, LINEAR
    normals : write NORMAL of the rest mesh and of the targets
    extras : more entries for ``asset.extras``
    embed_images : textures into the buffer (GLB); else referenced by file name (``.gltf``)

    Returns
    -------
    doc : dict, the glTF JSON; buf : :class:`GltfBuffer`; images : [(file name, source path)] of the
    textures referenced by name (``embed_images=False``)
    """
    scale = unit_scale(unit, "unit")
    V = np.asarray(neutral, np.float64)
    F = np.asarray(faces, np.int64)
    D = np.asarray(targets, np.float64).reshape(-1, len(V), 3)
    k = len(D)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
        raise InputError(f"glTF: expected neutral (n, 3) and faces (m, 3), found {V.shape}, {F.shape}")
    if len(names) != k:
        raise InputError(f"glTF: expected {k} target names, found {len(names)}")
    if not (np.isfinite(V).all() and np.isfinite(D).all()):
        raise InputError("glTF: expected finite positions and targets, found NaN/inf")
    if layout is not None and not layout.matches(len(V), F):
        layout = None
    split = _corner_keys(layout, F)
    gv = np.arange(len(V)) if split is None else split[0]
    tri = F.astype(np.uint32) if split is None else split[3]
    buf = GltfBuffer()
    attrs = {"POSITION": buf.add((V[gv] * scale).astype(np.float32), "VEC3", _ARRAY_BUFFER, True)}
    N0 = None
    if normals:
        N0 = _gl_normals(V, F, layout, split)
        attrs["NORMAL"] = buf.add(N0.astype(np.float32), "VEC3", _ARRAY_BUFFER)
    if split is not None and split[1] is not None:
        uv = np.zeros((len(gv), 2))
        has = split[1] >= 0
        uv[has] = layout.uv[split[1][has]]
        uv[:, 1] = 1.0 - uv[:, 1]
        attrs["TEXCOORD_0"] = buf.add(uv.astype(np.float32), "VEC2", _ARRAY_BUFFER)
    tgts = _morph_targets(buf, V, F, D, gv, layout, split, scale, N0)
    # materials and primitives
    doc_materials, textures, images, samplers, referenced = [], [], [], [], []
    if layout is not None and layout.material_names:
        fm = layout.face_material
        groups = [(i, np.flatnonzero(fm == i)) for i in range(-1, len(layout.material_names))]
        groups = [(i, f) for i, f in groups if len(f)]
        mats = [(None if i < 0 else layout.materials[i]) for i, _ in groups]
    else:
        groups, mats = [(-1, np.arange(len(F)))], [None]
    tex_of_path: dict = {}
    for mat in mats:
        doc_materials.append(_material(mat, buf, textures, images, samplers, tex_of_path, referenced, embed_images,
                                       has_uv="TEXCOORD_0" in attrs))
    prims = []
    for j, (_, f) in enumerate(groups):
        p = {"attributes": attrs, "indices": buf.add(tri[f].ravel(), "SCALAR", _ELEMENT_ARRAY_BUFFER), "mode": 4,
             "material": j}
        if k:
            p["targets"] = tgts
        prims.append(p)
    mesh = {"name": name, "primitives": prims, "extras": {"targetNames": [str(s) for s in names]}}
    if k:
        w0 = np.zeros(k) if weights is None else np.asarray(weights, np.float64)
        mesh["weights"] = [float(v) for v in w0]
    asset_extras = {"sourceUnit": unit, "metresPerSourceUnit": scale, **(extras or {})}
    doc = {
        "asset": {"version": "2.0", "generator": "facebasis", "extras": asset_extras},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": name}],
        "meshes": [mesh],
        "materials": doc_materials,
    }
    if textures:
        doc.update(textures=textures, images=images, samplers=samplers)
    if animation is not None:
        _animation(doc, buf, animation, k)
    return doc, buf, referenced


def _morph_targets(buf, V, F, D, gv, layout, split, scale: float, N0) -> list:
    """The glTF targets of the deltas ``D`` (k, n, 3) (source unit) at the glTF vertices ``gv``:
    POSITION (metres, with its bounds) and, when the rest normals ``N0`` are given, NORMAL deltas;
    added to ``buf`` shape by shape, 16 shapes per batch (one sparse product for their normals)."""
    tgts = []
    for s0 in range(0, len(D), 16):
        Dg = (D[s0:s0 + 16, gv] * scale).astype(np.float32)
        lo, hi = Dg.min(1), Dg.max(1)
        dN = _gl_normals(V + D[s0:s0 + 16], F, layout, split) - N0 if N0 is not None else None
        for j, d in enumerate(Dg):
            t = {"POSITION": buf.add(d, "VEC3", _ARRAY_BUFFER, (lo[j], hi[j]))}
            if N0 is not None:
                t["NORMAL"] = buf.add(dN[j].astype(np.float32), "VEC3", _ARRAY_BUFFER)
            tgts.append(t)
    return tgts


def _material(mat, buf, textures, images, samplers, tex_of_path, referenced, embed: bool, has_uv: bool) -> dict:
    kd = (0.8, 0.8, 0.8) if mat is None else tuple(float(c) for c in mat.kd)
    alpha = 1.0 if mat is None else float(mat.d)
    out = {"name": "facebasis_default" if mat is None else mat.name,
           "pbrMetallicRoughness": {"baseColorFactor": [*kd, alpha], "metallicFactor": 0.0, "roughnessFactor": 0.6}}
    if alpha < 1.0:
        out["alphaMode"] = "BLEND"
    path = None if mat is None else mat.map_kd_path
    if path is not None and has_uv and path.suffix.lower() in _MIME:
        if path not in tex_of_path:
            if not samplers:
                samplers.append({"magFilter": 9729, "minFilter": 9987, "wrapS": 10497, "wrapT": 10497})
            if embed:
                images.append({"bufferView": buf.view(path.read_bytes()), "mimeType": _MIME[path.suffix.lower()],
                               "name": path.stem})
            else:
                images.append({"uri": path.name, "name": path.stem})
                referenced.append((path.name, path))
            textures.append({"source": len(images) - 1, "sampler": 0})
            tex_of_path[path] = len(textures) - 1
        out["pbrMetallicRoughness"]["baseColorFactor"] = [1.0, 1.0, 1.0, alpha]  # the texture is the colour
        out["pbrMetallicRoughness"]["baseColorTexture"] = {"index": tex_of_path[path]}
    return out


def _animation(doc: dict, buf: GltfBuffer, anim: dict, k: int) -> None:
    t = np.asarray(anim["times"], np.float32).reshape(-1)
    if len(t) < 1 or not np.isfinite(t).all() or (len(t) > 1 and not np.all(np.diff(t) > 0)):
        raise InputError("animated glTF: expected finite, strictly increasing key times")
    t_acc = buf.add(t, "SCALAR", None, True)
    samplers, channels = [], []
    for path, kind, width in (("weights", "SCALAR", k), ("rotation", "VEC4", 4), ("translation", "VEC3", 3)):
        data = anim.get(path)
        if data is None or (path == "weights" and k == 0):
            continue
        a = np.asarray(data, np.float32)
        if a.shape != (len(t), width):
            raise InputError(f"animated glTF: expected {path} of shape ({len(t)}, {width}), found {a.shape}")
        if not np.isfinite(a).all():
            raise InputError(f"animated glTF: expected finite {path}, found NaN/inf")
        samplers.append({"input": t_acc, "output": buf.add(a.ravel() if kind == "SCALAR" else a, kind),
                         "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": 0, "path": path}})
    if channels:
        doc["animations"] = [{"name": anim.get("name", "capture"), "samplers": samplers, "channels": channels}]


# ---------------------------------------------------------------------- containers
def glb_container(doc: dict, chunks) -> bytes:
    """The GLB file of a glTF JSON document ``doc`` and its binary buffer, given as 4-byte aligned
    ``chunks`` in buffer order: a 12-byte header, the JSON chunk padded with spaces and the BIN
    chunk (glTF 2.0 specification, section "GLB File Format Specification")."""
    binary = b"".join(chunks)
    doc = dict(doc, buffers=[{"byteLength": len(binary)}])
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * ((-len(js)) % 4)
    total = 12 + 8 + len(js) + 8 + len(binary)
    return (struct.pack("<4sII", b"glTF", 2, total) + struct.pack("<I4s", len(js), b"JSON") + js
            + struct.pack("<I4s", len(binary), b"BIN\0") + binary)


def _finish(doc: dict, buf: GltfBuffer) -> dict:
    doc = dict(doc)
    doc["bufferViews"] = buf.views
    doc["accessors"] = buf.accessors
    return doc


def write_document(path, doc: dict, buf: GltfBuffer, referenced=()) -> Path:
    """Write a document built by :func:`gltf_document` as ``.glb`` or as ``.gltf`` + ``<stem>.bin``
    (and its referenced textures copied beside it), each file atomically."""
    path = check_gltf_path(path, "glTF output")
    doc = _finish(doc, buf)
    if path.suffix.lower() == ".glb":
        atomic_write_bytes(path, glb_container(doc, buf.chunks))
        return path
    binary = buf.binary()
    bin_name = path.stem + ".bin"
    doc["buffers"] = [{"byteLength": len(binary), "uri": bin_name}]
    textures = [(path.parent / fname, Path(src).read_bytes()) for fname, src in referenced]
    for dest, data in textures:  # a texture copy never replaces a different file of the user's: checked first
        if dest.exists() and (dest.is_dir() or dest.read_bytes() != data):
            from ..errors import InputError

            raise InputError(f"glTF output {path}: expected to copy the texture {dest.name} beside it, found a "
                             f"different {'folder' if dest.is_dir() else 'file'} {dest} there (it would be "
                             "overwritten); write the .gltf elsewhere or use .glb (textures embedded)")
    for dest, data in textures:
        if not dest.exists():
            atomic_write_bytes(dest, data)
    atomic_write_bytes(path.parent / bin_name, binary)
    atomic_write_bytes(path, json.dumps(doc, separators=(",", ":")).encode())
    return path


def glb_bytes(rig: Rig, unit: str = DEFAULT_UNIT, layout=None) -> bytes:
    """Serialise ``rig`` as a binary glTF 2.0 (GLB) file (see the module docstring)."""
    doc, buf, _ = gltf_document(rig.neutral, rig.faces, rig.deltas, rig.names, unit=unit,
                                layout=layout if layout is not None else rig.layout)
    return glb_container(_finish(doc, buf), buf.chunks)


def write_glb(rig: Rig, path, unit: str = DEFAULT_UNIT, layout=None) -> Path:
    """Write ``rig`` to ``path`` (``.glb`` binary, or ``.gltf`` JSON + ``.bin``) atomically, with the
    template's UVs and materials (``layout``, else the rig's own); returns the path."""
    check_gltf_path(path, "glTF output")
    embed = Path(path).suffix.lower() == ".glb"
    doc, buf, refs = gltf_document(rig.neutral, rig.faces, rig.deltas, rig.names, unit=unit,
                                   layout=layout if layout is not None else rig.layout, embed_images=embed)
    return write_document(path, doc, buf, refs)


__all__ = ["UNITS", "DEFAULT_UNIT", "unit_scale", "check_gltf_path", "GltfBuffer", "gltf_document", "glb_container",
           "write_document", "glb_bytes", "write_glb"]
