"""The demo runner (``soro demo``): the demos are found as the package data ``soro.demos`` (the repository's
``demos/`` folder, installed with the wheel; ``$SORO_DEMOS`` points at another folder), run through their
``main(out_dir, quick=False, **options)``, and their summary written to ``<out>/<name>/report.json``.

Only the standard library is imported here; a demo imports what it needs.
"""
import importlib.util
import os
import time
from pathlib import Path

from sorofem.errors import DependencyError, ParameterError

__all__ = ["DEFAULT_DEMO", "DemoNotFoundError", "demos_dir", "key_figures", "list_demos", "run_demo"]

#: The demo ``soro demo`` runs without a name: the end-to-end job.
DEFAULT_DEMO = "chain"


class DemoNotFoundError(ParameterError):
    """No demo of that name (the message lists the demos and the folder searched)."""


def demos_dir():
    """The folder of the demo scripts: ``$SORO_DEMOS`` if set, else the installed package ``soro.demos``.

    Raises
    ------
    DependencyError
        When neither exists (an installation without its package data: reinstall the project).
    """
    env = os.environ.get("SORO_DEMOS")
    if env:
        return Path(env)
    spec = importlib.util.find_spec("soro.demos")
    locations = list(spec.submodule_search_locations or ()) if spec is not None else []
    if not locations:
        raise DependencyError("the demos (package soro.demos) are not installed: reinstall the project "
                              "(`pip install .` from the repository), or set SORO_DEMOS to a folder of demos")
    return Path(locations[0])


def list_demos():
    """Names of the demos (files ``NAME.py`` of :func:`demos_dir` whose name does not start with ``_``)."""
    return sorted(p.stem for p in demos_dir().glob("*.py") if not p.name.startswith("_"))


def demo_path(name):
    """The script of demo ``name``; :class:`DemoNotFoundError` (naming the demos) when there is none."""
    path = demos_dir() / f"{name}.py"
    if not str(name) or str(name).startswith("_") or not path.is_file():
        raise DemoNotFoundError(f"no demo named {name!r}; available: {', '.join(list_demos()) or 'none'} "
                                f"(looked in {demos_dir()})")
    return path


def run_demo(name=DEFAULT_DEMO, out="out", quick=False, **options):
    """Run demo ``name``'s ``main(out_dir, quick, **options)`` and write ``<out>/<name>/report.json``.

    Parameters
    ----------
    name : str
        A name of :func:`list_demos`.
    out : str or Path
        Output folder; the demo writes to ``out/name/``.
    quick : bool
        The demo's short run (what the tests use).

    Returns
    -------
    dict
        The summary the demo returned, completed with ``demo``, ``quick`` and its wall time ``wall_time_s`` [s].
    """
    from sorofem.io import write_json

    path = demo_path(name)
    spec = importlib.util.spec_from_file_location(f"soro_demo_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    out_dir = Path(out) / name
    out_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    summary = module.main(out_dir, quick=quick, **options)
    summary = dict(summary or {})
    summary.setdefault("demo", name)
    summary["quick"] = bool(quick)
    summary["wall_time_s"] = round(time.perf_counter() - t0, 3)
    write_json(out_dir / "report.json", summary)
    return summary


def key_figures(summary, max_items=6):
    """The lines ``soro demo`` prints: each top-level figure of ``summary`` that is a number, a string, a bool
    or a list of at most ``max_items`` of those, as ``name: value``; tables and nested entries are named
    only (they are in ``report.json``).

    Returns
    -------
    list of str
    """
    def plain(v):
        return v is None or isinstance(v, (bool, int, float, str))

    def fmt(v):
        return f"{v:.6g}" if isinstance(v, float) else str(v)

    lines, nested = [], []
    for key, value in summary.items():
        if plain(value):
            lines.append(f"{key}: {fmt(value)}")
        elif isinstance(value, (list, tuple)) and len(value) <= max_items and all(plain(v) for v in value):
            lines.append(f"{key}: [{', '.join(fmt(v) for v in value)}]")
        else:
            nested.append(key)
    if nested:
        lines.append(f"(in report.json: {', '.join(nested)})")
    return lines
