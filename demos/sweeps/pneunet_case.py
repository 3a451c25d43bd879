"""One case of the PneuNet sweep (``soro sweep demos/sweeps/pneunet.toml``).

The 2D plane-strain PneuNet section of ``demos/pneunet_inflation.py`` (its geometry, strain-limiting layer
and tip angle), with the chamber pressure and the body material as parameters. Not a demo itself: the sweep
configuration names :func:`build` and :func:`summary` (the contract is in :mod:`soro.sweep`).

Parameters (``params``)
-----------------------
pressure : float
    Chamber pressure [Pa], ramped from 0 by the solve.
material : str
    Body material, a preset name of :data:`sorofem.materials.PRESETS` (the layer is Dragon Skin 30).
chambers : int
    Number of chambers (pitch 80 mm / 7 as in the demo).
size : float
    Mesh size [m]; P2 displacements.
"""
import importlib.util
from pathlib import Path

from sorofem import materials

_DEMO = Path(__file__).resolve().parents[1] / "pneunet_inflation.py"


def _demo():
    """The PneuNet demo module (geometry and tip angle are defined there once)."""
    spec = importlib.util.spec_from_file_location("soro_demo_pneunet_inflation", _DEMO)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _length(demo, chambers):
    return chambers * 80 * demo.mm / 7


def build(params, comm):
    """The PneuNet section on ``comm``: clamped left end, every chamber at ``params["pressure"]`` [Pa]."""
    from sorofem.fem import Fem
    from sorofem.mesh import Mesh

    demo = _demo()
    shape, length = demo.pneunet(int(params["chambers"]), dim=2)
    layer = demo.layer_shape(length, 2)          # the mesh follows the layer's top: exactly LAYER thick at any size
    msh = Mesh.from_sdf(shape, size=float(params["size"]), comm=comm, interfaces=[layer])
    msh.add_region("layer", layer, kind="cells")
    fem = Fem(msh, material=materials.PRESETS[params["material"]](), degree=2)
    fem.add_material("layer", materials.DragonSkin30())
    fem.add_support("left")
    for cavity in msh.cavities:
        fem.add_pressure(cavity, float(params["pressure"]))
    return fem


# the types of the parameters, checked when the sweep configuration is loaded (soro.sweep)
build.parameters = {"pressure": float, "material": str, "chambers": int, "size": float}


def summary(traj, params):
    """Tip bending angle [deg] at the final pressure, and the cavity area change [-] of the first chamber."""
    if traj.comm.rank != 0:
        return None
    demo = _demo()
    angle = demo.tip_angle(traj.vertices, traj.displacement, _length(demo, int(params["chambers"])))
    area = traj.cavity_volumes.get("cavity_0")
    out = {"tip_angle_deg": round(float(angle[-1]), 4)}
    if area is not None:
        out["cavity_0_area_change_rel"] = round(float(area[-1] / area[0] - 1.0), 6)
    return out
