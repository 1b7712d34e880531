"""Run inside Blender (``blender -b --factory-startup --python blender_inspect.py -- FILE.glb OUT.json``):
import a glTF file with Blender's own importer and write what an artist would see as JSON.

Debian's Blender 3.4 importer uses ``numpy.bool``, which NumPy 1.24+ removed: aliased here.
"""
import json
import sys

import numpy

if not hasattr(numpy, "bool"):
    numpy.bool = bool

import bpy  # noqa: E402

argv = sys.argv[sys.argv.index("--") + 1:]
src, out = argv[0], argv[1]
bpy.ops.wm.read_factory_settings(use_empty=True)
result = bpy.ops.import_scene.gltf(filepath=src)
report = {"result": sorted(result), "objects": []}
scene = bpy.context.scene
for ob in bpy.data.objects:
    entry = {"name": ob.name, "type": ob.type, "dimensions": list(ob.dimensions), "location": list(ob.location),
             "rotation_mode": ob.rotation_mode, "fcurves": [], "shape_key_fcurves": []}
    if ob.animation_data and ob.animation_data.action:
        for fc in ob.animation_data.action.fcurves:
            entry["fcurves"].append({"data_path": fc.data_path, "index": fc.array_index,
                                     "keys": [[k.co[0], k.co[1]] for k in fc.keyframe_points]})
    if ob.type == "MESH":
        me = ob.data
        entry["vertices"] = len(me.vertices)
        entry["polygons"] = len(me.polygons)
        entry["uv_layers"] = [uv.name for uv in me.uv_layers]
        entry["materials"] = []
        for mat in me.materials:
            if mat is None:
                continue
            images = []
            if mat.use_nodes:
                images = [n.image.name for n in mat.node_tree.nodes if n.type == "TEX_IMAGE" and n.image]
            entry["materials"].append({"name": mat.name, "images": images})
        keys = me.shape_keys
        entry["shape_keys"] = [kb.name for kb in keys.key_blocks] if keys else []
        if keys and keys.animation_data and keys.animation_data.action:
            for fc in keys.animation_data.action.fcurves:
                entry["shape_key_fcurves"].append({"data_path": fc.data_path,
                                                   "keys": [[k.co[0], k.co[1]] for k in fc.keyframe_points]})
        # the mesh's height in the world (metres) at the rest pose
        zs = [(ob.matrix_world @ v.co) for v in me.vertices]
        if zs:
            entry["world_extent"] = [max(c[i] for c in zs) - min(c[i] for c in zs) for i in range(3)]
    report["objects"].append(entry)
report["fps"] = scene.render.fps
with open(out, "w") as fh:
    json.dump(report, fh)
