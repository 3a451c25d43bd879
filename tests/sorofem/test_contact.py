"""Contact with SDF obstacles: weight carried, stick and slip on an incline, an impact, bad input."""
import numpy as np
import pytest

from sorofem import materials, sdf
from sorofem.errors import ParameterError
from sorofem.fem import Fem
from sorofem.mesh import Mesh
from sorofem.units import kPa, mm

G = 9.80665
FLOOR = sdf.Line((0.0, 0.0), (0.0, 1.0))  # solid below y = 0


@pytest.mark.parametrize("dim, mixed", [(2, False), (3, False), (2, True)])
def test_a_block_resting_on_a_floor_carries_its_weight(dim, mixed):
    """Also in the mixed (Taylor-Hood) formulation, whose contact acts on the displacement field."""
    W, H = 20 * mm, 10 * mm
    mat = materials.NeoHookean(E=100 * kPa, nu=0.4, density=1000.0)
    if dim == 2:
        msh = Mesh.rectangle(W, H, size=H / 4, center=(0.0, H / 2))
        floor, weight = FLOOR, mat.density * G * W * H
        fem = Fem(msh, mat, degree=2 if mixed else 1, mixed=mixed).add_support("left", "x")
    else:
        msh = Mesh.box(W, W, H, size=H / 2, center=(0.0, 0.0, H / 2))
        floor, weight = sdf.Plane((0.0, 0.0, 0.0), (0.0, 0.0, 1.0)), mat.density * G * W * W * H
        fem = Fem(msh, mat).add_support("left", "x").add_support("front", "y")
    traj = fem.add_gravity().add_contact(floor).solve(steps=2)
    force = traj.reactions["contact_0"][-1]
    assert force[-1] == pytest.approx(weight, rel=1e-2)
    assert np.allclose(force[:-1], 0.0, atol=1e-6 * weight)
    assert traj.contact_areas["contact_0"][-1] > 0.9 * (W if dim == 2 else W * W)
    penetration = -fem.evaluate([[0.0] * (dim - 1) + [0.0]])[0][-1]
    assert 0 < penetration < 0.05 * H / 4  # the documented default stiffness keeps it to a few % of h


@pytest.mark.parametrize("theta_deg", [10.0, 30.0])
def test_block_on_an_incline_sticks_below_the_friction_angle_and_slides_above(theta_deg):
    """mu = 0.3 (friction angle 16.7 deg); gravity tilted by theta. Below: it stays; above: its centre
    accelerates at g (sin theta - mu cos theta) (fitted after the landing transient, 1 %)."""
    mu, th = 0.3, np.radians(theta_deg)
    W, H = 20 * mm, 10 * mm
    msh = Mesh.rectangle(W, H, size=H / 2, center=(0.0, H / 2))
    mat = materials.NeoHookean(E=200 * kPa, nu=0.3, density=1000.0)
    fem = Fem(msh, mat).add_gravity(lambda t: np.array([G * np.sin(th), -G * np.cos(th)]))
    fem.add_contact(FLOOR, friction=mu, regularization=1e-7)  # sticking creeps by ~1e-7 m per step
    traj = fem.simulate(t_end=0.1, dt=0.002, rho_inf=0.0)
    x = traj.displacement[:, :, 0].mean(axis=1)
    accel = 2 * np.polyfit(traj.times[10:], x[10:], 2)[0]
    expected = G * (np.sin(th) - mu * np.cos(th))
    if expected < 0:  # after landing (the block starts touching, unloaded) it no longer slips
        assert abs(x[-1] - x[10]) < 1e-2 * 0.5 * G * np.sin(th) * traj.times[-1] ** 2 and abs(accel) < 1e-3 * G
    else:
        assert accel == pytest.approx(expected, rel=1e-2)
    fx, fy = traj.reactions["contact_0"][-1]
    assert fy == pytest.approx(mat.density * G * np.cos(th) * W * H, rel=1e-2)
    # the reported friction: it resists the slide (mu N uphill), or holds the block (m g sin theta uphill, on
    # average over the second half: the elastic block still rocks on its contact after the landing)
    if expected < 0:
        fx = traj.reactions["contact_0"][len(traj.times) // 2:, 0].mean()
    assert fx == pytest.approx(-(mat.density * G * np.sin(th) * W * H if expected < 0 else mu * fy), rel=2e-2)


def test_a_disk_hitting_the_floor_at_speed_does_not_tunnel_and_rebounds_with_bounded_energy():
    """1 m/s impact, dt = 0.2 ms (the impact moves a node by 0.2 mm = h/6 per step): the deepest point stays
    within 1 % of h, the disk bounces back up, and the energy never exceeds the initial one."""
    R = 5 * mm
    msh = Mesh.from_sdf(sdf.Circle(R, center=(0.0, R + 1 * mm)), size=R / 4)
    fem = Fem(msh, materials.NeoHookean(E=100 * kPa, nu=0.4, density=1000.0)).add_contact(FLOOR)
    traj = fem.simulate(t_end=0.02, dt=2e-4, rho_inf=0.9, velocity=np.array([0.0, -1.0]))
    energy = traj.energy + traj.kinetic_energy
    lowest = (traj.vertices[:, 1] + traj.displacement[:, :, 1]).min()
    assert lowest > -0.01 * R / 4
    assert energy.max() <= energy[0] * (1 + 1e-6)
    y = traj.displacement[:, :, 1].mean(axis=1)
    assert (y[-1] - y[-2]) / (traj.times[-1] - traj.times[-2]) > 0.5  # moving up again
    assert traj.contact_areas["contact_0"].max() > 0 and traj.contact_areas["contact_0"][-1] == 0


def test_moving_obstacle_pushes_the_body():
    """A floor rising by 1 mm under a block held on its top: the contact force balances the support."""
    W, H = 20 * mm, 10 * mm
    msh = Mesh.rectangle(W, H, size=H / 4, center=(0.0, H / 2))
    fem = Fem(msh, materials.NeoHookean(E=100 * kPa, nu=0.3)).add_support("top")
    traj = fem.add_contact(FLOOR, motion=lambda t: np.array([0.0, 1 * mm * t])).solve(steps=2)
    np.testing.assert_allclose(traj.reactions["contact_0"][-1], -traj.reactions["top"][-1], rtol=1e-6, atol=1e-9)
    assert fem.evaluate([[0.0, 0.0]])[0][1] == pytest.approx(1 * mm, rel=5e-2)


def test_bad_contact_input():
    W, H = 20 * mm, 10 * mm
    msh = Mesh.rectangle(W, H, size=H / 4, center=(0.0, H / 2))
    fem = Fem(msh, materials.Ecoflex0030()).add_support("left")
    fem.add_contact(sdf.Line((0.0, 2 * mm), (0.0, 1.0)))  # the floor cuts 2 mm into the body
    with pytest.raises(ParameterError, match=r"starts inside obstacle 'contact_0': a boundary point at \[.*\] m is 0.002 m deep"):
        fem.solve(steps=1)
    with pytest.raises(ParameterError, match="a 3D obstacle cannot touch a 2D body"):
        Fem(msh, materials.Ecoflex0030()).add_support("left").add_contact(sdf.Sphere(1.0)).solve(steps=1)
    with pytest.raises(ParameterError, match="friction must be >= 0"):
        fem.add_contact(FLOOR, friction=-0.1)
    with pytest.raises(ParameterError, match="must be a shape from sorofem.sdf"):
        fem.add_contact("floor")
