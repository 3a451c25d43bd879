"""Lazy package attributes (PEP 562) shared by the packages whose submodules import heavy libraries."""
import importlib

__all__ = ["lazy_attributes"]


def lazy_attributes(package, submodules, classes):
    """A module ``__getattr__`` for ``package`` that imports the submodule ``name`` (in ``submodules``), or the
    module of the class ``name`` (``classes``: name -> submodule), on first access."""
    def __getattr__(name):
        if name in submodules:
            return importlib.import_module(f"{package}.{name}")
        if name in classes:
            return getattr(importlib.import_module(f"{package}.{classes[name]}"), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")
    return __getattr__
