"""``facebasis report`` and ``sweep``: figures and tables from stored results, Dask studies."""

from __future__ import annotations

from pathlib import Path


def cmd_report(args) -> int:
    from ..report.run_report import report_run, sweep_report

    target = Path(args.path)
    formats = tuple(args.formats.split(","))
    if target.suffix.lower() == ".csv":
        from ..report.studies import read_table

        out = Path(args.out) if args.out else target.with_suffix("")
        paths = sweep_report(read_table(target), out, formats)
        if not paths:
            from ..errors import InputError

            raise InputError(f"{target}: expected rows of at least one study, found none")
    else:
        paths = report_run(target, args.out, formats)
    print(f"{len(paths)} files -> {paths[0].parent}")
    return 0


def cmd_sweep(args) -> int:
    from ..report.studies import STUDIES, run_tasks, study_tasks, write_table

    studies = STUDIES if args.study == "all" else tuple(args.study.split(","))
    try:
        seeds = tuple(int(s) for s in args.seeds.split(","))
    except ValueError:
        from ..errors import InputError

        raise InputError(f"--seeds: expected whole numbers separated by commas, found {args.seeds!r}") from None
    tasks = [t for st in studies for t in study_tasks(st, args.problem, seeds)]
    where = args.scheduler or f"a local Dask cluster of {args.workers or 'all'} worker processes"
    print(f"{len(tasks)} tasks ({', '.join(studies)}) on problem {args.problem}, seeds {list(seeds)}, on {where}")
    rows = run_tasks(tasks, scheduler=args.scheduler, workers=args.workers, progress=not args.quiet)
    write_table(rows, args.out)
    print(f"results table ({len(rows)} rows) -> {args.out}; figures: facebasis report {args.out}")
    return 0


def register(sub) -> None:
    """Add this group's subcommands to the ``facebasis`` parser."""
    p = sub.add_parser("report", help="figures and tables of a facebasis rig output folder or of a facebasis sweep table")
    p.add_argument("path", help="rig output folder, or the results .csv of facebasis sweep")
    p.add_argument("--out", default=None, help="output folder (default: RUN_DIR/report, or the CSV's name)")
    p.add_argument("--formats", default="png,pdf", help="figure formats (default png,pdf)")
    p.set_defaults(func=cmd_report)

    p = sub.add_parser("sweep", help="alpha / lambda / noise / method studies in parallel (Dask)")
    p.add_argument("--problem", default="default", choices=("default", "ict"),
                   help="person problem: the built-in face (default) or ICT (needs ../shared)")
    p.add_argument("--study", default="all", help="alpha, lambda, grid, noise, methods, a comma list, or all (default all)")
    p.add_argument("--seeds", default="0", help="problem seeds, comma separated (default 0)")
    p.add_argument("--out", required=True, help="results table (.csv)")
    p.add_argument("--scheduler", default=None, help="address of a Dask scheduler (default: a local cluster)")
    p.add_argument("--workers", type=int, default=None, help="local worker processes (default: one per core)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_sweep)
