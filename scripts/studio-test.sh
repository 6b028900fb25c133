#!/usr/bin/env bash
# The studio's page in a real browser (`make studio-test`; CI runs it):
# Debian's Chromium and ChromeDriver (installed here when missing) driven
# through WebDriver by the selenium client (PyPI, in its own virtual
# environment in the cache). On a run folder (default: a tiny run of the
# demo exemplar made here, levels 16^3..64^3): load the page, pick a
# variant, select a box at level 1 with the mouse and delete it, undo and
# redo with the keys, regenerate, check the 3D view is drawn, keep; then the
# kept folder is read back (scripts/studio_browser.py).
#   scripts/studio-test.sh [RUN_DIR]   the screenshot goes to $STUDIO_OUT (out/studio-test)
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
BIN=$ROOT/target/release/shapeshifter
OUT=${STUDIO_OUT:-$ROOT/out/studio-test}

need=()
[ -x /usr/bin/chromium ] || need+=(chromium)
[ -x /usr/bin/chromedriver ] || need+=(chromium-driver)
if ((${#need[@]})); then
  echo "studio-test: installing ${need[*]} (Debian)" >&2
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO=sudo
  $SUDO apt-get update -q
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q "${need[@]}" > /dev/null
fi
VENV=$(bash "$ROOT/scripts/venv.sh" browser-venv "selenium>=4.20,<5")
[ -x "$BIN" ] || { echo "studio-test: build first (make build)" >&2; exit 1; }

WORK=$(mktemp -d)
STUDIO_PID=""
cleanup() { [ -n "$STUDIO_PID" ] && kill "$STUDIO_PID" 2> /dev/null; wait 2> /dev/null || true; rm -rf "$WORK"; }
trap cleanup EXIT
mkdir -p "$OUT"
RUN=${1:-}
if [ -z "$RUN" ]; then
  RUN=$WORK/run
  echo "studio-test: a tiny run of the demo exemplar (16^3..64^3, small networks)" >&2
  "$BIN" -q demo -o "$RUN" -n 2 --jobs 2 \
    --set encode.sampling_resolution=128 --set encode.finest_resolution=64 \
    --set model.channels=8 --set model.upsampler_channels=8 \
    --set train.level0_iterations=150 --set train.upper_iterations=60 --set train.upsampler_iterations=60 \
    --set 'sample.level0={candidates = 1}' --set 'sample.attempts={count = 1}' --set 'sample.proposers={}' --set sample.level0_steps=20 --set sample.upper_steps=4 > /dev/null
  # A run folder shared by someone else may hold anything: a flag in its
  # eval.json that is markup must reach the page as text, not run.
  export STUDIO_HOSTILE_FLAG='<img src=x onerror="window.__xss=1">'
  python3 - "$RUN/eval.json" <<'EOF'
import json, os, sys
path = sys.argv[1]
run = json.load(open(path))
first = run["variants"][0]
first["structure"] = first.get("structure") or {}
first["structure"]["flags"] = list(first["structure"].get("flags") or []) + [os.environ["STUDIO_HOSTILE_FLAG"]]
json.dump(run, open(path, "w"))
EOF
fi

"$BIN" studio "$RUN" --port 0 > "$WORK/studio.out" 2> "$WORK/studio.err" &
STUDIO_PID=$!
for _ in $(seq 100); do grep -q '^studio: ' "$WORK/studio.out" 2> /dev/null && break; sleep 0.1; done
URL=$(sed -n 's/^studio: //p' "$WORK/studio.out")
[ -n "$URL" ] || { echo "studio-test: the studio printed no address:" >&2; cat "$WORK/studio.err" >&2; exit 1; }
# The address holds the token: given in the environment, not on a command line.
STUDIO_URL=$URL SHAPESHIFTER=$BIN "$VENV/bin/python" "$ROOT/scripts/studio_browser.py" "$RUN" "$OUT/studio_screenshot.png" || {
  echo "studio-test: the studio's log:" >&2; tail -20 "$WORK/studio.err" >&2; exit 1; }
# SIGTERM ends it within seconds, 143.
kill -TERM "$STUDIO_PID"
status=0; wait "$STUDIO_PID" || status=$?
STUDIO_PID=""
[ "$status" = 143 ] || { echo "studio-test: the studio ended with $status on SIGTERM, not 143" >&2; exit 1; }
echo "studio-test: SIGTERM ended the studio (143)"
