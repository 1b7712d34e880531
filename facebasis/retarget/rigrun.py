"""The ``retarget`` job as a library call: a rig's weights and head pose from a capture (read, check
everything, compute, write atomically; :mod:`.pipeline` re-exports it beside the animation jobs)."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from ..atomic import atomic_directory, atomic_write_bytes, atomic_write_json
from ..errors import InputError, NamedText, parameter_error, parse_mode
from ..capture.trackfile import read_capture


def _log(log, text):
    if log is not None:
        log(text)


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


def _point_summary(weights, log) -> dict:
    """summary.json's ``landmark_weights`` (and a log line) from the per-point noise model's square-root
    weights (L,) or None: each landmark's weight of its squared residual, ``(r / max(sigma_l, r))^2``, 1
    for the typical landmark (:mod:`.pointnoise`)."""
    if weights is None:
        return {}
    w = np.asarray(weights, np.float64) ** 2                     # weights of the squared residuals
    low = np.flatnonzero(w < 0.5)
    _log(log, f"landmark noise per point: {len(low)} of {len(w)} landmarks weigh less than half the typical one"
              + (" (" + ", ".join(f"{i}: {w[i]:.2f}" for i in low[np.argsort(w[low])][:8]) + ")" if len(low) else ""))
    return {"landmark_weights": [round(float(v), 4) for v in w]}


def run_retarget(capture_dir, out_dir, rig=None, landmarks=None, exclusive=(), smooth=None, ridge=None,
                 neutral: str = "neutral.obj", solver: str = "certified", first_frame_neutral: bool | None = None,
                 identity: str | None = None, exclude=(), preview: bool = True, log=None, animate_pose: bool = True,
                 unit: str = "cm", rest_anchor: bool = True, focal: float | None = None,
                 noise_model=None, point_noise=None, gaze=None, rest_depth=None) -> dict:
    """Per-frame weights and head pose of a rig from a capture's landmarks (see :mod:`.rigdrive`).

    ``animation.glb`` holds the weights and (``animate_pose``) the head's rotation and translation,
    in metres from the rig's ``unit`` (``cm``, ``m`` or ``mm``).

    ``ridge`` None or "auto" (the default) sets the ridge from the capture's landmark noise
    (:func:`.rigdrive.auto_ridge`); a number fixes it. ``identity`` "auto" (default), "first-frame"
    or "rig" (:func:`.rigdrive.resolve_identity`; ``first_frame_neutral=True`` is "first-frame").
    ``rest_anchor``: with ``identity`` "auto", the first frame's posture may be the rest face
    (:class:`.rigdrive.RigRetargeter`). ``focal`` (px, None: weak perspective; principal point the image
    centre, recorded as ``principal_point_px``), ``noise_model`` ("pixels", the default, or "rig") and ``point_noise``
    ("per-point", the default, or "shared"; the landmarks' weights in ``summary.json``) and ``gaze`` ("conjugate", the
    default, or "free"; the tied pairs in ``summary.json``), ``rest_depth`` ("tangent", default, or "none"): :class:`.rigdrive.RigRetargeter`. ``exclude``: rig-folder files to leave out (globs). ``preview`` (default): also ``preview.mp4``
    (the source video beside the rig rendered with the solved weights and head rotation) and
    ``weights.png`` (the main weights over time), see :mod:`.preview`.
    """
    from ..rigging.examples import parse_pairs
    from ..geometry.gltf import unit_scale
    from .framefit import check_camera
    from .preview import rig_frames
    from .restdepth import REST_DEPTH_MODES
    from .rigdrive import (DEFAULT_SMOOTH, GAZE_MODES, NOISE_MODELS, POINT_NOISE_MODES, RigRetargeter, resolve_identity,
                           resolve_pairs)

    unit_scale(unit)                                  # a bad --unit: said before any work
    check_camera(focal, None)                         # a bad focal length, and a bad noise model
    noise_model = parse_mode("noise_model", noise_model, NOISE_MODELS, "pixels")
    point_noise = parse_mode("point_noise", point_noise, POINT_NOISE_MODES, "per-point")
    gaze = parse_mode("gaze", gaze, GAZE_MODES, "conjugate")
    rest_depth = parse_mode("rest_depth", rest_depth, REST_DEPTH_MODES, "tangent")
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
                               focal=focal, centre=centre, noise_model=noise_model,
                               point_noise=point_noise, gaze=gaze, rest_depth=rest_depth)
    ridge_text = "auto (from the landmark noise)" if ridge == "auto" else f"{ridge:g}"
    _log(log, f"rig {r.source}: {r.n_shapes} shapes, {r.n_vertices} vertices; {len(idx)} landmarks; "
              f"{len(named)} exclusive pairs" + (": " + ", ".join(f"{a}:{b}" for a, b in named) if named else "")
         + f"; smooth {smooth:g}, ridge {ridge_text}; identity {identity}; gaze {gaze}"
         + (f" ({len(solver_obj.gaze_pairs)} eye-look pairs tied)" if gaze == "conjugate" else ""))
    result = solver_obj.run(cap.landmarks, cap.lost, cap.fps)
    extra = {"smooth": smooth, "ridge": result.ridge, "ridge_rule": "auto" if ridge == "auto" else "given",
             "solver": solver, "identity": identity, "first_frame_neutral": identity == "first-frame",
             "focal_px": focal, "principal_point_px": None if centre is None else [float(c) for c in centre],
             "noise_model": solver_obj.noise_model, "noise_pixel_scale": result.pixel_scale,
             "point_noise": point_noise, "gaze": gaze, "rest_depth": rest_depth,
             "gaze_pairs": [[r.names[a], r.names[b]] for a, b in solver_obj.gaze_pairs]}
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
    extra.update(_point_summary(result.point_weights, log))
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


__all__ = ["run_retarget", "load_retarget_rig", "write_retarget_outputs", "weights_csv", "pose_csv"]
