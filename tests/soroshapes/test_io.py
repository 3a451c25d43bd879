"""Beam model files (soroshapes.io): a beam written and read back is the same beam."""
import json

import numpy as np
import pytest

from sorofem import materials, sdf
from sorofem.errors import DataError, ParameterError

L = 0.1


def _beam(bases, dofs, section=None):
    from soroshapes import Shapes

    return Shapes(bases, dofs, length=L, section=section or sdf.Rectangle(0.01, 0.008),
                  material=materials.NeoHookean(E=1e6, nu=0.45, density=1000.0), damping=0.0, segments=12,
                  base=np.array([0.0, 0.002, 0.0]))


def _data_basis():
    from soroshapes import Basis

    s = np.linspace(0.0, 1.0, 21)
    return Basis.from_data(s, np.column_stack([1 + 0 * s, s, np.sin(3 * s)])).orthonormalize(L)


@pytest.mark.parametrize("family", ["chebyshev", "pcc", "data"])
def test_a_saved_beam_loads_with_the_same_statics_and_volume(tmp_path, family):
    """Round trip of each basis family: the loaded beam's static shape under the identified actuation equals
    the original's to rounding (1e-12 m of 0.1 m: the same numbers in, the same kernels), and so does the cavity
    volume model."""
    from soroshapes import Basis
    from soroshapes.dvs import PolynomialForce
    from soroshapes.io import load_beam, save_beam

    basis = {"chebyshev": Basis.chebyshev(3).orthonormalize(L), "pcc": Basis.pcc(3), "data": _data_basis()}[family]
    shp = _beam([None, None, basis, None, None, None], (0, 0, 3, 0, 0, 0))
    coef = np.array([[2e-4, -1e-4, 5e-5], [1e-9, 0.0, 0.0]])
    shp.add_actuator(PolynomialForce(coef), name="pressure/cavity_0")
    vol = (1e-6, np.array([1e-7, 0.0, 2e-8]), np.eye(3) * 1e-9)
    path = save_beam(tmp_path / "m.json", shp, {"pressure/cavity_0": coef}, {"cavity_0": vol}, meta={"why": "test"})
    new, f = load_beam(path)
    q0, q1 = shp.statics(u=[3000.0]), new.statics(u=[3000.0])
    assert np.abs(q0).max() > 1.0                   # a real bend (curvature coordinates of order 10 1/m sqrt(m))
    np.testing.assert_allclose(new.positions(q1), shp.positions(q0), atol=1e-12)
    assert new.inputs == shp.inputs and f.meta == {"why": "test"}
    assert f.volume("cavity_0", q1) == pytest.approx(vol[0] + vol[1] @ q0 + q0 @ vol[2] @ q0, rel=1e-12)


def test_a_circular_section_round_trips(tmp_path):
    from soroshapes import Basis
    from soroshapes.io import load_beam, save_beam

    shp = _beam(Basis.chebyshev(2), (0, 2, 2, 0, 0, 0), section=sdf.Circle(0.004))
    new, _ = load_beam(save_beam(tmp_path / "c.json", shp, {}))
    np.testing.assert_allclose(new.K, shp.K, rtol=1e-12)


def test_bad_files_and_bases_are_refused_with_a_reason(tmp_path):
    from soroshapes import Basis
    from soroshapes.io import load_beam, save_beam

    p = tmp_path / "x.json"
    p.write_text(json.dumps({"format": "other", "version": 1}))
    with pytest.raises(DataError, match="not a soro-beam version 1 file"):
        load_beam(p)
    with pytest.raises(ParameterError, match="stores chebyshev, legendre, pcc or data"):
        save_beam(tmp_path / "f.json", _beam(Basis.fourier(2), (0, 0, 2, 0, 0, 0)), {})
    with pytest.raises(ParameterError, match="another length"):
        save_beam(tmp_path / "o.json", _beam(Basis.chebyshev(2).orthonormalize(2 * L), (0, 0, 2, 0, 0, 0)), {})
