#!/usr/bin/env bash
# The files we write, opened by the real clients a pipeline uses (`make interop`;
# CI runs it after `make test`):
# - OpenVDB's own vdb_print lists every level file and points file;
# - Debian's pyopenvdb: readAll and readAllGridMetadata on every level file
#   (volumes: mask, density, P, N, Cd with their types and the exemplar's
#   transform); the points files are checked to hold the `points` grid;
# - Blender (headless): imports every level file as a volume object (grid
#   names and types, bounds on top of the exemplar mesh), and every mesh we
#   write (.ply and .glb, vertex colours present);
# - Pixar's usd-core (PyPI, its own virtual environment): opens the run's
#   variants.usda, selects every variant, checks prim types, counts against
#   the mesh and level files, asset paths, its validators; the same for the
#   binary layers (`usd --format usdc`), and that they hold the text's scene;
#   Blender 4.2 (PyPI's bpy module: Debian's Blender has no USD) imports it
#   with its USD importer (scripts/interop/usd_check.py, blender_usd.py);
# - Chromium (headless): opens report.html, every image decodes; a screenshot;
# - exemplars written by Open3D, laspy (+lazrs), pye57 and Blender's glTF
#   exporter read and encoded (scripts/interop-inputs.sh).
# Installs blender, chromium and libopenvdb-tools from Debian when missing.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
BIN=$ROOT/target/release/shapeshifter
OUT=${INTEROP_OUT:-$ROOT/out/interop}

need=()
command -v blender > /dev/null || need+=(blender)
command -v chromium > /dev/null || need+=(chromium)
command -v vdb_print > /dev/null || need+=(libopenvdb-tools)
/usr/bin/python3 -c "import pyopenvdb" 2> /dev/null || need+=(python3-openvdb)
if ((${#need[@]})); then
  echo "interop: installing ${need[*]} (Debian)" >&2
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO=sudo
  $SUDO apt-get update -q
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q "${need[@]}" > /dev/null
fi
[ -x "$BIN" ] || { echo "interop: build first (make build)" >&2; exit 1; }
[ -x "$ROOT/target/release/examples/demo_exemplar" ] || (cd "$ROOT" && cargo build --release --example demo_exemplar)

WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
mkdir -p "$OUT"

# A small but complete run: the demo exemplar through 32^3, two variants,
# each meshed as mesh.ply decimated to 3000 triangles, baked into a texture
# (mesh.obj + mesh.mtl + mesh_basecolor.png, a textured mesh.glb), and its USD
# layers.
"$ROOT/target/release/examples/demo_exemplar" --out "$WORK/mesh" > /dev/null
MESH=$WORK/mesh/demo_tower.ply
"$BIN" -q run "$MESH" -o "$WORK/run" -n 2 --seed 1 \
  --set encode.sampling_resolution=128 --set encode.finest_resolution=32 \
  --set train.level0_iterations=300 --set train.upper_iterations=60 --set train.upsampler_iterations=60 \
  --set mesh.faces=3000 --set mesh.glb=true > "$WORK/run.log"
LEVELS=$(find "$WORK/run" -name 'level_*.vdb' ! -name '*.points.vdb' | sort)
POINTS=$(find "$WORK/run" -name 'level_*.points.vdb' | sort)
# Meshes: the exemplar's finest level (32^3) meshed as PLY and glTF binary.
"$BIN" -q mesh "$WORK/run/exemplar/level_1.vdb" -o "$WORK/exemplar_level_1.ply" > /dev/null
"$BIN" -q mesh "$WORK/run/exemplar/level_1.vdb" -o "$WORK/exemplar_level_1.glb" > /dev/null
MESHES=$(ls "$WORK"/exemplar_level_1.ply "$WORK"/exemplar_level_1.glb; find "$WORK/run/variants" -name 'mesh.*' ! -name '*.png' ! -name '*.mtl' | sort)
"$BIN" info --json "$MESH" > "$WORK/mesh_info.json"
echo "interop: $(wc -w <<< "$LEVELS") level files, $(wc -w <<< "$POINTS") points files, $(wc -w <<< "$MESHES") meshes"

# --- OpenVDB's own tool --------------------------------------------------------
for f in $LEVELS $POINTS; do
  vdb_print -l "$f" > "$WORK/vdb_print.txt" || { echo "interop: vdb_print failed on $f" >&2; exit 1; }
done
for f in $POINTS; do
  vdb_print "$f" | grep -q '^points *ptdataidx32' || { echo "interop: $f holds no PointDataGrid 'points'" >&2; exit 1; }
done
echo "interop: vdb_print reads every level file and points file; each points file holds the PointDataGrid 'points'"
echo "interop: vdb_print lists every file; e.g. $(basename "$(dirname "$(echo "$LEVELS" | tail -1)")")/$(basename "$(echo "$LEVELS" | tail -1)"):"
vdb_print "$(echo "$LEVELS" | tail -1)" | sed 's/^/  vdb_print: /'

# --- pyopenvdb --------------------------------------------------------------------
/usr/bin/python3 "$ROOT/scripts/interop/pyopenvdb_check.py" "$WORK/mesh_info.json" $LEVELS

# --- Blender ------------------------------------------------------------------------
blender -b --factory-startup --python-exit-code 1 --python "$ROOT/scripts/interop/blender_check.py" -- \
  "$WORK/mesh_info.json" $LEVELS -- $MESHES 2> "$WORK/blender.err" | grep '^interop' || {
  echo "interop: Blender check failed:" >&2; tail -20 "$WORK/blender.err" >&2; exit 1; }

# --- USD: Pixar's usd-core and Blender's USD importer ----------------------------
# usd-core from PyPI in a virtual environment of its own in the cache folder
# (scripts/venv.sh: made once, the one `make test` uses).
USD_VENV=$(bash "$ROOT/scripts/venv.sh" usd-venv "usd-core==26.11")
[ -s "$WORK/run/variants.usda" ] || { echo "interop: the run wrote no variants.usda" >&2; exit 1; }
# Surface voxels of each variant's finest level, counted by pyopenvdb (not by us).
/usr/bin/python3 - "$WORK/run" > "$WORK/usd_counts.json" <<'PY'
import json, os, sys
import pyopenvdb
run = sys.argv[1]
counts = {}
for v in sorted(os.listdir(os.path.join(run, "variants"))):
    d = os.path.join(run, "variants", v)
    levels = sorted((int(f[6:-4]), f) for f in os.listdir(d)
                    if f.startswith("level_") and f.endswith(".vdb") and not f.endswith(".points.vdb"))
    grid = pyopenvdb.read(os.path.join(d, levels[-1][1]), "mask")
    counts[v] = sum(1 for item in grid.citerOnValues() if item.value > 0)
print(json.dumps(counts))
PY
"$USD_VENV/bin/python" "$ROOT/scripts/interop/usd_check.py" "$WORK/run" "$WORK/usd_counts.json"
# The same run's layers written binary (`usd --format usdc`, in a copy of the
# run): the same checks on variants.usdc, then the same scene as the text.
cp -r "$WORK/run" "$WORK/run_usdc"
"$BIN" -q usd "$WORK/run_usdc" --format usdc > /dev/null
"$USD_VENV/bin/python" "$ROOT/scripts/interop/usd_check.py" "$WORK/run_usdc" "$WORK/usd_counts.json" usdc
"$USD_VENV/bin/python" "$ROOT/scripts/interop/usd_binary_check.py" "$WORK/run" "$WORK/run_usdc"
# Blender imports the asset (the default variant) with its own USD importer.
DEFAULT_DIR="$WORK/run/variants/variant_000"
if [ -f "$DEFAULT_DIR/mesh_basecolor.png" ]; then TRIANGLES=$(grep -c '^f ' "$DEFAULT_DIR/mesh.obj");
else TRIANGLES=$(sed -n 's/^element face \([0-9]*\).*/\1/p' "$DEFAULT_DIR/mesh.ply" | head -1); fi
# Debian 12's Blender 3.4 is built without USD: Blender as a Python module
# (PyPI's bpy 4.2) in a virtual environment of its own.
BPY_VENV=$(bash "$ROOT/scripts/venv.sh" bpy-venv "bpy==4.2.0")
"$BPY_VENV/bin/python" "$ROOT/scripts/interop/blender_usd.py" \
  "$WORK/run/variants.usda" "$TRIANGLES" "$OUT/usd_blender.png" > "$WORK/blender_usd.out" 2>&1 || {
  echo "interop: Blender's USD import failed:" >&2; tail -20 "$WORK/blender_usd.out" >&2; exit 1; }
grep '^interop' "$WORK/blender_usd.out"
# The asset's tree, as usd-core lists it.
"$USD_VENV/bin/python" -c "
import sys
from pxr import Usd
stage = Usd.Stage.Open(sys.argv[1])
for prim in stage.Traverse():
    depth = len(prim.GetPath().pathString.split('/')) - 2
    sets = prim.GetVariantSets()
    extra = ''.join(f' {{{n} = {sets.GetVariantSet(n).GetVariantSelection()} of {len(sets.GetVariantSet(n).GetVariantNames())}}}' for n in sets.GetNames())
    print('  ' * depth + f'{prim.GetName()} ({prim.GetTypeName()}){extra}')
" "$WORK/run/variants.usda" > "$OUT/usd_tree.txt"
echo "interop: the asset's tree as usd-core composes it ($OUT/usd_tree.txt):"
sed 's/^/  usd: /' "$OUT/usd_tree.txt"

# --- report.html in a real browser ----------------------------------------------
REPORT=$WORK/run/report.html
[ -s "$REPORT" ] || { echo "interop: the run wrote no report.html" >&2; exit 1; }
CHROME=(chromium --headless --no-sandbox --disable-gpu --allow-file-access-from-files --virtual-time-budget=10000)
"${CHROME[@]}" --dump-dom "file://$REPORT" 2> /dev/null > "$WORK/dom.html"
loaded=$(sed -n 's/.*data-images-loaded="\([0-9]*\/[0-9]*\)".*/\1/p' "$WORK/dom.html" | head -1)
[ -n "$loaded" ] || { echo "interop: report.html: the page's image check did not run" >&2; exit 1; }
k=${loaded%/*}; n=${loaded#*/}
[ "$n" -gt 0 ] && [ "$k" = "$n" ] || { echo "interop: report.html: only $loaded images loaded" >&2; exit 1; }
"${CHROME[@]}" --window-size=1280,2400 --screenshot="$OUT/report_screenshot.png" "file://$REPORT" 2> /dev/null
[ -s "$OUT/report_screenshot.png" ] || { echo "interop: no screenshot" >&2; exit 1; }
echo "interop: chromium opened report.html: $loaded images loaded; screenshot $OUT/report_screenshot.png"
# --- Exemplars written by other tools ------------------------------------------
bash "$ROOT/scripts/interop-inputs.sh" "$WORK"
echo "interop: all checks passed"
