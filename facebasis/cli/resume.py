"""``facebasis rig --resume RUN_DIR``: add training expressions to a finished run, warm-started
(:func:`facebasis.rigging.enrich.resume_run`; the run's own schedule, pairs and options are kept,
so the flags that would change them are refused)."""

from __future__ import annotations

from pathlib import Path

from .common import virtual_edges_for
from .rig_common import cv_flags_given, progress, warnings


def _refused_flags(args) -> list[str]:
    """Flags a resumed run takes from the run itself (its schedule, pairs and options)."""
    return ([f for f, v in (("--alpha", args.alpha), ("--lambda", args.lam), ("--exclusive", args.exclusive or None))
             if v is not None] + cv_flags_given(args)
            + [f for f, v in (("--ipopt", args.ipopt), ("--unobserved", args.unobserved), ("--support", args.support),
                              ("--virtual-weight", args.virtual_weight), ("--virtual-mode", args.virtual_mode))
               if v is not None])


def resumed_run_inputs(args) -> list:
    """The inputs a run to resume records (its example folders, weight files, template and target):
    ``rig --resume RUN --out X`` reads them, so X must spare them too."""
    if args.resume is None or not (Path(args.resume) / "inputs.json").is_file():
        return []
    from ..rigging.verify import read_inputs

    inputs, ex_dirs, w_files = read_inputs(args.resume)
    src = inputs.get("sources") or {}
    return [*ex_dirs, *w_files, *(Path(args.resume) / src[k] for k in ("template", "target")
                                  if isinstance(src.get(k), str))]


def cmd_resume(args) -> int:
    from ..atomic import atomic_directory
    from ..errors import InputError
    from ..geometry.rig import load_rig_folder
    from ..rigging.enrich import resume_run
    from ..rigging.runs import write_rig_run

    given = _refused_flags(args)
    if given:
        raise InputError(f"--resume: expected the run's own schedule and pairs, found {', '.join(given)} "
                         "(start a new run to change them)")
    ve = None
    if args.virtual_edges is not None:
        if not args.template:
            raise InputError("--virtual-edges with --resume: expected --template as well, found none")
        ve = virtual_edges_for(args, load_rig_folder(args.template, args.neutral, args.exclude))
    run = resume_run(args.resume, args.examples, args.weights, template=args.template,
                     neutral=args.neutral if args.template else None, exclude=args.exclude, target=args.target,
                     iterations=args.iterations, virtual_edges=ve, progress=progress)
    result = run.result
    print(f"resumed {args.resume}: {run.n_previous} training expressions + {run.n_new} new"
          + ("" if run.n_new else " (nothing new: the run's rig and weights are returned unchanged)"))
    with atomic_directory(args.out) as stage:
        write_rig_run(stage, result, run.options, run.problem, list(run.example_dirs), list(run.weight_files),
                      sources=run.sources)
    warnings(result, run.options, list(run.problem.example_names))
    print(f"generated {run.problem.template.n_shapes} blendshapes in {run.seconds:.2f} s -> {args.out}")
    return 0
