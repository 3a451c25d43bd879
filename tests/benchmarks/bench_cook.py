"""Refinement studies of the FEM validation cases (figures, not timings): Cook's membrane in plane stress and the
shear mode of a nearly incompressible square (locking of displacement-only elements vs Taylor-Hood).

* Cook's membrane (linear, E = 1, nu = 1/3, unit total shear): the vertical displacement at (48, 52) for P1 and
  P2 triangles on n x n grids, n = 2..64, the observed order from successive differences, and
  the Richardson extrapolation of the three finest P2 levels, asserted within 0.1 % of the published 23.96.
* The shear mode of a unit square on rollers (closed form 2 pi^2 mu / rho for every nu): eigenvalue ratio to it
  for P1, P2 and Taylor-Hood at nu = 0.3 ... 0.499999 (8 x 8 grid); asserted: Taylor-Hood within 0.2 % for all.
"""
import math

import numpy as np
import pytest

from fem_cases import COOK_REFERENCE, cook_displacement, vortex_eigenvalue
from sorofem import materials

LEVELS = (2, 4, 8, 16, 32, 64)


def test_cook_membrane_refinement(record):
    rows = {}
    for degree in (1, 2):
        values = [cook_displacement(n, degree)[0] for n in LEVELS]
        steps = np.diff(values)                      # observed order from successive differences (no reference)
        rows[f"P{degree}"] = [round(v, 4) for v in values]
        rows[f"P{degree}_order"] = [round(math.log2(a / b), 2) for a, b in zip(steps, steps[1:])]
        print(f"\nP{degree}: " + ", ".join(f"n={n}: {v:.4f}" for n, v in zip(LEVELS, values)))
    v1, v2, v3 = rows["P2"][-3:]
    # Richardson with the observed order of the last three levels (Aitken's delta-squared)
    extrapolated = v3 - (v3 - v2) ** 2 / ((v3 - v2) - (v2 - v1))
    record(levels=list(LEVELS), reference=COOK_REFERENCE, extrapolated_P2=round(extrapolated, 4), **rows)
    assert extrapolated == pytest.approx(COOK_REFERENCE, rel=1e-3)
    assert abs(rows["P1"][-1] - COOK_REFERENCE) < abs(rows["P1"][0] - COOK_REFERENCE)


def test_shear_mode_locking_table(record):
    table = {}
    for nu in (0.3, 0.45, 0.49, 0.495, 0.4999, 0.499999):
        m = materials.LinearElastic(E=2 * (1 + nu), nu=nu, density=1.0)
        table[str(nu)] = {"P1": round(vortex_eigenvalue(m, 1, False), 4), "P2": round(vortex_eigenvalue(m, 2, False), 4),
                          "TH": round(vortex_eigenvalue(m, 2, True), 5)}
    record(eigenvalue_over_closed_form=table)
    for row in table.values():
        assert row["TH"] == pytest.approx(1.0, rel=2e-3)
    assert np.all(np.diff([row["P1"] for row in table.values()]) > 0)   # P1 locks more as nu -> 1/2
