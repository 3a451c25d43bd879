"""soroshapes: reduced-order Cosserat beam models, data-driven strain bases and networks of dynamic systems.

Runs without DOLFINx: it uses :mod:`sorofem.sdf` for sections and contact and reads FEM results only as
snapshot files. Numba kernels compile on first use, not at import: submodules (:mod:`~soroshapes.lie` the
SO(3)/SE(3) kernels, :mod:`~soroshapes.basis` the modal strain bases, :mod:`~soroshapes.beam` the beam's frozen
description, workspace, load terms and solvers, :mod:`~soroshapes.shapes` the Cosserat beam model,
:mod:`~soroshapes.numerics` the finite-difference helper, :mod:`~soroshapes.render` tube rendering,
:mod:`~soroshapes.model` networks of beams, fluidic reservoirs and state-space systems,
:mod:`~soroshapes.trajectory` the one result type of every simulation) and the public classes are loaded on
first attribute access, so ``import soroshapes`` does not import numba.
"""
from sorofem._lazy import lazy_attributes, moved_attributes

_SUBMODULES = ("lie", "basis", "beam", "shapes", "numerics", "render", "dvs", "model", "rigid", "control", "gym",
               "network", "integrate")
_CLASSES = {"Basis": "basis", "Shapes": "shapes", "IKResult": "shapes",
            "Model": "model", "StateSpace": "model", "Fluidic": "model", "RigidBody": "rigid",
            "SpinningBody": "rigid"}
# holonomic end constraints of beam statics (issue 25)
_SUBMODULES += ("constraints",)
_CLASSES.update(Weld="constraints", Pin="constraints", Align="constraints")
# valve flow functions of the reservoirs (issue 26)
_SUBMODULES += ("valves",)
_CLASSES.update(Orifice="valves")
# trees of beams and rigid links (issue 25)
_SUBMODULES += ("tree",)
_CLASSES.update(Tree="tree")
# beam model files (issue 24: the model `soro trade --tol` chooses, loaded by Python)
_SUBMODULES += ("io",)
# one trajectory type for beams, trees and networks; the old names are in README.md, "Moved names"
_SUBMODULES += ("trajectory",)
_CLASSES.update(Trajectory="trajectory")
MOVED = {"BeamTrajectory": "soroshapes.trajectory.Trajectory"}

__all__: list[str] = [*_SUBMODULES, *_CLASSES]


__getattr__ = moved_attributes(__name__, MOVED, lazy_attributes(__name__, _SUBMODULES, _CLASSES))
