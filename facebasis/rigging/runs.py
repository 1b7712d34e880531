"""Serialising results (history, options) to plain JSON for reports."""

from __future__ import annotations

import dataclasses

#: the cross-validation curve of ``alpha="auto"`` in a run folder (:mod:`facebasis.rigging.crossval`)
CROSSVAL_FILE = "crossval.json"


def history_to_json(result, options, problem) -> dict:
    """The per-iteration history of a generation run with its options (``alpha="auto"`` resolved
    to the schedule it chose; the request is kept as ``alpha_requested``)."""
    used = getattr(result, "options", None) or options
    opts = dataclasses.asdict(used)
    opts["alpha_requested"] = options.alpha if isinstance(options.alpha, str) else list(options.alpha)
    return {
        "options": opts,
        "unobserved": list(getattr(result, "unobserved", ())),
        "exclusive": [list(p) for p in problem.exclusive],
        "examples": list(problem.example_names),
        "shapes": list(problem.template.names),
        "precompute_seconds": result.precompute_seconds,
        "seconds": result.seconds,
        "all_ipopt_succeeded": result.all_ipopt_succeeded,
        "iterations": [dataclasses.asdict(h) for h in result.history],
    }


def write_rig_run(folder, result, options, problem, examples_dir, weights_file, relative_to=None,
                  sources=None) -> dict:
    """Write a generation run as `facebasis rig` writes it, into an existing (staging) folder:
    ``<shape>.obj`` + ``neutral.obj``, ``weights.json``, ``history.json``, ``residuals.json``,
    ``inputs.json`` (for `facebasis verify` and `facebasis rig --resume`), ``crossval.json``
    (the cross-validation curve, with ``alpha="auto"``) and ``rig.glb``. ``examples_dir`` and
    ``weights_file`` may be lists (a resumed run). Returns the history written."""
    from pathlib import Path

    from ..atomic import atomic_write_json
    from .examples import weights_to_json
    from ..geometry.gltf import write_glb
    from ..geometry.rig import write_shapes
    from .verify import write_inputs

    folder = Path(folder)
    write_shapes(folder, result.rig, layout=getattr(problem.template, "layout", None))
    names = problem.example_names
    atomic_write_json(folder / "weights.json", weights_to_json(result.weights, names, problem.template.names))
    history = history_to_json(result, options, problem)
    atomic_write_json(folder / "history.json", history)
    atomic_write_json(folder / "residuals.json", {
        "threshold": options.missing_threshold,
        "relative_residual": dict(zip(names, map(float, result.residuals))),
        "missing": list(result.missing)})
    # whether the virtual-edge energy shaped the run: a resumed run must be given it again
    sources = dict(sources or {}, virtual_edges=getattr(problem, "virtual_edges", None) is not None)
    write_inputs(folder, examples_dir, weights_file, problem.exclusive, result.final_step[1], relative_to,
                 unobserved=getattr(result, "unobserved", ()), sources=sources)
    cv = getattr(result, "crossval", None)
    if cv is not None:
        atomic_write_json(folder / CROSSVAL_FILE, cv.to_json())
    write_glb(result.rig, folder / "rig.glb", layout=getattr(problem.template, "layout", None))
    return history


def write_problem_inputs(folder, problem):
    """A generation problem's training expressions (``examples/<name>.obj``) and rough weights
    (``weights.json``) as files; returns (examples_dir, weights_file)."""
    from pathlib import Path

    from ..atomic import atomic_write_json
    from .examples import weights_to_json
    from ..geometry.meshio import write_mesh

    folder = Path(folder)
    for name, T in zip(problem.example_names, problem.examples):
        write_mesh(folder / "examples" / f"{name}.obj", T, problem.template.faces)
    atomic_write_json(folder / "weights.json",
                      weights_to_json(problem.initial_weights, problem.example_names, problem.template.names))
    return folder / "examples", folder / "weights.json"
