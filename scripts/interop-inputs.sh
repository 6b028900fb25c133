#!/usr/bin/env bash
# Exemplar files written by other tools (`make interop` runs this after the
# output checks): Open3D, laspy (+lazrs) and pye57 from PyPI in a virtual
# environment of their own outside the work tree (the cache folder, like
# libtorch's; a second run reuses it), and Blender's glTF exporter.
#   scripts/interop-inputs.sh WORK      (WORK: a scratch folder)
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
BIN=$ROOT/target/release/shapeshifter
WORK=$1
# Open3D's wheel links libusb-1.0 (its Kinect reader) and fails to import without it.
if ! dpkg-query -W -f='${Status}' libusb-1.0-0 2>/dev/null | grep -q "install ok installed"; then
  echo "interop-inputs: installing libusb-1.0-0 (Open3D needs it)" >&2
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO=sudo
  $SUDO apt-get update -q && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q libusb-1.0-0 > /dev/null
fi
VENV=$(bash "$ROOT/scripts/venv.sh" clouds-venv "laspy[lazrs]==2.5.4" "pye57==0.4.13" "open3d==0.18.0" numpy)

# The demo exemplar's 32^3 level as oriented coloured points, and the mesh
# exported by Blender as GLB.
mkdir -p "$WORK/inputs"
"$ROOT/target/release/examples/demo_exemplar" --out "$WORK/inputs/mesh" > /dev/null
"$BIN" -q encode "$WORK/inputs/mesh/demo_tower.ply" -o "$WORK/inputs/enc" --coarsest 16 --finest 32 --sampling-resolution 64
"$BIN" -q points "$WORK/inputs/enc/level_1.vdb" -o "$WORK/inputs/points.ply"
VOXELS=$(/usr/bin/python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['levels'][-1]['voxels'])" "$WORK/inputs/enc/manifest.json")
blender -b --factory-startup --python-expr "
import bpy, sys
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_mesh.ply(filepath='$WORK/inputs/mesh/demo_tower.ply')
# The PLY is y-up and Blender z-up: turned upright, so that the glTF (y-up) stands.
bpy.context.selected_objects[0].rotation_euler[0] = 1.5707963267948966
bpy.ops.export_scene.gltf(filepath='$WORK/inputs/blender.glb', export_format='GLB')
" > "$WORK/inputs/blender.log" 2>&1 || { tail -20 "$WORK/inputs/blender.log" >&2; echo "interop-inputs: Blender's glTF export failed" >&2; exit 1; }
"$VENV/bin/python" "$ROOT/scripts/interop_inputs.py" "$BIN" "$WORK/inputs" "$WORK/inputs/points.ply" "$VOXELS" "$WORK/inputs/blender.glb"
