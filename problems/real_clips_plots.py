"""Figures of :mod:`problems.real_clips` (numbers and generated cartoon pixels only): the weight, mouth
gap and head-pose curves of a clip, and the built-in cartoon warped at a few frames."""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: shapes drawn in the weight plot (largest mean weight)
TOP_K = 8



def plot_weights(path_png: Path, clip: str, fps: float, names, W, ypr, gap, gap_ref, ref_idx, title_extra: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.arange(len(W)) / fps
    top = np.argsort(-W.mean(0), kind="stable")[:TOP_K]
    fig, axes = plt.subplots(3, 1, figsize=(9.0, 7.2), sharex=True,
                             gridspec_kw={"height_ratios": [2.2, 1.0, 1.3]}, constrained_layout=True)
    ax = axes[0]
    cmap = plt.get_cmap("tab10")
    for j, i in enumerate(top):
        ax.plot(t, W[:, i], lw=1.0, color=cmap(j % 10), label=f"{names[i]} ({W[:, i].mean():.2f})")
    ax.set_ylabel("ICT weight")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title(f"{clip}: top {len(top)} ICT weights by mean ({title_extra})", fontsize=10)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False, title="shape (mean)",
              title_fontsize=8)
    ax.grid(alpha=0.3)
    ax = axes[1]
    ax.plot(t, gap, lw=1.0, color="k", label="tracked landmarks")
    if gap_ref is not None:
        ax.plot(ref_idx / fps, gap_ref, ".", ms=2.5, color="tab:red", label="dlib per-frame detection")
    ax.set_ylabel("mouth gap\n(/ eye-corner dist.)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    ax.grid(alpha=0.3)
    ax = axes[2]
    for k, (lab, c) in enumerate((("yaw", "tab:blue"), ("pitch", "tab:orange"), ("roll", "tab:green"))):
        ax.plot(t, ypr[:, k], lw=1.0, color=c, label=lab)
    ax.set_ylabel("head pose (deg)")
    ax.set_xlabel("time (s)")
    ax.set_xlim(0, t[-1] if len(t) > 1 else 1)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    ax.grid(alpha=0.3)
    fig.savefig(path_png, dpi=200)
    fig.savefig(path_png.with_suffix(".pdf"))
    plt.close(fig)


def strip_frames(T: int, gap, yaw, n: int = 6) -> list[int]:
    """Frame 0, the widest mouth, the two yaw extremes, then evenly spaced frames; sorted, distinct."""
    picks = [0, int(np.nanargmax(gap)), int(np.nanargmin(yaw)), int(np.nanargmax(yaw))]
    for f in np.linspace(0, T - 1, n + 2).round().astype(int)[1:-1]:
        if len(set(picks)) >= n:
            break
        picks.append(int(f))
    out = []
    for f in picks:
        if all(abs(f - g) > max(2, T // 50) for g in out):
            out.append(f)
    return sorted(out)[:n]


def cartoon_strip(path: Path, clip: str, capture_dir: Path, frames: list[int], fps: float):
    """The built-in cartoon warped by the capture at ``frames`` (same warp as run_animate2d)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from facebasis.capture.trackfile import read_capture
    from facebasis.defaults.cartoon import default_cartoon
    from facebasis.retarget.warp2d import CartoonAnimator

    cap = read_capture(capture_dir)
    face = default_cartoon()
    anim = CartoonAnimator(np.array(face.image), np.array(face.landmarks), cap.landmarks[0], cap.vertices[0],
                           cap.faces)
    meshes = anim.mesh(cap.vertices)
    fig, axes = plt.subplots(1, len(frames), figsize=(2.3 * len(frames), 2.65), constrained_layout=True)
    for ax, f in zip(np.atleast_1d(axes), frames):
        ax.imshow(anim.warp(meshes[f]))
        ax.set_title(f"frame {f} ({f / fps:.1f} s)", fontsize=9)
        ax.axis("off")
    fig.suptitle(f"built-in cartoon driven by {clip}", fontsize=10)
    fig.savefig(path, dpi=150)
    plt.close(fig)


