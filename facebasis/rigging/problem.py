"""The example-based generation problem, its options and its result (Gao, Tan, Guo, Fan 2015).

:class:`GenerationProblem` holds the template rig, the target neutral, the training expressions,
their rough weights and the exclusive pairs, all validated when it is made;
:class:`GenerationOptions` the alpha/lambda schedule (eq. 4-5), the regulariser's parameters
(eq. 3) and the solver choices; :class:`IterationRecord` and :class:`GenerationResult` what a run
returns. The steps are in :mod:`facebasis.rigging.basis` and :mod:`facebasis.rigging.weights`,
the alternation in :mod:`facebasis.rigging.generation`.

References
----------
- Gao Yali, Tan Guanghua, Guo Songrui, Fan Xiaowei. Example-based facial blendshape generation
    (基于样例的面部表情基生成). Computer Engineering 41(3): 258-261, 2015. Equation numbers
    "eq. N" in this module are this paper's unless another paper is named.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np


from ..errors import InputError, parameter_error
from ..geometry.mesh import validate_vertices
from ..geometry.rig import Rig


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

    def pairs_used_together(self) -> list[tuple[tuple[str, str], list[str]]]:
        """Exclusive pairs whose two shapes both have rough weights > 0 in some examples, with the
        names of those examples (the weight step keeps only one of the two in each)."""
        out = []
        for pair, (ia, ib) in zip(self.exclusive, self.pair_indices):
            both = [n for n, row in zip(self.example_names, self.initial_weights) if row[ia] > 0 and row[ib] > 0]
            if both:
                out.append((pair, both))
        return out


#: what a shape that no training expression activates becomes: its deformation transfer (its
#: weights held at 0), or fitted like every other shape
UNOBSERVED_MODES = ("transfer", "fit")

#: when the weight step runs the CasADi/IPOPT model of eq. 5 (its answer seeds the certified
#: polish); the other alternations use the certified solver alone, which returns the same optimum
IPOPT_MODES = ("every", "final", "never")

#: how ``alpha="auto"`` makes and scores its candidates (:mod:`facebasis.rigging.crossval`)
CV_CANDIDATES = ("coarse", "deletion", "path", "cold", "both")


@dataclass(frozen=True)
class GenerationOptions:
    """Schedule and parameters (defaults: the paper's).

    alpha and lambda go geometrically from their first to their last value over the iterations.
    ``alpha="auto"`` chooses the alpha schedule ``(5 a, a)`` (the paper's ratio) by k-fold
    cross-validation over the training expressions (:mod:`facebasis.rigging.crossval`; ``cv_folds``,
    ``cv_grid`` the candidate final alphas, ``cv_candidates`` ``"coarse"`` (default),
    ``"deletion"``, ``"path"``, ``"cold"`` or ``"both"``, ``cv_chain_iterations``); the final run
    is made the way the chosen candidate was (with ``"path"``: the warm-started path down to it).

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
    IPOPT's answer never improves on the certified optimum (it can only seed the tree), so it adds
    no accuracy; ``"final"`` keeps it as an independent cross-check whose status and raw objective
    the history records (the documentation's generation page quotes the formulation study).
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
    cv_candidates: str = "coarse"

    def __post_init__(self):
        # the errors name their field (structured: an application writes it by its own name for it)
        if int(self.iterations) < 1:
            raise parameter_error("iterations", ">= 1", self.iterations)
        auto = isinstance(self.alpha, str)
        if auto and self.alpha != "auto":
            raise parameter_error("alpha", "two numbers (first, last) or 'auto'", repr(self.alpha))
        for name in ("lam",) if auto else ("alpha", "lam"):
            v = tuple(float(a) for a in getattr(self, name))
            if len(v) != 2 or not all(np.isfinite(v)):
                raise parameter_error(name, "two finite values (first, last)", getattr(self, name))
            object.__setattr__(self, name, v)
        if not auto and min(self.alpha) <= 0:
            raise parameter_error("alpha", "values > 0", self.alpha)
        if min(self.lam) < 0:
            raise parameter_error("lam", "values >= 0", self.lam, label="lambda")
        if self.weight_measure not in ("relative", "absolute"):
            raise InputError(f"weight_measure: expected 'relative' or 'absolute', found {self.weight_measure!r}")
        if self.threads is not None and int(self.threads) < 1:
            raise InputError(f"threads: expected >= 1 or None (all cores), found {self.threads}")
        if not (0 < self.mu < 1) or self.sigma < 0:
            raise InputError(f"mu, sigma: expected 0 < mu < 1 and sigma >= 0, found {self.mu}, {self.sigma}")
        if self.ipopt not in IPOPT_MODES:
            raise parameter_error("ipopt", f"one of {', '.join(IPOPT_MODES)}", repr(self.ipopt))
        if self.unobserved not in UNOBSERVED_MODES:
            raise parameter_error("unobserved", f"one of {', '.join(UNOBSERVED_MODES)}", repr(self.unobserved))
        if not (np.isfinite(self.support) and 0.0 <= self.support <= 1.0):
            raise parameter_error("support", "a rough weight in [0, 1]", self.support)
        if int(self.cv_folds) < 2:
            raise parameter_error("cv_folds", ">= 2", self.cv_folds)
        if int(self.cv_chain_iterations) < 1:
            raise parameter_error("cv_chain_iterations", ">= 1", self.cv_chain_iterations)
        if self.cv_candidates not in CV_CANDIDATES:
            raise parameter_error("cv_candidates", f"one of {', '.join(CV_CANDIDATES)}", repr(self.cv_candidates))
        grid = tuple(float(a) for a in self.cv_grid)
        if any(not np.isfinite(a) or a <= 0 for a in grid):
            raise parameter_error("cv_grid", "final alphas > 0", self.cv_grid)
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
    #: the prior part of ``weight_objective``, ``lambda sum_j ||x_j - x~_j||^2`` (eq. 5's second term);
    #: ``weight_objective - weight_prior`` is the fit of the examples, which does not scale with lambda
    weight_prior: float = float("nan")


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
    contact : the :class:`~facebasis.contact.exact.ContactResult` of ``contact=True``, else None
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
    contact: object | None = None

    @classmethod
    def from_weights(cls, rig: Rig, weights: np.ndarray, problem: GenerationProblem,
                     options: "GenerationOptions | None", **fields) -> "GenerationResult":
        """The one constructor of a run's result: ``rig`` and the training weights (m, k) of
        ``problem``'s expressions, with the relative residuals (:func:`relative_residuals`) and the
        expressions above ``options.missing_threshold`` computed here; ``fields`` are the other
        attributes (``history``, ``seconds``, ``precompute_seconds``, ``unobserved``, ...)."""
        weights = np.asarray(weights, np.float64)
        residuals = relative_residuals(rig, problem.examples, weights)
        threshold = options.missing_threshold if options is not None else np.inf
        missing = tuple(n for n, r in zip(problem.example_names, residuals) if r > threshold)
        fields.setdefault("history", ())
        fields.setdefault("seconds", 0.0)
        fields.setdefault("precompute_seconds", 0.0)
        return cls(rig=rig, weights=weights, residuals=residuals, missing=missing,
                   example_names=problem.example_names, options=options, **fields)

    def with_weights(self, rig: Rig, weights: np.ndarray, problem: GenerationProblem) -> "GenerationResult":
        """This result with another rig and weights of ``problem``'s expressions (e.g. after exact
        contact); residuals and missing expressions are computed again, the rest is kept."""
        keep = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                if f.name not in ("rig", "weights", "residuals", "missing", "example_names", "options")}
        return GenerationResult.from_weights(rig, weights, problem, self.options, **keep)

    @property
    def final_step(self) -> tuple[float, float]:
        """(alpha, lambda) of the last alternation run: the lambda the stored weights were solved at
        (with ``alpha="auto"`` the run follows the cross-validated path, which need not end where
        ``options.schedule()`` does). Without alternations (a resume with no new examples), the end
        of the options' schedule."""
        if self.history:
            return float(self.history[-1].alpha), float(self.history[-1].lam)
        if self.options is None:
            raise InputError("generation result: expected its options or an alternation to read the final "
                             "(alpha, lambda) from, found neither")
        a, lam = self.options.schedule()[-1]
        return float(a), float(lam)

    @property
    def all_ipopt_succeeded(self) -> bool:
        return all(h.ipopt_success for h in self.history)


def relative_residuals(rig: Rig, examples: np.ndarray, X: np.ndarray) -> np.ndarray:
    """``||B_0 + sum_i x_ij B_i - T_j|| / ||T_j - B_0||`` for every example, (m,)."""
    fit = rig.evaluate(X)
    num = np.linalg.norm((fit - examples).reshape(len(examples), -1), axis=1)
    den = np.linalg.norm((examples - rig.neutral).reshape(len(examples), -1), axis=1)
    return num / np.maximum(den, 1e-300)


__all__ = ["GenerationProblem", "GenerationOptions", "GenerationResult", "IterationRecord", "relative_residuals",
           "IPOPT_MODES", "UNOBSERVED_MODES", "CV_CANDIDATES"]
