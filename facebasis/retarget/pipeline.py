"""The three retargeting jobs as library calls (read, check everything, compute, write atomically).

Each ``run_*`` checks every input before any computation and writes its output folder through
:func:`facebasis.atomic.atomic_directory`, so a failed run leaves no folder behind. They return a
small summary dict (also written as ``summary.json``).
"""

from __future__ import annotations

import csv
import io
import time
from pathlib import Path

import numpy as np

from ..atomic import atomic_directory, atomic_write_bytes, atomic_write_json
from ..errors import InputError, NamedText, parameter_error, parse_mode
from ..capture.trackfile import OVERLAY_FILE, read_capture


def _log(log, text):
    if log is not None:
        log(text)


# ----------------------------------------------------------------------------------------------
# 2D

def run_animate2d(capture_dir, out_dir, image=None, landmarks=None, gif_seconds: float = 4.0, head: str = "still",
                  log=None, amplitude: str = "feature") -> dict:
    """Animate a cartoon image (default: the built-in cartoon) by a capture folder.

    Writes ``cartoon.mp4`` (the source video's frames beside the cartoon when the capture records
    its video), ``cartoon.gif`` (the first ``gif_seconds``), ``cartoon_mesh.npz`` (vertices (T, N, 2),
    faces), ``cartoon_rest.png`` and ``summary.json``. ``head``: "still" (the cartoon shows the
    expression only) or "follow" (it also moves with the head), see :meth:`.CartoonAnimator.drive`.
    ``amplitude``: "feature" (each eye and the mouth in the cartoon's own proportions,
    :mod:`.featurescale`) or "uniform" (the paper's one scale). No frame is written with a triangle
    of the warp mesh flipped against the rest cartoon.
    """
    from .files import read_image, read_points2d
    from .headmotion import parse_head_mode
    from .media import check_video, read_video_frames, side_by_side, write_gif, write_mp4
    from .warp2d import CartoonAnimator

    from .featurescale import parse_amplitude

    head = parse_head_mode(head)
    amplitude = parse_amplitude(amplitude)
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
    anim = CartoonAnimator(img, pts, cap.landmarks[0], cap.vertices[0], cap.faces, head=head, amplitude=amplitude)
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
                   "amplitude": amplitude,
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


# ----------------------------------------------------------------------------------------------
# rig

def load_retarget_rig(rig=None, landmarks=None, neutral: str = "neutral.obj", n_landmarks: int | None = None,
                      exclude=(), log=None):
    """(rig, landmark indices, default exclusive pairs) for ``--rig`` (None/"default": built-in face).

    ``exclude``: globs of rig-folder files to leave out (``--exclude``, as ``transfer``'s); a folder
    whose shapes look like identity modes or are many gets a one-line warning through ``log``
    (:func:`facebasis.geometry.rig.rig_folder_warning`)."""
    from ..geometry.rig import load_rig_folder, rig_folder_warning
    from .files import read_indices
    from .rigdrive import check_landmark_indices

    exclude = tuple(exclude or ())
    if rig is None or str(rig) == "default":
        if exclude:
            raise InputError(what="{exclude}", expected="a rig folder ({rig} RIG_DIR) to leave files out of",
                             found=f"the built-in face ({{exclude}} {' '.join(exclude)})",
                             params={"exclude": "exclude", "rig": "rig"})
        from ..defaults.face import EXCLUSIVE_PAIRS, default_template
        from ..defaults.face_landmarks import face_landmarks

        r = default_template()
        idx = face_landmarks() if landmarks is None else read_indices(landmarks)
        default_pairs = EXCLUSIVE_PAIRS
    else:
        if landmarks is None:
            raise parameter_error("landmarks", f"a JSON file of vertex indices of rig {rig}", "none")
        r = load_rig_folder(rig, neutral, exclude)
        idx = read_indices(landmarks)
        default_pairs = ()
        warning = rig_folder_warning(r)
        if warning:
            _log(log, warning)
    n = len(idx) if n_landmarks is None else n_landmarks
    idx = check_landmark_indices(idx, r.n_vertices, n,
                                 f"landmark index file {landmarks}" if landmarks else "built-in face landmarks")
    return r, idx, default_pairs


def weights_csv(names, weights) -> bytes:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["frame", *names])
    for f, row in enumerate(np.asarray(weights)):
        w.writerow([f, *(f"{v:.6f}" for v in row)])
    return buf.getvalue().encode()


def pose_csv(result) -> bytes:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["frame", "time_s", "scale_px_per_unit", "rot_x_rad", "rot_y_rad", "rot_z_rad", "tx_px", "ty_px",
                "residual_px"])
    rv = result.rotation_vectors()
    for f in range(result.n_frames):
        w.writerow([f, f"{f / result.fps:.6f}", f"{result.scale[f]:.6f}", *(f"{v:.6f}" for v in rv[f]),
                    *(f"{v:.4f}" for v in result.translation[f]), f"{result.residual[f]:.4f}"])
    return buf.getvalue().encode()


def write_retarget_outputs(stage: Path, rig, result, pairs_named, extra: dict | None = None, *,
                           animate_pose: bool = True, unit: str = "cm") -> dict:
    """``weights.csv``, ``weights.json``, ``pose.csv``, ``animation.glb``, ``summary.json`` into ``stage``;
    ``animation.glb`` animates the head pose beside the weights unless ``animate_pose`` is False, in
    metres from the rig's ``unit``."""
    from .animation import write_rig_animation

    atomic_write_bytes(stage / "weights.csv", weights_csv(result.names, result.weights))
    atomic_write_json(stage / "weights.json", {"fps": result.fps, "names": list(result.names),
                                               "weights": np.round(result.weights, 6).tolist()})
    atomic_write_bytes(stage / "pose.csv", pose_csv(result))
    write_rig_animation(stage / "animation.glb", rig, np.clip(result.weights, 0.0, 1.0), result.fps, unit=unit,
                        pose=(result.scale, result.rotation, result.translation) if animate_pose else None)
    summary = {"frames": result.n_frames, "fps": result.fps, "shapes": rig.n_shapes,
               "exclusive": [f"{a}:{b}" for a, b in pairs_named],
               "residual_px_mean": float(np.nanmean(result.residual)),
               "residual_px_max": float(np.nanmax(result.residual)),
               "ms_per_frame": 1e3 * result.seconds / max(result.n_frames, 1), **(extra or {})}
    atomic_write_json(stage / "summary.json", summary)
    return summary


def _parse_ridge(ridge):
    """None -> the default ("auto"); "auto" stays; anything else a finite number >= 0."""
    from .rigdrive import DEFAULT_RIDGE

    if ridge is None:
        return DEFAULT_RIDGE
    if isinstance(ridge, str) and ridge.strip().lower() == "auto":
        return "auto"
    try:
        value = float(ridge)
    except (TypeError, ValueError):
        value = float("nan")
    if not (np.isfinite(value) and value >= 0):
        raise parameter_error("ridge", "a finite number >= 0", ridge, note=" (or 'auto', the default)")
    return value


#: relative landmark noise (rms residual over the rms landmark radius of the rig) above which the
#: retarget log suggests calibrating the identity (--identity auto, or first-frame): ~1% for 1 px noise
#: on a synthetic 20 px/cm face, 7% on a real webcam clip fitted with ICT's own neutral
FIRST_FRAME_HINT = 0.03


#: the log's words for the landmark evidence of a start at rest (:mod:`.reststart`)
_START = {True: " (the take starts at rest: still, lips closed)", False: " (the take does not start at rest)"}


def _finite(v):
    return float(v) if np.isfinite(v) else None


def run_retarget(capture_dir, out_dir, rig=None, landmarks=None, exclusive=(), smooth=None, ridge=None,
                 neutral: str = "neutral.obj", solver: str = "certified", first_frame_neutral: bool | None = None,
                 identity: str | None = None, exclude=(), preview: bool = True, log=None, animate_pose: bool = True,
                 unit: str = "cm", rest_anchor: bool = True, focal: float | None = None,
                 noise_model: str | None = None) -> dict:
    """Per-frame weights and head pose of a rig from a capture's landmarks (see :mod:`.rigdrive`).

    ``animation.glb`` holds the weights and (``animate_pose``) the head's rotation and translation,
    in metres from the rig's ``unit`` (``cm``, ``m`` or ``mm``).

    ``ridge`` None or "auto" (the default) sets the ridge from the capture's landmark noise
    (:func:`.rigdrive.auto_ridge`); a number fixes it. ``identity`` "auto" (default), "first-frame"
    or "rig" (:func:`.rigdrive.resolve_identity`; ``first_frame_neutral=True`` is "first-frame").
    ``rest_anchor``: with ``identity`` "auto", the first frame's posture may be the rest face
    (:class:`.rigdrive.RigRetargeter`). ``focal`` (px, None: weak perspective; principal point the image
    centre, recorded as ``principal_point_px``) and ``noise_model`` ("pixels", the default, or "rig"): :class:`.rigdrive.RigRetargeter`. ``exclude``: rig-folder files to leave out (globs). ``preview`` (default): also ``preview.mp4``
    (the source video beside the rig rendered with the solved weights and head rotation) and
    ``weights.png`` (the main weights over time), see :mod:`.preview`.
    """
    from ..rigging.examples import parse_pairs
    from ..geometry.gltf import unit_scale
    from .framefit import check_camera
    from .preview import rig_frames
    from .rigdrive import DEFAULT_SMOOTH, NOISE_MODELS, RigRetargeter, resolve_identity, resolve_pairs

    unit_scale(unit)                                  # a bad --unit: said before any work
    check_camera(focal, None)                         # a bad focal length, and a bad noise model
    noise_model = parse_mode("noise_model", noise_model, NOISE_MODELS, "pixels")
    ridge = _parse_ridge(ridge)
    from .rigdrive import IDENTITY_MODES

    if identity is not None and (not isinstance(identity, str) or identity not in IDENTITY_MODES):
        raise parameter_error("identity", f"one of {', '.join(IDENTITY_MODES)}", repr(identity))
    try:
        identity = resolve_identity(identity, first_frame_neutral)
    except InputError as exc:
        raise InputError(what="{identity} and {first_frame_neutral}", expected=exc.expected, found=exc.found,
                         params={"identity": "identity", "first_frame_neutral": "first_frame_neutral"}) from None
    cap = read_capture(capture_dir)
    r, idx, default_pairs = load_retarget_rig(rig, landmarks, neutral, cap.n_landmarks, exclude, log)
    named = parse_pairs(exclusive) if exclusive else tuple(default_pairs)
    resolve_pairs(r, named)                           # unknown names: RigError, before any work
    smooth = DEFAULT_SMOOTH if smooth is None else float(smooth)
    centre = None if focal is None else (cap.size[0] / 2.0, cap.size[1] / 2.0)
    solver_obj = RigRetargeter(r, idx, named, smooth, ridge, solver=solver, identity=identity, rest_anchor=rest_anchor,
                               focal=focal, centre=centre, noise_model=noise_model)
    ridge_text = "auto (from the landmark noise)" if ridge == "auto" else f"{ridge:g}"
    _log(log, f"rig {r.source}: {r.n_shapes} shapes, {r.n_vertices} vertices; {len(idx)} landmarks; "
              f"{len(named)} exclusive pairs" + (": " + ", ".join(f"{a}:{b}" for a, b in named) if named else "")
         + f"; smooth {smooth:g}, ridge {ridge_text}; identity {identity}")
    result = solver_obj.run(cap.landmarks, cap.lost, cap.fps)
    extra = {"smooth": smooth, "ridge": result.ridge, "ridge_rule": "auto" if ridge == "auto" else "given",
             "solver": solver, "identity": identity, "first_frame_neutral": identity == "first-frame",
             "focal_px": focal, "principal_point_px": None if centre is None else [float(c) for c in centre],
             "noise_model": solver_obj.noise_model, "noise_pixel_scale": result.pixel_scale}
    cal = result.calibration
    if cal is not None:
        moved = float(np.sqrt(np.mean(np.sum(cal.offset ** 2, axis=1))))
        extra.update({"identity_rms_px_rig_neutral": cal.rms_before, "identity_rms_px_calibrated": cal.rms_after,
                      "identity_offset_rms_rig_units": moved, "identity_pilot_frames": len(cal.frames)})
        steps = (f"; rest face {'kept' if cal.rest_applied else 'not kept'}"
                 f"{' (at the start of the take)' if cal.rest_anchored else ''}{_START.get(cal.rest_start, '')}, quantile baseline "
                 f"{'kept' if cal.quantile_applied else 'not kept'}" if identity == "auto" else "")
        extra.update({"identity_rest_face": bool(cal.rest_applied), "identity_quantile": bool(cal.quantile_applied),
                      "identity_rest_anchor": bool(rest_anchor), "identity_rest_anchored": bool(cal.rest_anchored),
                      "identity_rest_start": cal.rest_start, "identity_demand_ratio": _finite(cal.demand_ratio)})
        _log(log, f"identity: static landmark offset estimated on {len(cal.frames)} pilot frames "
                  f"({moved:.3g} rig units rms){steps}; pilot residual {cal.rms_before:.2f} px with the rig's "
                  f"neutral, {cal.rms_after:.2f} px calibrated")
    if ridge == "auto":
        v0 = r.neutral[idx]
        radius = float(np.sqrt(np.mean(np.sum((v0 - v0.mean(0)) ** 2, axis=1))))
        relative = result.noise / radius if radius > 0 else float("nan")
        noise_px = result.noise * float(np.nanmedian(result.scale))
        extra.update({"noise_rig_units": result.noise, "noise_px": noise_px, "noise_relative": relative})
        _log(log, f"landmark noise {noise_px:.2f} px ({result.noise:.3g} rig units, {100 * relative:.1f}% of the "
                  f"face's landmark radius): ridge {result.ridge:.3g}")
        if identity == "rig" and relative > FIRST_FRAME_HINT:
            _log(log, NamedText("hint: the rig's neutral reproduces these landmarks poorly (the face's shape is "
                                "not the rig's, or its landmarks are defined differently); {identity} auto (the "
                                "default) estimates the person's neutral from the capture, {identity} first-frame "
                                "takes frame 0 as it"))
    with atomic_directory(out_dir) as stage:
        if preview:
            extra.update(_write_previews(stage, capture_dir, cap, r.neutral, r.faces, r.names, result.weights,
                                         rig_frames(r, result.weights), result.rotation, log, focus=idx))
        summary = write_retarget_outputs(stage, r, result, named, extra, animate_pose=animate_pose, unit=unit)
    return summary


def _write_previews(stage, capture_dir, cap, rest, faces, names, weights, frame_vertices, rotation, log,
                    focus=None) -> dict:
    """``preview.mp4`` (+ ``weights.png`` when there are weights) into ``stage``; summary entries."""
    from .preview import plot_weights, source_video, write_preview

    video = source_video(capture_dir, cap)
    st = write_preview(stage / "preview.mp4", rest, faces, frame_vertices, cap.n_frames, cap.fps, rotation, video,
                       focus=focus)
    out = {"preview_frames": st.frames, "preview_size": [st.width, st.height], "preview_ms_per_frame": st.ms_per_frame,
           "preview_source": st.source}
    if weights is not None:
        out["weights_plot_shapes"] = plot_weights(stage / "weights.png", list(names), weights, cap.fps)
    _log(log, f"preview: {st.frames} frames {st.width}x{st.height}"
              + (f" beside {video}" if video is not None else "") + f", {st.ms_per_frame:.1f} ms per frame")
    return out


__all__ = ["run_animate2d", "run_animate3d", "run_retarget", "load_retarget_rig", "write_retarget_outputs",
           "weights_csv", "pose_csv"]
