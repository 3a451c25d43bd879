"""Kinematics of the four formulations, written once in 3x3 form.

Every formulation gives a 3x3 deformation gradient, so that material laws, follower pressures and cavity
volumes are written once in 3D algebra:

``plane_strain`` (2D, per unit depth)
    :math:`F = \\begin{bmatrix} I_2 + \\nabla u & 0 \\\\ 0 & 1 \\end{bmatrix}`, measure weight 1 [m of depth].
``plane_stress`` (2D, per unit reference thickness)
    :math:`F = \\begin{bmatrix} I_2 + \\nabla u & 0 \\\\ 0 & \\lambda_3 \\end{bmatrix}`, weight 1 [m of
    thickness]. The thickness stretch :math:`\\lambda_3 = 1 + e_{33}` is a discontinuous field of one degree
    below the displacement's, an unknown of the problem: stationarity of the energy with respect to it is
    :math:`\\int P_{33}\\, \\delta e_{33}\\, dX = 0`, the plane-stress condition, for every material law
    (for linear elasticity on straight-sided triangles it gives exactly the condensed plane-stress law,
    :math:`e_{33} = -\\lambda (\\varepsilon_{11} + \\varepsilon_{22}) / (\\lambda + 2\\mu)`).
``axisymmetric`` (2D section in the (r, z) = (x, y) half plane, x >= 0, revolved about the y axis)
    :math:`F = \\begin{bmatrix} I_2 + \\nabla u & 0 \\\\ 0 & 1 + u_r / R \\end{bmatrix}` (hoop stretch),
    measure weight :math:`2\\pi R`, so that integrals are over the full revolved body.
``3d``
    :math:`F = I + \\nabla u`, weight 1.

2D vectors (displacements, test functions, normals) are embedded as :math:`(a_1, a_2, 0)`.
"""
import math

import ufl

from ..errors import ParameterError

__all__ = ["FORMULATIONS", "Kinematics"]

FORMULATIONS = ("plane_strain", "plane_stress", "axisymmetric", "3d")


class Kinematics:
    """Kinematic helpers for one formulation on one mesh (UFL expressions).

    Parameters
    ----------
    formulation : {"plane_strain", "plane_stress", "axisymmetric", "3d"}
    domain : dolfinx.mesh.Mesh
    thickness_strain : UFL expression, optional
        The out-of-plane strain :math:`e_{33} = \\lambda_3 - 1` [-] (plane stress only, where it is required).
    """

    def __init__(self, formulation, domain, thickness_strain=None):
        if (formulation == "plane_stress") != (thickness_strain is not None):
            raise ParameterError("the thickness strain is given for (and only for) the plane-stress formulation")
        self.formulation = formulation
        self.thickness_strain = thickness_strain
        self.gdim = domain.geometry.dim
        self.X = ufl.SpatialCoordinate(domain)
        self.N = ufl.FacetNormal(domain)

    def embed(self, a):
        """A 2D UFL vector as a 3-vector (a1, a2, 0); 3D vectors unchanged."""
        if self.gdim == 3:
            return a
        return ufl.as_vector([a[0], a[1], 0.0])

    def F(self, u):
        """3x3 deformation gradient of the displacement ``u``."""
        g = ufl.grad(u)
        if self.formulation == "3d":
            return ufl.Identity(3) + g
        if self.formulation == "plane_strain":
            hoop = 1.0
        elif self.formulation == "plane_stress":
            hoop = 1.0 + self.thickness_strain
        else:
            hoop = 1.0 + u[0] / self.X[0]
        return ufl.as_matrix([[1.0 + g[0, 0], g[0, 1], 0.0],
                              [g[1, 0], 1.0 + g[1, 1], 0.0],
                              [0.0, 0.0, hoop]])

    @property
    def weight(self):
        """Measure weight: :math:`2\\pi R` for the axisymmetric formulation, else 1."""
        return 2.0 * math.pi * self.X[0] if self.formulation == "axisymmetric" else 1.0

    def current_area_vector(self, u):
        """Nanson's formula: the current oriented area per reference area, :math:`J F^{-T} N` (3-vector)."""
        F = self.F(u)
        return ufl.det(F) * ufl.inv(F).T * self.embed(self.N)

    def current_position(self, u):
        """Current position :math:`x = X + u` as a 3-vector (zero third component in 2D)."""
        return self.embed(self.X + u)

    @property
    def dimension(self):
        """Spatial dimension of the enclosed volumes: 2 for plane strain and plane stress (areas per depth; in
        plane stress times the current thickness stretch), else 3."""
        return 2 if self.formulation in ("plane_strain", "plane_stress") else 3
