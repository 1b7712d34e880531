"""Virtual edges (seed 004): detection, the energy in transfer and generation, the penetration counter."""

import json

import numpy as np
import pytest

from conftest import grid_sheet, requires_ict
from facebasis.cli import main
from facebasis.errors import InputError
from facebasis.geometry.meshio import read_mesh, write_mesh
from facebasis.contact.penetration import (intersecting_pairs, orient3d, penetration_report, triangle_pairs_intersect,
                                   triangle_surface_distance)
from facebasis.geometry.rig import Rig
from facebasis.geometry.transfer import DeformationTransfer
from facebasis.contact.virtual_edges import VirtualEdges, detect_virtual_edges, virtual_edge_targets


def folded_strip(gap=1.0, length=4.0, width=2.0, n_len=17, n_arc=7, n_wid=6):
    """A thin two-layer patch: a strip folded into a U (bottom layer z = 0, top layer z = gap,
    joined by a half circle at x = length), open at x = 0. Returns V (n, 3), F (m, 3), layer id."""
    xs = np.linspace(0.0, length, n_len)
    th = np.linspace(0.0, np.pi, n_arc)[1:-1]
    path = [(x, 0.0, 0) for x in xs]
    path += [(length + 0.5 * gap * np.sin(t), 0.5 * gap * (1 - np.cos(t)), 1) for t in th]
    path += [(x, gap, 2) for x in xs[::-1]]
    ys = np.linspace(0.0, width, n_wid)
    V = np.array([[px, y, pz] for px, pz, _ in path for y in ys])
    layer = np.repeat([lab for _, _, lab in path], n_wid)
    F = []
    for i in range(len(path) - 1):
        for j in range(n_wid - 1):
            a, b, c, d = i * n_wid + j, i * n_wid + j + 1, (i + 1) * n_wid + j, (i + 1) * n_wid + j + 1
            F += [(a, c, b), (b, c, d)]
    return V, np.array(F), layer


def press_rig(gap):
    """Template: the folded strip whose top layer is pressed 0.8 (template gap 1.0) toward the
    bottom at the open end, smoothly (still at the fold, which anchors the translation)."""
    V, F, layer = folded_strip(gap=1.0)
    top = layer == 2
    d = np.zeros_like(V)
    d[top, 2] = -0.8 * (1.0 - V[top, 0] / 4.0) ** 2
    rig = Rig(V, F, ("press",), d[None])
    target, _, _ = folded_strip(gap=gap)
    return rig, target, layer


# --- detection -------------------------------------------------------------------------------

def test_detection_finds_pairs_across_the_gap_and_none_on_a_flat_sheet():
    V, F, layer = folded_strip(gap=0.5)
    ve = detect_virtual_edges(V, F, cap=0.8, ratio=2.0)
    assert len(ve) > 0
    # every edge joins the two layers (never within a layer, never the fold)
    assert np.all(np.sort(layer[ve.edges], axis=1) == [0, 2])
    assert np.all(ve.euclidean < 0.8) and np.all(ve.geodesic >= 2.0 * ve.euclidean)
    assert np.all(np.bincount(ve.edges.ravel(), minlength=len(V)) <= ve.per_vertex)
    Vf, Ff = grid_sheet(12, 12, size=3.0)
    flat = detect_virtual_edges(Vf, Ff, cap=0.8, ratio=2.0)
    assert len(flat) == 0 and flat.candidates == 0


def test_thinning_spreads_the_edges():
    V, F, layer = folded_strip(gap=0.5)
    dense = detect_virtual_edges(V, F, cap=0.8, ratio=2.0, spacing=0.0, per_vertex=5)
    thin = detect_virtual_edges(V, F, cap=0.8, ratio=2.0, spacing=0.6, per_vertex=5)
    assert len(thin) < len(dense)
    # after thinning no two edges start within the spacing of each other, except at a shared end
    ends = thin.edges.ravel()
    D = np.linalg.norm(V[ends][:, None] - V[ends][None], axis=2)
    same = ends[:, None] == ends[None]
    assert np.all((D >= 0.6) | same | (D == 0) | (np.arange(len(ends))[:, None] // 2 == np.arange(len(ends))[None] // 2))


def test_region_mask_restricts_the_ends():
    V, F, layer = folded_strip(gap=0.5)
    mask = V[:, 1] < 1.0
    ve = detect_virtual_edges(V, F, cap=0.8, ratio=2.0, vertex_mask=mask)
    assert len(ve) > 0 and mask[ve.edges].all()


def _check_geodesic_decisions(V, F, n_sources=12):
    """For every candidate pair of a sample of source vertices (half of them ends of chosen
    edges), compare the graph-based decision g >= ratio * d with exact geodesics (pygeodesic: the
    exact MMP algorithm): graph distances never underestimate, at least 97% of the decisions agree
    (the rest sit on fans of skinny triangles, where graph paths overestimate by up to ~25%) and
    every chosen edge passes with exact geodesics, or misses the floor by less than 8%. Returns
    the median overestimate."""
    pygeodesic = pytest.importorskip("pygeodesic.geodesic")
    from scipy.spatial import cKDTree

    from facebasis.contact.geodesics import geodesic_pair_distances

    ve = detect_virtual_edges(V, F)
    rng = np.random.default_rng(0)
    sources = np.concatenate([rng.choice(np.unique(ve.edges), n_sources // 2, replace=False),
                              rng.choice(len(V), n_sources - n_sources // 2, replace=False)])
    tree = cKDTree(V)
    algo = pygeodesic.PyGeodesicAlgorithmExact(V, F.astype(np.int32))
    sample, g_exact = [], []
    for s in sources:
        partners = np.array([j for j in tree.query_ball_point(V[s], ve.cap) if j != s])
        dist, _ = algo.geodesicDistances(np.array([s], dtype=np.int32))
        sample += [(s, j) for j in partners]
        g_exact += list(np.asarray(dist)[partners])
    sample = np.array(sample)
    g_exact = np.array(g_exact)
    g_exact[~np.isfinite(g_exact) | (g_exact < 0)] = np.inf
    d = np.linalg.norm(V[sample[:, 0]] - V[sample[:, 1]], axis=1)
    g_graph = geodesic_pair_distances(V, F, sample, limit=ve.ratio * ve.cap * 1.5)
    assert np.all(g_graph >= g_exact * (1 - 1e-9))  # graph paths are never shorter than geodesics
    ratio = ve.ratio
    agree = (g_graph >= ratio * d) == (g_exact >= ratio * d)
    assert agree.mean() >= 0.97, f"{(~agree).sum()} of {len(agree)} decisions differ"
    # every chosen edge in the sample also passes with exact geodesics
    key = set(map(tuple, np.sort(ve.edges, axis=1).tolist()))
    chosen = np.array([tuple(sorted(p)) in key for p in sample.tolist()])
    assert chosen.sum() >= 1
    near_threshold = g_exact >= 0.92 * ratio * d  # exact ratio within 8% below the floor
    assert np.all(near_threshold[chosen]), sample[chosen & ~near_threshold]
    fin = np.isfinite(g_exact) & np.isfinite(g_graph)
    return float(np.median(g_graph[fin] / g_exact[fin]))


def test_geodesic_decisions_match_exact_geodesics_on_the_builtin_face():
    from facebasis.defaults.face import default_template

    rig = default_template()
    _check_geodesic_decisions(rig.neutral, rig.faces)


@requires_ict
def test_geodesic_decisions_match_exact_geodesics_on_ict():
    from problems.ict import ict_rig

    rig = ict_rig()
    overestimate = _check_geodesic_decisions(rig.neutral, rig.faces)
    assert overestimate < 1.05


def test_edges_json_round_trip_and_errors(tmp_path):
    V, F, _ = folded_strip(gap=0.5)
    ve = detect_virtual_edges(V, F, cap=0.8)
    ve.write(tmp_path / "e.json")
    back = VirtualEdges.read(tmp_path / "e.json", len(V))
    assert np.array_equal(back.edges, ve.edges) and back.ratio == ve.ratio
    with pytest.raises(InputError, match=f"expected edges for a mesh of 5 vertices, found {len(V)}"):
        VirtualEdges.read(tmp_path / "e.json", 5)
    (tmp_path / "bad.json").write_text(json.dumps({"n_vertices": 4, "edges": [[0, 9]]}))
    with pytest.raises(InputError, match=r"expected vertex indices in \[0, 4\), found 0..9"):
        VirtualEdges.read(tmp_path / "bad.json")
    (tmp_path / "self.json").write_text(json.dumps({"n_vertices": 4, "edges": [[1, 1]]}))
    with pytest.raises(InputError, match="expected edges between two different vertices"):
        VirtualEdges.read(tmp_path / "self.json")
    for name, body, message in (
            ("float.json", {"n_vertices": 4, "edges": [[0.5, 2]]}, r"edges as integer pairs \[\[u, v\], ...\], found float64"),
            ("flat.json", {"n_vertices": 4, "edges": [0, 1, 2, 3]}, r"found int64 values of shape \(4,\)"),
            ("twice.json", {"n_vertices": 4, "edges": [[0, 2], [1, 3], [2, 0]]},
             r"expected each edge once, found 1 listed more than once \(e.g. \[0, 2\]\)"),
            ("lengths.json", {"n_vertices": 4, "edges": [[0, 2], [1, 3]], "euclidean": [1.0]},
             r"'euclidean' with one value per edge \(2\), found 1")):
        (tmp_path / name).write_text(json.dumps(body))
        with pytest.raises(InputError, match=message):
            VirtualEdges.read(tmp_path / name)
    (tmp_path / "junk.json").write_text("[1, 2")
    with pytest.raises(InputError, match="expected a virtual-edges JSON"):
        VirtualEdges.read(tmp_path / "junk.json")
    with pytest.raises(InputError, match="found no such file"):
        VirtualEdges.read(tmp_path / "missing.json")


def test_detection_parameter_errors():
    V, F, _ = folded_strip()
    with pytest.raises(InputError, match="ratio: expected a geodesic/Euclidean floor > 1, found 0.5"):
        detect_virtual_edges(V, F, ratio=0.5)
    with pytest.raises(InputError, match="cap: expected a positive distance, found -1"):
        detect_virtual_edges(V, F, cap=-1.0)
    with pytest.raises(InputError, match="per_vertex: expected >= 1, found 0"):
        detect_virtual_edges(V, F, per_vertex=0)
    with pytest.raises(InputError, match=r"vertex_mask: expected shape \(\d+,\), found \(3,\)"):
        detect_virtual_edges(V, F, vertex_mask=np.ones(3, bool))


# --- energy ----------------------------------------------------------------------------------

@pytest.mark.parametrize("mode", ["gradient", "proportional"])
def test_virtual_edges_stop_a_press_from_crossing_the_layers(mode):
    """Template gap 1.0 pressed by 0.8; target gap 0.4. Plain transfer tilts the top layer by the
    template's angle and pushes it through the bottom one; with virtual edges it stays above:
    gradient targets keep most of the gap, proportional ones press by 0.8 x 0.4 of it."""
    rig, target, layer = press_rig(gap=0.4)
    V, F = rig.neutral, rig.faces
    ve = detect_virtual_edges(V, F, cap=1.2, ratio=2.0)
    plain = DeformationTransfer(rig, target).transfer()
    guarded = DeformationTransfer(rig, target, virtual_edges=ve, virtual_mode=mode).transfer()
    X_plain = target + plain.deltas[0]
    X_ve = target + guarded.deltas[0]
    top_open_end = (layer == 2) & (V[:, 0] < 0.3)
    assert len(intersecting_pairs(X_plain, F)) > 0
    assert np.all(X_plain[top_open_end, 2] < 0.0)
    assert len(intersecting_pairs(X_ve, F)) == 0
    assert np.all(X_ve[top_open_end, 2] > 0.0)
    if mode == "gradient":
        assert np.all(X_ve[top_open_end, 2] > 0.3)
    else:  # the expression is kept, scaled to the thinner gap
        assert np.all(X_ve[top_open_end, 2] < 0.2)


def test_proportional_virtual_edges_change_nothing_on_the_templates_own_neutral():
    rig, _, _ = press_rig(gap=1.0)
    ve = detect_virtual_edges(rig.neutral, rig.faces, cap=1.2)
    T = virtual_edge_targets(ve, rig.neutral, rig.deltas, rig.neutral, rig.faces, mode="proportional")
    E = ve.edges
    assert np.allclose(T[0], rig.deltas[0][E[:, 1]] - rig.deltas[0][E[:, 0]], atol=1e-12)
    out = DeformationTransfer(rig, rig.neutral, virtual_edges=ve).transfer()
    assert np.abs(out.deltas - rig.deltas).max() <= 1e-10
    # the gradient targets resist the press the template itself makes: self-transfer changes
    grad = DeformationTransfer(rig, rig.neutral, virtual_edges=ve, virtual_mode="gradient").transfer()
    assert np.abs(grad.deltas - rig.deltas).max() > 1e-3


def test_virtual_edge_targets_from_precomputed_frames_are_the_same():
    from facebasis.geometry.gradients import frames_cm

    rig, target, _ = press_rig(gap=0.4)
    F = rig.faces
    ve = detect_virtual_edges(rig.neutral, F, cap=1.2)
    A0 = frames_cm(rig.neutral, F)
    dA = frames_cm(rig.neutral + rig.deltas, F) - A0
    for mode in ("proportional", "gradient"):
        fresh = virtual_edge_targets(ve, rig.neutral, rig.deltas, target, F, mode)
        assert np.array_equal(virtual_edge_targets(ve, rig.neutral, rig.deltas, target, F, mode, A0, dA), fresh)
        assert np.array_equal(virtual_edge_targets(ve, rig.neutral, rig.deltas, target, F, mode, A0), fresh)
        # transfer() computes the frames once for both the edge targets and the virtual edges
        dt = DeformationTransfer(rig, target, virtual_edges=ve, virtual_mode=mode)
        cols = np.ascontiguousarray(np.moveaxis(fresh, 2, 1)).reshape(3 * len(rig.deltas), -1)
        manual = dt.solve_frame_deltas(dt.transferred_frame_deltas(), dt.anchor_values(), cols)
        assert np.array_equal(dt.transfer().deltas, manual)


def test_transfer_rejects_mismatched_virtual_edges():
    rig, target, _ = press_rig(gap=0.4)
    Vf, Ff = grid_sheet(12, 12, size=3.0)
    other = VirtualEdges(np.array([[0, 1]]), np.ones(1), np.ones(1), len(Vf), 1.0, 2.0, 4, 0.0)
    with pytest.raises(InputError, match=f"expected a mesh of {rig.n_vertices} vertices, found edges for {len(Vf)}"):
        DeformationTransfer(rig, target, virtual_edges=other)
    ve = detect_virtual_edges(rig.neutral, rig.faces, cap=1.2)
    with pytest.raises(InputError, match="virtual edge weight: expected a positive number, found 0"):
        DeformationTransfer(rig, target, virtual_edges=ve, virtual_weight=0.0)
    with pytest.raises(InputError, match=r"virtual edge mode: expected one of \('proportional', 'gradient'\), found 'x'"):
        DeformationTransfer(rig, target, virtual_edges=ve, virtual_mode="x")


# --- penetration counter ---------------------------------------------------------------------

def _brute_force_pairs(V, F):
    m = len(F)
    i, j = np.triu_indices(m, 1)
    disjoint = ~(F[i][:, :, None] == F[j][:, None, :]).any(axis=(1, 2))
    i, j = i[disjoint], j[disjoint]
    hit = triangle_pairs_intersect(V[F[i]], V[F[j]])
    return set(zip(i[hit].tolist(), j[hit].tolist()))


@pytest.mark.parametrize("seed", range(4))
def test_counter_agrees_with_brute_force_on_small_meshes(seed):
    rng = np.random.default_rng(seed)
    rig, target, _ = press_rig(gap=0.4)
    X = target + DeformationTransfer(rig, target).transfer().deltas[0]
    X = X + 0.05 * rng.standard_normal(X.shape)  # crumpled: many crossings in all directions
    fast = set(map(tuple, intersecting_pairs(X, rig.faces).tolist()))
    assert fast == _brute_force_pairs(X, rig.faces)
    assert len(fast) > 0


def test_counter_agrees_with_libigl_cgal():
    igl_cgal = pytest.importorskip("igl.copyleft.cgal")
    rig, target, _ = press_rig(gap=0.4)
    F = rig.faces
    X = target + DeformationTransfer(rig, target).transfer().deltas[0]
    _, _, IF, _, _ = igl_cgal.remesh_self_intersections(X, F.astype(np.int64), detect_only=True)
    IF = np.sort(np.asarray(IF), axis=1)
    shared = (F[IF[:, 0]][:, :, None] == F[IF[:, 1]][:, None, :]).any(axis=(1, 2))
    ref = set(map(tuple, np.unique(IF[~shared], axis=0).tolist()))
    assert set(map(tuple, intersecting_pairs(X, F).tolist())) == ref and len(ref) > 0


def test_exact_predicates_on_degenerate_configurations():
    # coplanar, touching at a point, sharing nothing: counted (closed sets)
    T1 = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], float)
    T2 = np.array([[[1, 0, 0.0], [2, 0, 0], [1, 1, 0]]], float)  # touches T1 at (1, 0, 0)
    T3 = np.array([[[1.0 + 2 ** -40, 0, 0], [2, 0, 0], [1, 1, 0]]], float)  # misses by 2^-40
    assert triangle_pairs_intersect(T1, T2)[0] and not triangle_pairs_intersect(T1, T3)[0]
    # an edge lying in the other triangle's plane, crossing it
    T4 = np.array([[[0.2, 0.2, 0.0], [0.2, -1, 0.0], [0.2, 0.2, 1.0]]], float)
    assert triangle_pairs_intersect(T1, T4)[0]
    # orientation exactly zero for coplanar points with huge coordinates, where float cancels
    a, b, c = np.array([1e16, 1, 0.0]), np.array([1e16 + 2, 3, 0.0]), np.array([1e16 + 4, 7, 0.0])
    assert orient3d(a, b, c, np.array([1e16 + 8, 11, 0.0])) == 0
    assert orient3d(a, b, c, np.array([1e16 + 8, 11, 2.0 ** -30])) != 0


def test_penetration_report_new_pairs_and_zones():
    rig, target, layer = press_rig(gap=0.4)
    F = rig.faces
    X = target + DeformationTransfer(rig, target).transfer().deltas[0]
    rep = penetration_report(X, F, references=[target], zones={"top": layer == 2})
    assert len(rep.new) == len(rep.pairs) > 0
    assert rep.zones["top"] == len(rep.new) and rep.zones["elsewhere"] == 0
    rep2 = penetration_report(X, F, references=[X])
    assert len(rep2.new) == 0


def tucked_strip():
    """A flat strip (rest) and a copy tucked under itself: column 3 is pulled back under column 0..1
    and the rest of the strip laid back over it, so triangles two columns apart along the surface
    cross (a local fold, no second layer)."""
    V, F = grid_sheet(10, 4, size=2.25)
    step = V[1, 0] - V[0, 0]
    col = np.rint(V[:, 0] / step).astype(int)
    X = V.copy()
    X[col == 3] = np.c_[np.full((col == 3).sum(), 0.5 * step), V[col == 3, 1], np.full((col == 3).sum(), -0.2 * step)]
    X[col >= 4, 0] = (col[col >= 4] - 3) * step
    X[col >= 4, 2] = 0.2 * step
    return V, X, F, step


def test_penetration_report_tells_local_folds_from_layer_crossings():
    V, X, F, step = tucked_strip()
    fold = penetration_report(X, F, references=[V], rest=V, local_within=4 * step)
    assert len(fold.new) > 0 and fold.local.all() and fold.count(local=True) == len(fold.new)
    # two vertex-disjoint triangles are at least one edge apart along the surface
    assert not penetration_report(X, F, references=[V], rest=V, local_within=0.8 * step).local.any()
    assert np.all(triangle_surface_distance(V, F, fold.new, np.inf) >= step - 1e-12)
    # the pressed two-layer strip: the layers are far apart along the surface (around the fold)
    rig, target, layer = press_rig(gap=0.4)
    Xp = target + DeformationTransfer(rig, target).transfer().deltas[0]
    press = penetration_report(Xp, rig.faces, references=[target], rest=target, local_within=1.0,
                               zones={"top": layer == 2})
    assert len(press.new) > 0 and press.count(local=False) == len(press.new) == press.count("top", local=False)


def test_penetration_report_errors():
    V, X, F, step = tucked_strip()
    with pytest.raises(InputError, match="expected rest and local_within together, found only rest"):
        penetration_report(X, F, rest=V)
    with pytest.raises(InputError, match="expected rest and local_within together, found only local_within"):
        penetration_report(X, F, local_within=1.0)
    with pytest.raises(InputError, match="local_within: expected a positive distance, found -1"):
        penetration_report(X, F, rest=V, local_within=-1.0)
    with pytest.raises(InputError, match=r"rest: expected vertices of shape \(40, 3\), found \(39, 3\)"):
        penetration_report(X, F, rest=V[:-1], local_within=1.0)
    rep = penetration_report(X, F, references=[V], zones={"a": np.ones(len(V), bool)})
    with pytest.raises(InputError, match="zone: expected one of \\['a', 'elsewhere'\\], found 'lids'"):
        rep.count("lids")
    with pytest.raises(InputError, match="made without a rest surface"):
        rep.count(local=True)
    assert rep.count("a") == len(rep.new) > 0 and rep.count("elsewhere") == 0


# --- CLI ---------------------------------------------------------------------------------------

def test_cli_virtual_edges_penetration_and_transfer(tmp_path, capsys):
    from facebasis.geometry.rig import write_rig_folder

    rig, target, _ = press_rig(gap=0.4)
    write_rig_folder(tmp_path / "tpl", rig)
    write_mesh(tmp_path / "target.obj", target, rig.faces)
    assert main(["virtual-edges", str(tmp_path / "tpl" / "neutral.obj"), "--out", str(tmp_path / "e.json"),
                 "--cap", "1.2", "--figure", str(tmp_path / "e.png")]) == 0
    assert (tmp_path / "e.png").is_file()
    n = len(json.loads((tmp_path / "e.json").read_text())["edges"])
    assert f"{n} virtual edges" in capsys.readouterr().out
    for extra, name in (([], "plain"), (["--virtual-edges", str(tmp_path / "e.json")], "ve")):
        assert main(["transfer", "--template", str(tmp_path / "tpl"), "--target", str(tmp_path / "target.obj"),
                     "--out", str(tmp_path / name)] + extra) == 0
    capsys.readouterr()
    assert main(["penetration", str(tmp_path / "plain" / "press.obj"), "--reference", str(tmp_path / "target.obj")]) == 0
    out = capsys.readouterr().out
    assert "new relative to 1 reference(s): 0" not in out
    assert main(["penetration", str(tmp_path / "ve" / "press.obj")]) == 0
    assert ": 0 intersecting triangle pairs" in capsys.readouterr().out
    # the pressed layers cross far from each other along the surface: layer crossings, no local folds
    n_new = len(penetration_report(read_mesh(tmp_path / "plain" / "press.obj")[0], rig.faces, references=[target]).new)
    assert main(["penetration", str(tmp_path / "plain" / "press.obj"), "--reference", str(tmp_path / "target.obj"),
                 "--rest", str(tmp_path / "target.obj")]) == 0
    assert f"new: {n_new} layer crossings, 0 local folds (triangles within 2 median edges" in capsys.readouterr().out
    assert main(["penetration", str(tmp_path / "plain" / "press.obj"), "--rest", str(tmp_path / "target.obj"),
                 "--local-within", "0"]) == 2
    assert "--local-within: expected a positive number of edge lengths, found 0" in capsys.readouterr().err
    write_mesh(tmp_path / "small.obj", target[:-3], rig.faces[:1])
    assert main(["penetration", str(tmp_path / "plain" / "press.obj"), "--rest", str(tmp_path / "small.obj")]) == 2
    assert f"small.obj: expected {len(target)} vertices" in capsys.readouterr().err
    assert main(["penetration", str(tmp_path / "ve" / "press.obj"), "--region", "5:2"]) == 2
    assert "--region: expected 0 <= START < END" in capsys.readouterr().err


@requires_ict
def test_ict_detection_catches_lips_and_lids():
    from problems.ict import ict_rig, ict_zones

    rig = ict_rig()
    ve = detect_virtual_edges(rig.neutral, rig.faces)
    zones = ict_zones()
    E = ve.edges
    assert zones["lips"][E].all(1).sum() >= 100
    assert zones["lids"][E].all(1).sum() >= 20


def test_penetration_figure_draws_layer_crossings_red_and_local_folds_orange(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from facebasis.report.render import HIGHLIGHT2_RGB, HIGHLIGHT_RGB, draw_mesh
    from facebasis.report.run_report import penetration_figure

    V, X, F, step = tucked_strip()
    rep = penetration_report(X, F, references=[V], rest=V, local_within=4 * step)
    local_tris = np.unique(rep.new[rep.local].ravel())
    crossing = np.zeros(len(F), bool)
    crossing[:2] = True
    folds = np.zeros(len(F), bool)
    folds[local_tris] = True
    fig, ax = plt.subplots()
    coll = draw_mesh(ax, X, F, view=(0.0, 0.0), highlight=crossing, highlight2=folds)
    colors = coll.get_facecolors()[:, :3]
    n_red = int(np.isclose(colors, HIGHLIGHT_RGB).all(1).sum())
    n_orange = int(np.isclose(colors, HIGHLIGHT2_RGB).all(1).sum())
    plt.close(fig)
    assert n_red == 2 and n_orange == int((folds & ~crossing).sum()) > 0
    data = {"faces": F, "names": ["tuck"], "crops": {"strip": ((0.0, 0.0), ((-1, 3), (-1, 3)))},
            "tuck/plain": X, "tuck/ve": V, "tuck/plain_hits": np.zeros(0, np.int64),
            "tuck/plain_local_hits": local_tris, "tuck/ve_hits": np.zeros(0, np.int64)}
    paths = penetration_figure(data, tmp_path, formats=("png",))
    assert [p.name for p in paths] == ["penetration_closeups.png"] and paths[0].stat().st_size > 0
