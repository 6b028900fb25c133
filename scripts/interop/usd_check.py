"""Pixar's usd-core opens a run's USD asset (`make interop`).

usage: usd_check.py RUN_DIR [COUNTS_JSON [EXT]]   (EXT: usda, the default, or usdc)

Checks, printing one `interop:` line per finding and exiting 1 on the first
failure:
- the stage opens; defaultPrim set, kind component, upAxis and metersPerUnit
  authored; the variant set `variant` has one variant per variant folder that
  holds a variant.usda, and a default selection;
- every variant selected in turn: a Mesh whose face counts and indices match
  the variant's mesh.ply (vertex and triangle counts; a textured variant: its
  mesh.obj) and whose displayColor has one colour per point; a Points prim
  with one point per surface voxel of the finest level (counted by pyopenvdb
  from level_K.vdb's mask grid, when it is given with --levels-counts);
  a Volume whose `level` variant set has one variant per level_K.vdb, each
  with OpenVDBAsset fields whose file paths resolve to existing files;
- a textured mesh: primvars:st faceVarying (one UV per corner), a bound
  UsdPreviewSurface whose UsdUVTexture file resolves;
- usd-core's validators (UsdValidation, what usdchecker runs) on the asset
  with each variant selected, and on one variant layer: no errors.
"""
import json
import os
import sys

from pxr import Usd, UsdGeom, UsdShade, UsdVol


def fail(msg):
    print(f"interop: USD check failed: {msg}", file=sys.stderr)
    sys.exit(1)


def ply_counts(path):
    """(vertices, faces) from a PLY header."""
    v = f = None
    with open(path, "rb") as fh:
        for line in fh:
            line = line.decode("ascii", "replace").strip()
            if line.startswith("element vertex"):
                v = int(line.split()[2])
            elif line.startswith("element face"):
                f = int(line.split()[2])
            elif line == "end_header":
                break
    return v, f


def obj_counts(path):
    v = f = 0
    with open(path) as fh:
        for line in fh:
            if line.startswith("v "):
                v += 1
            elif line.startswith("f "):
                f += 1
    return v, f


def main():
    run = sys.argv[1]
    counts = json.load(open(sys.argv[2])) if len(sys.argv) > 2 else {}
    ext = sys.argv[3] if len(sys.argv) > 3 else "usda"
    asset = os.path.join(run, f"variants.{ext}")
    stage = Usd.Stage.Open(asset)
    if not stage:
        fail(f"{asset} does not open")
    root = stage.GetDefaultPrim()
    if not root:
        fail("no defaultPrim")
    if Usd.ModelAPI(root).GetKind() != "component":
        fail(f"kind {Usd.ModelAPI(root).GetKind()!r}, expected component")
    layer = stage.GetRootLayer()
    if not (stage.HasAuthoredMetadata("upAxis") and stage.HasAuthoredMetadata("metersPerUnit")):
        fail("upAxis or metersPerUnit not authored")
    vset = root.GetVariantSets().GetVariantSet("variant")
    names = vset.GetVariantNames()
    folders = sorted(d for d in os.listdir(os.path.join(run, "variants"))
                     if os.path.isfile(os.path.join(run, "variants", d, f"variant.{ext}")))
    if sorted(names) != folders:
        fail(f"variants {names} but folders {folders}")
    if not vset.GetVariantSelection():
        fail("no default variant selection")
    print(f"interop: usd-core {'.'.join(map(str, Usd.GetVersion()))} opened {os.path.basename(asset)}: "
          f"defaultPrim {root.GetName()} (kind component), upAxis {UsdGeom.GetStageUpAxis(stage)}, "
          f"metersPerUnit {UsdGeom.GetStageMetersPerUnit(stage)}, {len(names)} variants, default {vset.GetVariantSelection()}")

    textured = 0
    for name in names:
        vset.SetVariantSelection(name)
        folder = os.path.join(run, "variants", name)
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(root.GetPath().AppendChild("mesh")))
        tex_obj = os.path.join(folder, "mesh.obj")
        if not mesh:
            fail(f"{name}: no Mesh prim")
        points = mesh.GetPointsAttr().Get()
        counts_attr = mesh.GetFaceVertexCountsAttr().Get()
        indices = mesh.GetFaceVertexIndicesAttr().Get()
        is_textured = os.path.isfile(os.path.join(folder, "mesh_basecolor.png")) and os.path.isfile(tex_obj)
        v, f = obj_counts(tex_obj) if is_textured else ply_counts(os.path.join(folder, "mesh.ply"))
        if (len(points), len(counts_attr)) != (v, f):
            fail(f"{name}: Mesh has {len(points)} points, {len(counts_attr)} faces; the mesh file {v}, {f}")
        if len(indices) != sum(counts_attr) or max(indices) >= len(points) or min(indices) < 0:
            fail(f"{name}: face indices do not match the counts or the points")
        colour = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("displayColor")
        if not colour or len(colour.Get()) != len(points):
            fail(f"{name}: displayColor missing or not one per point")
        if is_textured:
            textured += 1
            st = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st")
            if not st or st.GetInterpolation() != "faceVarying" or len(st.Get()) != len(indices):
                fail(f"{name}: primvars:st missing or not one UV per corner")
            material, _ = UsdShade.MaterialBindingAPI(mesh.GetPrim()).ComputeBoundMaterial()
            if not material:
                fail(f"{name}: textured mesh without a bound material")
            shader = material.ComputeSurfaceSource()[0]
            if shader.GetIdAttr().Get() != "UsdPreviewSurface":
                fail(f"{name}: surface shader {shader.GetIdAttr().Get()}")
            src = shader.GetInput("diffuseColor").GetConnectedSources()[0][0].source
            texture = UsdShade.Shader(src.GetPrim())
            path = texture.GetInput("file").Get()
            if not path or not path.resolvedPath or not os.path.isfile(path.resolvedPath):
                fail(f"{name}: texture {path} does not resolve")
        pts = UsdGeom.Points(stage.GetPrimAtPath(root.GetPath().AppendChild("points")))
        if not pts:
            fail(f"{name}: no Points prim")
        n_points = len(pts.GetPointsAttr().Get())
        want = counts.get(name)
        if want is not None and n_points != want:
            fail(f"{name}: Points has {n_points} points, the finest level {want} surface voxels")
        if len(pts.GetNormalsAttr().Get()) != n_points or len(UsdGeom.PrimvarsAPI(pts).GetPrimvar("displayColor").Get()) != n_points:
            fail(f"{name}: Points normals or colours not one per point")
        vol_prim = stage.GetPrimAtPath(root.GetPath().AppendChild("volume"))
        vol = UsdVol.Volume(vol_prim)
        if not vol:
            fail(f"{name}: no Volume prim")
        lset = vol_prim.GetVariantSets().GetVariantSet("level")
        levels = sorted(f for f in os.listdir(folder) if f.startswith("level_") and f.endswith(".vdb") and not f.endswith(".points.vdb"))
        lnames = lset.GetVariantNames()
        if sorted(f"{l}.vdb" for l in lnames) != levels:
            fail(f"{name}: volume levels {lnames}, files {levels}")
        for lname in lnames:
            lset.SetVariantSelection(lname)
            fields = vol.GetFieldPaths()
            if "density" not in fields:
                fail(f"{name}/{lname}: no density field")
            for fname, fpath in fields.items():
                asset_field = UsdVol.OpenVDBAsset(stage.GetPrimAtPath(fpath))
                fp = asset_field.GetFilePathAttr().Get()
                if not fp.resolvedPath or os.path.basename(fp.resolvedPath) != f"{lname}.vdb" or not os.path.isfile(fp.resolvedPath):
                    fail(f"{name}/{lname}: field {fname} file {fp} does not resolve to {lname}.vdb")
        lset.ClearVariantSelection()
    vset.ClearVariantSelection()
    print(f"interop: usd-core selected every variant: Mesh counts match mesh.ply / mesh.obj ({textured} textured, "
          f"UsdPreviewSurface + UsdUVTexture resolving), Points one per surface voxel, Volume with one `level` "
          f"variant per level_K.vdb and OpenVDBAsset paths resolving")

    # usd-core's validators (what usdchecker runs; 26.x replaced
    # UsdUtils.ComplianceChecker with the UsdValidation framework), on the
    # asset with every variant selected in turn and on one variant layer.
    from pxr import UsdValidation
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    context = UsdValidation.ValidationContext(validators)
    def validate(stage, what):
        found = context.Validate(stage)
        errors = [e for e in found if e.GetType() == UsdValidation.ValidationErrorType.Error]
        warnings = [e for e in found if e.GetType() == UsdValidation.ValidationErrorType.Warn]
        if errors:
            fail(f"UsdValidation on {what}: " + "; ".join(f"{e.GetName()}: {e.GetMessage()}" for e in errors))
        return warnings
    warned = []
    for name in names:
        vset.SetVariantSelection(name)
        warned += validate(stage, f"variants.{ext} ({name})")
    vset.ClearVariantSelection()
    layer_path = os.path.join(run, "variants", folders[0], f"variant.{ext}")
    warned += validate(Usd.Stage.Open(layer_path), os.path.relpath(layer_path, run))
    distinct = sorted({f"{e.GetName()}: {e.GetMessage()}" for e in warned})
    print(f"interop: usd-core's {len(validators)} validators (UsdValidation, as usdchecker): variants.{ext} with each "
          f"variant selected and {os.path.relpath(layer_path, run)}: no errors"
          + (f", warnings: {distinct}" if distinct else ", no warnings"))


if __name__ == "__main__":
    main()
