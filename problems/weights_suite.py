"""A suite of weight-step instances (Gao et al. 2015, eq. 5) for verifying how constraints are handled.

Every instance is one example's problem ``x^T G x - 2 c^T x + const + lam ||x - x~||^2`` on
``[0, 1]^k`` with ``x_a x_b = 0`` for the exclusive pairs: a named one-example
:class:`facebasis.rigging.weightproblem.WeightProblem` (:class:`~facebasis.rigging.weightproblem.WeightInstance`).

``weight_suite("ict")`` (ICT data from ``../shared``; 53 shapes, 12 pairs) or
``weight_suite("default")`` (the built-in face; 15 shapes, 5 pairs) returns, in this order:

* ``natural``: the training examples of two person problems (:mod:`problems.generation`), one
  against the deformation-transfer rig (blendshapes not yet fitted, as in the first alternation)
  and one against the person's true rig, with the rough weights as prior, lambda = 10;
* ``prior-both``: the prior pulls both weights of every pair to 0.9 (lambda 1 .. 1000);
* ``data-both``: the expression is made of both shapes of a pair (plus others), no prior;
* ``near-tie``: the expression is equally well explained by either side of a pair (up to 1e-7);
* ``on-bounds``: the data push weights beyond 1 and below 0;
* ``collinear``: one shape of a pair replaced by a near copy of its partner (Gram matrix
  condition number ~1e8);
* ``closed-form``: tiny hand-made instances whose optimum is known exactly.
"""

from __future__ import annotations

import numpy as np

from facebasis.rigging.certify import WeightInstance
from facebasis.rigging.weightproblem import WeightProblem

ICT_SUITE_PAIRS = (
    ("mouthLeft", "mouthRight"), ("jawLeft", "jawRight"), ("eyeLookIn_L", "eyeLookOut_L"),
    ("eyeLookIn_R", "eyeLookOut_R"), ("eyeLookUp_L", "eyeLookDown_L"), ("eyeLookUp_R", "eyeLookDown_R"),
    ("mouthSmile_L", "mouthFrown_L"), ("mouthSmile_R", "mouthFrown_R"), ("eyeBlink_L", "eyeWide_L"),
    ("eyeBlink_R", "eyeWide_R"), ("browDown_L", "browOuterUp_L"), ("browDown_R", "browOuterUp_R"),
)


def _gram_instances(kind, B, T, priors, lam, pairs, tag):
    """Instances for expressions T (m, 3n) against blendshapes B (k, 3n)."""
    G = B @ B.T
    C = B @ T.T
    problem = WeightProblem(G, C.T, [float(t @ t) for t in T], pairs, priors, float(lam))  # checked once
    return [WeightInstance(f"{kind}/{tag}/{j:02d}", kind, problem.example(j)) for j in range(len(T))]


def _adversarial(B, pairs, rng, tag):
    k = len(B)
    G = B @ B.T
    out = []
    P = np.asarray(pairs)

    def inst(kind, i, t, prior, lam, Bx=B, Gx=G):
        out.append(WeightInstance.make(f"{kind}/{tag}/{i}", kind, Gx, Bx @ t, float(t @ t), prior, float(lam), P))

    # the prior pulls both weights of every pair to 0.9
    for i, lam in enumerate((1.0, 10.0, 100.0, 1000.0)):
        x = np.zeros(k)
        x[rng.choice(k, 3, replace=False)] = rng.uniform(0.3, 0.8, 3)
        prior = np.zeros(k)
        prior[P.ravel()] = 0.9
        inst("prior-both", i, x @ B, prior, lam)
    # the data are made of both shapes of a pair
    for i in range(4):
        a, b = P[i % len(P)]
        x = np.zeros(k)
        x[[a, b]] = rng.uniform(0.5, 0.9, 2)
        others = np.setdiff1d(np.arange(k), P.ravel())
        x[rng.choice(others, 2, replace=False)] = rng.uniform(0.2, 0.6, 2)
        inst("data-both", i, x @ B, np.zeros(k), 0.01)
    # either side of a pair explains the data equally well: t = r (u_a + u_b), u = unit shapes
    for i in range(4):
        a, b = P[(i + 1) % len(P)]
        ua, ub = B[a] / np.linalg.norm(B[a]), B[b] / np.linalg.norm(B[b])
        r = 0.3 * min(np.linalg.norm(B[a]), np.linalg.norm(B[b]))
        t = r * (ua + (1.0 + 1e-7 * (i - 1.5)) * ub)
        inst("near-tie", i, t, np.zeros(k), 0.0)
    # weights pushed onto and beyond the bounds
    for i in range(4):
        x = np.zeros(k)
        idx = rng.choice(k, 4, replace=False)
        x[idx] = [1.6, -0.8, 1.0, 0.0]
        inst("on-bounds", i, x @ B, np.clip(x, 0, 1), 1.0 if i % 2 else 0.0)
    # nearly collinear: shape b of a pair is a near copy of a
    for i in range(4):
        a, b = P[(i + 2) % len(P)]
        Bc = B.copy()
        Bc[b] = B[a] + 1e-4 * np.linalg.norm(B[a]) / np.sqrt(B.shape[1]) * rng.standard_normal(B.shape[1])
        x = np.zeros(k)
        x[a] = 0.6
        x[rng.choice(np.setdiff1d(np.arange(k), [a, b]), 2, replace=False)] = 0.4
        inst("collinear", i, x @ Bc, np.zeros(k), 0.0, Bc, Bc @ Bc.T)
    return out


def closed_form_instances() -> list[WeightInstance]:
    """Tiny instances with optimum known by hand (``known_objective``)."""
    I2 = np.eye(2)
    P01 = np.array([[0, 1]])
    cases = [
        # G = I, c = (0.6, 0.8): branch x0 = 0 gives x1 = 0.8, f = 1 - 0.64
        ("pick-larger", I2, [0.6, 0.8], 1.0, [0, 0], 0.0, P01, 0.36),
        # prior 0.9 on both, lam 1: per weight min of x^2 + (x - 0.9)^2 is x = 0.45; one weight must be 0
        ("prior-both", I2, [0, 0], 0.0, [0.9, 0.9], 1.0, P01, 2 * 0.45 ** 2 + 0.81),
        # c = (2, 3) beyond the upper bound: x = (0, 1), f = 1 - 6
        ("upper-bound", I2, [2, 3], 0.0, [0, 0], 0.0, P01, -5.0),
        # chain (0,1), (1,2): {x0, x2} gives -(0.25 + 0.04) = -0.29, {x1} gives -0.49
        ("chain", np.eye(3), [0.5, 0.7, 0.2], 0.0, [0, 0, 0], 0.0, np.array([[0, 1], [1, 2]]), -0.49),
        # exact tie: G = diag(1, 4), c = (0.5, 1): either branch gives -0.25
        ("exact-tie", np.diag([1.0, 4.0]), [0.5, 1.0], 0.0, [0, 0], 0.0, P01, -0.25),
        # no pairs: x = clip(c) = (0, 0.3, 1, 0.5), f = -0.09 - 3 - 0.25
        ("box-only", np.eye(4), [-1, 0.3, 2, 0.5], 0.0, [0, 0, 0, 0], 0.0, np.zeros((0, 2), int), -3.34),
    ]
    return [WeightInstance.make(f"closed-form/{n}", "closed-form", np.asarray(G, float), np.asarray(c, float),
                                float(k0), np.asarray(p, float), float(lam), P, known)
            for n, G, c, k0, p, lam, P, known in cases]


def weight_suite(source: str = "ict", seed: int = 0) -> list[WeightInstance]:
    """The suite (see module docstring); ``source`` is ``"ict"`` (needs ``../shared``) or ``"default"``."""
    from facebasis.geometry.transfer import deformation_transfer

    if source == "ict":
        from problems.generation import ict_person_problem

        problems = [ict_person_problem(seed=seed + s) for s in (0, 1)]
        names = ICT_SUITE_PAIRS
    elif source == "default":
        from facebasis.defaults.face import EXCLUSIVE_PAIRS
        from facebasis.rigging.synthetic import default_face_problem

        problems = [default_face_problem(seed=seed + s, n_train=20) for s in (0, 1)]
        names = EXCLUSIVE_PAIRS
    else:
        from facebasis.errors import InputError

        raise InputError(f"suite source: expected 'ict' or 'default', found {source!r}")
    rng = np.random.default_rng(seed + 77)
    out = []
    for s, pp in enumerate(problems):
        p = pp.problem
        pairs = np.array([p.template.index(list(ab)) for ab in names])
        rig = deformation_transfer(p.template, p.target_neutral) if s == 0 else pp.truth
        B = rig.deltas.reshape(rig.n_shapes, -1)
        T = (p.examples - p.target_neutral).reshape(len(p.examples), -1)
        out += _gram_instances("natural", B, T, p.initial_weights, 10.0, pairs, "dt" if s == 0 else "truth")
        if s == 0:
            adversarial = _adversarial(B, pairs, rng, source)
    return out + adversarial + closed_form_instances()


__all__ = ["ICT_SUITE_PAIRS", "weight_suite", "closed_form_instances"]
