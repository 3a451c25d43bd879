"""PETSc started without its signal handlers, so that Python keeps its own.

When petsc4py initializes PETSc with the default options, PETSc installs handlers for SIGSEGV, SIGFPE, SIGBUS,
SIGPIPE, SIGTERM and more. In a Python process that replaces Python's own behaviour: a write to a socket whose
peer has gone (SIGPIPE, which Python ignores so that the write raises ``BrokenPipeError``) then aborts the whole
process through ``MPI_Abort`` ("Caught signal number 13 Broken Pipe"), and a native crash is reported by PETSc
without the Python stack that :mod:`faulthandler` would print. The board client in a process that also runs FEM,
as the test suite and the demos do, was killed that way when a board dropped its connection.

:func:`init` starts PETSc with ``-no_signal_handler`` (plus any ``PETSC_OPTIONS`` of the environment) unless
petsc4py was already initialized by the caller, in which case the caller's choice stands. The FEM packages
(``sorofem.mesh``, ``sorofem.fem``, ``sorofem.topopt``) call it before they import DOLFINx.
"""
import sys

__all__ = ["init"]


def init():
    """Initialize petsc4py without PETSc's signal handlers (idempotent; a no-op once PETSc is initialized)."""
    if "petsc4py.PETSc" in sys.modules:
        return
    import petsc4py

    # the first entry is the program name; under `python -c` sys.argv[0] is "-c", which petsc4py 3.22 (Debian 13)
    # takes for an option (it then prepends the interpreter, and PETSc warns at exit that "-c" was not used)
    prog = sys.argv[0] if sys.argv and sys.argv[0] and not sys.argv[0].startswith("-") else sys.executable
    petsc4py.init([prog or "python", "-no_signal_handler"])
