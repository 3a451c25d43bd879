"""A private venv holding PyElastica, the peer of the Cosserat-rod benchmarks.

The peer never enters the project's venv (its numba/numpy pins differ from ours): it is installed once into
``out/peers/elastica-venv`` from a plain, non-venv ``python3`` found on ``PATH`` (the pyenv interpreter on the
developers' machines and CI), and the benchmark scripts talk to it through a subprocess and JSON.
"""
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

__all__ = ["ensure_elastica_venv", "ElasticaVenvError", "PYELASTICA_VERSION", "DEFAULT_ROOT"]

PYELASTICA_VERSION = "1.0.0"
DEFAULT_ROOT = Path(__file__).resolve().parents[3] / "out" / "peers" / "elastica-venv"
_STAMP = ".soro-peer-stamp"
_PROJECT_VENV = (Path(__file__).resolve().parents[3] / ".venv").resolve()


class ElasticaVenvError(RuntimeError):
    """The peer venv could not be built; the message carries the tail of the failing command's output."""


def _tail(text, lines=30):
    return "\n".join(text.strip().splitlines()[-lines:])


def _run(cmd, what, timeout=1800):
    proc = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=timeout,
                          env={k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "PYTHONPATH",
                                                                                "PYTHONHOME")})
    if proc.returncode != 0:
        raise ElasticaVenvError(f"{what} failed (exit {proc.returncode}): {' '.join(map(str, cmd))}\n"
                                f"--- output tail ---\n{_tail(proc.stdout + proc.stderr)}")
    return proc.stdout


def _base_python():
    """The first ``python3`` on PATH that is a plain interpreter (not a venv, not the project's) with venv
    and ensurepip; ``SORO_PEER_PYTHON`` overrides the search."""
    override = os.environ.get("SORO_PEER_PYTHON")
    candidates = [override] if override else [str(Path(d) / "python3") for d in os.environ.get("PATH", "").split(
        os.pathsep) if d and (Path(d) / "python3").is_file()]
    probe = "import sys, venv, ensurepip; print(sys.executable); print(sys.prefix == sys.base_prefix)"
    rejected = []
    for exe in candidates:
        if Path(exe).resolve().is_relative_to(_PROJECT_VENV):
            rejected.append(f"{exe}: the project venv")
            continue
        try:
            out = subprocess.run([exe, "-c", probe], capture_output=True, text=True, timeout=60,
                                 env={k: v for k, v in os.environ.items() if k != "VIRTUAL_ENV"})
        except (OSError, subprocess.TimeoutExpired) as e:
            rejected.append(f"{exe}: {e}")
            continue
        lines = out.stdout.split()
        if out.returncode != 0 or len(lines) != 2:
            rejected.append(f"{exe}: no venv/ensurepip ({_tail(out.stderr, 1)})")
        elif lines[1] != "True":
            rejected.append(f"{exe}: is itself a venv")
        elif Path(lines[0]).resolve().is_relative_to(_PROJECT_VENV):
            rejected.append(f"{exe}: the project venv")
        else:
            return lines[0]
    raise ElasticaVenvError("no plain python3 with venv and ensurepip on PATH for the PyElastica peer venv "
                            "(set SORO_PEER_PYTHON to one); tried:\n  " + "\n  ".join(rejected or ["nothing"]))


def _venv_python(root):
    return Path(root) / "bin" / "python"


def _ready(root):
    stamp = Path(root) / _STAMP
    return stamp.is_file() and stamp.read_text().strip() == PYELASTICA_VERSION and _venv_python(root).exists()


def ensure_elastica_venv(root=DEFAULT_ROOT):
    """Create (once) a venv at ``root`` with ``pyelastica==1.0.0`` and return the path of its python.

    A stamp file records the version installed; an existing venv with the right stamp is reused in a few
    milliseconds. The venv is built in a temporary folder beside ``root`` and renamed into place, so an
    interrupted build leaves nothing half-made. Raises :class:`ElasticaVenvError` with the tail of the
    failing command's output (``venv`` creation or ``pip install``).
    """
    root = Path(root).absolute()
    if _ready(root):
        return _venv_python(root)
    base = _base_python()
    root.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=root.name + ".tmp-", dir=root.parent))
    try:
        # bin/python finds its venv through pyvenv.cfg beside it, so the renamed tree works; the console
        # scripts (bin/pip, ...) keep the temporary path in their shebang: call them as `python -m pip`.
        _run([base, "-m", "venv", tmp], "creating the PyElastica venv")
        _run([_venv_python(tmp), "-m", "pip", "install", "--no-input", f"pyelastica=={PYELASTICA_VERSION}"],
             f"pip install pyelastica=={PYELASTICA_VERSION}")
        _run([_venv_python(tmp), "-c", "import elastica"], "importing elastica in the peer venv")
        (tmp / _STAMP).write_text(PYELASTICA_VERSION + "\n")
        if _ready(root):  # another process finished first: keep its venv
            shutil.rmtree(tmp, ignore_errors=True)
            return _venv_python(root)
        if root.exists():
            shutil.rmtree(root)
        tmp.rename(root)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return _venv_python(root)


if __name__ == "__main__":
    print(ensure_elastica_venv(Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT_ROOT))
