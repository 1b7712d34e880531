"""A picture of a retargeting result: the source frame beside the rig, and the main weights over time.

``preview.mp4``: every frame of the capture's source video (or its overlay) on the left, on the
right the rig's mesh with that frame's solved weights, turned by the solved head rotation R and
rendered by the package's own rasteriser (:func:`facebasis.geometry.raster.rasterize_mesh`, numpy,
no OpenGL), at the source's height. The head keeps a fixed size and stays centred: the
weak-perspective scale and translation only say where the head is in the picture, which the source
already shows. Frames are encoded one at a time with PyAV (:func:`.media.write_mp4`), as the
capture overlay is, so memory does not grow with the clip.

``weights.png``: the weights of the :data:`MAIN_SHAPES` shapes that move most, one panel each, over
time in seconds (matplotlib, as the report figures).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..geometry.rig import Rig
from .pose import PI

#: shapes shown in the weight plot (the largest peaks; ties by mean)
MAIN_SHAPES = 8
#: part of the panel height the neutral head fills
FILL = 0.9
#: with landmark vertices given, the view frames their bounding box grown by this factor
FOCUS_MARGIN = 2.0
#: libx264 preset of the preview (measured 1.6 against 3.5 ms CPU per 700x300 frame for "veryfast")
PRESET = "ultrafast"
#: default panel size (height, width) when there is no source video
PANEL = (300, 300)


@dataclass(frozen=True)
class PreviewStats:
    """What :func:`write_preview` wrote: frames, their size (width, height), seconds and ms per frame
    (reading the source, rendering, encoding), and whether a source video was beside the rig."""

    frames: int
    width: int
    height: int
    seconds: float
    ms_per_frame: float
    source: str | None


class MeshRenderer:
    """Renders a mesh (one topology, moving vertices) into a panel of a fixed size.

    The view is fixed by the rest vertices: their bounding box's centre is the panel's centre and
    their height (or width) fills :data:`FILL` of it; x right, y up in the mesh (image y down).

    Parameters
    ----------
    rest : (n, 3) rest vertices (the rig's neutral)
    faces : (m, 3) triangles
    size : (height, width) of the panel in pixels
    focus : optional vertex indices (the landmark vertices): the view frames their bounding box
        grown by :data:`FOCUS_MARGIN` (the face) instead of the whole mesh (a head and neck)
    """

    def __init__(self, rest, faces, size=PANEL, focus=None):
        self.size = (int(size[0]), int(size[1]))
        if min(self.size) < 2:
            raise InputError(f"preview size: expected at least 2 x 2 pixels, found {self.size}")
        V0 = np.asarray(rest, np.float64)
        box = V0 if focus is None or len(focus) < 3 else V0[np.asarray(focus, np.int64)]
        lo, hi = box.min(0), box.max(0)
        if box is not V0:
            mid, half = (lo + hi) / 2.0, (hi - lo) / 2.0 * FOCUS_MARGIN
            lo, hi = mid - half, mid + half
        self.centre = (lo + hi) / 2.0
        extent = max(hi[1] - lo[1], (hi[0] - lo[0]) * self.size[0] / self.size[1], 1e-12)
        self.scale = FILL * self.size[0] / extent                       # pixels per mesh unit
        self.faces = np.asarray(faces)

    def render(self, vertices, rotation=None, out=None) -> np.ndarray:
        """RGB image (height, width, 3) uint8 of the mesh at ``vertices`` (n, 3), turned by
        ``rotation`` (3, 3) about the rest centre (image: ``Pi R``; z towards the viewer)."""
        from ..geometry.raster import rasterize_mesh

        R = np.eye(3) if rotation is None else np.asarray(rotation, np.float64)
        V = (np.asarray(vertices, np.float64) - self.centre) @ R.T
        H, W = self.size
        P = np.empty_like(V)
        P[:, :2] = self.scale * (V @ PI.T) + np.array([W / 2.0, H / 2.0])
        P[:, 2] = V[:, 2]
        return rasterize_mesh(P, self.faces, self.size, out=out)


def rig_frames(rig: Rig, weights):
    """``f -> (n, 3)`` vertices of the rig at frame f's weights (weights (T, k))."""
    W = np.asarray(weights, np.float32)
    D = np.ascontiguousarray(rig.deltas.reshape(rig.n_shapes, -1), np.float32)   # (k, 3n): float32 halves
    V0 = rig.neutral.astype(np.float32)                                         # the per-frame traffic
    return lambda f: V0 + (W[f] @ D).reshape(-1, 3)


def write_preview(path, rest, faces, frame_vertices, n_frames: int, fps: float, rotation=None, source=None,
                  size=None, focus=None) -> PreviewStats:
    """Encode ``preview.mp4``: the source video's frames beside the rendered mesh.

    Parameters
    ----------
    path : output MP4
    rest : (n, 3) rest vertices (fix the view); faces : (m, 3)
    frame_vertices : ``f -> (n, 3)`` vertices of frame f (e.g. :func:`rig_frames`)
    n_frames : T; fps : frames per second
    rotation : optional (T, 3, 3) head rotations (None: frontal)
    source : optional video whose frames go on the left (resized to the panel's height); past its
        end the left side stays white
    size : (height, width) of the mesh panel; default the source's height (square), else :data:`PANEL`
    focus : optional landmark vertex indices the view frames (:class:`MeshRenderer`)
    """
    from .media import read_video_frames, side_by_side, write_mp4

    T = int(n_frames)
    t0 = time.perf_counter()
    src = read_video_frames(source) if source is not None else None
    first = next(src, None) if src is not None else None
    if size is None:
        size = (first.shape[0], first.shape[0]) if first is not None else PANEL
    renderer = MeshRenderer(rest, faces, size, focus)
    buf = np.empty((renderer.size[0], renderer.size[1], 3), np.uint8)
    shape = {}

    def frames():
        left = first
        for f in range(T):
            img = renderer.render(frame_vertices(f), None if rotation is None else rotation[f], out=buf)
            if left is not None:
                img = side_by_side(left, img)
                shape["left"] = img.shape[1] - buf.shape[1]
                left = next(src, None) if f + 1 < T else None
            elif "left" in shape:            # the source ended early: keep the frame size constant
                img = np.concatenate([np.full((img.shape[0], shape["left"], 3), 255, np.uint8), img], 1)
            yield img

    n = write_mp4(path, frames(), fps, preset=PRESET)
    seconds = time.perf_counter() - t0
    width = renderer.size[1] + shape.get("left", 0)
    return PreviewStats(n, width - width % 2, renderer.size[0] - renderer.size[0] % 2, seconds,
                        1e3 * seconds / max(n, 1), None if source is None else str(source))


def source_video(capture_dir, cap):
    """The capture's source video if it still exists, else its ``overlay.mp4``, else None."""
    from pathlib import Path

    from ..capture.trackfile import OVERLAY_FILE

    if cap.video is not None and Path(cap.video).is_file():
        return Path(cap.video)
    overlay = Path(capture_dir) / OVERLAY_FILE
    return overlay if overlay.is_file() else None


def main_shapes(names, weights, n: int = MAIN_SHAPES) -> list[int]:
    """Indices of the ``n`` shapes with the largest peak weight (ties: larger mean), in rig order."""
    W = np.asarray(weights, np.float64)
    key = np.lexsort((-W.mean(0), -W.max(0)))
    return sorted(int(i) for i in key[:min(n, len(names))])


def plot_weights(path, names, weights, fps: float, n: int = MAIN_SHAPES, title: str | None = None) -> list[str]:
    """``weights.png``: the main shapes' weights over time, one panel each; returns their names."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    W = np.asarray(weights, np.float64)
    pick = main_shapes(names, W, n)
    t = np.arange(len(W)) / float(fps)
    fig, axes = plt.subplots(len(pick), 1, figsize=(7.0, 0.9 + 0.75 * len(pick)), sharex=True, squeeze=False)
    for ax, i in zip(axes[:, 0], pick):
        ax.plot(t, W[:, i], "-", color="tab:blue", lw=0.9)
        ax.set_ylim(-0.03, 1.03)
        ax.set_yticks([0, 0.5, 1])
        ax.set_ylabel(names[i], rotation=0, ha="right", va="center", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, lw=0.3, alpha=0.5)
        for side in ("top", "right"):
            ax.spines[side].set_visible(False)
    axes[-1, 0].set_xlabel("time (s)", fontsize=8)
    axes[0, 0].set_title(title or f"rig weights (0-1), the {len(pick)} shapes with the largest peaks", fontsize=9)
    fig.tight_layout(h_pad=0.2)
    fig.savefig(path, dpi=150)
    plt.close(fig)
    return [names[i] for i in pick]


__all__ = ["MeshRenderer", "PreviewStats", "write_preview", "rig_frames", "source_video", "plot_weights", "main_shapes", "MAIN_SHAPES"]
