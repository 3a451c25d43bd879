r"""Jellyfish gripper wrapping a sphere (`soro demo jellyfish_gripper`)
=================================================================

Purpose
-------
The seed's inverse-kinematics case study (Sec. V-D6, Fig. 14) after the ultra-gentle "jellyfish" gripper of
Sinatra et al. (Science Robotics 4, eaax5425, 2019): six thin silicone filaments hang from a hub and wrap
around a delicate object, here a sphere. Each finger is a reduced Cosserat beam (:class:`soroshapes.Shapes`);
its wrapped shape is found by multi-node inverse kinematics with the elastic null-space subtask, as in the
seed:

1. pre-deform the finger by forward kinematics with a chosen :math:`q_\mathrm{pre}` (bent outward at the
   hub so that it clears the sphere, curled inward along the rest);
2. project its backbone nodes onto the sphere, offset outward by the finger's half thickness :math:`h`:
   :math:`p^* = c + (R + h)(p - c) / |p - c|`;
3. solve the IK with the projected points of the distal half of the nodes as targets (damped least squares,
   subtask ``"elastic"``: :math:`\nabla\Psi = Kq`).

A single projection (the seed's procedure) leaves the targets inconsistent with the inextensible finger
(projection shortens or stretches their spacing), so steps 2-3 are repeated from the new shape until the
targets move by less than ``PASS_TOL``; the first pass is reported too.

Equations
---------
Strain :math:`\xi(\sigma) = \Theta(\sigma)q + (0, 0, 0, 1, 0, 0)` with Chebyshev polynomials :math:`T_0..T_2`
of :math:`2\sigma/L - 1` in both bendings (``dofs = (0, 3, 3, 0, 0, 0)``, :math:`n = 6`). Each IK iteration
takes :math:`\Delta q = J^T(JJ^T + \lambda^2 I)^{-1}e + (I - J^\dagger J)(-\alpha Kq)`. With 11 position
targets (33 equations for 6 unknowns) the problem is an over-determined least-squares fit: :math:`J` has full
column rank, its null space is empty and the elastic subtask cannot act (``subtask_effect_max``, the largest
difference [1/m] from a plain solve, is the size of the unconverged remainder); the IK error is the
least-squares residual, not zero. With the subtask the solver never meets its stall test, so every pass runs
to ``max_iterations`` = 200 (``ik_iterations`` sums the passes); a plain solve stops after 10-40 iterations
at the same error.

Limits: the tips end near the sphere's lower pole (``tip_radius_mm`` ~2 mm): 130 mm is about the path from
the hub around the sphere to its pole. Contact between fingers and gravity are not modelled (a pure
kinematic wrap, as in the seed).

Finger :math:`k` is clamped at :math:`r_b(\cos\phi_k, \sin\phi_k, 0)`, :math:`\phi_k = k\,60°`, pointing
down: body axes :math:`(e_x, e_y, e_z) = (-e_Z, e_\phi, e_r)`, so the thin side of the section (body
:math:`z`) is radial and the weak bending :math:`\kappa_y` curls the finger toward (:math:`\kappa_y > 0`) or
away from the axis.

Parameters
----------
=================  =====================================================================================
fingers            6, length 130 mm, section 10 mm x 2 mm rectangle (h = 1 mm), bases on a circle r_b = 22 mm
material           Neo-Hookean, E from Gent's relation at Shore 20A (0.73 MPa), nu = 0.45, 1070 kg/m^3
sphere             radius 40 mm, centre (0, 0, -60) mm
pre-deformation    q_pre = (5, 20, -15) 1/m on kappa_y (curvature -30 1/m at the hub, +20 mid-finger,
                   +10 at the tip), 0 on kappa_z
IK targets         the projected distal half of the nodes (sigma >= L/2: 11 nodes); subtask "elastic"
discretization     quick: 20 Magnus segments; full: 40 segments (targets on every other node)
=================  =====================================================================================

Figures
-------
``report.json`` holds the set-up (``fingers``, ``segments``, ``targets_per_finger``, ``youngs_modulus_MPa``,
``png_files``), per finger (lists, finger order) ``ik_error_m``, ``ik_iterations``, ``ik_converged``,
``projection_passes``, ``penetration_mm`` (max over the nodes of :math:`h - (|p - c| - R)`, 0 if none),
``wrap_angle_deg`` (angle at the sphere centre between the first and the last node within 0.5 mm of the
offset surface), ``time_per_ik_s``; and the summaries ``max_penetration_mm``, ``max_ik_error_m``,
``first_pass_penetration_mm``, ``first_pass_ik_error_m``, ``mean_wrap_angle_deg``, ``tip_radius_mm`` (distance
of the tips from the z axis), ``subtask_effect_max`` (max |q_elastic - q_plain|). Pictures:
``jellyfish.png`` (the six fingers and the sphere, 3D), ``finger_plane.png`` (finger 0 in its radial
plane: pre-deformed, first pass, final).
"""
import time
from pathlib import Path

import numpy as np

from sorofem import materials, sdf
from sorofem.units import mm

FINGERS, LENGTH, WIDTH, THICK, BASE_R = 6, 130 * mm, 10 * mm, 2 * mm, 22 * mm
CENTER, RADIUS = np.array([0.0, 0.0, -60 * mm]), 40 * mm
Q_PRE = np.array([5.0, 20.0, -15.0, 0.0, 0.0, 0.0])  # Chebyshev coefficients of (kappa_y, kappa_z) [1/m]
PASS_TOL = 2e-6          # stop the projection passes when no target moves more than this [m]
MAX_PASSES = 20
CONTACT_TOL = 0.5 * mm   # a node within this of the offset sphere counts as wrapped (wrap angle)


#: The full run and the short one (`--quick`, what the tests run): Magnus segments per finger.
FULL = dict(segments=40)
QUICK = dict(segments=20)


def main(out: Path, quick: bool = False) -> dict:
    from soroshapes import Basis, Shapes
    from soroshapes.render import render_png

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    segments = (QUICK if quick else FULL)["segments"]
    material = materials.NeoHookean(E=materials.gent_modulus(20), nu=0.45, density=1070.0)
    section = sdf.Rectangle(WIDTH, THICK)

    res = {k: [] for k in ("ik_error_m", "ik_iterations", "ik_converged", "projection_passes", "penetration_mm",
                           "wrap_angle_deg", "time_per_ik_s")}
    first_err, first_pen, tips, effect, beams = [], [], [], [], []
    warm = Shapes(Basis.chebyshev(3), dofs=(0, 3, 3, 0, 0, 0), length=LENGTH, section=section, material=material)
    warm.inverse_kinematics(warm.positions(Q_PRE)[-1], max_iterations=2)  # compile the kernels before timing
    for k in range(FINGERS):
        shp = Shapes(Basis.chebyshev(3), dofs=(0, 3, 3, 0, 0, 0), length=LENGTH, section=section,
                     material=material, base=base_pose(2 * np.pi * k / FINGERS), segments=segments)
        step = segments // 20                       # the same 11 target positions at both resolutions
        idx = np.arange(segments // 2, segments + 1, step)
        r, passes, its, times, first = wrap(shp, idx, Q_PRE)
        P = shp.positions(r.q)
        plain = shp.inverse_kinematics([(shp.sigma[i], p) for i, p in zip(idx, project(P[idx], THICK / 2))],
                                       q0=r.q)
        effect.append(float(np.abs(plain.q - r.q).max()))
        res["ik_error_m"].append(float(r.error))
        res["ik_iterations"].append(int(its))
        res["ik_converged"].append(bool(r.converged))
        res["projection_passes"].append(int(passes))
        res["penetration_mm"].append(float(max(0.0, -clearance(P).min()) / mm))
        res["wrap_angle_deg"].append(wrap_angle(P))
        res["time_per_ik_s"].append(float(np.mean(times)))
        first_err.append(float(first[0]))
        first_pen.append(float(first[1] / mm))
        tips.append(float(np.hypot(*P[-1, :2]) / mm))
        beams.append({"frames": shp.forward_kinematics(r.q), "radius": THICK / 2})
        if k == 0:
            shapes0, q_first, P0 = shp, first[2], P

    sphere = {"type": "sphere", "center": CENTER, "radius": RADIUS, "color": "tab:orange", "alpha": 0.35}
    title = f"six fingers wrapping a {2 * RADIUS / mm:.0f} mm sphere (IK, max penetration " \
            f"{max(res['penetration_mm']):.2f} mm)"
    render_png(out / "jellyfish.png", beams, obstacles=[sphere], view=(12, -60), title=title, size=(6.5, 6),
               dpi=130, color="tab:blue")
    plane_plot(out / "finger_plane.png", shapes0, q_first, P0)
    return {
        "fingers": FINGERS,
        "segments": segments,
        "targets_per_finger": int(len(idx)),
        "youngs_modulus_MPa": material.E / 1e6,
        **res,
        "max_penetration_mm": max(res["penetration_mm"]),
        "max_ik_error_m": max(res["ik_error_m"]),
        "first_pass_penetration_mm": max(first_pen),
        "first_pass_ik_error_m": max(first_err),
        "mean_wrap_angle_deg": float(np.mean(res["wrap_angle_deg"])),
        "tip_radius_mm": tips,
        "subtask_effect_max": max(effect),
        "png_files": 2,
    }


# ------------------------------------------------------------------------------------------------- the steps
def base_pose(phi):
    """Clamp pose (4, 4) of the finger at hub angle ``phi`` [rad]: on the circle r_b, pointing down (-z),
    body z radial (outward), body y tangential."""
    er = np.array([np.cos(phi), np.sin(phi), 0.0])
    ephi = np.array([-np.sin(phi), np.cos(phi), 0.0])
    g = np.eye(4)
    g[:3, :3] = np.column_stack([[0.0, 0.0, -1.0], ephi, er])
    g[:3, 3] = BASE_R * er
    return g


def project(P, offset):
    """Points P (m, 3) [m] projected radially onto the sphere of radius R + ``offset``."""
    d = P - CENTER
    return CENTER + (RADIUS + offset) * d / np.linalg.norm(d, axis=1)[:, None]


def clearance(P):
    """Signed distance [m] of the finger surface (nodes minus half thickness) to the sphere."""
    return np.linalg.norm(P - CENTER, axis=1) - RADIUS - THICK / 2


def wrap(shp, idx, q0):
    """Repeated projection + IK from ``q0``; returns (IKResult, passes, total iterations, IK times, first pass
    (error, penetration [m], q))."""
    q, P = q0.copy(), shp.positions(q0)
    targets = project(P[idx], THICK / 2)
    times, its, first = [], 0, None
    for k in range(1, MAX_PASSES + 1):
        t0 = time.perf_counter()
        r = shp.inverse_kinematics([(shp.sigma[i], targets[i_t]) for i_t, i in enumerate(idx)], q0=q,
                                   subtask="elastic")
        times.append(time.perf_counter() - t0)
        its += r.iterations
        q, P = r.q, shp.positions(r.q)
        if first is None:
            first = (r.error, max(0.0, -clearance(P).min()), r.q)
        new = project(P[idx], THICK / 2)
        moved = np.abs(new - targets).max()
        targets = new
        if moved < PASS_TOL:
            break
    return r, k, its, times, first


def wrap_angle(P):
    """Angle [deg] at the sphere centre spanned by the wrapped nodes (within CONTACT_TOL of the surface)."""
    touch = np.flatnonzero(np.abs(clearance(P)) < CONTACT_TOL)
    if len(touch) < 2:
        return 0.0
    u = (P[touch[[0, -1]]] - CENTER) / np.linalg.norm(P[touch[[0, -1]]] - CENTER, axis=1)[:, None]
    return float(np.degrees(np.arccos(np.clip(u[0] @ u[1], -1.0, 1.0))))


def plane_plot(path, shp, q_first, P):
    """The finger in its radial plane (r, z) [mm]: pre-deformed, first pass, final, targets, sphere."""
    from matplotlib.figure import Figure
    from sorofem.io import save_figure

    def rz(X):
        return np.hypot(X[:, 0], X[:, 1]) * np.sign(X[:, 0] + 1e-15) / mm, X[:, 2] / mm
    fig = Figure(figsize=(5.5, 6))
    ax = fig.subplots()
    a = np.linspace(0, 2 * np.pi, 400)
    ax.fill(RADIUS / mm * np.cos(a), CENTER[2] / mm + RADIUS / mm * np.sin(a), color="tab:orange", alpha=0.3,
            label=f"sphere R = {RADIUS / mm:.0f} mm")
    ax.plot((RADIUS + THICK / 2) / mm * np.cos(a), CENTER[2] / mm + (RADIUS + THICK / 2) / mm * np.sin(a), ":",
            color="tab:orange", lw=1, label="offset by h = 1 mm (targets)")
    ax.plot(*rz(shp.positions(Q_PRE)), "--", color="gray", label="pre-deformed (FK of q_pre)")
    ax.plot(*rz(shp.positions(q_first)), "-", color="tab:green", lw=1, label="first IK pass")
    ax.plot(*rz(P), "o-", color="tab:blue", ms=3, label="wrapped (final)")
    ax.plot([BASE_R / mm], [0.0], "ks", label="clamp")
    ax.set_aspect("equal")
    ax.set_xlabel("radial coordinate r [mm]")
    ax.set_ylabel("z [mm]")
    ax.set_title("finger 0 in its radial plane")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")
    save_figure(fig, path, dpi=120)


if __name__ == "__main__":
    import json
    import sys

    print(json.dumps(main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/jellyfish_gripper"),
                          quick="--quick" in sys.argv), indent=2))


def scene(quick=False):
    """``soro play jellyfish_gripper``: the six filaments, pre-curved by ``Q_PRE`` at rest, each with a chamber
    on its outer side fed by one supply pressure (a first-order line, 50 ms), the sphere drawn (no contact, as in
    the demo's kinematic wrap), an IK target at the tip of the first filament. The material gets a damping ratio
    of 0.1 (the demo's kinematic wrap needs none) so that the filaments settle."""
    from soro.play import Channel, Scene, Target
    from soroshapes import Basis, Model, Shapes, StateSpace

    material = materials.NeoHookean(E=materials.gent_modulus(20), nu=0.45, density=1070.0, damping=0.1)
    section = sdf.Rectangle(WIDTH, THICK)
    sphere = sdf.Sphere(RADIUS, center=tuple(CENTER))

    def rest(sigma):                     # the pre-deformation as the rest strain (Chebyshev T0..T2 on kappa_y)
        x = 2 * sigma / LENGTH - 1
        return (0.0, Q_PRE[0] + Q_PRE[1] * x + Q_PRE[2] * (2 * x * x - 1), 0.0, 1.0, 0.0, 0.0)

    mdl = Model().add(StateSpace(lambda x, u, t: (u - x) / 0.05, 1, 1), "supply")
    for k in range(FINGERS):
        shp = Shapes(Basis.chebyshev(3), dofs=(0, 3, 3, 0, 0, 0), length=LENGTH, section=section, material=material,
                     base=base_pose(2 * np.pi * k / FINGERS), segments=10 if quick else 20, xi0=rest,
                     contact_radius=THICK / 2)
        if k == 0:
            tip = shp.positions(np.zeros(shp.n))[-1]
        shp.add_chamber(4 * mm**2, (0.0, THICK / 4), name="chamber")       # outer side: curls inward
        mdl.add(shp, f"finger{k}").connect("supply", f"finger{k}", "chamber")
    return Scene(mdl, [Channel("supply.u0", 0.0, 30e3, label="supply pressure")], obstacles=(sphere,),
                 target=Target(tuple(tip), beam="finger0"), dt=2e-3, method="bdf2", view=(-20.0, 15.0),
                 title="jellyfish_gripper")
