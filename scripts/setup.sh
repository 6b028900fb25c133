#!/usr/bin/env bash
# One idempotent set-up for a fresh Debian 12 machine: Debian packages
# (g++, OpenVDB 10, OpenMesh 9, CGAL 5.5, ccache, the DejaVu font that build.rs
# embeds for the loss plots' text, ...), the pinned Rust (rustup) and libtorch 2.13.0 for
# tch 0.26 from the PyPI torch wheel, cached OUTSIDE the work tree so that
# clones and CI reuse it. A second run with everything present downloads
# nothing and takes about a second.
#   CUDA=1 scripts/setup.sh   installs the full CUDA torch wheel instead.
set -euo pipefail
cd "$(dirname "$0")/.."

# The C++ compiler, make and curl too: a bare Debian 12 has none of them.
PACKAGES=(g++ make curl ca-certificates git libopenvdb-dev libopenvdb-tools python3-openvdb
  libopenmesh-dev libcgal-dev libeigen3-dev libgmp-dev libmpfr-dev libtbb-dev libblosc-dev
  ccache pkg-config python3-venv fonts-dejavu-core libassimp-dev assimp-testmodels)
missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "setup: installing Debian packages: ${missing[*]}" >&2
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO=sudo
  $SUDO apt-get update -q
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q "${missing[@]}"
fi

# Rust: the version rust-toolchain.toml pins, through rustup (Debian 12's
# rustc 1.63 is too old). An existing rustup only adds the toolchain if it is
# missing; without rustup, rustup-init comes from static.rust-lang.org.
RUST_VERSION=$(sed -n 's/^channel *= *"\(.*\)"/\1/p' rust-toolchain.toml)
export PATH="${CARGO_HOME:-$HOME/.cargo}/bin:$PATH"
if ! command -v rustup >/dev/null 2>&1; then
  echo "setup: installing rustup and Rust $RUST_VERSION into ${CARGO_HOME:-$HOME/.cargo}" >&2
  # rustup picks its role from its file name: it must be called rustup-init.
  dir=$(mktemp -d)
  curl --proto '=https' --tlsv1.2 -sSf -o "$dir/rustup-init" \
    "https://static.rust-lang.org/rustup/dist/$(uname -m)-unknown-linux-gnu/rustup-init"
  chmod +x "$dir/rustup-init"
  "$dir/rustup-init" -y -q --profile minimal --default-toolchain "$RUST_VERSION" --no-modify-path
  rm -rf "$dir"
elif ! rustup run "$RUST_VERSION" rustc --version >/dev/null 2>&1; then
  echo "setup: installing Rust $RUST_VERSION (rustup)" >&2
  rustup toolchain install "$RUST_VERSION" --profile minimal
fi

CACHE="${SHAPESHIFTER_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/shapeshifter}"
if [ "${CUDA:-0}" = 1 ]; then VENV="$CACHE/torch-cuda-venv"; else VENV="$CACHE/torch-venv"; fi
TORCH="$VENV/lib/python3.11/site-packages/torch"
if [ ! -f "$VENV/.complete" ]; then
  echo "setup: installing libtorch 2.13.0 into $VENV" >&2
  rm -rf "$VENV"
  /usr/bin/python3 -m venv "$VENV" 2>/dev/null || python3 -m venv "$VENV"
  if [ "${CUDA:-0}" = 1 ]; then
    "$VENV/bin/pip" install -q torch==2.13.0
  else
    # libtorch_cpu.so itself needs libcudart.so.13 and libcupti.so.13: two small wheels.
    "$VENV/bin/pip" install -q --no-deps torch==2.13.0 "nvidia-cuda-runtime==13.0.96.*" \
      "nvidia-cuda-cupti==13.0.85.*"
  fi
  touch "$VENV/.complete"
fi
TORCH_PY_DIR=$(ls -d "$VENV"/lib/python3*/site-packages/torch | head -n1)
ln -sfn "$TORCH_PY_DIR" .libtorch
# .cargo/machine.toml (included by .cargo/config.toml, not tracked): this
# machine's paths, the same for every clone.
# - LIBTORCH, resolved: ccache hits on torch-sys's C++ in a fresh clone.
# - build-dir: cargo's intermediate files (dependencies compiled once, build
#   scripts' output) in one folder under the cache for every clone; the
#   programs stay in each clone's target/. A fresh clone compiles only this
#   crate (a cold cargo build 265 s, then 106 s in the next clone). Tests run
#   from that folder, so the helper programs are named: the clone's own.
# Rewritten only when it changes (torch-sys rebuilds when LIBTORCH does).
if [ "${CUDA:-0}" = 1 ]; then BUILD_DIR="$CACHE/cargo-build/cuda"; else BUILD_DIR="$CACHE/cargo-build/cpu"; fi
want="[env]
LIBTORCH = \"$(cd "$TORCH_PY_DIR" && pwd -P)\"
SHAPESHIFTER_VDB_PROBE = { value = \"target/release/shapeshifter-vdb-probe\", relative = true }
SHAPESHIFTER_ASSIMP = { value = \"target/release/shapeshifter-assimp\", relative = true }

[build]
build-dir = \"$BUILD_DIR\""
if [ "$(sed 1d .cargo/machine.toml 2>/dev/null)" != "$want" ]; then
  printf '# Written by scripts/setup.sh: this machine'"'"'s paths.\n%s\n' "$want" > .cargo/machine.toml.tmp
  mv .cargo/machine.toml.tmp .cargo/machine.toml
fi
rm -f .cargo/libtorch.toml  # its earlier name
# Each clone adds its own build of this crate there (about 1-2 GB with the
# tests); past 16 GiB the folder is emptied and refilled by the next build.
if [ -d "$BUILD_DIR" ] && [ "$(du -s --block-size=1G "$BUILD_DIR" | cut -f1)" -gt 16 ]; then
  echo "setup: $BUILD_DIR is over 16 GiB: emptied (the next build compiles the dependencies again)" >&2
  rm -rf "$BUILD_DIR"
fi

echo "setup: ready (Rust $RUST_VERSION, libtorch at $(readlink .libtorch))" >&2
