"""``facebasis report`` and ``sweep``: figures and tables from stored results, Dask studies."""

from __future__ import annotations

from pathlib import Path

from .outputs import Outputs


def _default_report_folder(args, attr):
    """``report``'s output when --out is not given: RUN_DIR/report, or the CSV's name without .csv."""
    target = Path(args.path)
    return str(target.with_suffix("") if target.suffix.lower() == ".csv" else target / "report")


def cmd_report(args) -> int:
    from ..atomic import atomic_directory
    from ..report.run_report import report_run, sweep_report

    target = Path(args.path)
    formats = tuple(args.formats.split(","))
    out = Path(args.out if args.out is not None else _default_report_folder(args, "out"))
    table = None
    if target.suffix.lower() == ".csv":  # inputs read before the output folder is staged
        from ..report.studies import read_table

        table = read_table(target)
    else:
        from ..report.run_report import check_run_folder

        check_run_folder(target)
    with atomic_directory(out, inputs=(target,)) as stage:
        if table is not None:
            paths = sweep_report(table, stage, formats)
            if not paths:
                from ..errors import InputError

                raise InputError(f"{target}: expected rows of at least one study, found none")
        else:
            paths = report_run(target, stage, formats, written_as=out)
    print(f"{len(paths)} files -> {out}")
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
    p.set_defaults(func=cmd_report, outputs=Outputs(writes=(("out", "folder", "--out"),), reads=("path",),
                                                   default=_default_report_folder))

    p = sub.add_parser("sweep", help="alpha / lambda / noise / method studies in parallel (Dask)")
    p.add_argument("--problem", default="default", choices=("default", "ict"),
                   help="person problem: the built-in face (default) or ICT (needs ../shared)")
    p.add_argument("--study", default="all", help="alpha, lambda, grid, noise, methods, a comma list, or all (default all)")
    p.add_argument("--seeds", default="0", help="problem seeds, comma separated (default 0)")
    p.add_argument("--out", required=True, help="results table (.csv)")
    p.add_argument("--scheduler", default=None, help="address of a Dask scheduler (default: a local cluster)")
    p.add_argument("--workers", type=int, default=None, help="local worker processes (default: one per core)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    from ..report import studies  # noqa: F401  (registers the results table's header: a later sweep may replace it)

    p.set_defaults(func=cmd_sweep, outputs=Outputs(writes=(("out", "file", "--out"),)))
