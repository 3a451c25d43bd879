"""soro: the application layer of the platform, on top of :mod:`sorofem` <- :mod:`soroshapes` <- :mod:`sorocontrol`.

:mod:`soro.cli`
    the ``soro`` command; the only place where errors become exit codes;
:mod:`soro.doctor`, :mod:`soro.demo`
    ``soro doctor`` (the installation's checks) and the demo runner (the demos are the package data
    ``soro.demos``);
:mod:`soro.sweep`
    ``soro sweep``: batches of FEM cases from a TOML file (schema, sampling, manifest, runner);
:mod:`soro.trade`
    ``soro trade``: the speed-accuracy study of beam models against their FEM parent;
:mod:`soro.robots`
    the open-hardware robots' twins, board profiles and export (``soro robot``), on the designs of
    :mod:`sorofem.robots`;
:mod:`soro.play`
    ``soro play``, the interactive browser page.

Nothing heavy is imported here: the submodules load on first access.
"""
import importlib

__all__ = ["cli", "demo", "doctor", "sweep", "trade", "robots", "play"]


def __getattr__(name):
    if name in __all__:
        return importlib.import_module(f"soro.{name}")
    raise AttributeError(f"module 'soro' has no attribute {name!r}")
