"""The compiled model of a :class:`~sorofem.fem.Fem` (:class:`FemForms`) and its load terms.

Each load term is a small function returning its UFL form in the reference configuration, with the weight
``kin.weight`` (1, or :math:`2\\pi R` when axisymmetric); :class:`~sorofem.fem.Fem` adds pressures and springs
to the internal-force residual and subtracts tractions, body forces and gravity (see :mod:`sorofem.fem.problem`
for the weak form).
"""
from dataclasses import dataclass
from typing import Any, NamedTuple, Optional

from .kinematics import Kinematics
from .newton import VolumeConstraint

__all__ = ["FemForms", "LoadConstant", "VolumeControl", "pressure_term", "traction_term", "spring_term",
           "gravity_term", "volume_term"]


class LoadConstant(NamedTuple):
    """A load of the model and the DOLFINx ``Constant`` its value is written into at each load level."""

    kind: str          # "pressure", "traction", "body" or "gravity"
    region: Optional[str]
    constant: Any
    load: Any          # the load: value(t)


class VolumeControl(NamedTuple):
    """A cavity under volume control: the region, the added-volume load and its bordered constraint."""

    region: str
    load: Any          # the load: value(t)
    constraint: VolumeConstraint


@dataclass(frozen=True)
class FemForms:
    """The compiled model of a :class:`Fem` (built on first use, rebuilt after a change): spaces, state,
    forms and the constants the loads are written into. Read it through :attr:`Fem.forms`; the fields are
    DOLFINx/UFL objects (``space`` the FunctionSpace of the state, ``residual``/``jacobian`` compiled forms,
    ``residual_ufl``/``internal_ufl`` the UFL residual with and without loads).

    Attributes
    ----------
    space : dolfinx.fem.FunctionSpace
        Space of the state (vector P1/P2, or mixed: displacement then pressure / thickness strain).
    state : dolfinx.fem.Function
        The current state; solvers write into it.
    kinematics : Kinematics
        F, the integration weight (:math:`2\\pi R` when axisymmetric) and the current area vector.
    dx : ufl.Measure
        Cell measure with the material markers (``dx(k)``: cells of the k-th material).
    bcs : tuple of DirichletBC
    prescribed : tuple of (tuple of Constant, load)
        Prescribed displacements and the constants of their components [m].
    load_constants : tuple of LoadConstant
    volume_controls : tuple of VolumeControl
    residual, jacobian : dolfinx.fem.Form
        :math:`R(u; v)` and :math:`\\partial R/\\partial u`.
    residual_ufl, internal_ufl : ufl.Form
        The residual with loads and the internal-force part only.
    energy : dolfinx.fem.Form
        Strain energy [J] (2D: [J/m]).
    volumes : dict name -> dolfinx.fem.Form
        Cavity volumes [m^3] (2D: [m^2]).
    vertex_space, vertex_displacement, gatherer
        P1 vector space, the displacement interpolated on it and the gatherer of vertex values to rank 0.
    support_dofs : dict region -> {component: owned dofs}
    growth : dolfinx.fem.Function
        Volume growth factor per cell (DG0) [-].
    expansions : tuple of (region, cells, load)
    von_mises : dolfinx.fem.Function
        DG0 von Mises stress [Pa]; ``stress_expressions`` fill it per material on ``material_cells``.
    """

    space: Any
    state: Any
    kinematics: Kinematics
    dx: Any
    cell_tags: Any
    bcs: tuple
    prescribed: tuple
    load_constants: tuple
    volume_controls: tuple
    residual: Any
    jacobian: Any
    residual_ufl: Any
    internal_ufl: Any
    energy: Any
    volumes: dict
    vertex_space: Any
    vertex_displacement: Any
    gatherer: Any
    support_dofs: dict
    growth: Any
    expansions: tuple
    von_mises: Any
    stress_expressions: tuple
    material_cells: tuple


# ---------------------------------------------------------------------------------------------- load terms
def pressure_term(kin, u, v, pressure, ds):
    """Follower pressure [Pa] on the current area (Nanson): :math:`\\int p\\,(J F^{-T} N)\\cdot v\\,w\\,dA`
    (``v`` embedded in 3D, :meth:`Kinematics.embed`)."""
    import ufl
    return pressure * ufl.dot(kin.current_area_vector(u), v) * kin.weight * ds


def traction_term(kin, traction, v, measure):
    """Dead load: :math:`\\int t\\cdot v\\,w` over ``measure`` (a traction [Pa] on ``ds``, a force density
    [N/m^3] on ``dx``)."""
    import ufl
    return ufl.dot(traction, v) * kin.weight * measure


def spring_term(kin, stiffness, u, v, ds):
    """Springs to ground: :math:`\\int k\\, u\\cdot v\\,w\\,dA`, ``stiffness`` k [N/m^3]."""
    import ufl
    return stiffness * ufl.dot(u, v) * kin.weight * ds


def gravity_term(kin, acceleration, v, dx, materials):
    """Weight: :math:`\\sum_k \\int_{\\Omega_k} \\rho_k\\, g\\cdot v\\,w\\,dX` (``dx(k)``: cells of material k)."""
    import ufl
    return sum(mat.density * ufl.dot(acceleration, v) * kin.weight * dx(k) for k, mat in enumerate(materials))


def volume_term(kin, u, ds):
    """Enclosed volume of a cavity from its boundary: :math:`-\\frac1d \\oint x\\cdot (J F^{-T} N)\\,w\\,dA`
    (the outward normal of the body points into the cavity) [m^3; m^2 per unit depth in 2D]."""
    import ufl
    return -ufl.dot(kin.current_position(u), kin.current_area_vector(u)) / kin.dimension * kin.weight * ds
