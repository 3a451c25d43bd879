r"""Five-fingered soft hand driven by phase-shifted pressure oscillators (`soro demo soft_hand`)
=========================================================================================

Purpose
-------
The seed's soft robotic hand (Sorotoki paper, Sec. VI, Fig. 15): five soft fingers, each a reduced Cosserat
beam with its own pressure-regulated fluidic reservoir, composed into one :class:`soroshapes.Model` and driven
by five square-wave pressure oscillators shifted by :math:`\pi/6` from one finger to the next, so that the
fingers curl one after the other. Figures: per-finger bending amplitude, the phase lag between neighbouring
fingers (the :math:`\pi/6` steps of the drive), the pressures reached and their tracking of the set point,
the implicit solver's Newton statistics, wall time and real-time factor.

Equations
---------
*Fingers.* Finger :math:`i` (``i = 0`` the thumb, 80 mm; ``1..4`` index to little finger, 90 mm) bends in
one plane only (``dofs = (0, 5, 0, 0, 0, 0)``, 5 Chebyshev modes :math:`T_0..T_4` of :math:`2\sigma/L - 1`):
:math:`\kappa_y(\sigma) = \sum_k T_k q_k` [1/m], so :math:`q_1` (the seed's "first joint") is the constant
part of the curvature. Dynamics :math:`M\ddot q + C\dot q + \tau K\dot q + Kq = G\,p`, Kelvin-Voigt damping
from the material's damping ratio (``Shapes`` default); gravity is not modelled (it would act out of the
bending plane of a hand lying palm-up, as in the seed's planar model).

*Input map (choice).* One chamber per finger (:meth:`Shapes.add_chamber`): cross-section
:math:`A_c` = 8 x 6 mm at :math:`d` = 2.5 mm from the backbone on the back of the finger, along the whole
length. Its pressure acts as a constant internal bending moment :math:`m = p A_c d`, so
:math:`G = \int \Theta^T (0, A_c d, 0, A_c, 0, 0)^T d\sigma` and the static answer is *exactly* a constant
curvature :math:`\kappa = p A_c d / EI` (represented by :math:`T_0` alone): 80 kPa curls a 90 mm finger by
:math:`\kappa L \approx 106^\circ`. The seed instead writes an input column on the first mode only,
``G = [5; 0; 0; 0; 0]`` (units mm, kPa); with a non-orthogonal Chebyshev stiffness that column does *not*
give a constant curvature, and its 5 has no physical unit we could carry over; the chamber has one.

*Reservoirs.* Isothermal ideal gas (:class:`soroshapes.Fluidic`) with the PI regulator of eq. (28)-(29) and a
valve saturation :math:`|\dot m| \le` 5 g/s; the regulator's set point is the oscillator's pressure. Volume
coupling :math:`V = V_0(1 + \tanh\alpha)`, :math:`V_0 = \tfrac{4\pi}{3} 35^3` mm^3 = 1.80e-4 m^3,
:math:`\alpha = 0.06\,q_1^{[1/\mathrm{mm}]} = 0.06 \cdot 10^{-3} q_1^{[1/\mathrm{m}]}`: the seed works in mm, so its
:math:`q_1` is in 1/mm while ours is in 1/m (factor 1e-3). With :math:`|q_1| \lesssim 25` 1/m this is a
volume change of ~0.15 %: a gentle load on the regulator. (The seed's code listing writes ``tanh(x/0.06)``,
2.8e5 times stronger than the text's :math:`\alpha = 0.06 q_1`; we follow the text; ``ALPHA_PER_MM``
switches it.) Regulator gains: :math:`k_p = V_0/(R T \tau_p)` with :math:`\tau_p` = 20 ms (the unsaturated
pressure loop's time constant) and :math:`k_i = k_p / 1` s (integral time 1 s: the reservoir is an
integrator, so the P part alone tracks; the slow I part only removes the offset from the volume change and
keeps the step overshoot at ~2 %).

*Oscillators (a set-point table).* The seed's :math:`p_{d,i} = 80\,\mathrm{sign}(\sin(7t + \phi_i))` kPa,
:math:`\phi_i = i\pi/6`, is smoothed to :math:`p_{d,i} = 80\,\tanh(k \sin(7t + \phi_i))/\tanh k` kPa with
:math:`k = 8` (10-90 % rise in ~40 ms, the plateaus reach exactly 80 kPa): a sign function has an infinite
slope at the switch, which an implicit solver with a reused Jacobian meets as a step in :math:`F` (Newton
failures, step cuts); a smooth switch of 40 ms is faster than the valve (~70 ms for the 160 kPa swing at
5 g/s), so the hand sees the same square wave. The controller plays one period of it as a periodic table
(:class:`soroshapes.network.Schedule`, samples every 0.1 ms: linear interpolation is within 0.3 Pa of the
formula), and the volume coupling is the declarative :class:`soroshapes.network.StateMap`
:math:`V_0 + V_0\tanh(\alpha)`: with them the whole network runs as one compiled kernel
(``mdl.evaluation_path == "compiled"``; the key figures equal those of the Python callables to 1e-6 deg).

*Integration.* ``Model.simulate`` with BDF2 (L-stable: the stiff, overdamped high Chebyshev modes and the
20 ms pressure loop are damped, not ringing as with the trapezoidal rule) in fixed steps of ``DT`` = 3.125 ms
(320 per second). In fixed steps ``rtol``, ``atol`` and ``newton_tol`` only set Newton's stopping test: it stops
when its estimated remaining error is below ``newton_tol (rtol |x| + atol s)`` = 0.03 |x| + 3e-7 s. Against a
Newton to 1e-7 |x| (rtol 1e-4, newton_tol 1e-3) the tip angles move by 0.0025 deg and the pressures by 8 Pa
(0.4 % of the discretization error below), at 1.6 times less CPU (``bench_model.py::
test_bench_soft_hand_newton_tolerance``: 2.48 Newton sweeps per step against 4.08).

*Accuracy: space against time.* The demo's accuracy is the largest tip-angle error over the five fingers and
the first 2 s (the 2 ms output grid of the old settings; every step of the others) against a reference
converged in both: 32 fourth-order Magnus pieces per finger, BDF2 at dt = 0.125 ms (16 pieces differ from it
by 0.003 deg; dt = 0.0625 ms by 0.001 deg). Its two parts, measured apart: the *space* error, the fingers'
discretization at the reference dt, and the *time* error, the step against the same fingers at 0.125 ms. The
two partly cancel in the total, so their sum is also given (a bound that does not rely on that). CPU per
simulated second and real-time factor: one core, every row with this Newton (0.03 |x|), load average 3.3
(``tests/benchmarks/bench_model.py::test_bench_soft_hand_space_time_trade`` measures a part of it again):

============  =======  ======  ======  ======  ==========  ========  =========
fingers       method   dt      space   time    total       CPU       real time
                       [ms]    [deg]   [deg]   (sum)       [ms/s]
============  =======  ======  ======  ======  ==========  ========  =========
10 x order 2  BDF2     2       1.213   0.334   0.90 (1.55) 16.7 (*)  60x (*)
10 x order 2  BDF2     3.125   1.213   0.821   0.46 (2.03) 13.1      76x
10 x order 2  BDF2     4       1.213   1.331   0.38 (2.54) 11.8      85x
4 x order 4   BDF2     2       0.175   0.333   0.23 (0.51) 17.1      59x
4 x order 4   BDF2     2.5     0.175   0.513   0.40 (0.69) 15.4      65x
4 x order 4   BDF2     3.125   0.175   0.818   0.70 (0.99) 13.6      74x   <- the demo
4 x order 4   BDF2     4       0.175   1.325   1.20 (1.50) 11.3      88x
6 x order 4   BDF2     3.125   0.207   0.815   0.63 (1.02) 16.4      61x
8 x order 4   BDF2     2       0.060   0.333   0.28 (0.39) 22.2      45x
8 x order 4   BDF2     3.125   0.060   0.814   0.76 (0.87) 17.5      57x
4 x order 4   trap.    4       0.175   0.343   0.25 (0.52) 22.8      44x
4 x order 4   trap.    6.25    0.175   0.841   0.73 (1.02) 14.8      67x
4 x order 4   midpt.   6.25    0.175   0.815   0.72 (0.99) 14.4      69x
============  =======  ======  ======  ======  ==========  ========  =========

(*) the previous version's settings (10 second-order pieces, dt = 2 ms), whose Newton stopped at 1e-3 |x|: 25.9
ms/s, 38.6x at load 4.3. The rule of the choice: the least CPU whose total error is within the previous version's
0.90 deg *and* whose space and time errors are each within it (the totals of the 10-piece fingers at 3-4 ms are
small only because a 1.2 deg space error cancels a time error of the opposite sign: luck, not accuracy). The
chosen 4 pieces of order 4 at 3.125 ms are 22 % more accurate in total (0.70 against 0.90 deg) at 1.8 times
less CPU than the previous version, back to back in one process (the bench above, load 3.7: 14.3 against 25.2 ms
per simulated second, 70x against 40x); the looser Newton gives about 1.5 of that, the step 1.2. Over the full
5 s run the totals are 0.74 against 0.97 deg (space 0.18 and 1.29, time 0.86 and 0.35). Fourth-order fingers cost
about what second-order ones do per step (10 pieces of order 2 evaluate the strains at 10 points, 4 pieces of
order 4 at 8: one and two Gauss points per piece), so they buy back the space error, and the larger step spends it on time, which grows as dt^2. The
trapezoidal and implicit midpoint rules have a 2.5 times smaller time error but cost twice as much per step
(their start-of-step evaluation F(t_k, x_k) is a forward dynamics of every finger), which leaves them a little
behind BDF2 at equal error. Fewer than 4 pieces of order 4 do not do: 3 give a space error of 2.8 deg, 2 a
singular mass matrix (5 modes, 4 Gauss points).

Parameters
----------
=================  =====================================================================================
fingers            5: thumb 80 mm, four fingers 90 mm; rounded rectangle 15 mm wide x 12 mm thick
                   (corner radius 3 mm), bending across the 12 mm thickness
material           Dragon Skin 10 preset (Yeoh, small-strain E = 216 kPa, 1070 kg/m^3, damping ratio 0.1)
palm               fingers' bases at x = 0, y = +-9, +-27 mm pointing along +x, palm normal +z (fingers
                   curl toward +z); thumb at (-45, 42) mm rotated 50 deg about z
chamber            8 x 6 mm at 2.5 mm behind the backbone, whole length
reservoir          V0 = 1.80e-4 m^3, isothermal air, 293.15 K, PI regulator (tau_p 20 ms, T_i 1 s,
                   5 g/s saturation)
drive              80 tanh(8 sin(7 t + i pi/6))/tanh 8 kPa, i = 0..4
simulation         T = 5 s (quick: 1 s), BDF2, dt = 3.125 ms, Newton to 0.03 |x| + 3e-7 s; fingers of
                   4 Magnus pieces of order 4
=================  =====================================================================================

Figures
-------
``report.json``: ``fingers``, ``lengths_mm``, ``modes``, ``youngs_modulus_kPa``, ``damping_tau_s``,
``first_frequency_Hz`` (per finger), ``static_angle_80kPa_deg`` (per finger, :math:`pA_cdL/EI`),
``bending_amplitude_deg`` (half the peak-to-peak tip angle over the last drive period), ``tip_angle_max_deg``,
``tip_angle_min_deg``, ``tip_excursion_mm`` (peak-to-peak tip travel), ``phase_deg`` (first harmonic at 7 rad/s
of each finger's tip angle over the analysis window, unwrapped), ``phase_step_deg`` (differences between
neighbours; the drive's step is 30 deg), ``phase_step_fingers_deg`` (the four identical 90 mm fingers),
``pressure_phase_step_deg``, ``max_pressure_kPa``, ``min_pressure_kPa``, ``plateau_tracking_error_kPa``
(largest :math:`|p - p_d|` where :math:`|p_d|` > 79 kPa and was so for 0.1 s), ``volume_change_max_pct``,
``valve_saturated_fraction``, ``analysis_window_s``, ``t_end_s``, ``dt_s``, ``method``, ``states``,
``rtol``, ``atol``, ``steps``, ``newton_iterations``, ``newton_per_step``, ``jacobians``, ``cut_steps``,
``simulation_wall_time_s``, ``real_time_factor`` (wall time of the run, after a warm-up of ten steps that loads
the compiled kernels). Pictures: ``trajectories.png`` (tip angles, tip paths in the bending plane, pressures and
set points vs time), ``hand.png`` (3D snapshot of the hand at the end, the fingers drawn through 16 pieces).
"""
from pathlib import Path

import numpy as np

from sorofem import materials, sdf
from sorofem.units import kPa, mm

NAMES = ("thumb", "index", "middle", "ring", "little")
LENGTHS = (80 * mm, 90 * mm, 90 * mm, 90 * mm, 90 * mm)
WIDTH, THICK, CORNER = 15 * mm, 12 * mm, 3 * mm
MODES = 5
#: the fingers' spatial discretization (Magnus pieces and order) and the integration: BDF2 in fixed steps of DT
#: [s]; Newton stops when its estimated remaining error is below NEWTON_TOL of rtol |x| + atol s. Chosen by the
#: space-time trade of the docstring ("Accuracy: space against time")
SEGMENTS, ORDER = 4, 4
DT, METHOD, RTOL, ATOL, NEWTON_TOL = 3.125e-3, "bdf2", 1e-1, 1e-6, 0.3
CH_AREA, CH_OFFSET = 6 * mm * 4 * mm, 2 * mm
P_AMP, OMEGA, PHASE, SHARPNESS = 80 * kPa, 7.0, np.pi / 6, 8.0
V0 = 4 * np.pi / 3 * (35 * mm) ** 3
ALPHA_PER_MM = 0.06          # alpha = 0.06 q1 with q1 in 1/mm (the seed's unit)
TAU_P, T_I, MAX_FLOW = 0.02, 1.0, 5e-3
DRIVE_TABLE_DT = 1e-4        # [s] the drive as a periodic table (interpolation error < 0.3 Pa)
R_AIR, T_AIR = 287.05, 293.15


#: The full run and the short one (`--quick`, what the tests run): simulated time [s], drive periods analysed
#: at its end (a quick run has ~1.1 periods: the last one).
FULL = dict(t_end=5.0, analysis_periods=2)
QUICK = dict(t_end=1.0, analysis_periods=1)


def main(out: Path, quick: bool = False) -> dict:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    mdl, fingers = build()
    prm = QUICK if quick else FULL
    t_end, dt, method, rtol, atol = prm["t_end"], DT, METHOD, RTOL, ATOL
    # a few steps first: a fresh process loads the compiled kernels (~0.5 s), which the real-time factor leaves out
    mdl.simulate(10 * dt, dt, method=method, rtol=rtol, atol=atol, newton_tol=NEWTON_TOL)
    tr = mdl.simulate(t_end, dt, method=method, rtol=rtol, atol=atol, newton_tol=NEWTON_TOL)
    st = tr.stats

    angles = [tip_angle(f, tr[n].q) for f, n in zip(fingers, NAMES)]
    period = 2 * np.pi / OMEGA
    # steady state needs a few decay times of the first mode (zeta omega ~ 2/s): analyse the last whole
    # period of a long run; a quick run has only ~1.1 periods, take the last period it has
    window = (max(0.0, t_end - prm["analysis_periods"] * period), t_end)
    sel = (tr.t >= window[0] - 1e-12)
    ph, amp_h = zip(*(first_harmonic_phase(tr.t[sel], a[sel], OMEGA) for a in angles))
    ph = np.unwrap(np.array(ph))
    pph = np.unwrap([first_harmonic_phase(tr.t[sel], tr[f"p_{n}"].pressure[sel], OMEGA)[0] for n in NAMES])
    last = tr.t >= t_end - period - 1e-12
    amp = [0.5 * (a[last].max() - a[last].min()) for a in angles]

    # pressure tracking on the plateaus: |p_d| above 79 kPa for at least the last 0.1 s
    pd = np.array([set_point(t) for t in tr.t])
    P = np.column_stack([tr[f"p_{n}"].pressure for n in NAMES])
    high = np.abs(pd) > 79 * kPa
    lag = int(round(0.1 / (tr.t[1] - tr.t[0])))
    settled = np.array([[k >= lag and high[k - lag:k + 1, i].all() for i in range(5)] for k in range(len(tr.t))])
    track = float(np.abs(P - pd)[settled].max()) if settled.any() else float("nan")
    # valve saturation: |kp e + ki s| >= max_flow
    kp = V0 / (R_AIR * T_AIR * TAU_P)
    sat = np.mean([np.abs(kp * (pd[:, i] - P[:, i]) + kp / T_I * tr[f"p_{n}"].x[:, -1]) >= MAX_FLOW
                   for i, n in enumerate(NAMES)])
    vol = max(float(np.max(np.abs(tr[f"p_{n}"].volume / V0 - 1))) for n in NAMES)
    EI = [f.E * f.section_properties.Iy for f in fingers]
    tips = [np.array([f.forward_kinematics(q)[-1, :3, 3] for q in tr[n].q[last]]) for f, n in zip(fingers, NAMES)]
    plots(out, fingers, tr, angles, window)

    return {
        "fingers": NAMES,
        "lengths_mm": [L / mm for L in LENGTHS],
        "modes": MODES,
        "states": mdl.n,
        "youngs_modulus_kPa": fingers[0].E / kPa,
        "damping_tau_s": [f.damping for f in fingers],
        "first_frequency_Hz": [float(f.natural_frequencies(1)[0]) for f in fingers],
        "static_angle_80kPa_deg": [float(np.degrees(P_AMP * CH_AREA * CH_OFFSET * L / ei))
                                   for L, ei in zip(LENGTHS, EI)],
        "bending_amplitude_deg": [float(np.degrees(a)) for a in amp],
        "first_harmonic_amplitude_deg": [float(np.degrees(a)) for a in amp_h],
        "tip_angle_max_deg": [float(np.degrees(a[last].max())) for a in angles],
        "tip_angle_min_deg": [float(np.degrees(a[last].min())) for a in angles],
        "tip_excursion_mm": [float(np.linalg.norm(p.max(0) - p.min(0)) / mm) for p in tips],
        "analysis_window_s": [float(w) for w in window],
        "phase_deg": [float(v) for v in np.degrees(ph)],
        "phase_step_deg": [float(v) for v in np.degrees(np.diff(ph))],
        "phase_step_fingers_deg": [float(v) for v in np.degrees(np.diff(ph[1:]))],
        "pressure_phase_step_deg": [float(v) for v in np.degrees(np.diff(pph))],
        "max_pressure_kPa": [float(v) for v in P.max(0) / kPa],
        "min_pressure_kPa": [float(v) for v in P.min(0) / kPa],
        "plateau_tracking_error_kPa": track / kPa,
        "volume_change_max_pct": 100 * vol,
        "valve_saturated_fraction": float(sat),
        "t_end_s": t_end,
        "dt_s": dt,
        "method": method,
        "rtol": rtol,
        "atol": atol,
        "newton_tol": NEWTON_TOL,
        "steps": int(st["steps"]),
        "newton_iterations": int(st["newton_iterations"]),
        "newton_per_step": st["newton_iterations"] / st["steps"],
        "jacobians": int(st["jacobians"]),
        "cut_steps": int(st["cut_steps"]),
        "simulation_wall_time_s": float(st["wall_time"]),
        "real_time_factor": float(t_end / st["wall_time"]),
    }


# ------------------------------------------------------------------------------------------------- the steps
def base_pose(i):
    """Base pose (4, 4) of finger i on the palm: body x along the finger, body z = -spatial z (so that a
    positive q1, the flexion the chamber produces, curls the finger toward the palm side, +z)."""
    flip = np.diag([1.0, -1.0, -1.0])
    g = np.eye(4)
    if i == 0:
        a = np.radians(50.0)
        Rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
        g[:3, :3], g[:3, 3] = Rz @ flip, (-45 * mm, 42 * mm, 0.0)
    else:
        g[:3, :3], g[:3, 3] = flip, (0.0, (27 - 18 * (i - 1)) * mm, 0.0)
    return g


def set_point(t):
    """Smoothed square waves p_d,i(t) [Pa], i = 0..4."""
    return P_AMP * np.tanh(SHARPNESS * np.sin(OMEGA * t + PHASE * np.arange(5))) / np.tanh(SHARPNESS)


def volume(q1):
    """Reservoir volume [m^3] from the finger's first coordinate q1 [1/m] (seed: alpha = 0.06 q1[1/mm])."""
    return V0 * (1.0 + np.tanh(ALPHA_PER_MM * 1e-3 * q1))


def build(segments=SEGMENTS, order=ORDER):
    """The hand: a :class:`soroshapes.Model` with fingers ``thumb``.. and reservoirs ``p_thumb``.., and the
    list of the five :class:`soroshapes.Shapes` (``segments`` Magnus pieces of ``order`` per finger)."""
    from soroshapes import Basis, Fluidic, Model, Shapes
    from soroshapes.network import Schedule, StateMap

    mat = materials.DragonSkin10()
    section = sdf.RoundedRectangle(WIDTH, THICK, CORNER)
    kp = V0 / (R_AIR * T_AIR * TAU_P)
    reg = dict(kp=kp, ki=kp / T_I, max_flow=MAX_FLOW)
    mdl, fingers = Model(), []
    for i, (name, L) in enumerate(zip(NAMES, LENGTHS)):
        shp = Shapes(Basis.chebyshev(MODES), dofs=(0, MODES, 0, 0, 0, 0), length=L, section=section,
                     material=mat, base=base_pose(i), segments=segments, order=order)
        # section axes (y, z) = body (y, z); the chamber behind the backbone (body +z) bends toward body -z,
        # i.e. q_y > 0 (the palm side after the base flip)
        shp.add_chamber(CH_AREA, (0.0, CH_OFFSET), name="chamber")
        fingers.append(shp)
        fl = Fluidic(None, V0=V0, T=T_AIR, gas_constant=R_AIR, regulator=reg)
        mdl.add(shp, name=name).add(fl, name=f"p_{name}")
        # volume(q1) as a declarative map of the finger's state: V0 + V0 tanh(alpha q1), compiled
        mdl.connect(StateMap(name, [ALPHA_PER_MM * 1e-3], index=0, offset=V0, scale=V0, function="tanh"),
                    f"p_{name}", port="volume")
        mdl.connect(f"p_{name}", name, "chamber")
    period = 2 * np.pi / OMEGA                 # set_point(t) over one period, linear between samples
    t = np.linspace(0.0, period, int(np.ceil(period / DRIVE_TABLE_DT)) + 1)
    pd = np.array([set_point(ti) for ti in t])
    mdl.set_controller(Schedule(t, {f"p_{n}": pd[:, i:i + 1] for i, n in enumerate(NAMES)}, period=period))
    return mdl, fingers


def tip_angle(shp, Q):
    """Flexion angle [rad] of the tip (rotation of the tip's body x about the body y axis) for rows of Q.
    Planar bending: theta(L) = int kappa_y dsigma = (int Theta dsigma) q exactly."""
    x, wg = np.polynomial.legendre.leggauss(2 * MODES + 8)          # exact for the polynomial modes
    col = 0.5 * shp.length * wg @ shp.theta(0.5 * shp.length * (x + 1))[:, 1, :]
    return Q @ col


def first_harmonic_phase(t, y, omega):
    """Phase [rad] of y's component at omega: y ~ a sin(omega t + phase) (least squares with an offset)."""
    A = np.column_stack([np.sin(omega * t), np.cos(omega * t), np.ones_like(t)])
    a, b, _ = np.linalg.lstsq(A, y, rcond=None)[0]
    return float(np.arctan2(b, a)), float(np.hypot(a, b))


def plots(out, fingers, tr, angles, window):
    from matplotlib import colormaps
    from matplotlib.figure import Figure
    from sorofem.io import save_figure

    from soroshapes.render import render_png

    colors = colormaps["viridis"](np.linspace(0, 0.9, 5))
    fig = Figure(figsize=(10, 10))
    ax = fig.subplots(3, 1, sharex=False)
    pd = np.array([set_point(t) for t in tr.t])
    for i, name in enumerate(NAMES):
        ax[0].plot(tr.t, np.degrees(angles[i]), color=colors[i], label=f"{name} (phi = {i}pi/6)")
        ax[2].plot(tr.t, tr[f"p_{name}"].pressure / kPa, color=colors[i], label=name)
        ax[2].plot(tr.t, pd[:, i] / kPa, ":", color=colors[i], lw=1)
        G = np.array([fingers[i].forward_kinematics(q)[-1, :3, 3] for q in tr[name].q])
        base = fingers[i].base
        local = (G - base[:3, 3]) @ base[:3, :3]          # tip in the finger's base frame
        ax[1].plot(local[:, 0] / mm, -local[:, 2] / mm, color=colors[i], label=name)
    ax[0].axvspan(*window, color="0.9", label="analysis window")
    ax[0].set_ylabel("tip flexion angle [deg]")
    ax[0].set_xlabel("time [s]")
    ax[0].legend(fontsize=8, ncol=3)
    ax[1].set_aspect("equal")
    ax[1].set_xlabel("along the finger [mm]")
    ax[1].set_ylabel("toward the palm side [mm]")
    ax[1].set_title("tip paths in each finger's bending plane")
    ax[1].legend(fontsize=8)
    ax[2].set_xlabel("time [s]")
    ax[2].set_ylabel("gauge pressure [kPa]")
    ax[2].set_title("reservoir pressures (solid) and oscillator set points (dotted)")
    for a in ax:
        a.grid(alpha=0.3)
    save_figure(fig, out / "trajectories.png", dpi=110)

    # drawn through the frames of 16 pieces (q are modal coordinates, the same for any pieces): the demo's 4 pieces
    # would show a curled finger as a polygon of 5 frames
    _, drawn = build(segments=16)
    beams = [{"frames": f.forward_kinematics(tr[n].q[-1]), "radius": 0.5 * THICK} for f, n in zip(drawn, NAMES)]
    render_png(out / "hand.png", beams, view=(30, -120), size=(7, 6), dpi=120,
               obstacles=[{"type": "plane", "point": (-45 * mm, 0.0, -0.5 * THICK), "normal": (0, 0, 1),
                           "size": 90 * mm, "color": "tan", "alpha": 0.4}],
               title=f"soft hand at t = {tr.t[-1]:.2f} s (palm below, fingers curl toward +z)")


if __name__ == "__main__":
    import json
    import sys

    print(json.dumps(main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/soft_hand"), quick="--quick" in sys.argv),
                     indent=2))


def scene(quick=False):
    """``soro play soft_hand``: the hand with one slider per finger, the set point [Pa] of its reservoir's
    regulator (the oscillators are replaced by the sliders)."""
    from soro.play import Channel, Scene

    # the page draws each finger through its node frames: 8 pieces (9 frames, 0.06 deg space error) look round
    # where the demo's 4 would show a curled finger as a polygon; play needs 1x real time, not the demo's 70x
    mdl, _ = build(segments=8)
    channels = [Channel(f"p_{n}.pressure_ref", 0.0, 100 * kPa, label=f"{n} pressure") for n in NAMES]
    return Scene(mdl, channels, dt=DT, method=METHOD, view=(-35.0, 35.0), title="soft_hand", focus="index")
