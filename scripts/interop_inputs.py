"""Exemplar files written by other tools, read by shapeshifter (`make interop`,
scripts/interop-inputs.sh runs this in its own virtual environment):

- Open3D reads the oriented, coloured points our `points` command wrote, and
  writes them again as PLY (binary with normals and colours; ASCII with
  colours only);
- laspy writes them as LAS 1.4 (point format 7: RGB, a WKT CRS) and, with its
  lazrs backend, as LAZ (point format 6: intensity and classes, no RGB), in
  UTM-like metres;
- pye57 writes them as an E57 scan (colours and intensity);
- Blender exported the exemplar mesh as GLB (the shell script did that).

Each file: `shapeshifter info --json` must report the writer's point count,
attributes, bounds (to the millimetre) and CRS; `shapeshifter encode` must give
levels whose finest one covers most of the voxels the points came from.

    python interop_inputs.py BIN WORK POINTS.ply LEVEL_VOXELS BLENDER.glb
"""
import json
import os
import subprocess
import sys

import laspy
import numpy as np
import open3d as o3d
import pye57

BIN, WORK, POINTS, LEVEL_VOXELS, GLB = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4]), sys.argv[5]
OFFSET = np.array([500000.0, 4100000.0, 120.0])
WKT = 'PROJCS["WGS 84 / UTM zone 33N",GEOGCS["WGS 84"],UNIT["metre",1],AUTHORITY["EPSG","32633"]]'


def fail(msg):
    print(f"interop: FAILED: {msg}", file=sys.stderr)
    sys.exit(1)


def info(path):
    r = subprocess.run([BIN, "info", "--json", path], capture_output=True, text=True)
    if r.returncode != 0:
        fail(f"info {path}: {r.stderr.strip()}")
    return json.loads(r.stdout)["outcomes"][0]["result"]


def encode(path, extra=()):
    out = os.path.join(WORK, "enc_" + os.path.basename(path).replace(".", "_"))
    r = subprocess.run([BIN, "-q", "encode", path, "-o", out, "--coarsest", "16", "--finest", "32", "--sampling-resolution", "64", *extra], capture_output=True, text=True)
    if r.returncode != 0:
        fail(f"encode {path}: {r.stderr.strip()}")
    manifest = json.load(open(os.path.join(out, "manifest.json")))
    return manifest["levels"][-1]["voxels"]


def check_cloud(path, writer, n, lo, hi, attributes, crs=None, extra=()):
    i = info(path)
    if i["kind"] != "cloud" or i["points"] != n:
        fail(f"{path}: {i.get('kind')} of {i.get('points')} points, {writer} wrote {n}")
    if not (np.allclose(i["bbox_min"], lo, atol=1e-3) and np.allclose(i["bbox_max"], hi, atol=1e-3)):
        fail(f"{path}: bounds {i['bbox_min']} - {i['bbox_max']}, {writer} wrote {lo} - {hi}")
    if sorted(i["attributes"]) != sorted(attributes):
        fail(f"{path}: attributes {i['attributes']}, {writer} wrote {attributes}")
    if crs is not None and crs not in (i.get("crs") or ""):
        fail(f"{path}: CRS {i.get('crs')}, {writer} wrote {crs}")
    voxels = encode(path, extra)
    if voxels < 0.8 * LEVEL_VOXELS:
        fail(f"{path}: its finest level has {voxels} voxels, the points came from {LEVEL_VOXELS}")
    print(f"interop: {writer}: {os.path.basename(path)} {n} points [{', '.join(i['attributes']) or 'positions only'}]"
          + (f", CRS {i['crs']}" if i.get("crs") else "") + f"; encoded, finest level {voxels} voxels (source level {LEVEL_VOXELS})")


# Open3D reads what `points` wrote.
pcd = o3d.io.read_point_cloud(POINTS)
if not (pcd.has_normals() and pcd.has_colors()):
    fail(f"Open3D read {POINTS} without normals or colours")
P = np.asarray(pcd.points, dtype=np.float64)
C = np.asarray(pcd.colors)
n = len(P)
print(f"interop: Open3D {o3d.__version__} reads our points PLY: {n} points with normals and colours")
lo, hi = P.min(0), P.max(0)

p = os.path.join(WORK, "o3d_binary.ply")
o3d.io.write_point_cloud(p, pcd, write_ascii=False)
check_cloud(p, f"Open3D {o3d.__version__} (binary PLY)", n, lo, hi, ["normals", "rgb"])
plain = o3d.geometry.PointCloud(pcd.points)
plain.colors = pcd.colors
p = os.path.join(WORK, "o3d_ascii.ply")
o3d.io.write_point_cloud(p, plain, write_ascii=True)
check_cloud(p, f"Open3D {o3d.__version__} (ASCII PLY, no normals)", n, lo, hi, ["rgb"])

# laspy: metres around a UTM origin (ten times the exemplar's size), turned
# from the exemplar's y up to z up, as LAS and E57 have it.
M = np.stack([P[:, 0], -P[:, 2], P[:, 1]], 1) * 10 + OFFSET
header = laspy.LasHeader(point_format=7, version="1.4")
header.offsets, header.scales = OFFSET, [0.001] * 3
header.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr(WKT))
header.global_encoding.wkt = True
las = laspy.LasData(header)
las.x, las.y, las.z = M[:, 0], M[:, 1], M[:, 2]
las.red, las.green, las.blue = [(C[:, k] * 65535).astype(np.uint16) for k in range(3)]
las.intensity = (np.arange(n) % 1000).astype(np.uint16)
las.classification = np.full(n, 6, np.uint8)
p = os.path.join(WORK, "laspy.las")
las.write(p)
Q = np.round((M - OFFSET) / 0.001) * 0.001 + OFFSET
check_cloud(p, f"laspy {laspy.__version__} (LAS 1.4 format 7)", n, Q.min(0), Q.max(0), ["rgb", "intensity", "classification"], crs="EPSG:32633")

h6 = laspy.LasHeader(point_format=6, version="1.4")
h6.offsets, h6.scales = OFFSET, [0.001] * 3
laz = laspy.LasData(h6)
laz.x, laz.y, laz.z = M[:, 0], M[:, 1], M[:, 2]
laz.intensity = (C[:, 0] * 4000).astype(np.uint16)
laz.classification = np.where(M[:, 2] > np.median(M[:, 2]), 6, 2).astype(np.uint8)
p = os.path.join(WORK, "laspy.laz")
laz.write(p, laz_backend=laspy.LazBackend.Lazrs)
check_cloud(p, f"laspy {laspy.__version__} + lazrs (LAZ format 6)", n, Q.min(0), Q.max(0), ["intensity", "classification"], extra=("--cloud-colour", "intensity"))

# pye57: one scan with colours and intensity.
p = os.path.join(WORK, "pye57.e57")
e57 = pye57.E57(p, mode="w")
e57.write_scan_raw({
    "cartesianX": M[:, 0], "cartesianY": M[:, 1], "cartesianZ": M[:, 2],
    "colorRed": (C[:, 0] * 255).astype(np.uint8), "colorGreen": (C[:, 1] * 255).astype(np.uint8), "colorBlue": (C[:, 2] * 255).astype(np.uint8),
    "intensity": (C[:, 1]).astype(np.float32),
})
e57.close()
check_cloud(p, f"pye57 {getattr(pye57.__version__, '__version__', pye57.__version__)} (E57)", n, M.min(0), M.max(0), ["rgb", "intensity"])

# Blender's GLB of the exemplar mesh.
i = info(GLB)
if i["kind"] != "mesh" or i["triangles"] < 100:
    fail(f"{GLB}: {i}")
voxels = encode(GLB)
print(f"interop: Blender's GLB export: {i['vertices']} vertices, {i['triangles']} triangles, colour {i['colour_source']}; encoded, finest level {voxels} voxels")
if voxels < 0.8 * LEVEL_VOXELS:
    fail(f"{GLB}: finest level {voxels} voxels against {LEVEL_VOXELS}")
