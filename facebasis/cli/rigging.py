"""``facebasis transfer``, ``rig``, ``export``, ``verify``: deformation transfer and example-based
rig generation (Gao, Tan, Guo, Fan 2015) with certified weights."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from .outputs import READS_ONLY, Outputs
from .common import (add_rig_folder_args, add_virtual_edge_args, check_virtual_edge_args, describe_pairs,
                     pair_of_floats, virtual_edges_for)


def cmd_transfer(args) -> int:
    from ..atomic import atomic_directory
    from ..geometry.rig import load_rig_folder, load_target_neutral, write_shapes
    from ..geometry.transfer import DeformationTransfer

    _check_contact_flags(args)
    check_virtual_edge_args(args)
    template = load_rig_folder(args.template, args.neutral, args.exclude)
    _warn_rig_folder(template)
    target = load_target_neutral(args.target, template)
    if args.contact:  # names, size and the target's own intersections, before any solving (as rig does)
        _check_contact_target(args, template, target)
    ve = virtual_edges_for(args, template)
    t0 = time.perf_counter()
    dt = DeformationTransfer(template, target, virtual_edges=ve, virtual_weight=args.virtual_weight,
                             virtual_mode=args.virtual_mode)
    contact = None
    if args.contact:
        from ..contact.exact import contact_transfer

        contact = contact_transfer(template, target, exclude=args.contact_exclude, transfer=dt,
                                   allow_target_pairs=args.contact_allow_target_pairs)
        result = contact.rig
    else:
        result = dt.transfer()
    seconds = time.perf_counter() - t0
    with atomic_directory(args.out) as stage:
        missing = write_shapes(stage, result, layout=template.layout)
        if contact is not None:
            _write_contact(stage, contact)
    print(f"transferred {result.n_shapes} shapes onto {args.target} in {seconds:.3f} s -> {args.out}")
    if missing:
        print(f"note: the template names {', '.join(missing)}, not found beside {args.template}: not copied",
              file=sys.stderr)
    if contact is not None:
        print(contact.table())
        return _contact_verdict(contact, "transferred", args.contact_exclude)
    return 0


def _alpha_option(text):
    """``--alpha``: ``auto`` or FIRST,LAST."""
    return "auto" if str(text).strip().lower() == "auto" else pair_of_floats(text, "--alpha")


def _cv_grid(values) -> tuple[float, ...]:
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
    return tuple(_once(out, "--cv-grid"))


def add_contact_target_args(p) -> None:
    """``--contact-strict`` / ``--contact-allow-target-pairs`` (transfer and rig, declared once)."""
    p.add_argument("--contact-strict", action="store_true",
                   help="with --contact: refuse a target neutral that intersects itself where the template does not "
                        "(by default those pairs are kept as they are, said in one line, and no new pair appears)")
    p.add_argument("--contact-allow-target-pairs", action="store_true",
                   help="with --contact: keep the target neutral's own intersections (the default now; the flag "
                        "is kept for older scripts)")


def _warn_rig_folder(template) -> None:
    """One line on stderr for a template folder that looks as it ships (identity modes, many shapes)."""
    from ..geometry.rig import rig_folder_warning

    warning = rig_folder_warning(template)
    if warning:
        print(warning, file=sys.stderr)


def _check_contact_flags(args) -> None:
    """The contact flags of transfer and rig: the others need ``--contact``; names given twice kept once."""
    from ..errors import InputError

    given = [flag for flag, v in (("--contact-exclude", args.contact_exclude), ("--contact-strict", args.contact_strict),
                                  ("--contact-allow-target-pairs", args.contact_allow_target_pairs)) if v]
    if not args.contact and given:
        raise InputError(f"{', '.join(given)}: expected --contact as well, found none")
    if args.contact_strict and args.contact_allow_target_pairs:
        raise InputError("--contact-strict: expected it or --contact-allow-target-pairs, found both (strict refuses "
                         "the target's own intersections, the other keeps them)")
    args.contact_exclude = _once(args.contact_exclude, "--contact-exclude")
    args.contact_allow_target_pairs = not args.contact_strict  # the target's own intersections are kept by default


def _check_contact_target(args, template, target) -> None:
    """Names, size and the target neutral's own intersections, before any solving; those are kept as
    they are (one line says how many and where) unless ``--contact-strict`` refuses the target."""
    from ..contact.exact import check_contact_inputs, describe_target_pairs

    own = check_contact_inputs(template, target, args.contact_exclude, args.contact_allow_target_pairs,
                               what="--contact", exclude_what="--contact-exclude", target_what=str(args.target))
    if len(own):
        print(f"contact: the target neutral {args.target} intersects itself beyond the template neutral in "
              f"{describe_target_pairs(own, target, template.faces)}: kept as they are, no new pair is allowed "
              "(--contact-strict refuses such a target)", file=sys.stderr)


def _once(values, flag: str) -> list:
    """``values`` in order with repeats dropped, saying so (a repeated flag value is kept once)."""
    out = list(dict.fromkeys(values))
    if len(out) < len(values):
        repeated = sorted({str(v) for v in values if values.count(v) > 1})
        print(f"note: {flag} {', '.join(repeated)} given more than once: used once", file=sys.stderr)
    return out


def _rig_options(args):
    from ..errors import InputError
    from ..rigging.generation import GenerationOptions

    grid = _cv_grid(args.cv_grid)
    if args.cv_given and str(args.alpha).strip().lower() != "auto":
        raise InputError(f"{', '.join(args.cv_given)}: expected --alpha auto as well (cross-validation chooses "
                         f"alpha only then), found --alpha {args.alpha}")
    try:
        return GenerationOptions(iterations=args.iterations, alpha=_alpha_option(args.alpha),
                                 lam=pair_of_floats(args.lam, "--lambda"), virtual_weight=args.virtual_weight,
                                 virtual_mode=args.virtual_mode, ipopt=args.ipopt, unobserved=args.unobserved,
                                 support=args.support, cv_folds=args.cv_folds, cv_grid=grid,
                                 cv_candidates=args.cv_candidates)
    except InputError as err:  # the options' own checks name their fields: say the flag the user typed
        text = str(err)
        field = text.split(":", 1)[0]
        if field in _OPTION_FLAGS:
            raise InputError(_OPTION_FLAGS[field] + text[len(field):]) from None
        raise


#: GenerationOptions fields -> the rig command's flags (for the options' own error messages)
_OPTION_FLAGS = {"iterations": "--iterations", "alpha": "--alpha", "lambda": "--lambda", "lam": "--lambda",
                 "support": "--support", "cv_folds": "--cv-folds", "cv_grid": "--cv-grid",
                 "cv_candidates": "--cv-candidates", "virtual_weight": "--virtual-weight",
                 "virtual_mode": "--virtual-mode", "ipopt": "--ipopt", "unobserved": "--unobserved"}


def _progress(rec, total):
    flag = "" if rec.ipopt_success else f"  [IPOPT: {rec.ipopt_status}]"
    ipopt = f"IPOPT {rec.ipopt_iterations} it" if rec.ipopt_iterations else "certified"
    print(f"  iteration {rec.iteration}/{total}: alpha {rec.alpha:.3g} lambda {rec.lam:.3g} "
          f"E_fit {rec.e_fit:.4g} E_reg {rec.e_reg:.4g} weight objective {rec.weight_objective:.6g} "
          f"({ipopt}, {rec.basis_seconds + rec.weight_seconds:.2f} s){flag}", flush=True)


def _cv_progress(fold, alpha, error):
    print(f"  cross-validation fold {fold + 1}: alpha {alpha:g} held-out error {error:.4f}", flush=True)


def _warnings(result, options, names):
    for h in result.history:
        if not h.ipopt_success:
            print(f"warning: IPOPT returned {h.ipopt_status} at iteration {h.iteration}; its answer was replaced "
                  "by the certified optimum (branch and bound)", file=sys.stderr)
    for name in result.missing:
        print(f"warning: training expression {name} keeps a relative residual of "
              f"{result.residuals[names.index(name)]:.3f} > {options.missing_threshold}: the template "
              "may lack a shape it needs (missing expression)", file=sys.stderr)


def cmd_rig(args) -> int:
    from ..atomic import atomic_directory
    from ..errors import InputError
    from ..geometry.rig import load_rig_folder, load_target_neutral
    from ..rigging.examples import load_examples, load_weights, parse_pairs
    from ..rigging.generation import BlendshapeGenerator, GenerationProblem
    from ..rigging.runs import write_rig_run

    if args.resume is not None:
        if args.contact or args.contact_exclude or args.contact_allow_target_pairs or args.contact_strict:
            raise InputError("--contact with --resume: expected a fresh run (contact is not stored in a run "
                             "to resume), found --resume")
        return _cmd_rig_resume(args)
    absent = [f for f, v in (("--template", args.template), ("--target", args.target),
                             ("--examples", args.examples), ("--weights", args.weights)) if v is None]
    if absent:
        raise InputError(f"rig: expected {', '.join(absent)} (or --resume RUN_DIR), found none")
    # everything is validated before any solving starts
    _check_contact_flags(args)
    options = _rig_options(args)
    template = load_rig_folder(args.template, args.neutral, args.exclude)
    _warn_rig_folder(template)
    target = load_target_neutral(args.target, template)
    if args.contact:
        _check_contact_target(args, template, target)
    names, examples = load_examples(args.examples, template)
    X0 = load_weights(args.weights, names, template.names)
    ve = virtual_edges_for(args, template)
    pairs = parse_pairs(args.exclusive)
    problem = GenerationProblem(template, target, examples, X0, names, pairs, ve)
    if options.auto_alpha and len(names) < options.cv_folds:
        raise InputError(f"--alpha auto: expected at least {options.cv_folds} training expressions for "
                         f"{options.cv_folds}-fold cross-validation (--cv-folds), found {len(names)}")
    print(f"template {template.n_shapes} shapes, {template.n_vertices} vertices; {len(names)} training "
          f"expressions; {describe_pairs(problem.exclusive, len(args.exclusive))}")
    for text, name in ((args.alpha, "--alpha"), (args.lam, "--lambda")):
        if text is not None and str(text).strip().lower() != "auto" and "," not in str(text):
            print(f"note: {name} {text} is one number: held constant over all iterations (FIRST,LAST gives a schedule)")
    for (a, b), (ia, ib) in zip(problem.exclusive, problem.pair_indices):
        both = [n for n, row in zip(names, X0) if row[ia] > 0 and row[ib] > 0]
        if both:
            print(f"warning: exclusive pair {a}:{b}: the rough weights of {len(both)} example(s) use both shapes "
                  f"({', '.join(both[:5])}{', ...' if len(both) > 5 else ''}); the weight step will keep only one "
                  "of them in each", file=sys.stderr)
    gen = BlendshapeGenerator(problem, options)
    if gen.unobserved:
        print(f"{len(gen.unobserved)} shape(s) without support in the examples (rough weights < {options.support:g}) "
              f"keep their deformation transfer: {', '.join(gen.unobserved)}")
    result = gen.run(_progress, cv_progress=_cv_progress if options.auto_alpha else None)
    cv = result.crossval
    if cv is not None:
        print(f"--alpha auto: {len(cv.grid)} candidates x {len(cv.fold_errors)} folds in {cv.seconds:.1f} s; "
              f"chose alpha {cv.schedule[0]:g} -> {cv.schedule[1]:g} (held-out error {min(cv.errors):.4f})")
    contact = None
    if args.contact:
        from ..rigging.contactstep import contact_generation

        contact, result = contact_generation(gen, result, args.contact_exclude, args.contact_allow_target_pairs)
    sources = {"template": args.template, "neutral": args.neutral, "exclude": list(args.exclude),
               "target": args.target}
    with atomic_directory(args.out) as stage:
        write_rig_run(stage, result, options, problem, args.examples, args.weights, sources=sources)
        if contact is not None:
            _write_contact(stage, contact)
    _warnings(result, options, list(names))
    print(f"generated {template.n_shapes} blendshapes in {result.seconds + result.precompute_seconds:.2f} s -> {args.out}")
    if contact is not None:
        print(contact.table())
        print(f"exact contact: {contact.seconds['total']:.2f} s")
        return _contact_verdict(contact, "generated", args.contact_exclude)
    return 0


def _write_contact(stage, contact) -> None:
    """``contact.json``: the exact check's verdict and the per-shape table, kept with the shapes."""
    import json

    (stage / "contact.json").write_text(json.dumps(contact.record(), indent=1))


def _contact_verdict(contact, what: str, excluded) -> int:
    """Say what the exact check found after the contact solve; 1 if a shape keeps a new pair."""
    if not contact.ok:
        bad = [s.name for s in contact.shapes if not s.excluded and s.new_pairs_left]
        print(f"CONTACT NOT MET: {len(bad)} shape(s) keep new intersecting pairs after the exact check "
              f"({', '.join(bad)}); they are written as solved", file=sys.stderr)
        return 1
    retreated = [f"{s.name} ({s.retreated} vertices, {100 * s.retreat_loss:.1f}% of its delta)"
                 for s in contact.shapes if not s.excluded and s.retreated]
    if retreated:  # intersection-free, but less of the shape: the user should see it
        print(f"exact contact: the solve-and-check rounds left pairs in {len(retreated)} shape(s); they were "
              f"pulled back towards the target neutral around those pairs: {', '.join(retreated)}", file=sys.stderr)
    print(f"exact check: no {what} shape has a triangle pair intersecting that does not intersect in the "
          "target neutral or in the template shape" + (f" (excluded: {', '.join(excluded)})" if excluded else ""))
    return 0


def _edges_file(args) -> list:
    """``--virtual-edges EDGES.json`` (without a file the edges are detected: nothing read)."""
    return [] if args.virtual_edges in (None, "detect") else [args.virtual_edges]


def _resumed_run_inputs(args) -> list:
    """The inputs a run to resume records (its example folders, weight files, template and target):
    ``rig --resume RUN --out X`` reads them, so X must spare them too."""
    if args.resume is None or not (Path(args.resume) / "inputs.json").is_file():
        return []
    from ..rigging.verify import read_inputs

    inputs, ex_dirs, w_files = read_inputs(args.resume)
    src = inputs.get("sources") or {}
    return [*ex_dirs, *w_files, *(Path(args.resume) / src[k] for k in ("template", "target")
                                  if isinstance(src.get(k), str))]


def _cmd_rig_resume(args) -> int:
    from ..atomic import atomic_directory
    from ..errors import InputError
    from ..geometry.rig import load_rig_folder
    from ..rigging.enrich import resume_run
    from ..rigging.runs import write_rig_run

    if (Path(args.resume) / "contact.json").is_file():
        raise InputError(f"--resume {args.resume}: expected a run made without --contact, found contact.json (its "
                         "shapes were corrected for contact; a resumed run re-generates them without it and would "
                         "drop that guarantee); start a new run with --contact")
    if args.alpha_given or args.lam_given or args.exclusive or args.cv_given or args.run_given:
        given = [f for f, v in (("--alpha", args.alpha_given), ("--lambda", args.lam_given),
                                ("--exclusive", bool(args.exclusive))) if v] + args.cv_given + args.run_given
        raise InputError(f"--resume: expected the run's own schedule and pairs, found {', '.join(given)} "
                         "(start a new run to change them)")
    if (Path(args.resume) / "inputs.json").is_file():
        from ..rigging.verify import read_inputs

        src = read_inputs(args.resume)[0].get("sources") or {}
        if src.get("virtual_edges") is True and args.virtual_edges is None:
            raise InputError(f"--resume {args.resume}: expected --virtual-edges (and --template) as the run was made "
                             "with virtual edges, found none (the resumed run would drop their energy)")
    ve = None
    if args.virtual_edges is not None:
        if not args.template:
            raise InputError("--virtual-edges with --resume: expected --template as well, found none")
        ve = virtual_edges_for(args, load_rig_folder(args.template, args.neutral, args.exclude))
    run = resume_run(args.resume, args.examples, args.weights, template=args.template,
                     neutral=args.neutral if args.template else None, exclude=args.exclude, target=args.target,
                     iterations=args.iterations_given, virtual_edges=ve, progress=_progress)
    result = run.result
    print(f"resumed {args.resume}: {run.n_previous} training expressions + {run.n_new} new"
          + ("" if run.n_new else " (nothing new: the run's rig and weights are returned unchanged)"))
    with atomic_directory(args.out) as stage:
        write_rig_run(stage, result, run.options, run.problem, list(run.example_dirs), list(run.weight_files),
                      sources=run.sources)
    _warnings(result, run.options, list(run.problem.example_names))
    print(f"generated {run.problem.template.n_shapes} blendshapes in {run.seconds:.2f} s -> {args.out}")
    return 0


def cmd_verify(args) -> int:
    from ..rigging.examples import parse_pairs
    from ..rigging.verify import verify_run

    from ..errors import InputError

    if not 0 <= args.tolerance < float("inf"):
        raise InputError(f"--tolerance: expected a relative gap >= 0, found {args.tolerance}")
    report = verify_run(args.run_dir, tolerance=args.tolerance, check_pairs=parse_pairs(args.exclusive))
    print(f"{report.run_dir}: {len(report.examples)} examples, lambda {report.lam:g}, tolerance {report.tolerance:g} "
          "(relative objective gap of the stored weights to the certified global optimum)")
    print(f"exclusive pairs of the run: {describe_pairs(report.pairs, len(report.pairs))}")
    print(report.table())
    bad = [e.name for e in report.examples if not e.ok]
    if report.checked:
        print("pairs named with --exclusive (largest |x_a x_b| of the stored weights over all examples):")
        for chk in report.checked:
            flag = "ok" if chk.ok else "BREACHED"
            print(f"  {chk.a}:{chk.b}  {chk.max_product:.3g}  at {chk.worst_example}  "
                  f"({'a constraint of the run' if chk.in_run else 'not a constraint of the run'})  {flag}")
        breached = [f"{c.a}:{c.b}" for c in report.checked if not c.ok]
        if breached:
            print(f"NOT EXCLUSIVE: the stored weights breach {len(breached)} pair(s) named with --exclusive "
                  f"({', '.join(breached)})", file=sys.stderr)
    else:
        breached = []
    if bad:  # said as well when a named pair is breached: both verdicts, one exit status
        print(f"NOT OPTIMAL: {len(bad)} of {len(report.examples)} stored answers ({', '.join(bad)})", file=sys.stderr)
    if bad or breached:
        return 1
    print(f"all {len(report.examples)} stored answers are certified optimal")
    return 0


def _gltf_buffer(args) -> list:
    """``export --out X.gltf`` also writes ``X.bin`` beside it."""
    out = Path(args.out)
    return [(str(out.with_suffix(".bin")), "file", "--out (its .bin)")] if out.suffix.lower() == ".gltf" else []


def cmd_export(args) -> int:
    from ..geometry.gltf import check_gltf_path, unit_scale, write_glb
    from ..geometry.rig import load_rig_folder, rig_folder_warning

    if args.template is not None and args.rig is not None:
        from ..errors import InputError

        raise InputError(f"export: expected the rig folder once, found {args.rig} and --template {args.template}")
    folder = args.rig if args.rig is not None else args.template
    if folder is None:
        from ..errors import InputError

        raise InputError("export: expected a rig folder (RIG_DIR or --template), found none")
    unit_scale(args.unit)
    check_gltf_path(args.out)
    rig = load_rig_folder(folder, args.neutral, args.exclude)
    warning = rig_folder_warning(rig)
    if warning:
        print(warning, file=sys.stderr)
    t0 = time.perf_counter()
    out = write_glb(rig, args.out, unit=args.unit)
    layout = rig.layout
    what = ("" if layout is None else
            f", UVs {'yes' if layout.uv is not None else 'no'}, {max(len(layout.material_names), 1)} material(s)")
    print(f"{rig.n_shapes} morph targets, {rig.n_vertices} vertices{what}, {args.unit} -> metres, written in "
          f"{time.perf_counter() - t0:.3f} s -> {out}")
    return 0


def _cmd_rig_defaults(func, defaults):
    """Fill the schedule flags' defaults after parsing, remembering which were given (``--resume``
    keeps the run's own schedule and refuses new ones)."""
    alpha = ",".join(f"{a:g}" for a in defaults.alpha)
    lam = ",".join(f"{a:g}" for a in defaults.lam)

    def run(args):
        args.alpha_given, args.lam_given = args.alpha is not None, args.lam is not None
        args.iterations_given = args.iterations
        # the cross-validation flags only mean something with --alpha auto on a fresh run
        args.cv_given = [flag for flag, v in (("--cv-folds", args.cv_folds), ("--cv-grid", args.cv_grid or None),
                                              ("--cv-candidates", args.cv_candidates)) if v is not None]
        # options a resumed run takes from the run itself (history.json): given with --resume they are refused
        args.run_given = [flag for flag, v in (("--ipopt", args.ipopt), ("--unobserved", args.unobserved),
                                               ("--support", args.support), ("--virtual-weight", args.virtual_weight))
                          if v is not None] + (["--virtual-mode"] if args.virtual_mode is not None else [])
        check_virtual_edge_args(args)
        if args.support is not None and args.unobserved == "fit":
            from ..errors import InputError

            raise InputError(f"--support {args.support:g}: expected --unobserved transfer (the support threshold "
                             "only decides which shapes keep their transfer), found --unobserved fit")
        args.ipopt = defaults.ipopt if args.ipopt is None else args.ipopt
        args.unobserved = defaults.unobserved if args.unobserved is None else args.unobserved
        args.support = defaults.support if args.support is None else args.support
        args.cv_folds = defaults.cv_folds if args.cv_folds is None else args.cv_folds
        args.cv_candidates = defaults.cv_candidates if args.cv_candidates is None else args.cv_candidates
        args.alpha = alpha if args.alpha is None else args.alpha
        args.lam = lam if args.lam is None else args.lam
        args.iterations = defaults.iterations if args.iterations is None else args.iterations
        return func(args)

    return run


def register(sub) -> None:
    """Add this group's subcommands to the ``facebasis`` parser."""
    from ..rigging.crossval import DEFAULT_GRID
    from ..rigging.generation import IPOPT_MODES, UNOBSERVED_MODES, GenerationOptions

    defaults = GenerationOptions()
    alpha = ",".join(f"{a:g}" for a in defaults.alpha)
    lam = ",".join(f"{a:g}" for a in defaults.lam)
    p = sub.add_parser("transfer", help="deformation transfer of a template rig onto a target neutral")
    add_rig_folder_args(p)
    p.add_argument("--target", required=True, help="target neutral mesh (.obj/.ply), template topology")
    p.add_argument("--out", required=True, help="output folder: <shape>.obj for every template shape")
    add_virtual_edge_args(p)
    p.add_argument("--contact", action="store_true",
                   help="exact contact: the least-squares transfer subject to no triangle pair intersecting that "
                        "does not intersect in the target neutral or in the template shape; checked exactly after "
                        "every solve (exit status 1 if a shape keeps a new pair)")
    p.add_argument("--contact-exclude", action="extend", nargs="+", default=[], metavar="SHAPE",
                   help="with --contact: shapes left as plain transfer, e.g. correctives meant to press layers "
                        "together (several after one flag or repeated)")
    add_contact_target_args(p)
    p.set_defaults(func=cmd_transfer, outputs=Outputs(writes=(("out", "folder", "--out"),),
                                                     reads=("template", "target"), derived=_edges_file))

    p = sub.add_parser("rig", help="example-based blendshape generation (Gao et al. 2015)")
    p.add_argument("--template", default=None, help="template rig folder (neutral + one mesh per blendshape)")
    p.add_argument("--neutral", default="neutral.obj",
                   help="file name of the neutral inside the rig folder (default neutral.obj)")
    p.add_argument("--exclude", action="append", default=[], metavar="GLOB",
                   help="ignore rig-folder files matching this glob (repeatable), e.g. 'identity*'")
    p.add_argument("--target", default=None, help="target neutral mesh, template topology")
    p.add_argument("--examples", default=None, help="folder of training expression meshes (names = file stems)")
    p.add_argument("--weights", default=None, help='rough weights JSON: {"ex00": {"jawOpen": 0.8}}')
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--iterations", type=int, default=None,
                   help=f"alternations (default {defaults.iterations}; with --resume: alternations after the warm "
                        "start, default 3)")
    p.add_argument("--alpha", default=None,
                   help=f"alpha schedule FIRST,LAST (default {alpha}), or 'auto': chosen by k-fold cross-validation "
                        "over the training expressions (curve in crossval.json)")
    p.add_argument("--lambda", dest="lam", default=None, help=f"lambda schedule FIRST,LAST (default {lam})")
    p.add_argument("--contact", action="store_true",
                   help="exact contact: after generation, move each generated shape by the smallest displacement "
                        "(smoothed by the transfer energy) so that no triangle pair intersects that does not intersect "
                        "in the target neutral or in the template shape, then solve the final weight step again; "
                        "checked exactly after every solve (exit status 1 if a shape keeps a new pair)")
    p.add_argument("--contact-exclude", action="extend", nargs="+", default=[], metavar="SHAPE",
                   help="with --contact: shapes left as generated, e.g. correctives meant to press layers together "
                        "(several after one flag or repeated)")
    add_contact_target_args(p)
    p.add_argument("--exclusive", action="extend", nargs="+", default=[], metavar="SHAPE_A:SHAPE_B",
                   help="mutually exclusive shape pairs (complementarity x_a x_b = 0); give several after one "
                        "flag (--exclusive A:B C:D) or repeat the flag; every pair is kept")
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
    p.add_argument("--cv-candidates", choices=("deletion", "path", "cold", "both"), default=None,
                   help="--alpha auto: one warm-started path on all training expressions, each candidate scored by "
                        "deleting each fold from its last basis step, the rig returned the path's at the chosen alpha "
                        "(deletion, about 2-4 runs); each fold's candidates along its own path and the final run along "
                        "the same path down to the chosen alpha (path), every candidate from the rough weights with "
                        "its own schedule (cold, about 3.5x the cost), or both curves and the lower one (both; "
                        f"default {defaults.cv_candidates})")
    p.add_argument("--resume", default=None, metavar="RUN_DIR",
                   help="add the training expressions of --examples/--weights to this finished run and warm-start "
                        "from its blendshapes and weights (template and target default to the run's)")
    add_virtual_edge_args(p)
    p.set_defaults(func=_cmd_rig_defaults(cmd_rig, defaults),
                   outputs=Outputs(writes=(("out", "folder", "--out"),),
                                   reads=("template", "target", "examples", "weights", "resume"),
                                   derived=lambda a: _edges_file(a) + _resumed_run_inputs(a), allow=("resume",)))

    p = sub.add_parser("export", help="a rig folder as glTF 2.0 (.glb or .gltf) with one morph target per shape")
    p.add_argument("rig", nargs="?", default=None,
                   help="rig folder (neutral + one mesh per blendshape), e.g. a facebasis rig output")
    p.add_argument("--template", default=None, metavar="RIG_DIR", help="the rig folder, spelled as transfer spells it")
    p.add_argument("--neutral", default="neutral.obj",
                   help="file name of the neutral inside the rig folder (default neutral.obj)")
    p.add_argument("--exclude", action="append", default=[], metavar="GLOB",
                   help="ignore rig-folder files matching this glob (repeatable), e.g. 'identity*'")
    p.add_argument("--unit", default="cm", metavar="cm|m|mm",
                   help="the rig's length unit (default cm: ICT-FaceKit and the built-in face); glTF is written in "
                        "metres and the unit recorded in asset.extras")
    p.add_argument("--out", required=True,
                   help="output .glb (binary glTF) or .gltf (JSON, with OUT.bin and the textures beside it); the "
                        "folder must exist")
    p.set_defaults(func=cmd_export, outputs=Outputs(writes=(("out", "file", "--out"),), reads=("rig", "template"),
                                                    also=_gltf_buffer))

    p = sub.add_parser("verify", help="certify the stored weights of a facebasis rig output folder")
    p.add_argument("run_dir", help="output folder of facebasis rig (with inputs.json)")
    p.add_argument("--tolerance", type=float, default=1e-6,
                   help="largest relative objective gap accepted (default 1e-6); exit status 1 beyond it")
    p.add_argument("--exclusive", action="extend", nargs="+", default=[], metavar="SHAPE_A:SHAPE_B",
                   help="also report the largest product x_a x_b of the stored weights over these pairs "
                        "(several after one flag or repeated); exit status 1 if any exceeds 1e-8")
    p.set_defaults(func=cmd_verify, outputs=READS_ONLY)
