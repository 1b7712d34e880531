"""Similarity (rotation, translation, uniform scale) alignment of a template to a scan.

Two ways in: from corresponding landmarks (closed form, Umeyama 1991), or, without landmarks, a
search over candidate orientations. The search is needed because a face scan and the template may
start in very different poses, and plain ICP (or trimesh's ``mesh_other``) from a single start falls
into a wrong minimum on such data.

Candidate starts: both shapes are centred on their area-weighted centroids, scaled by their
area-weighted RMS radius and turned into their principal axes; the 24 proper rotations that map
the template's principal axes onto the scan's (any order, any signs with determinant +1) are each
refined by a few steps of trimmed symmetric ICP with scale on area-sampled points. The best few
distinct ones by that residual, and restarts turned a little around the best of them, are refined by
one-sided (scan to template) trimmed point-to-plane ICP, and the pose with the lowest one-sided
residual is kept and checked (:mod:`.rigidcheck`).

References
----------
Umeyama S. Least-squares estimation of transformation parameters between two point patterns.
IEEE PAMI 13(4), 1991 (eq. 40-42: rotation, translation and scale from the cross-covariance SVD).
Chetverikov D. et al. The trimmed iterative closest point algorithm. ICPR 2002.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import permutations, product

import numpy as np
from scipy.spatial import cKDTree

from ..errors import parameter_error
from .rigidcheck import RigidResult, pose_check, rotation_angle, trimmed

#: the restarts' axes and turning directions (:func:`_perturbations`)
_AXIS_SIGNS = tuple((e, sign) for e in np.eye(3) for sign in (1.0, -1.0))


@dataclass(frozen=True)
class Similarity:
    """``x -> scale * rotation @ x + translation``.

    Attributes
    ----------
    scale : float
    rotation : (3, 3) proper rotation
    translation : (3,)
    """

    scale: float = 1.0
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def apply(self, X: np.ndarray) -> np.ndarray:
        """Map points (..., 3)."""
        return self.scale * (np.asarray(X) @ self.rotation.T) + self.translation

    def inverse(self) -> "Similarity":
        Rt = self.rotation.T
        return Similarity(1.0 / self.scale, Rt, -(Rt @ self.translation) / self.scale)

    def then(self, other: "Similarity") -> "Similarity":
        """``other`` after ``self``."""
        return Similarity(other.scale * self.scale, other.rotation @ self.rotation,
                          other.scale * other.rotation @ self.translation + other.translation)

    def as_dict(self) -> dict:
        return {"scale": float(self.scale), "rotation": self.rotation.tolist(),
                "translation": self.translation.tolist()}


@dataclass(frozen=True)
class RigidOptions:
    """Options of :func:`align_similarity`.

    Attributes
    ----------
    samples : points sampled (by area) on each surface for the candidate search
    candidate_iterations : ICP steps per candidate orientation
    refine_candidates : how many of the best candidates are refined further
    refine_iterations : steps of the one-sided scan-to-template ICP that refines each kept start (``4
        samples`` scan points matched to ``16 samples`` template points)
    keep_template : fraction of template-to-scan pairs kept (the template covers parts a scan lacks)
    keep_scan : fraction of scan-to-template pairs kept (noise, stray parts of the scan)
    seed : seed of the point sampling
    scale : estimate the scale (else a rigid motion: e.g. the same person's scans from one scanner)
    plane_iterations : at most this many steps of the final point-to-plane refinement
        (:func:`refine_point_to_plane`; it stops when a step is negligible: from a pose 2-3 cm off,
        as the point-to-point stage can leave it, it needs about 40)
    perturbations : restarts around the best refined pose (rotations by +-``perturb_degrees`` about
        each axis: 0 to 6), kept if their scan-to-template residual is lower
    perturb_degrees : the restarts' rotation, in (0, 90]
    distinct_degrees : poses whose rotations differ by more than this, in (0, 90], are distinct: it
        selects the search candidates that are refined (pairwise distinct) and the check's runner-up
    ambiguous_ratio : a distinct pose with a residual below this multiple of the best's makes the
        pose ambiguous (:mod:`.rigidcheck`)
    near : a scan point lies near the template within this fraction of the template's RMS radius
    min_near_share : a pose with a smaller share of scan points near the template is doubtful
    """

    samples: int = 1500
    candidate_iterations: int = 5
    refine_candidates: int = 3
    refine_iterations: int = 8
    keep_template: float = 0.6
    keep_scan: float = 0.9
    seed: int = 0
    scale: bool = True
    plane_iterations: int = 50
    perturbations: int = 6
    perturb_degrees: float = 10.0
    distinct_degrees: float = 10.0
    ambiguous_ratio: float = 1.1
    near: float = 0.05
    min_near_share: float = 0.5

    def __post_init__(self):
        least = {"samples": 10, "candidate_iterations": 0, "refine_candidates": 1, "refine_iterations": 0,
                 "plane_iterations": 0, "seed": 0, "perturbations": 0}
        for k, lo in least.items():
            v = getattr(self, k)
            if isinstance(v, bool) or not (isinstance(v, (int, np.integer)) and v >= lo):
                raise parameter_error(f"rigid_{k}", f"an integer >= {lo}", repr(v), label=f"rigid.{k}")
        for k in ("keep_template", "keep_scan", "near", "min_near_share"):
            v = getattr(self, k)
            if isinstance(v, bool) or not (isinstance(v, (int, float, np.floating)) and 0 < v <= 1):
                raise parameter_error(f"rigid_{k}", "a fraction in (0, 1]", repr(v), label=f"rigid.{k}")
        if not self.perturbations <= len(_AXIS_SIGNS):
            raise parameter_error("rigid_perturbations", f"an integer in [0, {len(_AXIS_SIGNS)}]",
                                  repr(self.perturbations), label="rigid.perturbations")
        for k, lo, hi, closed in (("perturb_degrees", 0.0, 90.0, False), ("distinct_degrees", 0.0, 90.0, False),
                                  ("ambiguous_ratio", 1.0, np.inf, True)):
            v = getattr(self, k)
            ok = isinstance(v, (int, float, np.floating)) and not isinstance(v, bool) and v <= hi
            if not (ok and (v >= lo if closed else v > lo)):
                raise parameter_error(f"rigid_{k}", f"a number in {'[' if closed else '('}{lo:g}, {hi:g}]", repr(v),
                                      label=f"rigid.{k}")
        if not isinstance(self.scale, (bool, np.bool_)):
            raise parameter_error("rigid_scale", "True or False", repr(self.scale), label="rigid.scale")


def umeyama(A: np.ndarray, B: np.ndarray, scale: bool = True) -> Similarity:
    """Least-squares similarity with ``B ~ s R A + t`` (Umeyama 1991, eq. 40-42).

    Parameters
    ----------
    A, B : (k, 3) corresponding points, k >= 3 not collinear
    scale : estimate the scale (else 1)
    """
    ma, mb = A.mean(0), B.mean(0)
    a, b = A - ma, B - mb
    U, S, Vt = np.linalg.svd(b.T @ a / len(A))
    d = np.ones(3)
    d[2] = np.sign(np.linalg.det(U @ Vt)) or 1.0
    R = (U * d) @ Vt
    var_a = (a ** 2).sum() / len(A)
    s = float((S * d).sum() / var_a) if scale and var_a > 0 else 1.0
    return Similarity(s, R, mb - s * R @ ma)


def area_samples(V: np.ndarray, F: np.ndarray, k: int, rng: np.random.Generator, normals: bool = False):
    """``k`` points (k, 3) drawn uniformly by area on the triangles ``F`` of ``V`` (and, with
    ``normals``, their triangles' unit normals (k, 3))."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    t = rng.choice(len(F), size=k, p=area / area.sum())
    r1, r2 = rng.random(k), rng.random(k)
    s = np.sqrt(r1)
    P = (1 - s)[:, None] * a[t] + (s * (1 - r2))[:, None] * b[t] + (s * r2)[:, None] * c[t]
    if not normals:
        return P
    N = np.cross(b[t] - a[t], c[t] - a[t])
    return P, N / np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-300)


def principal_frame(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Area-weighted centroid (3,), principal axes (3, 3) as columns of a proper rotation (largest
    variance first, determinant +1), RMS radius of a surface."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    w = area / area.sum()
    centroid = w @ ((a + b + c) / 3.0)
    # second moment of each triangle about the centroid: (sum of corner outer products + 9 g g^T) / 12
    corners = np.stack([a, b, c], 1) - centroid
    g = corners.sum(1)
    cov = (np.einsum("t,tki,tkj->ij", w, corners, corners) + np.einsum("t,ti,tj->ij", w, g, g)) / 12.0
    evals, evecs = np.linalg.eigh(cov)
    axes = evecs[:, ::-1].copy()
    # a right-handed frame: eigh's signs are arbitrary, and with one frame left-handed every one of the 24
    # proper candidate rotations As G At^T would be a reflection (issue #27: seed-2 scans landed 33 deg off)
    if np.linalg.det(axes) < 0:
        axes[:, 2] *= -1.0
    return centroid, axes, float(np.sqrt(max(evals.sum(), 1e-300)))


def _cube_rotations() -> list[np.ndarray]:
    """The 24 proper rotations that permute and flip the coordinate axes."""
    out = []
    for perm in permutations(range(3)):
        for signs in product((1.0, -1.0), repeat=3):
            G = np.zeros((3, 3))
            G[np.arange(3), perm] = signs
            if np.linalg.det(G) > 0:
                out.append(G)
    return out


def trimmed_icp(T_pts: np.ndarray, T_tree: cKDTree, S_pts: np.ndarray, S_tree: cKDTree, sim: Similarity,
                iterations: int, options: RigidOptions) -> tuple[Similarity, float]:
    """Symmetric trimmed ICP with scale from a start ``sim`` (template -> scan).

    Parameters
    ----------
    T_pts : (p, 3) template points, mapped to the scan by ``sim`` (``T_tree`` is their tree, template frame)
    S_pts : (q, 3) scan points (``S_tree`` is their tree); every k-th (about p of them) is matched to the
        template, in the template's frame, so neither tree is rebuilt
    iterations : ICP steps

    Returns
    -------
    sim : the refined similarity
    score : trimmed symmetric RMS distance divided by the scale (template units), lower is better
    """
    scan_q = S_pts[:: max(1, len(S_pts) // max(len(T_pts), 1))]
    score = np.inf
    for it in range(iterations + 1):
        d1, j1 = S_tree.query(sim.apply(T_pts))
        d2, j2 = T_tree.query(sim.inverse().apply(scan_q))
        d2 = d2 * sim.scale  # scan units, as d1
        k1, k2 = trimmed(d1, options.keep_template), trimmed(d2, options.keep_scan)
        score = float(np.sqrt((np.sum(d1[k1] ** 2) + np.sum(d2[k2] ** 2)) / (len(k1) + len(k2)))) / sim.scale
        if it == iterations:
            break
        A = np.concatenate([T_pts[k1], T_pts[j2[k2]]])
        B = np.concatenate([S_pts[j1[k1]], scan_q[k2]])
        sim = umeyama(A, B, scale=options.scale)
    return sim, score


def scan_to_template_icp(T_tree: cKDTree, T_pts: np.ndarray, T_normals: np.ndarray, S_pts: np.ndarray,
                         sim: Similarity, iterations: int, keep: float, scale: bool = True
                         ) -> tuple[Similarity, float, np.ndarray]:
    """One-sided trimmed point-to-plane ICP with scale: each scan point to its closest template point.

    Every point of a scan has a counterpart on a whole-head template, not every template point one on
    the scan (a face-only scan); this residual does not pull the template onto parts the scan lacks.
    The scan is mapped into the template's frame for the queries, so the template's tree is built
    once. Each step solves the linearised point-to-plane problem of :func:`refine_point_to_plane` with
    the template's normals (point-to-point ICP needs several times as many steps to slide into place).

    Parameters
    ----------
    T_tree : tree of the template points ``T_pts`` (p, 3), ``T_normals`` (p, 3) their unit normals
    S_pts : (q, 3) scan points
    sim : start similarity (template -> scan)
    keep : fraction of the scan's pairs kept (the closest ones)

    Returns
    -------
    sim : refined similarity
    residual : trimmed RMS scan-to-template point distance in scan units (after the last step)
    distances : (q,) each scan point's distance to the template at ``sim``, template units
    """
    res = np.inf
    for it in range(iterations + 1):
        d, j = T_tree.query(sim.inverse().apply(S_pts))
        k = trimmed(d, keep)
        res = float(sim.scale * np.sqrt(np.mean(d[k] ** 2)))
        if it == iterations or len(k) < 7:
            break
        X, n = sim.apply(T_pts[j[k]]), T_normals[j[k]] @ sim.rotation.T
        sim = sim.then(_plane_step(X, S_pts[k], n, scale)[0])
    return sim, res, d


def _plane_step(X: np.ndarray, Q: np.ndarray, n: np.ndarray, scale: bool) -> tuple[Similarity, np.ndarray]:
    """The similarity step that moves points ``X`` (k, 3) onto the planes through ``Q`` with normals
    ``n``: ``x -> c + (1 + d)(I + [w]x)(x - c) + t`` linearised about the centroid ``c`` of ``X``,
    the 7 x 7 (6 x 6 without scale) normal equations of ``sum ((x' - q) . n)^2``; also the step's
    unknowns ``x`` (w, t[, d])."""
    r0 = ((X - Q) * n).sum(1)
    c = X.mean(0)
    y = X - c
    J = np.concatenate([np.cross(y, n), n, (y * n).sum(1, keepdims=True)], 1)  # (k, 7): w, t, d
    if not scale:
        J = J[:, :6]
    H = J.T @ J
    x = np.linalg.solve(H + 1e-12 * np.trace(H) * np.eye(len(H)), -J.T @ r0)
    R = _rotation_from_vector(x[:3])
    s = 1.0 + x[6] if scale else 1.0
    return Similarity(s, R, c - s * R @ c + x[3:6]), x


def _perturbations(degrees: float) -> list[np.ndarray]:
    """Rotations by +-``degrees`` about each coordinate axis (6)."""
    return [_rotation_from_vector(sign * np.radians(degrees) * e) for e, sign in _AXIS_SIGNS]


def align_similarity(T_V: np.ndarray, T_F: np.ndarray, S_V: np.ndarray, S_F: np.ndarray,
                     options: RigidOptions = RigidOptions(), start: Similarity | None = None
                     ) -> tuple[Similarity, float]:
    """Similarity that lays the template ``(T_V, T_F)`` onto the scan ``(S_V, S_F)``.

    Parameters
    ----------
    T_V : (n, 3), T_F : (m, 3) the template
    S_V : (N, 3), S_F : (M, 3) the scan (any topology, holes allowed)
    start : a known start (e.g. from landmarks); then the candidate search is skipped: the start and
        the restarts around it are refined

    Returns
    -------
    sim : template -> scan similarity
    score : trimmed RMS scan-to-template residual in template units
    """
    res = search_similarity(T_V, T_F, S_V, S_F, options, start)
    return res.similarity, res.score


def search_similarity(T_V: np.ndarray, T_F: np.ndarray, S_V: np.ndarray, S_F: np.ndarray,
                      options: RigidOptions = RigidOptions(), start: Similarity | None = None
                      ) -> RigidResult:
    """:func:`align_similarity` with the check of the found pose (:class:`RigidResult`).

    Stages: the 24 principal-frame candidates, each a few steps of symmetric trimmed ICP on sparse
    samples (:func:`trimmed_icp`); the ``refine_candidates`` best of them, pairwise distinct, and
    ``perturbations`` restarts around the best so far, each refined by the one-sided scan-to-template
    ICP (:func:`scan_to_template_icp`) on dense samples; the pose with the lowest scan-to-template
    residual is kept. The refined candidates also give the check (:func:`.rigidcheck.pose_check`): one
    ending at a distinct pose (rotation differing by more than ``options.distinct_degrees``) with a
    residual within ``options.ambiguous_ratio`` of the best makes the pose ambiguous.
    """
    rng = np.random.default_rng(options.seed)
    scan_samples = area_samples(S_V, S_F, 4 * options.samples, rng)
    T_dense, T_N = area_samples(T_V, T_F, 16 * options.samples, rng, normals=True)
    T_tree = cKDTree(T_dense)
    ct, At, rt = principal_frame(T_V, T_F)
    if start is not None:
        starts = [start]
    else:
        cs, As, rs = principal_frame(S_V, S_F)
        T_s = area_samples(T_V, T_F, options.samples, rng)
        S_s = scan_samples[: options.samples]
        S_s_tree, T_s_tree = cKDTree(S_s), cKDTree(T_s)
        results = []
        for G in _cube_rotations():  # 24 candidate orientations (loop over candidates, not points)
            R = As @ G @ At.T
            s = rs / rt if options.scale else 1.0
            sim0 = Similarity(s, R, cs - s * R @ ct)
            sim, score = trimmed_icp(T_s, T_s_tree, S_s, S_s_tree, sim0, options.candidate_iterations, options)
            results.append((score, sim))
        results.sort(key=lambda r: r[0])
        starts = []
        for _, sim in results:  # the best few, pairwise distinct
            if all(rotation_angle(sim.rotation @ o.rotation.T) > options.distinct_degrees for o in starts):
                starts.append(sim)
            if len(starts) == options.refine_candidates:
                break
    refined = [scan_to_template_icp(T_tree, T_dense, T_N, scan_samples, s0, options.refine_iterations,
                                    options.keep_scan, options.scale) for s0 in starts]
    best = min(refined, key=lambda r: r[1])[0]
    for P in _perturbations(options.perturb_degrees)[: options.perturbations]:
        c = best.apply(T_dense).mean(0)  # turn about the template's centre as placed on the scan
        s0 = best.then(Similarity(1.0, P, c - P @ c))
        refined.append(scan_to_template_icp(T_tree, T_dense, T_N, scan_samples, s0, options.refine_iterations,
                                            options.keep_scan, options.scale))
    return pose_check(refined, 0 if start is not None else len(starts), rt, options)


def _rotation_from_vector(w: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation (3, 3) by angle |w| about w."""
    a = float(np.linalg.norm(w))
    if a < 1e-15:
        return np.eye(3)
    k = w / a
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


def refine_point_to_plane(T_pts: np.ndarray, closest, sim: Similarity, iterations: int = 15,
                          keep: float = 0.6, tolerance: float = 1e-7, scale: bool = True
                          ) -> tuple[Similarity, float]:
    """Trimmed point-to-plane ICP with scale, against the scan's exact closest surface points.

    Each step linearises ``x -> c + (1 + d)(I + [w]x)(x - c) + t`` about the template points'
    centroid ``c`` and solves the 7 x 7 normal equations of ``sum ((x' - q) . n)^2`` over the kept
    pairs; this converges in a few steps and exactly to a pose in which the template lies on the scan.

    Parameters
    ----------
    T_pts : (p, 3) template points
    closest : callable ``P (p, 3) -> (Q (p, 3), normals (p, 3), dist (p,), rim (p,) bool)``
    sim : start similarity (template -> scan)
    scale : also refine the scale (else only the rotation and translation: 6 x 6 equations)

    Returns
    -------
    sim : refined similarity
    rms : trimmed RMS of the point-to-plane residuals divided by the scale (template units)
    """
    rms = np.inf
    for _ in range(iterations):
        X = sim.apply(T_pts)
        Q, N, dist, rim = closest(X)
        idx = trimmed(np.where(rim, np.inf, dist), keep)
        idx = idx[~rim[idx]]
        if len(idx) < 7:
            break
        rms = float(np.sqrt(np.mean(((X[idx] - Q[idx]) * N[idx]).sum(1) ** 2))) / sim.scale
        step, x = _plane_step(X[idx], Q[idx], N[idx], scale)
        sim = sim.then(step)
        if np.abs(x).max() < tolerance:
            break
    return sim, rms
