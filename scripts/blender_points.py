"""Blender's own picture of a point cloud (Cycles, each point a small sphere
through geometry nodes), from the camera angles of shapeshifter's previews
(azimuth 35, elevation 25, orthographic): a reference rendered by another
tool to set beside `shapeshifter render` / `encode --preview`.

    blender -b --factory-startup --python scripts/blender_points.py -- POINTS.ply OUT.png z|y RADIUS
    blender -b --factory-startup --python scripts/blender_points.py -- MESH.glb OUT.png y 0

POINTS.ply holds vertices only (x y z, optionally red green blue); `z` or
`y` is its up axis; RADIUS is each point's sphere radius in its units. A
.glb is imported by Blender's glTF importer and drawn as a mesh, with its
vertex colours (COLOR_0) as the base colour (glTF is y-up: Blender's
importer turns it z-up).
"""
import bpy, sys, math
argv = sys.argv[sys.argv.index("--") + 1:]
ply, out, up = argv[0], argv[1], argv[2]
bpy.ops.wm.read_factory_settings(use_empty=True)
mesh_file = ply.lower().endswith(".glb")
if mesh_file:
    import numpy
    numpy.bool = bool  # Blender 3.4's glTF importer on numpy 1.24
    bpy.ops.import_scene.gltf(filepath=ply)
    ob = [o for o in bpy.context.scene.objects if o.type == "MESH"][0]
else:
    bpy.ops.import_mesh.ply(filepath=ply)
    ob = bpy.context.selected_objects[0]
    if up == "y":
        ob.rotation_euler[0] = math.pi / 2
bpy.context.view_layer.update()
mat = bpy.data.materials.new("m"); mat.use_nodes = True
attr = mat.node_tree.nodes.new("ShaderNodeAttribute"); attr.attribute_name = ob.data.color_attributes[0].name if ob.data.color_attributes else "Col"
mat.node_tree.links.new(attr.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
# Points as spheres: geometry nodes Mesh to Points, coloured by the vertex colours.
mod = ob.modifiers.new("pts", "NODES") if not mesh_file else None
if mesh_file:
    ob.data.materials.clear(); ob.data.materials.append(mat)
else:
    tree = bpy.data.node_groups.new("pts", "GeometryNodeTree")
    mod.node_group = tree
    tree.inputs.new("NodeSocketGeometry", "Geometry"); tree.outputs.new("NodeSocketGeometry", "Geometry")
    n_in = tree.nodes.new("NodeGroupInput"); n_out = tree.nodes.new("NodeGroupOutput")
    m2p = tree.nodes.new("GeometryNodeMeshToPoints"); m2p.inputs["Radius"].default_value = float(argv[3])
    setm = tree.nodes.new("GeometryNodeSetMaterial")
    tree.links.new(n_in.outputs[0], m2p.inputs["Mesh"]); tree.links.new(m2p.outputs[0], setm.inputs[0]); tree.links.new(setm.outputs[0], n_out.inputs[0])
    setm.inputs["Material"].default_value = mat
scene = bpy.context.scene
scene.render.engine = "CYCLES"; scene.cycles.samples = 16; scene.cycles.device = "CPU"; scene.cycles.use_denoising = False
scene.render.resolution_x = scene.render.resolution_y = 640
bpy.ops.object.camera_add(); cam = bpy.context.object; scene.camera = cam
cam.data.type = "ORTHO"
import mathutils
vs = [ob.matrix_world @ ob.data.vertices[i].co for i in range(0, len(ob.data.vertices), 50)]
lo = mathutils.Vector([min(v[k] for v in vs) for k in range(3)]); hi = mathutils.Vector([max(v[k] for v in vs) for k in range(3)])
centre = (lo + hi) / 2; size = max((hi - lo).length, 1e-6)
cam.data.ortho_scale = size * 1.05
az, el = math.radians(35), math.radians(25)
d = mathutils.Vector((math.sin(az) * math.cos(el), -math.cos(az) * math.cos(el), math.sin(el)))
cam.location = centre + d * size * 3; cam.data.clip_end = size * 10
cam.rotation_euler = (-d).to_track_quat("-Z", "Y").to_euler()
bpy.ops.object.light_add(type="SUN"); bpy.context.object.rotation_euler = (math.radians(40), math.radians(20), math.radians(30)); bpy.context.object.data.energy = 3
scene.world = bpy.data.worlds.new("w"); scene.world.color = (0.8, 0.8, 0.82)
scene.render.filepath = out
bpy.ops.render.render(write_still=True)
