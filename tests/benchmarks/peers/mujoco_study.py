"""MuJoCo side of the Cosserat-rod benchmarks: the cantilever as a chain of rigid links with elastic hinges.

MuJoCo (``pip install '.[peers]'`` into the project's venv; it pins nothing we pin) is imported by the
functions only, so that importing this file (pytest's doctest collection) needs nothing.

The rod is the one of ``elastica_cases.py`` (``L = 0.2 m``, ``r = 5 mm``, ``E = 1 MPa``, ``1000 kg/m^3``),
clamped at the origin along ``+x``, loaded along ``-z``, bending in the x-z plane. Discretization (the
pseudo-rigid-body chain, MuJoCo's usual way to model a flexible beam without its cable plugin): ``n`` links of
length ``l = L / n``, each with the mass :math:`\\rho A l` at its centre and the inertia of a solid cylinder;
hinges about ``y`` at the start of every link with the stiffness of the bending energy
:math:`\\int EI\\kappa^2/2` lumped at the joints, :math:`EI/l` (``2 EI / l`` at the clamp, which carries half a
link). The chain is inextensible and unshearable: it converges to Kirchhoff's elastica as :math:`1/n^2`.

Statics (MuJoCo has no static solver): damped dynamics to rest with the ``implicitfast`` integrator, joint
damping proportional to the stiffness (``beta`` [s]), time step at the explicit stability bound of the stiffest
hinge (``dt_factor`` times :math:`2/\\omega_{max}`); stops when every joint speed is below ``v_tol`` [rad/s].
Timing: ``wall_s`` is the stepping loop (``mj_step`` in batches between the checks), ``build_s`` compiling the
model from XML. The tip load is a dead force applied at the tip through ``xfrc_applied`` (force and moment at
the last link's centre of mass), refreshed at every check.
"""
import math
import time

ROD = {"length": 0.2, "radius": 5e-3, "E": 1e6, "density": 1000.0, "g": 9.81}

__all__ = ["ROD", "chain_xml", "static_tip", "release_tip", "available"]


def available():
    """(True, version) if MuJoCo imports, else (False, the reason)."""
    try:
        import mujoco
    except Exception as e:  # ImportError, or a broken binary wheel
        return False, f"{type(e).__name__}: {e}"
    return True, mujoco.__version__


def _section():
    r = ROD["radius"]
    A = math.pi * r * r
    EI = ROD["E"] * math.pi * r**4 / 4
    return A, EI


def chain_xml(n, dt, beta=0.0, gravity=True):
    """MJCF of the n-link chain; joint damping ``beta`` times the joint stiffness; time step ``dt`` [s]."""
    L, r, rho = ROD["length"], ROD["radius"], ROD["density"]
    A, EI = _section()
    l = L / n
    m = rho * A * l
    Ia = 0.5 * m * r * r                              # about the link's axis (x)
    It = m * (3 * r * r + l * l) / 12                 # about y and z through the centre
    g = ROD["g"] if gravity else 0.0
    body = ""
    for i in reversed(range(n)):
        k = (2.0 if i == 0 else 1.0) * EI / l
        tip = '<site name="tip" pos="%r 0 0"/>' % l if i == n - 1 else ""
        body = (f'<body name="b{i}" pos="{0.0 if i == 0 else l!r} 0 0">'
                f'<joint name="j{i}" type="hinge" axis="0 1 0" stiffness="{k!r}" damping="{beta * k!r}"/>'
                f'<inertial pos="{l / 2!r} 0 0" mass="{m!r}" diaginertia="{Ia!r} {It!r} {It!r}"/>'
                f'{tip}{body}</body>')
    return (f'<mujoco><option timestep="{dt!r}" gravity="0 0 {-g!r}" integrator="implicitfast"/>'
            f'<worldbody>{body}</worldbody></mujoco>')


def _quiet(mujoco):
    """Route MuJoCo's warnings (an unstable trial step) away from the MUJOCO_LOG.TXT it would write in the working
    folder: the runs read the warning counters instead."""
    mujoco.set_mju_user_warning(lambda message: None)


def _omega_max(n):
    """Highest hinge frequency estimate [rad/s]: the last link on its joint, sqrt(k / (m l^2 / 3))."""
    L, rho = ROD["length"], ROD["density"]
    A, EI = _section()
    l = L / n
    return math.sqrt((EI / l) / (rho * A * l * l * l / 3))


def _tip_wrench(mujoco, model, data, P):
    """Dead force P [N] along -z at the tip: force and moment at the last link's centre of mass."""
    last = model.nbody - 1
    tip = data.site_xpos[0]
    com = data.xipos[last]
    F = (0.0, 0.0, -P)
    rx, ry, rz = tip[0] - com[0], tip[1] - com[1], tip[2] - com[2]
    data.xfrc_applied[last, :3] = F
    data.xfrc_applied[last, 3:] = (ry * F[2] - rz * F[1], rz * F[0] - rx * F[2], rx * F[1] - ry * F[0])


def static_tip(case, n, beta=0.05, dt_factor=0.5, v_tol=1e-6, check_every=50, t_max=20.0, load_factor=3.0):
    """Rest position of the tip (dx, dz) [m] under ``gravity`` or a ``tip_load`` (``P L^2 / EI = load_factor``),
    by damped dynamics. Returns a dict with ``tip_dx``, ``tip_dz``, ``wall_s``, ``build_s``, ``steps``,
    ``simulated_s``, ``converged``."""
    import mujoco
    import numpy as np
    _quiet(mujoco)
    L = ROD["length"]
    _, EI = _section()
    dt = dt_factor * 2.0 / _omega_max(n)
    t0 = time.perf_counter()
    model = mujoco.MjModel.from_xml_string(chain_xml(n, dt, beta, gravity=(case == "gravity")))
    data = mujoco.MjData(model)
    build = time.perf_counter() - t0
    P = load_factor * EI / L**2 if case == "tip_load" else 0.0
    steps, converged = 0, False
    t0 = time.perf_counter()
    mujoco.mj_forward(model, data)
    while steps * dt < t_max:
        if P:
            _tip_wrench(mujoco, model, data, P)
        mujoco.mj_step(model, data, nstep=check_every)
        steps += check_every
        if not np.all(np.isfinite(data.qvel)) or data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number:
            break
        if np.max(np.abs(data.qvel)) < v_tol:
            converged = True
            break
    wall = time.perf_counter() - t0
    mujoco.mj_kinematics(model, data)
    tip = data.site_xpos[0]
    return {"n_links": n, "tip_dx": float(tip[0] - L), "tip_dz": float(tip[2]), "wall_s": wall, "build_s": build,
            "steps": steps, "simulated_s": steps * dt, "dt": dt, "converged": converged}


def release_tip(n, dt, t_end=1.0, record_every_s=0.01):
    """The chain released straight under gravity, undamped: tip positions (x, z) [m] every ``record_every_s``
    and the wall time of the stepping [s] (``mj_step`` in batches between the records)."""
    import mujoco
    import numpy as np
    _quiet(mujoco)
    model = mujoco.MjModel.from_xml_string(chain_xml(n, dt, 0.0, gravity=True))
    data = mujoco.MjData(model)
    per = max(1, int(round(record_every_s / dt)))
    nrec = int(round(t_end / (per * dt)))
    out = np.zeros((nrec + 1, 2))
    mujoco.mj_forward(model, data)
    out[0] = data.site_xpos[0][[0, 2]]
    t0 = time.perf_counter()
    for k in range(1, nrec + 1):
        mujoco.mj_step(model, data, nstep=per)
        mujoco.mj_kinematics(model, data)
        out[k] = data.site_xpos[0][[0, 2]]
    wall = time.perf_counter() - t0
    # MuJoCo resets the state when the accelerations blow up (and warns): such a run is unstable, not finite
    blown = int(data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number)
    return {"n_links": n, "dt": dt, "tip": out, "wall_s": wall,
            "stable": bool(np.all(np.isfinite(out)) and blown == 0)}
