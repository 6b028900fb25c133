"""pyopenvdb (Debian's python3-openvdb) on the level files we write.

Usage: pyopenvdb_check.py MESH_INFO.json LEVEL.vdb...
MESH_INFO.json is `shapeshifter info --json` of the exemplar mesh: every level
must sit on top of it (its active voxels' world bounds inside the mesh's
bounds, grown by one voxel)."""
import json
import sys

import pyopenvdb as vdb

EXPECTED = {"mask": "float", "density": "float", "P": "vec3s", "N": "vec3s", "Cd": "vec3s"}


def fail(msg):
    print(f"interop: pyopenvdb: FAIL {msg}")
    sys.exit(1)


info = json.load(open(sys.argv[1]))["outcomes"][0]["result"]
lo, hi = info["bbox_min"], info["bbox_max"]
files = sys.argv[2:]
for path in files:
    try:
        grids, file_meta = vdb.readAll(path)
        meta_only = vdb.readAllGridMetadata(path)
    except Exception as e:  # the failure this check exists for
        fail(f"{path}: readAll: {e}")
    types = {g.name: g.valueTypeName for g in grids}
    if types != EXPECTED:
        fail(f"{path}: grids {types}, expected {EXPECTED}")
    if {g.name for g in meta_only} != set(EXPECTED):
        fail(f"{path}: readAllGridMetadata lists {[g.name for g in meta_only]}")
    mask = next(g for g in grids if g.name == "mask")
    for key in ("creator", "shapeshifter_level", "shapeshifter_resolution", "shapeshifter_exemplar"):
        if key not in mask.metadata:
            fail(f"{path}: no '{key}' metadata")
    (i0, j0, k0), (i1, j1, k1) = mask.evalActiveVoxelBoundingBox()
    voxel = mask.transform.voxelSize()[0]
    a = mask.transform.indexToWorld((i0, j0, k0))
    b = mask.transform.indexToWorld((i1, j1, k1))
    for axis in range(3):
        if a[axis] < lo[axis] - 1.5 * voxel or b[axis] > hi[axis] + 1.5 * voxel:
            fail(f"{path}: active voxels span {a}..{b}, outside the exemplar's bounds {lo}..{hi} (voxel {voxel:.4g})")
    n = mask.activeVoxelCount()
    if n == 0:
        fail(f"{path}: no active voxels")
version = '.'.join(str(v) for v in getattr(vdb, 'LIBRARY_VERSION', ())) or '?'
print(f"interop: pyopenvdb (OpenVDB {version}): readAll and readAllGridMetadata read all "
      f"{len(files)} level files: grids mask, density (float), P, N, Cd (vec3s), metadata present, "
      f"every level inside the exemplar's bounds")
