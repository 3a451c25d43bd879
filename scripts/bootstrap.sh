#!/usr/bin/env bash
# One-command setup of the development environment, idempotent.
#
#  1. Debian packages (FEniCSx/DOLFINx with PETSc and SLEPc, gmsh, numba, SciPy, MPI, ...), installed with
#     apt-get only when one is missing (`apt-get update` once, `sudo` when not root). Supported: Debian 12
#     (bookworm: DOLFINx 0.5.2, Python 3.11, numpy 1.24) and Debian 13 (trixie: DOLFINx 0.9, Python 3.13,
#     numpy 2.2). Elsewhere with apt-get it installs the same package names and says that the result is untested.
#  2. .venv made from Debian's /usr/bin/python3 with --system-site-packages, so it sees those packages.
#  3. The project, editable, plus PyPI extras (OpenCV, tqdm, Gymnasium; Playwright for soro play's tests), with
#     a constraints file that pins the versions of every numerical package Debian provides (numpy above all: a
#     numpy from PyPI breaks DOLFINx).
#  4. The beam and network kernels compiled once into numba's on-disk cache (python -m soroshapes.shapes,
#     python -m soroshapes.precompile).
#
# A second run checks a stamp (hash of this script, pyproject.toml and the installed package set) and
# returns in about a second without changing anything. Usage: bash scripts/bootstrap.sh [--force]
# (`--packages` prints the Debian package list and exits: scripts/test-trixie.sh uses it).
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$here"
VENV=${SORO_VENV:-$here/.venv}
force=0
[ "${1:-}" = "--force" ] && force=1

say() { printf '[bootstrap] %s\n' "$*"; }
die() { printf '[bootstrap] error: %s\n' "$*" >&2; exit 1; }

# --- 0. a Debian system ------------------------------------------------------------------------------
ROOT=${SORO_BOOTSTRAP_ROOT:-}  # tests point this at a fake root to check the non-Debian message
if [ ! -f "$ROOT/etc/debian_version" ] || ! command -v apt-get >/dev/null || ! command -v dpkg-query >/dev/null; then
  die "this setup needs Debian 12 (bookworm) or 13 (trixie), or a derivative with apt-get: the FEniCSx stack
  comes from Debian's packages (python3-dolfinx 0.5.2 or 0.9). On another system use the container: make
  container-test (docker or podman), or install DOLFINx 0.5-0.9 yourself and create .venv by hand (README,
  'Supported DOLFINx')."
fi
. "$ROOT/etc/os-release" 2>/dev/null || true
case "${VERSION_CODENAME:-}" in
  bookworm) release="Debian 12 (bookworm): DOLFINx 0.5.2, supported" ;;
  trixie) release="Debian 13 (trixie): DOLFINx 0.9, supported" ;;
  *) release="'${PRETTY_NAME:-unknown}' (${VERSION_CODENAME:-no codename}): NOT a supported release (Debian 12 and
  13 are); installing the same Debian package names, whatever DOLFINx version they bring is untested (soro doctor
  tells whether it is in the supported range)" ;;
esac

# chromium: the headless browser of soro play's tests (driven by Playwright from PyPI, the `play` extra; its own
# browser download is never used).
# libopenblas0-serial: Debian's alternatives then route libblas.so.3/liblapack.so.3 (MUMPS, numpy, scipy) to
# OpenBLAS instead of the reference BLAS: the 95k-DOF 3D MUMPS factorization drops from 8.1 s to 1.5 s.
# The serial build, so that MPI ranks do not oversubscribe the cores with BLAS threads.
PACKAGES=(
  python3 python3-venv python3-dev python3-pip python3-setuptools python3-wheel
  python3-dolfinx python3-petsc4py python3-slepc4py python3-mpi4py openmpi-bin
  python3-gmsh python3-meshio python3-h5py python3-numba python3-scipy python3-numpy
  python3-matplotlib python3-pytest python3-skimage python3-hypothesis
  libopenblas0-serial
  chromium
  build-essential make git ca-certificates
)
if [ "${1:-}" = "--packages" ]; then
  printf '%s\n' "${PACKAGES[@]}"
  exit 0
fi
say "$release"

stamp_of() {
  # What the environment depends on: this script, the project metadata, and the Debian versions in use.
  { cat "$here/scripts/bootstrap.sh" "$here/pyproject.toml";
    dpkg-query -W -f='${Package} ${Version}\n' "${PACKAGES[@]}" 2>/dev/null; } | sha256sum | cut -d' ' -f1
}

if [ $force -eq 0 ] && [ -f "$VENV/.bootstrap-stamp" ] && [ -x "$VENV/bin/python" ] \
   && [ "$(cat "$VENV/.bootstrap-stamp")" = "$(stamp_of)" ]; then
  say "up to date ($VENV)"
  exit 0
fi

# --- 1. Debian packages --------------------------------------------------------------------------------
missing=()
for p in "${PACKAGES[@]}"; do
  status=$(dpkg-query -W -f='${db:Status-Abbrev}' "$p" 2>/dev/null || true)
  [ "${status:0:2}" = "ii" ] || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null || die "missing Debian packages (${missing[*]}) and not root: install sudo or run as root"
    SUDO="sudo"
  fi
  say "installing Debian packages: ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -q || die "apt-get update failed: check the network access to the Debian mirror"
  $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}" \
    || die "apt-get install failed for: ${missing[*]}"
else
  say "Debian packages present"
fi

# --- 2. the venv -----------------------------------------------------------------------------------------
if [ ! -x "$VENV/bin/python" ]; then
  say "creating $VENV (Debian's python3, --system-site-packages)"
  /usr/bin/python3 -m venv --system-site-packages "$VENV"
fi
"$VENV/bin/python" -c 'import sys; sys.exit(0 if sys.base_prefix == "/usr" else 1)' \
  || die "$VENV was not made from Debian's /usr/bin/python3: remove it (rm -rf $VENV) and run again"

# --- 3. constraints: Debian's versions of the numerical stack ---------------------------------------------
constraints="$VENV/constraints.txt"
/usr/bin/python3 - > "$constraints" <<'PY'
import importlib.metadata as md
for dist in ("numpy", "scipy", "numba", "llvmlite", "h5py", "matplotlib", "meshio", "mpi4py",
             "petsc4py", "slepc4py", "fenics-dolfinx", "gmsh", "pillow", "contourpy", "scikit-image",
             "networkx", "pytest", "packaging", "setuptools"):
    try:
        print(f"{dist}=={md.version(dist)}")
    except md.PackageNotFoundError:
        pass
PY
grep -q '^numpy==' "$constraints" || die "Debian's numpy is not visible to /usr/bin/python3 (python3-numpy)"

# --- 4. the project and PyPI extras ------------------------------------------------------------------------
say "installing the project (editable) and extras into $VENV"
export PIP_DISABLE_PIP_VERSION_CHECK=1
"$VENV/bin/python" -m pip install -q --no-build-isolation -c "$constraints" -e ".[extras,play]" \
  || die "pip install failed; see the messages above (network access to PyPI is needed for opencv, tqdm and gymnasium)"
"$VENV/bin/python" - <<'PY' || exit 1
import numpy, sys
if not numpy.__file__.startswith("/usr/lib/python3/"):
    sys.exit(f"[bootstrap] error: numpy comes from {numpy.__file__}, not Debian; remove .venv and run again")
PY

# --- 5. compiled kernels -------------------------------------------------------------------------------------
# numba compiles the beam kernels on first use (~40 s); compile them once here into the source tree's cache, which
# every later process finds (any folder, any user: sorofem._numba), so a first statics + simulate takes < 1 s.
say "compiling the beam and network kernels into numba's cache (one to two minutes the first time)"
(cd /tmp && "$VENV/bin/python" -m soroshapes.shapes) || die "precompiling the beam kernels failed (see above)"
(cd /tmp && "$VENV/bin/python" -m soroshapes.precompile) || die "precompiling the network kernels failed (see above)"

stamp_of > "$VENV/.bootstrap-stamp"
say "done: $VENV ($("$VENV/bin/python" -c 'import dolfinx; print("DOLFINx", dolfinx.__version__)'))"
