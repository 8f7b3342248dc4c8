"""Contact and friction laws (SI units): small pure functions and, for the choice
of law, equinox Modules (an abstract base and final subclasses).

Every normal law here has the form (model.md, "Normal contact force")

    F_n = K(delta) delta^n (1 + chi delta_dot / delta_dot_minus)   for delta > 0, else 0,

and differs only in its stiffness K(delta) and hysteresis factor chi(c_e)
([`AbstractContactLaw`][jaxcrank.physics.laws.AbstractContactLaw]). Friction is the modified Coulomb law with a choice
of
ramp ([`AbstractFrictionLaw`][jaxcrank.physics.laws.AbstractFrictionLaw]). Names (`CONTACT_LAWS`,
`FRICTION_LAWS`) are used only where text comes in: TOML files and the CLI.
Powers, square roots and kinks go through [`jaxcrank.physics.safemath`][] so values and
gradients stay finite everywhere, including delta <= 0 and zero slip.
"""

from __future__ import annotations

import abc
import math
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import scipy.optimize

from .safemath import positive_power, smoothstep

# --------------------------------------------------------------------------- stiffness


def effective_compliance(compliance_1, compliance_2):
    """s1 + s2 with s_k = (1 - nu_k^2) / E_k, 1/Pa. E* = 1 / (s1 + s2)."""
    return compliance_1 + compliance_2


def hertz_stiffness(hole_radius, pin_radius, compliance_sum):
    """Lankarani-Nikravesh / Hertz stiffness, paper Eq. 3, N/m^1.5.

    ``K = 4 / (3 (s1 + s2)) * sqrt(R_h R_p / (R_h - R_p))`` (the paper's pi in
    numerator and denominator cancel). Steel, 8/7.5 mm: 5.25e10 N/m^1.5.
    """
    return 4.0 / (3.0 * compliance_sum) * jnp.sqrt(hole_radius * pin_radius / (hole_radius - pin_radius))


def hybrid_elastic_force(penetration, clearance, compliance_sum):
    """Elastic part K_n(delta) delta^1.5 of the paper's hybrid law (Eq. 6-7), N.

    ``K_n = (pi/8) E* sqrt(2 delta (3c + 2 delta)^2 / (c + delta)^3)`` (Bai & Zhao
    2012, empirical: used as written, with K_n in Pa and delta in m). Multiplied
    out so no square root of delta remains:
    ``K_n delta^1.5 = (pi/8) E* sqrt(2) (3c + 2 delta) delta^2 / (c + delta)^1.5``.
    Only valid for the Hertz exponent n = 1.5.
    """
    d = jnp.maximum(penetration, 0.0)
    e_star = 1.0 / compliance_sum
    return (math.pi / 8.0) * e_star * math.sqrt(2.0) * (3.0 * clearance + 2.0 * d) * d**2 / (clearance + d) ** 1.5


# --------------------------------------------------------------------------- normal laws


class AbstractContactLaw(eqx.Module):
    """A normal contact law ``F_n = K(delta) delta^n (1 + chi delta_dot / delta_dot_minus)``
    (model.md, "Normal contact force"). Subclasses give the elastic part
    ``K(delta) delta^n`` with its stored energy, and the hysteresis factor chi(c_e).
    A law has no parameters of its own (the restitution, exponent and geometry are
    arguments), so choosing one changes the compiled program, never a leaf to trace.

    ``name`` is the law's name in TOML files and on the command line.
    """

    name: ClassVar[str]

    @abc.abstractmethod
    def hysteresis_factor(self, restitution):
        """chi(c_e), dimensionless, for a restitution coefficient c_e in (0, 1]."""

    @abc.abstractmethod
    def elastic_force(self, penetration, *, hole_radius, pin_radius, compliance_sum, exponent=1.5):
        """Elastic (non-dissipative) normal force K(delta) delta^n for delta > 0, else 0, N.

        Args: penetration delta, m; hole and pin radii, m; compliance_sum
        s1 + s2 = sum of (1 - nu^2) / E, 1/Pa; exponent n, dimensionless."""

    @abc.abstractmethod
    def elastic_energy(self, penetration, *, hole_radius, pin_radius, compliance_sum, exponent=1.5):
        """Energy stored in the contact, the integral of
        [`elastic_force`][jaxcrank.physics.laws.AbstractContactLaw.elastic_force] over [0, delta], J."""

    def normal_force(
        self,
        penetration,
        penetration_rate,
        approach_speed,
        restitution,
        *,
        hole_radius,
        pin_radius,
        compliance_sum,
        exponent=1.5,
    ):
        """Normal contact force magnitude F_n >= 0 and its elastic part, N.

        ``F_n = K(delta) delta^n (1 + chi delta_dot / delta_dot_minus)`` for delta > 0.

        Args:
            penetration: delta, m (negative when separated).
            penetration_rate: delta_dot, m/s (positive approaching).
            approach_speed: delta_dot_minus, the normal speed at the onset of the
                impact, m/s, > 0.
            restitution: c_e in (0, 1].
            hole_radius: radius of the hole, m.
            pin_radius: radius of the pin, m (smaller than the hole's).
            compliance_sum: 1/Pa.
            exponent: n.

        Returns:
            ``(F_n, F_elastic)``; F_n is clipped at zero (contacts push, never pull).
        """
        f_el = self.elastic_force(
            penetration,
            hole_radius=hole_radius,
            pin_radius=pin_radius,
            compliance_sum=compliance_sum,
            exponent=exponent,
        )
        chi = self.hysteresis_factor(restitution)
        f = f_el * (1.0 + chi * penetration_rate / approach_speed)
        return jnp.maximum(f, 0.0), f_el


class AbstractHertzLaw(AbstractContactLaw):
    """A law with the constant Hertz stiffness K of [`hertz_stiffness`][jaxcrank.physics.laws.hertz_stiffness]:
    ``K delta^n`` with stored energy ``K delta^(n+1) / (n+1)``."""

    def elastic_force(self, penetration, *, hole_radius, pin_radius, compliance_sum, exponent=1.5):
        k = hertz_stiffness(hole_radius, pin_radius, compliance_sum)
        return k * positive_power(penetration, exponent)

    def elastic_energy(self, penetration, *, hole_radius, pin_radius, compliance_sum, exponent=1.5):
        k = hertz_stiffness(hole_radius, pin_radius, compliance_sum)
        return k * positive_power(penetration, exponent + 1.0) / (exponent + 1.0)


class LankaraniNikravesh(AbstractHertzLaw):
    """Lankarani & Nikravesh (1990), paper Eq. 2-4: chi = 3 (1 - c_e^2) / 4."""

    name: ClassVar[str] = "lankarani_nikravesh"

    def hysteresis_factor(self, restitution):
        return 0.75 * (1.0 - restitution**2)


def _corrected_chi(restitution):
    """chi = 3 (1 - c_e^2) exp(2 (1 - c_e)) / 4 (paper Eq. 5, after Vogel 1996)."""
    return 0.75 * (1.0 - restitution**2) * jnp.exp(2.0 * (1.0 - restitution))


class CorrectedDamping(AbstractHertzLaw):
    """Hertz stiffness with the corrected damping of paper Eq. 5:
    chi = 3 (1 - c_e^2) exp(2 (1 - c_e)) / 4."""

    name: ClassVar[str] = "corrected_damping"

    def hysteresis_factor(self, restitution):
        return _corrected_chi(restitution)


class HuntCrossley(AbstractHertzLaw):
    """Hunt & Crossley (1975): chi = 3 (1 - c_e) / 2."""

    name: ClassVar[str] = "hunt_crossley"

    def hysteresis_factor(self, restitution):
        return 1.5 * (1.0 - restitution)


class Flores(AbstractHertzLaw):
    """Flores et al. (2011): chi = 8 (1 - c_e) / (5 c_e)."""

    name: ClassVar[str] = "flores"

    def hysteresis_factor(self, restitution):
        return 8.0 * (1.0 - restitution) / (5.0 * restitution)


class Gonthier(AbstractHertzLaw):
    """Gonthier et al. (2004): chi = (1 - c_e^2) / c_e."""

    name: ClassVar[str] = "gonthier"

    def hysteresis_factor(self, restitution):
        return (1.0 - restitution**2) / restitution


class Hybrid(AbstractContactLaw):
    """The paper's hybrid law (Eq. 6-8, after Bai & Zhao 2012): the stiffness of
    [`hybrid_elastic_force`][jaxcrank.physics.laws.hybrid_elastic_force] with the Eq. 5 damping,
    chi = 3 (1 - c_e^2) exp(2 (1 - c_e)) / 4. Only for the Hertz exponent n = 1.5
    (the ``exponent`` argument is ignored)."""

    name: ClassVar[str] = "hybrid"

    def hysteresis_factor(self, restitution):
        return _corrected_chi(restitution)

    def elastic_force(self, penetration, *, hole_radius, pin_radius, compliance_sum, exponent=1.5):
        force = hybrid_elastic_force(penetration, hole_radius - pin_radius, compliance_sum)
        return jnp.where(penetration > 0.0, force, 0.0)

    def elastic_energy(self, penetration, *, hole_radius, pin_radius, compliance_sum, exponent=1.5):
        # 8-point Gauss-Legendre: the integrand is smooth (delta^2 times a rational function)
        nodes, weights = np.polynomial.legendre.leggauss(8)
        d = jnp.maximum(penetration, 0.0)
        x = 0.5 * d * (jnp.asarray(nodes) + 1.0)
        f = hybrid_elastic_force(x, hole_radius - pin_radius, compliance_sum)
        return 0.5 * d * jnp.sum(jnp.asarray(weights) * f)


#: contact laws by their TOML/CLI name
CONTACT_LAWS: dict[str, type[AbstractContactLaw]] = {
    law.name: law for law in (Hybrid, LankaraniNikravesh, CorrectedDamping, HuntCrossley, Flores, Gonthier)
}


# --------------------------------------------------------------------------- friction


class AbstractFrictionLaw(eqx.Module):
    """Modified Coulomb friction (Ambrosio 2002, paper Eq. 9),
    ``F_t = -mu c_d(|v_t|) F_n sign(v_t)``; subclasses give the dynamic-friction
    factor c_d of the normalised slip ``x = (|v_t| - v0) / (v1 - v0)``.
    ``name`` is the law's name in TOML files and on the command line."""

    name: ClassVar[str]

    @abc.abstractmethod
    def ramp(self, x):
        """c_d in [0, 1] as a function of the normalised slip x (0 at x <= 0, 1 at x >= 1)."""

    def factor(self, slip_speed, stick_speed, full_slip_speed):
        """c_d(|v_t|) for slip speed v_t, stick speed v0 and full-slip speed v1 (m/s)."""
        return self.ramp((jnp.abs(slip_speed) - stick_speed) / (full_slip_speed - stick_speed))

    def force(self, slip_speed, normal_force, coefficient, stick_speed, full_slip_speed):
        """Tangential force on the pin along the tangent t, ``-mu c_d(v_t) F_n sign(v_t)``, N.

        Args: slip speed v_t, m/s; normal force F_n, N; coefficient mu; stick and
        full-slip speeds v0 < v1, m/s. c_d vanishes near zero slip, so ``sign`` is
        never differentiated."""
        c_d = self.factor(slip_speed, stick_speed, full_slip_speed)
        return -coefficient * c_d * normal_force * jnp.sign(slip_speed)


class Ambrosio(AbstractFrictionLaw):
    """Ambrosio's reference ramp: linear from 0 at v0 to 1 at v1 (kinks at both ends)."""

    name: ClassVar[str] = "ambrosio"

    def ramp(self, x):
        return jnp.clip(x, 0.0, 1.0)


class SmoothRamp(AbstractFrictionLaw):
    """The same ramp as a C2 quintic [`smoothstep`][jaxcrank.physics.laws.smoothstep] (for differentiable solves)."""

    name: ClassVar[str] = "smooth"

    def ramp(self, x):
        return smoothstep(x)


#: friction laws by their TOML/CLI name
FRICTION_LAWS: dict[str, type[AbstractFrictionLaw]] = {law.name: law for law in (SmoothRamp, Ambrosio)}


# --------------------------------------------------------------------------- restitution


def achieved_restitution(chi: float) -> float:
    """Restitution e that a law with hysteresis factor chi actually gives in a
    single impact: the root of ``chi (1 + e) = ln((1 + chi) / (1 - chi e))``
    (model.md). Independent of the stiffness K(delta) and of the approach speed.
    For chi -> 0, e -> 1 - 2 chi / 3 ... ; e < 1/chi always.
    """
    chi = float(chi)
    if chi <= 0.0:
        return 1.0

    def residual(e):
        return chi * (1.0 + e) - math.log((1.0 + chi) / (1.0 - chi * e))

    upper = min(1.0, 1.0 / chi) * (1.0 - 1e-15)
    return scipy.optimize.brentq(residual, 0.0, upper, xtol=1e-15, rtol=1e-14, maxiter=500)
