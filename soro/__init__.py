"""soro: the application layer of the platform (on top of :mod:`sorofem`, :mod:`soroshapes` and
:mod:`sorocontrol`): :mod:`soro.play`, the interactive browser page. Nothing heavy is imported here."""

__all__ = ["play"]


def __getattr__(name):
    if name == "play":
        import importlib
        return importlib.import_module("soro.play")
    raise AttributeError(f"module 'soro' has no attribute {name!r}")
