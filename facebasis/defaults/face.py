"""The built-in default face: a generated blendshape rig with lips, a mouth socket and eyelids.

Everything here is made by code, so a new user can run every command without any data. The face
is a front mask in centimetres (about 14 cm wide and 18 cm high) built on a (u, v) grid:

* the mouth and both eyes are slits in the grid (the vertices along the slit are duplicated, so the
  upper and lower lip, and the upper and lower lid, are separate surface layers that meet only at
  the corners);
* each slit's boundary loop is extruded backwards into a closed pocket: a mouth socket that curls
  up behind the upper lip and down behind the lower lip, and a shallow eye socket;
* the lips nearly touch (0.6 mm gap) with the socket 5-8 mm behind them, and the lids are 6-9 mm
  apart: exactly the thin multi-layer regions where deformation transfer can push one layer
  through another (Li et al. 2023).

Two people share the topology: :func:`default_template` (the generic rig) and
:func:`default_person` (a different face shape with its own, person-specific expressions: other
strengths, an asymmetric smile, a wider jaw opening). :func:`default_problem` builds training
expressions and rough weights from the person's rig for the example-based generation demo.

Blendshapes (ARKit names): jawOpen, mouthSmile_L/R, mouthFrown_L/R, mouthLeft, mouthRight,
mouthPucker, eyeBlink_L/R, eyeWide_L/R, browInnerUp, cheekPuff_L/R. ``_L`` is the face's own left
(+x; the face looks along +z).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from ..geometry.rig import Rig

SHAPE_NAMES = (
    "jawOpen", "mouthSmile_L", "mouthSmile_R", "mouthFrown_L", "mouthFrown_R", "mouthLeft",
    "mouthRight", "mouthPucker", "eyeBlink_L", "eyeBlink_R", "eyeWide_L", "eyeWide_R",
    "browInnerUp", "cheekPuff_L", "cheekPuff_R",
)

#: Mutually exclusive pairs of the default rig (used by the weight step's complementarity).
EXCLUSIVE_PAIRS = (("mouthLeft", "mouthRight"), ("mouthSmile_L", "mouthFrown_L"),
                   ("mouthSmile_R", "mouthFrown_R"), ("eyeBlink_L", "eyeWide_L"),
                   ("eyeBlink_R", "eyeWide_R"))

# grid resolution and the slits, in grid indices: (row, first column, last column)
NU, NV = 57, 71
MOUTH = (18, 19, 37)
EYE_L = (44, 34, 46)   # +x side (face's left)
EYE_R = (44, 10, 22)
MOUTH_RINGS, EYE_RINGS = 6, 4


@dataclass(frozen=True)
class FaceParams:
    """Geometry and expression style of one generated person (lengths in cm)."""

    half_width: float = 7.0
    half_height: float = 9.0
    depth: float = 4.0
    nose: float = 2.2
    lips: float = 0.7
    brow: float = 0.5
    chin: float = 0.6
    lip_gap: float = 0.06
    eye_open: float = 0.8
    # expression style
    jaw_angle: float = 0.22
    smile: tuple[float, float] = (1.0, 1.0)  # (left, right) strength
    frown: tuple[float, float] = (1.0, 1.0)
    mouth_shift: float = 0.7
    pucker: float = 1.0
    blink_over: float = 1.0  # fraction of the lid opening a blink closes
    wide: float = 0.3
    brow_up: float = 0.8
    puff: tuple[float, float] = (0.8, 0.8)
    smile_with_cheeks: float = 0.0  # person-specific coupling: the smile also puffs the cheek
    name: str = field(default="default", compare=False)


TEMPLATE = FaceParams(name="default-template")
PERSON = FaceParams(
    half_width=7.6, half_height=8.5, depth=4.5, nose=2.7, lips=0.9, brow=0.7, chin=0.9,
    lip_gap=0.05, eye_open=0.7, jaw_angle=0.27, smile=(1.35, 0.9), frown=(0.8, 1.1),
    mouth_shift=0.55, pucker=1.25, blink_over=1.0, wide=0.25, brow_up=1.1, puff=(0.9, 1.1),
    smile_with_cheeks=0.35, name="default-person",
)


# ----------------------------------------------------------------------------------------------
# topology (shared by every person)

@dataclass(frozen=True)
class _Topology:
    faces: np.ndarray           # (m, 3)
    n_vertices: int
    uv: np.ndarray              # (n, 2) grid parameter of every vertex (pocket vertices: their loop's)
    side: np.ndarray            # (n,) +1 upper copy / above slit, -1 lower, 0 elsewhere (per slit vertex)
    pocket: np.ndarray          # (n,) 0 for the face; ring index (1..K, K+1 = cap) inside a pocket
    pocket_id: np.ndarray       # (n,) -1 face, 0 mouth, 1 eye L, 2 eye R
    loops: tuple                # per slit: (loop vertex ids, ring vertex ids (K, len(loop)), cap id)
    slit_pairs: tuple           # per slit: (upper ids, lower ids) of interior slit columns


def _grid_uv(r, c):
    return np.stack([-1.0 + 2.0 * c / (NU - 1), -1.0 + 2.0 * r / (NV - 1)], axis=-1)


@lru_cache(maxsize=1)
def _topology() -> _Topology:
    gid = np.arange(NV * NU).reshape(NV, NU)
    n = NV * NU
    rr, cc = np.meshgrid(np.arange(NV), np.arange(NU), indexing="ij")
    uv = [_grid_uv(rr.ravel(), cc.ravel())]
    side = np.zeros(n)
    # quad corner ids; slits replace the bottom corners of the quads just above the slit row
    bl, br = gid[:-1, :-1].copy(), gid[:-1, 1:].copy()
    tl, tr = gid[1:, :-1].copy(), gid[1:, 1:].copy()
    slit_pairs = []
    upper_sets = []
    for row, c0, c1 in (MOUTH, EYE_L, EYE_R):
        cols = np.arange(c0 + 1, c1)
        upper = np.arange(n, n + len(cols))
        n += len(cols)
        uv.append(_grid_uv(np.full(len(cols), row), cols))
        lower = gid[row, cols]
        side = np.concatenate([side, np.ones(len(cols))])
        side[lower] = -1.0
        # quads of grid row `row` (between rows row and row+1) use the upper copies at the bottom
        bl[row, cols] = upper
        br[row, cols - 1] = upper
        slit_pairs.append((upper, lower))
        upper_sets.append((row, c0, c1, upper, lower))
    quads = np.stack([bl.ravel(), br.ravel(), tr.ravel(), tl.ravel()], axis=1)
    faces = [np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])]
    pocket = np.zeros(n, int)
    pocket_id = -np.ones(n, int)
    loops = []
    uv_all = np.concatenate(uv)
    uv_extra, side_extra, pocket_extra, pid_extra = [], [], [], []
    for sid, ((row, c0, c1, upper, lower), K) in enumerate(zip(upper_sets, (MOUTH_RINGS, EYE_RINGS, EYE_RINGS))):
        loop = np.concatenate([[gid[row, c0]], upper, [gid[row, c1]], lower[::-1]])
        L = len(loop)
        rings = n + np.arange(K * L).reshape(K, L)
        cap = n + K * L
        n = cap + 1
        loop_side = np.concatenate([[0.0], np.ones(len(upper)), [0.0], -np.ones(len(lower))])
        uv_extra += [np.tile(uv_all[loop], (K, 1)), uv_all[loop].mean(0, keepdims=True)]
        side_extra += [np.tile(loop_side, K), [0.0]]
        pocket_extra += [np.repeat(np.arange(1, K + 1), L), [K + 1]]
        pid_extra += [np.full(K * L + 1, sid)]
        prev = loop
        for k in range(K):
            cur = rings[k]
            a, b = prev, np.roll(prev, -1)
            c, d = np.roll(cur, -1), cur
            # the face traverses the loop edge (a, b) as (b, a): keep the pocket consistent
            faces.append(np.stack([a, d, c], 1))
            faces.append(np.stack([a, c, b], 1))
            prev = cur
        faces.append(np.stack([prev, np.full(L, cap), np.roll(prev, -1)], 1))
        loops.append((loop, rings, cap))
        pocket_id[loop] = sid
    uv_all = np.concatenate([uv_all] + uv_extra)
    side = np.concatenate([side] + [np.asarray(s, float) for s in side_extra])
    pocket = np.concatenate([pocket] + [np.asarray(p) for p in pocket_extra])
    pocket_id = np.concatenate([pocket_id] + pid_extra)
    F = np.concatenate(faces).astype(np.int64)
    return _Topology(F, n, uv_all, side, pocket, pocket_id, tuple(loops), tuple(slit_pairs))


# ----------------------------------------------------------------------------------------------
# geometry

def _bump(u, v, u0, v0, su, sv):
    return np.exp(-(((u - u0) / su) ** 2) - ((v - v0) / sv) ** 2)


def _slit_profile(u, c0, c1):
    """0 at the slit corners, 1 in the middle (smooth), for grid parameter u."""
    u0, u1 = -1.0 + 2.0 * c0 / (NU - 1), -1.0 + 2.0 * c1 / (NU - 1)
    s = np.clip((u - u0) / (u1 - u0), 0.0, 1.0)
    return np.sin(np.pi * s) ** 0.8


def _face_surface(u, v, p: FaceParams):
    x = p.half_width * (u + 0.04 * u ** 3)
    y = p.half_height * v
    z = p.depth * (1.0 - 0.55 * u ** 2 - 0.22 * v ** 2 - 0.25 * (u * v) ** 2)
    z = z + p.nose * _bump(u, v, 0.0, 0.02, 0.11, 0.22)
    z = z + p.lips * _bump(u, v, 0.0, -0.49, 0.30, 0.12)
    z = z + p.brow * (_bump(u, v, 0.36, 0.47, 0.22, 0.07) + _bump(u, v, -0.36, 0.47, 0.22, 0.07))
    z = z - 0.6 * (_bump(u, v, 0.36, 0.25, 0.2, 0.1) + _bump(u, v, -0.36, 0.25, 0.2, 0.1))
    z = z + p.chin * _bump(u, v, 0.0, -0.82, 0.25, 0.1)
    return np.stack([x, y, z], axis=-1)


def _neutral(p: FaceParams, topo: _Topology) -> np.ndarray:
    uv = topo.uv
    P = _face_surface(uv[:, 0], uv[:, 1], p)
    face = topo.pocket == 0
    # open the slits: upper copies up, lower down, by half the gap at that column
    for (row, c0, c1), gap in zip((MOUTH, EYE_L, EYE_R), (p.lip_gap, p.eye_open, p.eye_open)):
        v_row = -1.0 + 2.0 * row / (NV - 1)
        prof = _slit_profile(uv[:, 0], c0, c1)
        near = face & (np.abs(uv[:, 1] - v_row) < 1e-9)
        h = 0.5 * gap * prof
        P[near, 1] += topo.side[near] * h[near]
        # open the eyes smoothly: the lid skin above/below follows, fading over 3 grid rows
        if gap > 0.2:
            dv = (uv[:, 1] - v_row) / (2.0 / (NV - 1))
            ring = face & ~near & (np.abs(dv) <= 3) & (prof > 0)
            fade = np.clip(1.0 - (np.abs(dv[ring]) - 1) / 3.0, 0.0, 1.0)
            P[ring, 1] += np.sign(dv[ring]) * 0.5 * gap * prof[ring] * fade
    # pockets: rings behind each slit loop
    for sid, (loop, rings, cap) in enumerate(topo.loops):
        base = P[loop]
        s_loop = topo.side[loop]
        K = rings.shape[0]
        mouth = sid == 0
        cx = base[:, 0].mean()
        prof = _slit_profile(topo.uv[loop, 0], *((MOUTH, EYE_L, EYE_R)[sid][1:]))
        for k in range(K):
            s = (k + 1) / (K + 1)
            ring = base.copy()
            if mouth:
                # curl behind the lips: up/down by up to 1.6 cm, back by up to 3 cm
                spread = 1.6 * np.sin(np.pi * min(1.0, 1.3 * s)) ** 0.6 * (0.35 + 0.65 * prof)
                ring[:, 1] += s_loop * spread + 0.0
                ring[:, 2] -= 0.55 + 2.6 * s
                ring[:, 0] = cx + (base[:, 0] - cx) * (1.0 + 0.25 * np.sin(np.pi * s))
            else:
                spread = 0.25 * np.sin(np.pi * s) * prof
                ring[:, 1] += s_loop * spread
                ring[:, 2] -= 0.35 + 0.9 * s
                ring[:, 0] = cx + (base[:, 0] - cx) * (1.0 - 0.35 * s)
            P[rings[k]] = ring
        P[cap] = P[rings[-1]].mean(0) - np.array([0.0, 0.0, 0.2])
    return P


# ----------------------------------------------------------------------------------------------
# expressions (displacement fields on the neutral)

def _weight_from_grid(topo, fn):
    """Evaluate a weight field on (u, v); pocket rings fade with depth."""
    w = fn(topo.uv[:, 0], topo.uv[:, 1])
    depth_fade = np.where(topo.pocket > 0, np.clip(1.0 - 0.18 * topo.pocket, 0.0, 1.0), 1.0)
    return w * depth_fade


def _expressions(p: FaceParams, topo: _Topology, P: np.ndarray) -> np.ndarray:
    uv, side = topo.uv, topo.side
    u, v = uv[:, 0], uv[:, 1]
    W, H = p.half_width, p.half_height
    mouth_v = -1.0 + 2.0 * MOUTH[0] / (NV - 1)
    mouth_slit = topo.pocket_id == 0
    below = np.where(side != 0, side < 0, v < mouth_v - 1e-9)
    # jaw: lower face below the mouth line (lower lip copies and lower half of the socket)
    corner_u = -1.0 + 2.0 * MOUTH[2] / (NU - 1)
    # sharp split between the lips inside the mouth span, a smooth fold beyond the corners
    beyond = np.clip((np.abs(u) - corner_u) / 0.2, 0.0, 1.0)
    soft = 1.0 / (1.0 + np.exp((v - mouth_v + 0.04) / 0.05))
    jaw_w = (1.0 - beyond) * np.where(below, 1.0, 0.0) + beyond * soft
    side_fade = np.clip((np.abs(u) - 0.45) / 0.5, 0.0, 1.0)
    jaw_w = jaw_w * (1.0 - side_fade * side_fade * (3.0 - 2.0 * side_fade))  # smooth fade to the cheeks
    jaw_w = jaw_w * np.where(mouth_slit & (topo.pocket > 0), np.clip(1.0 - 0.12 * topo.pocket, 0, 1), 1.0)
    jaw_w = np.where((topo.pocket > 0) & ~mouth_slit, 0.0, jaw_w)
    pivot = np.array([0.0, mouth_v * H + 2.0, -7.0])
    t = p.jaw_angle
    # rotation about the x axis through the pivot behind the face: the chin goes down and back
    R = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
    jaw = jaw_w[:, None] * ((P - pivot) @ R.T + pivot - P)

    mouth_region = _weight_from_grid(topo, lambda uu, vv: _bump(uu, vv, 0.0, mouth_v, 0.42, 0.16))

    def corner(sign):
        return _weight_from_grid(topo, lambda uu, vv: _bump(uu, vv, sign * corner_u, mouth_v, 0.16, 0.12))

    def smile(sign, s):
        w = corner(sign)
        d = np.stack([sign * 0.55 * w, 0.6 * w, -0.25 * w], 1) * s
        if p.smile_with_cheeks:
            d = d + p.smile_with_cheeks * s * cheek(sign)
        return d

    def frown(sign, s):
        w = corner(sign)
        return np.stack([sign * 0.1 * w, -0.55 * w, 0.0 * w], 1) * s

    def cheek(sign):
        w = _weight_from_grid(topo, lambda uu, vv: _bump(uu, vv, sign * 0.5, -0.3, 0.18, 0.16))
        w = np.where(topo.pocket > 0, 0.0, w)
        nrm = np.stack([sign * 0.8 * np.ones_like(w), -0.1 * np.ones_like(w), 0.6 * np.ones_like(w)], 1)
        return w[:, None] * nrm

    lips = _weight_from_grid(topo, lambda uu, vv: _bump(uu, vv, 0.0, mouth_v, 0.3, 0.1))
    pucker = np.stack([-0.45 * (P[:, 0] / W) * lips * 2.0, 0.0 * lips, 0.9 * lips], 1) * p.pucker

    def eye(sid_slit, sign, mode):
        row, c0, c1 = (EYE_L, EYE_R)[sid_slit]
        upper, lower = topo.slit_pairs[1 + sid_slit]
        v_row = -1.0 + 2.0 * row / (NV - 1)
        prof = _slit_profile(u, c0, c1)
        opening = p.eye_open * prof  # lid distance at this u
        dv = (v - v_row) / (2.0 / (NV - 1))
        on_eye = (topo.pocket == 0) | (topo.pocket_id == 1 + sid_slit)
        upper_lid = on_eye & (side >= 0) & (dv > -0.5) & (prof > 0)
        upper_lid &= ~((topo.pocket > 0) & (side <= 0))
        fade = np.where(side > 0, 1.0, np.clip(1.0 - (dv - 0.0) / 5.0, 0.0, 1.0))
        fade = np.where(topo.pocket > 0, np.where(side > 0, np.clip(1.0 - 0.35 * topo.pocket, 0, 1), 0.0), fade)
        w = np.where(upper_lid, fade, 0.0)
        d = np.zeros_like(P)
        if mode == "blink":
            d[:, 1] = -p.blink_over * opening * w
            d[:, 2] = 0.15 * w * prof
        else:
            d[:, 1] = p.wide * w * prof
        return d

    brow = _weight_from_grid(topo, lambda uu, vv: _bump(uu, vv, 0.0, 0.5, 0.35, 0.12))
    brow = np.where(topo.pocket > 0, 0.0, brow)
    brow_d = np.stack([0 * brow, p.brow_up * brow, 0.1 * brow], 1)

    shapes = {
        "jawOpen": jaw,
        "mouthSmile_L": smile(+1, p.smile[0]),
        "mouthSmile_R": smile(-1, p.smile[1]),
        "mouthFrown_L": frown(+1, p.frown[0]),
        "mouthFrown_R": frown(-1, p.frown[1]),
        "mouthLeft": np.stack([p.mouth_shift * mouth_region, 0 * mouth_region, 0 * mouth_region], 1),
        "mouthRight": np.stack([-p.mouth_shift * mouth_region, 0 * mouth_region, 0 * mouth_region], 1),
        "mouthPucker": pucker,
        "eyeBlink_L": eye(0, +1, "blink"),
        "eyeBlink_R": eye(1, -1, "blink"),
        "eyeWide_L": eye(0, +1, "wide"),
        "eyeWide_R": eye(1, -1, "wide"),
        "browInnerUp": brow_d,
        "cheekPuff_L": p.puff[0] * cheek(+1),
        "cheekPuff_R": p.puff[1] * cheek(-1),
    }
    return np.stack([shapes[s] for s in SHAPE_NAMES])


def make_face(params: FaceParams = TEMPLATE) -> Rig:
    """Generate one person's rig (neutral + 15 blendshapes) in the shared default topology."""
    topo = _topology()
    P = _neutral(params, topo)
    D = _expressions(params, topo, P)
    return Rig(P, topo.faces, SHAPE_NAMES, D, source=params.name)


def default_template() -> Rig:
    """The generic template rig of the built-in face."""
    return make_face(TEMPLATE)


def default_person() -> Rig:
    """The second person: another face shape with person-specific expressions (ground truth)."""
    return make_face(PERSON)


def region_masks() -> dict[str, np.ndarray]:
    """Boolean vertex masks of the built-in face: lips, mouth_socket, eyelids, eye_sockets."""
    topo = _topology()
    u, v = topo.uv[:, 0], topo.uv[:, 1]
    mouth_v = -1.0 + 2.0 * MOUTH[0] / (NV - 1)
    eye_v = -1.0 + 2.0 * EYE_L[0] / (NV - 1)
    face = topo.pocket == 0
    lips = face & (np.abs(u) < 0.4) & (np.abs(v - mouth_v) < 0.12)
    lids = face & (np.abs(np.abs(u) - 0.41) < 0.25) & (np.abs(v - eye_v) < 0.12)
    return {
        "lips": lips,
        "mouth_socket": topo.pocket_id == 0,
        "eyelids": lids,
        "eye_sockets": (topo.pocket_id >= 1) & (topo.pocket > 0),
    }
