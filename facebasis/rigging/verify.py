"""``facebasis verify RUN_DIR``: re-solve a rig run's weight problems to certified optima.

A ``facebasis rig`` output folder holds the generated blendshapes (``neutral.obj`` + one OBJ per
shape), the solved weights (``weights.json``) and ``inputs.json``, which records where the
training expressions and rough weights came from, the exclusive pairs and the final lambda. The
last weight step of the run solved eq. 5 of Gao et al. 2015 for exactly these blendshapes, so every
stored weight vector should be the global optimum of its example's problem

    min_x ||B x - t_j||^2 + lambda ||x - x~_j||^2,   0 <= x <= 1,   x_a x_b = 0.

This module rebuilds the :class:`~facebasis.rigging.weightproblem.WeightProblem` from the meshes on
disk, solves each example with :class:`facebasis.rigging.certify.CertifiedWeightSolver`, and reports
per example the objective gap of the stored weights, their complementarity and bound residuals (from
the problem) and a verdict.

References
----------
- Gao Yali, Tan Guanghua, Guo Songrui, Fan Xiaowei. Example-based facial blendshape generation
    (基于样例的面部表情基生成). Computer Engineering 41(3): 258-261, 2015. Equation numbers
    "eq. N" in this module are this paper's unless another paper is named.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .certify import CertifiedWeightSolver
from .weightproblem import WeightProblem, pair_products
from ..errors import InputError
from ..jsonio import read_json

INPUTS_FILE = "inputs.json"


@dataclass(frozen=True)
class ExampleVerdict:
    name: str
    stored_objective: float
    certified_objective: float
    relative_gap: float        # (stored - certified) / max(1, |certified|)
    max_complementarity: float
    max_bound_violation: float
    nodes: int
    ok: bool


@dataclass(frozen=True)
class PairCheck:
    """The largest complementarity product ``max_j |x_ja x_jb|`` of the stored weights over one pair
    the user named at verify time, whether or not the run was solved with it."""
    a: str
    b: str
    max_product: float
    worst_example: str
    in_run: bool               # the run's own inputs.json lists this pair
    ok: bool                   # max_product <= the residual tolerance


@dataclass(frozen=True)
class VerifyReport:
    run_dir: str
    lam: float
    tolerance: float
    examples: tuple[ExampleVerdict, ...]
    pairs: tuple[tuple[str, str], ...] = ()       # the exclusive pairs the run was solved with
    checked: tuple[PairCheck, ...] = ()           # pairs named at verify time

    @property
    def ok(self) -> bool:
        return all(e.ok for e in self.examples) and all(c.ok for c in self.checked)

    def table(self) -> str:
        head = f"{'example':16s} {'stored':>14s} {'certified':>14s} {'rel. gap':>10s} {'max|xa xb|':>10s} " \
               f"{'bound viol.':>11s} {'nodes':>6s}  verdict"
        rows = [head]
        for e in self.examples:
            rows.append(f"{e.name:16s} {e.stored_objective:14.8g} {e.certified_objective:14.8g} {e.relative_gap:10.2e} "
                        f"{e.max_complementarity:10.1e} {e.max_bound_violation:11.1e} {e.nodes:6d}  "
                        f"{'optimal' if e.ok else 'NOT OPTIMAL'}")
        return "\n".join(rows)


def write_inputs(stage: Path, examples_dir, weights_file, exclusive, final_lambda: float, relative_to=None,
                 unobserved=(), sources=None) -> None:
    """Record a run's inputs (``inputs.json``) so that :func:`verify_run` can re-solve it later.

    ``examples_dir`` / ``weights_file``: one path each, or lists of paths (a resumed run's training
    expressions come from several folders). ``unobserved``: shapes whose weights the run held at 0.
    ``sources``: optional {"template", "neutral", "exclude", "target"} of the run (for ``--resume``).
    Paths are stored absolute, or relative to ``relative_to`` (the run folder's final location)
    when given, so a self-contained folder can be moved.
    """
    from ..atomic import atomic_write_json

    def rel(p):
        if isinstance(p, (list, tuple)):
            return [rel(q) for q in p]
        p = Path(p).resolve()
        return os.path.relpath(p, Path(relative_to).resolve()) if relative_to is not None else str(p)

    obj = {"examples": rel(examples_dir), "weights": rel(weights_file),
           "exclusive": [list(p) for p in exclusive], "final_lambda": float(final_lambda),
           "unobserved": list(unobserved)}
    if sources:
        obj["sources"] = {k: (rel(v) if k in ("template", "target") else v) for k, v in sources.items()}
    atomic_write_json(stage / INPUTS_FILE, obj)


def read_inputs(run_dir):
    """``inputs.json`` of a run: (inputs dict, example folders, weight files) with paths resolved
    against the run folder; raises :class:`InputError` naming what is missing."""
    run = Path(run_dir)
    path = run / INPUTS_FILE
    if not path.is_file():
        raise InputError(f"{run}: expected {INPUTS_FILE} (written by `facebasis rig`), found no such file")
    try:
        inputs = read_json(path, "keys examples, weights, exclusive, final_lambda (the run's inputs as JSON)")
        ex, wf = inputs["examples"], inputs["weights"]
        inputs["exclusive"], inputs["final_lambda"] = inputs["exclusive"], float(inputs["final_lambda"])
        ex, wf = ([ex] if isinstance(ex, str) else list(ex)), ([wf] if isinstance(wf, str) else list(wf))
        if len(ex) != len(wf):
            raise ValueError(f"{len(ex)} example folders, {len(wf)} weight files")
        pairs = inputs["exclusive"]
        if not isinstance(pairs, list) or not all(isinstance(p, list) and len(p) == 2
                                                  and all(isinstance(n, str) for n in p) for p in pairs):
            raise ValueError(f"'exclusive' must be a list of [SHAPE_A, SHAPE_B], found {pairs!r:.80}")
        held = inputs.get("unobserved", [])
        if not isinstance(held, list) or not all(isinstance(n, str) for n in held):
            raise ValueError(f"'unobserved' must be a list of shape names, found {held!r:.80}")
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{path}: expected keys examples, weights, exclusive, final_lambda, found an unreadable "
                         f"file ({exc})") from exc

    def resolve(p):
        return Path(p) if Path(p).is_absolute() else run / p

    return inputs, [resolve(p) for p in ex], [resolve(p) for p in wf]


def load_training(examples_dirs, weight_files, template):
    """Training expressions and rough weights of several (folder, weights file) pairs, in order;
    names must be unique across the folders. Returns (names, examples (m, n, 3), rough (m, k))."""
    from .examples import load_examples, load_weights

    names, T, X = [], [], []
    for d, w in zip(examples_dirs, weight_files):
        n, t = load_examples(d, template)
        clash = sorted(set(n) & set(names))
        if clash:
            raise InputError(f"examples folder {d}: expected new training expression names, found names already "
                             f"used: {clash}")
        names += n
        T.append(t)
        X.append(load_weights(w, n, template.names))
    return tuple(names), np.concatenate(T), np.concatenate(X)


def verify_run(run_dir, tolerance: float = 1e-6, residual_tolerance: float = 1e-8,
               check_pairs=()) -> VerifyReport:
    """Certify the stored weights of a ``facebasis rig`` output folder (see module docstring).

    ``check_pairs``: extra ``(shape_a, shape_b)`` pairs; for each, the report gives the largest
    product ``|x_a x_b|`` of the stored weights over all examples (:class:`PairCheck`), so a user
    can confirm that a constraint they meant to impose holds, whatever the run recorded."""
    from .examples import load_weights, parse_pairs
    from ..geometry.rig import load_rig_folder

    run = Path(run_dir)
    path = run / INPUTS_FILE
    inputs, example_dirs, weight_files = read_inputs(run)
    exclusive, lam = inputs["exclusive"], inputs["final_lambda"]
    rig = load_rig_folder(run, "neutral.obj")
    stored_names = {s for row in read_json(run / "weights.json", "the run's weights JSON").values()
                    if isinstance(row, dict) for s in row}
    missing = sorted(stored_names - set(rig.names))
    if missing:  # a shape file removed from the run, not a fault of the inputs
        raise InputError(f"{run}: expected a mesh for every shape its weights.json names, found none for {missing} "
                         f"(missing {', '.join(m + '.obj' for m in missing[:3])}?)")
    names, T, prior = load_training(example_dirs, weight_files, rig)
    stored = load_weights(run / "weights.json", names, rig.names)
    held = [str(s) for s in inputs.get("unobserved", [])]
    free = np.ones(rig.n_shapes, bool)
    if held:
        free[rig.index(held, what=f"{path}: unobserved shapes")] = False
    run_pairs = parse_pairs([f"{a}:{b}" for a, b in exclusive])
    pairs = np.array([rig.index([a, b], what=f"{path}: exclusive pair {a}:{b}") for a, b in run_pairs],
                     dtype=np.int64).reshape(-1, 2)
    extra = tuple((str(a), str(b)) for a, b in check_pairs)
    for a, b in extra:
        rig.index([a, b], what=f"{{exclusive}} {a}:{b}", params={"exclusive": "exclusive"})
        if a == b:
            raise InputError(what=f"{{exclusive}} {a}:{b}", expected="two different shapes", found="one twice",
                             params={"exclusive": "exclusive"})
    problem = WeightProblem.from_rig(rig, T, pairs, prior, lam)
    # shapes the run held at 0 (no support in the examples) stay at 0: certify over the others
    sub, idx = problem.restrict(free)
    certifier = CertifiedWeightSolver(sub)
    f_stored, comp, bound = problem.objective(stored), problem.complementarity(stored), problem.bounds(stored)
    if held:  # a shape the run held at 0 must be 0 in the stored weights: count a breach as a bound residual
        bound = np.maximum(bound, np.abs(stored[:, ~free]).max(axis=1))
    out = []
    for j, name in enumerate(names):
        cs = certifier.solve_example(j, start=stored[j, idx])
        gap = (f_stored[j] - cs.objective) / max(1.0, abs(cs.objective))
        # |gap|: a stored objective below the certified global optimum is not a better answer but the
        # answer of another problem (another prior, pairs or held shapes than inputs.json records)
        ok = abs(gap) <= tolerance and comp[j] <= residual_tolerance and bound[j] <= residual_tolerance
        out.append(ExampleVerdict(name, float(f_stored[j]), cs.objective, float(gap), float(comp[j]), float(bound[j]),
                                  cs.nodes, bool(ok)))
    checked = []
    run_keys = {frozenset(p) for p in run_pairs}
    for a, b in extra:
        prod = pair_products(stored, np.array([rig.index([a, b])]))
        worst = int(np.argmax(prod))
        checked.append(PairCheck(a, b, float(prod[worst]), names[worst], frozenset((a, b)) in run_keys,
                                 bool(prod[worst] <= residual_tolerance)))
    return VerifyReport(str(run), lam, tolerance, tuple(out), run_pairs, tuple(checked))


__all__ = ["ExampleVerdict", "PairCheck", "VerifyReport", "verify_run", "write_inputs", "read_inputs",
           "load_training", "INPUTS_FILE"]
