#!/usr/bin/env bash
# Our Poisson meshing (`shapeshifter mesh --method poisson`, CGAL underneath)
# against Open3D's screened Poisson at depth 9, side by side in one run, on
# the same oriented points: the ruined tower's 256^3 level (`encode`, then
# `points` for Open3D). Runs alternate (ours, Open3D, ours, ...) so that load
# from elsewhere falls on both; the table gives medians. Both meshes are
# scored by the same code (examples/mesh_fidelity.rs `compare`: Chamfer and
# Hausdorff against the exemplar, 300k area samples each side, in voxels of
# the level).
#
#   make bench-poisson            or   scripts/poisson-vs-open3d.sh
#   RUNS=5 DEPTH=9 OUT=/tmp/p scripts/poisson-vs-open3d.sh
#
# Wall times: ours is the whole command (reading the level file, meshing,
# colours, writing the PLY); Open3D's is its reconstruction call alone
# (without importing Open3D, reading the points or writing the mesh), which
# favours Open3D. Open3D 0.20.0 from PyPI goes into a virtual environment
# outside the work tree (the cache folder, like libtorch's); a second run
# reuses it.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD

RUNS=${RUNS:-3}
DEPTH=${DEPTH:-}          # ours: --depth N; empty: the default (8)
OPEN3D_DEPTH=${OPEN3D_DEPTH:-9}
OUT=${OUT:-out/poisson-vs-open3d}
TOWER=${TOWER:-../shared/data/towerruins/towerruins.obj}
BIN="$ROOT/target/release/shapeshifter"
FIDELITY="$ROOT/target/release/examples/mesh_fidelity"

# Open3D's wheel links libusb-1.0 (for its Kinect reader) and fails to import without it.
if ! dpkg-query -W -f='${Status}' libusb-1.0-0 2>/dev/null | grep -q "install ok installed"; then
  echo "poisson-vs-open3d: installing libusb-1.0-0 (Open3D needs it)" >&2
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO=sudo
  $SUDO apt-get update -q && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q libusb-1.0-0
fi
VENV=$(bash "$ROOT/scripts/venv.sh" open3d-venv open3d==0.20.0)

cargo build --release -q
cargo build --release -q --example mesh_fidelity --example demo_exemplar

mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
if [ -f "$TOWER" ]; then
  EXEMPLAR=$TOWER
else
  echo "poisson-vs-open3d: THE RUINED TOWER IS ABSENT ($TOWER, from ../shared/data):" \
    "measuring on the embedded demo exemplar instead; these figures are not the README's." >&2
  "$ROOT/target/release/examples/demo_exemplar" --out "$OUT/demo" > /dev/null
  EXEMPLAR="$OUT/demo/demo_tower.ply"
fi
"$BIN" --quiet encode "$EXEMPLAR" -o "$OUT/level" > /dev/null
LEVEL=$(ls "$OUT"/level/level_*.vdb | sort -V | tail -n1)
"$BIN" --quiet points "$LEVEL" -o "$OUT/points.ply"

now() { date +%s.%N; }
median() { sort -g | awk '{v[NR] = $1} END {print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2}'; }
ours_args=(mesh "$LEVEL" -o "$OUT/ours.ply" --method poisson)
[ -n "$DEPTH" ] && ours_args+=(--depth "$DEPTH")
: > "$OUT/ours.times"
: > "$OUT/open3d.times"
for i in $(seq "$RUNS"); do
  t0=$(now)
  "$BIN" --quiet "${ours_args[@]}"
  t1=$(now)
  awk -v a="$t0" -v b="$t1" 'BEGIN {print b - a}' >> "$OUT/ours.times"
  "$VENV/bin/python" "$ROOT/scripts/open3d_poisson.py" "$OUT/points.ply" "$OUT/open3d.ply" "$OPEN3D_DEPTH" \
    | sed -n 's/^open3d depth [0-9]*: \([0-9.]*\) s.*/\1/p' >> "$OUT/open3d.times"
  echo "run $i/$RUNS: ours $(tail -n1 "$OUT/ours.times" | xargs printf '%.2f') s, open3d $(tail -n1 "$OUT/open3d.times") s" >&2
done

"$FIDELITY" compare --mesh "$EXEMPLAR" --level "$LEVEL" "$OUT/ours.ply" "$OUT/open3d.ply" > "$OUT/fidelity.txt"
row() {  # name, times file, mesh file
  local line
  line=$(grep -F "$3:" "$OUT/fidelity.txt")
  printf '| %s | %.2f | %s | %s | %s |\n' "$1" "$(median < "$2")" \
    "$(sed -n 's/.*: \([0-9]*\) vertices.*/\1/p' <<< "$line")" \
    "$(sed -n 's/.*Chamfer \([0-9.]*\) voxels.*/\1/p' <<< "$line")" \
    "$(sed -n 's/.*Hausdorff \([0-9.]*\) voxels.*/\1/p' <<< "$line")"
}
{
  echo "$(basename "$EXEMPLAR"): $(basename "$LEVEL"), $(grep -a -m1 '^element vertex' "$OUT/points.ply" | cut -d' ' -f3) oriented points; medians of $RUNS runs; $(nproc) cores"
  echo
  echo "| method | median wall s | vertices | Chamfer (voxels) | Hausdorff (voxels) |"
  echo "|---|---|---|---|---|"
  row "ours: shapeshifter mesh --method poisson${DEPTH:+ --depth $DEPTH} (CGAL), whole command" "$OUT/ours.times" "$OUT/ours.ply"
  row "Open3D $("$VENV/bin/python" -c 'import open3d; print(open3d.__version__)' 2>/dev/null) screened Poisson depth $OPEN3D_DEPTH, reconstruction call only" "$OUT/open3d.times" "$OUT/open3d.ply"
} | tee "$OUT/table.md"
