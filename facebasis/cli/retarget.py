"""Command-line commands of expression reproduction: animate2d, animate3d, retarget.

``register(subparsers)`` adds them to the ``facebasis`` command; the handlers only parse, call
:mod:`facebasis.retarget.pipeline` and print.
"""

from __future__ import annotations

from .common import Once, add_rig_folder_args, say
from .outputs import Outputs, capture_video

_OUT = (("out", "folder", "--out"),)


def _capture_video(args):
    return capture_video(args.capture) + ([args.rig] if getattr(args, "rig", None) not in (None, "default") else [])


def cmd_animate2d(args) -> int:
    from ..retarget.pipeline import run_animate2d

    s = run_animate2d(args.capture, args.out, args.image, args.landmarks, head=args.head, log=say(args.command),
                      amplitude=args.amplitude, jaw=args.jaw)
    beside = f", beside {s['video_beside']}" if s["video_beside"] else ""
    print(f"animated {s['frames']} frames ({s['warp_ms_per_frame']:.1f} ms per frame warp{beside}) -> {args.out}")
    return 0


def cmd_animate3d(args) -> int:
    from ..retarget.pipeline import run_animate3d

    s = run_animate3d(args.capture, args.out, args.mesh, args.landmarks, head=args.head, log=say(args.command),
                      unit=args.unit, neutral=args.neutral, exclude=args.exclude, preview=not args.no_preview)
    print(f"drove {s['vertices']} vertices over {s['frames']} frames in {s['seconds']:.2f} s -> {args.out}")
    return 0


def cmd_retarget(args) -> int:
    import math

    from ..errors import InputError
    from ..retarget.pipeline import run_retarget

    if args.smooth is not None and not (math.isfinite(args.smooth) and args.smooth >= 0):
        raise InputError(f"--smooth: expected a finite number >= 0, found {args.smooth}")

    if args.first_frame_neutral:
        if args.identity not in (None, "first-frame"):
            raise InputError(f"--first-frame-neutral: expected no other --identity, found --identity {args.identity} "
                             f"(--first-frame-neutral is the older spelling of --identity first-frame)")
        print("note: --first-frame-neutral is the older spelling of --identity first-frame (it still works)")
    s = run_retarget(args.capture, args.out, args.rig, args.landmarks, args.exclusive, args.smooth,
                     ridge=args.ridge, neutral=args.neutral,
                     identity="first-frame" if args.first_frame_neutral else args.identity, exclude=args.exclude,
                     preview=not args.no_preview, log=say(args.command), animate_pose=not args.no_pose, unit=args.unit,
                     rest_anchor=args.rest_anchor != "off", focal=args.focal, noise_model=args.noise_model,
                     point_noise=args.point_noise, gaze=args.gaze, rest_depth=args.rest_depth)
    print(f"solved {s['frames']} frames, {s['ms_per_frame']:.2f} ms per frame; landmark residual "
          f"{s['residual_px_mean']:.3f} px mean, {s['residual_px_max']:.3f} px max -> {args.out}")
    return 0


def _head_options(p, what: str) -> None:
    """``--head still|follow`` and its shorthand ``--follow-head`` (animate2d, animate3d)."""
    p.add_argument("--head", default="still", metavar="still|follow",
                   help=f"still (default): the {what} keeps its size and place and shows the expression only (the "
                        f"head's scale, in-plane rotation and shift are taken out of the capture); follow: the "
                        f"whole {what} also moves, turns and scales with the head")
    p.add_argument("--follow-head", dest="head", action="store_const", const="follow",
                   help="the same as --head follow")


def _camera_args(p) -> None:
    """--focal and --noise-model (the camera and the landmark noise model of the rig fit)."""
    p.add_argument("--focal", default=None, action=Once, type=float, metavar="PX",
                   help="the camera's focal length in pixels (principal point: the image centre); every fit then "
                        "divides the perspective out of the landmarks, so a face that comes closer is not read as "
                        "an expression (default: a weak-perspective camera)")
    p.add_argument("--noise-model", default=None, action=Once, choices=("pixels", "rig"),
                   help="landmark noise of a fixed size in 'pixels' (default: a frame whose face is smaller in the "
                        "image weighs its landmarks less) or in 'rig' units (the former model)")
    p.add_argument("--point-noise", default=None, action=Once, choices=("per-point", "shared"),
                   help="'per-point' (default): every landmark's own noise is estimated from the capture and a "
                        "landmark the rig reproduces worse than the typical one weighs less (a detector's jaw "
                        "line or brows, an eyelid); 'shared': one noise for all landmarks (the former model)")
    p.add_argument("--gaze", default=None, action=Once, choices=("conjugate", "free"),
                   help="'conjugate' (default): the two eyes look the same way (a prior on the difference of the "
                        "rig's conjugate eye-look pairs, up with up, down with down, one eye's in with the other's out: "
                        "landmarks see no iris, only the lids); "
                        "'free': each eye's look shapes on their own (the former model)")
    p.add_argument("--rest-depth", default=None, action=Once, choices=("tangent", "none"),
                   help="with --identity auto: 'tangent' (default) also tries the rest face's landmark offsets lifted "
                        "onto the rig's skin along each frame's view (a detector's convention slides along the skin), "
                        "kept if the check frames fit better than with the flat offsets; 'none': flat (the former model)")


def _cartoon_options(p) -> None:
    """animate2d's ``--amplitude`` and ``--jaw``: how the cartoon's features and contour follow the capture."""
    p.add_argument("--amplitude", default="feature", metavar="feature|uniform",
                   help="how far each feature moves (default feature: each eye and the mouth in the "
                        "cartoon's own proportions, the brows with their eyes, e.g. a cartoon eye twice as tall "
                        "closes by twice as much; "
                        "uniform: one scale for the whole face, the paper's eq. 12-13)")
    p.add_argument("--jaw", default=None, action=Once, metavar="lips|capture",
                   help="the face contour on a head held still (default lips: it follows the lower lip, so the "
                        "chin drops as the mouth opens and head turns do not swing the outline; capture: the "
                        "captured contour, turns included)")


def register(subparsers) -> None:
    """Add ``animate2d``, ``animate3d`` and ``retarget`` to an argparse sub-parser collection."""
    p = subparsers.add_parser(
        "animate2d", help="animate a single cartoon image with a tracked face video",
        description="Place the tracked face mesh on a cartoon image (radial basis functions trained on the "
                    "landmarks) and warp the image triangle by triangle for every frame. Writes cartoon.mp4 "
                    "(beside the source video when the capture folder records it), cartoon.gif and "
                    "cartoon_mesh.npz.")
    p.add_argument("capture", metavar="CAPTURE_DIR", help="capture folder with track.npz")
    p.add_argument("--image", default=None, metavar="CARTOON.png",
                   help="cartoon image (default: the built-in cartoon face)")
    p.add_argument("--landmarks", default=None, metavar="CARTOON.pts",
                   help="the cartoon's landmarks, .pts or .json, as many as the capture has (needed with --image)")
    _head_options(p, "cartoon")
    _cartoon_options(p)
    p.add_argument("--out", required=True, help="output folder")
    p.set_defaults(func=cmd_animate2d, outputs=Outputs(writes=_OUT, reads=("capture", "image", "landmarks"),
                                                      derived=_capture_video))

    p = subparsers.add_parser(
        "animate3d", help="drive a 3D face mesh with a tracked face video",
        description="Move the mesh's landmark vertices by the tracked landmark motion (in the mesh's x-y "
                    "plane, scaled to the mesh) and deform the rest smoothly. Writes frames.npz and an "
                    "animated animation.glb.")
    p.add_argument("capture", metavar="CAPTURE_DIR", help="capture folder with track.npz")
    p.add_argument("--mesh", default=None, metavar="FACE.obj|RIG_DIR",
                   help="target mesh facing +z with y up, or a rig folder whose neutral is driven (default: the "
                        "built-in face)")
    add_rig_folder_args(p, template=None, where="a rig folder given as --mesh")
    p.add_argument("--no-preview", action="store_true",
                   help="do not write preview.mp4 (the source video beside the driven mesh)")
    p.add_argument("--landmarks", default=None, metavar="INDICES.json",
                   help="JSON list of the mesh's vertex indices, one per capture landmark (needed with --mesh)")
    p.add_argument("--unit", default="cm", metavar="cm|m|mm",
                   help="the mesh's length unit; animation.glb is written in metres (default cm: the built-in face)")
    _head_options(p, "mesh")
    p.add_argument("--out", required=True, help="output folder")
    p.set_defaults(func=cmd_animate3d, outputs=Outputs(writes=_OUT, reads=("capture", "mesh", "landmarks"),
                                                      derived=_capture_video))

    p = subparsers.add_parser(
        "retarget", help="blendshape weights and head pose of a rig for every frame of a tracked video",
        description="Fit, frame by frame, the rig's weights (between 0 and 1, exclusive pairs never both "
                    "active, smooth over time) and a weak-perspective head pose to the tracked landmarks. "
                    "Writes weights.csv, weights.json, pose.csv and an animated animation.glb.")
    p.add_argument("capture", metavar="CAPTURE_DIR", help="capture folder with track.npz")
    p.add_argument("--rig", default=None, metavar="RIG_DIR",
                   help="rig folder (neutral + one mesh per blendshape), or 'default' for the built-in face "
                        "(the default)")
    add_rig_folder_args(p, template=None, exclude_note=" for an ICT-FaceKit FaceXModel folder; a folder whose "
                        "shape names look like identity modes, or that has more than 100 shapes, gets a warning")
    p.add_argument("--no-preview", action="store_true",
                   help="do not write preview.mp4 (the source video beside the rig rendered with the solved "
                        "weights and head rotation) and weights.png (the main weights over time)")
    p.add_argument("--landmarks", default=None, metavar="INDICES.json",
                   help="JSON list of the rig's vertex indices, one per capture landmark (needed with a rig folder)")
    p.add_argument("--exclusive", action="extend", nargs="+", default=[], metavar="SHAPE_A:SHAPE_B",
                   help="shape pairs that are never active together; give several after one flag "
                        "(--exclusive A:B C:D) or repeat the flag (default: none for a rig folder, the "
                        "built-in face's own pairs for the built-in face)")
    p.add_argument("--smooth", type=float, default=None, metavar="S",
                   help="temporal smoothness: weight of the change from the previous frame (default 0.05; 0 "
                        "solves every frame on its own)")
    p.add_argument("--ridge", default=None, metavar="R|auto",
                   help="pull of every weight towards 0, in the rig's squared units (rig units after dividing "
                        "the pixels by the head's scale). Default 'auto': (noise / 0.5)^2, at least 0.001, where "
                        "noise is the median rms landmark residual (rig units) of up to 40 evenly spaced frames "
                        "each fitted on its own, i.e. a "
                        "prior of standard deviation 0.5 on every weight against the capture's own landmark noise; "
                        "0.001 on noise-free data, about 0.2 on a webcam clip with --first-frame-neutral, so "
                        "shapes stop saturating on noise and face-shape differences (see reports/reproduction). "
                        "A number fixes it")
    p.add_argument("--identity", default=None, metavar="auto|first-frame|rig|quantile",
                   help="how the filmed person's neutral face is obtained, so that the difference between their "
                        "face and the rig's is not read as expression. 'auto' (default): estimated from the capture, "
                        "no neutral frame needed: the rest face (the median of the densest quarter of 100 pilot "
                        "faces, posed on the rig's neutral; kept if it fits the pilot frames better), then shapes "
                        "that stay on through nearly all of it (the lowest 10%% of their weights on 40 pilot frames) "
                        "plus the median landmark residual no shape can produce; of the two calibrations (with and "
                        "without the rest face) the one that fits the pilot frames better is kept. 'quantile': the "
                        "second step alone (the default before). 'first-frame': frame 0 shows the neutral face "
                        "(wrong if the capture starts on an expression). 'rig': the rig's own neutral")
    p.add_argument("--rest-anchor", default=None, action=Once, choices=("on", "off"),
                   help="with --identity auto: when the first frame's posture recurs in the clip and, as the neutral, "
                        "asks the frames for no more negative weight than the commonest posture, the rest face is "
                        "that posture (default on); 'off': the densest cluster of pilot faces alone")
    _camera_args(p)
    p.add_argument("--first-frame-neutral", action="store_true", help="older spelling of --identity first-frame")
    p.add_argument("--unit", default="cm", metavar="cm|m|mm",
                   help="the rig's length unit; animation.glb is written in metres (default cm: ICT-FaceKit and the "
                        "built-in face)")
    p.add_argument("--no-pose", action="store_true",
                   help="leave the head's rotation and translation out of animation.glb (weights only)")
    p.add_argument("--out", required=True, help="output folder")
    p.set_defaults(func=cmd_retarget, outputs=Outputs(writes=_OUT, reads=("capture", "landmarks"),
                                                     derived=_capture_video))


__all__ = ["register", "cmd_animate2d", "cmd_animate3d", "cmd_retarget"]
