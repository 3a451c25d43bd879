"""Layering: the reduced-order and control layers never pull in DOLFINx or PETSc, and the packages import fast."""
import json
import subprocess
import sys

import pytest

HEAVY = ("dolfinx", "petsc4py", "slepc4py", "ufl", "ffcx", "basix", "gmsh")

_PROBE = r"""
import importlib, json, pkgutil, sys
names = sys.argv[1:]
imported = []
for name in names:
    pkg = importlib.import_module(name)
    imported.append(name)
for name in names:
    pkg = sys.modules[name]
    for info in pkgutil.walk_packages(pkg.__path__, prefix=name + "."):
        importlib.import_module(info.name)
        imported.append(info.name)
print(json.dumps({"imported": imported, "modules": sorted(sys.modules)}))
"""


def _import_tree(*packages):
    """Import ``packages`` and all their submodules in a fresh interpreter; return (imported, sys.modules)."""
    res = subprocess.run([sys.executable, "-c", _PROBE, *packages], capture_output=True, text=True, check=True)
    data = json.loads(res.stdout)
    return data["imported"], set(data["modules"])


@pytest.mark.parametrize("package", ["soroshapes", "sorocontrol"])
def test_reduced_and_control_layers_never_import_fem_stack(package):
    imported, modules = _import_tree(package)
    leaked = sorted(m for m in modules if m.split(".")[0] in HEAVY)
    assert not leaked, f"importing {package} (all of {imported}) pulled in {leaked}"


def test_sorofem_import_is_lazy():
    res = subprocess.run([sys.executable, "-c",
                          "import json, sys, sorofem, sorofem.units, sorofem.errors, sorofem.io;"
                          "print(json.dumps(sorted(sys.modules)))"],
                         capture_output=True, text=True, check=True)
    modules = set(json.loads(res.stdout))
    leaked = sorted(m for m in modules if m.split(".")[0] in HEAVY + ("numba", "scipy", "matplotlib"))
    assert not leaked, f"`import sorofem` loaded {leaked}"


def test_lazy_submodule_access_and_unknown_attribute():
    import sorofem
    assert sorofem.units.mm == 1e-3
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        sorofem.nope  # noqa: B018
