"""``facebasis virtual-edges`` and ``penetration``: virtual edges against layer penetration
(Li, Shen, Liu 2023) and the exact count of intersecting triangle pairs."""

from __future__ import annotations

from pathlib import Path

from .outputs import READS_ONLY, Outputs


def cmd_virtual_edges(args) -> int:
    from ..contact.penetration import parse_region
    from ..contact.virtual_edges import detect_virtual_edges
    from ..geometry.meshio import read_mesh

    V, F = read_mesh(args.mesh, check_degenerate=True)
    mask = parse_region(args.region, len(V)) if args.region else None
    ve = detect_virtual_edges(V, F, cap=args.cap, ratio=args.ratio, per_vertex=args.per_vertex,
                              spacing=args.spacing, vertex_mask=mask, name=str(args.mesh))
    if args.figure:  # the figure first: a failure there leaves no edges file half a result
        from ..report.figures import virtual_edges_figure

        figure = Path(args.figure)
        paths = virtual_edges_figure(V, F, ve.edges, figure, title=f"{Path(args.mesh).name}: {len(ve)} virtual edges",
                                     formats=(figure.suffix.lower()[1:],))
    ve.write(args.out)
    print(f"{len(ve)} virtual edges ({ve.candidates} candidate pairs with distance < {ve.cap:.4g} and "
          f"geodesic/Euclidean >= {ve.ratio:g}) in {ve.seconds:.2f} s -> {args.out}")
    if args.figure:
        print(f"figure -> {', '.join(map(str, paths))}")
    return 0


def _figure_file(text: str) -> str:
    """``--figure``: a .png, .pdf or .svg file name (its suffix is the format)."""
    import argparse

    if Path(text).suffix.lower() not in (".png", ".pdf", ".svg"):
        raise argparse.ArgumentTypeError(f"expected a .png, .pdf or .svg file name, found {text!r}")
    return text


def cmd_penetration(args) -> int:
    from ..contact.penetration import parse_region, penetration_report, region_faces
    from ..geometry.meshio import read_mesh, read_mesh_like

    V, F = read_mesh(args.mesh)
    refs = [read_mesh_like(r, len(V), F, str(args.mesh)) for r in args.reference]
    face_mask = region_faces(F, parse_region(args.region, len(V))) if args.region else None
    rest, within = None, None
    if args.rest is not None:
        from ..geometry.mesh import median_edge_length

        rest = read_mesh_like(args.rest, len(V), F, str(args.mesh))
        if not (args.local_within > 0):
            from ..errors import InputError

            raise InputError(f"--local-within: expected a positive number of edge lengths, found {args.local_within}")
        within = args.local_within * median_edge_length(rest, F)
    rep = penetration_report(V, F, refs, face_mask, rest=rest, local_within=within)
    where = f" in region {args.region} ({int(face_mask.sum())} triangles)" if face_mask is not None else ""
    print(f"{args.mesh}: {len(rep.pairs)} intersecting triangle pairs{where}")
    if refs:
        print(f"  new relative to {len(refs)} reference(s): {len(rep.new)}")
    if rest is not None:
        print(f"  {'new' if refs else 'all'}: {rep.count(local=False)} layer crossings, {rep.count(local=True)} local folds "
              f"(triangles within {args.local_within:g} median edges = {within:.4g} along {args.rest})")
    shown = rep.new if refs else rep.pairs
    for a, b in shown[: args.show].tolist():
        print(f"  triangles {a} {F[a].tolist()} x {b} {F[b].tolist()}")
    return 0


def register(sub) -> None:
    """Add this group's subcommands to the ``facebasis`` parser."""
    from ..contact.penetration import LOCAL_FOLD_EDGES
    from ..contact.virtual_edges import DEFAULT_CAP_EDGES, DEFAULT_PER_VERTEX, DEFAULT_RATIO, DEFAULT_SPACING_EDGES

    p = sub.add_parser("virtual-edges", help="detect virtual edges across thin layers (Li et al. 2023)")
    p.add_argument("mesh", help="neutral mesh (.obj/.ply)")
    p.add_argument("--out", required=True, help="output EDGES.json")
    p.add_argument("--cap", type=float, default=None, help=f"Euclidean cap in mesh units (default {DEFAULT_CAP_EDGES:g} median edge lengths)")
    p.add_argument("--ratio", type=float, default=DEFAULT_RATIO, help=f"geodesic/Euclidean floor (default {DEFAULT_RATIO:g})")
    p.add_argument("--per-vertex", type=int, default=DEFAULT_PER_VERTEX,
                   help=f"edges kept per vertex (default {DEFAULT_PER_VERTEX})")
    p.add_argument("--spacing", type=float, default=None,
                   help=f"exclusion radius around chosen ends, mesh units (default {DEFAULT_SPACING_EDGES:g} median "
                        "edge lengths; 0: no exclusion)")
    p.add_argument("--region", default=None, metavar="START:END", help="only vertices START..END-1 as ends")
    p.add_argument("--figure", default=None, metavar="FIGURE.png", type=_figure_file,
                   help="also draw the edges over the mesh (.png, .pdf or .svg)")
    p.set_defaults(func=cmd_virtual_edges,
                   outputs=Outputs(writes=(("out", "file", "--out"), ("figure", "file", "--figure")), reads=("mesh",)))

    p = sub.add_parser("penetration", help="count intersecting triangle pairs exactly")
    p.add_argument("mesh", help="mesh to check")
    p.add_argument("--reference", action="append", default=[], metavar="REF",
                   help="same-topology mesh whose intersecting pairs are not new (repeatable)")
    p.add_argument("--region", default=None, metavar="START:END", help="only triangles with all vertices in START..END-1")
    p.add_argument("--rest", default=None, metavar="REST",
                   help="rest mesh (e.g. the target neutral): split the pairs into local folds and layer crossings")
    p.add_argument("--local-within", type=float, default=LOCAL_FOLD_EDGES, metavar="K",
                   help="with --rest: triangles closer than K median edge lengths along REST are a local fold "
                        f"(default {LOCAL_FOLD_EDGES:g})")
    p.add_argument("--show", type=int, default=10, help="list this many pairs (default 10)")
    p.set_defaults(func=cmd_penetration, outputs=READS_ONLY)
