"""Quiet JIT compilation: DOLFINx compiles forms and elements through cffi/setuptools, whose distutils
shim logs every compiler call at INFO on the root logger (and FFCx installs a root handler that prints it).
Importing the FEM layer installs one filter that drops those INFO records; warnings and errors still pass.
"""
import logging

__all__ = ["silence_compiler_logs"]


def _not_compiler_chatter(record):
    path = record.pathname.replace("\\", "/")
    return record.levelno >= logging.WARNING or not ("distutils" in path or "setuptools" in path)


def silence_compiler_logs():
    """Install the root-logger filter once (idempotent)."""
    root = logging.getLogger()
    if _not_compiler_chatter not in root.filters:
        root.addFilter(_not_compiler_chatter)
