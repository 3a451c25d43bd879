"""The platform's exception hierarchy.

Every error the platform raises on purpose is a :class:`SoroError`, so a script can catch them all at once,
and a subclass names the layer that failed. Messages say what went wrong *and what to do about it*.

``SoroError``
    ├── ``ParameterError``     a non-physical or inconsistent parameter (negative modulus, nu >= 0.5, ...)
    ├── ``GeometryError``      bad shapes or geometric queries (empty shape, self-intersecting polygon, ...)
    ├── ``MeshError``          meshing failed or produced an unusable mesh
    ├── ``DataError``          a result file or data set is missing, corrupt, of another version, or non-finite
    ├── ``ConvergenceError``   a solver did not converge (says which step, which residual, what to try)
    ├── ``ProtocolError``      a malformed or unexpected message on the board link
    ├── ``SafetyError``        a command that would break a pressure or rate limit
    └── ``DependencyError``   a missing or broken dependency (``soro doctor`` tells how to fix it)

``ParameterError``, ``GeometryError`` and ``MeshError`` are also ``ValueError`` so that generic input validation code that
expects ``ValueError`` keeps working.
"""

__all__ = [
    "SoroError",
    "ParameterError",
    "GeometryError",
    "MeshError",
    "DataError",
    "ConvergenceError",
    "ProtocolError",
    "SafetyError",
    "DependencyError",
]


class SoroError(Exception):
    """Base class of every error raised on purpose by the platform."""


class ParameterError(SoroError, ValueError):
    """A parameter is non-physical or inconsistent (negative modulus, Poisson ratio outside (-1, 0.5), ...)."""


class GeometryError(SoroError, ValueError):
    """A shape or geometric query is invalid (empty shape, non-positive size, self-intersecting polygon)."""


class MeshError(SoroError, ValueError):
    """Meshing failed or produced a mesh that cannot be used (quality, missing regions, unreadable file)."""


class DataError(SoroError, ValueError):
    """A result file or data set is missing, corrupt, of an unsupported version, or holds non-finite values."""


class ConvergenceError(SoroError, RuntimeError):
    """A nonlinear or time-stepping solver failed; the message names the step, the residual and a remedy."""


class ProtocolError(SoroError, IOError):
    """A malformed, unauthenticated or unexpected message on the board link."""


class SafetyError(SoroError):
    """A command would violate a safety limit (pressure range, rate limit, watchdog)."""


class DependencyError(SoroError, ImportError):
    """A required dependency is missing or broken; the message tells how to install or repair it."""
