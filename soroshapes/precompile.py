"""Compile the network kernels into numba's on-disk cache (``python -m soroshapes.precompile``, the bootstrap's
precompile step after ``python -m soroshapes.shapes``).

The warm-up lives here, not in :mod:`soroshapes.network`: it builds a :class:`~soroshapes.model.Model`, and
:mod:`soroshapes.model` imports the network module, so a warm-up there made an import cycle.
"""
import time

__all__ = ["warm_up"]


def warm_up():
    """Compile (or load from numba's cache) every kernel of the compiled network path by running a tiny network
    of each system and coupling kind for a few steps: what a bootstrap or precompile step calls so that the first
    compiled simulation of a fresh process does not wait for numba (about 30 s with an empty cache). Returns the
    wall time [s]."""
    from sorofem import materials, sdf

    from .basis import Basis
    from .model import Fluidic, Model, StateSpace
    from .network import Schedule, StateMap
    from .shapes import Shapes

    t0 = time.perf_counter()
    shp = Shapes(Basis.chebyshev(2), dofs=(0, 2, 0, 0, 0, 0), length=0.05, section=sdf.Circle(0.004),
                 material=materials.NeoHookean(E=1e6, nu=0.45, density=1000.0), segments=2)
    shp.add_gravity().add_chamber(1e-5, (0.0, 0.002))
    mdl = (Model().add(shp, "beam").add(Fluidic(None, V0=1e-6, regulator=dict(kp=1e-9, ki=1e-8, max_flow=1e-4)), "p")
           .add(StateSpace.linear([[-10.0]], [[10.0]]), "lag")
           .connect("p", "beam").connect("lag", "p")
           .connect(StateMap("beam", [1e-8], index=0, offset=1e-6), "p", port="volume")
           .set_controller(Schedule([0.0, 1.0], {"lag": [[0.0], [1e3]]})))
    mdl.simulate(4e-3, 1e-3, "bdf2", compiled=True)
    mdl.simulate(4e-3, 1e-3, "bdf2", compiled=True, adaptive=True)       # the error-controlled driver
    from .tree import precompile as tree_kernels          # trees of bodies (issue 25)
    tree_kernels()
    return time.perf_counter() - t0


if __name__ == "__main__":
    from soroshapes.precompile import warm_up as _warm_up     # the package's module, not this __main__ copy
    print(f"network kernels ready in {_warm_up():.1f} s")
