"""Hyperelastic finite elements on DOLFINx: the :class:`Fem` problem builder, its solvers and results.

See :mod:`sorofem.fem.problem` for the weak form, :mod:`sorofem.fem.kinematics` for the plane-strain,
axisymmetric and 3D kinematics and :mod:`sorofem.fem.newton` for the Newton iteration.
"""
from .._petsc import init as _init_petsc

_init_petsc()  # before DOLFINx: Python keeps its signal handling (sorofem._petsc)

from .eigen import Modes
from .kinematics import FORMULATIONS
from .forms import FemForms
from .problem import PRESSURE_SPACES, Fem, LockingWarning
from .results import Trajectory

__all__ = ["Fem", "FemForms", "LockingWarning", "Trajectory", "Modes", "FORMULATIONS", "PRESSURE_SPACES"]
