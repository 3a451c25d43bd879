"""Shared pytest fixtures and the benchmark marking: the suite's only conftest.py.

One conftest for the whole tree: with ``--doctest-modules`` pytest 8 imports every ``conftest.py`` as a top-level
module named ``conftest`` and refuses a second one ("import file mismatch"), so the benchmark folder has none.

Benchmarks: every test under ``tests/benchmarks/`` is marked ``bench``; ``make bench`` runs them, ``make test``
does not. A benchmark measures figures in one run (ratios against a baseline or a peer where a target is stated),
prints them and records them with the ``record`` fixture in ``out/bench/<name>.json``. It asserts correctness of
what it measured, never a time.
"""
import json
import os
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BENCHMARKS = REPO / "tests" / "benchmarks"
BENCH_OUT = REPO / "out" / "bench"


@pytest.hookimpl(tryfirst=True)  # mark before `-m` deselects
def pytest_collection_modifyitems(items):
    for item in items:
        if BENCHMARKS in Path(str(item.fspath)).resolve().parents:
            item.add_marker(pytest.mark.bench)


@pytest.fixture
def repo():
    """The repository root."""
    return REPO


@pytest.fixture
def python():
    """The interpreter running the tests (the project's venv under `make test`)."""
    return sys.executable


@pytest.fixture
def subprocess_env():
    """Environment for child processes: MPI allowed as root, no inherited pytest plugins."""
    env = dict(os.environ)
    env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    return env


@pytest.fixture
def record(request):
    """``record(**figures)``: print the figures and merge them into ``out/bench/<test module>.json``."""
    def _record(**figures):
        from sorofem.io import write_json
        path = BENCH_OUT / f"{Path(str(request.fspath)).stem}.json"
        data = json.loads(path.read_text()) if path.exists() else {}
        data[request.node.name] = figures
        write_json(path, data)
        print(f"\n[bench] {request.node.name}: " + ", ".join(f"{k}={v}" for k, v in figures.items()))
    return _record
