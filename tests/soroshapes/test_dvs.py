"""Strain recovery from snapshot files, DVS bases and identification (soroshapes.dvs), on synthetic FEM fields.

The synthetic fields are Cosserat rods of known strain mapped onto simplex meshes: the cross-section point
(y, z) at arc length X goes to :math:`p(X) + R(X)(0, y, z)` with :math:`g(X) = \\exp(X\\hat\\xi)`. Linear
elements interpolate that curved field, so the recovered strain converges at second order in the element
size; the tolerances below are a few times the error measured at these resolutions.
"""
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm

from sorofem import materials, sdf
from sorofem.errors import DataError, ParameterError
from soroshapes import Basis, Shapes
from soroshapes.dvs import Backbone, dvs_basis, identify, recover_strains

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from fields import H, L, bar_mesh_2d, bar_mesh_3d, hat, rod_field, write  # noqa: E402


@pytest.mark.parametrize("dim", [2, 3])
def test_uniform_strain_is_recovered_to_discretization_accuracy(tmp_path, dim):
    if dim == 2:
        xi = np.array([0.0, 0.0, 15.0, 1.02, 0.0, 0.0])          # planar bending and stretch
        V, cells = bar_mesh_2d(60, 4)
        kind = "triangle"
    else:
        xi = np.array([6.0, -4.0, 12.0, 1.0, 0.0, 0.0])          # bending about y and z, and twist
        V, cells = bar_mesh_3d(80, 4)
        kind = "tetrahedron"
    path = write(tmp_path / "bar.h5", V, cells, kind, [np.zeros_like(V), rod_field(V, xi)])
    data = recover_strains(path, Backbone.line([0.0] + [0.0] * (dim - 1), [L] + [0.0] * (dim - 1)), samples=41)
    assert np.allclose(data.xi[0], [0, 0, 0, 1, 0, 0], atol=1e-12)     # undeformed: the straight reference
    assert np.allclose(data.xi0, [0, 0, 0, 1, 0, 0], atol=1e-12)
    err = np.abs(data.xi[1] - xi)
    scale = np.abs(xi).max()
    assert err[2:-2].max() < 0.01 * scale, err.max(axis=0)       # inside: second-order recovery
    assert err.max() < 0.03 * scale, err.max(axis=0)             # ends: one-sided, first order
    # the recovered frames are the rod's
    g_end = expm(hat(xi) * L)
    assert np.allclose(data.frames[1, -1, :3, 3], g_end[:3, 3], atol=1e-3 * L)


def test_recovered_strain_converges_at_second_order(tmp_path):
    xi = np.array([0.0, 0.0, 25.0, 1.0, 0.0, 0.0])
    errs = []
    for n in (20, 40):
        V, cells = bar_mesh_2d(n, 2)
        path = write(tmp_path / f"bar{n}.h5", V, cells, "triangle", [rod_field(V, xi)])
        data = recover_strains(path, Backbone.line([0.0, 0.0], [L, 0.0]), samples=21)
        errs.append(np.abs(data.xi[0, 2:-2, 2] - xi[2]).max())
    assert errs[0] / errs[1] > 3.0


def test_pod_of_snapshots_spanning_two_modes_returns_two_modes(tmp_path):
    V, cells = bar_mesh_2d(80, 2)
    s = V[:, 0] / L
    # curvature fields a(t) (1 + s) + b(t) cos(3 s) mapped by integrating the planar rod exactly per vertex
    phi = [lambda x: 1 + x, lambda x: np.cos(3 * x)]
    amps = [(5.0, 0.0), (0.0, 6.0), (4.0, 3.0), (-3.0, 5.0), (2.0, -4.0)]
    fields = []
    xs = np.linspace(0, 1, 2001)
    for a, b in amps:
        kappa = a * phi[0](xs) + b * phi[1](xs)
        theta = np.concatenate([[0], np.cumsum((kappa[1:] + kappa[:-1]) / 2 * np.diff(xs) * L)])
        px = np.concatenate([[0], np.cumsum(np.cos((theta[1:] + theta[:-1]) / 2) * np.diff(xs) * L)])
        py = np.concatenate([[0], np.cumsum(np.sin((theta[1:] + theta[:-1]) / 2) * np.diff(xs) * L)])
        th, x0, y0 = np.interp(s, xs, theta), np.interp(s, xs, px), np.interp(s, xs, py)
        U = np.column_stack([x0 - np.sin(th) * V[:, 1] - V[:, 0], y0 + np.cos(th) * V[:, 1] - V[:, 1]])
        fields.append(U)
    data = recover_strains(write(tmp_path / "modes.h5", V, cells, "triangle", fields),
                           Backbone.line([0.0, 0.0], [L, 0.0]), samples=61)
    bases, kept, info = dvs_basis(data, (0, 0, 6, 0, 0, 0), energy=1 - 1e-6)
    assert kept[2] == 2
    # the two modes span the generating functions: projection residual ~ discretization error
    sig = data.sigma
    B = bases[2](sig / L)
    for f in phi:
        y = f(sig / L)
        c = np.linalg.lstsq(B, y, rcond=None)[0]
        assert np.linalg.norm(B @ c - y) < 1e-2 * np.linalg.norm(y)   # recovery error, mostly at the ends
    # orthonormal in L2(0, L): composite Gauss over the spline pieces (exact for piecewise cubics)
    x, w = np.polynomial.legendre.leggauss(4)
    knots = sig / L
    a, b = knots[:-1, None], knots[1:, None]
    pts, wts = ((a + b) / 2 + (b - a) / 2 * x).ravel(), ((b - a) / 2 * w).ravel()
    Bq = bases[2](pts)
    assert np.allclose(Bq.T @ (wts[:, None] * Bq) * L, np.eye(2), atol=1e-10)


def test_identified_actuation_reproduces_the_static_response(tmp_path):
    """A synthetic 'FEM' whose curvature is exactly a(p) (1 + s) with a(p) = 40 p - 8 p^2 (p in units of 10
    kPa): the one-mode DVS beam with the identified quadratic actuation must reproduce the tip at a pressure
    between the training samples, and a chamber volume linear in a(p) is fitted as a function of q."""
    V, cells = bar_mesh_2d(60, 2)
    s = V[:, 0] / L
    pressures = np.linspace(0.0, 1.0, 6)
    test_p = 0.55

    def field(p):
        a = 40 * p - 8 * p**2
        th = a * (s + s**2 / 2) * L
        xs = np.linspace(0, 1, 4001)
        thx = a * (xs + xs**2 / 2) * L
        px = np.concatenate([[0], np.cumsum(np.cos((thx[1:] + thx[:-1]) / 2) * np.diff(xs) * L)])
        py = np.concatenate([[0], np.cumsum(np.sin((thx[1:] + thx[:-1]) / 2) * np.diff(xs) * L)])
        x0, y0 = np.interp(s, xs, px), np.interp(s, xs, py)
        return np.column_stack([x0 - np.sin(th) * V[:, 1] - V[:, 0], y0 + np.cos(th) * V[:, 1] - V[:, 1]]), a
    fields, amps = zip(*[field(p) for p in pressures])
    p_si = 1e4 * pressures
    path = write(tmp_path / "ramp.h5", V, cells, "triangle", fields, inputs={"pressure": p_si},
                 volumes={"cavity": 1e-6 * (1 + 0.01 * np.array(amps))})
    data = recover_strains(path, Backbone.line([0.0, 0.0], [L, 0.0]), samples=61)
    bases, kept, _ = dvs_basis(data, (0, 0, 1, 0, 0, 0))
    shp = Shapes(bases, kept, length=L, section=sdf.Rectangle(0.01, H),
                 material=materials.NeoHookean(E=1e5, nu=0.45, density=1000), damping=0.0, segments=20)
    ident = identify(shp, data, degree=2)
    assert ident.fit_error < 1e-3 and shp.inputs == ["pressure"]
    U_test, _ = field(test_p)
    tip_fem = np.array([L, 0.0]) + U_test[np.argmin(np.hypot(V[:, 0] - L, V[:, 1]))]
    tip_beam = shp.positions(shp.statics(u=[1e4 * test_p]))[-1, :2]
    assert np.linalg.norm(tip_beam - tip_fem) < 0.01 * L
    vq = [ident.volume("cavity", q) for q in ident.q]
    assert np.allclose(vq, data.cavity_volumes["cavity"], rtol=1e-6)


def test_bad_input_is_refused(tmp_path):
    V, cells = bar_mesh_2d(10, 2)
    path = write(tmp_path / "b.h5", V, cells, "triangle", [np.zeros_like(V)])
    with pytest.raises(ParameterError, match="leaves the mesh"):
        recover_strains(path, Backbone.line([0.0, 0.0], [2 * L, 0.0]))
    with pytest.raises(ParameterError, match="3D backbone"):
        recover_strains(path, Backbone.line([0, 0, 0], [L, 0, 0]))
    with pytest.raises(ParameterError, match="distinct"):
        Backbone([[0, 0], [0, 0]])
    data = recover_strains(path, Backbone.line([0.0, 0.0], [L, 0.0]))
    with pytest.raises(DataError, match="never changes"):
        dvs_basis(data, (0, 0, 2, 0, 0, 0))
    shp = Shapes(Basis.chebyshev(2), (0, 0, 2, 0, 0, 0), length=L, section=sdf.Rectangle(0.01, H),
                 material=materials.NeoHookean(E=1e5, nu=0.45, density=1000), damping=0.0)
    with pytest.raises(ParameterError, match="no input"):
        identify(shp, data, inputs=["pressure"])
