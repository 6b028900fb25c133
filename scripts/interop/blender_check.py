"""Blender (headless) on the files we write.

Usage: blender -b --factory-startup --python-exit-code 1 --python blender_check.py --
       MESH_INFO.json LEVEL.vdb... -- MESH.(ply|glb|obj)...
Every level file is imported as a volume object: grids mask, density (FLOAT),
P, N, Cd (VECTOR_FLOAT), bounds on top of the exemplar (MESH_INFO.json is
`shapeshifter info --json` of the exemplar mesh). Every mesh is imported with
Blender's own importers and must carry vertex colours and sit on top of the
exemplar too; a baked light mesh (mesh.obj, and the mesh.glb beside a
mesh_basecolor.png) must carry a loaded base-colour texture and UVs instead."""
import json
import os
import sys

import bpy
import numpy
from mathutils import Vector

# Blender 3.4's glTF importer uses numpy.bool, which Debian 12's numpy 1.24
# removed: every glTF import fails without this alias (a Blender/numpy
# mismatch, not a property of the file; the alias is what numpy.bool was).
if not hasattr(numpy, "bool"):
    numpy.bool = bool

args = sys.argv[sys.argv.index("--") + 1:]
info = json.load(open(args[0]))["outcomes"][0]["result"]
split = args.index("--", 1)
levels, meshes = args[1:split], args[split + 1:]
lo, hi = Vector(info["bbox_min"]), Vector(info["bbox_max"])
size = (hi - lo).length
EXPECTED = {"mask": "FLOAT", "density": "FLOAT", "P": "VECTOR_FLOAT", "N": "VECTOR_FLOAT", "Cd": "VECTOR_FLOAT"}


def fail(msg):
    print(f"interop: blender: FAIL {msg}")
    sys.exit(1)


def world_bounds(obj):
    corners = [obj.matrix_world @ Vector(c) for c in obj.bound_box]
    return (Vector([min(c[i] for c in corners) for i in range(3)]),
            Vector([max(c[i] for c in corners) for i in range(3)]))


def on_top(name, a, b, tolerance):
    """a..b inside the exemplar's bounds grown by `tolerance` (world units)."""
    for i in range(3):
        if a[i] < lo[i] - tolerance or b[i] > hi[i] + tolerance:
            fail(f"{name}: bounds {tuple(a)}..{tuple(b)} not on the exemplar's {tuple(lo)}..{tuple(hi)}")


bpy.ops.wm.read_factory_settings(use_empty=True)
for path in levels:
    vol = bpy.data.volumes.new(os.path.basename(path))
    vol.filepath = path
    obj = bpy.data.objects.new(vol.name, vol)
    bpy.context.scene.collection.objects.link(obj)
    if not vol.grids.load():
        fail(f"{path}: grids do not load: {vol.grids.error_message}")
    types = {g.name: g.data_type for g in vol.grids}
    if types != EXPECTED:
        fail(f"{path}: grids {types}, expected {EXPECTED}")
    bpy.context.view_layer.update()
    a, b = world_bounds(obj)
    # Blender bounds a volume by its grids' leaf nodes (8^3 voxels), not by
    # the active voxels: up to 8 voxels of slack on each side.
    voxel = max(vol.grids[0].matrix_object.to_scale())
    on_top(path, a, b, 8 * voxel + 1e-4 * size)
print(f"interop: blender {bpy.app.version_string}: {len(levels)} level files import as volumes "
      f"(mask, density FLOAT; P, N, Cd VECTOR_FLOAT), bounds on the exemplar's")

for path in meshes:
    before = set(bpy.data.objects)
    if path.endswith(".glb"):
        bpy.ops.import_scene.gltf(filepath=path)
    elif path.endswith(".obj"):
        bpy.ops.import_scene.obj(filepath=path)
    else:
        bpy.ops.import_mesh.ply(filepath=path)
    new = [o for o in bpy.data.objects if o not in before and o.type == "MESH"]
    if len(new) != 1:
        fail(f"{path}: imported {len(new)} mesh objects")
    obj = new[0]
    me = obj.data
    if len(me.polygons) == 0:
        fail(f"{path}: no faces")
    # A baked mesh (mesh.obj, and mesh.glb beside a texture) carries its
    # colour as an image texture of its material, which must have loaded.
    images = [n.image for slot in obj.material_slots if slot.material and slot.material.use_nodes
              for n in slot.material.node_tree.nodes if n.type == "TEX_IMAGE" and n.image is not None]
    textured = path.endswith(".obj") or (path.endswith(".glb") and os.path.isfile(os.path.join(os.path.dirname(path), "mesh_basecolor.png")))
    if textured:
        if not images or images[0].size[0] == 0 or not me.uv_layers:
            fail(f"{path}: no loaded base-colour texture or no UVs after import")
    elif len(me.color_attributes) == 0:
        fail(f"{path}: no vertex colours after import")
    bpy.context.view_layer.update()
    a, b = world_bounds(obj)
    if path.endswith(".glb") or path.endswith(".obj"):
        # glTF is +Y up; Blender's importer turns it to +Z up: (x, y, z) -> (x, -z, y).
        a, b = Vector((a.x, b.z, -b.y)), Vector((b.x, a.z, -a.y))
        a, b = Vector([min(a[i], b[i]) for i in range(3)]), Vector([max(a[i], b[i]) for i in range(3)])
    on_top(path, a, b, 0.05 * size)
    shown = os.path.join(os.path.basename(os.path.dirname(path)), os.path.basename(path))
    if textured:
        colour = f"texture {images[0].size[0]}x{images[0].size[1]} on UV map '{me.uv_layers[0].name}'"
    else:
        attr = me.color_attributes[0]
        colour = f"colours '{attr.name}' ({attr.domain.lower()})"
    print(f"interop: blender: {shown}: {len(me.vertices)} vertices, {len(me.polygons)} faces, "
          f"{colour}, on the exemplar's bounds")
print(f"interop: blender: all {len(meshes)} meshes import with their colours (vertex colours or baked texture)")
