"""Mechanism parameters as pytrees, their validation, and the paper preset.

Every number a user may sweep or differentiate is a pytree leaf (``jax.grad``,
``jax.vmap`` and optax act on a [`Mechanism`][jaxcrank.physics.params.Mechanism] directly). Only choices that
change the structure of the model are static: the contact and friction laws
(leafless equinox Modules, [`jaxcrank.physics.laws`][]), and whether a joint is
ideal (which changes the number of degrees of freedom).

All values are SI: metres, kilograms, seconds, radians, newtons, pascals.

Validation runs in ``__check_init__`` on concrete values, so a bad mechanism is
rejected with a sentence naming the parameter and its valid range before any
solve. Values that are JAX tracers (inside ``jit``/``grad``/``vmap``) are not
checked there; they were checked when the concrete mechanism was built.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import numpy as np

from .laws import CONTACT_LAWS, FRICTION_LAWS, AbstractContactLaw, AbstractFrictionLaw, Hybrid, SmoothRamp


class ParameterError(ValueError):
    """A parameter is outside its valid range; the message names it and the range."""


def _concrete(value):
    """Return ``value`` as a numpy array, or ``None`` when it is a JAX tracer."""
    if isinstance(value, jax.core.Tracer):
        return None
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError(f"expected a number, got {value!r}") from None


def _check(name: str, value, *, low=None, high=None, low_open=True, high_open=True, unit=""):
    """Raise [`ParameterError`][jaxcrank.physics.params.ParameterError] unless every element of ``value`` is in
    range."""
    arr = _concrete(value)
    if arr is None:
        return
    ok = np.isfinite(arr)
    if low is not None:
        ok &= (arr > low) if low_open else (arr >= low)
    if high is not None:
        ok &= (arr < high) if high_open else (arr <= high)
    if not np.all(ok):
        lo = "-inf" if low is None else f"{low:g}"
        hi = "inf" if high is None else f"{high:g}"
        interval = f"{'(' if low_open or low is None else '['}{lo}, {hi}{')' if high_open or high is None else ']'}"
        bad = arr[~ok].ravel()[0] if arr.ndim else arr
        raise ParameterError(f"{name} = {bad:g}{' ' + unit if unit else ''} is outside its valid range {interval}")


class Material(eqx.Module):
    """Elastic properties of one body's contact surface.

    Attributes:
        youngs_modulus: Young's modulus E, Pa. Default: steel, 207 GPa.
        poisson_ratio: Poisson's ratio nu, dimensionless, in (0, 0.5). Default 0.3.
    """

    youngs_modulus: float = 207e9
    poisson_ratio: float = 0.3

    def __check_init__(self):
        _check("youngs_modulus", self.youngs_modulus, low=0.0, unit="Pa")
        _check("poisson_ratio", self.poisson_ratio, low=0.0, high=0.5)

    @property
    def compliance(self):
        """(1 - nu^2) / E, 1/Pa."""
        return (1.0 - self.poisson_ratio**2) / self.youngs_modulus


class Joint(eqx.Module):
    """A revolute joint: a pin (journal) of radius ``pin_radius`` in a hole (bearing)
    of radius ``hole_radius``.

    Attributes:
        hole_radius: bearing radius R_h, m.
        pin_radius: journal radius R_p, m; must be smaller than ``hole_radius``.
        ideal: static flag; ``True`` models a perfect revolute joint (zero clearance,
            no contact law, two fewer degrees of freedom). The radii are still used
            for the contact-point geometry of the driving moment.

    The radial clearance is ``c = hole_radius - pin_radius`` (paper Eq. 1).
    """

    hole_radius: float
    pin_radius: float
    ideal: bool = eqx.field(static=True, default=False)

    def __check_init__(self):
        _check("hole_radius", self.hole_radius, low=0.0, unit="m")
        _check("pin_radius", self.pin_radius, low=0.0, unit="m")
        hole, pin = _concrete(self.hole_radius), _concrete(self.pin_radius)
        if hole is not None and pin is not None and not self.ideal and np.any(pin >= hole):
            raise ParameterError(
                f"pin_radius = {np.max(pin):g} m must be smaller than hole_radius = "
                f"{np.min(hole):g} m (valid range: 0 < pin_radius < hole_radius); "
                "for a joint without clearance set ideal = true"
            )

    @property
    def clearance(self):
        """Radial clearance c = R_h - R_p, m."""
        return self.hole_radius - self.pin_radius


class Contact(eqx.Module):
    """Normal contact law settings (model.md, "Normal contact force").

    Attributes:
        law: the normal law, a [`jaxcrank.physics.laws.AbstractContactLaw`][]
            (TOML/CLI names in ``laws.CONTACT_LAWS``). The default
            [`Hybrid`][jaxcrank.physics.laws.Hybrid] is the paper's Eq. 6-8 (Bai & Zhao 2012
            stiffness with Eq. 5 damping).
        restitution: coefficient of restitution c_e in (0, 1] that sets the
            hysteresis damping factor chi of the law. The restitution a law
            actually achieves follows chi (see ``laws.achieved_restitution``).
        exponent: Hertz exponent n of delta^n, dimensionless (1.5 for these laws).
        min_approach_speed: floor on the impact approach speed delta_dot_minus,
            m/s. Guards the damping term chi * delta_dot / delta_dot_minus against
            grazing contacts (division by ~0). Impacts slower than this are damped
            as if they arrived at this speed.
        memory_time: relaxation time of the approach-speed memory state, s,
            away from the walls. While a joint is separated the memory follows
            the normal speed's time derivative exactly and relaxes onto the
            normal speed (which erases the offset left by the last rebound);
            during contact it is frozen, so it holds the speed at the onset of
            the impact (``model.memory_relaxation``). Shorter values make the
            problem stiffer everywhere; the fast reset near the walls is
            ``reset_time``.
        freeze_time: time to contact, s, at the current normal speed, over
            which the memory's exact tracking is blended off before an onset
            (and on again after a separation) rather than switched (keeps
            reverse-mode gradients exact through impact onsets). The blend
            weight is moment-matched, so the memory misses the onset speed by
            only O((a t_f / v)^3) for a normal acceleration a
            (``model.memory_tracking``). The contact force is zero there.
        reset_window: time to or from the wall, s, at the current normal speed,
            within which the memory relaxes with ``reset_time`` (fading out by
            twice it); a separation is always followed by such a window, so a
            re-impact microseconds later finds the memory reset.
        reset_time: relaxation time of the memory inside ``reset_window``, s
            (exp(-27) of the last impact's offset left with the defaults).
            The solver resolves this decay: about 25 steps per separation.
    """

    law: AbstractContactLaw = Hybrid()
    restitution: float = 0.9
    exponent: float = 1.5
    min_approach_speed: float = 1e-3
    memory_time: float = 1e-5
    freeze_time: float = 1e-7
    reset_window: float = 1e-6
    reset_time: float = 5e-8

    def __check_init__(self):
        if not isinstance(self.law, AbstractContactLaw):
            raise ParameterError(
                f"contact law {self.law!r} is not a jaxcrank.physics.laws.AbstractContactLaw; pass e.g. "
                f"laws.Flores() (TOML and --set take the names: {', '.join(CONTACT_LAWS)})"
            )
        _check("restitution", self.restitution, low=0.0, high=1.0, high_open=False)
        _check("exponent", self.exponent, low=1.0, high=3.0, low_open=False, high_open=False)
        _check("min_approach_speed", self.min_approach_speed, low=0.0, unit="m/s")
        _check("memory_time", self.memory_time, low=0.0, unit="s")
        _check("freeze_time", self.freeze_time, low=0.0, unit="s")
        _check("reset_window", self.reset_window, low=0.0, unit="s")
        _check("reset_time", self.reset_time, low=0.0, unit="s")


class Friction(eqx.Module):
    """Modified Coulomb friction (Ambrosio 2002, paper Eq. 9).

    ``F_t = -mu c_d(v_t) F_n sign(v_t)`` with ``c_d = 0`` for ``|v_t| <= v0``,
    rising to 1 at ``v1``. The ramp width ``v1 - v0`` is the smoothing width.

    Attributes:
        law: the ramp, a [`jaxcrank.physics.laws.AbstractFrictionLaw`][]:
            [`SmoothRamp`][jaxcrank.physics.laws.SmoothRamp] (``"smooth"``, C2 quintic ramp between
            v0 and v1, the default for differentiable solves) or
            [`Ambrosio`][jaxcrank.physics.laws.Ambrosio] (``"ambrosio"``, the reference linear
            ramp, with kinks at v0 and v1).
        coefficient: dynamic friction coefficient mu, dimensionless, >= 0
            (0 disables friction).
        stick_speed: v0, slip speed below which no friction acts, m/s, >= 0.
            Default 1e-4 m/s (Ambrosio's typical value).
        slip_speed: v1, slip speed from which full friction acts, m/s, > v0.
            Default 1e-2 m/s, wider than Ambrosio's typical 2e-4 m/s: with the
            paper's rod inertia (J2 = 2.2e-4 kg m^2) and impact forces of ~10 kN
            at pin C, a 1e-4 m/s ramp makes pin sticking stiff to ~1e10 1/s
            (measured: the explicit solve stalls at dt ~ 2e-10 s); 1e-2 m/s is
            still below typical slip speeds (0.1-0.5 m/s). See docs/numerics.md, "Friction
            ramp width".
    """

    law: AbstractFrictionLaw = SmoothRamp()
    coefficient: float = 0.1
    stick_speed: float = 1e-4
    slip_speed: float = 1e-2

    def __check_init__(self):
        if not isinstance(self.law, AbstractFrictionLaw):
            raise ParameterError(
                f"friction law {self.law!r} is not a jaxcrank.physics.laws.AbstractFrictionLaw; pass e.g. "
                f"laws.Ambrosio() (TOML and --set take the names: {', '.join(FRICTION_LAWS)})"
            )
        _check("friction coefficient", self.coefficient, low=0.0, low_open=False)
        _check("stick_speed", self.stick_speed, low=0.0, low_open=False, unit="m/s")
        _check("slip_speed", self.slip_speed, low=0.0, unit="m/s")  # NaN and inf fail the comparison below
        v0, v1 = _concrete(self.stick_speed), _concrete(self.slip_speed)
        if v0 is not None and v1 is not None and np.any(v1 <= v0):
            raise ParameterError(
                f"slip_speed = {np.min(v1):g} m/s must be greater than stick_speed = "
                f"{np.max(v0):g} m/s (valid range: slip_speed > stick_speed >= 0)"
            )


class Mechanism(eqx.Module):
    """Offset slider-crank with clearance joints at B (crank pin in rod big end)
    and C (slider pin in rod small end). model.md describes every field.

    Attributes:
        crank_length: L1, m.
        rod_length: L2, m; must exceed ``crank_length + |offset|``.
        offset: eccentricity e of the slider line y = e, m.
        crank_mass: m1, kg.
        rod_mass: m2, kg.
        slider_mass: m3, kg.
        crank_inertia: J1 about each centre
            of mass, kg m^2 (J1 and J3 do not enter the dynamics at constant
            crank speed; kept for the record and for extensions).
        rod_inertia: J2 about each centre
            of mass, kg m^2 (J1 and J3 do not enter the dynamics at constant
            crank speed; kept for the record and for extensions).
        slider_inertia: J3 about each centre
            of mass, kg m^2 (J1 and J3 do not enter the dynamics at constant
            crank speed; kept for the record and for extensions).
        crank_speed: omega, rad/s (600 rpm = 62.83 rad/s), constant.
        initial_crank_angle: theta1 at t = 0, rad.
        gravity: g along -y, m/s^2.
        joint_B: the two clearance joints (the same for joint_C).
        joint_C: the two clearance joints (the same for joint_B).
        crank_material: contact surface materials (the same for rod_material, slider_material).
        rod_material: contact surface materials (the same for crank_material, slider_material).
        slider_material: contact surface materials (the same for crank_material, rod_material).
        contact: normal contact law settings.
        friction: friction law settings.
    """

    crank_length: float = 0.150
    rod_length: float = 0.403
    offset: float = 0.050
    crank_mass: float = 0.6967
    rod_mass: float = 1.5473
    slider_mass: float = 1.7964
    crank_inertia: float = 1.931e-3
    rod_inertia: float = 2.233e-4
    slider_inertia: float = 3.431e-4
    crank_speed: float = 2.0 * math.pi * 600.0 / 60.0
    initial_crank_angle: float = 0.0
    gravity: float = 9.81
    joint_B: Joint = Joint(hole_radius=8e-3, pin_radius=7.5e-3)
    joint_C: Joint = Joint(hole_radius=8e-3, pin_radius=7.5e-3)
    crank_material: Material = Material()
    rod_material: Material = Material()
    slider_material: Material = Material()
    contact: Contact = Contact()
    friction: Friction = Friction()

    def __check_init__(self):
        for name in ("crank_length", "rod_length"):
            _check(name, getattr(self, name), low=0.0, unit="m")
        _check("offset", self.offset, unit="m")
        for name in ("crank_mass", "rod_mass", "slider_mass"):
            _check(name, getattr(self, name), low=0.0, unit="kg")
        for name in ("crank_inertia", "rod_inertia", "slider_inertia"):
            _check(name, getattr(self, name), low=0.0, unit="kg m^2")
        _check("crank_speed", self.crank_speed, low=0.0, unit="rad/s")
        _check("initial_crank_angle", self.initial_crank_angle, unit="rad")
        _check("gravity", self.gravity, low=0.0, low_open=False, unit="m/s^2")
        l1, l2, e = (_concrete(x) for x in (self.crank_length, self.rod_length, self.offset))
        if l1 is not None and l2 is not None and e is not None:
            margin = l2 - l1 - np.abs(e)
            if np.any(margin <= 0.0):
                i = np.unravel_index(np.argmin(margin), np.shape(margin)) if np.ndim(margin) else ()
                l1_, l2_, e_ = (np.broadcast_to(x, np.shape(margin))[i] for x in (l1, l2, e))
                raise ParameterError(
                    f"geometry is not assemblable for a full crank rotation: rod_length = {l2_:g} m "
                    f"must exceed crank_length + |offset| = {l1_:g} + {abs(e_):g} = "
                    f"{l1_ + abs(e_):g} m (valid range: rod_length > crank_length + |offset|)"
                )

    @property
    def period(self):
        """Time of one crank revolution, s."""
        return 2.0 * math.pi / self.crank_speed


def paper() -> Mechanism:
    """The paper's Table 1 mechanism as read in model.md.

    Assumptions (each a field the user can change):

    - offset e = L4 - L3 = 50 mm: the paper gives L3 = 450 and L4 = 500 mm but no e.
    - inertias: the table's "kg.mm^2" values read as kg m^2 (kg mm^2 would be
      physically impossible). J2 = 2.233e-4 kg m^2 is about 100x below a uniform
      0.403 m rod (0.021 kg m^2); the table value is kept.
    - materials: steel on steel, E = 207 GPa, nu = 0.3 (not given in the paper).
    - restitution c_e = 0.9, friction mu = 0.1 (dry steel), friction ramp
      v0 = 1e-4 m/s to v1 = 1e-2 m/s (not given in the paper; see ``Friction``).
    - crank speed 600 rpm, starting at theta1 = 0, pins centred in their holes and
      moving with the ideal mechanism's velocities.
    - gravity 9.81 m/s^2 along -y.
    """
    return Mechanism()


def with_clearance(mech: Mechanism, clearance_B=None, clearance_C=None) -> Mechanism:
    """Return ``mech`` with new radial clearances (m) at B and/or C, keeping the
    hole radii and shrinking the pins."""
    if clearance_B is not None:
        mech = eqx.tree_at(lambda m: m.joint_B.pin_radius, mech, mech.joint_B.hole_radius - clearance_B)
    if clearance_C is not None:
        mech = eqx.tree_at(lambda m: m.joint_C.pin_radius, mech, mech.joint_C.hole_radius - clearance_C)
    return mech


def _leaf(mech: Mechanism, name: str):
    """(getter, current value) of the numeric parameter at dotted path ``name``."""

    def get(m):
        for p in name.split("."):
            m = getattr(m, p)
        return m

    try:
        current = get(mech)
    except AttributeError:
        raise ParameterError(
            f"unknown design variable {name!r}: use a numeric Mechanism field such as "
            "'rod_length', a dotted path such as 'contact.restitution', or "
            "'clearance_B' / 'clearance_C'"
        ) from None
    if isinstance(current, (str, bool, eqx.Module)):
        raise ParameterError(f"design variable {name!r} is not a number")
    return get, current


def set_parameter(mech: Mechanism, name: str, x) -> Mechanism:
    """``mech`` with parameter ``name`` set to ``x`` (SI). Names are the
    mechanism's scalar fields (``crank_length``, ``rod_length``, ``offset``, ...),
    dotted paths into its parts (``contact.restitution``) or ``clearance_B`` /
    ``clearance_C`` (radial clearance, m: the pin shrinks, the hole stays)."""
    if name == "clearance_B":
        return with_clearance(mech, clearance_B=x)
    if name == "clearance_C":
        return with_clearance(mech, clearance_C=x)
    return eqx.tree_at(_leaf(mech, name)[0], mech, x)


def set_parameters(mech: Mechanism, names, values) -> Mechanism:
    """``mech`` with each parameter in ``names`` set to the matching entry of
    ``values`` (SI; traceable), as [`set_parameter`][jaxcrank.physics.params.set_parameter]."""
    for i, name in enumerate(names):
        mech = set_parameter(mech, name, values[i])
    return mech


def get_parameter(mech: Mechanism, name: str) -> float:
    """Current value (SI) of a design variable name (see [`set_parameter`][jaxcrank.physics.params.set_parameter])."""
    return float(parameter_value(mech, name))


def parameter_value(mech: Mechanism, name: str):
    """Value (SI) of parameter ``name`` of ``mech``, traceable (an array or a float)."""
    if name in ("clearance_B", "clearance_C"):
        return getattr(mech, "joint_" + name[-1]).clearance
    return _leaf(mech, name)[1]


_UNITS = {
    "crank_length": "m",
    "rod_length": "m",
    "offset": "m",
    "crank_mass": "kg",
    "rod_mass": "kg",
    "slider_mass": "kg",
    "crank_inertia": "kg_m2",
    "rod_inertia": "kg_m2",
    "slider_inertia": "kg_m2",
    "crank_speed": "rad_s",
    "initial_crank_angle": "rad",
    "gravity": "m_s2",
    "hole_radius": "m",
    "pin_radius": "m",
    "clearance_B": "m",
    "clearance_C": "m",
    "youngs_modulus": "Pa",
    "poisson_ratio": "1",
    "restitution": "1",
    "exponent": "1",
    "min_approach_speed": "m_s",
    "memory_time": "s",
    "freeze_time": "s",
    "reset_window": "s",
    "reset_time": "s",
    "coefficient": "1",
    "stick_speed": "m_s",
    "slip_speed": "m_s",
}


def parameter_unit(name: str) -> str:
    """SI unit of a parameter name (as in [`set_parameter`][jaxcrank.physics.params.set_parameter]), written for column
    names: ``m``, ``kg``, ``kg_m2``, ``rad_s``, ``m_s``, ``m_s2``, ``Pa``, ``s``, ``rad`` or ``1``
    (dimensionless)."""
    get_parameter(Mechanism(), name)  # raises on unknown names
    return _UNITS[name.rsplit(".", 1)[-1]]
