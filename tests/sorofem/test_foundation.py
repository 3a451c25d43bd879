"""Units, the error hierarchy and atomic file writes."""
import json
import math

import pytest

from sorofem import errors, io, units


def test_units_convert_to_si():
    assert 80 * units.mm == pytest.approx(0.08)
    assert 40 * units.kPa == pytest.approx(4e4)
    assert 1 * units.MPa == pytest.approx(1e6)
    assert 180 * units.deg == pytest.approx(math.pi)
    assert 5 * units.g == pytest.approx(5e-3)
    assert units.gravity[2] == pytest.approx(-9.80665)
    assert 1 * units.psi == pytest.approx(6894.757, rel=1e-6)


@pytest.mark.parametrize("cls", [errors.ParameterError, errors.GeometryError, errors.MeshError, errors.DataError, errors.ConvergenceError,
                                 errors.ProtocolError, errors.SafetyError, errors.DependencyError])
def test_every_error_is_a_soro_error(cls):
    assert issubclass(cls, errors.SoroError)
    with pytest.raises(errors.SoroError, match="what to do"):
        raise cls("what to do")


def test_geometry_errors_are_value_errors():
    assert issubclass(errors.GeometryError, ValueError)
    assert issubclass(errors.MeshError, ValueError)


def test_atomic_write_keeps_old_file_on_failure(tmp_path):
    target = tmp_path / "result.json"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with io.atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("crash mid-write")
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["result.json"], "temporary file left behind"


def test_atomic_write_makes_ordinary_file_permissions(tmp_path):
    import os
    import stat
    with io.atomic_path(tmp_path / "a.txt") as tmp:
        tmp.write_text("x")
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE((tmp_path / "a.txt").stat().st_mode) == 0o666 & ~umask


def test_write_json_refuses_nan_and_names_the_key(tmp_path):
    target = tmp_path / "r.json"
    with pytest.raises(ValueError, match=r"summary.metrics\[1\] is nan"):
        io.write_json(target, {"metrics": [1.0, float("nan")]})
    assert not target.exists()
    import numpy as np
    io.write_json(target, {"a": np.arange(3), "b": np.float64(2.0)})
    assert json.loads(target.read_text()) == {"a": [0, 1, 2], "b": 2.0}
