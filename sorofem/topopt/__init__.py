"""Topology optimization of soft structures and actuators: SIMP, filters, MMA/OC, adjoints, export.

Layer 2 (DOLFINx, imported when a problem is built). The flow::

    from sorofem.mesh import Mesh
    from sorofem import topopt
    msh = Mesh.rectangle(60.0, 20.0, 1.0, center=(30.0, 10.0), cell="quadrilateral")
    prob = topopt.Compliance(msh, volume_fraction=0.5, penalty=3.0, radius=1.5)
    prob.add_support("left", components=0).add_point_support((60.0, 0.0), components=1)
    prob.add_point_force((0.0, 20.0), (0.0, -1.0))
    res = topopt.optimize(prob, method="oc")          # or "mma"
    topopt.density_png(prob, res.x, "mbb.png"); topopt.write_stl(prob, res.x, "mbb.stl", thickness=5.0)

Modules: :mod:`.mma` (Svanberg's MMA), :mod:`.oc` (optimality criteria), :mod:`.filters` (Helmholtz and
cone filters, Heaviside projection), :mod:`.problems` (compliance, compliant mechanisms, pressure-driven
actuators; linear and hyperelastic; adjoint sensitivities), :mod:`.optimize` (the loop, checkpoints),
:mod:`.export` (PNG, XDMF, thresholded and smooth meshes, extruded STL).
"""
from .._petsc import init as _init_petsc

_init_petsc()  # before DOLFINx: Python keeps its signal handling (sorofem._petsc)

from .export import density_image, density_png, design_mesh, nodal_density, threshold_mesh, write_stl, write_xdmf
from .filters import ConeFilter, Heaviside, HelmholtzFilter, LinkedFilter
from .mma import MMA, mma_subproblem
from .oc import oc_update
from .optimize import Result, load_design, optimize, save_design
from .problems import Compliance, Evaluation, Mechanism, PressureActuator, TopOpt

__all__ = ["MMA", "mma_subproblem", "oc_update", "HelmholtzFilter", "ConeFilter", "LinkedFilter", "Heaviside",
           "TopOpt", "Compliance", "Mechanism", "PressureActuator", "Evaluation", "optimize", "Result", "save_design",
           "load_design", "nodal_density", "density_image", "density_png", "write_xdmf", "threshold_mesh",
           "design_mesh", "write_stl"]
