"""Animated glTF 2.0 binary (``.glb``): one mesh with morph targets plus a glTF animation of their
weights.

The file holds what :func:`facebasis.geometry.gltf.glb_bytes` writes (POSITION and indices of the
rest mesh, one morph target per shape with its delta as POSITION, names in
``mesh.extras.targetNames``), and one animation: a sampler whose input accessor holds the key
times (seconds, ``frame / fps``) and whose output accessor holds, per key, one weight per morph
target (``count = T * k``), with LINEAR interpolation, and one channel targeting node 0's
``weights``. Blender's importer turns it into shape-key actions; three.js plays it with an
``AnimationMixer``.

This is a complete writer of its own (the static writer in ``geometry/gltf.py`` has no hook for
animations); both could share a buffer builder if ``glb_bytes`` accepted extra accessors and
top-level entries.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from ..atomic import atomic_write_bytes
from ..errors import InputError
from ..geometry.gltf import glb_container

_FLOAT, _UINT = 5126, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963


def animated_glb_bytes(neutral, faces, targets, names: Sequence[str], times, weights, *,
                       name: str = "face", animation_name: str = "capture") -> bytes:
    """Serialise a morph-target mesh with a weight animation as GLB.

    Parameters
    ----------
    neutral : (n, 3) rest positions; faces : (m, 3) triangles
    targets : (k, n, 3) morph-target deltas; names : k target names
    times : (T,) strictly increasing key times in seconds
    weights : (T, k) morph weights per key (any finite values; the rig and mesh writers of this
        package keep them in [0, 1])
    """
    V = np.asarray(neutral, np.float32)
    F = np.asarray(faces, np.uint32)
    D = np.asarray(targets, np.float32)
    t = np.asarray(times, np.float32).reshape(-1)
    W = np.asarray(weights, np.float32)
    k = len(D)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
        raise InputError(f"animated glTF: expected neutral (n, 3) and faces (m, 3), found {V.shape}, {F.shape}")
    if D.shape != (k, len(V), 3) or len(names) != k:
        raise InputError(f"animated glTF: expected {len(names)} targets of shape ({len(V)}, 3), found {D.shape}")
    if W.shape != (len(t), k) or len(t) < 1:
        raise InputError(f"animated glTF: expected weights of shape ({len(t)}, {k}), found {W.shape}")
    if not (np.isfinite(W).all() and np.isfinite(t).all() and np.isfinite(D).all() and np.isfinite(V).all()):
        raise InputError("animated glTF: expected finite positions, targets, times and weights, found NaN/inf")
    if len(t) > 1 and not np.all(np.diff(t) > 0):
        raise InputError("animated glTF: expected strictly increasing key times")
    chunks, views, accessors = [], [], []
    offset = 0

    def add(data: np.ndarray, target: int | None, component: int, kind: str, minmax: bool) -> int:
        nonlocal offset
        raw = np.ascontiguousarray(data).tobytes()
        pad = (-len(raw)) % 4
        chunks.append(raw + b"\0" * pad)
        view = {"buffer": 0, "byteOffset": offset, "byteLength": len(raw)}
        if target is not None:
            view["target"] = target
        views.append(view)
        count = int(len(data)) if kind != "SCALAR" else int(data.size)
        acc = {"bufferView": len(views) - 1, "componentType": component, "count": count, "type": kind}
        if minmax:
            d2 = data.reshape(count, -1)
            acc["min"] = [float(v) for v in d2.min(0)]
            acc["max"] = [float(v) for v in d2.max(0)]
        accessors.append(acc)
        offset += len(raw) + pad
        return len(accessors) - 1

    pos = add(V, _ARRAY_BUFFER, _FLOAT, "VEC3", True)
    idx = add(F.ravel(), _ELEMENT_ARRAY_BUFFER, _UINT, "SCALAR", False)
    tgts = [{"POSITION": add(d, _ARRAY_BUFFER, _FLOAT, "VEC3", True)} for d in D]
    t_acc = add(t, None, _FLOAT, "SCALAR", True)             # sampler input: key times (s)
    w_acc = add(W.ravel(), None, _FLOAT, "SCALAR", False)    # sampler output: T * k weights
    mesh = {"name": name, "primitives": [{"attributes": {"POSITION": pos}, "indices": idx, "mode": 4}],
            "extras": {"targetNames": [str(s) for s in names]}}
    if k:
        mesh["primitives"][0]["targets"] = tgts
        mesh["weights"] = [float(v) for v in W[0]]
    doc = {
        "asset": {"version": "2.0", "generator": "facebasis"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": name}],
        "meshes": [mesh],
        "buffers": [{"byteLength": offset}],
        "bufferViews": views,
        "accessors": accessors,
    }
    if k:
        doc["animations"] = [{"name": animation_name,
                              "samplers": [{"input": t_acc, "output": w_acc, "interpolation": "LINEAR"}],
                              "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}]}]
    return glb_container(doc, chunks)


def frame_times(n_frames: int, fps: float) -> np.ndarray:
    """Key times ``frame / fps`` in seconds, (T,)."""
    if not np.isfinite(fps) or fps <= 0:
        raise InputError(f"fps: expected a positive number, found {fps}")
    return np.arange(int(n_frames), dtype=np.float64) / float(fps)


def write_rig_animation(path, rig, weights, fps: float) -> Path:
    """The rig's morph targets and an animation of its weights (T, k) at ``fps``, written atomically."""
    W = np.asarray(weights, np.float64)
    if W.ndim != 2 or W.shape[1] != rig.n_shapes:
        raise InputError(f"rig animation: expected weights of shape (T, {rig.n_shapes}), found {W.shape}")
    path = Path(path)
    atomic_write_bytes(path, animated_glb_bytes(rig.neutral, rig.faces, rig.deltas, rig.names,
                                                frame_times(len(W), fps), W))
    return path


__all__ = ["animated_glb_bytes", "frame_times", "write_rig_animation"]
