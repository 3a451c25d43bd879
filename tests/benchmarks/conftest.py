"""Benchmarks: every test in this folder is marked `bench`; `make bench` runs them, `make test` does not.

A benchmark measures figures in one run (ratios against a baseline or a peer where a target is stated),
prints them and records them with the ``record`` fixture in ``out/bench/<name>.json``. It asserts
correctness of what it measured, never a time.
"""
import json
from pathlib import Path

import pytest

OUT = Path(__file__).resolve().parents[2] / "out" / "bench"


@pytest.hookimpl(tryfirst=True)  # mark before `-m` deselects
def pytest_collection_modifyitems(items):
    for item in items:
        if Path(str(item.fspath)).parent == Path(__file__).parent:
            item.add_marker(pytest.mark.bench)


@pytest.fixture
def record(request):
    """``record(**figures)``: print the figures and merge them into ``out/bench/<test module>.json``."""
    def _record(**figures):
        from sorofem.io import write_json
        path = OUT / f"{Path(str(request.fspath)).stem}.json"
        data = json.loads(path.read_text()) if path.exists() else {}
        data[request.node.name] = figures
        write_json(path, data)
        print(f"\n[bench] {request.node.name}: " + ", ".join(f"{k}={v}" for k, v in figures.items()))
    return _record
