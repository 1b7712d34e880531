"""Registration of 3D face scans (any topology) to a template: meshes in the template's topology.

Per scan: a similarity alignment (:mod:`.rigid`; from landmarks when given, else a search over
candidate orientations plus trimmed ICP with scale); with a shape model (:mod:`.shapemodel`) a fit
in it first: a neutral scan within the template's identity space, an expression scan as the
person's registered neutral plus the template's expressions transferred to the person (weights
bounded); then non-rigid ICP with a stiffness schedule (:mod:`.nricp`; Amberg et al. 2007's optimal-step loop with a rotation-aware stiffness term: local similarities from the template, since two faces differ in local size;
local rotations from a person's registered neutral). From a registered neutral the alignment is rigid (no scale: same
person, same scanner). The work happens in the start mesh's frame and units; the result is mapped
back onto the scan. Landmarks may be given (indices or points) or found on the scan (``"auto"``, :mod:`.scanlandmarks`).

:class:`Registration` holds what depends only on the template (edges, Laplacian, incidence,
landmarks) and registers any number of scans; :func:`register_scan` is the one-off form. For a person's expressions, register the neutral scan first, then each expression with
``start=<registered neutral>``: every expression then starts from the person's own neutral, so a vertex index
means the same point of the face across the set. :func:`.registerfiles.register_files` does this for files and
writes ``<stem>.obj`` and ``<stem>.json`` (the report) per scan, atomically.

References
----------
Amberg B., Romdhani S., Vetter T. Optimal step nonrigid ICP algorithms for surface registration.
CVPR 2007.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError, MeshError
from .expressionregions import RegionOptions, expression_fit
from .mesh import connected_components, median_edge_length, validate_mesh
from .nricp import NonRigidICP, NricpOptions, ScanSurface
from .detailprior import DetailPriorOptions, detail_report, identity_fit_with_detail
from .normalstage import NormalStageOptions, normal_displacement
from .pairschedule import check_schedule
from .rigid import RigidOptions, Similarity, refine_point_to_plane, search_similarity, umeyama
from .shapemodel import ModelFit, ModelFitOptions, ShapeBasis, fit_shape_model
from .unseen import extend_unseen

#: A scan whose size (bounding-box diagonal) differs from the template's by more than this factor
#: (either way) is refused as being in other units.
UNIT_RATIO = 4.0

AFTER_MODEL = ("nricp", "normal", "nricp+normal")  #: the stages that may follow a shape-model fit


@dataclass(frozen=True)
class RegistrationOptions:
    """Options of :class:`Registration`.

    Attributes
    ----------
    rigid : the similarity alignment's options
    nricp : the non-rigid ICP's stiffness schedule and correspondence rules from the template (another
        person: local similarities, since faces differ in local size, not only in shape)
    nricp_from_start : the same from a given start mesh (the person's registered neutral: local
        rotations, as skin moving over the same face stretches little)
    unit_ratio : refuse scans whose size differs from the template's by more than this factor
    identity_fit : the identity-space fit of a neutral scan (:mod:`.shapemodel`), when the template
        has an identity basis; ``detail``: its prior on detail outside the space (:mod:`.detailprior`)
    expression_fit : the expression fit of an expression scan, when expressions are given (``scan_pairs``: with
        scan-to-model pairs, eq. S1 of :mod:`.scanpairs`: an opened mouth is not fitted as lips closed over its hole)
    expression_pairs_schedule : when those pairs join the fit (:mod:`.pairschedule`): ``"after"`` (the default: a
        one-sided fit first, then continued with them; the one that explains more of the scan, eq. S2) or ``"joint"``
    nricp_after_model : the non-rigid stage after either fit (from the fitted mesh: local rotations)
    after_model : the stage after either fit: ``"normal"`` (the default: offsets along the fitted
        model's normals only, :mod:`.normalstage`: cannot slide), ``"nricp"`` (free non-rigid ICP,
        ``nricp_after_model``) or ``"nricp+normal"`` (both, in this order)
    normal_stage : the normal stage's options
    expression_regions : then one weight per soft region (:mod:`.expressionregions`; count 0: whole only)
    auto_landmark_weight : landmarks found on the scan (``"auto"``) pull with this times the
        non-rigid stage's landmark weights
    expression_max : upper bound of the expression weights (lower bound 0). Above 1: a person's
        expression may be stronger than the template's (ICT person of ``problems.generation``: jawOpen 1.4 x
        the template's, p95 0.57 cm with weights in [0, 1], 0.21 cm in [0, 1.5])
    """

    rigid: RigidOptions = field(default_factory=RigidOptions)
    nricp: NricpOptions = field(default_factory=lambda: NricpOptions(local_scale=True))
    nricp_from_start: NricpOptions = field(default_factory=NricpOptions)
    unit_ratio: float = UNIT_RATIO
    identity_fit: ModelFitOptions = field(default_factory=ModelFitOptions)
    expression_fit: ModelFitOptions = field(default_factory=lambda: ModelFitOptions(scale=False, prior=1e-4,
                                                                                    prior_start=1e-2, scan_pairs=5000))
    expression_pairs_schedule: str = "after"
    nricp_after_model: NricpOptions = field(default_factory=NricpOptions)
    expression_max: float = 1.5
    auto_landmark_weight: float = 0.1
    after_model: str = "normal"
    normal_stage: NormalStageOptions = field(default_factory=NormalStageOptions)
    expression_regions: RegionOptions = field(default_factory=RegionOptions)
    detail: DetailPriorOptions = field(default_factory=DetailPriorOptions)

    def __post_init__(self):
        check_schedule(self.expression_pairs_schedule)
        if self.after_model not in AFTER_MODEL:
            raise InputError(f"after_model: expected one of {', '.join(AFTER_MODEL)}, found {self.after_model!r}")


@dataclass(frozen=True)
class RegistrationResult:
    """One registered scan.

    Attributes
    ----------
    vertices : (n, 3) the template's topology laid on the scan, in the scan's frame and units
    similarity : template -> scan similarity of the rigid stage (after a model fit: ``model.pose.then(similarity)``)
    distance : (n,) distance of each vertex to the scan surface (scan units)
    no_surface : (n,) bool, vertices that found no usable scan surface (followed the stiffness term)
    iterations : non-rigid ICP iterations over all stiffness levels
    rigid_score : trimmed RMS of the rigid stage (template units): the search's scan-to-template residual before a model fit, else the final point-to-plane RMS
    rigid_check : the check of the rigid search's pose (:class:`~.rigidcheck.RigidResult`), or None
    landmark_error : (k,) distance of each registered landmark vertex to its scan landmark, or None
    seconds : wall time
    model : the identity or expression fit before the non-rigid stage (None without a basis)
    model_kind : ``"identity"``, ``"expressions"`` or None
    model_names : the basis meshes' names (for the report)
    landmarks_found : with landmarks found on the scan (``"auto"``): (found on both the scan and the template, used: within 2 edge lengths of the mesh before the non-rigid stage); None otherwise
    """

    vertices: np.ndarray
    similarity: Similarity
    distance: np.ndarray
    no_surface: np.ndarray
    iterations: int
    rigid_score: float
    landmark_error: np.ndarray | None
    seconds: float
    model: ModelFit | None = None
    model_kind: str | None = None
    model_names: tuple = ()
    landmarks_found: tuple | None = None
    rigid_check: object = None

    def report(self) -> dict:
        """Summary as plain JSON types (distances in scan units)."""
        d = self.distance[~self.no_surface]
        stats = (lambda a: {"median": float(np.median(a)), "p95": float(np.percentile(a, 95)),
                            "max": float(a.max())}) if len(d) else (lambda a: None)
        lm = self.landmark_error
        return {
            "vertices": int(len(self.vertices)),
            "residual": stats(d),
            "residual_note": "distance of the vertices that found scan surface to the scan, scan units",
            "iterations": int(self.iterations),
            "landmark_error": None if lm is None or not len(lm) else {"mean": float(lm.mean()), "max": float(lm.max())},
            **({} if self.landmarks_found is None else {"landmarks_found": int(self.landmarks_found[0]),
                                                          "landmarks_used": int(self.landmarks_found[1])}),
            "no_surface_vertices": int(self.no_surface.sum()),
            "no_surface_fraction": float(self.no_surface.mean()),
            "rigid": {**self.similarity.as_dict(), "trimmed_rms_template_units": float(self.rigid_score), "check": self.rigid_check and self.rigid_check.as_dict()},
            "seconds": float(self.seconds),
            **({} if self.model is None else {self.model_kind: self._model_report()}),
        }

    def _model_report(self) -> dict:
        m = self.model
        c = {str(k): float(v) for k, v in zip(self.model_names, m.coefficients)}
        if self.model_kind == "expressions":
            c = {k: v for k, v in c.items() if v > 1e-4}
        return {"coefficients": c, "rms_point_to_plane_template_units": float(m.rms), "pairs": int(m.pairs),
                "iterations": int(m.iterations), **detail_report(m)}


def _bbox_diagonal(V: np.ndarray) -> float:
    return float(np.linalg.norm(V.max(0) - V.min(0)))


def check_landmarks(template_landmarks, scan_landmarks, n_template: int, n_scan: int | None,
                    template_name: str = "template landmarks", scan_name: str = "scan landmarks"
                    ) -> tuple[np.ndarray, np.ndarray | None]:
    """Validate a landmark pair; returns template indices (k,) and scan landmarks (k,) or (k, 3).

    Raises
    ------
    InputError
        Non-integer or out-of-range template indices, different lengths, fewer than 3 landmarks,
        scan landmarks that are neither indices (checked against ``n_scan``) nor 3D points.
    """
    t = np.asarray(template_landmarks)
    if t.ndim != 1 or not (np.issubdtype(t.dtype, np.integer) or (t.size and np.all(np.mod(t, 1) == 0))):
        raise InputError(f"{template_name}: expected a list of template vertex indices, found shape {t.shape} of {t.dtype}")
    t = t.astype(np.int64)
    s = np.asarray(scan_landmarks, dtype=np.float64) if scan_landmarks is not None else None
    if s is not None and len(s) != len(t):
        raise InputError(f"{scan_name} and {template_name}: expected the same number of landmarks, found "
                         f"{len(s)} and {len(t)}")
    if len(t) < 3:
        raise InputError(f"{template_name}: expected at least 3 landmarks, found {len(t)}")
    bad = np.flatnonzero((t < 0) | (t >= n_template))
    if len(bad):
        raise InputError(f"{template_name}: expected vertex indices in [0, {n_template}), found "
                         f"{int(t[bad[0]])} at position {int(bad[0])} ({len(bad)} out of range)")
    if s is not None:
        if s.ndim == 1:
            if not np.all(np.mod(s, 1) == 0):
                raise InputError(f"{scan_name}: expected scan vertex indices or [x, y, z] points, found non-integers")
            if n_scan is not None:
                bad = np.flatnonzero((s < 0) | (s >= n_scan))
                if len(bad):
                    raise InputError(f"{scan_name}: expected vertex indices in [0, {n_scan}), found "
                                     f"{int(s[bad[0]])} at position {int(bad[0])} ({len(bad)} out of range)")
            s = s.astype(np.int64)
        elif s.ndim != 2 or s.shape[1] != 3 or not np.all(np.isfinite(s)):
            raise InputError(f"{scan_name}: expected k vertex indices or k finite [x, y, z] points, found shape {s.shape}")
    return t, s


class Registration:
    """A template prepared for registering many scans.

    Parameters
    ----------
    V : (n, 3) template neutral, F : (m, 3) its triangles
    options : :class:`RegistrationOptions`
    landmarks : (k,) template vertex indices used when scan landmarks are given
    name : the template's name in messages
    identity : identity basis (:class:`.shapemodel.ShapeBasis`): a scan registered from the template
        is fitted in its space first
    expressions : the template's expressions (:meth:`person_expressions` carries them to a person)
    detector : a 2D face detector (:func:`facebasis.capture.detect.get_detector`): enables
        ``scan_landmarks="auto"`` (:mod:`.scanlandmarks`); the template's own are found here

    Raises
    ------
    InputError
        A basis of another shape; with a detector, no face on the template's front render.
    """

    def __init__(self, V, F, options: RegistrationOptions | None = None, landmarks=None, name: str = "template",
                 identity: ShapeBasis | None = None, expressions: ShapeBasis | None = None, detector=None):
        self.V, self.F = validate_mesh(V, F, name, check_degenerate=False)
        self.name = name
        self.options = options or RegistrationOptions()
        self.landmarks = None
        if landmarks is not None:
            self.landmarks, _ = check_landmarks(landmarks, None, len(self.V), None)
        self.h = median_edge_length(self.V, self.F)
        self.diagonal = _bbox_diagonal(self.V)
        self.nricp = NonRigidICP(self.F, len(self.V))
        # a template of several parts (ICT-FaceKit's full head: skin, eyeballs, teeth, gums, ...): the
        # skin (the largest part) meets the scan; the other parts follow the model fit (or stay rigid)
        labels = connected_components(self.F, len(self.V))
        count = np.bincount(labels)
        self.skin = np.flatnonzero(labels == np.argmax(count)) if len(count) > 1 else None
        if self.skin is not None:  # the skin alone: rigid stage; non-rigid stage after a model fit
            self._skin_where = np.full(len(self.V), -1)
            self._skin_where[self.skin] = np.arange(len(self.skin))
            Fs = self._skin_where[self.F[labels[self.F[:, 0]] == np.argmax(count)]]
            self._skin_icp = NonRigidICP(Fs, len(self.skin))
        for basis, what in ((identity, "identity basis"), (expressions, "expression basis")):
            if basis is not None and basis.deltas.shape[1:] != self.V.shape:
                raise InputError(f"{what} {basis.source}: expected displacements of shape (K, {len(self.V)}, 3) as "
                                 f"{name}, found {basis.deltas.shape}")
        self.identity, self.expressions, self.auto = identity, expressions, None
        if detector is not None:  # landmarks found on scans: the template's own, found once
            from .scanlandmarks import AutoLandmarks

            self.auto = AutoLandmarks(self.V, self.F, detector, name)

    def person_expressions(self, neutral: np.ndarray, transfer: str = "deformation") -> np.ndarray:
        """The template's expressions carried onto a person's registered neutral, in its frame.

        Parameters
        ----------
        neutral : (n, 3) the person's registered neutral (any frame: the template -> neutral
            similarity is fitted on all vertices, Umeyama 1991)
        transfer : ``"deformation"`` (deformation transfer, Sumner & Popovic 2004, in the template's
            frame: the person's own jaw opens) or ``"linear"`` (the template's displacements, rotated
            and scaled)

        Returns
        -------
        (K, n, 3) displacements in ``neutral``'s frame
        """
        if self.expressions is None:
            raise InputError(f"{self.name}: expressions requested but the template has no expression basis")
        g = umeyama(self.V, neutral)
        D = self.expressions.deltas
        if transfer == "deformation":
            from .rig import Rig
            from .transfer import deformation_transfer

            rig = Rig(self.V, self.F, tuple(self.expressions.names), D, source="expression basis")
            D = deformation_transfer(rig, g.inverse().apply(neutral)).deltas
        elif transfer != "linear":
            raise InputError(f"transfer: expected 'deformation' or 'linear', found {transfer!r}")
        return g.scale * (D @ g.rotation.T)

    def check_scan(self, V, F, name: str = "scan", scan_landmarks=None):
        """Validate a scan (and its landmarks) before any work; returns ``(V, F, scan landmarks)``."""
        V = np.asarray(V, dtype=np.float64) if V is not None else V
        F = np.asarray(F) if F is not None else np.zeros((0, 3), np.int64)
        if F.size == 0:
            raise MeshError(f"{name}: expected a triangle mesh, found no faces (a point cloud cannot be registered)")
        V, F = validate_mesh(V, F, name, check_degenerate=False)
        ratio = _bbox_diagonal(V) / self.diagonal
        r = self.options.unit_ratio
        if not 1.0 / r <= ratio <= r:
            raise InputError(
                f"{name}: expected a size like the template's (bounding-box diagonal {self.diagonal:.4g}), found "
                f"{_bbox_diagonal(V):.4g}, {ratio:.3g} times as large; the units differ: scale the scan by about "
                f"{_nice_scale(1.0 / ratio):g}")
        lm = None
        if scan_landmarks is not None:
            if self.landmarks is None:
                raise InputError(f"{name}: scan landmarks given but the template has no landmarks")
            _, lm = check_landmarks(self.landmarks, scan_landmarks, len(self.V), len(V))
            if lm.ndim == 1:
                lm = V[lm]
        return V, F, lm

    def register(self, V, F, scan_landmarks=None, start: np.ndarray | None = None,
                 name: str = "scan", expressions: np.ndarray | None = None) -> RegistrationResult:
        """Register one scan.

        Parameters
        ----------
        V : (N, 3) scan vertices, F : (M, 3) scan triangles (any topology, holes allowed)
        scan_landmarks : (k,) scan vertex indices or (k, 3) points, matching the template landmarks,
            or ``"auto"``: found on the scan (needs a ``detector``), after the rigid stage
        start : (n, 3) start mesh in the template's topology (e.g. the person's registered neutral,
            in any frame); default the template neutral (then fitted in the identity basis first,
            if the template has one)
        name : the scan's name in messages
        expressions : (K, n, 3) expression displacements in ``start``'s frame (:meth:`person_expressions`): the
            scan is first fitted as ``start`` plus a combination of them (weights in ``[0, expression_max]``)

        Returns
        -------
        RegistrationResult
        """
        auto = isinstance(scan_landmarks, str) and scan_landmarks == "auto"
        if auto and self.auto is None:
            raise InputError(f"{name}: landmarks 'auto' need a detector (Registration(..., detector=...))")
        V, F, lm_pts = self.check_scan(V, F, name, None if auto else scan_landmarks)
        P = self.V
        if start is not None:
            P = validate_mesh(start, self.F, f"{name}: start mesh", check_degenerate=False)[0]
            if len(P) != len(self.V):
                raise InputError(f"{name}: start mesh: expected {len(self.V)} vertices, found {len(P)}")
        if expressions is not None and (start is None or np.shape(expressions)[1:] != P.shape):
            raise InputError(f"{name}: expressions: expected (K, {len(P)}, 3) displacements of a start mesh, found "
                             f"{np.shape(expressions)}{'' if start is not None else ' without a start mesh'}")
        t0 = time.perf_counter()
        # rigid stage: in the scan's frame
        # from the person's registered neutral (same scanner, same units): a rigid motion, no scale
        rigid = self.options.rigid if start is None else dataclasses.replace(self.options.rigid, scale=False)
        guess = umeyama(P[self.landmarks], lm_pts, scale=rigid.scale) if lm_pts is not None else None
        # several parts: the skin aligns (the scan has no eyeballs, teeth: FaceXModel whole landed 6.5 cm off)
        Ps, Fs = (P, self.F) if self.skin is None else (P[self.skin], self._skin_icp.F)
        check = search_similarity(Ps, Fs, V, F, rigid, start=guess)
        sim, score = check.similarity, check.score
        surface = ScanSurface(V, F)
        with_model = (start is None and self.identity is not None) or expressions is not None
        if not with_model:  # (a model fit refines the pose itself, with the shape)
            sub = Ps[np.random.default_rng(rigid.seed).choice(len(Ps), min(len(Ps), 4000), replace=False)]
            sim, score = refine_point_to_plane(sub, surface.closest, sim, rigid.plane_iterations,
                                               rigid.keep_template, scale=rigid.scale)
        # non-rigid stage: in the rest mesh's frame and units (stiffness and thresholds are unit-free there)
        inv = sim.inverse()
        surface_t = surface.moved(inv.apply(V))
        lm_t = inv.apply(lm_pts) if lm_pts is not None else None
        lm_idx = self.landmarks if lm_pts is not None else None
        opts = self.options.nricp if start is None else self.options.nricp_from_start
        h = median_edge_length(P, self.F)
        model, kind, names = self._fit_model(P, surface_t, h, start is None, expressions)
        if model is not None:
            P, opts = model.vertices, self.options.nricp_after_model
            h = median_edge_length(P, self.F)
        if auto:  # detections on an untextured render are ~1 cm apart from one face to another: weak pull
            lm_idx, lm_t, found = self._auto_landmarks(P, surface_t, F, h, start is not None)
            lm_pts = sim.apply(lm_t) if lm_t is not None else None
            opts = dataclasses.replace(opts, landmark_weight=tuple(self.options.auto_landmark_weight * w
                                                                   for w in opts.landmark_weight))
        res = self._refine(P, surface_t, opts, lm_idx, lm_t, h, model is not None)
        res = extend_unseen(self, model, res, surface_t, kind == "identity")  # the sockets, holes: eq. U1
        Xt = res.vertices
        if self.skin is not None:  # the other parts have no scan surface: keep them where the fit put them
            Xt = P.copy()
            Xt[self.skin] = res.vertices[self.skin]
        X = sim.apply(Xt)
        lm_err = np.linalg.norm(X[lm_idx] - lm_pts, axis=1) if lm_pts is not None else None
        return RegistrationResult(X, sim, res.distance * sim.scale, res.no_surface, res.iterations, score,
                                  lm_err, time.perf_counter() - t0, model, kind, names,
                                  (found, len(lm_idx) if lm_idx is not None else 0) if auto else None, check)

    def _refine(self, P, surface_t, opts, lm_idx, lm_t, h, after_model: bool):
        """The last stage: non-rigid ICP, or after a model fit the stage ``options.after_model``."""
        how = self.options.after_model if after_model else "nricp"
        res = None if how == "normal" else (self._skin_fit(P, surface_t, opts, lm_idx, lm_t, h) if after_model and
                                            self.skin is not None else self.nricp.fit(P, surface_t, opts, lm_idx, lm_t, h=h))
        if how == "nricp":
            return res
        R = P if res is None else res.vertices
        out = normal_displacement(R, self.nricp.vertex_normals(R), self.nricp.L, surface_t, h,
                                  self.options.normal_stage, use=self.skin)
        return dataclasses.replace(out, iterations=out.iterations + (0 if res is None else res.iterations))

    def _skin_fit(self, P, surface_t, opts, lm_idx, lm_t, h):
        """The non-rigid stage on the skin alone after a model fit (the other parts keep the fit's places:
        FaceXModel 14062 of 26719 vertices); the others ``no_surface``, at their nearest scan vertex's distance."""
        where, on = self._skin_where, None if lm_idx is None else self._skin_where[lm_idx] >= 0
        lm = (where[lm_idx[on]], lm_t[on]) if on is not None and on.any() else (None, None)
        r = self._skin_icp.fit(P[self.skin], surface_t, opts, *lm, h=h)
        X, dist, no = P.copy(), surface_t.tree.query(P)[0], np.ones(len(P), bool)
        X[self.skin], dist[self.skin], no[self.skin] = r.vertices, r.distance, r.no_surface
        return dataclasses.replace(r, vertices=X, distance=dist, no_surface=no)

    def _auto_landmarks(self, P, surface_t, F, h, from_start: bool):
        """Landmarks found on the scan (:mod:`.scanlandmarks`), seen from the template's front, as
        ``(template indices, points in P's frame)`` or ``(None, None)``. Pairs farther than 2 ``h``
        from the current mesh ``P`` (after the rigid stage and any model fit) are dropped: a detection
        lifted into a hole or a socket, or a detector that places a point differently on two faces
        (on untextured renders of two ICT persons in their true pose: 1.2 cm apart on average)."""
        g = umeyama(self.V, P) if from_start else Similarity()  # P's frame -> the template's: g^-1
        idx, pts = self.auto.on_scan(g.inverse().apply(surface_t.V), F)
        pts = g.apply(pts)
        ok = np.linalg.norm(P[idx] - pts, axis=1) <= 2.0 * h
        return (idx[ok], pts[ok], len(idx)) if ok.sum() >= 3 else (None, None, len(idx))

    def _fit_model(self, P, surface_t, h, from_template: bool, expressions):
        """The identity fit (from the template, with a basis) or the expression fit (with ``expressions``;
        :mod:`.shapemodel`, :mod:`.expressionregions`) as ``(fit, kind, names)``; ``(None, None, ())`` otherwise."""
        normals = self.nricp.vertex_normals
        if from_template and self.identity is not None:
            fit = fit_shape_model(P, self.identity.deltas, surface_t, normals, h, self.options.identity_fit,
                                  use=self.skin)
            return identity_fit_with_detail(self, fit, P, surface_t, h), "identity", tuple(self.identity.names)
        if expressions is not None:
            return expression_fit(P, np.asarray(expressions, float), surface_t, normals, h, self.options, self.skin,
                                  self.expressions)
        return None, None, ()


def _nice_scale(x: float) -> float:
    """``x`` rounded to a power of ten when close to one (units), else to 3 significant digits."""
    p = 10.0 ** np.round(np.log10(x))
    return float(p) if abs(np.log10(x / p)) < 0.15 else float(f"{x:.3g}")


def register_scan(template_V, template_F, scan_V, scan_F, options: RegistrationOptions | None = None,
                  template_landmarks=None, scan_landmarks=None, start=None) -> RegistrationResult:
    """Register one scan onto a template (the one-off form of :class:`Registration`)."""
    return Registration(template_V, template_F, options, template_landmarks).register(
        scan_V, scan_F, scan_landmarks, start)

