"""Contact and friction laws as small pure functions (SI units).

Every normal law here has the form (model.md, "Normal contact force")

    F_n = K(delta) delta^n (1 + chi delta_dot / delta_dot_minus)   for delta > 0, else 0,

and differs only in its stiffness K(delta) and hysteresis factor chi(c_e).
Powers, square roots and kinks are wrapped in double ``where`` so values and
gradients stay finite everywhere, including delta <= 0 and zero slip.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import scipy.optimize

from .params import CONTACT_LAWS

# --------------------------------------------------------------------------- safe math


def safe_norm(v, axis=-1):
    """Euclidean norm with a zero (not NaN) gradient at v = 0."""
    sq = jnp.sum(v * v, axis=axis)
    positive = sq > 0.0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, sq, 1.0)), 0.0)


def smoothstep(x):
    """C2 quintic step 10x^3 - 15x^4 + 6x^5 of x clipped to [0, 1]: 0 at x <= 0, 1 at x >= 1."""
    x = jnp.clip(x, 0.0, 1.0)
    return x**3 * (10.0 - 15.0 * x + 6.0 * x**2)


def positive_power(x, p):
    """x**p for x > 0, else 0; finite gradient everywhere (p >= 1)."""
    positive = x > 0.0
    return jnp.where(positive, jnp.where(positive, x, 1.0) ** p, 0.0)


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


# --------------------------------------------------------------------------- hysteresis


def hysteresis_factor(law: str, restitution):
    """chi(c_e) of each law, dimensionless.

    - ``lankarani_nikravesh`` (paper Eq. 4): 3 (1 - c_e^2) / 4
    - ``corrected_damping`` and ``hybrid`` (paper Eq. 5 and 8, after Vogel 1996):
      3 (1 - c_e^2) exp(2 (1 - c_e)) / 4
    - ``hunt_crossley`` (Hunt & Crossley 1975): 3 (1 - c_e) / 2
    - ``flores`` (Flores et al. 2011): 8 (1 - c_e) / (5 c_e)
    - ``gonthier`` (Gonthier et al. 2004): (1 - c_e^2) / c_e
    """
    ce = restitution
    if law == "lankarani_nikravesh":
        return 0.75 * (1.0 - ce**2)
    if law in ("corrected_damping", "hybrid"):
        return 0.75 * (1.0 - ce**2) * jnp.exp(2.0 * (1.0 - ce))
    if law == "hunt_crossley":
        return 1.5 * (1.0 - ce)
    if law == "flores":
        return 8.0 * (1.0 - ce) / (5.0 * ce)
    if law == "gonthier":
        return (1.0 - ce**2) / ce
    raise ValueError(f"unknown contact law {law!r}; valid names: {', '.join(CONTACT_LAWS)}")


# --------------------------------------------------------------------------- normal force


def elastic_force(law: str, penetration, *, hole_radius, pin_radius, compliance_sum, exponent=1.5):
    """Elastic (non-dissipative) normal force K(delta) delta^n for delta > 0, else 0, N."""
    if law == "hybrid":
        return jnp.where(penetration > 0.0, hybrid_elastic_force(penetration, hole_radius - pin_radius, compliance_sum), 0.0)
    k = hertz_stiffness(hole_radius, pin_radius, compliance_sum)
    return k * positive_power(penetration, exponent)


def elastic_energy(law: str, penetration, *, hole_radius, pin_radius, compliance_sum, exponent=1.5):
    """Elastic energy stored in the contact, integral of ``elastic_force`` over
    [0, delta], J. Closed form for constant K; 8-point Gauss-Legendre for the
    hybrid law (its integrand is smooth: delta^2 times a rational function)."""
    if law == "hybrid":
        nodes, weights = np.polynomial.legendre.leggauss(8)
        d = jnp.maximum(penetration, 0.0)
        x = 0.5 * d * (jnp.asarray(nodes) + 1.0)
        f = hybrid_elastic_force(x, hole_radius - pin_radius, compliance_sum)
        return 0.5 * d * jnp.sum(jnp.asarray(weights) * f)
    k = hertz_stiffness(hole_radius, pin_radius, compliance_sum)
    return k * positive_power(penetration, exponent + 1.0) / (exponent + 1.0)


def normal_force(law: str, penetration, penetration_rate, approach_speed, restitution, *,
                 hole_radius, pin_radius, compliance_sum, exponent=1.5):
    """Normal contact force magnitude F_n >= 0, N.

    ``F_n = K(delta) delta^n (1 + chi delta_dot / delta_dot_minus)`` for delta > 0.
    ``approach_speed`` is delta_dot_minus (m/s, > 0), the normal speed at the onset
    of the impact; ``penetration_rate`` is delta_dot (m/s, positive approaching).
    The force is clipped at zero: contacts push, never pull.

    Returns ``(F_n, F_elastic)``.
    """
    f_el = elastic_force(law, penetration, hole_radius=hole_radius, pin_radius=pin_radius,
                         compliance_sum=compliance_sum, exponent=exponent)
    chi = hysteresis_factor(law, restitution)
    f = f_el * (1.0 + chi * penetration_rate / approach_speed)
    return jnp.maximum(f, 0.0), f_el


# --------------------------------------------------------------------------- friction


def friction_ramp(law: str, slip_speed, stick_speed, full_slip_speed):
    """Dynamic-friction factor c_d(|v_t|) in [0, 1] of the modified Coulomb law.

    ``ambrosio``: 0 up to v0, linear to 1 at v1, 1 above (Ambrosio 2002).
    ``smooth``: the same with a C2 quintic ramp 10x^3 - 15x^4 + 6x^5.
    """
    x = (jnp.abs(slip_speed) - stick_speed) / (full_slip_speed - stick_speed)
    if law == "ambrosio":
        return jnp.clip(x, 0.0, 1.0)
    if law == "smooth":
        return smoothstep(x)
    raise ValueError(f"unknown friction law {law!r}")


def friction_force(law: str, slip_speed, normal_force_, coefficient, stick_speed, full_slip_speed):
    """Tangential force on the pin along the tangent t, ``-mu c_d(v_t) F_n sign(v_t)``, N
    (paper Eq. 9). c_d vanishes near zero slip, so ``sign`` is never differentiated."""
    return -coefficient * friction_ramp(law, slip_speed, stick_speed, full_slip_speed) * normal_force_ * jnp.sign(slip_speed)


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
