"""``facebasis rig``: example-based blendshape generation (Gao, Tan, Guo, Fan 2015) with certified
weights; ``rig --resume RUN_DIR`` continues a finished run (:mod:`facebasis.cli.resume`).

The command parses, calls the library and prints: the options' checks, the cross-validation's
and the problem's are the library's (their errors name the library's parameters, which the CLI
writes as its flags, :data:`facebasis.cli.common.FLAGS`).
"""

from __future__ import annotations

import sys

from .common import (add_rig_folder_args, add_virtual_edge_args, check_virtual_edge_args, describe_pairs, once,
                     pair_of_floats, virtual_edges_for, warn_rig_folder)
from .exact_contact import (add_contact_args, check_contact_target, contact_flags_given, contact_request, contact_verdict,
                            write_contact)
from .outputs import Outputs
from .resume import cmd_resume, resumed_run_inputs
from .rig_common import cv_flags_given, cv_progress, progress, warnings


def alpha_option(text):
    """``--alpha``: ``auto`` or FIRST,LAST."""
    return "auto" if str(text).strip().lower() == "auto" else pair_of_floats(text, "--alpha")


def cv_grid(values) -> tuple[float, ...]:
    """``--cv-grid`` values (several after one flag, comma-separated or repeated): candidate final alphas."""
    from ..errors import InputError

    out = []
    for v in values or ():
        for part in str(v).split(","):
            try:
                a = float(part)
            except ValueError:
                a = float("nan")
            if not (a > 0 and a < float("inf")):
                raise InputError(f"--cv-grid: expected final alphas > 0, found {part!r}")
            out.append(a)
    return tuple(once(out, "--cv-grid"))


def _schedule_text(pair) -> str:
    return ",".join(f"{a:g}" for a in pair)


def rig_options(args, virtual_mode: str):
    """:class:`~facebasis.rigging.problem.GenerationOptions` of the flags (defaults: the options').
    The options check themselves; their errors name their fields, written as flags by the CLI."""
    from ..errors import InputError
    from ..rigging.problem import GenerationOptions

    defaults = GenerationOptions()
    grid = cv_grid(args.cv_grid)
    alpha = _schedule_text(defaults.alpha) if args.alpha is None else args.alpha
    cv_given = cv_flags_given(args)
    if cv_given and str(alpha).strip().lower() != "auto":
        raise InputError(f"{', '.join(cv_given)}: expected --alpha auto as well (cross-validation chooses "
                         f"alpha only then), found --alpha {alpha}")

    def pick(value, default):
        return default if value is None else value

    return GenerationOptions(
        iterations=pick(args.iterations, defaults.iterations), alpha=alpha_option(alpha),
        lam=pair_of_floats(pick(args.lam, _schedule_text(defaults.lam)), "--lambda"),
        virtual_weight=args.virtual_weight, virtual_mode=virtual_mode,
        ipopt=pick(args.ipopt, defaults.ipopt), unobserved=pick(args.unobserved, defaults.unobserved),
        support=pick(args.support, defaults.support), cv_folds=pick(args.cv_folds, defaults.cv_folds),
        cv_grid=grid, cv_candidates=pick(args.cv_candidates, defaults.cv_candidates))


def _say_inputs(args, problem, options) -> None:
    """What the run is made of, the notes on one-number schedules and the pairs the rough weights use together."""
    template, names = problem.template, problem.example_names
    print(f"template {template.n_shapes} shapes, {template.n_vertices} vertices; {len(names)} training "
          f"expressions; {describe_pairs(problem.exclusive, len(args.exclusive))}")
    for text, name in ((args.alpha, "--alpha"), (args.lam, "--lambda")):
        if text is not None and str(text).strip().lower() != "auto" and "," not in str(text):
            print(f"note: {name} {text} is one number: held constant over all iterations (FIRST,LAST gives a schedule)")
    for (a, b), both in problem.pairs_used_together():
        print(f"warning: exclusive pair {a}:{b}: the rough weights of {len(both)} example(s) use both shapes "
              f"({', '.join(both[:5])}{', ...' if len(both) > 5 else ''}); the weight step will keep only one "
              "of them in each", file=sys.stderr)


def cmd_rig(args) -> int:
    from ..errors import InputError

    # the checks of a fresh and a resumed run alike, before anything is read
    virtual_mode = check_virtual_edge_args(args, allowed_without_edges=args.resume is not None)
    if args.support is not None and args.unobserved == "fit":
        raise InputError(f"--support {args.support:g}: expected --unobserved transfer (the support threshold "
                         "only decides which shapes keep their transfer), found --unobserved fit")
    if args.resume is not None:
        if contact_flags_given(args):
            raise InputError("--contact with --resume: expected a fresh run (contact is not stored in a run "
                             "to resume), found --resume")
        return cmd_resume(args)
    absent = [f for f, v in (("--template", args.template), ("--target", args.target),
                             ("--examples", args.examples), ("--weights", args.weights)) if v is None]
    if absent:
        raise InputError(f"rig: expected {', '.join(absent)} (or --resume RUN_DIR), found none")
    return _fresh_run(args, virtual_mode)


def _fresh_run(args, virtual_mode: str) -> int:
    from ..atomic import atomic_directory
    from ..geometry.rig import load_rig_folder, load_target_neutral
    from ..rigging.heldout import check_folds
    from ..rigging.examples import load_examples, load_weights, parse_pairs
    from ..rigging.generation import BlendshapeGenerator
    from ..rigging.problem import GenerationProblem
    from ..rigging.runs import write_rig_run

    # everything is validated before any solving starts
    contact = contact_request(args)
    options = rig_options(args, virtual_mode)
    template = load_rig_folder(args.template, args.neutral, args.exclude)
    warn_rig_folder(template)
    target = load_target_neutral(args.target, template)
    if contact is not None:
        check_contact_target(contact, template, target, args.target)
    names, examples = load_examples(args.examples, template)
    X0 = load_weights(args.weights, names, template.names)
    ve = virtual_edges_for(args, template)
    problem = GenerationProblem(template, target, examples, X0, names, parse_pairs(args.exclusive), ve)
    if options.auto_alpha:
        check_folds(len(names), options.cv_folds)
    _say_inputs(args, problem, options)
    gen = BlendshapeGenerator(problem, options)
    if gen.unobserved:
        print(f"{len(gen.unobserved)} shape(s) without support in the examples (rough weights < {options.support:g}) "
              f"keep their deformation transfer: {', '.join(gen.unobserved)}")
    result = gen.run(progress, cv_progress=cv_progress if options.auto_alpha else None)
    cv = result.crossval
    if cv is not None:
        print(f"--alpha auto: {len(cv.grid)} candidates x {len(cv.fold_errors)} folds in {cv.seconds:.1f} s; "
              f"chose alpha {cv.schedule[0]:g} -> {cv.schedule[1]:g} (held-out error {cv.best_error:.4f})")
    found = None
    if contact is not None:
        from ..rigging.contactstep import contact_generation

        found, result = contact_generation(gen, result, list(contact.exclude), contact.allow_target_pairs)
    sources = {"template": args.template, "neutral": args.neutral, "exclude": list(args.exclude),
               "target": args.target}
    with atomic_directory(args.out) as stage:
        write_rig_run(stage, result, options, problem, args.examples, args.weights, sources=sources)
        if found is not None:
            write_contact(stage, found)
    warnings(result, options, list(names))
    print(f"generated {template.n_shapes} blendshapes in {result.seconds + result.precompute_seconds:.2f} s -> {args.out}")
    if found is not None:
        print(found.table())
        print(f"exact contact: {found.seconds['total']:.2f} s")
        return contact_verdict(found, "generated", list(contact.exclude))
    return 0


def _derived_inputs(args) -> list:
    from .transfer import edges_file

    return edges_file(args) + resumed_run_inputs(args)


def _add_schedule_args(p, defaults) -> None:
    """``--iterations``, ``--alpha``, ``--lambda``: the alternations and their schedules."""
    p.add_argument("--iterations", type=int, default=None,
                   help=f"alternations (default {defaults.iterations}; with --resume: alternations after the warm "
                        "start, default 3)")
    p.add_argument("--alpha", default=None,
                   help=f"alpha schedule FIRST,LAST (default {_schedule_text(defaults.alpha)}), or 'auto': chosen by "
                        "k-fold cross-validation over the training expressions (curve in crossval.json)")
    p.add_argument("--lambda", dest="lam", default=None,
                   help=f"lambda schedule FIRST,LAST (default {_schedule_text(defaults.lam)})")


def _add_solver_args(p, defaults) -> None:
    """``--ipopt``, ``--unobserved``, ``--support`` and the cross-validation of ``--alpha auto``."""
    from ..rigging.cvcurve import DEFAULT_GRID
    from ..rigging.problem import CV_CANDIDATES, IPOPT_MODES, UNOBSERVED_MODES

    p.add_argument("--ipopt", choices=IPOPT_MODES, default=None,
                   help="when the weight step also solves the CasADi/IPOPT model of eq. 5 (its answer seeds the "
                        f"certified solver, whose optimum is the answer either way; default {defaults.ipopt})")
    p.add_argument("--unobserved", choices=UNOBSERVED_MODES, default=None,
                   help="shapes whose rough weights stay below --support in every example: keep their deformation "
                        f"transfer (weights held at 0) or fit them like the others (default {defaults.unobserved})")
    p.add_argument("--support", type=float, default=None,
                   help=f"rough weight a shape needs in some example to count as observed (default {defaults.support:g})")
    p.add_argument("--cv-folds", type=int, default=None,
                   help=f"folds of --alpha auto (default {defaults.cv_folds})")
    p.add_argument("--cv-grid", action="extend", nargs="+", default=[], metavar="ALPHA",
                   help="candidate final alphas of --alpha auto (several after one flag or repeated; default "
                        f"{' '.join(f'{a:g}' for a in DEFAULT_GRID)})")
    p.add_argument("--cv-candidates", choices=CV_CANDIDATES, default=None,
                   help="--alpha auto: one warm-started path on all training expressions, every other candidate "
                        "scored by deleting folds from its last basis step (half the folds while the path runs, all "
                        "for the best and its two neighbours), the rig returned the path's at the chosen alpha "
                        "(coarse); the same path, every other candidate and the best's better neighbour scored on "
                        "every fold (deletion, about 1.3x coarse); each fold's candidates along its own path and the final run along "
                        "the same path down to the chosen alpha (path), every candidate from the rough weights with "
                        "its own schedule (cold, about 3.5x the cost), or both curves and the lower one (both; "
                        f"default {defaults.cv_candidates})")


def register(sub) -> None:
    """Add ``rig`` to the ``facebasis`` parser."""
    from ..rigging.problem import GenerationOptions

    defaults = GenerationOptions()
    p = sub.add_parser("rig", help="example-based blendshape generation (Gao et al. 2015)")
    add_rig_folder_args(p, template="optional")
    p.add_argument("--target", default=None, help="target neutral mesh, template topology")
    p.add_argument("--examples", default=None, help="folder of training expression meshes (names = file stems)")
    p.add_argument("--weights", default=None, help='rough weights JSON: {"ex00": {"jawOpen": 0.8}}')
    p.add_argument("--out", required=True, help="output folder")
    _add_schedule_args(p, defaults)
    add_contact_args(p, "exact contact: after generation, move each generated shape by the smallest displacement "
                        "(smoothed by the transfer energy) so that no triangle pair intersects that does not intersect "
                        "in the target neutral or in the template shape, then solve the final weight step again; "
                        "checked exactly after every solve (exit status 1 if a shape keeps a new pair)",
                     "with --contact: shapes left as generated, e.g. correctives meant to press layers together "
                     "(several after one flag or repeated)")
    p.add_argument("--exclusive", action="extend", nargs="+", default=[], metavar="SHAPE_A:SHAPE_B",
                   help="mutually exclusive shape pairs (complementarity x_a x_b = 0); give several after one "
                        "flag (--exclusive A:B C:D) or repeat the flag; every pair is kept")
    _add_solver_args(p, defaults)
    p.add_argument("--resume", default=None, metavar="RUN_DIR",
                   help="add the training expressions of --examples/--weights to this finished run and warm-start "
                        "from its blendshapes and weights (template and target default to the run's)")
    add_virtual_edge_args(p)
    p.set_defaults(func=cmd_rig, outputs=Outputs(writes=(("out", "folder", "--out"),),
                                                 reads=("template", "target", "examples", "weights", "resume"),
                                                 derived=_derived_inputs, allow=("resume",)))
