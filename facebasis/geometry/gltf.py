"""Interchange: a rig as glTF 2.0 binary (``.glb``) with one named morph target per blendshape.

The file holds one mesh: POSITION (float32) and indices (uint32) of the neutral, and for every
blendshape a morph target whose POSITION attribute is the shape's delta (float32), as the glTF
specification defines morph targets. Target names go into ``mesh.extras.targetNames``, the
convention Blender, three.js and game engines read; default weights are 0. Written atomically.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np

from ..atomic import atomic_write_bytes
from .rig import Rig

_FLOAT, _UINT = 5126, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963


def glb_bytes(rig: Rig) -> bytes:
    """Serialise ``rig`` as a binary glTF 2.0 (GLB) file."""
    k = rig.n_shapes
    chunks, views, accessors = [], [], []
    offset = 0

    def add(data: np.ndarray, target: int, component: int, kind: str, minmax: bool) -> int:
        nonlocal offset
        raw = np.ascontiguousarray(data).tobytes()
        pad = (-len(raw)) % 4
        chunks.append(raw + b"\0" * pad)
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(raw), "target": target})
        acc = {"bufferView": len(views) - 1, "componentType": component, "count": int(len(data)), "type": kind}
        if minmax:
            acc["min"] = [float(v) for v in data.min(0)]
            acc["max"] = [float(v) for v in data.max(0)]
        accessors.append(acc)
        offset += len(raw) + pad
        return len(accessors) - 1

    pos = add(rig.neutral.astype(np.float32), _ARRAY_BUFFER, _FLOAT, "VEC3", True)
    idx = add(rig.faces.astype(np.uint32).ravel(), _ELEMENT_ARRAY_BUFFER, _UINT, "SCALAR", False)
    targets = [{"POSITION": add(d.astype(np.float32), _ARRAY_BUFFER, _FLOAT, "VEC3", True)} for d in rig.deltas]
    doc = {
        "asset": {"version": "2.0", "generator": "facebasis"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "face"}],
        "meshes": [{"name": "face", "primitives": [{"attributes": {"POSITION": pos}, "indices": idx, "mode": 4,
                                                     "targets": targets}],
                    "weights": [0.0] * k, "extras": {"targetNames": list(rig.names)}}],
        "buffers": [{"byteLength": offset}],
        "bufferViews": views,
        "accessors": accessors,
    }
    return glb_container(doc, chunks)


def glb_container(doc: dict, chunks) -> bytes:
    """The GLB file of a glTF JSON document ``doc`` and its binary buffer, given as 4-byte aligned
    ``chunks`` in buffer order: a 12-byte header, the JSON chunk padded with spaces and the BIN
    chunk (glTF 2.0 specification, section "GLB File Format Specification")."""
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * ((-len(js)) % 4)
    binary = b"".join(chunks)
    total = 12 + 8 + len(js) + 8 + len(binary)
    return (struct.pack("<4sII", b"glTF", 2, total) + struct.pack("<I4s", len(js), b"JSON") + js
            + struct.pack("<I4s", len(binary), b"BIN\0") + binary)


def write_glb(rig: Rig, path) -> Path:
    """Write ``rig`` to ``path`` (``.glb``) atomically; returns the path."""
    path = Path(path)
    atomic_write_bytes(path, glb_bytes(rig))
    return path


__all__ = ["glb_bytes", "glb_container", "write_glb"]
