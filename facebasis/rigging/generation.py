"""Example-based facial blendshape generation (Gao, Tan, Guo, Fan 2015; see References).

Given a template rig ``S_0, S_1..S_k``, a target neutral ``B_0``, training expressions ``T_1..T_m``
of the target and rough weights ``x~``, alternate

* the **basis step** (eq. 2-4): with weights fixed, for every triangle solve for the target
  blendshapes' frame edge columns ``A_i^B`` (3 x 2)

      E_fit = sum_j || A_j^T - A_0^B - sum_i x_ij A_i^B ||_F^2                      (eq. 2)
      E_reg = sum_i w_i || A~_i - A_i^B ||_F^2                                     (eq. 3)
      min  E_fit + alpha E_reg                                                      (eq. 4)

  with ``A~_i`` the deformation transfer of template shape i and per-triangle weights
  ``w_i = ((1 + s_i) / (mu + s_i))^sigma`` (mu = 0.1, sigma = 2); then reconstruct vertex deltas
  from the edges with the factor-once :class:`~facebasis.geometry.poisson.EdgePoisson`;
* the **weight step** (eq. 5): :class:`~facebasis.rigging.weights.WeightSolver` (CasADi + IPOPT, then the
  certified global optimum of every example by branch and bound, :mod:`facebasis.rigging.certify`).

The problem, options and result live in :mod:`facebasis.rigging.problem`, the basis step in
:mod:`facebasis.rigging.basis`, the weight step's two solves in :mod:`facebasis.rigging.certify`
and :mod:`facebasis.rigging.weights`; this module precomputes once and alternates
(:class:`BlendshapeGenerator`, :func:`generate_blendshapes`).

Units of ``w_i``: the paper's ``s_i = ||A_i^S||`` is a length, so ``w_i`` would change with the
mesh's units (cm vs m). facebasis uses by default the scale-free relative edge change
``s_i = ||A_i^S||_F / ||A_0^S||_F`` over the frame's two edge columns (``weight_measure="relative"``);
``"absolute"`` gives the paper's literal, unit-dependent form.

References
----------
- Gao Yali, Tan Guanghua, Guo Songrui, Fan Xiaowei. Example-based facial blendshape generation
    (基于样例的面部表情基生成). Computer Engineering 41(3): 258-261, 2015. Equation numbers
    "eq. N" in this module are this paper's unless another paper is named.
- Sumner R. W., Popovic J. Deformation transfer for triangle meshes. ACM Transactions on Graphics
    23(3) (SIGGRAPH 2004): 399-405.
"""

from __future__ import annotations

import dataclasses
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from threadpoolctl import threadpool_limits

from ..errors import InputError
from ..geometry.gradients import frames_cm
from ..geometry.rig import Rig
from ..geometry.transfer import DeformationTransfer
from ..workers import available_cores
from .basis import basis_rows, regularisation_weights, to_triangle_major, training_rows
from .certify import certify_problem
from .contactstep import contact_generation
from .crossval import cross_validate_alpha
from .problem import GenerationOptions, GenerationProblem, GenerationResult, IterationRecord
from .weightproblem import WeightProblem, WeightSolution
from .weights import WeightSolver

# ----------------------------------------------------------------------------------------------
# orchestration: problem -> precompute -> steps -> result

@dataclass(frozen=True, eq=False)
class TemplatePart:
    """What a run precomputes from the template and the target neutral alone (the same for every
    subset of the training expressions and every schedule).

    dt : the :class:`~facebasis.geometry.transfer.DeformationTransfer` (frames, factorisation)
    A_tilde : (m_tri, 6, k) eq. 3 prior, the transferred frame deltas, triangle-major
    w : (m_tri, k) eq. 3 per-triangle regulariser weights
    extra_targets : (e, 3k) virtual-edge targets (Li et al. 2023) or None
    anchor_rows : (a, 3k) anchor values (the template's delta at still vertices)
    """

    dt: DeformationTransfer
    A_tilde: np.ndarray
    w: np.ndarray
    extra_targets: np.ndarray | None
    anchor_rows: np.ndarray

    @classmethod
    def build(cls, problem: GenerationProblem, options: GenerationOptions) -> "TemplatePart":
        tpl = problem.template
        F = tpl.faces
        dt = DeformationTransfer(tpl, problem.target_neutral, virtual_edges=problem.virtual_edges,
                                 virtual_weight=options.virtual_weight, virtual_mode=options.virtual_mode)
        m_tri = len(F)
        # template frame deltas A_i^S - A_0^S (k, 3, 3, m_tri), computed once for eq. 3's prior and w_i
        dA = frames_cm(tpl.neutral + tpl.deltas, F)
        dA -= dt.template_frames
        # eq. 3 prior: A~_i = Q_i A_0^B - A_0^B = (A_i^S - A_0^S) (A_0^S)^-1 A_0^B
        A_tilde = to_triangle_major(dt.transferred_frame_deltas(frame_deltas=dA).reshape(tpl.n_shapes, 6,
                                                                                         m_tri))  # (m_tri, 6, k)
        w = np.ascontiguousarray(regularisation_weights(dA[:, :, :2], dt.template_frames, options.mu,
                                                        options.sigma, options.weight_measure))  # (m_tri, k)
        # virtual-edge targets (Li et al. 2023) of every shape, from the template as in deformation transfer:
        # (k*3, e) with rows (shape, coordinate) -> (e, 3k) with columns (coordinate, shape)
        vc = dt.virtual_edge_cols(frame_deltas=dA)
        extra = None if vc is None else np.ascontiguousarray(
            vc.reshape(tpl.n_shapes, 3, -1).transpose(2, 1, 0)).reshape(vc.shape[1], -1)
        del dA
        # anchors keep the template's delta (zero at still vertices), as deformation transfer does;
        # rows (a, 3k) with columns (coordinate, shape)
        av = dt.anchor_values()  # (k, a, 3)
        anchors = np.ascontiguousarray(av.transpose(1, 2, 0)).reshape(av.shape[1], -1)
        return cls(dt, A_tilde, w, extra, anchors)

    def reconstruct(self, rows) -> np.ndarray:
        """Vertex deltas from the basis step's frame rows (2, m_tri, 3, k): returns (n, 3k) with
        column ``d k + i`` = coordinate d of shape i."""
        two, m_tri, three, k = rows.shape
        return self.dt.poisson.solve_frame_rows(rows.reshape(2 * m_tri, 3 * k), self.anchor_rows, self.extra_targets)

    @cached_property
    def transfer_rows(self) -> np.ndarray:
        """The deformation transfer of every template shape as vertex deltas (n, 3k) (the prior
        A~ reconstructed; computed once, shared by every generator of this part)."""
        k = self.A_tilde.shape[2]
        return self.reconstruct(np.ascontiguousarray(self.A_tilde.reshape(-1, 3, 2, k).transpose(2, 0, 1, 3)))


@dataclass(frozen=True, eq=False)
class ExamplePart:
    """What a run precomputes from the training expressions' deltas ``E = T - B_0`` (m, n, 3):

    R : (m_tri, 6, m) frame deltas ``A_j^T - A_0^B`` (only the two edge columns enter, and edges are
        linear in the vertices, so they are the edges of ``T_j - B_0``), triangle-first
    targets : ``t_j`` per coordinate, three (n, m) (the reconstruction's output is (n, 3k) with
        columns (coordinate, shape), so the weight step's Gram matrices are three products of its slices)
    target_sq : (m,) ``||t_j||^2``
    """

    R: np.ndarray
    targets: tuple
    target_sq: np.ndarray

    @classmethod
    def build(cls, E, F) -> "ExamplePart":
        with threadpool_limits(1):
            return cls(training_rows(E, F), tuple(np.ascontiguousarray(E[:, :, d].T) for d in range(3)),
                       (E ** 2).sum(axis=(1, 2)))

    def subset(self, idx) -> "ExamplePart":
        """The part of the training expressions ``idx`` (their rows, in that order)."""
        return ExamplePart(np.ascontiguousarray(self.R[:, :, idx]),
                           tuple(np.ascontiguousarray(T[:, idx]) for T in self.targets), self.target_sq[idx])


#: ``BlendshapeGenerator(free=...)`` not given: decided from the problem and options
_DECIDE = object()


class BlendshapeGenerator:
    """Precomputes everything a run needs once: transfer (frames, factorisation), the
    deformation-transfer prior, regulariser weights (:class:`TemplatePart`), training frame deltas
    (:class:`ExamplePart`) and the CasADi solver (built when first needed). The settings
    (problem, options, the parts, the free shapes) are fixed when it is made; :meth:`subset` and
    :meth:`with_options` make new generators that share the precompute.
    """

    def __init__(self, problem: GenerationProblem, options: GenerationOptions | None = None, *,
                 template_part: TemplatePart | None = None, example_part: ExamplePart | None = None,
                 free=_DECIDE, precompute_seconds: float | None = None):
        t0 = time.perf_counter()
        self.problem = problem
        self.options = options or GenerationOptions()
        examples_part = None
        if example_part is None:
            # the training expressions' part of the precompute runs on a second thread while this one
            # sets up the transfer (both are numpy work that releases the GIL)
            side = ThreadPoolExecutor(1)
            examples_part = side.submit(ExamplePart.build, problem.examples - problem.target_neutral,
                                        problem.template.faces)
            side.shutdown(wait=False)
        self.template_part = template_part or TemplatePart.build(problem, self.options)
        self.example_part = example_part or examples_part.result()
        self.pairs = problem.pair_indices
        self._weight_solver = None  # the CasADi model, built when first needed (ipopt option)
        self._weight_solver_future = None  # ... or on a side thread while the alternations run
        self.free = self._free_shapes() if free is _DECIDE else free
        self.precompute_seconds = (time.perf_counter() - t0) if precompute_seconds is None else precompute_seconds

    # the precompute's arrays, by the names of the paper's quantities
    dt = property(lambda self: self.template_part.dt)
    A_tilde = property(lambda self: self.template_part.A_tilde)
    w = property(lambda self: self.template_part.w)
    R = property(lambda self: self.example_part.R)
    targets = property(lambda self: self.example_part.targets)
    target_sq = property(lambda self: self.example_part.target_sq)

    def reconstruct(self, rows) -> np.ndarray:
        """Vertex deltas (n, 3k) from the basis step's frame rows (2, m_tri, 3, k) (:meth:`TemplatePart.reconstruct`)."""
        return self.template_part.reconstruct(rows)

    @staticmethod
    def deltas_of(Bv) -> np.ndarray:
        """(n, 3k) reconstruction output -> (k, n, 3) deltas."""
        n = Bv.shape[0]
        return np.ascontiguousarray(Bv.reshape(n, 3, -1).transpose(2, 0, 1))

    def _free_shapes(self):
        """(k,) bool, shapes whose weights the weight step may change; None if all (see ``unobserved``).

        A shape is unobserved when its rough weight stays below ``support`` in every training
        expression *and* so does its weight when the expressions are fitted to the deformation
        transfer (bounds + complementarity, no prior): the rough weights alone misclassify a shape
        a training expression uses weakly, whose rough weight the noise pushed below ``support``.
        """
        if self.options.unobserved != "transfer":
            return None
        support = self.options.support
        free = self.problem.initial_weights.max(axis=0) >= support
        if free.all():
            return None
        free |= self.transfer_weights().max(axis=0) >= support
        return None if free.all() else free

    def transfer_rows(self) -> np.ndarray:
        """The deformation transfer of every template shape as vertex deltas (n, 3k) (:attr:`TemplatePart.transfer_rows`)."""
        return self.template_part.transfer_rows

    def transfer_weights(self) -> np.ndarray:
        """(m, k) weights of the training expressions fitted to the deformation transfer (certified,
        bounds + complementarity, no prior)."""
        return certify_problem(self.weight_problem(self.transfer_rows(), 0.0, None)).X

    @property
    def unobserved(self) -> tuple[str, ...]:
        """Names of the shapes no training expression supports (held at their deformation transfer)."""
        names = self.problem.template.names
        return () if self.free is None else tuple(names[i] for i in np.flatnonzero(~self.free))

    def subset(self, indices) -> "BlendshapeGenerator":
        """The generator of the training expressions ``indices`` only, sharing the template's
        precompute (transfer, prior, regulariser weights), for cross-validation."""
        idx = np.asarray(indices, dtype=np.int64)
        p = self.problem
        sub = dataclasses.replace(p, examples=p.examples[idx], initial_weights=p.initial_weights[idx],
                                  example_names=tuple(p.example_names[i] for i in idx))
        return BlendshapeGenerator(sub, self.options, template_part=self.template_part,
                                   example_part=self.example_part.subset(idx),
                                   precompute_seconds=self.precompute_seconds)

    def with_options(self, options: GenerationOptions) -> "BlendshapeGenerator":
        """The same generator with other schedule options (alpha, lambda, iterations, ipopt); the
        precompute does not depend on them (nor do the free shapes unless ``unobserved`` or
        ``support`` change)."""
        same = (options.unobserved, options.support) == (self.options.unobserved, self.options.support)
        return BlendshapeGenerator(self.problem, options, template_part=self.template_part,
                                   example_part=self.example_part, free=self.free if same else _DECIDE,
                                   precompute_seconds=self.precompute_seconds)

    @property
    def weight_solver(self) -> WeightSolver:
        """The CasADi/IPOPT model of eq. 5 (built once, on first use)."""
        if self._weight_solver is None:
            future, self._weight_solver_future = self._weight_solver_future, None
            self._weight_solver = future.result() if future is not None else self._build_weight_solver()
        return self._weight_solver

    def _build_weight_solver(self) -> WeightSolver:
        return WeightSolver(self.problem.template.n_shapes, len(self.problem.examples), self.pairs,
                            self.options.ipopt_options, polish=self.options.polish)

    def _prebuild_weight_solver(self, schedule) -> None:
        """Start building the CasADi model on a side thread when a run of ``schedule`` will call
        IPOPT: CasADi releases the GIL while it builds, so the build overlaps the
        first alternations instead of delaying the final one."""
        if self._weight_solver is not None or self._weight_solver_future is not None:
            return
        if any(self._runs_ipopt(it, len(schedule)) for it in range(len(schedule))):
            side = ThreadPoolExecutor(1)
            self._weight_solver_future = side.submit(self._build_weight_solver)
            side.shutdown(wait=False)

    def gram(self, Bv):
        """``G = B^T B`` (k, k) and ``c_j = B^T t_j`` as rows, (m, k), from the reconstruction ``Bv``
        (n, 3k)."""
        k = self.problem.template.n_shapes
        cols = [Bv[:, d * k:(d + 1) * k] for d in range(3)]  # (n, k) strided views, no copy
        # one BLAS thread: on a busy machine OpenBLAS's threads made B^T T take 0.3 s instead of 9 ms
        with threadpool_limits(1):
            G = sum(B.T @ B for B in cols)
            C = sum(T.T @ B for B, T in zip(cols, self.targets))
        return G, C

    def weight_problem(self, Bv, lam: float, prior) -> WeightProblem:
        """Eq. 5 for the training expressions against the blendshapes ``Bv`` (n, 3k) of
        :meth:`reconstruct`, with the prior (m, k) or None (zeros) weighted by ``lam``."""
        G, C = self.gram(Bv)
        return WeightProblem(G, C, self.target_sq, self.pairs, prior, lam)

    def weight_step(self, Bv, lam, X0=None, ipopt: bool = True) -> WeightSolution:
        """Eq. 5 with the blendshapes ``Bv`` (n, 3k) of :meth:`reconstruct`: the CasADi/IPOPT model
        polished by the certified solver (``ipopt``), or the certified solver alone."""
        problem = self.weight_problem(Bv, lam, self.problem.initial_weights)
        if ipopt:
            return self.weight_solver.solve_problem(problem, X0, free=self.free)
        return certify_problem(problem, free=self.free)

    def _runs_ipopt(self, it: int, total: int) -> bool:
        mode = self.options.ipopt
        return mode == "every" or (mode == "final" and it == total - 1)

    def run(self, progress=None, *, X0=None, schedule=None, cv_progress=None) -> GenerationResult:
        """Alternate the basis and weight steps over the schedule (default: the options').

        ``alpha="auto"`` first chooses the schedule by cross-validation (:mod:`.crossval`; the
        alternations are then those of :meth:`~.crossval.CrossValidation.final_schedule`);
        ``X0`` (m, k) starts from other weights than the rough ones (a warm start);
        ``schedule`` is a list of (alpha, lambda), one per alternation. The generator is not
        changed: the options the run settled on (``alpha="auto"`` resolved) are ``result.options``.
        """
        t_start = time.perf_counter()
        p, opts = self.problem, self.options
        crossval, done = None, []  # done: alternations already made (the "deletion" cross-validation's path)
        if schedule is None and opts.auto_alpha:
            crossval = cross_validate_alpha(self, progress=cv_progress)
            # the final run is made the way the curve scored the chosen alpha (crossval.final_schedule)
            schedule = crossval.final_schedule(opts)
            opts = dataclasses.replace(opts, alpha=crossval.schedule)
            if crossval.final_state is not None:  # "deletion": the path on all expressions is there up to
                # the chosen alpha's last alternation; that one is run here (with IPOPT as the options say)
                X0 = crossval.final_state["X"]
                done = list(crossval.final_state["history"])
                schedule = schedule[len(done):]
        X = p.initial_weights.copy() if X0 is None else np.array(X0, dtype=np.float64)  # (m, k)
        if X.shape != p.initial_weights.shape:
            raise InputError(f"X0: expected shape {p.initial_weights.shape}, found {X.shape}")
        if self.free is not None:
            X[:, ~self.free] = 0.0  # unobserved shapes: the first basis step already leaves them at their transfer
        schedule = opts.schedule() if schedule is None else [(float(a), float(b)) for a, b in schedule]
        self._prebuild_weight_solver(schedule)
        if done and progress is not None:  # numbered after the path's alternations
            shown, offset = progress, len(done)

            def progress(rec, total):
                shown(dataclasses.replace(rec, iteration=offset + rec.iteration), offset + total)
        workers = opts.threads or available_cores()
        pool = ThreadPoolExecutor(workers) if workers > 1 else None
        try:
            history, X, deltas = self._iterate(X, schedule, pool, progress)
            if done:  # the path's earlier alternations, renumbered after them
                history = done + [dataclasses.replace(h, iteration=len(done) + h.iteration) for h in history]
        finally:
            if pool is not None:
                pool.shutdown()
        rig = Rig(p.target_neutral, p.template.faces, p.template.names, deltas, source="example-based generation")
        return GenerationResult.from_weights(rig, X, p, opts, history=tuple(history),
                                             seconds=time.perf_counter() - t_start,
                                             precompute_seconds=self.precompute_seconds, unobserved=self.unobserved,
                                             crossval=crossval)

    def _iterate(self, X, schedule, pool, progress):
        history = []
        rows = None  # the basis step's output, one buffer for all alternations (reconstruct copies out of it)
        for it, (alpha, lam) in enumerate(schedule):
            t0 = time.perf_counter()
            # parallel over blocks of triangles (pool), not inside BLAS
            with threadpool_limits(1):  # one BLAS thread: spinning OpenBLAS threads cost 10x on a busy machine
                rows, e_fit, e_reg = basis_rows(X.T, self.R, self.A_tilde, self.w, alpha, executor=pool, out=rows)
            Bv = self.reconstruct(rows)
            t1 = time.perf_counter()
            sol = self.weight_step(Bv, lam, X0=X, ipopt=self._runs_ipopt(it, len(schedule)))
            X = sol.weights
            history.append(IterationRecord(
                iteration=it + 1, alpha=alpha, lam=lam, e_fit=e_fit, e_reg=e_reg,
                weight_objective=sol.objective, ipopt_objective=sol.ipopt_objective,
                max_complementarity=sol.max_complementarity, max_bound_violation=sol.max_bound_violation,
                ipopt_max_complementarity=sol.ipopt_max_complementarity,
                ipopt_max_bound_violation=sol.ipopt_max_bound_violation, ipopt_status=sol.ipopt_status,
                ipopt_iterations=sol.ipopt_iterations, ipopt_success=sol.ipopt_success,
                basis_seconds=t1 - t0, weight_seconds=sol.seconds, weight_prior=_prior_term(sol),
            ))
            if progress is not None:
                progress(history[-1], len(schedule))
        return history, X, self.deltas_of(Bv)


def _prior_term(sol) -> float:
    """``lambda sum_j ||x_j - x~_j||^2`` of a weight step's answer (eq. 5's prior part)."""
    P = sol.problem
    D = np.asarray(sol.X, float) - P.prior
    return float(np.sum(P.lam * np.einsum("jk,jk->j", D, D)))


def generate_blendshapes(problem: GenerationProblem, options: GenerationOptions | None = None,
                         progress=None, *, contact: bool = False, contact_exclude=(),
                         allow_target_pairs: bool = False) -> GenerationResult:
    """Example-based blendshape generation (Gao et al. 2015): precompute, alternate, return the result.

    ``contact=True`` then makes the generated shapes intersection-free (exact contact,
    :func:`facebasis.rigging.contactstep.contact_generation`: no triangle pair intersects unless it
    does in the target neutral or in the template shape; ``contact_exclude`` names shapes left as
    generated) and re-solves the final weight step; the :class:`~facebasis.contact.exact.ContactResult`
    is ``result.contact`` (check ``result.contact.ok``).
    """
    if contact:  # the contact inputs are checked before any solving starts
        from ..contact.exact import check_contact_inputs

        check_contact_inputs(problem.template, problem.target_neutral, contact_exclude, allow_target_pairs)
    elif contact_exclude or allow_target_pairs:
        raise InputError("contact_exclude / allow_target_pairs: expected contact=True as well, found contact=False")
    gen = BlendshapeGenerator(problem, options)
    res = gen.run(progress)
    if contact:
        found, res = contact_generation(gen, res, contact_exclude, allow_target_pairs)
        res = dataclasses.replace(res, contact=found)
    return res


__all__ = ["BlendshapeGenerator", "TemplatePart", "ExamplePart", "generate_blendshapes"]
