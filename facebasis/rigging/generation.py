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

Per triangle the basis step is the k x k system ``(X X^T + alpha W) Y = X R + alpha W A~``; with
m well below k it is solved through the m x m Woodbury form, in blocks of triangles with BLAS matrix
products; otherwise (more training expressions) by a k x k Cholesky per triangle (:func:`use_direct`);
the blocks run on worker threads.

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
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from threadpoolctl import threadpool_limits

from ..errors import InputError, SolverError
from ..geometry.gradients import frames_cm
from ..geometry.mesh import validate_vertices
from ..geometry.rig import Rig
from ..geometry.transfer import DeformationTransfer
from .weights import WeightSolver, WeightSolution, eq5_objective, solve_certified


# ----------------------------------------------------------------------------------------------
# problem, options, result

@dataclass(frozen=True)
class GenerationProblem:
    """Inputs of example-based generation.

    Attributes
    ----------
    template : Rig, ``S_0`` and deltas ``S_i`` (k shapes)
    target_neutral : (n, 3) ``B_0`` in the template's topology
    examples : (m, n, 3) training expressions ``T_j`` (absolute positions)
    initial_weights : (m, k) rough weights ``x~`` in [0, 1]
    example_names : m names (e.g. file stems)
    exclusive : pairs of shape names that are mutually exclusive (complementarity)
    virtual_edges : optional :class:`~facebasis.contact.virtual_edges.VirtualEdges` (Li et al. 2023): their energy
        joins every reconstruction of the basis step, with the deformation-transfer targets
    """

    template: Rig
    target_neutral: np.ndarray
    examples: np.ndarray
    initial_weights: np.ndarray
    example_names: tuple[str, ...] = ()
    exclusive: tuple[tuple[str, str], ...] = ()
    virtual_edges: object | None = None

    def __post_init__(self):
        t = self.template
        B0 = validate_vertices(self.target_neutral, "target neutral", t.n_vertices)
        T = np.ascontiguousarray(self.examples, dtype=np.float64)
        if T.ndim != 3 or T.shape[1:] != (t.n_vertices, 3):
            raise InputError(f"examples: expected shape (m, {t.n_vertices}, 3), found {T.shape}")
        if len(T) == 0:
            raise InputError("examples: expected at least one training expression, found none")
        names = tuple(self.example_names) or tuple(f"ex{j:02d}" for j in range(len(T)))
        if len(names) != len(T):
            raise InputError(f"example_names: expected {len(T)}, found {len(names)}")
        bad = [names[j] for j in np.flatnonzero(~np.isfinite(T).all(axis=(1, 2)))]
        if bad:
            raise InputError(f"examples: expected finite coordinates, found NaN/inf in {bad}")
        X = np.asarray(self.initial_weights, dtype=np.float64)
        if X.shape != (len(T), t.n_shapes):
            raise InputError(f"initial_weights: expected shape ({len(T)}, {t.n_shapes}), found {X.shape}")
        if not np.isfinite(X).all():
            raise InputError("initial_weights: expected finite values, found NaN/inf")
        out = np.argwhere((X < 0) | (X > 1))
        if len(out):
            j, i = out[0]
            raise InputError(
                f"initial_weights: expected values in [0, 1], found {len(out)} outside, e.g. "
                f"{names[j]}.{t.names[i]} = {X[j, i]:g}"
            )
        pairs = tuple((str(a), str(b)) for a, b in self.exclusive)
        for a, b in pairs:
            t.index([a, b], what=f"exclusive pair {a}:{b}")
            if a == b:
                raise InputError(f"exclusive pair {a}:{b}: expected two different shapes, found one twice")
        object.__setattr__(self, "target_neutral", B0)
        object.__setattr__(self, "examples", T)
        object.__setattr__(self, "initial_weights", X)
        object.__setattr__(self, "example_names", names)
        object.__setattr__(self, "exclusive", pairs)
        ve = self.virtual_edges
        if ve is not None and getattr(ve, "n_vertices", None) != t.n_vertices:
            raise InputError(f"virtual_edges: expected edges for {t.n_vertices} vertices, found "
                             f"{getattr(ve, 'n_vertices', type(ve).__name__)}")

    @property
    def pair_indices(self) -> np.ndarray:
        if not self.exclusive:
            return np.zeros((0, 2), dtype=np.int64)
        return np.array([self.template.index([a, b]) for a, b in self.exclusive])


#: what a shape that no training expression activates becomes: its deformation transfer (its
#: weights held at 0), or fitted like every other shape
UNOBSERVED_MODES = ("transfer", "fit")

#: when the weight step runs the CasADi/IPOPT model of eq. 5 (its answer seeds the certified
#: polish); the other alternations use the certified solver alone, which returns the same optimum
IPOPT_MODES = ("every", "final", "never")


@dataclass(frozen=True)
class GenerationOptions:
    """Schedule and parameters (defaults: the paper's).

    alpha and lambda go geometrically from their first to their last value over the iterations.
    ``alpha="auto"`` chooses the alpha schedule ``(5 a, a)`` (the paper's ratio) by k-fold
    cross-validation over the training expressions (:mod:`facebasis.rigging.crossval`; ``cv_folds``,
    ``cv_grid`` the candidate final alphas, ``cv_chain_iterations``).

    ``unobserved``: a shape whose rough weights stay below ``support`` in every training
    expression has no support in the examples. With ``"transfer"`` (default) its weights are held
    at 0, so the basis step leaves it at its deformation transfer (eq. 4 decouples it; the
    regulariser alone decides it). With ``"fit"`` (the paper) it is fitted like the others: the
    noise of its rough weights lets it absorb other shapes' residuals, which makes it worse than
    the template's delta and its weights drift from the truth with every alternation.

    ``ipopt`` says when the weight step solves the joint CasADi/IPOPT model of eq. 5: ``"every"``
    alternation, only the ``"final"`` one (default), or ``"never"``. Its answer only seeds the
    certified branch and bound (:mod:`facebasis.rigging.certify`), whose per-example global optimum
    is the weight step's answer either way; without IPOPT the certified solver runs unseeded.
    Measured on ICT with 80 training expressions: identical weights (max difference 1e-15),
    IPOPT 0.65-1.1 s per alternation against 0.05-0.07 s for the certified solver, and IPOPT's
    seed makes the tree larger (706 nodes against 629), so IPOPT adds no accuracy; ``"final"``
    keeps it as an independent cross-check whose status and raw objective the history records.
    """

    iterations: int = 10
    alpha: tuple[float, float] | str = (0.5, 0.1)
    lam: tuple[float, float] = (100.0, 10.0)
    mu: float = 0.1
    sigma: float = 2.0
    weight_measure: str = "relative"
    missing_threshold: float = 0.2
    polish: bool = True
    ipopt_options: dict = field(default_factory=dict)
    threads: int | None = None
    virtual_weight: float | None = None
    virtual_mode: str = "proportional"
    ipopt: str = "final"
    unobserved: str = "transfer"
    support: float = 0.3
    cv_folds: int = 4
    cv_grid: tuple[float, ...] = ()
    cv_chain_iterations: int = 2

    def __post_init__(self):
        if int(self.iterations) < 1:
            raise InputError(f"iterations: expected >= 1, found {self.iterations}")
        auto = isinstance(self.alpha, str)
        if auto and self.alpha != "auto":
            raise InputError(f"alpha: expected two numbers (first, last) or 'auto', found {self.alpha!r}")
        for name in ("lam",) if auto else ("alpha", "lam"):
            v = tuple(float(a) for a in getattr(self, name))
            if len(v) != 2 or not all(np.isfinite(v)):
                raise InputError(f"{name}: expected two finite values (first, last), found {getattr(self, name)}")
            object.__setattr__(self, name, v)
        if not auto and min(self.alpha) <= 0:
            raise InputError(f"alpha: expected values > 0, found {self.alpha}")
        if min(self.lam) < 0:
            raise InputError(f"lambda: expected values >= 0, found {self.lam}")
        if self.weight_measure not in ("relative", "absolute"):
            raise InputError(f"weight_measure: expected 'relative' or 'absolute', found {self.weight_measure!r}")
        if self.threads is not None and int(self.threads) < 1:
            raise InputError(f"threads: expected >= 1 or None (all cores), found {self.threads}")
        if not (0 < self.mu < 1) or self.sigma < 0:
            raise InputError(f"mu, sigma: expected 0 < mu < 1 and sigma >= 0, found {self.mu}, {self.sigma}")
        if self.ipopt not in IPOPT_MODES:
            raise InputError(f"ipopt: expected one of {', '.join(IPOPT_MODES)}, found {self.ipopt!r}")
        if self.unobserved not in UNOBSERVED_MODES:
            raise InputError(f"unobserved: expected one of {', '.join(UNOBSERVED_MODES)}, found {self.unobserved!r}")
        if not (np.isfinite(self.support) and 0.0 <= self.support <= 1.0):
            raise InputError(f"support: expected a rough weight in [0, 1], found {self.support}")
        if int(self.cv_folds) < 2:
            raise InputError(f"cv_folds: expected >= 2, found {self.cv_folds}")
        if int(self.cv_chain_iterations) < 1:
            raise InputError(f"cv_chain_iterations: expected >= 1, found {self.cv_chain_iterations}")
        grid = tuple(float(a) for a in self.cv_grid)
        if any(not np.isfinite(a) or a <= 0 for a in grid):
            raise InputError(f"cv_grid: expected final alphas > 0, found {self.cv_grid}")
        object.__setattr__(self, "cv_grid", grid)
        if not self.polish and self.ipopt != "every":
            raise InputError(f"polish: expected True unless ipopt='every' (IPOPT's raw answers), found polish=False "
                             f"with ipopt={self.ipopt!r}")

    @property
    def auto_alpha(self) -> bool:
        return isinstance(self.alpha, str)

    def schedule(self) -> list[tuple[float, float]]:
        if self.auto_alpha:
            raise InputError("alpha: 'auto' has no schedule before cross-validation chooses one "
                             "(generate_blendshapes / BlendshapeGenerator.run choose it)")
        n = int(self.iterations)
        s = np.linspace(0.0, 1.0, n) if n > 1 else np.zeros(1)
        a0, a1 = self.alpha
        l0, l1 = self.lam
        alphas = a0 * (a1 / a0) ** s
        lams = l0 * (l1 / l0) ** s if min(l0, l1) > 0 else l0 + (l1 - l0) * s
        return list(zip(alphas.tolist(), lams.tolist()))


@dataclass(frozen=True)
class IterationRecord:
    iteration: int
    alpha: float
    lam: float
    e_fit: float
    e_reg: float
    weight_objective: float
    ipopt_objective: float
    max_complementarity: float
    max_bound_violation: float
    ipopt_max_complementarity: float
    ipopt_max_bound_violation: float
    ipopt_status: str
    ipopt_iterations: int
    ipopt_success: bool
    basis_seconds: float
    weight_seconds: float


@dataclass(frozen=True)
class GenerationResult:
    """Output of :func:`generate_blendshapes`.

    rig : the generated target rig (neutral ``B_0``, deltas ``B_i``)
    weights : (m, k) solved weights of the training expressions
    history : one :class:`IterationRecord` per alternation
    residuals : (m,) relative vertex residual ``||B_0 + B x_j - T_j|| / ||T_j - B_0||``
    missing : names of training expressions whose residual exceeds the threshold
    example_names, seconds
    options : the options the alternation ran with (``alpha="auto"`` resolved to its choice)
    unobserved : names of the shapes without support in the examples (kept at their transfer)
    crossval : the :class:`~facebasis.rigging.crossval.CrossValidation` behind ``alpha="auto"``, else None
    """

    rig: Rig
    weights: np.ndarray
    history: tuple[IterationRecord, ...]
    residuals: np.ndarray
    missing: tuple[str, ...]
    example_names: tuple[str, ...]
    seconds: float
    precompute_seconds: float
    options: "GenerationOptions | None" = None
    unobserved: tuple[str, ...] = ()
    crossval: object | None = None

    @property
    def all_ipopt_succeeded(self) -> bool:
        return all(h.ipopt_success for h in self.history)


# ----------------------------------------------------------------------------------------------
# pure functions of the method

def regularisation_weights(template_frame_deltas, template_frames, mu=0.1, sigma=2.0, measure="relative"):
    """Per-triangle regulariser weights of eq. 3, (m_tri, k).

    ``w = ((1 + s) / (mu + s))^sigma`` with ``s = ||A_i^S||`` (``measure="absolute"``, the paper)
    or ``s = ||A_i^S|| / ||A_0^S||`` (``"relative"``, scale-free), norms over the two edge columns.

    Parameters
    ----------
    template_frame_deltas : (k, 3, 2, m_tri) edge columns of ``S_i``'s frames minus ``S_0``'s
    template_frames : (3, 3, m_tri) frames of ``S_0``
    """
    s = np.sqrt((template_frame_deltas ** 2).sum(axis=(1, 2)))  # (k, m_tri)
    if measure == "relative":
        s = s / np.sqrt((template_frames[:, :2] ** 2).sum(axis=(0, 1)))

    return (((1.0 + s) / (mu + s)) ** sigma).T


#: triangles per block of the basis step (blocks stay in cache and run on the worker threads)
BASIS_BLOCK = 512

#: the basis step uses the m x m Woodbury form while ``m < WOODBURY_RATIO * k``, else the direct
#: k x k Cholesky per triangle. Measured on ICT (k = 53, 28,068 triangles, one core): Woodbury
#: 0.95 s vs direct 1.14 s per step at m = 40, 1.73 s vs 1.14 s at m = 53 (forming the m x m
#: systems costs 2 k m^2 per triangle against k^3 / 3 for the Cholesky factor).
WOODBURY_RATIO = 0.8


def use_direct(k: int, m: int) -> bool:
    """Whether the basis step solves the k x k systems directly (else the m x m Woodbury form)."""
    return m >= WOODBURY_RATIO * k


def _lapack_posv():
    from scipy.linalg import lapack

    return lapack.dposv


def _basis_block(X, XX, RT, AT, w, alpha, out, s):
    """Eq. 4 on the triangles of slice ``s``; writes ``out[:, s]`` and returns (E_fit, E_reg) there.

    Triangle-major layout, so that every product has the shapes (6c, .) x (., k) and the result
    lands in the reconstruction's layout without a transpose of the whole array:
    ``RT`` (6, m_tri, m) and ``AT`` (6, m_tri, k) hold ``R_j`` and ``A~_i`` with the 6 edge-column
    entries (coordinate d, column e) first; ``out`` is (2, m_tri, 3, k) = [column e, triangle,
    coordinate d, shape i]. ``XX`` is ``X X^T`` (k, k) when :func:`use_direct` (k x k Cholesky
    solves, one LAPACK ``posv`` per triangle), else the (k, m*m) table of ``x_i x_i^T`` for the
    Woodbury form.
    """
    k, m = X.shape
    wt = w[s]                                            # (c, k)
    c = wt.shape[0]
    Rs = np.ascontiguousarray(RT[:, s, :]).reshape(6 * c, m)
    As = AT[:, s, :]                                     # (6, c, k)
    if use_direct(k, m):  # (X X^T + D) Y = X R + D A~ directly, per triangle (Cholesky: D > 0)
        D = alpha * wt
        A = np.broadcast_to(XX, (c, k, k)).copy()
        A.reshape(c, -1)[:, :: k + 1] += D
        rhs = (Rs @ X.T).reshape(6, c, k)
        rhs += D[None] * As
        Yt = np.ascontiguousarray(rhs.transpose(1, 0, 2))  # (c, 6, k): Yt[t].T is (k, 6) Fortran-ordered
        posv = _lapack_posv()
        for t in range(c):  # one LAPACK call per triangle, in place, without the GIL
            _, x, info = posv(A[t].T, Yt[t].T, overwrite_a=1, overwrite_b=1)
            if info != 0:  # pragma: no cover - X X^T + D is positive definite for alpha, w > 0
                raise SolverError(f"basis step: Cholesky failed on a triangle (LAPACK info {info})", str(info))
        Y = np.ascontiguousarray(Yt.transpose(1, 0, 2))    # (6, c, k)
    else:
        dinv = 1.0 / (alpha * wt)                        # D^-1, (c, k)
        Gm = (Rs @ X.T).reshape(6, c, k)                 # sum_j x_ij R_j
        Gm *= dinv[None]
        Gm += As                                         # D^-1 (X R + D A~)
        XtG = (Gm.reshape(6 * c, k) @ X).reshape(6, c, m)
        # K_t = I + X^T D_t^-1 X for every triangle of the block: one (c, k) x (k, m*m) product
        K = (dinv @ XX).reshape(c, m, m)
        K.reshape(c, -1)[:, :: m + 1] += 1.0
        Z = np.linalg.solve(K, XtG.transpose(1, 2, 0))   # (c, m, 6)
        XZ = (np.ascontiguousarray(Z.transpose(2, 0, 1)).reshape(6 * c, m) @ X.T).reshape(6, c, k)
        XZ *= dinv[None]
        Y = np.subtract(Gm, XZ, out=Gm)                  # (6, c, k)
    out[:, s] = Y.reshape(3, 2, c, k).transpose(1, 2, 0, 3)
    # eq. 2 and eq. 3 on the block
    fit = (Y.reshape(6 * c, k) @ X).reshape(6 * c, m)
    fit -= Rs
    diff = As - Y
    diff *= diff
    return float(np.vdot(fit, fit)), float(np.einsum("ck,dck->", wt, diff))


def basis_rows(X, RT, AT, w, alpha, *, executor=None, block: int = BASIS_BLOCK):
    """Eq. 4 for every triangle in the triangle-major layout of :func:`_basis_block`.

    Returns (out (2, m_tri, 3, k), E_fit, E_reg); ``out.reshape(2 m_tri, 3k)`` is what
    :meth:`facebasis.geometry.poisson.EdgePoisson.solve_frame_rows` takes.
    """
    k, m = X.shape
    m_tri = RT.shape[1]
    X = np.ascontiguousarray(X, dtype=np.float64)
    XX = X @ X.T if use_direct(k, m) else (X[:, :, None] * X[:, None, :]).reshape(k, m * m)
    out = np.empty((2, m_tri, 3, k))
    blocks = [slice(i, min(i + block, m_tri)) for i in range(0, m_tri, block)]
    if executor is None:
        parts = [_basis_block(X, XX, RT, AT, w, alpha, out, s) for s in blocks]
    else:
        parts = list(executor.map(lambda s: _basis_block(X, XX, RT, AT, w, alpha, out, s), blocks))
    return out, float(sum(p[0] for p in parts)), float(sum(p[1] for p in parts))


def training_rows(E, F) -> np.ndarray:
    """Edge columns of the frames of deltas ``E`` (m, n, 3) in the triangle-major layout
    (6, m_tri, m) of :func:`basis_rows`: row ``2 d + e`` is coordinate d of column e
    (e = 0: v2 - v1, e = 1: v3 - v1), as ``frames_cm(T)[:, :, :2] - frames_cm(B_0)[:, :2]``."""
    Et = np.ascontiguousarray(np.asarray(E, dtype=np.float64).transpose(1, 2, 0))  # (n, 3, m)
    v1 = Et[F[:, 0]]
    out = np.empty((3, 2, len(F), Et.shape[2]))
    out[:, 0] = (Et[F[:, 1]] - v1).transpose(1, 0, 2)
    out[:, 1] = (Et[F[:, 2]] - v1).transpose(1, 0, 2)
    return out.reshape(6, len(F), -1)


def to_triangle_major(A) -> np.ndarray:
    """(q, 6, m_tri) -> (6, m_tri, q), the layout of :func:`basis_rows`."""
    return np.ascontiguousarray(np.asarray(A, dtype=np.float64).transpose(1, 2, 0))


def basis_step(X, R, A_tilde, w, alpha, *, executor=None, block: int = BASIS_BLOCK, energies: bool = False):
    """Solve eq. 4 for every triangle at once.

    Parameters
    ----------
    X : (k, m) weights, column j = x_j
    R : (m, 6, m_tri) training frame deltas ``A_j^T - A_0^B`` (edge columns, flattened 3 x 2)
    A_tilde : (k, 6, m_tri) deformation-transfer prior ``A~_i``
    w : (m_tri, k) regulariser weights
    alpha : regularisation weight (> 0)
    executor : optional ``concurrent.futures`` executor; blocks of triangles run on it
    block : triangles per block
    energies : also return ``(E_fit, E_reg)`` of eq. 2 and 3 at the solution

    Returns
    -------
    Y : (k, 6, m_tri) blendshape frame deltas ``A_i^B`` minimising ``E_fit + alpha E_reg``
    (and ``E_fit, E_reg`` if ``energies``).

    Notes
    -----
    Per triangle ``(X X^T + D) Y = X R + D A~`` with ``D = alpha diag(w_t)``. With m small against k
    (:func:`use_direct`) the Woodbury identity
    ``(D + X X^T)^-1 = D^-1 - D^-1 X (I + X^T D^-1 X)^-1 X^T D^-1`` reduces each triangle to an
    m x m solve (one BLAS product per contraction over a block); otherwise the k x k system is
    solved directly, one in-place LAPACK Cholesky solve (``posv``) per triangle. Triangles are
    processed in cache-sized blocks; blocks are independent and run in parallel on ``executor``. This wrapper converts
    layouts; the generator calls :func:`basis_rows` on data kept in its layout.
    """
    k = X.shape[0]
    m_tri = R.shape[-1]
    out, e_fit, e_reg = basis_rows(X, to_triangle_major(R), to_triangle_major(A_tilde), w, alpha,
                                   executor=executor, block=block)
    Y = np.ascontiguousarray(out.transpose(3, 2, 0, 1)).reshape(k, 6, m_tri)  # [i, (d, e), t]
    return (Y, e_fit, e_reg) if energies else Y


def basis_energies(X, R, A_tilde, w, Y):
    """``E_fit`` (eq. 2) and ``E_reg`` (eq. 3) at blendshape frames Y, over edge columns."""
    k, m = X.shape
    fit = (X.T @ Y.reshape(k, -1)).reshape(R.shape)
    fit -= R
    e_fit = float(np.einsum("i,i->", fit.ravel(), fit.ravel()))
    diff = A_tilde - Y
    diff *= diff
    e_reg = float(np.einsum("kt,kct->", w.T, diff))
    return e_fit, e_reg


# ----------------------------------------------------------------------------------------------
# orchestration: problem -> precompute -> steps -> result

class BlendshapeGenerator:
    """Precomputes everything a run needs once: transfer (frames, factorisation), the
    deformation-transfer prior, regulariser weights, training frame deltas and the CasADi solver.
    """

    def __init__(self, problem: GenerationProblem, options: GenerationOptions | None = None):
        t0 = time.perf_counter()
        self.problem = problem
        self.options = options or GenerationOptions()
        opts = self.options
        tpl = problem.template
        F = tpl.faces
        self.dt = DeformationTransfer(tpl, problem.target_neutral, virtual_edges=problem.virtual_edges,
                                      virtual_weight=opts.virtual_weight, virtual_mode=opts.virtual_mode)
        m_tri = len(F)
        # template frame deltas A_i^S - A_0^S (k, 3, 3, m_tri), computed once for eq. 3's prior and w_i
        dA = frames_cm(tpl.neutral + tpl.deltas, F)
        dA -= self.dt.template_frames
        # eq. 3 prior: A~_i = Q_i A_0^B - A_0^B = (A_i^S - A_0^S) (A_0^S)^-1 A_0^B
        self.A_tilde = to_triangle_major(self.dt.transferred_frame_deltas(frame_deltas=dA).reshape(tpl.n_shapes, 6,
                                                                                                  m_tri))  # (6, m_tri, k)
        self.w = np.ascontiguousarray(regularisation_weights(dA[:, :, :2], self.dt.template_frames, opts.mu,
                                                             opts.sigma, opts.weight_measure))  # (m_tri, k)
        # virtual-edge targets (Li et al. 2023) of every shape, from the template as in deformation transfer:
        # (k*3, e) with rows (shape, coordinate) -> (e, 3k) with columns (coordinate, shape)
        vc = self.dt.virtual_edge_cols(frame_deltas=dA)
        self.virtual_rows = None if vc is None else np.ascontiguousarray(
            vc.reshape(tpl.n_shapes, 3, -1).transpose(2, 1, 0)).reshape(vc.shape[1], -1)
        del dA
        B0 = problem.target_neutral
        # training frame deltas A_j^T - A_0^B: only the two edge columns enter, and edges are linear
        # in the vertices, so they are the edges of T_j - B_0; built in the triangle-major layout
        E = problem.examples - B0
        self.R = training_rows(E, F)  # (6, m_tri, m)
        # t_j per coordinate, (n, m) each: the reconstruction's output is (n, 3k) with columns
        # (coordinate, shape), so the weight step's Gram matrices are three products of its slices
        self.targets = [np.ascontiguousarray(E[:, :, d].T) for d in range(3)]
        self.target_sq = (E ** 2).sum(axis=(1, 2))
        self.pairs = problem.pair_indices
        self._weight_solver = None  # the CasADi model, built when first needed (ipopt option)
        # anchors keep the template's delta (zero at still vertices), as deformation transfer does;
        # rows (a, 3k) with columns (coordinate, shape)
        av = self.dt.anchor_values()  # (k, a, 3)
        self.anchor_rows = np.ascontiguousarray(av.transpose(1, 2, 0)).reshape(av.shape[1], -1)
        self._transfer_rows = None
        self.free = self._free_shapes()
        self.precompute_seconds = time.perf_counter() - t0

    def reconstruct(self, rows) -> np.ndarray:
        """Vertex deltas from the basis step's frame rows (2, m_tri, 3, k): returns (n, 3k) with
        column ``d k + i`` = coordinate d of shape i."""
        two, m_tri, three, k = rows.shape
        return self.dt.poisson.solve_frame_rows(rows.reshape(2 * m_tri, 3 * k), self.anchor_rows, self.virtual_rows)

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
        """The deformation transfer of every template shape as vertex deltas (n, 3k) (the prior
        A~ reconstructed; computed once and shared with :meth:`subset` copies)."""
        if getattr(self, "_transfer_rows", None) is None:
            k = self.problem.template.n_shapes
            rows = np.ascontiguousarray(self.A_tilde.reshape(3, 2, -1, k).transpose(1, 2, 0, 3))
            self._transfer_rows = self.reconstruct(rows)
        return self._transfer_rows

    def transfer_weights(self) -> np.ndarray:
        """(m, k) weights of the training expressions fitted to the deformation transfer (certified,
        bounds + complementarity, no prior)."""
        G, C = self.gram(self.transfer_rows())
        m, k = self.problem.initial_weights.shape
        return solve_certified(G, C, self.target_sq, np.zeros((m, k)), 0.0, self.pairs).weights

    @property
    def unobserved(self) -> tuple[str, ...]:
        """Names of the shapes no training expression supports (held at their deformation transfer)."""
        names = self.problem.template.names
        return () if self.free is None else tuple(names[i] for i in np.flatnonzero(~self.free))

    def subset(self, indices) -> "BlendshapeGenerator":
        """The generator of the training expressions ``indices`` only, sharing the template's
        precompute (transfer, prior, regulariser weights), for cross-validation."""
        import copy
        import dataclasses

        idx = np.asarray(indices, dtype=np.int64)
        p = self.problem
        g = copy.copy(self)
        g.problem = dataclasses.replace(p, examples=p.examples[idx], initial_weights=p.initial_weights[idx],
                                        example_names=tuple(p.example_names[i] for i in idx))
        g.R = np.ascontiguousarray(self.R[:, :, idx])
        g.targets = [np.ascontiguousarray(T[:, idx]) for T in self.targets]
        g.target_sq = self.target_sq[idx]
        g._weight_solver = None
        g.free = g._free_shapes()
        return g

    def with_options(self, options: "GenerationOptions") -> "BlendshapeGenerator":
        """The same generator with other schedule options (alpha, lambda, iterations, ipopt); the
        precompute does not depend on them."""
        import copy

        g = copy.copy(self)
        g.options = options
        g._weight_solver = None
        g.free = g._free_shapes()
        return g

    @property
    def weight_solver(self) -> WeightSolver:
        """The CasADi/IPOPT model of eq. 5 (built once, on first use)."""
        if self._weight_solver is None:
            self._weight_solver = WeightSolver(self.problem.template.n_shapes, len(self.problem.examples),
                                               self.pairs, self.options.ipopt_options, polish=self.options.polish)
        return self._weight_solver

    def gram(self, Bv):
        """``G = B^T B`` (k, k) and ``C = B^T t_j`` (k, m) from the reconstruction ``Bv`` (n, 3k)."""
        k = self.problem.template.n_shapes
        cols = [Bv[:, d * k:(d + 1) * k] for d in range(3)]  # (n, k) strided views, no copy
        # one BLAS thread: on a busy machine OpenBLAS's threads made B^T T take 0.3 s instead of 9 ms
        with threadpool_limits(1):
            G = sum(B.T @ B for B in cols)
            C = sum((T.T @ B).T for B, T in zip(cols, self.targets))
        return G, C

    def weight_step(self, Bv, lam, X0=None, ipopt: bool = True) -> WeightSolution:
        """Eq. 5 with the blendshapes ``Bv`` (n, 3k) of :meth:`reconstruct`: the CasADi/IPOPT model
        polished by the certified solver (``ipopt``), or the certified solver alone."""
        G, C = self.gram(Bv)
        if ipopt:
            return self.weight_solver.solve(G, C, self.target_sq, self.problem.initial_weights, lam, X0, free=self.free)
        return solve_certified(G, C, self.target_sq, self.problem.initial_weights, lam, self.pairs, free=self.free)

    def _runs_ipopt(self, it: int, total: int) -> bool:
        mode = self.options.ipopt
        return mode == "every" or (mode == "final" and it == total - 1)

    def run(self, progress=None, *, X0=None, schedule=None, cv_progress=None) -> GenerationResult:
        """Alternate the basis and weight steps over the schedule (default: the options').

        ``alpha="auto"`` first chooses the schedule by cross-validation (:mod:`.crossval`);
        ``X0`` (m, k) starts from other weights than the rough ones (a warm start);
        ``schedule`` is a list of (alpha, lambda), one per alternation.
        """
        t_start = time.perf_counter()
        crossval = None
        if schedule is None and self.options.auto_alpha:
            from .crossval import cross_validate_alpha

            crossval = cross_validate_alpha(self, progress=cv_progress)
            self.options = dataclasses.replace(self.options, alpha=crossval.schedule)
        p, opts = self.problem, self.options
        X = p.initial_weights.copy() if X0 is None else np.array(X0, dtype=np.float64)  # (m, k)
        if X.shape != p.initial_weights.shape:
            raise InputError(f"X0: expected shape {p.initial_weights.shape}, found {X.shape}")
        if self.free is not None:
            X[:, ~self.free] = 0.0  # unobserved shapes: the first basis step already leaves them at their transfer
        schedule = opts.schedule() if schedule is None else [(float(a), float(b)) for a, b in schedule]
        workers = opts.threads or _available_cores()
        pool = ThreadPoolExecutor(workers) if workers > 1 else None
        try:
            history, X, deltas = self._iterate(X, schedule, pool, progress)
        finally:
            if pool is not None:
                pool.shutdown()
        rig = Rig(p.target_neutral, p.template.faces, p.template.names, deltas, source="example-based generation")
        residuals = relative_residuals(rig, p.examples, X)
        missing = tuple(n for n, r in zip(p.example_names, residuals) if r > opts.missing_threshold)
        return GenerationResult(rig=rig, weights=X, history=tuple(history), residuals=residuals, missing=missing,
                                example_names=p.example_names, seconds=time.perf_counter() - t_start,
                                precompute_seconds=self.precompute_seconds, options=opts,
                                unobserved=self.unobserved, crossval=crossval)

    def _iterate(self, X, schedule, pool, progress):
        history = []
        for it, (alpha, lam) in enumerate(schedule):
            t0 = time.perf_counter()
            # parallel over blocks of triangles (pool), not inside BLAS
            with threadpool_limits(1):  # one BLAS thread: spinning OpenBLAS threads cost 10x on a busy machine
                rows, e_fit, e_reg = basis_rows(X.T, self.R, self.A_tilde, self.w, alpha, executor=pool)
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
                basis_seconds=t1 - t0, weight_seconds=sol.seconds,
            ))
            if progress is not None:
                progress(history[-1], len(schedule))
        return history, X, self.deltas_of(Bv)


def _available_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def relative_residuals(rig: Rig, examples: np.ndarray, X: np.ndarray) -> np.ndarray:
    """``||B_0 + sum_i x_ij B_i - T_j|| / ||T_j - B_0||`` for every example, (m,)."""
    fit = rig.evaluate(X)
    num = np.linalg.norm((fit - examples).reshape(len(examples), -1), axis=1)
    den = np.linalg.norm((examples - rig.neutral).reshape(len(examples), -1), axis=1)
    return num / np.maximum(den, 1e-300)


def generate_blendshapes(problem: GenerationProblem, options: GenerationOptions | None = None,
                         progress=None) -> GenerationResult:
    """Example-based blendshape generation (Gao et al. 2015): precompute, alternate, return the result."""
    gen = BlendshapeGenerator(problem, options)
    res = gen.run(progress)
    return res


def refit_weights(rig: Rig, expressions: np.ndarray, pairs=(), lam: float = 0.0, prior=None,
                  solver: WeightSolver | None = None) -> WeightSolution:
    """Fit weights of given expressions (m, n, 3) to a rig (eq. 5 with an optional prior)."""
    T = (np.asarray(expressions, float) - rig.neutral).reshape(len(expressions), -1)
    B = rig.deltas.reshape(rig.n_shapes, -1)
    prior = np.zeros((len(T), rig.n_shapes)) if prior is None else prior
    solver = solver or WeightSolver(rig.n_shapes, len(T), pairs)
    return solver.solve(B @ B.T, B @ T.T, (T ** 2).sum(1), prior, lam)


def reproduction_error(rig: Rig, expressions: np.ndarray, pairs=(), solver: WeightSolver | None = None) -> float:
    """How well ``rig`` reproduces expressions (h, n, 3) with refitted weights (bounds, complementarity,
    no prior): ``||B_0 + B x - T|| / ||T - B_0||`` over all of them. Compares rigs fairly, since a
    shape's amplitude and its weight trade off (method.md A)."""
    sol = refit_weights(rig, expressions, pairs, solver=solver)
    return float(np.linalg.norm(rig.evaluate(sol.weights) - expressions) / np.linalg.norm(expressions - rig.neutral))


__all__ = ["GenerationProblem", "GenerationOptions", "GenerationResult", "IterationRecord", "BlendshapeGenerator",
           "generate_blendshapes", "basis_step", "basis_rows", "basis_energies", "regularisation_weights", "relative_residuals",
           "refit_weights", "reproduction_error", "eq5_objective"]
