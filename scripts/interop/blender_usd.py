"""Blender imports a run's USD asset with its own USD importer.

Usage: python blender_usd.py RUN/variants.usda TRIANGLES [OUT.png]
with Blender as a Python module (PyPI's `bpy`, in its own virtual
environment: Debian 12's Blender 3.4 is built without USD support, its
`wm.usd_import` operator does not exist).

The default variant's mesh must arrive as a mesh object with TRIANGLES faces
(the default variant's mesh file), with a colour attribute (displayColor) or,
for a textured mesh, a material whose node tree holds an image texture that
loaded. With OUT.png, a Cycles picture of the imported mesh from the previews'
camera (azimuth 35, elevation 25, orthographic), for the README.
"""
import math
import sys

import bpy
import mathutils

args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
usd, triangles = args[0], int(args[1])
out = args[2] if len(args) > 2 else None


def fail(msg):
    print(f"interop: blender usd: FAIL {msg}")
    sys.exit(1)


bpy.ops.wm.read_factory_settings(use_empty=True)
result = bpy.ops.wm.usd_import(filepath=usd)
if "FINISHED" not in result:
    fail(f"usd_import returned {result}")
meshes = [o for o in bpy.context.scene.objects if o.type == "MESH"]
if not meshes:
    fail(f"no mesh object from {usd} (objects: {[o.name for o in bpy.context.scene.objects]})")
ob = max(meshes, key=lambda o: len(o.data.polygons))
faces = len(ob.data.polygons)
if faces != triangles:
    fail(f"{ob.name}: {faces} faces, the default variant's mesh has {triangles}")
colours = [a.name for a in ob.data.color_attributes]
images = []
for slot in ob.material_slots:
    if slot.material and slot.material.use_nodes:
        for node in slot.material.node_tree.nodes:
            if node.type == "TEX_IMAGE" and node.image is not None:
                if node.image.size[0] == 0:
                    fail(f"{ob.name}: texture {node.image.filepath} did not load")
                images.append(f"{node.image.name} {node.image.size[0]}x{node.image.size[1]}")
if not colours and not images:
    fail(f"{ob.name}: neither a colour attribute nor a texture")
print(f"interop: blender {bpy.app.version_string} imported {usd.split('/')[-1]} (default variant): mesh '{ob.name}' "
      f"{faces} faces as the mesh file, colour attributes {colours}, textures {images or 'none'}")

if out:
    scene = bpy.context.scene
    for o in list(scene.objects):
        if o is not ob:
            bpy.data.objects.remove(o)
    # Blender's importer keeps a Y-up stage's coordinates: stood up for the
    # picture (Blender is Z-up), as its glTF importer would.
    if "upAxis = \"Y\"" in open(usd).read(4096):
        ob.rotation_euler[0] = math.pi / 2
    scene.view_settings.view_transform = "Standard"
    if not images:
        # Vertex colours as the base colour (Blender's importer makes none).
        mat = bpy.data.materials.new("displayColor")
        mat.use_nodes = True
        attr = mat.node_tree.nodes.new("ShaderNodeAttribute")
        attr.attribute_name = colours[0]
        mat.node_tree.links.new(attr.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
        ob.data.materials.clear()
        ob.data.materials.append(mat)
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 16
    scene.cycles.device = "CPU"
    scene.cycles.use_denoising = False
    scene.render.resolution_x = scene.render.resolution_y = 640
    bpy.ops.object.camera_add()
    cam = bpy.context.object
    scene.camera = cam
    cam.data.type = "ORTHO"
    bpy.context.view_layer.update()
    vs = [ob.matrix_world @ ob.data.vertices[i].co for i in range(0, len(ob.data.vertices), 50)]
    lo = mathutils.Vector([min(v[k] for v in vs) for k in range(3)])
    hi = mathutils.Vector([max(v[k] for v in vs) for k in range(3)])
    centre, size = (lo + hi) / 2, max((hi - lo).length, 1e-6)
    cam.data.ortho_scale = size * 1.05
    az, el = math.radians(35), math.radians(25)
    d = mathutils.Vector((math.sin(az) * math.cos(el), -math.cos(az) * math.cos(el), math.sin(el)))
    cam.location = centre + d * size * 3
    cam.data.clip_end = size * 10
    cam.rotation_euler = (-d).to_track_quat("-Z", "Y").to_euler()
    bpy.ops.object.light_add(type="SUN")
    bpy.context.object.rotation_euler = (math.radians(40), math.radians(20), math.radians(30))
    bpy.context.object.data.energy = 3
    scene.world = bpy.data.worlds.new("w")
    scene.world.color = (0.8, 0.8, 0.82)
    scene.render.filepath = out
    bpy.ops.render.render(write_still=True)
    print(f"interop: blender usd: picture {out}")
