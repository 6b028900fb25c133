#!/usr/bin/env bash
# Pixar's usd-core (PyPI) in a virtual environment of its own in the cache
# folder, made once: `make test` validates a written USD asset with it, and
# `make interop` opens a whole run's asset. Prints the venv's python.
set -euo pipefail
CACHE="${SHAPESHIFTER_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/shapeshifter}"
DIR="$CACHE/usd-venv"
if [ ! -f "$DIR/.complete" ]; then
  echo "usd-venv: installing usd-core==26.11 into $DIR" >&2
  rm -rf "$DIR"
  /usr/bin/python3 -m venv "$DIR"
  "$DIR/bin/pip" install -q "usd-core==26.11"
  touch "$DIR/.complete"
fi
echo "$DIR/bin/python"
