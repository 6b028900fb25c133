#!/usr/bin/env bash
# scripts/venv.sh NAME PACKAGE...: a Python virtual environment NAME in the
# cache folder holding PACKAGE... from PyPI, made once (a second call, or a
# second clone, reuses it). Prints its folder. `make test` makes `usd-venv`
# (Pixar's usd-core, which validates written USD assets); `make interop` and
# `make studio-test` make theirs.
set -euo pipefail
NAME=$1; shift
CACHE="${SHAPESHIFTER_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/shapeshifter}"
DIR="$CACHE/$NAME"
if [ ! -f "$DIR/.complete" ]; then
  echo "venv: installing $* into $DIR" >&2
  rm -rf "$DIR"
  /usr/bin/python3 -m venv "$DIR"
  "$DIR/bin/pip" install -q "$@"
  touch "$DIR/.complete"
fi
echo "$DIR"
