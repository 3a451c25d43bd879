"""An installed copy (a wheel, not the editable install of the repository) has the ``soro`` command and every
demo: the demos are the package data ``soro.demos`` (pyproject.toml), found without the repository's layout.

The wheel is built once from a copy of the sources (an in-tree build writes ``build/`` and ``*.egg-info``
into the repository), installed without dependencies into a fresh venv made like the bootstrap's (Debian's
Python with its system site packages: numpy, scipy, numba, gmsh, matplotlib, DOLFINx), and run from an empty
folder, so that neither the repository nor its editable install can be what answers.
"""
import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DEBIAN_PYTHON = Path("/usr/bin/python3")


def _run(cmd, cwd, timeout=300, env=None):
    res = subprocess.run([str(c) for c in cmd], cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env)
    assert res.returncode == 0, f"{' '.join(map(str, cmd))} failed ({res.returncode}):\n{res.stdout[-3000:]}\n" \
                                f"{res.stderr[-3000:]}"
    return res.stdout


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """The venv (its bin folder) with the wheel installed, and an empty folder to run in."""
    if not DEBIAN_PYTHON.is_file():
        pytest.skip("no Debian /usr/bin/python3 to make a venv like the bootstrap's")
    base = tmp_path_factory.mktemp("wheel")
    src = base / "src"
    src.mkdir()
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    folders = {p.split(".")[0] for p in cfg["packages"]} | set(cfg["package-dir"].values())
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, src / name)
    for folder in sorted(folders):
        shutil.copytree(ROOT / folder, src / folder, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "SORO_DEMOS", "PIP_REQUIRE_VIRTUALENV")}
    _run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "--no-index",
          "-w", base / "dist", "."], cwd=src, env=env)
    wheel, = (base / "dist").glob("soro-*.whl")
    venv = base / "venv"
    _run([DEBIAN_PYTHON, "-m", "venv", "--system-site-packages", venv], cwd=base, env=env)
    _run([venv / "bin/python", "-m", "pip", "install", "-q", "--no-deps", "--no-index", wheel], cwd=base, env=env)
    run = base / "run"
    run.mkdir()
    return venv / "bin", run, env


@pytest.mark.slow
def test_the_wheel_lists_every_demo_and_runs_one(installed):
    bin_dir, run, env = installed
    where = _run([bin_dir / "python", "-c", "import soro, soro.demo; print(soro.__file__); "
                  "print(soro.demo.demos_dir())"], cwd=run, env=env).split()
    assert all(Path(w).is_relative_to(bin_dir.parent) for w in where), where    # the installed copy answers
    listed = _run([bin_dir / "soro", "demo", "--list"], cwd=run, env=env).split()
    demos = sorted(p.stem for p in (ROOT / "demos").glob("*.py") if not p.name.startswith("_"))
    assert listed == demos and "sdf_gallery" in listed
    assert (Path(where[1]) / "sweeps" / "pneunet.toml").is_file()                 # the demos' data files too
    out = _run([bin_dir / "soro", "demo", "sdf_gallery", "--quick", "--out", "o"], cwd=run, env=env, timeout=600)
    assert "report: o/sdf_gallery/report.json" in out
    assert (run / "o" / "sdf_gallery" / "report.json").stat().st_size > 0
    res = subprocess.run([bin_dir / "soro", "demo", "no_such_demo"], cwd=run, capture_output=True, text=True,
                         env=env, timeout=120)
    assert res.returncode == 2 and "no demo named 'no_such_demo'; available: board_pick_place" in res.stderr
