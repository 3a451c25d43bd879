"""sorofem.sdf STL I/O: the one writer (units in the header), read-back scale, and the surface checks that
a print-ready file must pass (watertight, oriented, one shell, positive volume)."""
import math

import numpy as np
import pytest

from sorofem import sdf
from sorofem.errors import GeometryError
from sorofem.units import mm

_REC = [("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]


def _raw(path):
    """The coordinates exactly as a slicer reads them (no unit conversion)."""
    data = path.read_bytes()
    return data[:80], np.frombuffer(data, _REC, offset=84)["v"].astype(float)


@pytest.mark.parametrize("units,per_m", [("mm", 1e3), ("m", 1.0), ("cm", 1e2), ("in", 1 / 0.0254)])
def test_to_stl_writes_the_unit_and_reads_back_in_metres(tmp_path, units, per_m):
    box = sdf.Box((20 * mm, 10 * mm, 4 * mm), (5 * mm, 0, 0))
    kw = {} if units == "mm" else {"units": units}
    path = box.to_stl(tmp_path / "box.stl", resolution=1 * mm, **kw)
    header, raw = _raw(path)
    assert header.rstrip().endswith(f"units: {units}".encode())
    assert sdf.stl_units(path) == units
    # the box's x extent is 20 mm: 20 in a mm file, 0.02 in a metre file
    assert np.ptp(raw[..., 0]) == pytest.approx(0.020 * per_m, rel=0.03)
    tri, _ = sdf.read_stl(path)
    assert np.ptp(tri[..., 0]) == pytest.approx(0.020, rel=0.03)
    assert tri[..., 0].min() == pytest.approx(-5 * mm, abs=0.3 * mm)
    # an explicit unit overrides the header
    tri_m, _ = sdf.read_stl(path, units="m")
    assert np.ptp(tri_m[..., 0]) == pytest.approx(0.020 * per_m, rel=0.03)


def test_write_stl_of_given_triangles_and_errors(tmp_path):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) * 10 * mm
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    path = sdf.write_stl(tmp_path / "tet.stl", v, f)
    tri, nrm = sdf.read_stl(path)
    chk = sdf.surface_check(tri)
    assert chk["watertight"] and chk["shells"] == 1
    assert chk["volume"] == pytest.approx((10 * mm) ** 3 / 6, rel=1e-6)
    assert np.allclose(nrm[0], [0, 0, -1])
    with pytest.raises(GeometryError, match="units"):
        sdf.write_stl(tmp_path / "x.stl", v, f, units="furlong")
    with pytest.raises(GeometryError, match="NaN"):
        sdf.write_stl(tmp_path / "x.stl", v * np.nan, f)
    # an STL without a unit in its header is read as millimetres (slicer convention)
    data = bytearray(path.read_bytes())
    data[:80] = b"exported by some CAD tool".ljust(80)
    (tmp_path / "cad.stl").write_bytes(bytes(data))
    assert sdf.stl_units(tmp_path / "cad.stl") is None
    assert np.ptp(sdf.read_stl(tmp_path / "cad.stl")[0][..., 0]) == pytest.approx(10 * mm, rel=1e-6)  # file holds 10


def test_surface_check_finds_holes_flips_and_shells(tmp_path):
    r = 5 * mm
    tri, _ = sdf.read_stl(sdf.Sphere(r).to_stl(tmp_path / "s.stl", resolution=1 * mm))
    good = sdf.surface_check(tri)
    assert good["watertight"] and good["shells"] == 1
    assert good["volume"] == pytest.approx(4 / 3 * math.pi * r**3, rel=0.05)
    holed = sdf.surface_check(tri[1:])
    assert not holed["watertight"] and holed["boundary_edges"] == 3
    flipped = tri.copy()
    flipped[0] = flipped[0][::-1]
    bad = sdf.surface_check(flipped)
    assert not bad["watertight"] and bad["misoriented_edges"] == 3 and bad["boundary_edges"] == 0
    two = sdf.Sphere(r) | sdf.Sphere(r, (20 * mm, 0, 0))
    tri2, _ = sdf.read_stl(two.to_stl(tmp_path / "two.stl", resolution=1 * mm))
    chk2 = sdf.surface_check(tri2)
    assert chk2["watertight"] and chk2["shells"] == 2
    # a closed cavity is a second (inward-facing) shell of the same part
    hollow = sdf.Sphere(2 * r) - sdf.Sphere(r)
    chk3 = sdf.surface_check(sdf.read_stl(hollow.to_stl(tmp_path / "h.stl", resolution=1 * mm))[0])
    assert chk3["watertight"] and chk3["shells"] == 2
    assert chk3["volume"] == pytest.approx(4 / 3 * math.pi * (8 - 1) * r**3, rel=0.05)


def test_one_stl_writer_in_the_code_base():
    """Every STL the platform writes goes through sdf.write_stl (which takes the unit): no other module packs
    the 50-byte binary STL record or writes an STL header."""
    from pathlib import Path
    root = Path(__file__).resolve().parents[2]
    writer = root / "sorofem" / "sdf" / "export.py"
    offenders = []
    for pkg in ("sorofem", "soroshapes", "sorocontrol", "demos"):
        for path in (root / pkg).rglob("*.py"):
            text = path.read_text(encoding="utf-8")
            if path != writer and ('"<f4", (3, 3)' in text or "binary STL, units" in text
                                   or 'file_format="stl"' in text or "numpy-stl" in text):
                offenders.append(str(path.relative_to(root)))
    assert offenders == []
