"""Incremental enrichment: add training expressions to a finished generation run, warm-started.

``facebasis rig --resume RUN_DIR --examples MORE_DIR --weights MORE.json --out OUT`` (and
:func:`resume_run`) rebuilds the generation problem of RUN_DIR (its template, target, training
expressions and rough weights, recorded in ``inputs.json``; its options, in ``history.json``) with
the new training expressions appended, and warm-starts from the finished run:

1. one weight step (eq. 5, certified) of *all* training expressions against the run's blendshapes
   at its final lambda: the old expressions get back exactly the run's weights (the run ended
   with this very weight step), the new ones get their weights in the run's rig;
2. ``iterations`` alternations (default :data:`RESUME_ITERATIONS`) at the run's final alpha and
   lambda (the end of its schedule), from those weights.

With no new training expressions there is nothing to fit: the run's rig and weights are returned
unchanged (the run already ended at the alternation's answer for its expressions).

References
----------
- Gao Yali, Tan Guanghua, Guo Songrui, Fan Xiaowei. Example-based facial blendshape generation
    (基于样例的面部表情基生成). Computer Engineering 41(3): 258-261, 2015. Equation numbers
    "eq. N" in this module are this paper's unless another paper is named.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, parameter_error
from ..jsonio import read_json
from ..geometry.rig import Rig
from .generation import BlendshapeGenerator
from .problem import GenerationOptions, GenerationProblem, GenerationResult

#: alternations at the final alpha and lambda after the warm start
RESUME_ITERATIONS = 3

#: the parameter the errors about the finished run name (an application writes it by its own name)
_RUN = {"run_dir": "run_dir"}


@dataclass(frozen=True)
class ResumedRun:
    """A resumed run: the result, its problem and options, where its inputs came from."""

    result: GenerationResult
    problem: GenerationProblem
    options: GenerationOptions
    example_dirs: tuple[str, ...]
    weight_files: tuple[str, ...]
    sources: dict
    n_previous: int
    n_new: int
    seconds: float


def _read_history(run: Path):
    """The finished run's options and the (alpha, lambda) of its last alternation (None when it
    recorded none: then the end of its options' schedule is used), from one read of history.json."""
    path = run / "history.json"
    if not path.is_file():
        raise InputError(what=f"{{run_dir}} {run}", expected="history.json (written by `facebasis rig`)",
                         found="no such file", params=_RUN)
    history = read_json(path, "the run's history (JSON)")
    try:
        opts = history["options"]
        known = {f.name for f in dataclasses.fields(GenerationOptions)}
        kw = {k: (tuple(v) if isinstance(v, list) else v) for k, v in opts.items() if k in known}
    except (KeyError, TypeError, AttributeError) as exc:
        raise InputError(f"{path}: expected the run's options under 'options', found an unreadable file ({exc})") from exc
    its = history.get("iterations") or []
    try:
        final_step = (float(its[-1]["alpha"]), float(its[-1]["lam"])) if its else None
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{path}: expected alpha and lam in its last iteration, found {exc}") from exc
    return GenerationOptions(**kw), final_step


def rig_as_rows(rig: Rig) -> np.ndarray:
    """A rig's deltas in the reconstruction layout (n, 3k) of the generator (column ``d k + i``)."""
    return np.ascontiguousarray(rig.deltas.transpose(1, 2, 0)).reshape(rig.n_vertices, -1)


def resume_generation(generator: BlendshapeGenerator, previous_rig: Rig, previous_weights: np.ndarray,
                      n_previous: int, iterations: int = RESUME_ITERATIONS, progress=None,
                      final_step=None) -> GenerationResult:
    """Warm-started generation (module docstring) on ``generator``, whose first ``n_previous``
    training expressions are those of the finished run (rig ``previous_rig``, weights
    ``previous_weights`` (n_previous, k), in the generator's shape order)."""
    t0 = time.perf_counter()
    p, opts = generator.problem, generator.options
    k = p.template.n_shapes
    if previous_rig.n_shapes != k or previous_rig.n_vertices != p.template.n_vertices:
        raise InputError(what="{run_dir}", expected=f"a run of {k} shapes on {p.template.n_vertices} vertices",
                         found=f"{previous_rig.n_shapes} shapes on {previous_rig.n_vertices}", params=_RUN)
    if int(iterations) < 1:
        raise parameter_error("iterations", ">= 1 alternations after the warm start", iterations)
    alpha, lam = opts.schedule()[-1] if final_step is None else final_step
    n_new = len(p.examples) - n_previous
    used = dataclasses.replace(opts, iterations=int(iterations), alpha=(alpha, alpha), lam=(lam, lam))
    if n_new == 0:
        return GenerationResult.from_weights(previous_rig, previous_weights, p, used, history=(),
                                             seconds=time.perf_counter() - t0,
                                             precompute_seconds=generator.precompute_seconds,
                                             unobserved=generator.unobserved)
    gen = generator.with_options(used)
    X = gen.weight_step(rig_as_rows(previous_rig), lam, ipopt=False).weights
    return gen.run(progress, X0=X, schedule=[(alpha, lam)] * int(iterations))


def resume_run(run_dir, more_examples, more_weights, *, template=None, neutral=None, exclude=None, target=None,
               iterations: int | None = None, threads: int | None = None, virtual_edges=None,
               progress=None) -> ResumedRun:
    """Resume the finished run ``run_dir`` with the training expressions of ``more_examples``
    (a folder) and their rough weights ``more_weights`` (JSON), both None for none;
    ``template``/``target`` default to the ones the run recorded. Everything is read and validated
    before any solving: a run corrected for exact contact (``contact.json``) is refused (resuming
    would re-generate its shapes without that guarantee), and a run made with virtual edges needs
    ``virtual_edges`` again."""
    from ..geometry.rig import load_rig_folder, load_target_neutral
    from .examples import load_weights
    from .verify import load_training, read_inputs

    t0 = time.perf_counter()
    run = Path(run_dir)
    if not run.is_dir():
        raise InputError(what="{run_dir}", expected="a finished `facebasis rig` output folder",
                         found=f"no folder {run}", params=_RUN)
    if (run / "contact.json").is_file():
        raise InputError(what=f"{{run_dir}} {run_dir}", expected="a run made without {contact}",
                         found="contact.json (its shapes were corrected for contact; a resumed run re-generates them "
                               "without it and would drop that guarantee); start a new run with {contact}",
                         params={**_RUN, "contact": "contact"})
    inputs, ex_dirs, w_files = read_inputs(run)
    src = dict(inputs.get("sources") or {})
    if src.get("virtual_edges") is True and virtual_edges is None:
        raise InputError(what=f"{{run_dir}} {run_dir}", expected="{virtual_edges} (and {template}) as the run was made "
                         "with virtual edges", found="none (the resumed run would drop their energy)",
                         params={**_RUN, "virtual_edges": "virtual_edges", "template": "template"})
    options, final_step = _read_history(run)
    if threads is not None:
        options = dataclasses.replace(options, threads=threads)

    def resolve(p):
        return str(p if Path(p).is_absolute() else run / p)

    tpl_dir = template or (resolve(src["template"]) if "template" in src else None)
    tgt = target or (resolve(src["target"]) if "target" in src else None)
    if tpl_dir is None or tgt is None:
        raise InputError(what=f"{{run_dir}} {run}", expected="{template} and {target} (the run's inputs.json "
                         "records none)", found="neither" if tpl_dir is None and tgt is None else "only one",
                         params={**_RUN, "template": "template", "target": "target"})
    neutral = neutral or src.get("neutral", "neutral.obj")
    exclude = list(exclude) if exclude else list(src.get("exclude", []))
    tpl = load_rig_folder(tpl_dir, neutral, exclude)
    B0 = load_target_neutral(tgt, tpl)
    if (more_examples is None) != (more_weights is None):
        raise InputError(what="{run_dir}", expected="{more_examples} and {more_weights} together (or neither)",
                         found="only " + ("{more_examples}" if more_weights is None else "{more_weights}"),
                         params={**_RUN, "more_examples": "more_examples", "more_weights": "more_weights"})
    more_dirs = [] if more_examples is None else [Path(more_examples)]
    more_files = [] if more_weights is None else [Path(more_weights)]
    n_prev = len(load_training(ex_dirs, w_files, tpl)[0])
    names, T, X0 = load_training(ex_dirs + more_dirs, w_files + more_files, tpl)
    prev = load_rig_folder(run, "neutral.obj")
    missing = sorted(set(tpl.names) - set(prev.names))
    if missing or prev.n_shapes != tpl.n_shapes:
        raise InputError(what=f"{{run_dir}} {run}", expected=f"the template's {tpl.n_shapes} shapes in the run folder",
                         found=f"{prev.n_shapes} (missing {missing})", params=_RUN)
    prev = Rig(B0, tpl.faces, tpl.names, prev.deltas[prev.index(tpl.names)], source=f"run {run}")
    W = load_weights(run / "weights.json", names[:n_prev], tpl.names)
    problem = GenerationProblem(tpl, B0, T, X0, names, tuple(tuple(p) for p in inputs["exclusive"]), virtual_edges)
    gen = BlendshapeGenerator(problem, options)
    result = resume_generation(gen, prev, W, n_prev, iterations or RESUME_ITERATIONS, progress,
                               final_step=final_step)
    sources = {"template": tpl_dir, "neutral": neutral, "exclude": exclude, "target": tgt}
    return ResumedRun(result, problem, result.options, tuple(map(str, ex_dirs + more_dirs)),
                      tuple(map(str, w_files + more_files)), sources, n_prev, len(names) - n_prev,
                      time.perf_counter() - t0)


__all__ = ["ResumedRun", "resume_run", "resume_generation", "rig_as_rows", "RESUME_ITERATIONS"]
