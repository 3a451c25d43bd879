"""Closed-form and semi-analytic references for the validation tests (derivations in the docstrings).

Every function takes SI inputs and returns SI outputs. They depend on numpy/scipy only.
"""
import numpy as np
from scipy.integrate import quad, solve_bvp

__all__ = ["cylinder_inflation_pressure", "sphere_inflation_pressure", "elastica_tip", "elastica_gravity_tip",
           "cantilever_frequencies", "EULER_BERNOULLI_BETA_L", "sphere_pressure_maximum", "buckled_strut",
           "clamped_elastica", "rotating_cantilever_frequency"]

#: Roots of cos(bL) cosh(bL) = -1: clamped-free Euler-Bernoulli beam, first three bending modes.
EULER_BERNOULLI_BETA_L = (1.8751040687, 4.6940911330, 7.8547574382)


def cylinder_inflation_pressure(mu, A, B, a):
    """Inner pressure [Pa] that inflates an incompressible Neo-Hookean thick cylinder (plane strain) from inner
    radius ``A`` to ``a`` (outer radius ``B``).

    Incompressibility in plane strain: :math:`r^2 - a^2 = R^2 - A^2`. Radial equilibrium
    :math:`d\\sigma_{rr}/dr + (\\sigma_{rr} - \\sigma_{\\theta\\theta})/r = 0` with :math:`\\sigma_{rr}(b) = 0`,
    :math:`\\sigma_{rr}(a) = -p` and :math:`\\sigma_{\\theta\\theta} - \\sigma_{rr} = \\mu(\\lambda^2 - \\lambda^{-2})`,
    :math:`\\lambda = r/R`, give :math:`p = \\int_a^b \\mu(\\lambda^2 - \\lambda^{-2})\\, dr / r`.
    """
    c = a * a - A * A
    if c == 0:
        return 0.0
    b = np.sqrt(B * B + c)

    def integrand(r):
        lam2 = r * r / (r * r - c)
        return mu * (lam2 - 1.0 / lam2) / r
    return quad(integrand, a, b, epsabs=0, epsrel=1e-12)[0]


def sphere_inflation_pressure(mu, A, B, a):
    """Inner pressure [Pa] inflating an incompressible Neo-Hookean thick sphere from inner radius ``A`` to ``a``.

    Incompressibility :math:`r^3 - a^3 = R^3 - A^3`; with :math:`\\lambda = r/R`,
    :math:`\\sigma_{\\theta\\theta} - \\sigma_{rr} = \\mu(\\lambda^2 - \\lambda^{-4})` and equilibrium
    :math:`d\\sigma_{rr}/dr + 2(\\sigma_{rr} - \\sigma_{\\theta\\theta})/r = 0`:
    :math:`p = \\int_a^b 2\\mu(\\lambda^2 - \\lambda^{-4})\\, dr / r`.
    """
    c = a**3 - A**3
    if c == 0:
        return 0.0
    b = np.cbrt(B**3 + c)

    def integrand(r):
        lam = r / np.cbrt(r**3 - c)
        return 2 * mu * (lam**2 - lam**-4) / r
    return quad(integrand, a, b, epsabs=0, epsrel=1e-12)[0]


def elastica_tip(L, EI, P, n=400):
    """Tip displacement (dx, dy) [m] of an inextensible clamped elastica of length ``L`` [m] and bending stiffness
    ``EI`` [N m^2] under a dead transverse tip force ``P`` [N] (along -y).

    With the slope :math:`\\theta(s)`, the moment :math:`EI\\,\\theta'(s) = -P\\,(x(L) - x(s))` gives
    :math:`EI\\,\\theta'' = P\\cos\\theta`,
    :math:`\\theta(0) = 0` (clamped), :math:`\\theta'(L) = 0` (free end); then :math:`x' = \\cos\\theta`,
    :math:`y' = \\sin\\theta`. Solved with scipy's collocation BVP solver (tolerance 1e-10) from the linear
    solution as initial guess; ``dx = x(L) - L`` and ``dy = y(L)``.
    """
    s = np.linspace(0.0, L, n)
    k = P / EI

    def rhs(s, y):  # y = [theta, theta', x, y]
        return np.vstack([y[1], k * np.cos(y[0]), np.cos(y[0]), np.sin(y[0])])

    def bc(ya, yb):
        return np.array([ya[0], yb[1], ya[2], ya[3]])

    guess = np.zeros((4, n))
    guess[0] = -k * (L * s - s * s / 2)
    guess[1] = -k * (L - s)
    guess[2] = s
    sol = solve_bvp(rhs, bc, s, guess, tol=1e-10, max_nodes=100000)
    if not sol.success:
        raise RuntimeError(f"elastica BVP did not converge: {sol.message}")
    return sol.y[2, -1] - L, sol.y[3, -1]


def elastica_gravity_tip(L, EI, w, n=400, tol=1e-10):
    """Tip displacement (dx, dy) [m] of an inextensible, unshearable clamped elastica of length ``L`` [m] and
    bending stiffness ``EI`` [N m^2] under a uniform distributed dead load ``w`` [N/m] (along -y), e.g. its own
    weight :math:`w = \\rho A g`.

    With the slope :math:`\\theta(s)` (counter-clockwise from +x, so negative as the rod droops), the moment of
    the load beyond :math:`s` is :math:`EI\\,\\theta'(s) = -w\\int_s^L (x(\\sigma) - x(s))\\,d\\sigma`;
    differentiating once, :math:`EI\\,\\theta'' = w\\,(L - s)\\cos\\theta`, with :math:`\\theta(0) = 0`
    (clamped) and :math:`\\theta'(L) = 0` (free end); then :math:`x' = \\cos\\theta`,
    :math:`y' = \\sin\\theta`. The small-load limit is Euler-Bernoulli's :math:`dy = -wL^4/(8EI)`,
    :math:`dx = -w^2L^7/(112\\,EI^2)`. Solved with scipy's collocation BVP solver (tolerance ``tol``) on
    ``n`` initial nodes, by continuation in the load from the linear solution (steps that keep the linear tip
    slope increment below 0.5 rad); ``dx = x(L) - L`` and ``dy = y(L)``.
    """
    s = np.linspace(0.0, L, n)
    w_total = float(w)
    steps = max(1, int(np.ceil(abs(w_total) * L**3 / (6 * EI) / 0.5)))
    k = w_total / steps / EI
    guess = np.zeros((4, n))  # y = [theta, theta', x, y]: the linear solution of the first load step
    guess[0] = -k * (L**3 - (L - s) ** 3) / 6
    guess[1] = -k * (L - s) ** 2 / 2
    guess[2] = s
    guess[3] = -k * (L**3 * s / 6 + ((L - s) ** 4 - L**4) / 24)

    def bc(ya, yb):
        return np.array([ya[0], yb[1], ya[2], ya[3]])

    sol = None
    for i in range(1, steps + 1):
        ki = w_total * i / steps / EI

        def rhs(s, y, ki=ki):
            return np.vstack([y[1], ki * (L - s) * np.cos(y[0]), np.cos(y[0]), np.sin(y[0])])

        mesh, y0 = (s, guess) if sol is None else (sol.x, sol.y)
        sol = solve_bvp(rhs, bc, mesh, y0, tol=tol, max_nodes=100000)
        if not sol.success:
            raise RuntimeError(f"gravity elastica BVP did not converge at load step {i}/{steps}: {sol.message}")
    return sol.y[2, -1] - L, sol.y[3, -1]


def cantilever_frequencies(L, E, I, rho, A, n=3):
    """First ``n`` (<= 3) bending frequencies [Hz] of a clamped-free Euler-Bernoulli beam:
    :math:`f_k = (\\beta_k L)^2 / (2\\pi L^2) \\sqrt{EI/(\\rho A)}`."""
    return [(bl**2) / (2 * np.pi * L**2) * np.sqrt(E * I / (rho * A)) for bl in EULER_BERNOULLI_BETA_L[:n]]


def sphere_pressure_maximum(mu, A, B):
    """(p_max [Pa], a at p_max [m]): the limit point of :func:`sphere_inflation_pressure` (bounded search of
    its maximum over A < a < 5 A; the curve has one maximum)."""
    from scipy.optimize import minimize_scalar

    res = minimize_scalar(lambda a: -sphere_inflation_pressure(mu, A, B, a), bounds=(1.001 * A, 5 * A),
                          method="bounded", options={"xatol": 1e-10 * A})
    return -res.fun, res.x


def buckled_strut(w_over_L):
    """Post-buckling of an inextensible Euler strut clamped at one end and guided at the other (the end slides
    sideways and along the axis without rotating): ``(P/P_cr, shortening/L)`` for the sideways offset ``w``
    of the guided end, ``w_over_L`` = w/L (array).

    The buckled strut is antisymmetric about its midpoint, an inflection point: each half is a clamped-free
    elastica of length :math:`\\ell = L/2` under the end load P. With :math:`k = \\sin(\\theta_0/2)`
    (:math:`\\theta_0` the slope at the inflection point), :math:`\\sqrt{P/EI}\\,\\ell = K(k)`, the half's
    sideways deflection :math:`2k\\ell/K(k)` and its axial length :math:`\\ell\\,(2E(k)/K(k) - 1)`, with the
    complete elliptic integrals K, E of modulus k (scipy's ``ellipk(m)``, ``ellipe(m)`` take
    :math:`m = k^2`). Hence, with :math:`P_{cr} = \\pi^2 EI/L^2`:

    .. math:: \\frac{w}{L} = \\frac{2k}{K(k)},\\quad \\frac{P}{P_{cr}} = \\frac{4K(k)^2}{\\pi^2},\\quad
              \\frac{\\Delta}{L} = 2 - \\frac{2E(k)}{K(k)} .

    ``k`` is found from ``w/L`` by root finding (w/L = 2k/K(k) grows monotonically from 0 to 0.76 at k = 0.95).
    """
    from scipy.optimize import brentq
    from scipy.special import ellipe, ellipk

    ratios, shortenings = [], []
    for wl in np.abs(np.atleast_1d(np.asarray(w_over_L, dtype=float))):
        if wl == 0:
            ratios.append(1.0)
            shortenings.append(0.0)
            continue
        m = brentq(lambda m: 2 * np.sqrt(m) / ellipk(m) - wl, 0.0, 0.9025, xtol=1e-15)
        ratios.append(4 * ellipk(m) ** 2 / np.pi**2)
        shortenings.append(2 - 2 * ellipe(m) / ellipk(m))
    return np.array(ratios), np.array(shortenings)


def clamped_elastica(k, L, s):
    """The first (symmetric) post-buckled shape of an inextensible strut of length ``L`` [m] clamped at both ends
    (both ends held on the x axis with their tangents along x, one moved towards the other): for the elliptic
    modulus ``k`` = sin(theta_0/2) (theta_0 the slope at the inflection points), returns ``(P/P_cr,
    shortening/L, x, y)`` with the positions x, y [m] at arc lengths ``s`` [m] and :math:`P_{cr} =
    4\\pi^2 EI/L^2`.

    Derivation. The clamped-clamped strut in its first mode has inflection points at L/4 and 3L/4 and zero
    transverse end forces (symmetry), so every quarter is the clamped-free elastica of length :math:`\\ell = L/4`
    under the end load P, the curve of :func:`buckled_strut` (whose halves have length L/2) with the half-wave
    period doubled: :math:`\\sqrt{P/EI}\\,\\ell = K(k)`, i.e. :math:`\\alpha L = 4K` with
    :math:`\\alpha = \\sqrt{P/EI}`, and :math:`P/P_{cr} = 4K^2/\\pi^2`. Measured from the clamp (where the
    curvature is largest and :math:`\\theta = 0`), :math:`EI\\theta'' + P\\sin\\theta = 0` is solved by
    :math:`\\sin(\\theta/2) = k\\,\\mathrm{sn}(\\alpha s, k)`; then :math:`\\cos(\\theta/2) = \\mathrm{dn}`, so
    :math:`x' = \\cos\\theta = 2\\,\\mathrm{dn}^2 - 1` and :math:`y' = \\sin\\theta = 2k\\,\\mathrm{sn}\\,\\mathrm{dn}`
    integrate to

    .. math:: x(s) = \\frac{2E(\\mathrm{am}(\\alpha s), k) - \\alpha s}{\\alpha}, \\qquad
              y(s) = \\frac{2k}{\\alpha}\\left(1 - \\mathrm{cn}(\\alpha s, k)\\right).

    At :math:`s = L` (:math:`\\alpha s = 4K`): :math:`y = 0`, :math:`\\theta = 0` and :math:`x = L(2E/K - 1)`,
    so the shortening is :math:`\\Delta/L = 2 - 2E(k)/K(k)` (as :func:`buckled_strut`); the midpoint
    deflection is :math:`y(L/2) = 4k/\\alpha = kL/K(k)`. Small k: :math:`y \\approx (kL/\\pi)(1 - \\cos 2\\pi s/L)`,
    the linear clamped-clamped mode.
    """
    from scipy.special import ellipe, ellipeinc, ellipj, ellipk

    m = k * k
    K, E = ellipk(m), ellipe(m)
    alpha = 4 * K / L
    u = alpha * np.asarray(s, dtype=float)
    sn, cn, dn, ph = ellipj(u, m)
    x = (2 * ellipeinc(ph, m) - u) / alpha
    y = 2 * k / alpha * (1 - cn)
    return 4 * K**2 / np.pi**2, 2 - 2 * E / K, x, y


def rotating_cantilever_frequency(L, EI, rhoA, spin):
    """First flapwise (out of the plane of rotation) natural frequency [rad/s] of a uniform Euler-Bernoulli
    cantilever of length ``L`` [m], bending stiffness ``EI`` [N m^2] and mass per length ``rhoA`` [kg/m], clamped
    on the axis of a hub spinning at ``spin`` [rad/s] (zero hub radius) and lying in the plane of rotation.

    In the rotating frame the centrifugal field :math:`\\rho A\\Omega^2 x` stretches the beam with the tension
    :math:`T(x) = \\rho A\\Omega^2 (L^2 - x^2)/2` and has no component along the flapwise deflection w (nor does
    the Coriolis force of a flapwise velocity), so the modes solve

    .. math:: EI\\,w'''' - (T w')' = \\rho A\\,\\omega^2 w, \\quad w(0) = w'(0) = 0,\\ w''(L) = w'''(L) = 0,

    solved as a boundary-value problem for :math:`\\omega^2` (scipy's ``solve_bvp``, tolerance 1e-10, the
    normalization :math:`w(L) = 1`, from the non-rotating mode). At small spin it follows Southwell's relation
    :math:`\\omega^2 = \\omega_0^2 + K_1\\Omega^2` with :math:`K_1 = 1.193` for the first mode of the uniform
    cantilever (e.g. Wright, Smith, Thresher & Wang, J. Appl. Mech. 49 (1982) 197-202; Bielawa, Rotary Wing
    Structural Dynamics and Aeroelasticity, 2006); at larger spin the curve bends below that line.
    """
    bl = EULER_BERNOULLI_BETA_L[0]
    s = np.linspace(0.0, 1.0, 200)
    om2 = spin**2 * rhoA * L**4 / EI                      # dimensionless: L = EI = rhoA = 1

    def rhs(x, y, p):
        T, dT = om2 * (1 - x * x) / 2, -om2 * x
        return np.vstack([y[1], y[2], y[3], dT * y[1] + T * y[2] + p[0] * y[0]])

    def bc(ya, yb, p):
        return np.array([ya[0], ya[1], yb[2], yb[3], yb[0] - 1.0])

    b = bl * s
    sig = (np.cosh(bl) + np.cos(bl)) / (np.sinh(bl) + np.sin(bl))
    shape = [np.cosh(b) - np.cos(b) - sig * (np.sinh(b) - np.sin(b)),
             bl * (np.sinh(b) + np.sin(b) - sig * (np.cosh(b) - np.cos(b))),
             bl**2 * (np.cosh(b) + np.cos(b) - sig * (np.sinh(b) + np.sin(b))),
             bl**3 * (np.sinh(b) - np.sin(b) - sig * (np.cosh(b) + np.cos(b)))]
    tip = shape[0][-1]
    sol = solve_bvp(rhs, bc, s, np.array(shape) / tip, p=[bl**4 + 1.193 * om2], tol=1e-10, max_nodes=100000)
    if not sol.success:
        raise RuntimeError(f"rotating cantilever eigenproblem did not converge: {sol.message}")
    return float(np.sqrt(sol.p[0] * EI / (rhoA * L**4)))
