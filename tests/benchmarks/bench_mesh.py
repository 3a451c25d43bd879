"""Benchmark: meshing time of a 2D PneuNet section at about 5k triangles (target < 2 s).

Figures: wall time of ``Mesh.from_sdf`` (gmsh on rank 0 + DOLFINx distribution + region tagging + quality),
number of cells, ratio of the time to the 2 s target (< 1 meets it). The mesh itself is checked (area,
cavities); the time is recorded, never asserted.
"""
import math
import time

import pytest

from sorofem import sdf
from sorofem.units import mm

TARGET_S = 2.0
W, H, RC = 80 * mm, 16 * mm, 3 * mm


def section():
    body = sdf.RoundedRectangle(W, H, radius=RC)
    for i in range(4):
        body = body - sdf.Rectangle(8 * mm, 8 * mm, center=((i - 1.5) * 16 * mm, 1 * mm))
    return body


@pytest.mark.parametrize("method", ["csg", "levelset"])
def test_pneunet_section_meshing_time(record, method):
    from sorofem.mesh import Mesh

    shape = section()
    Mesh.from_sdf(shape, size=2 * mm, method=method)  # warm up imports and the form JIT cache
    t0 = time.perf_counter()
    msh = Mesh.from_sdf(shape, size=0.7 * mm, method=method)
    elapsed = time.perf_counter() - t0
    exact = W * H - (4 - math.pi) * RC**2 - 4 * (8 * mm) ** 2
    # P1 with rounded corners of r = 3 mm, h = 0.7 mm: chord loss (h/r)^2/6 of 4 quarter disks, < 1e-4 of A
    assert msh.area == pytest.approx(exact, rel=5e-4)
    assert msh.cavities == ["cavity_0", "cavity_1", "cavity_2", "cavity_3"]
    assert 4000 <= msh.num_cells <= 7000
    record(method=method, time_s=round(elapsed, 3), cells=msh.num_cells, ratio_to_target=round(elapsed / TARGET_S, 3),
           min_angle_deg=round(msh.quality["min_angle"], 2))
