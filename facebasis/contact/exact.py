"""Exact contact for deformation transfer and for generated shapes: no new intersecting triangle pair.

For every shape, the delta closest to the plain one (in the energy below) such that no
vertex-disjoint triangle pair intersects unless it intersects in the target neutral ``B0`` or in the
template shape ``S_i`` (layer crossings and local folds alike); vertices farther than ``reach`` from
a contact keep the plain delta exactly. Each shape is solved by :class:`~facebasis.contact.solver.ContactSolver`
(separating planes from ``B0``, the separation QP of :mod:`facebasis.contact.qp`, repeated until the
package's exact counter finds no new pair); shapes run in forked worker processes.

Energy
------
* :func:`contact_transfer` (``facebasis transfer --contact``): the deformation-transfer energy itself,
  ``x^T L x`` with the transfer's factored normal matrix (``stiffness=0``).
* :func:`contact_correct` (``facebasis rig --contact``): shapes generated from examples, whose fit is
  measured by vertex positions (eq. 5 of Gao et al. 2015, the held-out reproduction error): by default
  ``x^T (L + beta I) x`` with ``beta = RIG_STIFFNESS``, the smallest displacement, smoothed by the
  transfer energy over about ``1 / sqrt(beta)`` median edges. On the ICT person case (seed 0) the
  held-out error grows by 8.9% with ``beta = 0``, 5.0% with 10, 4.75% with 100 (measured as
  ``python -m problems.bench_contact --rig --stiffness BETA`` does); most of it is jawOpen, whose
  true shape pushes the mouth corners through each other as well (the true rig corrected the same way:
  held-out error 0 -> 0.038). Seed 1, whose target neutral intersects itself in 389 pairs (allowed),
  ends clean too (``RIG_ROUNDS`` rounds; jawOpen needs 99) but its held-out error grows by 47.7%
  (0.0822 -> 0.1214): its true rig has 7,065 new pairs, and corrected the same way costs 0 -> 0.080,
  so intersection-free shapes cost it about ``hypot(0.0822, 0.080) = 0.115`` (+40%) by that
  measure; mouthRollUpper, mouthShrugLower, mouthRollLower and mouthFunnel carry most of it, for
  the true rig as for the generated one. Those four re-corrected with ``beta`` 10 / 100 / 1000 give
  0.1220 / 0.1213 / 0.1215 (``beta`` 0: 0.1428): the energy is not what is left.

Limits
------
Next to pairs where the target neutral intersects itself (``allow_target_pairs``) a correction
slides the crossing onto neighbouring triangles and the rounds find those pairs a few at a time; a
shape still left with pairs after the stiff pass and the transfer-energy fallback is pulled back
towards the neutral around them (:meth:`ContactSolver._retreat`, ``retreated`` in its report), so
the exact check always ends clean; the report says which pass ended each shape.

References
----------
- Sumner R. W., Popovic J. Deformation transfer for triangle meshes. SIGGRAPH 2004.
- Gao Yali, Tan Guanghua, Guo Songrui, Fan Xiaowei. Example-based facial blendshape generation.
    Computer Engineering 41(3): 258-261, 2015.
"""

from __future__ import annotations

import time

import numpy as np

from ..errors import InputError
from ..geometry.mesh import validate_vertices
from ..geometry.rig import Rig
from ..geometry.transfer import DeformationTransfer
from ..workers import available_cores
from .proximity import new_pairs
from .solver import (  # noqa: F401  (re-exported: the contact API in one place)
    MARGIN_EDGES, POLISH_RATIO, REACH_EDGES, STILL_EDGES, ContactResult, ContactShape, ContactSolver,
)

#: largest mesh (vertices) accepted by default: ICT's 14k vertices take ~46 s CPU for 52 shapes (mouthClose excluded)
MAX_VERTICES = 60_000
#: ``beta`` of :func:`contact_correct` (generated shapes): the position term of ``x^T (L + beta I) x``
RIG_STIFFNESS = 100.0
#: solve-and-check rounds of :func:`contact_correct`'s stiff pass: more than the transfer's 40, so that
#: shapes next to the target neutral's own crossings end with the stiff energy rather than the fallback
RIG_ROUNDS = 120


def check_size(n_vertices: int, max_vertices: int | None = None, what: str = "contact") -> None:
    """InputError when a mesh is too large for the contact time budget (default ``MAX_VERTICES``)."""
    max_vertices = MAX_VERTICES if max_vertices is None else int(max_vertices)
    if n_vertices > max_vertices:
        raise InputError(f"{what}: expected a mesh of at most {max_vertices} vertices for the time budget (ICT's "
                         f"14062 vertices are within it; reports/contact/contact.md has their time), found {n_vertices}; "
                         + ("run without --contact" if what.startswith("--") else
                            "pass max_vertices= to allow more, or go without contact"))


def check_target_neutral(target, template: Rig, allow: bool = False, what: str = "target neutral") -> np.ndarray:
    """The pairs (q, 2) of triangles intersecting in ``target`` but not in the template neutral; an
    InputError naming them unless ``allow`` (then they stay allowed in every shape)."""
    bad = new_pairs(np.asarray(target, np.float64), template.faces, (template.neutral,))
    if len(bad) and not allow:
        ex = ", ".join(f"({i}, {j})" for i, j in bad[:5].tolist())
        raise InputError(f"{what}: expected no intersecting triangle pairs beyond the template neutral's, "
                         f"found {len(bad)} (triangles {ex}{', ...' if len(bad) > 5 else ''}); fix the mesh or "
                         "allow them (allow_target_pairs=True, --contact-allow-target-pairs)")
    return bad


def check_contact_inputs(template: Rig, target_neutral, exclude=(), allow_target_pairs: bool = False, *,
                         what: str = "contact", exclude_what: str | None = None,
                         target_what: str = "target neutral") -> np.ndarray:
    """What exact contact needs, checked before any solving (``rig --contact`` and
    ``generate_blendshapes(contact=True)``): known shape names in ``exclude``, a mesh within the time
    budget (:func:`check_size`), and a target neutral (n, 3) that does not intersect itself beyond
    the template neutral unless ``allow_target_pairs`` (:func:`check_target_neutral`). Messages name
    ``exclude_what`` (default ``<what>_exclude``), ``what`` and ``"<what>: <target_what>"``. Returns
    the target's own intersecting pairs (q, 2) beyond the template neutral's (allowed ones)."""
    if exclude:
        template.index(list(exclude), what=exclude_what or f"{what}_exclude")
    check_size(template.n_vertices, what=what)
    return check_target_neutral(target_neutral, template, allow_target_pairs, what=f"{what}: {target_what}")


def describe_target_pairs(pairs, target_neutral, faces) -> str:
    """Where a target neutral's own intersecting triangle pairs (q, 2) lie, in one line: how many,
    a few of them, and the box (mesh units) of the triangles involved."""
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    if not len(pairs):
        return "no pairs"
    V = np.asarray(target_neutral, np.float64)
    P = V[np.asarray(faces)[np.unique(pairs)].ravel()]
    lo, hi = P.min(0), P.max(0)
    centre = ", ".join(f"{c:.3g}" for c in (lo + hi) / 2)
    size = " x ".join(f"{c:.3g}" for c in hi - lo)
    ex = ", ".join(f"({i}, {j})" for i, j in pairs[:3].tolist())
    return (f"{len(pairs)} triangle pair(s) ({ex}{', ...' if len(pairs) > 3 else ''}) in a box of {size} "
            f"around ({centre})")


def _check_exclude(exclude, names, what: str) -> list:
    exclude = [exclude] if isinstance(exclude, str) else list(exclude)
    unknown = [e for e in exclude if e not in names]
    if unknown:
        raise InputError(f"contact exclude: expected shape names of the {what} ({', '.join(list(names)[:4])}, "
                         f"...), found unknown {', '.join(repr(u) for u in unknown)}")
    return exclude


def _correct_job(solver: "ContactSolver", job: tuple):
    """One shape: ``solver.correct(name, plain delta, template delta)``."""
    return solver.correct(*job)


def _serve(solver, jobs, tasks, results, parent: int) -> None:
    """A forked worker: job indices from ``tasks`` (None ends it), ``(k, result, error)`` to
    ``results``. ``solver`` and ``jobs`` are the parent's, inherited by the fork (never pickled)."""
    from ..workers import worker_init

    worker_init(parent)  # ignores Ctrl-C, dies with its parent, prints nothing
    while (k := tasks.get()) is not None:
        try:
            results.put((k, _correct_job(solver, jobs[k]), None))
        except Exception as exc:  # noqa: BLE001 - handed to the parent, which raises it
            results.put((k, None, exc))


def _correct_all(solver: "ContactSolver", jobs: list, workers: int) -> list:
    """``solver.correct`` on every job, in order; in ``workers`` forked processes when more than one
    (largest plain motion first, so that the slow shapes start early; each worker takes the next
    shape as it finishes one). The solver and the jobs reach the workers through the fork itself:
    no module state, nothing large pickled; only indices and results cross the queues."""
    import multiprocessing as mp
    import os

    if workers == 1 or "fork" not in mp.get_all_start_methods():
        return [_correct_job(solver, job) for job in jobs]
    ctx = mp.get_context("fork")
    tasks, results = ctx.SimpleQueue(), ctx.SimpleQueue()
    order = sorted(range(len(jobs)), key=lambda k: -float(np.abs(jobs[k][1]).sum()))
    for k in order:
        tasks.put(k)
    for _ in range(workers):
        tasks.put(None)
    procs = [ctx.Process(target=_serve, args=(solver, jobs, tasks, results, os.getpid()), daemon=True)
             for _ in range(workers)]
    out = [None] * len(jobs)
    try:
        for p in procs:
            p.start()
        for _ in jobs:
            k, result, error = results.get()
            if error is not None:
                raise error
            out[k] = result
    finally:
        for p in procs:
            if p.is_alive():
                p.terminate()
        for p in procs:
            p.join()
    return out


def _correct_shapes(solver: "ContactSolver", names: list, deltas: np.ndarray, template_deltas: np.ndarray,
                    exclude, workers: int | None):
    """The one driver of :func:`contact_transfer` and :func:`contact_correct`: every shape of
    ``names`` not in ``exclude`` corrected by ``solver`` (``deltas`` (k, n, 3), the shapes' plain or
    generated deltas, corrected in place; ``template_deltas`` (k, n, 3) the template's shapes of the
    same names). Returns (the reports, one per name (excluded ones say so), the worker count used)."""
    reports = [ContactShape(name, excluded=True) if name in exclude else None for name in names]
    todo = [k for k, name in enumerate(names) if name not in exclude]
    used = max(1, min(available_cores() if workers is None else int(workers), max(len(todo), 1)))
    jobs = [(names[k], deltas[k].copy(), template_deltas[k]) for k in todo]
    for k, (d, rep) in zip(todo, _correct_all(solver, jobs, used)):
        deltas[k] = d
        reports[k] = rep
    return reports, used


def contact_transfer(template: Rig, target_neutral, names=None, exclude=(), anchors=None, margin=None,
                     reach=None, allow_target_pairs: bool = False, max_vertices: int | None = None,
                     max_iterations: int = 40, transfer: DeformationTransfer | None = None,
                     workers: int | None = None, stiffness: float = 0.0) -> ContactResult:
    """Deformation transfer with exact contact: no triangle pair intersects in a transferred shape
    unless it intersects in the target neutral or in the template shape.

    Parameters
    ----------
    template : Rig; target_neutral : (n, 3) in its topology
    names : shapes to transfer (default all); exclude : shape names left as plain transfer (e.g.
        shapes meant to press layers together whose result should not be corrected)
    anchors : as :class:`DeformationTransfer`; transfer : an existing one to reuse (virtual edges...)
    margin, reach : see :class:`ContactSolver`
    allow_target_pairs : accept a target neutral that intersects itself where the template neutral does
        not (its pairs stay allowed); by default that is an error
    max_vertices : refuse larger meshes (time budget)
    workers : processes correcting shapes in parallel (default: the available cores; 1 = in this
        process; needs the ``fork`` start method, otherwise 1)
    stiffness : ``beta`` of the energy ``x^T (L + beta I) x`` (default 0: the transfer's own energy)

    Returns
    -------
    :class:`ContactResult`; ``result.ok`` is False if any shape has new pairs left (see its report).
    """
    t_all = time.perf_counter()
    check_size(template.n_vertices, max_vertices)
    B0 = validate_vertices(target_neutral, "target neutral", template.n_vertices)
    names = list(template.names) if names is None else list(names)
    template.index(names)
    exclude = _check_exclude(exclude, template.names, "template")
    seconds = {}
    t = time.perf_counter()
    check_target_neutral(B0, template, allow_target_pairs)
    seconds["target check"] = time.perf_counter() - t
    t = time.perf_counter()
    dt = DeformationTransfer(template, B0, anchors) if transfer is None else transfer
    plain = dt.transfer(names)
    seconds["plain transfer"] = time.perf_counter() - t
    t = time.perf_counter()
    solver = ContactSolver(dt, margin, reach, max_iterations, stiffness=stiffness)
    seconds["contact setup"] = time.perf_counter() - t
    t = time.perf_counter()
    deltas = plain.deltas.copy()
    reports, used = _correct_shapes(solver, names, deltas, template.deltas[template.index(names)], exclude, workers)
    seconds["shapes"] = time.perf_counter() - t
    seconds["total"] = time.perf_counter() - t_all
    seconds["workers"] = used
    rig = Rig(B0, template.faces, tuple(names), deltas, source="deformation transfer, exact contact")
    return ContactResult(rig, plain, tuple(reports), seconds)


def contact_correct(rig: Rig, template: Rig, transfer: DeformationTransfer | None = None, exclude=(),
                    margin=None, reach=None, max_iterations: int = RIG_ROUNDS, workers: int | None = None,
                    stiffness: float = RIG_STIFFNESS, allow_target_pairs: bool = False,
                    max_vertices: int | None = None, fallback_iterations: int | None = None) -> ContactResult:
    """Exact contact for shapes made otherwise (example-based generation) on the target neutral ``rig.neutral``.

    Each shape of ``rig`` (named as in ``template``) is moved least in ``x^T (L + stiffness I) x``
    (``L`` the normal matrix of ``transfer``, default a plain transfer onto ``rig.neutral``) so that no
    triangle pair intersects unless it intersects in ``rig.neutral`` or in the template's shape of the
    same name. Parameters as :func:`contact_transfer`; ``stiffness`` defaults to ``RIG_STIFFNESS``
    (the smallest displacement: see the module notes); ``fallback_iterations`` bounds the rounds of
    the transfer-energy fallback (:class:`ContactSolver`). ``result.plain`` is ``rig`` itself.
    """
    check_size(template.n_vertices, max_vertices)
    B0 = validate_vertices(rig.neutral, "target neutral", template.n_vertices)
    names = list(rig.names)
    idx = template.index(names)
    exclude = _check_exclude(exclude, names, "rig")
    t_all = time.perf_counter()
    seconds = {}
    check_target_neutral(B0, template, allow_target_pairs)
    seconds["target check"] = time.perf_counter() - t_all
    dt = DeformationTransfer(template, B0) if transfer is None else transfer
    if not np.allclose(dt.target_neutral, B0):
        raise InputError("contact: expected the transfer's target neutral to be the rig's neutral, found another mesh")
    t = time.perf_counter()
    solver = ContactSolver(dt, margin, reach, max_iterations, stiffness=stiffness,
                           fallback_iterations=fallback_iterations)
    seconds["contact setup"] = time.perf_counter() - t
    t = time.perf_counter()
    deltas = np.array(rig.deltas, dtype=np.float64, copy=True)
    reports, used = _correct_shapes(solver, names, deltas, template.deltas[idx], exclude, workers)
    seconds["shapes"] = time.perf_counter() - t
    seconds["total"] = time.perf_counter() - t_all
    seconds["workers"] = used
    source = f"{rig.source}, exact contact" if getattr(rig, "source", None) else "exact contact"
    return ContactResult(Rig(B0, template.faces, tuple(names), deltas, source=source), rig, tuple(reports), seconds)


__all__ = ["ContactShape", "ContactResult", "ContactSolver", "contact_transfer", "contact_correct", "check_size",
           "check_target_neutral", "MAX_VERTICES", "MARGIN_EDGES", "REACH_EDGES", "RIG_STIFFNESS", "RIG_ROUNDS"]
