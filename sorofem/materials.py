"""Material laws: hyperelastic strain energies (UFL and numpy) and presets for soft-robotics materials.

Every hyperelastic law here is written in the decoupled form

.. math::

    \\psi(F) = W(\\bar I_1, \\bar I_2) + U(J), \\qquad
    J = \\det F,\\; C = F^T F,\\; I_1 = \\operatorname{tr} C,\\; I_2 = \\tfrac12 (I_1^2 - \\operatorname{tr} C^2),\\;
    \\bar I_1 = J^{-2/3} I_1,\\; \\bar I_2 = J^{-4/3} I_2,

with the volumetric energy :math:`U(J) = \\tfrac{\\kappa}{4}(J^2 - 1 - 2\\ln J)` (convex, zero with zero slope
at :math:`J = 1`, infinite as :math:`J \\to 0`) and the bulk modulus :math:`\\kappa`. ``psi`` is energy per
unit reference volume [J/m^3 = Pa]. The isochoric parts:

=================  =========================================================================
``NeoHookean``     :math:`W = \\tfrac{\\mu}{2}(\\bar I_1 - 3)`
``MooneyRivlin``   :math:`W = c_{10}(\\bar I_1 - 3) + c_{01}(\\bar I_2 - 3)`,  :math:`\\mu = 2(c_{10}+c_{01})`
``Yeoh``           :math:`W = \\sum_{i=1}^{3} c_i(\\bar I_1 - 3)^i`,  :math:`\\mu = 2 c_1`
=================  =========================================================================

``NeoHookean(..., form="coupled")`` is the textbook compressible form with Lame's parameters,
:math:`\\psi = \\tfrac{\\mu}{2}(I_1 - 3) - \\mu \\ln J + \\tfrac{\\lambda}{2}(\\ln J)^2`
(:math:`\\lambda = \\kappa - 2\\mu/3`; the same small-strain constants as the decoupled form).

``LinearElastic`` (for rigid parts: PLA, frames) is :math:`\\psi = \\tfrac{\\lambda}{2}(\\operatorname{tr}\\varepsilon)^2
+ \\mu\\, \\varepsilon:\\varepsilon` with :math:`\\varepsilon = \\operatorname{sym}(F) - I`.

For the mixed displacement-pressure formulation every law splits as
:math:`\\psi = \\hat\\psi(F) + \\tfrac{k}{2} g(F)^2` (exactly, or with the volumetric law replaced at large
strain) and gives :meth:`Material.mixed_energy` :math:`\\hat\\psi(F) + p\\, g(F) - p^2/(2k)`, whose stationary
point in the pressure :math:`p` [Pa] is :math:`p = k\\, g(F)`:

=====================  ==========================================  ==================  ============
law                    :math:`\\hat\\psi`                          :math:`g`            :math:`k`
=====================  ==========================================  ==================  ============
decoupled laws         :math:`W(\\bar I_1, \\bar I_2)`               :math:`J - 1`        :math:`\\kappa`
coupled Neo-Hookean    :math:`\\tfrac{\\mu}{2}(I_1-3) - \\mu\\ln J`      :math:`\\ln J`        :math:`\\lambda`
``LinearElastic``      :math:`\\mu\\, \\mathrm{dev}\\,\\varepsilon : \\mathrm{dev}\\,\\varepsilon`  :math:`\\operatorname{tr}\\varepsilon`  :math:`K`
=====================  ==========================================  ==================  ============

(for the decoupled laws the mixed volumetric energy is :math:`\\kappa (J-1)^2/2`, equal to :math:`U(J)` to
second order at :math:`J = 1`).

The same formula serves two back ends: :meth:`Material.strain_energy` takes a UFL 3x3 deformation gradient
(the FEM embeds plane-strain gradients in 3x3), and :meth:`Material.energy`, :meth:`Material.pk1`,
:meth:`Material.cauchy` take numpy arrays of shape ``(..., 3, 3)`` (tests, post-processing).

Each material also carries its density [kg/m^3], a damping ratio [-] (modal, used for Rayleigh damping) and a
Coulomb friction coefficient [-], and gives the small-strain constants ``E``, ``G``, ``nu``, ``K`` used by beam
models.

Presets
-------
SI values. "Sorotoki" marks coefficients read from the Sorotoki toolkit's material library (converted from
MPa); each silicone preset was checked against the manufacturer's datasheet "100 % modulus" (engineering
stress at stretch 2 in uniaxial tension) and kept when within 20 %, else its :math:`c_1` was recalibrated
to that datasheet value (test ``test_presets_match_datasheet_100pct_modulus``). Where only a Shore A hardness
is known, the modulus comes from Gent's relation (A. N. Gent, Trans. Inst. Rubber Ind. 34, 46, 1958)
:math:`E = 0.0981(56 + 7.62336 S) / (0.137505 (254 - 2.54 S))` MPa.

=====================  ==============================================  ========  =======================
preset                 law and coefficients                            rho       source / check
=====================  ==============================================  ========  =======================
``Ecoflex0010``        Yeoh c=(16.24, -0.2, 0.023) kPa                 1070      c1 fitted to datasheet
                                                                                 100 % modulus 55 kPa
                                                                                 (Sorotoki's c1 = 3 kPa
                                                                                 gives 8.7 kPa)
``Ecoflex0030``        Yeoh c=(17, -0.2, 0.023) kPa                    1070      Sorotoki; datasheet
                                                                                 69 kPa, model 58 kPa
``Ecoflex0050``        Yeoh c=(23.6, 0.1, 0) kPa                       1070      c1 fitted to datasheet
                                                                                 83 kPa (Sorotoki's
                                                                                 14.5 kPa gives 52 kPa)
``DragonSkin10``       Yeoh c=(36, 0.25, 0.023) kPa                    1070      Sorotoki; datasheet
                                                                                 152 kPa, model 131 kPa
``DragonSkin30``       Yeoh c=(153.6, 1.6, 0) kPa                      1070      Sorotoki; datasheet
                                                                                 593 kPa, model 560 kPa
``Elastosil4601``      Yeoh c=(110, 20, 0) kPa                         1332      Sorotoki (Shore 28A)
``Elastic50A``         Yeoh c=(505.6, 0, 2.562) kPa                    1200      Sorotoki (Formlabs
                                                                                 Elastic 50A, Shore 50A)
``Elastic80A``         Neo-Hookean E = 9.35 MPa                        1200      Gent's relation at
                                                                                 Shore 80A (Formlabs
                                                                                 Flexible 80A); estimate
``NinjaFlex``          Neo-Hookean E = 12 MPa, nu = 0.45               1190      datasheet tensile modulus
                                                                                 (Shore 85A TPU)
``TPU90A``             Neo-Hookean E = 20.8 MPa, nu = 0.45             1200      Gent's relation at 90A
``PLA``                linear E = 3.5 GPa, nu = 0.35                   1240      Sorotoki E, nu; typical
                                                                                 PLA density
=====================  ==============================================  ========  =======================

Silicone presets default to a Poisson ratio of 0.49 at small strain (bulk modulus :math:`\\kappa \\approx 50\\mu`);
pass ``nu=0.4999`` (with the FEM's mixed formulation) to approach incompressibility. Damping ratios are
Sorotoki's (0.03 Ecoflex 00-10/00-30, 0.035 Ecoflex 00-50, 0.1 Dragon Skin and TPU, 0.2 Elastosil); friction
defaults to 0.5, a placeholder to set for your surfaces.
"""
import math

import numpy as np

from .errors import ParameterError

__all__ = [
    "Material", "Hyperelastic", "NeoHookean", "MooneyRivlin", "Yeoh", "LinearElastic",
    "bulk_from_poisson", "gent_modulus",
    "Ecoflex0010", "Ecoflex0030", "Ecoflex0050", "DragonSkin10", "DragonSkin30", "Elastosil4601",
    "Elastic50A", "Elastic80A", "NinjaFlex", "TPU90A", "PLA", "PRESETS",
]


def _positive(name, value):
    value = float(value)
    if not math.isfinite(value) or value <= 0:
        raise ParameterError(f"{name} must be a positive finite number, got {value}")
    return value


def _nonnegative(name, value):
    value = float(value)
    if not math.isfinite(value) or value < 0:
        raise ParameterError(f"{name} must be a non-negative finite number, got {value}")
    return value


def _poisson(nu):
    nu = float(nu)
    if not -1.0 < nu < 0.5:
        raise ParameterError(f"Poisson ratio nu={nu} is outside (-1, 0.5); for an incompressible material use "
                             "nu=0.4999 with the mixed displacement-pressure formulation")
    return nu


def bulk_from_poisson(mu, nu):
    """Bulk modulus [Pa] from the shear modulus ``mu`` [Pa] and small-strain Poisson ratio ``nu``:
    :math:`\\kappa = 2\\mu(1+\\nu) / (3(1-2\\nu))`."""
    return 2.0 * _positive("mu", mu) * (1.0 + _poisson(nu)) / (3.0 * (1.0 - 2.0 * nu))


def gent_modulus(shore_a):
    """Young's modulus [Pa] from a Shore A hardness by Gent's relation (1958); valid roughly for 20A-90A,
    with a scatter of tens of percent: use it only where no measured curve is known."""
    s = float(shore_a)
    if not 0 < s < 100:
        raise ParameterError(f"Shore A hardness must be in (0, 100), got {s}")
    return 0.0981 * (56.0 + 7.62336 * s) / (0.137505 * (254.0 - 2.54 * s)) * 1e6


class Material:
    """Base of every material: density [kg/m^3], damping ratio [-], friction coefficient [-], a name.

    Materials are immutable descriptions; use :meth:`with_` to make a modified copy.
    """

    def __init__(self, *, density=1000.0, damping=0.0, friction=0.5, name=None):
        self.density = _positive("density", density)
        self.damping = _nonnegative("damping", damping)
        self.friction = _nonnegative("friction", friction)
        self.name = name or type(self).__name__

    # --- to implement --------------------------------------------------------------------------------
    def strain_energy(self, F):
        """Strain energy density [Pa] as a UFL expression of a 3x3 UFL deformation gradient ``F``."""
        raise NotImplementedError

    def energy(self, F):
        """Strain energy density [Pa] for numpy deformation gradients of shape ``(..., 3, 3)``."""
        raise NotImplementedError

    def pk1(self, F):
        """First Piola-Kirchhoff stress :math:`P = \\partial\\psi/\\partial F` [Pa], shape ``(..., 3, 3)``."""
        raise NotImplementedError

    @property
    def G(self):
        """Small-strain shear modulus [Pa]."""
        raise NotImplementedError

    @property
    def K(self):
        """Small-strain bulk modulus [Pa]."""
        raise NotImplementedError

    def _mixed_parts(self, F):
        """``(psi_hat, g, k)`` of the split :math:`\\psi = \\hat\\psi + k g^2/2` (see the module doc), UFL."""
        raise NotImplementedError

    # --- derived -------------------------------------------------------------------------------------
    def mixed_energy(self, F, p):
        """Energy density [Pa] of the mixed formulation, :math:`\\hat\\psi(F) + p\\, g(F) - p^2/(2k)`, as a UFL
        expression of a 3x3 UFL ``F`` and the pressure field ``p`` [Pa] (see the module doc)."""
        psi_hat, g, k = self._mixed_parts(F)
        return psi_hat + p * g - p**2 / (2.0 * k)

    @property
    def E(self):
        """Small-strain Young's modulus [Pa]: :math:`E = 9KG/(3K+G)`."""
        return 9.0 * self.K * self.G / (3.0 * self.K + self.G)

    @property
    def nu(self):
        """Small-strain Poisson ratio [-]: :math:`\\nu = (3K-2G)/(2(3K+G))`."""
        return (3.0 * self.K - 2.0 * self.G) / (2.0 * (3.0 * self.K + self.G))

    def cauchy(self, F):
        """Cauchy stress :math:`\\sigma = J^{-1} P F^T` [Pa] for numpy ``F`` of shape ``(..., 3, 3)``."""
        F = _as_gradient(F)
        return self.pk1(F) @ np.swapaxes(F, -1, -2) / np.linalg.det(F)[..., None, None]

    def with_(self, **changes):
        """A copy with some constructor arguments changed, e.g. ``Ecoflex0030().with_(nu=0.4999)``."""
        args = self._args()
        if "nu" in changes:  # the Poisson ratio replaces the stored bulk modulus
            args.pop("kappa", None)
        if "E" in changes:  # Young's modulus replaces the stored shear modulus
            args.pop("mu", None)
        if "lmbda" in changes:  # Lame's first parameter replaces the stored bulk modulus
            args.pop("kappa", None)
        return type(self)(**{**args, **changes})

    def _args(self):
        return dict(density=self.density, damping=self.damping, friction=self.friction, name=self.name)

    def __repr__(self):
        body = ", ".join(f"{k}={v!r}" for k, v in self._args().items())
        return f"{type(self).__name__}({body})"


def _as_gradient(F):
    F = np.asarray(F, dtype=float)
    if F.shape[-2:] != (3, 3):
        raise ParameterError(f"deformation gradients must have shape (..., 3, 3), got {F.shape}; embed a 2D "
                             "plane-strain gradient as [[F11, F12, 0], [F21, F22, 0], [0, 0, 1]]")
    J = np.linalg.det(F)
    if np.any(~np.isfinite(J)) or np.any(J <= 0):
        raise ParameterError(f"det F must be positive (no inverted material), got min det F = {np.min(J):.3g}")
    return F


class Hyperelastic(Material):
    """Decoupled isotropic hyperelastic law :math:`\\psi = W(\\bar I_1, \\bar I_2) + U(J)` (see module doc).

    Subclasses give the isochoric energy :meth:`_w` and its derivatives :meth:`_dw`
    (:math:`\\partial W/\\partial \\bar I_1`, :math:`\\partial W/\\partial \\bar I_2`), and the initial shear
    modulus ``mu``. The bulk modulus is ``kappa`` [Pa] or follows from ``nu`` (default 0.49).
    """

    def __init__(self, *, kappa=None, nu=None, **kw):
        super().__init__(**kw)
        if kappa is not None and nu is not None:
            raise ParameterError("give either kappa (bulk modulus) or nu (Poisson ratio), not both")
        self._nu_arg = nu
        self.kappa = _positive("kappa", kappa) if kappa is not None else bulk_from_poisson(self.mu, 0.49 if nu is None else nu)

    # isochoric part, written with arithmetic only so that it works for UFL and numpy alike
    def _w(self, I1b, I2b):
        raise NotImplementedError

    def _dw(self, I1b, I2b):
        raise NotImplementedError

    @property
    def mu(self):
        raise NotImplementedError

    @property
    def G(self):
        return self.mu

    @property
    def K(self):
        return self.kappa

    def volumetric_energy(self, J, log=np.log):
        """:math:`U(J) = \\tfrac{\\kappa}{4}(J^2 - 1 - 2\\ln J)` [Pa]; pass ``log=ufl.ln`` for UFL."""
        return 0.25 * self.kappa * (J**2 - 1.0 - 2.0 * log(J))

    def isochoric_energy(self, F):
        """:math:`W(\\bar I_1, \\bar I_2)` [Pa] as a UFL expression of a 3x3 UFL ``F`` (mixed formulations)."""
        import ufl
        J = ufl.det(F)
        C = F.T * F
        I1 = ufl.tr(C)
        I2 = 0.5 * (I1**2 - ufl.tr(C * C))
        return self._w(J ** (-2.0 / 3.0) * I1, J ** (-4.0 / 3.0) * I2)

    def strain_energy(self, F):
        import ufl
        return self.isochoric_energy(F) + self.volumetric_energy(ufl.det(F), log=ufl.ln)

    def _mixed_parts(self, F):
        import ufl
        return self.isochoric_energy(F), ufl.det(F) - 1.0, self.kappa

    @staticmethod
    def _invariants(F):
        J = np.linalg.det(F)
        C = np.swapaxes(F, -1, -2) @ F
        I1 = np.trace(C, axis1=-2, axis2=-1)
        I2 = 0.5 * (I1**2 - np.einsum("...ij,...ji->...", C, C))
        return J, C, I1, I2

    def energy(self, F):
        F = _as_gradient(F)
        J, _, I1, I2 = self._invariants(F)
        return self._w(J ** (-2 / 3) * I1, J ** (-4 / 3) * I2) + self.volumetric_energy(J)

    def pk1(self, F):
        """:math:`P = W_1 \\partial\\bar I_1/\\partial F + W_2 \\partial\\bar I_2/\\partial F + U'(J) J F^{-T}` with
        :math:`\\partial\\bar I_1/\\partial F = J^{-2/3}(2F - \\tfrac23 I_1 F^{-T})`,
        :math:`\\partial\\bar I_2/\\partial F = J^{-4/3}(2(I_1 F - F C) - \\tfrac43 I_2 F^{-T})` and
        :math:`U'(J) = \\tfrac{\\kappa}{2}(J - 1/J)`."""
        F = _as_gradient(F)
        J, C, I1, I2 = self._invariants(F)
        FinvT = np.swapaxes(np.linalg.inv(F), -1, -2)
        Ja = J[..., None, None]
        I1a, I2a = I1[..., None, None], I2[..., None, None]
        W1, W2 = self._dw(J ** (-2 / 3) * I1, J ** (-4 / 3) * I2)
        W1, W2 = np.broadcast_to(W1, J.shape)[..., None, None], np.broadcast_to(W2, J.shape)[..., None, None]
        dI1b = Ja ** (-2 / 3) * (2 * F - (2 / 3) * I1a * FinvT)
        dI2b = Ja ** (-4 / 3) * (2 * (I1a * F - F @ C) - (4 / 3) * I2a * FinvT)
        dU = 0.5 * self.kappa * (Ja - 1 / Ja)
        return W1 * dI1b + W2 * dI2b + dU * Ja * FinvT

    def _args(self):
        return {**super()._args(), "kappa": self.kappa}


class NeoHookean(Hyperelastic):
    """Neo-Hookean solid in the decoupled form :math:`\\psi = \\tfrac{\\mu}{2}(\\bar I_1 - 3) + U(J)` (default) or
    the coupled form with Lame's parameters,
    :math:`\\psi = \\tfrac{\\mu}{2}(I_1 - 3) - \\mu \\ln J + \\tfrac{\\lambda}{2}(\\ln J)^2`.

    Parameters
    ----------
    mu : float, optional
        Shear modulus [Pa]. Alternatively give ``E`` [Pa] (with ``nu``, default 0.49, or ``kappa`` or ``lmbda``).
    kappa, nu, lmbda : float, optional
        One of: bulk modulus [Pa], small-strain Poisson ratio [-] (default 0.49), Lame's first parameter [Pa]
        (:math:`\\lambda = \\kappa - 2\\mu/3`). Both forms have the same small-strain constants.
    form : {"decoupled", "coupled"}
        Which energy (see above); they differ at finite volume change only.
    density, damping, friction, name : see :class:`Material`.

    Examples
    --------
    >>> from sorofem.units import kPa
    >>> m = NeoHookean(E=19 * kPa, nu=0.45)
    >>> round(m.E / kPa, 6), round(m.nu, 6)
    (19.0, 0.45)
    >>> c = NeoHookean(mu=1.0, lmbda=2.0, form="coupled")
    >>> round(c.K, 6), round(c.lmbda, 6)
    (2.666667, 2.0)
    """

    FORMS = ("decoupled", "coupled")

    def __init__(self, mu=None, *, E=None, lmbda=None, form="decoupled", **kw):
        if form not in self.FORMS:
            raise ParameterError(f"form must be one of {self.FORMS}, got {form!r}")
        self.form = form
        if (mu is None) == (E is None):
            raise ParameterError("give exactly one of mu (shear modulus) or E (Young's modulus), in Pa")
        if lmbda is not None:
            given = [k for k in ("kappa", "nu") if kw.get(k) is not None]
            if given:
                raise ParameterError(f"give one of lmbda, kappa or nu for the volumetric stiffness, not lmbda and "
                                     f"{given[0]}")
            lmbda = float(lmbda)
            if not math.isfinite(lmbda):
                raise ParameterError(f"lmbda must be finite [Pa], got {lmbda}")
        if mu is not None:
            self._mu = _positive("mu", mu)
        elif lmbda is not None:  # E = mu (3 lmbda + 2 mu) / (lmbda + mu): the positive root in mu
            E = _positive("E", E)
            self._mu = ((E - 3 * lmbda) + math.sqrt((E - 3 * lmbda) ** 2 + 8 * E * lmbda)) / 4
            if not (math.isfinite(self._mu) and self._mu > 0):
                raise ParameterError(f"E={E} Pa and lmbda={lmbda} Pa give no positive shear modulus")
        elif kw.get("kappa") is not None:  # mu from E and the bulk modulus: E = 9 K mu / (3 K + mu)
            E, kappa = _positive("E", E), _positive("kappa", kw["kappa"])
            if E >= 9 * kappa:
                raise ParameterError(f"E={E} Pa needs a bulk modulus kappa > E/9, got kappa={kappa} Pa")
            self._mu = 3 * kappa * E / (9 * kappa - E)
        else:
            nu = kw.get("nu")
            self._mu = _positive("E", E) / (2 * (1 + _poisson(0.49 if nu is None else nu)))
        if lmbda is not None:
            kappa = lmbda + 2.0 * self._mu / 3.0
            if kappa <= 0:
                raise ParameterError(f"lmbda={lmbda} Pa needs lmbda > -2 mu / 3 = {-2 * self._mu / 3:.6g} Pa (a "
                                     "positive bulk modulus)")
            kw["kappa"] = kappa
        super().__init__(**kw)

    @property
    def mu(self):
        return self._mu

    @property
    def lmbda(self):
        """Lame's first parameter [Pa], :math:`\\lambda = \\kappa - 2\\mu/3`."""
        return self.kappa - 2.0 * self._mu / 3.0

    def _w(self, I1b, I2b):
        return 0.5 * self._mu * (I1b - 3.0)

    def _dw(self, I1b, I2b):
        return 0.5 * self._mu, 0.0

    # the coupled form: psi = mu/2 (I1 - 3) - mu ln J + lmbda/2 (ln J)^2
    def strain_energy(self, F):
        if self.form == "decoupled":
            return super().strain_energy(F)
        import ufl
        lnJ = ufl.ln(ufl.det(F))
        return 0.5 * self._mu * (ufl.tr(F.T * F) - 3.0) - self._mu * lnJ + 0.5 * self.lmbda * lnJ**2

    def _mixed_parts(self, F):
        if self.form == "decoupled":
            return super()._mixed_parts(F)
        import ufl
        lnJ = ufl.ln(ufl.det(F))
        return 0.5 * self._mu * (ufl.tr(F.T * F) - 3.0) - self._mu * lnJ, lnJ, self.lmbda

    def energy(self, F):
        if self.form == "decoupled":
            return super().energy(F)
        F = _as_gradient(F)
        J, _, I1, _ = self._invariants(F)
        lnJ = np.log(J)
        return 0.5 * self._mu * (I1 - 3.0) - self._mu * lnJ + 0.5 * self.lmbda * lnJ**2

    def pk1(self, F):
        """Decoupled: see :meth:`Hyperelastic.pk1`. Coupled:
        :math:`P = \\mu (F - F^{-T}) + \\lambda \\ln J\\, F^{-T}`."""
        if self.form == "decoupled":
            return super().pk1(F)
        F = _as_gradient(F)
        FinvT = np.swapaxes(np.linalg.inv(F), -1, -2)
        lnJ = np.log(np.linalg.det(F))[..., None, None]
        return self._mu * (F - FinvT) + self.lmbda * lnJ * FinvT

    def _args(self):
        return {"mu": self._mu, **super()._args(), "form": self.form}


class MooneyRivlin(Hyperelastic):
    """Mooney-Rivlin solid, :math:`W = c_{10}(\\bar I_1 - 3) + c_{01}(\\bar I_2 - 3)`, :math:`\\mu = 2(c_{10}+c_{01})`.

    ``c10``, ``c01`` in Pa; stable at small strain when :math:`c_{10} + c_{01} > 0`.
    """

    def __init__(self, c10, c01, **kw):
        self.c10, self.c01 = float(c10), float(c01)
        if not (math.isfinite(self.c10) and math.isfinite(self.c01)) or self.c10 + self.c01 <= 0:
            raise ParameterError(f"Mooney-Rivlin needs c10 + c01 > 0 (shear modulus 2(c10+c01)), got c10={c10}, "
                                 f"c01={c01}")
        super().__init__(**kw)

    @property
    def mu(self):
        return 2.0 * (self.c10 + self.c01)

    def _w(self, I1b, I2b):
        return self.c10 * (I1b - 3.0) + self.c01 * (I2b - 3.0)

    def _dw(self, I1b, I2b):
        return self.c10, self.c01

    def _args(self):
        return {"c10": self.c10, "c01": self.c01, **super()._args()}


class Yeoh(Hyperelastic):
    """Yeoh solid, :math:`W = c_1(\\bar I_1-3) + c_2(\\bar I_1-3)^2 + c_3(\\bar I_1-3)^3`, :math:`\\mu = 2c_1`.

    ``c1 > 0``, ``c2``, ``c3`` in Pa.
    """

    def __init__(self, c1, c2=0.0, c3=0.0, **kw):
        self.c1 = _positive("c1", c1)
        self.c2, self.c3 = float(c2), float(c3)
        if not (math.isfinite(self.c2) and math.isfinite(self.c3)):
            raise ParameterError(f"Yeoh coefficients must be finite, got c2={c2}, c3={c3}")
        super().__init__(**kw)

    @property
    def mu(self):
        return 2.0 * self.c1

    def _w(self, I1b, I2b):
        x = I1b - 3.0
        return self.c1 * x + self.c2 * x**2 + self.c3 * x**3

    def _dw(self, I1b, I2b):
        x = I1b - 3.0
        return self.c1 + 2.0 * self.c2 * x + 3.0 * self.c3 * x**2, 0.0

    def _args(self):
        return {"c1": self.c1, "c2": self.c2, "c3": self.c3, **super()._args()}


class LinearElastic(Material):
    """Small-strain isotropic elasticity for stiff parts (PLA frames, rigid inserts).

    :math:`\\psi = \\tfrac{\\lambda}{2}(\\operatorname{tr}\\varepsilon)^2 + \\mu\\,\\varepsilon:\\varepsilon`,
    :math:`\\varepsilon = \\operatorname{sym}(F) - I`, :math:`P = \\lambda \\operatorname{tr}(\\varepsilon) I + 2\\mu\\varepsilon`.
    Not objective: use only where rotations stay small.

    Parameters
    ----------
    E : float
        Young's modulus [Pa].
    nu : float
        Poisson ratio [-], in (-1, 0.5).
    """

    def __init__(self, E, nu=0.3, **kw):
        super().__init__(**kw)
        self._E, self._nu = _positive("E", E), _poisson(nu)
        self.lmbda = self._E * self._nu / ((1 + self._nu) * (1 - 2 * self._nu))
        self.mu = self._E / (2 * (1 + self._nu))

    @property
    def G(self):
        return self.mu

    @property
    def K(self):
        return self.lmbda + 2.0 * self.mu / 3.0

    def strain_energy(self, F):
        import ufl
        eps = ufl.sym(F) - ufl.Identity(3)
        return 0.5 * self.lmbda * ufl.tr(eps) ** 2 + self.mu * ufl.inner(eps, eps)

    def _mixed_parts(self, F):
        import ufl
        eps = ufl.sym(F) - ufl.Identity(3)
        dev = eps - ufl.tr(eps) / 3.0 * ufl.Identity(3)
        return self.mu * ufl.inner(dev, dev), ufl.tr(eps), self.K

    def _eps(self, F):
        F = np.asarray(F, dtype=float)
        if F.shape[-2:] != (3, 3):
            raise ParameterError(f"deformation gradients must have shape (..., 3, 3), got {F.shape}")
        return 0.5 * (F + np.swapaxes(F, -1, -2)) - np.eye(3)

    def energy(self, F):
        eps = self._eps(F)
        tr = np.trace(eps, axis1=-2, axis2=-1)
        return 0.5 * self.lmbda * tr**2 + self.mu * np.einsum("...ij,...ij->...", eps, eps)

    def pk1(self, F):
        eps = self._eps(F)
        tr = np.trace(eps, axis1=-2, axis2=-1)[..., None, None]
        return self.lmbda * tr * np.eye(3) + 2.0 * self.mu * eps

    def cauchy(self, F):
        """Small-strain stress (equal to :meth:`pk1`; the reference and current configurations coincide)."""
        return self.pk1(F)

    def _args(self):
        return {"E": self._E, "nu": self._nu, **super()._args()}


# --- presets ----------------------------------------------------------------------------------------------
kPa = 1e3


def Ecoflex0010(**kw):
    """Smooth-On Ecoflex 00-10 (Yeoh; c1 fitted to the datasheet 100 % modulus of 55 kPa)."""
    return Yeoh(**{"c1": 16.24 * kPa, "c2": -0.2 * kPa, "c3": 0.023 * kPa, "density": 1070.0, "damping": 0.03,
                   "name": "Ecoflex 00-10", **kw})


def Ecoflex0030(**kw):
    """Smooth-On Ecoflex 00-30 (Yeoh, Sorotoki's coefficients; datasheet 100 % modulus 69 kPa)."""
    return Yeoh(**{"c1": 17.0 * kPa, "c2": -0.2 * kPa, "c3": 0.023 * kPa, "density": 1070.0, "damping": 0.03,
                   "name": "Ecoflex 00-30", **kw})


def Ecoflex0050(**kw):
    """Smooth-On Ecoflex 00-50 (Yeoh; c1 fitted to the datasheet 100 % modulus of 83 kPa)."""
    return Yeoh(**{"c1": 23.6 * kPa, "c2": 0.1 * kPa, "c3": 0.0, "density": 1070.0, "damping": 0.035,
                   "name": "Ecoflex 00-50", **kw})


def DragonSkin10(**kw):
    """Smooth-On Dragon Skin 10 (Yeoh, Sorotoki's coefficients; datasheet 100 % modulus 152 kPa)."""
    return Yeoh(**{"c1": 36.0 * kPa, "c2": 0.25 * kPa, "c3": 0.023 * kPa, "density": 1070.0, "damping": 0.1,
                   "name": "Dragon Skin 10", **kw})


def DragonSkin30(**kw):
    """Smooth-On Dragon Skin 30 (Yeoh, Sorotoki's coefficients; datasheet 100 % modulus 593 kPa)."""
    return Yeoh(**{"c1": 153.6 * kPa, "c2": 1.6 * kPa, "c3": 0.0, "density": 1070.0, "damping": 0.1,
                   "name": "Dragon Skin 30", **kw})


def Elastosil4601(**kw):
    """Wacker Elastosil M4601 (Yeoh, Sorotoki's coefficients; Shore 28A)."""
    return Yeoh(**{"c1": 110.0 * kPa, "c2": 20.0 * kPa, "c3": 0.0, "density": 1332.0, "damping": 0.2,
                   "name": "Elastosil M4601", **kw})


def Elastic50A(**kw):
    """Formlabs Elastic 50A resin (Yeoh, Sorotoki's coefficients; Shore 50A)."""
    return Yeoh(**{"c1": 505.6 * kPa, "c2": 0.0, "c3": 2.562 * kPa, "density": 1200.0, "damping": 0.03,
                   "name": "Elastic 50A", **kw})


def Elastic80A(**kw):
    """Formlabs Flexible/Elastic 80A resin: Neo-Hookean with E from Gent's relation at Shore 80A (an estimate)."""
    return NeoHookean(**{"E": gent_modulus(80), "density": 1200.0, "damping": 0.03, "name": "Elastic 80A", **kw})


def NinjaFlex(**kw):
    """NinjaFlex TPU (Shore 85A): Neo-Hookean with the datasheet tensile modulus 12 MPa, nu = 0.45."""
    return NeoHookean(**{"E": 12e6, "nu": 0.45, "density": 1190.0, "damping": 0.1, "name": "NinjaFlex", **kw})


def TPU90A(**kw):
    """Generic TPU, Shore 90A: Neo-Hookean with E from Gent's relation (20.8 MPa), nu = 0.45."""
    return NeoHookean(**{"E": gent_modulus(90), "nu": 0.45, "density": 1200.0, "damping": 0.1, "name": "TPU 90A",
                         **kw})


def PLA(**kw):
    """PLA (printed rigid parts): linear elastic E = 3.5 GPa, nu = 0.35, density 1240 kg/m^3."""
    return LinearElastic(**{"E": 3.5e9, "nu": 0.35, "density": 1240.0, "damping": 0.02, "name": "PLA", **kw})


#: Preset constructors by name.
PRESETS = {f.__name__: f for f in (Ecoflex0010, Ecoflex0030, Ecoflex0050, DragonSkin10, DragonSkin30,
                                   Elastosil4601, Elastic50A, Elastic80A, NinjaFlex, TPU90A, PLA)}
