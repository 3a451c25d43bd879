#!/usr/bin/env bash
# Build docker/Dockerfile and run the test suite inside it (its last stage runs `make test`).
#
#  1. Engine: docker when `docker info` answers (a working engine); otherwise podman, installed with apt-get
#     when missing. SORO_ENGINE=docker|podman forces one.
#  2. Base image debian:bookworm: used when present; else pulled; when the pull fails (no registry
#     reachable), made locally by docker/make-base-image.sh (debootstrap from the Debian mirror).
#  3. Build with the repository root as context; the test stage runs every time (a new SORO_TEST_RUN).
#     The Debian-packages and venv layers stay cached while only the sources change.
#  4. Prints the build time (and the base image's, when it was made) at the end.
#
# Usage: bash docker/container-test.sh [extra build options, e.g. --no-cache or --target dev]
# Environment: SORO_ENGINE, SORO_IMAGE (tag, default soro:test), SORO_PULL_TIMEOUT (seconds, default 120),
# SORO_CA_BUNDLE (CA certificates given to pip in the build, default /etc/ssl/certs/ca-certificates.crt),
# SORO_TEST_TIMEOUT (seconds for the whole `make test` inside, default 3600; a hung test then fails the build).
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$here"
IMAGE=${SORO_IMAGE:-soro:test}
BASE=debian:bookworm
PULL_TIMEOUT=${SORO_PULL_TIMEOUT:-120}

say() { printf '[container-test] %s\n' "$*"; }
die() { printf '[container-test] error: %s\n' "$*" >&2; exit 1; }
fmt() { printf '%dm%02ds' $(( $1 / 60 )) $(( $1 % 60 )); }

t_start=$(date +%s)
base_seconds=""

# --- 1. the engine ---------------------------------------------------------------------------------------------
engine=${SORO_ENGINE:-}
if [ -z "$engine" ]; then
  if command -v docker >/dev/null && docker info >/dev/null 2>&1; then
    engine=docker
  else
    if command -v docker >/dev/null; then
      say "docker is installed but no Docker engine answers (docker info failed): using podman"
    else
      say "no docker: using podman"
    fi
    engine=podman
  fi
fi
case "$engine" in docker|podman) ;; *) die "SORO_ENGINE must be docker or podman, not '$engine'" ;; esac

if [ "$engine" = podman ] && ! command -v podman >/dev/null; then
  command -v apt-get >/dev/null \
    || die "neither a Docker engine nor podman is available, and there is no apt-get to install podman: install docker or podman"
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null || die "podman is missing and this is not root: install podman (apt-get install podman) as root"
    SUDO=sudo
  fi
  say "podman is missing; installing it: $SUDO apt-get update && $SUDO apt-get install -y podman"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -q || die "apt-get update failed: check the network access to the Debian mirror"
  $SUDO apt-get install -y -q podman || die "apt-get install podman failed"
fi
command -v "$engine" >/dev/null || die "$engine is not installed"
say "engine: $engine ($("$engine" --version 2>/dev/null | head -n1))"

build_opts=()
if [ "$engine" = docker ]; then
  # BuildKit reads docker/Dockerfile.dockerignore (the legacy builder would copy .venv and out/ into the image).
  export DOCKER_BUILDKIT=1
else
  # podman on these machines: the default "oci" isolation runs each RUN step in a crun container, which fails
  # here ("cgroups in hybrid mode not supported", and `podman run` fails on setrlimit RLIMIT_NOFILE);
  # --isolation=chroot runs the steps in a chroot with no cgroup setup, and works. The default overlay
  # storage driver works with it; where overlay does not (e.g. podman inside another container), run with
  # STORAGE_DRIVER=vfs in the environment (podman reads it; slower, more disk).
  # --pull=never: the base image was prepared above (present, pulled, or made by make-base-image.sh).
  build_opts+=(--isolation=chroot --ignorefile docker/Dockerfile.dockerignore --pull=never)
fi

# The host's CA bundle, for pip inside the build when HTTPS goes through a TLS-intercepting proxy whose CA
# the host trusts (as on these machines). A build secret: used by the pip step, not stored in the image.
CA_BUNDLE=${SORO_CA_BUNDLE:-/etc/ssl/certs/ca-certificates.crt}
if [ -s "$CA_BUNDLE" ]; then
  build_opts+=(--secret "id=ca-bundle,src=$CA_BUNDLE")
else
  say "no CA bundle at $CA_BUNDLE (SORO_CA_BUNDLE): pip in the image uses the image's own certificates"
fi

# --- 2. the base image -----------------------------------------------------------------------------------------
if "$engine" image inspect "$BASE" >/dev/null 2>&1; then
  say "base image $BASE: present"
else
  # A short name: podman resolves it with the unqualified-search registries of /etc/containers/registries.conf
  # (none configured means the pull fails at once, and the image is made locally instead).
  say "base image $BASE: not present; trying to pull it (at most ${PULL_TIMEOUT} s)"
  if timeout "$PULL_TIMEOUT" "$engine" pull "$BASE" </dev/null; then
    say "pulled $BASE"
  else
    say "cannot pull $BASE (no registry reachable?): making it locally with docker/make-base-image.sh"
    t0=$(date +%s)
    bash docker/make-base-image.sh "$engine" || die "could not make the base image $BASE (see the messages above)"
    base_seconds=$(( $(date +%s) - t0 ))
  fi
fi

# --- 3. build, running the tests --------------------------------------------------------------------------------
say "$engine build ${build_opts[*]} -f docker/Dockerfile -t $IMAGE $* ."
t_build=$(date +%s)
status=0
"$engine" build "${build_opts[@]}" --build-arg "SORO_TEST_RUN=$(date +%s)" \
  --build-arg "SORO_TEST_TIMEOUT=${SORO_TEST_TIMEOUT:-3600}" \
  -f docker/Dockerfile -t "$IMAGE" "$@" . || status=$?
build_seconds=$(( $(date +%s) - t_build ))
total_seconds=$(( $(date +%s) - t_start ))

# --- 4. times ------------------------------------------------------------------------------------------------------
[ -n "$base_seconds" ] && say "base image made in $(fmt "$base_seconds")"
if [ $status -ne 0 ]; then
  say "build time $(fmt "$build_seconds"), total $(fmt "$total_seconds")"
  die "the image build failed (exit $status). A failing 'make test' step means a test failed inside the
  container: its output, and the summary line, are above. A failing apt or pip step: check the network
  access to the Debian mirror and PyPI."
fi
case " $* " in
  *" --target"*) say "image $IMAGE built (the stage named by --target; the tests run in the last stage, test)" ;;
  *) say "image $IMAGE built and the test suite passed inside it" ;;
esac
say "build time $(fmt "$build_seconds") (tests included), total $(fmt "$total_seconds")"
