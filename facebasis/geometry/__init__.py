"""Geometry core shared by every method: meshes, files, triangle frames, factor-once solves.

Imports nothing of the methods (:mod:`facebasis.contact`, :mod:`facebasis.rigging`, capture,
retarget); an extra edge term such as virtual edges reaches deformation transfer through a small
object interface (see :class:`~facebasis.geometry.transfer.DeformationTransfer`).

Modules
-------
mesh        validation of vertex and face arrays, unique edges, median edge length
meshio      OBJ/PLY reading and writing (atomic), "read a mesh in a reference's topology"
gradients   triangle frames and deformation gradients, the frame-to-edge operator
laplacian   the cotangent Laplace-Beltrami operator and lumped mass (planar or spatial meshes)
obj         the vectorised OBJ reader and writer
objlayout   an OBJ's own layout (vt/vn, materials, groups, polygons) kept in the meshes written in its topology
objscan     byte-level scanning of OBJ lines (keywords, numbers, face references) for objlayout
numtext     decimal text to and from arrays, exact and loop-free (the OBJ reader's and writer's kernels)
poisson     factor-once reconstruction of vertices from triangle edges (Cholesky, cholespy)
boxqp       exact convex box-constrained QPs (DAQP + active-set refinement): certification's nodes, model fits
cholesky    the one sparse Cholesky wrapper (CHOLMOD through cholespy), factored once, solved many times
transfer    deformation transfer (Sumner & Popovic 2004), factored once for all shapes
rig         the :class:`Rig` type, rig folders
gltf        a rig as glTF 2.0 (.glb/.gltf, metres, normals, UVs, materials) with one morph target per shape
rigid       similarity alignment of a template to a scan (landmarks, or orientation search + trimmed ICP)
rigidcheck  the check of a found pose: share of the scan near the template, distinct poses that fit as well
nricp       non-rigid ICP with a stiffness schedule (Amberg et al. 2007), closest points on a scan
registration  scans of any topology to meshes in the template's topology (rigid + model fit + non-rigid ICP)
registerfiles  registering scan files: inputs checked before any work, outputs written atomically
shapemodel  identity and expression bases: fitting a scan in a linear shape space (pose + bounded coefficients)
scanpairs   scan-to-model pairs of the model fits (a model part over a scan's hole, e.g. lips closed over a mouth)
pairschedule  when the expression fit's scan pairs join it (after a one-sided fit) and which fit is kept (eq. S2)
expressionregions  one expression weight per soft region (a person's expression whose strength varies over the face)
normalstage  offsets along a fitted model's normals only (after a shape-model fit: a detail stage that cannot slide)
detailprior  the identity fit with a smooth normal field outside the space (a Gaussian-process prior, manifold harmonics)
detailevidence  the field's deviation and the scan's noise level per scan by the evidence of the linearised joint fit
fieldnormals  the detail field along the person's fitted modes' normals, not the template's (eq. D4: no slide along the skin)
fieldamplitude  the detail field's deviation over the skin, larger where the modes alone leave residuals (eq. D5)
unseen      the registered neutral where no scan sees (sockets, holes): the seen detail extended in 3D (GP mean)
scanlandmarks  landmarks found on a scan: front render, a 2D detector object, ray lift onto the surface
raster      flat-shaded numpy rasterisation of a mesh into an image (preview videos; no OpenGL)

References
----------
Sumner R. W., Popovic J. Deformation transfer for triangle meshes. ACM SIGGRAPH 2004.
"""
