"""``soro doctor``: the versions of the numerical stack (DOLFINx, PETSc, SLEPc, MPI, numba, gmsh, OpenCV, ...),
the JIT cache (writable; no stale lock of a killed compile, :mod:`sorofem.jitcache`), that a UFL form
JIT-compiles and assembles, and that ``mpirun -n 2`` works. :func:`doctor` prints the report and returns the
exit status: 0 when all is well, otherwise 1, with one line per problem that says how to fix it.

Only the standard library is imported at load time; every check imports what it tests.
"""
import importlib
import os
import platform
import shutil
import subprocess
import sys
import time
from pathlib import Path

__all__ = ["doctor", "mpi_env"]

_BOOTSTRAP = "run `bash scripts/bootstrap.sh` from the repository (or `make test`), then use `.venv/bin/soro`"


def mpi_env():
    """Environment for ``mpirun``: Debian's OpenMPI refuses to run as root without these two variables."""
    env = dict(os.environ)
    env.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
    env.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    env.setdefault("OMPI_MCA_rmaps_base_oversubscribe", "1")
    return env


# (label, module, version getter, fix hint)
_PACKAGES = [
    ("numpy", "numpy", lambda m: m.__version__, "apt-get install python3-numpy; " + _BOOTSTRAP),
    ("scipy", "scipy", lambda m: m.__version__, "apt-get install python3-scipy; " + _BOOTSTRAP),
    ("numba", "numba", lambda m: m.__version__, "apt-get install python3-numba; " + _BOOTSTRAP),
    ("gmsh", "gmsh", lambda m: m.__version__, "apt-get install python3-gmsh; " + _BOOTSTRAP),
    ("meshio", "meshio", lambda m: m.__version__, "apt-get install python3-meshio; " + _BOOTSTRAP),
    ("h5py", "h5py", lambda m: m.__version__, "apt-get install python3-h5py; " + _BOOTSTRAP),
    ("matplotlib", "matplotlib", lambda m: m.__version__, "apt-get install python3-matplotlib; " + _BOOTSTRAP),
    ("mpi4py", "mpi4py", lambda m: m.__version__, "apt-get install python3-mpi4py; " + _BOOTSTRAP),
    ("MPI library", "mpi4py.MPI", lambda m: m.Get_library_version().splitlines()[0].strip(),
     "apt-get install openmpi-bin python3-mpi4py; " + _BOOTSTRAP),
    ("PETSc", "petsc4py.PETSc", lambda m: ".".join(map(str, m.Sys.getVersion())),
     "apt-get install python3-petsc4py; " + _BOOTSTRAP),
    ("SLEPc", "slepc4py.SLEPc", lambda m: ".".join(map(str, m.Sys.getVersion())),
     "apt-get install python3-slepc4py; " + _BOOTSTRAP),
    ("DOLFINx", "dolfinx", lambda m: m.__version__,
     "apt-get install python3-dolfinx (Debian 12 ships 0.5.2, Debian 13 0.9.0); " + _BOOTSTRAP),
    ("OpenCV", "cv2", lambda m: m.__version__,
     "pip install opencv-python-headless into the project's venv; " + _BOOTSTRAP),
    ("tqdm", "tqdm", lambda m: m.__version__, "pip install tqdm into the project's venv; " + _BOOTSTRAP),
]


def _check_packages():
    rows, problems = [], []
    for label, module, version, fix in _PACKAGES:
        try:
            mod = importlib.import_module(module)
            rows.append((label, str(version(mod)), getattr(mod, "__file__", "") or ""))
        except Exception as e:  # noqa: BLE001 - any import failure is a problem to report, not to raise
            rows.append((label, "MISSING", f"{type(e).__name__}: {e}"))
            problems.append(f"{label} cannot be imported ({type(e).__name__}: {e}). Fix: {fix}")
    return rows, problems


def _check_debian_numpy():
    """numpy must be Debian's build: DOLFINx, SciPy and numba were compiled against it."""
    try:
        import numpy
    except ImportError:
        return []  # already reported
    if not numpy.__file__.startswith("/usr/lib/python3/"):
        return [f"numpy {numpy.__version__} is loaded from {numpy.__file__}, not Debian's /usr/lib/python3: "
                "a pip-installed numpy shadows the one DOLFINx was built against. Fix: "
                "`.venv/bin/pip uninstall numpy`, then " + _BOOTSTRAP + " (it pins numpy with a constraints file)"]
    return []


def _blas():
    """Which BLAS Debian's alternatives give ``libblas.so.3`` (MUMPS, numpy and scipy use it)."""
    import glob

    for link in sorted(glob.glob("/usr/lib/*-linux-gnu/libblas.so.3")):
        real = os.path.realpath(link)
        if "openblas" in real:
            return f"OpenBLAS ({real})"
        if "blis" in real or "mkl" in real or "atlas" in real:
            return real
        return (f"reference BLAS ({real}): direct solves run ~5x slower; "
                "`apt-get install libopenblas0-serial` (scripts/bootstrap.sh does)")
    return "not found in /usr/lib/*-linux-gnu (not a Debian layout)"


def _check_dolfinx_support():
    """Whether the installed DOLFINx is in the tested range (:data:`sorofem._dolfinx.SUPPORTED`)."""
    from sorofem import _dolfinx

    ok, sentence = _dolfinx.support_status()
    return ("yes: " if ok else "NO: ") + sentence, ([] if ok else [sentence])


def _check_jit():
    """Compile and assemble a small UFL form: integral of 1 over the unit square must be 1."""
    from sorofem._jit import silence_compiler_logs

    silence_compiler_logs()
    t0 = time.perf_counter()
    try:
        from mpi4py import MPI
        import ufl
        import dolfinx.fem
        import dolfinx.mesh
        msh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 2, 2)
        one = dolfinx.fem.Constant(msh, 1.0)
        value = dolfinx.fem.assemble_scalar(dolfinx.fem.form(one * ufl.dx(domain=msh)))
    except Exception as e:  # noqa: BLE001
        return f"failed ({type(e).__name__}: {e})", [
            f"a UFL form does not JIT-compile ({type(e).__name__}: {e}). Fix: check that gcc and "
            "python3-dev are installed (apt-get install build-essential python3-dev) and that "
            "~/.cache/fenics is writable; " + _BOOTSTRAP]
    if abs(value - 1.0) > 1e-12:
        return f"wrong result {value}", [f"a JIT-compiled form gave {value} instead of 1.0: the FEniCSx "
                                         "installation is broken; reinstall python3-dolfinx"]
    return f"ok ({time.perf_counter() - t0:.1f} s)", []


def _check_jit_cache(directory=None):
    """The JIT cache: its directory, module count and locks; a stale lock (killed compile) is a problem."""
    from sorofem import jitcache

    directory = Path(directory) if directory is not None else jitcache.cache_dir()
    if not directory.exists():
        return f"{directory} (empty)", []
    if not os.access(directory, os.W_OK):
        return f"{directory} not writable", [f"the JIT cache {directory} is not writable: forms cannot be "
                                             "compiled. Fix: chown or chmod it, or set XDG_CACHE_HOME"]
    modules = len(list(directory.glob("*.c.cached")))
    locks = jitcache.scan(directory)
    stale = [lock for lock in locks if lock.stale]
    status = f"{directory}: {modules} compiled module(s), {len(locks) - len(stale)} compiling, {len(stale)} stale"
    problems = []
    if stale:
        files = " ".join(str(lock.path) for lock in stale)
        problems.append(f"{len(stale)} stale JIT lock(s) of killed compiles ({stale[0].reason}): every run that "
                        f"needs those forms waits for the JIT timeout and fails. Fix: rm {files} "
                        "(soro sweep removes them at start)")
    return status, problems


def _check_mpi():
    """Run two ranks that sum their ranks with an allreduce."""
    mpirun = shutil.which("mpirun")
    if mpirun is None:
        return "mpirun not found", ["mpirun is not on PATH. Fix: apt-get install openmpi-bin"]
    # only rank 0 prints: output of two ranks interleaves character by character
    code = ("from mpi4py import MPI; c = MPI.COMM_WORLD; s = c.allreduce(c.rank)\n"
            "if c.rank == 0: print(c.size, s)")
    try:
        res = subprocess.run([mpirun, "-n", "2", sys.executable, "-c", code], capture_output=True, text=True,
                             timeout=120, env=mpi_env(), stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return "timed out", ["`mpirun -n 2` did not finish in 120 s. Fix: check that no firewall or hostname "
                             "lookup blocks OpenMPI (try `mpirun -n 2 hostname`)"]
    lines = res.stdout.split()
    if res.returncode != 0 or lines != ["2", "1"]:
        return f"failed (exit {res.returncode})", [
            f"`mpirun -n 2 python` failed (exit {res.returncode}): {res.stderr.strip()[-300:]} Fix: "
            "apt-get install openmpi-bin python3-mpi4py; as root set OMPI_ALLOW_RUN_AS_ROOT=1 and "
            "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1"]
    return "ok (2 ranks)", []


def doctor(stream=None):
    """Check the installation; print a report to ``stream`` (default stdout). Return the exit status."""
    out = stream or sys.stdout
    print(f"soro doctor — Python {platform.python_version()} at {sys.executable}", file=out)
    rows, problems = _check_packages()
    width = max(len(r[0]) for r in rows)
    for label, version, where in rows:
        print(f"  {label:<{width}}  {version}", file=out)
    problems += _check_debian_numpy()
    print(f"  {'BLAS':<{width}}  {_blas()}", file=out)
    have_dolfinx = all(r[1] != "MISSING" for r in rows if r[0] in ("DOLFINx", "mpi4py"))
    status, p = _check_jit_cache()
    problems += p
    print(f"  {'JIT cache':<{width}}  {status}", file=out)
    if have_dolfinx:
        support, p = _check_dolfinx_support()
        problems += p
        status, p = _check_jit()
        problems += p
    else:
        support = status = "skipped (DOLFINx missing)"
    print(f"  {'supported':<{width}}  {support}", file=out)
    print(f"  {'form JIT':<{width}}  {status}", file=out)
    status, p = _check_mpi()
    problems += p
    print(f"  {'mpirun -n 2':<{width}}  {status}", file=out)
    if problems:
        print(f"\n{len(problems)} problem(s):", file=out)
        for p in problems:
            print(f"  - {p}", file=out)
        return 1
    print("\nall checks passed", file=out)
    return 0
