"""Every public name that moved (README.md, "Moved names") fails at its old import path with an ImportError that
names its new place, and the new place has it.

The renamed arguments and methods that still work with a DeprecationWarning are checked where they live:
``Fem.solve/follow(t_end=)`` and ``Fem.add_force`` in tests/sorofem/test_fem_api.py, ``TopOpt.add_force`` in
tests/sorofem/test_topopt.py, the sweep TOML's ``[solve] t_end`` in tests/soro/test_sweep.py.
"""
import importlib
import re
import subprocess
import sys

import pytest

ROBOTS = ("export", "preview_png", "board_profile", "VEAB_SIGNAL_RANGE", "Scene", "Channel", "twin_shapes", "scene",
          "reach", "bellows_modulus", "BELLOWS_E_FACTOR", "PARALLEL_BELLOWS_E_FACTOR")
TRADE = ("trade", "cheapest", "within", "trade_table", "trade_text", "trade_figure", "trade_report", "trade_files",
         "SELECTION_KEYS", "TIME_BAND")

#: (old module, old name or None for the module itself) -> (new module, new name): what moved, from where to where.
MOVED = {
    ("sorofem.cli", None): ("soro.cli", "main"),
    ("sorofem.cli", "main"): ("soro.cli", "main"),
    ("sorofem.cli", "run_sweep"): ("soro.cli", "run_sweep"),
    ("sorofem.cli", "run_demo"): ("soro.demo", "run_demo"),
    ("sorofem.cli", "list_demos"): ("soro.demo", "list_demos"),
    ("sorofem.cli", "DEFAULT_DEMO"): ("soro.demo", "DEFAULT_DEMO"),
    ("sorofem.cli", "DEMOS_DIR"): ("soro.demo", "demos_dir"),
    ("sorofem.cli", "doctor"): ("soro.doctor", "doctor"),
    ("sorofem.cli", "run_trade"): ("soro.trade", "run_trade"),
    **{("sorofem.sweep", name): ("soro.sweep", name)
       for name in ("Sweep", "grid", "latin_hypercube", "format_record", "provenance_changes", "SOLVE_KEYS",
                    "SOLVE_TYPES", "PARAMETER_TYPES", "MODES", "MAX_CELLS")},
    **{("soroshapes.dvs", name): ("soro.trade", name) for name in TRADE},
    **{("sorofem.robots", name): ("soro.robots", name) for name in ROBOTS},
    ("soroshapes.network", "warm_up"): ("soroshapes.precompile", "warm_up"),
    **{(module, name): ("soroshapes.trajectory", "Trajectory")
       for module, name in (("soroshapes", "BeamTrajectory"), ("soroshapes.shapes", "BeamTrajectory"),
                            ("soroshapes.beam", "BeamTrajectory"), ("soroshapes.tree", "TreeTrajectory"),
                            ("soroshapes.model", "ModelTrajectory"), ("soroshapes.model", "SystemTrajectory"))},
}


def _import(module, name):
    """``import module`` (name None) or ``from module import name``, as a user writes it."""
    if name is None:
        exec(f"import {module}", {})
    else:
        exec(f"from {module} import {name}", {})


@pytest.mark.parametrize(("old", "new"), list(MOVED.items()), ids=lambda v: ".".join(p for p in v if p))
def test_an_old_import_path_fails_naming_the_new_place(old, new):
    with pytest.raises(ImportError) as info:
        _import(*old)
    assert new[0] in str(info.value) and "Moved names" in str(info.value), str(info.value)
    assert callable(getattr(importlib.import_module(new[0]), new[1])) or new[1].isupper()


def test_the_layers_keep_their_own_names():
    """The moves leave what stayed importable: sorofem.robots' designs, soroshapes.dvs's model building, the
    network's Schedule; an unknown name is still an AttributeError."""
    from sorofem.robots import Design, design
    from soroshapes.dvs import dvs_basis, identify  # noqa: F401
    from soroshapes.network import Schedule  # noqa: F401

    import soroshapes.dvs
    assert not hasattr(Design, "scene") and callable(design)
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        soroshapes.dvs.nope  # noqa: B018
    assert importlib.util.find_spec("sorofem.io") is not None   # the moved-module finder answers only its names


def test_the_readme_lists_every_moved_name(repo):
    text = (repo / "README.md").read_text()
    section = re.search(r"## Moved names\n(.*?)\n## ", text, flags=re.S)
    assert section, "README.md has no 'Moved names' section"
    rows = section.group(1)
    missing = sorted({f"{m}.{n}" if n else m for (m, n) in MOVED     # a name, or its whole module as "m.*"
                      if f"`{m}.*`" not in rows and f"`{n or m}`" not in rows and f"`{m}.{n}`" not in rows})
    assert not missing, f"add to README.md's 'Moved names': {missing}"


def test_the_old_precompile_entry_names_the_new_one():
    """``python -m soroshapes.network`` (the bootstrap's old precompile step) no longer warms up: the new step is
    ``python -m soroshapes.precompile`` (tests/soroshapes/test_network.py runs it)."""
    run = subprocess.run([sys.executable, "-c", "import soroshapes.network as n; n.warm_up"], capture_output=True,
                         text=True, timeout=120)
    assert run.returncode != 0 and "soroshapes.precompile.warm_up" in run.stderr
