"""Kinematics of the three formulations, written once in 3x3 form.

Every formulation gives a 3x3 deformation gradient, so that material laws, follower pressures and cavity
volumes are written once in 3D algebra:

``plane_strain`` (2D, per unit depth)
    :math:`F = \\begin{bmatrix} I_2 + \\nabla u & 0 \\\\ 0 & 1 \\end{bmatrix}`, measure weight 1 [m of depth].
``axisymmetric`` (2D section in the (r, z) = (x, y) half plane, x >= 0, revolved about the y axis)
    :math:`F = \\begin{bmatrix} I_2 + \\nabla u & 0 \\\\ 0 & 1 + u_r / R \\end{bmatrix}` (hoop stretch),
    measure weight :math:`2\\pi R`, so that integrals are over the full revolved body.
``3d``
    :math:`F = I + \\nabla u`, weight 1.

2D vectors (displacements, test functions, normals) are embedded as :math:`(a_1, a_2, 0)`.
"""
import math

import ufl

__all__ = ["FORMULATIONS", "Kinematics"]

FORMULATIONS = ("plane_strain", "axisymmetric", "3d")


class Kinematics:
    """Kinematic helpers for one formulation on one mesh (UFL expressions).

    Parameters
    ----------
    formulation : {"plane_strain", "axisymmetric", "3d"}
    domain : dolfinx.mesh.Mesh
    """

    def __init__(self, formulation, domain):
        self.formulation = formulation
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
        hoop = 1.0 if self.formulation == "plane_strain" else 1.0 + u[0] / self.X[0]
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
        """Spatial dimension of the enclosed volumes: 2 for plane strain (areas per depth), else 3."""
        return 2 if self.formulation == "plane_strain" else 3
