"""Expression reproduction: drive a cartoon image, a 3D mesh or a blendshape rig with a tracked face.

Method (Wu & Ju, "Markerless facial expression capture and reproduction", Acta Electronica Sinica,
2016(9), reproduction part, eq. 10-13): a multiquadric radial basis function network trained on the
landmark pairs places the capture's first-frame mesh on the target (eq. 10-11); the captured
displacements, scaled by the ratio of the two meshes' mean edge lengths (eq. 12-13), move the
target. In 2D the cartoon image is warped triangle by triangle with bilinear interpolation; in 3D
the target's landmark vertices are moved and the rest follows a smooth (biharmonic, factor-once)
deformation. Beyond the paper, the landmarks also drive a blendshape rig: per-frame weights
(bounds, exclusive pairs solved to a certified optimum, temporal smoothness) with a weak-perspective
head pose.

Modules
-------
rbf        eq. 10-13: multiquadric RBF correspondence, mean-edge-length scale
warp2d     a cartoon image animated by the capture (:class:`CartoonAnimator`)
raster2d   the vectorised piecewise-affine image warp (scanline rasteriser, ``cv2.remap``)
mouth2d    the mouth of the cartoon warp: how open it is drawn (opacity), the inner-lip strip of a cut mesh
mouthpaint an open mouth painted as a mouth: upper teeth, a cavity darkest at the back, the tongue
eyepaint   a closing eye painted as a lid coming down over it, with a lash line at its edge
foldfree   fold-free 2D mesh deformation (bounded-distortion projection, local/global, exact check)
headmotion the head's per-frame similarity apart from the expression (Procrustes on stable landmarks)
jawline    the face contour of a still head: it follows the lower lip, not the head's turns
featurescale eq. 12 per feature: each eye and the mouth moved in the target's own proportions
drive3d    biharmonic mesh driving by landmark vertices (:class:`MeshDriver`)
rigdrive   rig weights + head pose from 2D landmarks (:class:`RigRetargeter`)
rigoptions the rig fit's identity mode, landmark vertex indices and exclusive pairs, checked
pointnoise each landmark's own noise from the pilot fits: a landmark the rig reproduces worse weighs less
gaze       conjugate gaze: a prior that the two eyes look the same way (landmarks see lids, not irises)
framefit   one frame's pose/weight fit with frozen settings (:class:`FrameSolver`, :class:`FrameFit`)
pose       weak-perspective head pose: Rodrigues, projection, closed-form and Gauss-Newton fits
observe    which shapes the landmarks can tell apart (:func:`identifiability`)
calibrate  the person's neutral landmarks estimated from the capture (identity "auto"): an offset,
           returned, never applied to the solver it is given; the rest face at the take's start when allowed
onesided   how much a candidate neutral makes a capture's frames demand negative weights (rest-face check)
reststart  whether a take starts at rest, from its first frames' landmarks (still, lips closed)
restdepth  the rest face's depth: each landmark's offset lifted onto the rig's skin (tangent plane)
animation  GLB with morph targets and a glTF weight animation
synthetic  synthetic captures with known weights and pose (tests, benchmark)
preview    preview.mp4 (the source beside the rig or mesh rendered per frame) and weights.png

Captures are read with :func:`facebasis.capture.trackfile.read_capture` (the stated interface
between the two halves of the method).
files      landmark/index/image input files; media: MP4 (PyAV) and GIF output
pipeline   the three command-line jobs as library calls (checked inputs, atomic output folders)
rigrun     the ``retarget`` job (:func:`run_retarget`, re-exported by ``pipeline``)
"""

from .animation import animated_glb_bytes, write_rig_animation
from .drive3d import MeshAnimation, MeshDriver, drive_mesh
from .rbf import RBFMap, edge_length_ratio, fit_rbf
from .rigdrive import RetargetResult, RigRetargeter, identifiability, retarget_landmarks
from .warp2d import CartoonAnimation, CartoonAnimator, animate_cartoon

__all__ = ["RBFMap", "fit_rbf", "edge_length_ratio", "CartoonAnimator", "CartoonAnimation", "animate_cartoon",
           "MeshDriver", "MeshAnimation", "drive_mesh", "RigRetargeter", "RetargetResult", "retarget_landmarks",
           "identifiability", "animated_glb_bytes", "write_rig_animation"]
