"""Parameter validation and the settings a joint law is made of: surface materials,
the normal contact law and the friction law.

Every number a user may sweep or differentiate is a pytree leaf (``jax.grad``,
``jax.vmap`` and optax act on a mechanism directly). Only choices that
change the structure of the model are static: the laws themselves
(leafless equinox Modules, [`jaxcrank.physics.laws`][]), and which joints are ideal
(which changes the number of degrees of freedom).

All values are SI: metres, kilograms, seconds, radians, newtons, pascals.

Validation runs in ``__check_init__`` on concrete values, so a bad mechanism is
rejected with a sentence naming the parameter and its valid range before any
solve. Values that are JAX tracers (inside ``jit``/``grad``/``vmap``) are not
checked there; they were checked when the concrete mechanism was built.
"""

from __future__ import annotations

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


def check_range(name: str, value, *, low=None, high=None, low_open=True, high_open=True, unit=""):
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
        finite = "a finite number" if low is None and high is None else f"a finite number in {interval}"
        if not np.isfinite(bad) or (low is None and high is None):
            raise ParameterError(f"{name} = {bad:g}{' ' + unit if unit else ''} must be {finite}")
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
        check_range("youngs_modulus", self.youngs_modulus, low=0.0, unit="Pa")
        check_range("poisson_ratio", self.poisson_ratio, low=0.0, high=0.5)

    @property
    def compliance(self):
        """(1 - nu^2) / E, 1/Pa."""
        return (1.0 - self.poisson_ratio**2) / self.youngs_modulus


class Contact(eqx.Module):
    """Normal contact law settings of a dry clearance joint (model.md, "Normal contact force").

    Attributes:
        law: the normal law, a [`jaxcrank.physics.laws.AbstractContactLaw`][]
            (TOML/CLI names in ``laws.CONTACT_LAWS``). The default
            [`Hybrid`][jaxcrank.physics.laws.Hybrid] is the paper's Eq. 6-8 (Bai & Zhao 2012
            stiffness with Eq. 5 damping).
        restitution: coefficient of restitution c_e in (0, 1] that sets the
            hysteresis damping factor chi of the law. The restitution a law
            actually achieves follows chi (see ``laws.achieved_restitution``).
        exponent: Hertz exponent n of delta^n, dimensionless (1.5 for these laws).

    Raises:
        ParameterError: a law that is not a contact law, or a value out of its range.
    """

    law: AbstractContactLaw = Hybrid()
    restitution: float = 0.9
    exponent: float = 1.5

    def __check_init__(self):
        if not isinstance(self.law, AbstractContactLaw):
            raise ParameterError(
                f"contact law {self.law!r} is not a jaxcrank.physics.laws.AbstractContactLaw; pass e.g. "
                f"laws.Flores() (TOML and --set take the names: {', '.join(CONTACT_LAWS)})"
            )
        check_range("restitution", self.restitution, low=0.0, high=1.0, high_open=False)
        check_range("exponent", self.exponent, low=1.0, high=3.0, low_open=False, high_open=False)


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
        check_range("friction coefficient", self.coefficient, low=0.0, low_open=False)
        check_range("stick_speed", self.stick_speed, low=0.0, low_open=False, unit="m/s")
        check_range("slip_speed", self.slip_speed, low=0.0, unit="m/s")  # NaN and inf fail the comparison below
        v0, v1 = _concrete(self.stick_speed), _concrete(self.slip_speed)
        if v0 is not None and v1 is not None and np.any(v1 <= v0):
            raise ParameterError(
                f"slip_speed = {np.min(v1):g} m/s must be greater than stick_speed = "
                f"{np.max(v0):g} m/s (valid range: slip_speed > stick_speed >= 0)"
            )
