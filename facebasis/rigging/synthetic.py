"""Synthetic person-specific problems with a known ground truth (for tests, demo and benchmarks).

A *person problem* is a generation problem plus the truth behind it:

* a person-specific rig that differs from the template as a real person's would: per shape a
  strength, a left/right asymmetry, a smooth spatial modulation of the motion (the person's own
  muscle pattern, not a rescaling), and couplings between shapes (:func:`personalise`);
* training expressions: sparse combinations of 2-5 shapes of that rig, covering every shape and
  respecting the exclusive pairs; rough initial weights = truth + uniform noise, clipped to [0, 1];
* held-out expressions made the same way, for measuring how well a rig reproduces unseen
  expressions (weights refitted).

:func:`default_face_problem` builds one on the built-in face (its second person is the truth);
``problems.generation.ict_person_problem`` builds one on the ICT data.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .problem import GenerationProblem
from ..geometry.rig import Rig


@dataclass(frozen=True)
class PersonProblem:
    """A generation problem with its ground truth and held-out expressions."""

    problem: GenerationProblem
    truth: Rig
    true_weights: np.ndarray       # (m, k) of the training expressions
    heldout: np.ndarray            # (h, n, 3)
    heldout_weights: np.ndarray    # (h, k)


def _smooth_field(P: np.ndarray, rng, n_centres=6, width=2.5):
    """A smooth random scalar field on points P (n, 3), mean ~0, amplitude ~1."""
    lo, hi = P.min(0), P.max(0)
    centres = rng.uniform(lo, hi, (n_centres, 3))
    amp = rng.uniform(-1.0, 1.0, n_centres)
    d2 = ((P[:, None, :] - centres[None]) ** 2).sum(-1)
    scale = width * np.linalg.norm(hi - lo) / 10.0
    return (np.exp(-d2 / (2 * scale ** 2)) * amp).sum(1)


def personalise(base: Rig, seed: int = 0, couplings=(), strength=(0.7, 1.4), asym=0.3, modulation=0.35) -> Rig:
    """Make a person-specific rig from ``base`` (deltas already on the person's neutral)."""
    rng = np.random.default_rng(seed)
    P = base.neutral
    x = (P[:, 0] - P[:, 0].mean()) / (np.ptp(P[:, 0]) / 2)
    D = base.deltas.copy()
    out = np.empty_like(D)
    for i in range(base.n_shapes):  # loop over shapes (tens), not triangles
        s = rng.uniform(*strength)
        a = rng.uniform(-asym, asym)
        field = _smooth_field(P, rng)
        mod = s * (1.0 + a * np.tanh(2 * x)) * (1.0 + modulation * np.tanh(field))
        out[i] = D[i] * mod[:, None]
    for a, b, c in couplings:
        ia, ib = base.index([a, b])
        out[ia] = out[ia] + c * out[ib]
    return base.with_neutral(P, out, source=f"person-specific (seed {seed})")


def sparse_weights(rng, n_expr, k, pairs, n_active=(2, 5), cover=True, lo=0.25, hi=1.0):
    """Random sparse weights (n_expr, k) respecting exclusive pairs; with ``cover`` every shape is used."""
    X = np.zeros((n_expr, k))
    order = rng.permutation(k) if cover else np.array([], dtype=int)
    pos = 0
    partner = {}
    for a, b in pairs:
        partner.setdefault(a, []).append(b)
        partner.setdefault(b, []).append(a)
    for j in range(n_expr):
        n = rng.integers(n_active[0], n_active[1] + 1)
        chosen = []
        while pos < len(order) and len(chosen) < n:
            chosen.append(int(order[pos]))
            pos += 1
        while len(chosen) < n:
            chosen.append(int(rng.integers(k)))
        for i in chosen:
            if any(X[j, p] > 0 for p in partner.get(i, [])):
                continue
            X[j, i] = rng.uniform(lo, hi)
    return X


def make_person_problem(template: Rig, truth: Rig, exclusive, n_train=20, n_heldout=20, noise=0.3,
                        seed=0) -> PersonProblem:
    rng = np.random.default_rng(seed + 1000)
    pairs = [tuple(template.index([a, b])) for a, b in exclusive]
    Xt = sparse_weights(rng, n_train, template.n_shapes, pairs)
    # held-out expressions from their own stream: the same for any number of training expressions
    Xh = sparse_weights(np.random.default_rng(seed + 2000), n_heldout, template.n_shapes, pairs, cover=False)
    rough = np.clip(Xt + rng.uniform(-noise, noise, Xt.shape), 0.0, 1.0)
    problem = GenerationProblem(template, truth.neutral, truth.evaluate(Xt), rough,
                                tuple(f"ex{j:02d}" for j in range(n_train)), tuple(exclusive))
    return PersonProblem(problem, truth, Xt, truth.evaluate(Xh), Xh)


def default_face_problem(seed: int = 0, n_train: int = 10, n_heldout: int = 10, noise: float = 0.3) -> PersonProblem:
    from ..defaults.face import EXCLUSIVE_PAIRS, default_person, default_template

    return make_person_problem(default_template(), default_person(), EXCLUSIVE_PAIRS, n_train, n_heldout, noise, seed)
