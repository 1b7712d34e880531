"""The three retargeting jobs as library calls (read, check everything, compute, write atomically).

Each ``run_*`` checks every input before any computation and writes its output folder through
:func:`facebasis.atomic.atomic_directory`, so a failed run leaves no folder behind. They return a
small summary dict (also written as ``summary.json``).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..atomic import atomic_directory, atomic_write_bytes, atomic_write_json
from ..errors import InputError, parameter_error
from ..capture.trackfile import OVERLAY_FILE, read_capture
from .rigrun import _log, _write_previews, load_retarget_rig, pose_csv, run_retarget, weights_csv, write_retarget_outputs


# ----------------------------------------------------------------------------------------------
# 2D

def run_animate2d(capture_dir, out_dir, image=None, landmarks=None, gif_seconds: float = 4.0, head: str = "still",
                  log=None, amplitude: str = "feature", jaw: str = "lips") -> dict:
    """Animate a cartoon image (default: the built-in cartoon) by a capture folder.

    Writes ``cartoon.mp4`` (the source video's frames beside the cartoon when the capture records
    its video), ``cartoon.gif`` (the first ``gif_seconds``), ``cartoon_mesh.npz`` (vertices (T, N, 2),
    faces), ``cartoon_rest.png`` and ``summary.json``. ``head``: "still" (the cartoon shows the
    expression only) or "follow" (it also moves with the head), see :meth:`.CartoonAnimator.drive`.
    ``amplitude``: "feature" (each eye and the mouth in the cartoon's own proportions,
    :mod:`.featurescale`) or "uniform" (the paper's one scale). ``jaw``: "lips" (the face contour follows the
    lower lip, not the head's turns, :mod:`.jawline`) or "capture". No frame is written with a triangle
    of the warp mesh flipped against the rest cartoon.
    """
    from .files import read_image, read_points2d
    from .headmotion import parse_head_mode
    from .media import check_video, read_video_frames, side_by_side, write_gif, write_mp4
    from .warp2d import CartoonAnimator

    from .featurescale import parse_amplitude

    head = parse_head_mode(head)
    amplitude = parse_amplitude(amplitude)
    from .jawline import parse_jaw_mode

    jaw = parse_jaw_mode(jaw)
    cap = read_capture(capture_dir)
    if (image is None) != (landmarks is None):
        raise InputError(what="{image} and {landmarks}", expected="both (a cartoon and its landmarks) or neither "
                         "(the built-in cartoon)", found="only one",
                         params={"image": "image", "landmarks": "landmarks"})
    if image is None:
        from ..defaults.cartoon import default_cartoon

        face = default_cartoon()
        img, pts, what = np.array(face.image), np.array(face.landmarks), "the built-in cartoon (68 iBUG landmarks)"
        if cap.n_landmarks != len(pts):
            raise InputError(what="cartoon landmarks", expected=f"{cap.n_landmarks} points (the capture's count)",
                             found=f"{len(pts)} on the built-in cartoon", note="; give {image} and {landmarks}",
                             params={"image": "image", "landmarks": "landmarks"})
    else:
        pts = read_points2d(landmarks)
        if len(pts) != cap.n_landmarks:
            raise InputError(f"cartoon landmark file {landmarks}: expected {cap.n_landmarks} points (the capture's "
                             f"count), found {len(pts)}")
        img, what = read_image(image), str(image)
    t0 = time.perf_counter()
    anim = CartoonAnimator(img, pts, cap.landmarks[0], cap.vertices[0], cap.faces, head=head, amplitude=amplitude,
                            jaw=jaw)
    if anim.amplitude != amplitude:
        _log(log, f"amplitude: 'feature' needs the 68 iBUG landmarks, found {cap.n_landmarks}: eq. 12's single "
                  "scale is used (amplitude uniform)")
        amplitude = anim.amplitude
    drive = anim.drive(cap.vertices, cap.landmarks)
    meshes = drive.meshes
    n_fold = int(np.count_nonzero(drive.folded_target))
    n_fallback = int(np.count_nonzero(drive.alpha < 1))
    _log(log, f"cartoon: {what}, {img.shape[1]}x{img.shape[0]}; capture {cap.n_frames} frames, "
              f"{cap.vertices.shape[1]} vertices; eq. 13 scale {anim.scale:.4f}; head {head}; amplitude {amplitude}; "
              f"{n_fold} frames would fold, the warp gave way in {int(np.count_nonzero(drive.iterations))} "
              f"(blended towards the rest in {n_fallback})")
    overlay = Path(capture_dir) / OVERLAY_FILE  # the source video, or else the capture's overlay of it
    video = cap.video if cap.video is not None else (overlay if overlay.is_file() else None)
    if video is not None:
        check_video(video, f"capture {capture_dir}: its video")
    gif_frames, warp_seconds = [], 0.0

    def frames():
        nonlocal warp_seconds
        src = read_video_frames(video, what=f"capture {capture_dir}: its video") if video is not None else None
        for f in range(cap.n_frames):
            t1 = time.perf_counter()
            out = anim.frame_at(drive, f)
            warp_seconds += time.perf_counter() - t1
            if len(gif_frames) <= gif_seconds * cap.fps:
                gif_frames.append(out)
            if src is not None:
                left = next(src, None)
                if left is not None:
                    out = side_by_side(left, out)
            yield out

    with atomic_directory(out_dir) as stage:
        n = write_mp4(stage / "cartoon.mp4", frames(), cap.fps)
        write_gif(stage / "cartoon.gif", gif_frames, cap.fps, gif_seconds)
        np.savez(stage / "cartoon_mesh.npz", vertices=meshes.astype(np.float32), faces=anim.faces,
                 rest=anim.rest, fps=np.float64(cap.fps))
        import cv2

        ok, png = cv2.imencode(".png", np.ascontiguousarray(img[..., ::-1]))  # imwrite fails silently (full disk)
        if not ok:  # pragma: no cover - OpenCV cannot encode an (H, W, 3) uint8 image
            raise InputError(f"cartoon image: OpenCV could not encode it as PNG ({img.shape}, {img.dtype})")
        atomic_write_bytes(stage / "cartoon_rest.png", png.tobytes())
        summary = {"frames": n, "fps": cap.fps, "scale_eq13": anim.scale, "rbf_c": anim.rbf.c, "head": head,
                   "amplitude": amplitude, "jaw": jaw,
                   "frames_target_folded": n_fold, "frames_gave_way": int(np.count_nonzero(drive.iterations)),
                   "frames_blended_to_rest": n_fallback, "plan_ms_per_frame": 1e3 * drive.seconds / max(n, 1),
                   "video_beside": str(video) if video is not None else None,
                   "warp_ms_per_frame": 1e3 * warp_seconds / max(n, 1), "seconds": time.perf_counter() - t0}
        atomic_write_json(stage / "summary.json", summary)
    return summary


# ----------------------------------------------------------------------------------------------
# 3D

def _default_face_mesh():
    from ..defaults.face import default_template
    from ..defaults.face_landmarks import face_landmarks

    rig = default_template()
    return rig.neutral, rig.faces, face_landmarks()


def _mesh_or_rig_neutral(mesh, neutral: str = "neutral.obj", exclude=(), log=None):
    """(V, F) of ``--mesh``: a mesh file, or a rig folder's neutral (``--neutral``, ``--exclude`` as
    ``transfer``'s; the folder's warning, :func:`facebasis.geometry.rig.rig_folder_warning`)."""
    from pathlib import Path

    from ..geometry.meshio import read_mesh
    from ..geometry.rig import load_rig_folder, rig_folder_warning

    exclude = tuple(exclude or ())
    if mesh is not None and Path(mesh).is_dir():
        rig = load_rig_folder(mesh, neutral, exclude)
        warning = rig_folder_warning(rig)
        if warning:
            _log(log, warning)
        return rig.neutral, rig.faces
    given = ([f"{{exclude}} {' '.join(exclude)}"] if exclude else []) + \
        ([f"{{neutral}} {neutral}"] if neutral != "neutral.obj" else [])
    if given:
        raise InputError(what=", ".join(given), expected="a rig folder as {mesh}",
                         found='the built-in face' if mesh is None else f'the mesh file {mesh}',
                         params={"exclude": "exclude", "neutral": "neutral", "mesh": "mesh"})
    return read_mesh(mesh) if mesh is not None else None


def run_animate3d(capture_dir, out_dir, mesh=None, landmarks=None, head: str = "still", log=None,
                  unit: str = "cm", neutral: str = "neutral.obj", exclude=(), preview: bool = True) -> dict:
    """Drive a mesh (default: the built-in face) by a capture; writes ``frames.npz`` (vertices
    (T, n, 3), faces), ``animation.glb`` (morph targets over a PCA basis of the motion,
    :func:`.animation.compact_vertex_animation`, in metres from the mesh's ``unit``, with an OBJ
    mesh's UVs and materials), ``preview.mp4`` (unless ``preview`` is False: the source video beside
    the driven mesh, :mod:`.preview`) and ``summary.json``. ``head``: "still" (expression only) or
    "follow" (the whole mesh moves with the head). ``mesh`` may be a rig folder: its neutral
    (``neutral``, files matching an ``exclude`` glob left out) is driven."""
    from pathlib import Path

    from ..geometry.gltf import unit_scale
    from ..geometry.objlayout import read_obj_layout
    from .animation import frame_times, vertex_animation_glb_bytes
    from .drive3d import MeshDriver
    from .files import read_indices
    from .headmotion import parse_head_mode
    from .rigdrive import check_landmark_indices

    head = parse_head_mode(head)
    unit_scale(unit)                                  # a bad --unit: said before any work
    cap = read_capture(capture_dir)
    layout = None
    mesh_vf = _mesh_or_rig_neutral(mesh, neutral, exclude, log)
    if mesh is None:
        V, F, idx = _default_face_mesh()
        if landmarks is not None:
            idx = read_indices(landmarks)
        name = "the built-in face"
    else:
        if landmarks is None:
            raise parameter_error("landmarks", f"a JSON file of {cap.n_landmarks} vertex indices of {mesh}", "none")
        V, F = mesh_vf
        layout = read_obj_layout(Path(mesh) / neutral if Path(mesh).is_dir() else mesh)
        idx = read_indices(landmarks)
        name = str(mesh)
    idx = check_landmark_indices(idx, len(V), cap.n_landmarks,
                                 f"landmark index file {landmarks}" if landmarks else "landmark indices")
    t0 = time.perf_counter()
    driver = MeshDriver(V, F, idx, cap.landmarks[0], cap.vertices[0], cap.faces, head=head)
    anim = driver.run(cap.landmarks, cap.fps)
    glb, motion = vertex_animation_glb_bytes(V, F, anim.vertices, frame_times(cap.n_frames, cap.fps), unit=unit,
                                             layout=layout)
    glb_error, names = motion.max_error, motion.names
    _log(log, f"mesh: {name}, {len(V)} vertices; {cap.n_frames} frames; eq. 13 scale {driver.scale:.4g}; "
              f"factorised in {driver.setup_seconds:.2f} s; animation: {len(names)} morph targets "
              f"(PCA basis of {motion.rank}; largest vertex error {glb_error:.3g} mesh units, bound "
              f"{motion.tolerance:.3g})")
    with atomic_directory(out_dir) as stage:
        np.savez(stage / "frames.npz", vertices=anim.vertices.astype(np.float32), faces=anim.faces,
                 indices=idx, fps=np.float64(cap.fps))
        atomic_write_bytes(stage / "animation.glb", glb)
        summary = {"frames": cap.n_frames, "fps": cap.fps, "vertices": len(V), "scale_eq13": driver.scale, "head": head,
                   "morph_targets": len(names), "animation_max_vertex_error": glb_error,
                   "animation_error_bound": motion.tolerance, "animation_basis": motion.rank,
                   "seconds": time.perf_counter() - t0,
                   "z": "unchanged (monocular capture: in-plane motion only)"}
        if preview:
            summary.update(_write_previews(stage, capture_dir, cap, V, F, None, None, lambda f: anim.vertices[f],
                                           None, log, focus=idx))
        atomic_write_json(stage / "summary.json", summary)
    return summary


__all__ = ["run_animate2d", "run_animate3d", "run_retarget", "load_retarget_rig", "write_retarget_outputs",
           "weights_csv", "pose_csv"]
