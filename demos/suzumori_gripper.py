r"""Four-finger soft gripper: static pinches, then screwing a hexagonal bolt (`soro demo suzumori_gripper`)
=========================================================================================================

Purpose
-------
The seed's bolt-screwing gripper (Sorotoki paper, Sec. VI; after Suzumori's flexible microactuator): four
soft fingers, each with three pressure chambers, hang around the head of a hexagonal bolt. Biasing the
chambers bends every finger toward the bolt (pinch grasp); adding pressures that rotate around each finger
makes its tip trace a circle, so that during the inner half of the circle the fingertip is pressed on the
bolt head and drags it tangentially by friction, and during the outer half it comes back free. The bolt
turns about its axis against its rotational damping. Before it, the seed's two static grasps (its Fig. 27):
the pinch of a 40 mm glass beaker by the four fingers and the pair-pinch of a 5 mm thick wrench by two
fingers. Figures: the static grasps' contact forces and hold margins (the friction force the fingers can give
over the weight it must carry), the bolt grasp's normal force, the bolt's mean rate in revolutions per second
(the seed reports 0.16 rev/s simulated, 0.25 rev/s measured) against the friction-limited rate, the solver
statistics; PNGs of the static grasps (``suzumori_grasps.png``) and of the gripper and the bolt's angle.

Equations
---------
*Fingers* (the seed's parameters): L = 80 mm, outer radius R = 6 mm, Neo-Hookean E = 1 MPa, nu = 0.3,
rho = 2000 kg/m^3, Chebyshev bases of 3 modes in both bendings (``dofs = (0, 3, 3, 0, 0, 0)``, n = 6 per
finger), Kelvin-Voigt damping from a damping ratio 0.1, gravity along -z. Finger j hangs from
:math:`(37.5\,\mathrm{mm})(\cos\alpha_j, \sin\alpha_j, 0)`, :math:`\alpha_j = j\pi/2`, along -z; its body y
axis is tangential, body z radially outward.

*The chambers* are those of Suzumori's flexible microactuator (FMA; the seed's refs. [4], [5]): a 12 mm
fibre-reinforced rubber tube whose bore is partitioned into three chambers by radial walls (its section is
three 120 deg sectors, not three small holes). Neither the seed's text nor its code gives the chambers' size
(its code applies each chamber's pressure as a force bundle 3 mm off the axis, with no area), so we take the
bore of radius 5 mm (a 1 mm outer wall) split by 1 mm partitions, the walls chosen so that a chamber's
centroid sits at the seed's 3 mm: each chamber 21.33 mm^2 with its centroid 3.04 mm off the axis (the
section properties of the chamber's SDF, :func:`finger_section`), a bending moment per pressure
:math:`A r` = 64.9 mm^3, 3.06 times that of the round 1.5 mm chamber at 3 mm used before (7.07 mm^2,
21.2 mm^3, which gave a beaker hold margin of 0.21). The hollow section (49.1 mm^2, second moment 590 mm^4
against the solid rod's 1018 mm^4) is the beam's section, so mass and bending stiffness follow the same
geometry. Chamber k at section angle :math:`\phi_k = 0, 2\pi/3, 4\pi/3` (:meth:`Shapes.add_chamber`) bends
the finger away from itself, toward :math:`e_k = -(\cos\phi_k, \sin\phi_k)` in (y, z). The pressure range
stays 0-300 kPa (our bound; the seed states none).

*Drive.* The desired tip direction in the section plane is
:math:`\delta(t) = b\,e_{in} + a(\cos\omega t\, e_{in} + \sin\omega t\, e_{t})` with :math:`e_{in}` = -z (toward
the bolt) and :math:`e_t` = +y (tangential, the same sense on every finger, so all push the bolt the same
way round); chamber pressures :math:`p_k = P_0 + \tfrac23 (\delta\cdot e_k)`, which realizes the bending
moment :math:`\propto \delta` with :math:`p_k \ge 0` as long as :math:`P_0 \ge \tfrac23|\delta|`. Bias
:math:`b` = 55 kPa (the pinch: the free tip moves 8.8 mm inward, onto the head's corners), circle
:math:`a` = 30 kPa at 2 Hz (+-4.7 mm: the inner half presses on the flats, the outer half clears the corners),
:math:`P_0` = 60 kPa: the free tip path of the former drive (150, 80, 160 kPa on the former, weaker fingers),
scaled to the FMA fingers (0.16 mm of free tip travel per kPa); the bias ramps up over the first 0.3 s
(grasp), the circle starts at 0.4 s.

*Static grasps* (seed Fig. 27), each a static equilibrium (:meth:`Shapes.statics`, the object fixed, the
finger-object contact of :meth:`Shapes.add_contact` with the parameters below; friction takes no part at rest).
The chamber pressures that bend a finger toward a unit direction :math:`d` of its section with the least
pressure are :math:`p_k = \tfrac23 b\,(e_k\cdot d - \min_j e_j\cdot d)` (the bending moment is
:math:`\propto b\,d`, the common part bends nothing), with :math:`b` set so that the largest is
:math:`P_{max}` = 300 kPa (the bolt drive's range). *Pinch*: the beaker (the seed's SDF: a cylinder
40 x 40 x 60 mm, here from 30 to 90 mm below the fingers' base), all four fingers bent inward.
*Pair-pinch*: the wrench (the seed's SDF: a 5 x 10 x 100 mm box; the 5 mm across the plane that bisects
fingers 0 and 1, its 100 mm along that plane, horizontal, 72 mm below the base, at the fingertips' height),
fingers 0 and 1 bent toward that plane. *Hold margin*: :math:`\mu\sum_j |F_{n,j}| / (m g)`, the friction
force available from the normal forces :math:`F_{n,j}` (horizontal: the contact faces are vertical) over the weight;
above 1 the grasp holds the object against gravity. Masses: the wrench 5 x 10 x 100 mm of steel (7850
kg/m^3): 39 g; the beaker: 30 g (an empty 50 mL borosilicate beaker, about 42 mm x 60 mm, weighs 30-35 g;
the seed gives none). The finger's blocked tip force :math:`3M/(2L)` (:math:`M = A r b` the chambers'
moment) bounds what any pressure below :math:`P_{max}` can give: 0.365 N per finger at 300 kPa with the
FMA's chambers (0.12 N with the former round ones). The beaker: 0.290 N per finger, hold margin 2.36
(held); the wrench: 0.285 N per finger, margin 0.89: the two fingers pinch it but at mu = 0.6 carry 89 %
of its 39 g (it would slip; at 340 kPa the same solve gives 0.339 N per finger, margin 1.06: held; or
mu = 0.68 at 300 kPa; we keep one friction coefficient for every contact and the 300 kPa range).

*Bolt.* A hexagonal head (circumradius 24 mm, height 14 mm, centred 72 mm below the fingers' base) on a
:class:`soroshapes.SpinningBody` about z: :math:`I\ddot\theta = -\mu_\Omega\dot\theta + m_z` (seed eq. (31))
with the seed's damping :math:`\mu_\Omega` = 2.5 in its unit system (mm, N, s: a torque in N mm per rad/s;
Sorotoki works in mm, N, MPa, tonne, s), i.e. :math:`\mu_\Omega` = 2.5e-3 N m s/rad in SI, and
:math:`I` = 2e-5 kg m^2 (the seed leaves :math:`I_\Omega` blank; a steel head of this size; the damping
dominates at these rates: :math:`I/\mu_\Omega` = 8 ms). When the fingertips slip on the head, the bolt
turns no faster than the friction they can transmit, :math:`\omega \le \mu\,\bar F_n\,r/\mu_\Omega`
(:math:`\bar F_n` the total normal force, :math:`r` the head's radius): ``friction_limited_rev_per_s``.
Against the seed's 0.16 rev/s: at :math:`\mu_\Omega` = 2.5e-3 N m s/rad, 0.16 rev/s (1.0 rad/s) needs a
driving torque of 2.5e-3 N m, a tangential force of 0.105 N at the head's 24 mm, so a normal force of
0.044 N per finger at :math:`\mu` = 0.6 on all four, pressed all the time. The former fingers (7.07 mm^2
chambers) pressed 0.0095 N while screwing and turned the bolt at 0.019 rev/s (quick) / 0.026 rev/s (full
run), under their friction limit of 0.035 rev/s. On the same free tip path the FMA fingers press 3.5 times
harder, 0.033 N on average while screwing (``screw_force_N_mean``: pulses of up to 0.078 N on the circle's
inner half, none on the outer), and turn the bolt at 0.037 rev/s over the full run's last 2.5 s (0.021 rev/s
over the quick run's last 0.5 s; 0.100 turns in 3.4 s) in the seed's staircase (``suzumori_gripper.png``: a
step forward on every inner half, a small slip back on every outer half), under their friction limit of
0.12 rev/s (``friction_limited_rev_per_s``), which is still below the seed's 0.16: the pulsed normal force
carries less than a constant 0.044 N would. Deeper drives press harder but do not turn faster (full runs,
bias/circle/P0 in kPa: 75/45/85 0.038 rev/s, limit 0.21; 100/60/110 0.020 rev/s, limit 0.29; 100/90/130
-0.006 rev/s): fingers bent that far reach under the head's lower edge and drag it back with their sides. The
seed reached its 0.16 rev/s "through careful parameter and input shaping" (unstated); a drive shaped for
these fingers is the next step.

*Contact* (:func:`soroshapes.rigid.couple_contact`): the finger's tube (radius 6 mm) against the head's SDF,
penalty 2e5 N/m^2 per unit length, damping 20 N s/m^2, Coulomb friction 0.6 regularized at 2 mm/s; forces
and moments are equal and opposite on finger and bolt.

*Integration.* ``Model.simulate``, BDF2, dt = 2 ms.
"""
import functools
import time
from pathlib import Path

import numpy as np

from sorofem import materials, sdf
from sorofem.units import kPa, mm

# ------------------------------------------------------------------------------------------------ parameters
L, R, RING, R_BOLT, H_BOLT, Z_BOLT = 80 * mm, 6 * mm, 37.5 * mm, 24 * mm, 14 * mm, -72 * mm
BORE, WALL = 5 * mm, 1 * mm                             # the chambers' bore radius [m], partition walls [m]
PHI = np.array([0.0, 2 * np.pi / 3, 4 * np.pi / 3])     # chambers' section angles [rad]
E_K = -np.column_stack([np.cos(PHI), np.sin(PHI)])      # direction each chamber bends its finger, (y, z)
BIAS, CIRCLE, P0, FREQ = 55 * kPa, 30 * kPa, 60 * kPa, 2.0     # drive [Pa], [Pa], [Pa], [Hz]
T_GRASP, T_SCREW = 0.3, 0.4                             # grasp ramp's end, the circle's start [s]
BOLT_INERTIA = 2e-5                                     # [kg m^2] (the seed leaves it blank)
BOLT_DAMPING = 2.5 * 1e-3                               # the seed's mu_Omega = 2.5 N mm s/rad -> [N m s/rad]
P_MAX = 300 * kPa                                       # the static grasps' largest chamber pressure [Pa]
BEAKER_R, BEAKER_H, BEAKER_Z, BEAKER_MASS = 20 * mm, 60 * mm, -60 * mm, 0.030   # [m], [m], centre z [m], [kg]
WRENCH_SIZE, WRENCH_Z, WRENCH_MASS = (5 * mm, 100 * mm, 10 * mm), -72 * mm, 7850.0 * 5e-3 * 10e-3 * 100e-3
GRAVITY = 9.81                                          # [m/s^2]
#: Finger-bolt contact: penalty [N/m^2], damping [N s/m^2], Coulomb friction [-], regularization [m/s].
CONTACT = dict(stiffness=2e5, damping=20.0, friction=0.6, regularization=2e-3)
DT, DRIVE_TABLE_DT = 2e-3, 5e-4                         # step [s]; the drive's table, a quarter step [s]
#: The full run and the short one (`--quick`, what the tests run): simulated time [s].
FULL = dict(t_end=3.4)
QUICK = dict(t_end=1.4)


def main(out: Path, quick: bool = False) -> dict:
    """Grasp and screw the bolt into ``out``; returns the report (``suzumori_gripper.png`` drawn)."""
    from soroshapes.network import Schedule

    T = (QUICK if quick else FULL)["t_end"]

    # 0. the static grasps of the seed's Fig. 27: the beaker by four fingers, the wrench by two
    grasps = {"beaker": static_grasp(beaker(), range(4), [(0.0, -1.0)] * 4, BEAKER_MASS),
              "wrench": static_grasp(wrench(), (0, 1), pair_directions(), WRENCH_MASS)}
    plot_grasps(grasps, out / "suzumori_grasps.png")

    # 1. the model: four fingers, the bolt, contact between each finger and the bolt's head
    mdl, fingers = gripper()

    # 2. the drive as a table sampled at a quarter of the step (its kinks at 0.3, 0.4 and 0.5 s are samples):
    #    a Schedule runs compiled inside the network, a Python callable would not
    times = np.linspace(0.0, T, int(round(T / DRIVE_TABLE_DT)) + 1)
    table = np.array([pressures(t) for t in times])
    mdl.set_controller(Schedule(times, {f"finger{j}": table for j in range(4)}))

    # 3. simulate
    t0 = time.perf_counter()
    tr = mdl.simulate(T, DT, "bdf2", rtol=1e-5, atol=1e-8)
    wall = time.perf_counter() - t0

    # 4. the bolt's rate after the first turn of the circle, the grasp's normal force
    angle = tr["bolt"].x[:, 0]
    screw = tr.t >= T_SCREW + 0.5
    rate = np.polyfit(tr.t[screw], angle[screw], 1)[0]
    force = grasp_force(mdl, fingers, tr)
    grasp = (tr.t > T_GRASP) & (tr.t < T_SCREW)
    limit = CONTACT["friction"] * 4 * force[screw].mean() * R_BOLT / BOLT_DAMPING / (2 * np.pi)

    # 5. figure: the gripper at the end (mm), the bolt's angle and the grasp force against time
    plot(fingers, tr, angle, force, out / "suzumori_gripper.png")
    return {
        "pinch_beaker": {k: v for k, v in grasps["beaker"].items() if k not in ("shapes", "object")},
        "pair_pinch_wrench": {k: v for k, v in grasps["wrench"].items() if k not in ("shapes", "object")},
        "revolutions_per_second": round(float(rate / (2 * np.pi)), 5),
        "seed_rev_per_s": {"simulated": 0.16, "measured": 0.25},
        "friction_limited_rev_per_s": round(float(limit), 5),
        "bolt_damping_N_m_s": BOLT_DAMPING,
        "bolt_turns": round(float(angle[-1] / (2 * np.pi)), 5),
        "grasp_force_N": round(float(force[grasp].mean()), 7) if grasp.any() else 0.0,
        "screw_force_N_mean": round(float(force[screw].mean()), 7),
        "screw_force_N_max": round(float(force[screw].max()), 6),
        "drive_frequency_hz": FREQ, "simulated_s": T, "wall_time_s_sim": round(wall, 2),
        "real_time_factor": round(T / wall, 4), "evaluation_path": tr.stats.get("path"),
        "newton_iterations": int(tr.stats.get("newton_iterations", 0)) if isinstance(tr.stats, dict) else None,
        "png": "suzumori_gripper.png", "pngs": ["suzumori_grasps.png", "suzumori_gripper.png"],
    }


# ------------------------------------------------------------------------------------------------- the steps
def chamber_shape(phi):
    """One chamber of the finger's section (2D SDF): the 120 deg sector of the bore (radius BORE) centred at the
    section angle ``phi`` [rad], between two radial partitions WALL thick."""
    a1, a2 = phi - np.pi / 3, phi + np.pi / 3
    d1, d2 = np.array([np.cos(a1), np.sin(a1)]), np.array([np.cos(a2), np.sin(a2)])
    n1, n2 = np.array([-d1[1], d1[0]]), np.array([d2[1], -d2[0]])      # the edges' normals into the sector
    s, _ = np.linalg.solve(np.column_stack([d1, -d2]), 0.5 * WALL * (n2 - n1))
    apex = s * d1 + 0.5 * WALL * n1                                   # where the two partitions' faces meet
    mid = np.array([np.cos(phi), np.sin(phi)])
    far = 3 * BORE
    return sdf.Circle(BORE) & sdf.Polygon([tuple(apex), tuple(apex + far * d1), tuple(apex + 1.5 * far * mid),
                                           tuple(apex + far * d2)])


@functools.lru_cache(maxsize=1)
def finger_section():
    """(section SDF, chamber areas [m^2] (3,), chamber centroids (3, 2) [m]): the 12 mm tube with its three
    sector chambers cut out, and each chamber's area and centroid (numerical section properties, 0.01 mm
    grid)."""
    from sorofem.sdf.properties import section_properties

    chambers = [chamber_shape(phi) for phi in PHI]
    section = sdf.Circle(R) - chambers[0] - chambers[1] - chambers[2]
    props = [section_properties(c, resolution=0.01 * mm) for c in chambers]
    return section, np.array([p.area for p in props]), np.array([p.centroid for p in props])


def finger(j):
    """Finger j: a Shapes hanging from the ring at angle j pi/2, with three chambers and gravity."""
    from soroshapes import Basis, Shapes

    a = j * np.pi / 2
    tangential = np.array([-np.sin(a), np.cos(a), 0.0])
    base = np.eye(4)
    base[:3, 0] = (0.0, 0.0, -1.0)                      # body x (rod axis) down
    base[:3, 1] = tangential                            # body y tangential
    base[:3, 2] = np.cross(base[:3, 0], tangential)     # body z radially outward
    base[:3, 3] = (RING * np.cos(a), RING * np.sin(a), 0.0)
    section, areas, centroids = finger_section()
    shp = Shapes(Basis.chebyshev(3), (0, 3, 3, 0, 0, 0), length=L, section=section,
                 material=materials.NeoHookean(E=1.0e6, nu=0.3, density=2000.0, damping=0.1), base=base,
                 segments=12, contact_radius=R)
    for k in range(3):
        shp.add_chamber(areas[k], tuple(centroids[k]), name=f"chamber{k}")
    shp.add_gravity((0.0, 0.0, -9.81))
    return shp


def bolt():
    """The hexagonal bolt head spinning about z against its rotational damping."""
    from soroshapes import RigidBody

    hexagon = sdf.Polygon([(R_BOLT * np.cos(t), R_BOLT * np.sin(t)) for t in np.arange(6) * np.pi / 3])
    pose = np.eye(4)
    pose[2, 3] = Z_BOLT
    return RigidBody.spinning((0.0, 0.0, 1.0), BOLT_INERTIA, BOLT_DAMPING, hexagon.extrude(H_BOLT), pose0=pose,
                              name="bolt")


def gripper():
    """The model: ``finger0..3`` and ``bolt``, each finger in contact with the bolt. Returns ``(model,
    fingers)``."""
    from soroshapes import Model
    from soroshapes.rigid import couple_contact

    fingers = [finger(j) for j in range(4)]
    mdl = Model()
    for j, f in enumerate(fingers):
        mdl.add(f, f"finger{j}")
    mdl.add(bolt())
    for j in range(4):
        couple_contact(mdl, f"finger{j}", "bolt", **CONTACT)
    return mdl, fingers


def pressures(t):
    """Chamber pressures [Pa] (3,) of every finger at time t [s] (the drive of the module docstring)."""
    ramp = min(t / T_GRASP, 1.0)
    e_in, e_t = np.array([0.0, -1.0]), np.array([1.0, 0.0])
    delta = BIAS * ramp * e_in
    if t > T_SCREW:
        w = 2 * np.pi * FREQ * (t - T_SCREW)
        delta = delta + CIRCLE * (np.cos(w) * e_in + np.sin(w) * e_t) * min((t - T_SCREW) / 0.1, 1.0)
    return P0 * ramp + 2.0 / 3.0 * E_K @ delta


def chamber_pressures(direction, p_max=P_MAX):
    """The least chamber pressures [Pa] (3,) that bend a finger toward the unit ``direction`` (y, z) of its
    section, the largest ``p_max`` [Pa] (the static grasps of the module docstring)."""
    d = np.asarray(direction, dtype=float)
    c = E_K @ (d / np.linalg.norm(d))
    b = p_max / (2.0 / 3.0 * (c.max() - c.min()))
    return 2.0 / 3.0 * b * (c - c.min())


def beaker():
    """The seed's beaker: a vertical cylinder, 40 mm across and 60 mm tall, on the gripper's axis."""
    return sdf.Cylinder(BEAKER_R, BEAKER_H, center=(0.0, 0.0, BEAKER_Z))


def pair_directions():
    """The directions (y, z) in the sections of fingers 0 and 1 toward the plane that bisects them."""
    n = np.array([1.0, -1.0, 0.0]) / np.sqrt(2.0)           # the plane's normal, finger 0 on its + side
    out = []
    for j, sign in ((0, -1.0), (1, 1.0)):
        a = j * np.pi / 2
        tangential, radial = np.array([-np.sin(a), np.cos(a), 0.0]), np.array([np.cos(a), np.sin(a), 0.0])
        out.append((sign * n @ tangential, sign * n @ radial))
    return out


def wrench():
    """The seed's wrench: a 5 x 10 x 100 mm box, 5 mm across the plane bisecting fingers 0 and 1, 100 mm along
    it (horizontal), centred on that plane where the two fingers meet."""
    centre = 0.75 * RING * np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0) + np.array([0.0, 0.0, WRENCH_Z])
    box = sdf.Box(WRENCH_SIZE, center=(0.0, 0.0, 0.0))
    return box.rotate(-np.pi / 4, axis=(0.0, 0.0, 1.0)).translate(tuple(centre))


def static_grasp(obj, which, directions, mass):
    """The static equilibrium of fingers ``which`` bent toward ``directions`` at P_MAX against the fixed
    ``obj``: per finger its normal (horizontal) contact force [N], the total, the friction force available
    and the hold margin over the weight of ``mass`` [kg]; the mean horizontal travel of a free fingertip at
    these pressures and the mean gap between the straight fingertip's tube and ``obj`` [mm] (no contact
    unless the travel exceeds the gap); ``shapes``: (finger, q) for the figure."""
    normal, shapes, travel, gap = [], [], [], []
    for j, d in zip(which, directions):
        free = finger(j)
        tip0 = free.positions(np.zeros(free.n))[-1]
        travel.append(np.linalg.norm((free.positions(free.statics(u=chamber_pressures(d), steps=4))[-1] - tip0)[:2]))
        gap.append(float(obj(tip0[None])[0]) - R)
        f = finger(j).add_contact(obj, **CONTACT)
        q = f.statics(u=chamber_pressures(d), steps=4)
        normal.append(float(np.linalg.norm(f.contact_forces(q).sum(axis=0)[:2])))
        shapes.append((f, q))
    total = float(sum(normal))
    available = CONTACT["friction"] * total
    return {"normal_force_N": [round(v, 7) for v in normal], "total_normal_N": round(total, 7),
            "friction_available_N": round(available, 7), "weight_N": round(mass * GRAVITY, 5),
            "hold_margin": round(available / (mass * GRAVITY), 5),
            "free_tip_travel_mm": round(float(np.mean(travel)) / mm, 3),
            "gap_to_close_mm": round(float(np.mean(gap)) / mm, 3),
            "pressures_kPa":
            [[round(float(p) / kPa, 2) for p in chamber_pressures(d)] for d in directions],
            "shapes": shapes, "object": obj}


def grasp_force(mdl, fingers, tr):
    """The mean over the fingers of the horizontal contact force [N] on each finger, per time step."""
    from soroshapes.rigid import beam_contact

    c = CONTACT
    out = []
    for k in range(len(tr.t)):
        total = 0.0
        for j, f in enumerate(fingers):
            F = beam_contact(f, mdl["bolt"].system, c["stiffness"], c["damping"], c["friction"],
                             c["regularization"], q=tr[f"finger{j}"].q[k], qd=tr[f"finger{j}"].qd[k],
                             x=tr["bolt"].x[k], nodes=True)[2]
            total += np.linalg.norm(F.sum(axis=0)[:2])
        out.append(total / 4)
    return np.array(out)


# ------------------------------------------------------------------------------------------------ the figures
def plot_grasps(grasps, path):
    """``suzumori_grasps.png`` (seed Fig. 27): the beaker pinched by four fingers and the wrench pinched by two,
    the objects' surfaces sampled as grey points and the fingers' backbones [mm], the hold margins in the titles."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(11, 4.8))
    rng = np.random.default_rng(0)
    for k, (name, g) in enumerate(grasps.items()):
        ax = fig.add_subplot(1, 2, k + 1, projection="3d")
        pts = rng.uniform(-0.06, 0.06, (60000, 3)) + np.array([0.0, 0.0, -0.06])
        near = np.abs(g["object"](pts)) < 0.7 * mm
        ax.scatter(*(pts[near] / mm).T, s=0.5, color="0.6", alpha=0.4)
        for f, q in g["shapes"]:
            P = f.positions(q) / mm
            ax.plot(P[:, 0], P[:, 1], P[:, 2], lw=6, alpha=0.8)
        ax.set(xlabel="x [mm]", ylabel="y [mm]", zlabel="z [mm]", xlim=(-60, 60), ylim=(-60, 60), zlim=(-120, 0),
               title=f"{name}: {g['total_normal_N']:.3f} N normal, hold margin {g['hold_margin']:.2f}")
    save_figure(fig, path)


def plot(fingers, tr, angle, force, path):
    """``suzumori_gripper.png``: the fingers and the bolt head at the end [mm]; the bolt angle [rev] and the
    mean normal force per finger [N] against time."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(11, 4.2))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    k_end = len(tr.t) - 1
    for j, f in enumerate(fingers):
        P = f.positions(tr[f"finger{j}"].q[k_end])
        ax.plot(P[:, 0] / mm, P[:, 1] / mm, P[:, 2] / mm, lw=6, alpha=0.7)
    th = angle[k_end] + np.arange(7) * np.pi / 3
    for z in (Z_BOLT - H_BOLT / 2, Z_BOLT + H_BOLT / 2):
        ax.plot(R_BOLT / mm * np.cos(th), R_BOLT / mm * np.sin(th), np.full(7, z / mm), "k", lw=1)
    ax.set(xlabel="x [mm]", ylabel="y [mm]", zlabel="z [mm]", title="pinch grasp on the bolt head")
    bx = fig.add_subplot(1, 2, 2)
    bx.plot(tr.t, angle / (2 * np.pi), label="bolt angle [rev]")
    bx.plot(tr.t, force, label="mean normal force per finger [N]")
    bx.axvline(T_SCREW, color="0.6", lw=0.8)
    bx.set(xlabel="t [s]")
    bx.legend(fontsize=8)
    bx.grid(alpha=0.3)
    save_figure(fig, path)


# ------------------------------------------------------------------------------------------- soro play scene
def scene(quick=False):
    """``soro play suzumori_gripper``: the four three-chamber fingers around the bolt, one pressure slider per
    chamber (0-300 kPa)."""
    from soro.play import Channel, Scene

    mdl, _ = gripper()
    channels = [Channel(f"finger{j}.chamber{k}", 0.0, 300 * kPa, label=f"finger {j} chamber {k}")
                for j in range(4) for k in range(3)]
    return Scene(mdl, channels, dt=DT, method="bdf2", view=(-30.0, 20.0), title="suzumori_gripper")
