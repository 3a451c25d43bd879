"""Lazy package attributes (PEP 562) shared by the packages whose submodules import heavy libraries, and the
ImportErrors of public names that moved (they name the new place)."""
import importlib

__all__ = ["lazy_attributes", "moved", "moved_attributes", "moved_modules"]


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


def moved(old, new):
    """The :class:`ImportError` for a public name ``old`` that moved to ``new``: its message names the new place
    (README.md, "Moved names")."""
    return ImportError(f"{old} moved to {new} (see 'Moved names' in README.md)", name=old)


def moved_attributes(package, table, fallback=None):
    """A module ``__getattr__`` for ``package``: a name of ``table`` (name -> its new place) raises
    :func:`moved`'s ImportError (``from package import name`` then says where the name went); any other name goes
    to ``fallback`` (another module ``__getattr__``) or is an AttributeError."""
    def __getattr__(name):
        if name in table:
            raise moved(f"{package}.{name}", table[name])
        if fallback is not None:
            return fallback(name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")
    return __getattr__


class _MovedModules:
    """A meta-path finder that answers ``import old`` for the modules of its table with :func:`moved`'s
    ImportError and leaves every other name to the next finder."""

    def __init__(self):
        self.table = {}

    def find_spec(self, fullname, path=None, target=None):
        if fullname in self.table:
            raise moved(fullname, self.table[fullname])
        return None


_FINDER = _MovedModules()


def moved_modules(table):
    """Make ``import OLD`` of a module that moved raise an ImportError naming its new place (``table``: old module
    name -> new place); the finder is installed once, at the front of ``sys.meta_path``, and answers only the
    names of its table."""
    import sys

    _FINDER.table.update(table)
    if _FINDER not in sys.meta_path:
        sys.meta_path.insert(0, _FINDER)
