"""Loading the ICT-FaceKit rig from ``../shared/data/ict/ict_face.npz`` (never copied here).

The data path is ``$FACEBASIS_ICT`` if set, else ``<repo>/../shared/data/ict/ict_face.npz``.
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

import numpy as np

from facebasis.errors import InputError
from facebasis.geometry.rig import Rig

REPO = Path(__file__).resolve().parent.parent


def ict_path() -> Path:
    return Path(os.environ.get("FACEBASIS_ICT", REPO.parent / "shared" / "data" / "ict" / "ict_face.npz"))


def ict_available() -> bool:
    return ict_path().is_file()


@lru_cache(maxsize=1)
def _load():
    path = ict_path()
    if not path.is_file():
        raise InputError(f"ICT data: expected {path}, found no such file (set FACEBASIS_ICT)")
    with np.load(path, allow_pickle=False) as d:
        return {k: d[k] for k in d.files}


def ict_rig() -> Rig:
    """ICT's generic neutral with its 53 expressions (float64, cm)."""
    d = _load()
    return Rig(d["neutral"].astype(np.float64), d["faces"].astype(np.int64),
               tuple(str(s) for s in d["expression_names"]), d["expression_deltas"].astype(np.float64),
               source="ICT-FaceKit")


def ict_identity(weights: np.ndarray) -> np.ndarray:
    """Neutral of the person with identity weights ``c`` (100,): ``neutral + sum_k c_k I_k``."""
    d = _load()
    c = np.asarray(weights, dtype=np.float64)
    return d["neutral"].astype(np.float64) + np.tensordot(c, d["identity_deltas"].astype(np.float64), axes=1)


def ict_random_identity(seed: int = 0, scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A seeded random identity: (weights (100,), neutral (n, 3))."""
    c = scale * np.random.default_rng(seed).standard_normal(100)
    return c, ict_identity(c)


def ict_regions() -> dict[str, tuple[int, int]]:
    d = _load()
    return {str(n): (int(a), int(b)) for n, (a, b) in zip(d["region_names"], d["region_ranges"])}


def ict_zones(lip_radius: float = 1.2, lid_radius: float = 0.8) -> dict[str, np.ndarray]:
    """Vertex masks (n,) of the thin layered zones of the ICT face, for locating penetrations.

    ``lips``: face vertices within ``lip_radius`` cm of the 20 mouth landmarks (68-point indices
    48-67) and the whole mouth socket; ``lids``: face vertices within ``lid_radius`` cm of the 12
    eye landmarks (36-47) and both eye sockets.
    """
    from scipy.spatial import cKDTree

    d = _load()
    V = d["neutral"].astype(np.float64)
    lm = d["landmarks68"].astype(np.int64)
    reg = ict_regions()
    face = np.zeros(len(V), bool)
    face[slice(*reg["face"])] = True
    tree = cKDTree(V)

    def near(idx, r):
        m = np.zeros(len(V), bool)
        for hits in tree.query_ball_point(V[idx], r):
            m[hits] = True
        return m & face

    lips = near(lm[48:68], lip_radius)
    lips[slice(*reg["mouth_socket"])] = True
    lids = near(lm[36:48], lid_radius)
    lids[slice(*reg["eye_socket_left"])] = True
    lids[slice(*reg["eye_socket_right"])] = True
    return {"lips": lips, "lids": lids}
