"""The `soro` command: doctor (versions, JIT, MPI, fixes), the demo runner and the sweep subcommand
(whose runs are tested in tests/sorofem/test_sweep.py)."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

from sorofem import cli

SORO = [sys.executable, "-m", "sorofem.cli"]


@pytest.mark.slow
def test_doctor_passes_and_prints_every_version(subprocess_env):
    res = subprocess.run([*SORO, "doctor"], capture_output=True, text=True, env=subprocess_env, timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
    for label in ("DOLFINx", "PETSc", "SLEPc", "MPI library", "numba", "gmsh", "OpenCV", "form JIT", "mpirun -n 2"):
        line = next((ln for ln in res.stdout.splitlines() if ln.strip().startswith(label)), None)
        assert line is not None, f"{label} missing from doctor output"
        assert "MISSING" not in line and "failed" not in line, line
    import dolfinx

    found = next(ln for ln in res.stdout.splitlines() if ln.strip().startswith("DOLFINx"))
    assert found.split()[-1] == dolfinx.__version__  # the version it found: Debian 12's 0.5.2 or 13's 0.9.x
    support = next(ln for ln in res.stdout.splitlines() if ln.strip().startswith("supported"))
    assert f"yes: DOLFINx {dolfinx.__version__} is supported" in support, support


def test_doctor_without_dolfinx_fails_with_the_fix(tmp_path, subprocess_env):
    """Shadow DOLFINx with a package that cannot be imported: doctor must exit 1 and say how to fix it."""
    fake = tmp_path / "dolfinx"
    fake.mkdir()
    (fake / "__init__.py").write_text("raise ImportError('No module named dolfinx (test shadow)')\n")
    env = {**subprocess_env, "PYTHONPATH": str(tmp_path)}
    res = subprocess.run([*SORO, "doctor"], capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 1
    assert "DOLFINx" in res.stdout and "MISSING" in res.stdout
    assert "apt-get install python3-dolfinx" in res.stdout
    assert "scripts/bootstrap.sh" in res.stdout


def test_demo_list_and_unknown_demo(capsys):
    assert cli.main(["demo", "--list"]) == 0
    names = capsys.readouterr().out.split()
    assert cli.DEFAULT_DEMO in names
    with pytest.raises(SystemExit, match="no demo named 'nope'"):
        cli.run_demo("nope")


def test_run_demo_writes_report(tmp_path, monkeypatch):
    demos = tmp_path / "demos"
    demos.mkdir()
    (demos / "tiny.py").write_text("def main(out, quick=False):\n"
                                   "    (out / 'x.txt').write_text('hi')\n"
                                   "    return {'value': 2.5}\n")
    monkeypatch.setattr(cli, "DEMOS_DIR", demos)
    summary = cli.run_demo("tiny", out=tmp_path / "out", quick=True)
    report = json.loads((tmp_path / "out/tiny/report.json").read_text())
    assert report["value"] == 2.5 and report["quick"] is True and report["demo"] == "tiny"
    assert summary["wall_time_s"] >= 0
    assert (tmp_path / "out/tiny/x.txt").read_text() == "hi"


def test_sweep_subcommand_options_and_lazy_import(capsys):
    res = subprocess.run([sys.executable, "-c", "import sys, sorofem.cli; "
                          "print('sorofem.sweep' in sys.modules, 'numpy' in sys.modules)"],
                         capture_output=True, text=True, check=True)
    assert res.stdout.split() == ["False", "False"], "sorofem.cli must import only the standard library"
    with pytest.raises(SystemExit) as exit_:
        cli.main(["sweep", "--help"])
    assert exit_.value.code == 0
    text = capsys.readouterr().out
    for option in ("config", "--out", "--group-size", "--retry-failed", "--dry-run"):
        assert option in text
    assert cli.main(["sweep", "no/such/config.toml"]) == 2
    assert "no sweep configuration at no/such/config.toml" in capsys.readouterr().err


def test_soro_trade_on_snapshot_files(tmp_path):
    """The trade from two snapshot files of a synthetic bending case (the DVS tests' field), through the CLI."""
    import numpy as np
    from fields import L, bar_mesh_2d, rod_field, write

    V, cells = bar_mesh_2d(40, 2)
    p = np.linspace(0, 1e4, 6)
    fields = [rod_field(V, np.array([0, 0, 3e-3 * pk, 1, 0, 0])) for pk in p]
    train = write(tmp_path / "train.h5", V, cells, "triangle", fields, inputs={"pressure": p})
    test = write(tmp_path / "test.h5", V, cells, "triangle", [rod_field(V, np.array([0, 0, 16.5, 1, 0, 0]))],
                 inputs={"pressure": [5.5e3]})
    code = cli.main(["trade", str(train), str(test), "--backbone", f"0,0:{L},0", "--out", str(tmp_path / "t")])
    assert code == 0
    text = (tmp_path / "t" / "trade.txt").read_text()
    assert "cheapest within 3 %" in text and (tmp_path / "t" / "trade.png").stat().st_size > 0
    assert cli.main(["trade", str(train)]) == 2
