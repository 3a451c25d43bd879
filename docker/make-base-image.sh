#!/usr/bin/env bash
# Make the `debian:bookworm` base image locally, for machines where no container registry can be reached.
#
#   debootstrap --variant=minbase bookworm ROOTFS http://deb.debian.org/debian
#   (apt sources set to bookworm, bookworm-updates and bookworm-security; the packages upgraded from them)
#   tar -C ROOTFS -c . | podman import - debian:bookworm      (or `docker import` where a Docker engine runs)
#
# Idempotent: does nothing when the image exists (use --force to rebuild it). Needs root (debootstrap) and
# network access to the Debian mirror only. Usage: bash docker/make-base-image.sh [--force] [docker|podman]
# The engine defaults to SORO_ENGINE, else docker when `docker info` works, else podman.
set -euo pipefail

IMAGE=${SORO_BASE_IMAGE:-debian:bookworm}
MIRROR=${SORO_DEBIAN_MIRROR:-http://deb.debian.org/debian}
SECURITY_MIRROR=${SORO_DEBIAN_SECURITY_MIRROR:-http://deb.debian.org/debian-security}
SUITE=bookworm

say() { printf '[base-image] %s\n' "$*"; }
die() { printf '[base-image] error: %s\n' "$*" >&2; exit 1; }

force=0
engine=${SORO_ENGINE:-}
for arg in "$@"; do
  case "$arg" in
    --force) force=1 ;;
    docker|podman) engine=$arg ;;
    -h|--help) sed -n '2,10p' "$0"; exit 0 ;;
    *) die "unknown argument '$arg' (usage: $0 [--force] [docker|podman])" ;;
  esac
done
if [ -z "$engine" ]; then
  if command -v docker >/dev/null && docker info >/dev/null 2>&1; then engine=docker; else engine=podman; fi
fi
command -v "$engine" >/dev/null || die "'$engine' is not installed (docker/container-test.sh installs podman with apt-get)"

if [ $force -eq 0 ] && "$engine" image inspect "$IMAGE" >/dev/null 2>&1; then
  say "$IMAGE already exists in $engine's image store; nothing to do (--force rebuilds it)"
  exit 0
fi

[ "$(id -u)" -eq 0 ] || die "debootstrap needs root: run as root (sudo bash $0)"
if ! command -v debootstrap >/dev/null; then
  say "installing debootstrap: apt-get update && apt-get install -y debootstrap"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -q || die "apt-get update failed: check the network access to the Debian mirror"
  apt-get install -y -q --no-install-recommends debootstrap || die "apt-get install debootstrap failed"
fi
keyring=/usr/share/keyrings/debian-archive-keyring.gpg
[ -f "$keyring" ] || die "$keyring is missing: apt-get install debian-archive-keyring (debootstrap checks the mirror's signature with it)"

start=$(date +%s)
rootfs=$(mktemp -d "${TMPDIR:-/var/tmp}/soro-rootfs.XXXXXX")
cleanup() {
  # /proc may still be mounted in the chroot when a step failed: unmount before removing anything.
  if mountpoint -q "$rootfs/proc" 2>/dev/null; then umount -l "$rootfs/proc" || true; fi
  rm -rf --one-file-system "$rootfs"
}
trap cleanup EXIT

say "debootstrap --variant=minbase $SUITE $rootfs $MIRROR (a few minutes)"
debootstrap --variant=minbase --keyring="$keyring" "$SUITE" "$rootfs" "$MIRROR" > "$rootfs.log" 2>&1 \
  || { tail -n 30 "$rootfs.log" >&2; die "debootstrap failed (full log: $rootfs.log)"; }
rm -f "$rootfs.log"

# The same apt sources as an official debian:bookworm image: the release, its updates and its security fixes.
say "apt sources: $SUITE $SUITE-updates ($MIRROR), $SUITE-security ($SECURITY_MIRROR)"
rm -f "$rootfs/etc/apt/sources.list"
cat > "$rootfs/etc/apt/sources.list.d/debian.sources" <<EOF
Types: deb
URIs: $MIRROR
Suites: $SUITE $SUITE-updates
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg

Types: deb
URIs: $SECURITY_MIRROR
Suites: $SUITE-security
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
EOF
# As in the official images: no service is started by package installs inside a container.
printf '#!/bin/sh\nexit 101\n' > "$rootfs/usr/sbin/policy-rc.d"
chmod 755 "$rootfs/usr/sbin/policy-rc.d"

# Bring the packages up to the point release + security fixes, so the image matches an up-to-date host.
say "apt-get update && apt-get dist-upgrade inside the new root"
mount -t proc proc "$rootfs/proc"
chroot "$rootfs" /usr/bin/env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin DEBIAN_FRONTEND=noninteractive \
  sh -c 'apt-get update -q && apt-get dist-upgrade -y -q && apt-get clean' > "$rootfs.upgrade.log" 2>&1 \
  || { tail -n 30 "$rootfs.upgrade.log" >&2; die "apt-get inside the new root failed (full log: $rootfs.upgrade.log)"; }
rm -f "$rootfs.upgrade.log"
umount "$rootfs/proc"
# Leave no package lists, caches or logs in the image (apt-get update runs again where it is needed).
rm -rf "$rootfs"/var/lib/apt/lists/* "$rootfs"/var/cache/apt/*.bin "$rootfs"/var/cache/apt/archives/*.deb \
       "$rootfs"/var/log/apt/* "$rootfs"/var/log/dpkg.log "$rootfs"/var/log/bootstrap.log "$rootfs"/tmp/*
: > "$rootfs/etc/hostname"
: > "$rootfs/etc/resolv.conf"  # the engine mounts its own at run/build time

# The configuration of an official image: PATH set, bash as the command.
say "importing into $engine as $IMAGE ($(du -sh --one-file-system "$rootfs" | cut -f1) root filesystem)"
tar --numeric-owner --xattrs -C "$rootfs" -c . \
  | "$engine" import --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
      --change 'CMD ["bash"]' - "$IMAGE" >/dev/null \
  || die "$engine import failed"
"$engine" image inspect "$IMAGE" >/dev/null 2>&1 || die "$IMAGE is not in $engine's image store after the import"
say "made $IMAGE in $(( $(date +%s) - start )) s"
