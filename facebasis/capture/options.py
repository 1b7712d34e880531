"""Options of :class:`facebasis.capture.tracker.FaceTracker`."""

from __future__ import annotations

from dataclasses import dataclass, field

from .meshtrack import MeshOptions
from .particle import FilterOptions


@dataclass(frozen=True)
class TrackerOptions:
    """Options of :class:`FaceTracker`.

    Attributes
    ----------
    use_filter : bool
        Stabilise LK with the CONDENSATION filter (False: raw LK, for comparison).
    refine_mesh : bool
        Run the Levenberg-Marquardt mesh tracking after the harmonic initialisation.
    mesh_spacing : float or None
        Mesh edge length in pixels (default: face width / 12).
    lk_levels : int
        Pyramid levels above the base image.
    fb_threshold : float
        Forward-backward error limit, pixels at reference face size.
    windows : dict or None
        Per-region LK windows ``{region: (width, height)}`` overriding
        :data:`facebasis.capture.landmarks.DEFAULT_WINDOWS`.
    inner_lips : str
        ``"auto"`` (default): as ``"follow"``, except that an inner-lip point whose first-frame
        appearance the drift correction finds again this frame (accepted by ``drift_max_shift`` and
        ``drift_zncc``) keeps its tracked position and renews the lip-thickness offset ``o`` it is
        followed with once it is no longer found (a mouth that opens changes the patch). On warped
        faces, where a closed mouth is stretched but stays closed, following the outer lip put the
        inner lips 1.5-2 px off on a 205 px face (mean; 4 px worst), tracking them 0.2-0.5 px
        (reports/capture/gt_benchmark.md). ``"follow"``: the inner-lip points of a 68-point iBUG set (61-63, 65-67) follow
        their outer-lip partner across the same lip (50-52, 56-58),
        ``p_inner = p_outer + a o``, with ``o`` the lip-thickness offset of the first frame and
        ``a`` the complex factor (rotation and scale) of the least-squares similarity of the outer
        lip (48-59) from the first frame, see :func:`follow_outer_lip`. In detector mode each
        detection's own offset (inner minus partner, brought back by ``a``) renews ``o``
        (exponential average, :data:`LIP_RENEW`). ``"track"``: LK and the filter on the lip line
        itself (the earlier behaviour): closed lips put an upper and a lower point on one patch, so
        they move alike and the mouth does not open (reports/reproduction/real_clips_notes.md).
    drift_correction : bool
        Correct every frame's LK positions against the first frame's appearance (template update
        with drift correction, Matthews, Ishikawa & Baker 2004): each landmark's first-frame patch
        (its LK window, blurred) is aligned to the new frame by Gauss-Newton
        (:func:`facebasis.capture.lk.template_align`) from the frame-to-frame position, under the
        local affine deformation of the mesh since frame 0 (:func:`facebasis.capture.lk.local_affine`);
        the result is accepted where it lies within ``drift_max_shift`` of the frame-to-frame
        position and its zero-mean NCC with the template is at least ``drift_zncc``; otherwise the
        frame-to-frame position stands. Accepted points count as confident measurements for the
        filter. Without it, frame-to-frame LK errors add up over a take (drift).
    drift_affine : bool
        Solve for the affine part of the template warp too (started at the mesh's); False keeps the
        mesh's affine and solves for the translation only.
    drift_max_shift : float
        Largest accepted correction, pixels at reference face size.
    drift_zncc : float
        Smallest accepted zero-mean NCC of the aligned patch with the first frame's.
    drift_blur : float
        Gaussian blur (pixels at reference face size, times the clipped face scale) of the image the
        drift correction aligns on (the mesh stage keeps ``mesh.blur``). 0.5: aligned on the mesh's
        image (1.5, before), the blurred first-frame patches lost the fine texture that pins them
        along an edge, and the points slid along the lip line and the eyelids as the mouth opened
        and the eyes blinked, by up to 4 px on a 345 px wide face (Grace Hopper upscaled 2x:
        landmarks 0.40 -> 0.20 px mean, max 3.9 -> 1.2; every warped face of
        reports/capture/gt_benchmark.md gains). Must be >= 0.
    drift_recovery : float
        For a point lost in the previous frame, ``drift_max_shift`` is multiplied by this and the
        NCC threshold raised halfway to 1, so the first frame's appearance can pull it back.
    outlier_distance : float
        A landmark farther than this many (frame-0) face widths from where the affine motion of its
        neighbours since frame 0 puts it is moved there and reported lost (0: off); see
        :meth:`FaceTracker._repair_outliers`.
    detected_lids : float
        In detector mode, weight ``g`` in ``[0, 1]`` of each frame's detected eyelids: every lid point is
        placed in the frame of its eye's tracked corners at the running average
        ``z_t = z_{t-1} + g (z_det - z_{t-1})`` of its detected coordinate there
        (:mod:`facebasis.capture.eyelids`), so the eyes blink when the detector sees a blink. 0: the
        lids are tracked as without a detector (the filter, trusting Lucas-Kanade and the drift
        correction against the open first-frame eye, barely let a detection move them). Acts only on frames
        with a detection (an eye the detector missed, or tracking only, places the lids as
        ``lid_search`` says); the ``capture`` command refuses it without a detector.
    lid_search : bool
        Without a detection (tracking only, or a frame the detector missed), keep each lid point at
        its first-frame place along the eye and search the lid across the eye for the first-frame look
        of its outer side (:class:`facebasis.capture.eyelids.LidSearch`). False: the lids are tracked
        as the other points (they slid along the lid line and did not follow a lid covering the eye).
    filter : FilterOptions
    mesh : MeshOptions
    """

    use_filter: bool = True
    refine_mesh: bool = True
    mesh_spacing: float | None = None
    lk_levels: int = 3
    fb_threshold: float = 1.0
    windows: dict | None = None
    inner_lips: str = "auto"
    drift_correction: bool = True
    drift_affine: bool = True
    drift_max_shift: float = 1.0
    drift_zncc: float = 0.9
    drift_blur: float = 0.5
    drift_recovery: float = 4.0
    outlier_distance: float = 0.15
    detected_lids: float = 0.7
    lid_search: bool = True
    filter: FilterOptions = field(default_factory=FilterOptions)
    mesh: MeshOptions = field(default_factory=MeshOptions)
