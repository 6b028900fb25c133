#!/usr/bin/env bash
# `make setup` on a bare Debian 12: a debootstrap chroot (minbase: no compiler,
# no Rust, no Python, no make), the project copied in (git archive), then
# `apt-get install make` and `make setup` as the README says, then the
# versions of what the build needs. Root only; installs debootstrap when
# missing. Keeps the chroot in $BARE_ROOT (default /var/tmp/shapeshifter-bare)
# for a second look; `make setup-check` runs it.
#   BARE_FRESH=1  starts from a new chroot (what "a machine with nothing installed" means)
#   BARE_TEST=1   then runs `make test` there too, timed from the bare system, with
#                 ../shared bound read-only beside the copy (as CI has it)
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=${BARE_ROOT:-/var/tmp/shapeshifter-bare}
[ "$(id -u)" -eq 0 ] || { echo "setup-check: needs root (debootstrap, chroot)" >&2; exit 1; }
command -v debootstrap >/dev/null || { apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q debootstrap; }
[ "${BARE_FRESH:-0}" = 1 ] && rm -rf "$ROOT"
if [ ! -x "$ROOT/usr/bin/apt-get" ]; then
  echo "setup-check: debootstrap bookworm (minbase) into $ROOT" >&2
  rm -rf "$ROOT"
  debootstrap --variant=minbase bookworm "$ROOT" http://deb.debian.org/debian >/dev/null
fi
cleanup() { for m in root/shared dev/pts dev sys proc; do umount -l "$ROOT/$m" 2>/dev/null || true; done; }
trap cleanup EXIT
mount -t proc proc "$ROOT/proc"
mount -t sysfs sys "$ROOT/sys"
mount --bind /dev "$ROOT/dev"
mount --bind /dev/pts "$ROOT/dev/pts"
cp /etc/resolv.conf "$ROOT/etc/resolv.conf"
# This site's network: the certificate authorities it adds (a proxy's, say)
# and pip's configuration, which a machine of the site would have too.
mkdir -p "$ROOT/usr/local/share/ca-certificates"
cp /usr/local/share/ca-certificates/*.crt "$ROOT/usr/local/share/ca-certificates/" 2>/dev/null || true
[ -f /etc/pip.conf ] && cp /etc/pip.conf "$ROOT/etc/pip.conf"
rm -rf "$ROOT/root/shapeshifter" && mkdir -p "$ROOT/root/shapeshifter"
git archive HEAD | tar -x -C "$ROOT/root/shapeshifter"
if [ "${BARE_TEST:-0}" = 1 ] && [ -d ../shared ]; then
  mkdir -p "$ROOT/root/shared" && mount --bind -o ro ../shared "$ROOT/root/shared"
fi
echo "setup-check: before make setup the chroot has: $(chroot "$ROOT" sh -c 'command -v make g++ cargo rustc python3 ~/.cargo/bin/cargo || true' | tr '\n' ' ')" >&2
# The instruction-set caps, where set, go in: an AVX-512 machine held to AVX2
# (ATEN_CPU_CAPABILITY=avx2 ONEDNN_MAX_CPU_ISA=AVX2 MKL_ENABLE_INSTRUCTIONS=AVX2)
# times what an ordinary CPU does.
isa_caps=()
for v in ATEN_CPU_CAPABILITY ONEDNN_MAX_CPU_ISA MKL_ENABLE_INSTRUCTIONS; do
  [ -n "${!v:-}" ] && isa_caps+=("$v=${!v}")
done
chroot "$ROOT" /usr/bin/env -i HOME=/root TERM=dumb BARE_TEST="${BARE_TEST:-0}" "${isa_caps[@]}" PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin bash -c '
  set -euo pipefail
  cd /root/shapeshifter
  bare=$(date +%s)
  apt-get update -q >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -q make ca-certificates >/dev/null
  update-ca-certificates >/dev/null
  start=$(date +%s)
  make setup
  echo "setup-check: make setup took $(( $(date +%s) - start )) s"
  export PATH="$HOME/.cargo/bin:$PATH"
  echo "setup-check: $(cargo --version), $(rustc --version)"
  echo "setup-check: $(g++ --version | head -1)"
  echo "setup-check: libtorch $(readlink .libtorch)"
  echo "setup-check: OpenVDB $(dpkg-query -W -f="\${Version}" libopenvdb-dev), CGAL $(dpkg-query -W -f="\${Version}" libcgal-dev), OpenMesh $(dpkg-query -W -f="\${Version}" libopenmesh-dev)"
  start=$(date +%s)
  make setup >/dev/null 2>&1
  echo "setup-check: a second make setup took $(( $(date +%s) - start )) s"
  if [ "$BARE_TEST" = 1 ]; then
    start=$(date +%s)
    SHAPESHIFTER_NO_SKIPS=1 make test > /root/make-test.log 2>&1 || { tail -30 /root/make-test.log; exit 1; }
    echo "setup-check: make test took $(( $(date +%s) - start )) s after set-up; $(( $(date +%s) - bare )) s from the bare system"
    # The build (cargo'"'"'s "Finished ... in" of each build) and the tests ("finished in").
    grep -E "^test result|nothing skipped|SKIPPED|Finished" /root/make-test.log | sed "s/^ */setup-check: /"
  fi
'
