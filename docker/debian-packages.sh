#!/usr/bin/env bash
# Install the Debian packages that scripts/bootstrap.sh lists (its PACKAGES=( ... ) array), nothing else.
#
# Used by docker/Dockerfile for its first, slow layer: that layer then depends on bootstrap.sh alone, so it
# stays cached while the sources or pyproject.toml change. bootstrap.sh, run afterwards, finds every package
# present and skips apt. When the array cannot be found, this does nothing and bootstrap installs them later.
# Usage: bash docker/debian-packages.sh [path/to/bootstrap.sh]
set -euo pipefail
src=${1:-scripts/bootstrap.sh}
say() { printf '[debian-packages] %s\n' "$*"; }

decl=$(sed -n '/^PACKAGES=(/,/^)/p' "$src")
PACKAGES=()
[ -n "$decl" ] && eval "$decl"
if [ ${#PACKAGES[@]} -eq 0 ]; then
  say "no PACKAGES=( ... ) array in $src: leaving the Debian packages to bootstrap.sh"
  exit 0
fi
say "installing ${#PACKAGES[@]} packages from $src: ${PACKAGES[*]}"
export DEBIAN_FRONTEND=noninteractive
apt-get update -q
apt-get install -y -q --no-install-recommends "${PACKAGES[@]}"
# No package lists or downloaded .deb files in the image (bootstrap runs apt-get update if it ever needs to).
apt-get clean
rm -rf /var/lib/apt/lists/*
