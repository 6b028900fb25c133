#!/usr/bin/env bash
# Vendors the three.js files the studio page uses (src/studio/page/vendor/three/),
# from the npm registry at the pinned version, with the licence. The files are
# committed and built into the binary (include_bytes!): the page works offline
# and nothing is fetched at run time. Run again to move to another version.
set -euo pipefail
VERSION=${THREE_VERSION:-0.187.0}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
DEST=$ROOT/src/studio/page/vendor/three
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
(cd "$WORK" && npm pack --silent "three@$VERSION" > /dev/null && tar xzf "three-$VERSION.tgz")
P=$WORK/package
mkdir -p "$DEST"
cp "$P/build/three.module.js" "$P/build/three.core.js" "$P/LICENSE" "$DEST/"
cp "$P/examples/jsm/controls/OrbitControls.js" "$P/examples/jsm/loaders/PLYLoader.js" "$DEST/"
echo "three.js $VERSION (npm: three@$VERSION), MIT licence (LICENSE)" > "$DEST/VERSION"
(cd "$DEST" && sha256sum three.module.js three.core.js OrbitControls.js PLYLoader.js >> VERSION)
echo "vendored three.js $VERSION into $DEST"
