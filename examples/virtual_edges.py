"""Virtual edges on the built-in face (Li, Shen, Liu 2023): pairs of vertices close in space but far
apart along the surface (the lips, the lids), found by comparing graph geodesics with straight
distances, and drawn over the mesh."""

from _common import output_folder
from facebasis.contact.virtual_edges import detect_virtual_edges
from facebasis.defaults.face import default_template
from facebasis.report.figures import virtual_edges_figure

out = output_folder(__file__)
rig = default_template()
ve = detect_virtual_edges(rig.neutral, rig.faces)
print(f"{len(ve.edges)} virtual edges on a face of {rig.n_vertices} vertices")
virtual_edges_figure(rig.neutral, rig.faces, ve.edges, out / "virtual_edges", title="built-in face",
                     formats=("png",))
print(f"figure: {out / 'virtual_edges.png'}")
