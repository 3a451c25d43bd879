"""Hyperelastic finite elements on DOLFINx: the :class:`Fem` problem builder, its solvers and results.

See :mod:`sorofem.fem.problem` for the weak form, :mod:`sorofem.fem.kinematics` for the plane-strain,
axisymmetric and 3D kinematics and :mod:`sorofem.fem.newton` for the Newton iteration.
"""
from .eigen import Modes
from .kinematics import FORMULATIONS
from .problem import Fem
from .results import Trajectory

__all__ = ["Fem", "Trajectory", "Modes", "FORMULATIONS"]
