"""Refinement studies of the path-following validation cases (figures, not timings), the tolerances of
tests/sorofem/test_continuation.py rest on them:

* thick sphere (B = 1.5 A) followed through its pressure maximum: the largest difference of the pressure from
  the (incompressible) closed form along the path (to a = 2.2 A), relative to p_max, for 2, 3, 6 and 12 cells
  across the wall at nu = 0.4999, and at 6 cells for nu = 0.49999. The mesh error is gone from 3 cells on: what
  remains (~2.5e-4) is the model's compressibility, kappa/mu = 2(1 + nu)/(3(1 - 2 nu)) = 5000, which a ten
  times stiffer bulk modulus cuts about ten times; asserted: the last two levels within 5e-5 of each other,
  below 5e-4, and the nu = 0.49999 error at least 4 times smaller.
* clamped-guided strut (L/h = 25) on its buckled branch: the largest difference of P/P_cr from the elastica
  up to w = 0.2 L for 1, 2, 4 and 8 cells across; asserted: it settles (the last two levels within 0.05 % of
  each other) at a value below 0.4 % (the continuum's O((h/L)^2) departure from the elastica, not the mesh).
"""
import numpy as np

from analytic import buckled_strut, sphere_inflation_pressure, sphere_pressure_maximum
from fem_cases import STRUT, inner_radius, strut, strut_end_offset, thick_sphere


def test_thick_sphere_limit_point_refinement(record):
    A, B, mu = 0.01, 0.015, 100e3
    p_max, _ = sphere_pressure_maximum(mu, A, B)
    def error(n, nu=0.4999):
        traj = thick_sphere(A, B, mu, p_max, n, nu).follow(load_level=2.0, steps=8,
                                                           until=lambda tr: inner_radius(tr, A)[-1] > 2.2 * A)
        a, p = inner_radius(traj, A), traj.inputs["pressure/inner"]
        ref = np.array([sphere_inflation_pressure(mu, A, B, ai) for ai in a])
        return float(np.abs(p - ref).max() / p_max), float(p.max() / p_max)

    levels = (2, 3, 6, 12)
    errors, limits = zip(*[error(n) for n in levels])
    stiffer, _ = error(6, nu=0.49999)
    record(cells_across=list(levels), max_error_over_p_max=list(errors), p_top_over_p_max=list(limits),
           max_error_6_cells_nu_0_49999=stiffer)
    assert abs(errors[-1] - errors[-2]) < 5e-5 and errors[-1] < 5e-4 and stiffer < errors[2] / 4


def test_buckled_strut_refinement(record):
    L, P_cr = STRUT["L"], STRUT["P_cr"]
    levels, errors, first = (1, 2, 4, 8), [], []
    for n in levels:
        traj = strut(n).follow(load_level=1.0, steps=20, until=lambda tr: abs(strut_end_offset(tr)[-1]) > 0.2 * L,
                               monitor_stability=True, branch_switch=True)
        k = traj.metadata["critical_points"][0]["step"]
        P, w = -traj.reactions["right"][k + 1:, 0], strut_end_offset(traj)[k + 1:]
        ratio, _ = buckled_strut(w / L)
        errors.append(float(np.abs(P / P_cr - ratio).max()))
        first.append(float(P[0] / P_cr))
    record(cells_across=list(levels), max_error_P_over_P_cr=errors, P_first_buckled_over_P_cr=first)
    assert abs(errors[-1] - errors[-2]) < 5e-4 and errors[-1] < 4e-3
