#!/usr/bin/env bash
# The second test stage: the suite on Debian 13 (trixie: DOLFINx 0.9, PETSc 3.22, Python 3.13, numpy 2,
# gmsh 4.13, pytest 8), installed the way a user installs it (scripts/bootstrap.sh, then `make test`).
#
#  1. A trixie root made with `debootstrap --variant=minbase`, cached outside the clone in
#     $SORO_TRIXIE_CACHE/trixie (default /var/cache/soro/trixie) so that later runs reuse it (~1 s). The cache is
#     valid while its stamp matches (suite, mirror, the project's Debian package list, the recipe below) and it
#     is younger than $SORO_TRIXIE_MAX_AGE_DAYS (default 30: point releases); otherwise it is rebuilt, in a
#     new directory that replaces the old one only when complete. Building (~560 packages) took 2.5 min on a
#     quiet machine and 10 min at load 10 on 2 cores.
#  2. The clone's files (tracked and untracked, not ignored: no .venv, no out/) are copied to /root/soro in
#     the root; there `make test` runs: bootstrap.sh (apt-get for missing packages, the venv, pip extras), the
#     serial suite, the MPI tests. The JUnit files come back to out/test-trixie/.
#
# Needs root (chroot, mounts) and network access to the Debian mirror and PyPI; when one is missing it fails
# with a message, it never skips. Usage: bash scripts/test-trixie.sh [--rebuild]; PYTEST_OPTS passes through.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
CACHE=${SORO_TRIXIE_CACHE:-/var/cache/soro}
ROOT=$CACHE/trixie
SUITE=trixie
MAX_AGE_DAYS=${SORO_TRIXIE_MAX_AGE_DAYS:-30}
RECIPE=1  # bump when the way the root is made changes
rebuild=0
[ "${1:-}" = "--rebuild" ] && rebuild=1

say() { printf '[test-trixie] %s\n' "$*"; }
die() { printf '[test-trixie] error: %s\n' "$*" >&2; exit 1; }

[ "$(id -u)" -eq 0 ] || die "needs root (debootstrap, chroot and mounts); run it as root or with sudo"

# The mirror this machine's apt sources name (deb822 .sources or one-line .list), else Debian's CDN.
mirror_of_host() {
  local m
  m=$(grep -hs '^URIs:' /etc/apt/sources.list.d/*.sources 2>/dev/null | awk '{print $2}' | grep -v security \
      | grep -m1 '/debian/\?$' || true)
  [ -n "$m" ] || m=$(grep -hs '^deb ' /etc/apt/sources.list /etc/apt/sources.list.d/*.list 2>/dev/null \
      | awk '{print $2}' | grep -v security | grep -m1 '/debian/\?$' || true)
  echo "${m:-http://deb.debian.org/debian}"
}
MIRROR=${SORO_DEBIAN_MIRROR:-$(mirror_of_host)}

stamp() {
  { echo "recipe $RECIPE suite $SUITE mirror $MIRROR"; bash "$here/scripts/bootstrap.sh" --packages; } \
    | sha256sum | cut -d' ' -f1
}

cache_ok() {
  [ -f "$ROOT/.soro-stamp" ] && [ "$(cat "$ROOT/.soro-stamp")" = "$(stamp)" ] \
    || { say "cache: no root yet, or its stamp (suite, mirror, package list, recipe) changed: rebuilding"; return 1; }
  [ -n "$(find "$ROOT/.soro-stamp" -mtime -"$MAX_AGE_DAYS")" ] \
    || { say "cache: older than $MAX_AGE_DAYS days: rebuilding"; return 1; }
  grep -q '^13\.' "$ROOT/etc/debian_version" 2>/dev/null || { say "cache: not a Debian 13 root: rebuilding"; return 1; }
  dolfinx_in_root >/dev/null || { say "cache: python3-dolfinx is not installed in it: rebuilding"; return 1; }
}

dolfinx_in_root() { chroot "$ROOT" dpkg-query -W -f='${Version}' python3-dolfinx 2>/dev/null; }

# rm -rf of a root that still has /dev bound into it would delete the host's /dev: unmount first, refuse if
# something stays mounted, and never cross into another file system
safe_rm() {
  local d=$1 m
  [ -e "$d" ] || return 0
  d=$(realpath "$d")
  for m in $(awk -v d="$d" '$2 == d || index($2, d "/") == 1 {print $2}' /proc/mounts | sort -r); do
    umount -R "$m" 2>/dev/null || umount -R -l "$m" 2>/dev/null || true
  done
  if awk -v d="$d" '$2 == d || index($2, d "/") == 1' /proc/mounts | grep -q .; then
    die "file systems are still mounted under $d; unmount them (see /proc/mounts), then run again"
  fi
  rm -rf --one-file-system "$d"
}

MOUNTED=()
mount_into() {  # proc, sys, a recursive bind of /dev (OpenMPI's shared memory lives in /dev/shm)
  local r=$1
  mount -t proc proc "$r/proc" && MOUNTED+=("$r/proc")
  mount -t sysfs sys "$r/sys" && MOUNTED+=("$r/sys")
  mount --rbind /dev "$r/dev" && mount --make-rslave "$r/dev" && MOUNTED+=("$r/dev")
  cp /etc/resolv.conf "$r/etc/resolv.conf"
  # pip inside needs the host's CA bundle (TLS interception on some networks)
  mkdir -p "$r/etc/ssl/certs"
  cp "${PIP_CERT:-/etc/ssl/certs/ca-certificates.crt}" "$r/etc/ssl/certs/soro-host-ca.crt"
}
unmount_all() {
  local m
  for ((i = ${#MOUNTED[@]} - 1; i >= 0; i--)); do
    m=${MOUNTED[i]}
    umount -R "$m" 2>/dev/null || umount -R -l "$m" 2>/dev/null || true
  done
  MOUNTED=()
}
trap unmount_all EXIT

in_root() {  # run a command in the root with a clean environment
  chroot "$1" /usr/bin/env -i PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin HOME=/root \
    LANG=C.UTF-8 DEBIAN_FRONTEND=noninteractive PIP_CERT=/etc/ssl/certs/soro-host-ca.crt \
    PYTEST_OPTS="${PYTEST_OPTS:-}" "${@:2}"
}

build_root() {
  command -v debootstrap >/dev/null || {
    say "installing debootstrap on the host"
    apt-get install -y -q debootstrap >/dev/null || die "apt-get install debootstrap failed (Debian mirror reachable?)"
  }
  local new=$ROOT.new
  safe_rm "$new"
  mkdir -p "$CACHE"
  say "building a Debian 13 root in $new from $MIRROR (debootstrap --variant=minbase $SUITE)"
  debootstrap --variant=minbase "$SUITE" "$new" "$MIRROR" > "$CACHE/debootstrap.log" 2>&1 \
    || die "debootstrap failed (log: $CACHE/debootstrap.log): is the mirror $MIRROR reachable? Set SORO_DEBIAN_MIRROR to another"
  mount_into "$new"
  local pkgs
  pkgs=$(bash "$here/scripts/bootstrap.sh" --packages | tr '\n' ' ')
  say "installing the project's Debian packages in the root (~560 packages, 2-10 min; log: $CACHE/apt.log)"
  in_root "$new" bash -c "apt-get update -q && apt-get install -y -q --no-install-recommends $pkgs" \
    > "$CACHE/apt.log" 2>&1 || die "apt-get in the trixie root failed (log: $CACHE/apt.log)"
  in_root "$new" apt-get clean
  unmount_all
  stamp > "$new/.soro-stamp"
  safe_rm "$ROOT"
  mv "$new" "$ROOT"
}

mkdir -p "$CACHE"
exec 9>"$CACHE/trixie.lock"
flock 9  # one stage at a time uses the root

t0=$(date +%s)
if [ $rebuild -eq 1 ] || ! cache_ok; then
  build_root
else
  say "cache valid: $ROOT (python3-dolfinx $(dolfinx_in_root))"
fi
t1=$(date +%s)

# the clone's files, fresh each run, and the user's caches of a fresh machine (a killed earlier run can leave an
# FFCx compile lock in ~/.cache/fenics that makes the same form time out in the next run)
work=$ROOT/root/soro
safe_rm "$work"
safe_rm "$ROOT/root/.cache"
mkdir -p "$work"
(cd "$here" && git ls-files -z --cached --others --exclude-standard \
   | while IFS= read -r -d '' f; do [ -e "$f" ] && printf '%s\0' "$f"; done \
   | tar --null -T - -cf -) | tar -xf - -C "$work"
mount_into "$ROOT"
say "running make test in the Debian 13 root"
status=0
in_root "$ROOT" bash -c 'cd /root/soro && make test' || status=$?
unmount_all
mkdir -p "$here/out/test-trixie"
cp "$work"/out/test/*.xml "$here/out/test-trixie/" 2>/dev/null || true
t2=$(date +%s)
say "root ready in $((t1 - t0)) s, make test in $((t2 - t1)) s; exit status $status (JUnit: out/test-trixie/)"
exit $status
