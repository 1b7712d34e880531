"""Run inside Blender (``blender -b --factory-startup --python blender_inspect.py -- OUT.json FILE.glb ...``):
import each glTF file (``.glb`` or ``.gltf``) into an empty scene with Blender's own importer and
write what an artist would see as JSON: ``{file: report}``.

Debian's Blender 3.4 importer uses ``numpy.bool``, which NumPy 1.24+ removed: aliased here.
"""
import json
import sys

argv = sys.argv[sys.argv.index("--") + 1:]
try:
    import numpy
except ImportError:  # Blender's Python without NumPy (Debian: python3-numpy): its glTF importer cannot run
    with open(argv[0], "w") as fh:
        json.dump({"__skip__": "Blender's Python has no NumPy (apt-get install python3-numpy)"}, fh)
    sys.exit(0)

if not hasattr(numpy, "bool"):
    numpy.bool = bool

import bpy  # noqa: E402

out, files = argv[0], argv[1:]


def inspect(src):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    result = bpy.ops.import_scene.gltf(filepath=src)
    report = {"result": sorted(result), "objects": []}
    for ob in bpy.data.objects:
        entry = {"name": ob.name, "type": ob.type, "dimensions": list(ob.dimensions), "location": list(ob.location),
                 "rotation_mode": ob.rotation_mode, "fcurves": [], "shape_key_fcurves": []}
        if ob.animation_data and ob.animation_data.action:
            for fc in ob.animation_data.action.fcurves:
                entry["fcurves"].append({"data_path": fc.data_path, "index": fc.array_index,
                                         "keys": [list(k.co) for k in fc.keyframe_points]})
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
                                                       "keys": [list(k.co) for k in fc.keyframe_points]})
            co = [ob.matrix_world @ v.co for v in me.vertices]
            entry["world_extent"] = [max(c[i] for c in co) - min(c[i] for c in co) for i in range(3)] if co else []
        report["objects"].append(entry)
    report["fps"] = bpy.context.scene.render.fps
    return report


reports = {}
for f in files:
    try:
        reports[f] = inspect(f)
    except Exception as exc:  # noqa: BLE001 - reported to the test, which fails on it
        reports[f] = {"error": f"{type(exc).__name__}: {exc}"}
with open(out, "w") as fh:
    json.dump(reports, fh)
