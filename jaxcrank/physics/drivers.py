"""What turns a linkage: a driver turns one body that is jointed to the ground, at a
prescribed angle ([`ConstantSpeed`][jaxcrank.physics.drivers.ConstantSpeed],
[`SpeedProfile`][jaxcrank.physics.drivers.SpeedProfile]) or by a torque
([`Torque`][jaxcrank.physics.drivers.Torque]). ``name`` is a driver's ``type`` in TOML files.
Everything is SI: rad, rad/s, N m.
"""

from __future__ import annotations

import abc
import math
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .params import ParameterError, _concrete, check_range


class AbstractDriver(eqx.Module):
    """What turns the linkage: a prescribed angle of ``body`` (``prescribed``), or a
    torque on it. The body must be jointed to the ground. Every driver has an
    ``initial_angle`` (rad), the body's angle at t = 0.

    ``speed_scale`` (rad/s) scales the state's rates; ``period`` (s) is the time of one
    revolution (at the nominal speed for a torque driver).
    """

    name: ClassVar[str]
    prescribed: ClassVar[bool]
    body: eqx.AbstractVar[str]

    @property
    @abc.abstractmethod
    def speed_scale(self):
        """Nominal angular speed, rad/s (stop-gradient where used as a scale)."""

    @property
    def period(self):
        """Time of one revolution at the nominal speed, s."""
        return 2.0 * math.pi / self.speed_scale

    def angle(self, t: Float[ArrayLike, ""]) -> Float[Array, ""]:
        """The prescribed angle of the driven body at time t, rad."""
        raise NotImplementedError(f"a {self.name!r} driver prescribes no angle")


class ConstantSpeed(AbstractDriver):
    """The driven body turns at a constant speed: angle = initial_angle + speed t.

    Attributes:
        body: the driven body (jointed to the ground).
        speed: rad/s, > 0.
        initial_angle: its angle at t = 0, rad.
    """

    name: ClassVar[str] = "constant_speed"
    prescribed: ClassVar[bool] = True
    body: str = eqx.field(static=True)
    speed: float
    initial_angle: float = 0.0

    def __check_init__(self):
        check_range("driver.speed", self.speed, low=0.0, unit="rad/s")
        check_range("driver.initial_angle", self.initial_angle, unit="rad")

    @property
    def speed_scale(self):
        return self.speed

    def angle(self, t):
        return self.initial_angle + self.speed * t


class SpeedProfile(AbstractDriver):
    """A prescribed, periodic speed: ``omega(t) = speed (1 + sum_k c_k cos(k speed t) +
    s_k sin(k speed t))`` for harmonics k = 1, 2, ..., so the angle is
    ``initial_angle + speed t + sum_k (c_k sin(k speed t) + s_k (1 - cos(k speed t))) / k``
    and one revolution still takes 2 pi / speed.

    Attributes:
        body: the driven body (jointed to the ground).
        speed: mean angular speed, rad/s, > 0.
        initial_angle: rad.
        cosine: relative amplitudes c_k of the cosine harmonics (dimensionless).
        sine: relative amplitudes s_k of the sine harmonics (dimensionless).

    Raises:
        ParameterError: when the amplitudes could make the speed reach zero
            (sum of |c_k| + |s_k| must stay below 1).
    """

    name: ClassVar[str] = "speed_profile"
    prescribed: ClassVar[bool] = True
    body: str = eqx.field(static=True)
    speed: float
    initial_angle: float = 0.0
    cosine: tuple[float, ...] = ()
    sine: tuple[float, ...] = ()

    def __check_init__(self):
        check_range("driver.speed", self.speed, low=0.0, unit="rad/s")
        amps = [_concrete(a) for a in (*self.cosine, *self.sine)]
        if all(a is not None for a in amps) and sum(float(np.abs(a)) for a in amps) >= 1.0:
            raise ParameterError(
                "driver harmonics: the sum of |cosine| + |sine| amplitudes must be below 1 (valid range: [0, 1)), "
                "or the speed would reach zero"
            )

    @property
    def speed_scale(self):
        return self.speed

    def angle(self, t):
        w = self.speed
        out = self.initial_angle + w * t
        for k, c in enumerate(self.cosine, start=1):
            out = out + c * jnp.sin(k * w * t) / k
        for k, s in enumerate(self.sine, start=1):
            out = out + s * (1.0 - jnp.cos(k * w * t)) / k
        return out


class Torque(AbstractDriver):
    """A constant torque on the driven body, which turns freely from an initial speed
    (zero torque: a free-running mechanism).

    Attributes:
        body: the driven body (jointed to the ground).
        torque: N m, on the body, counter-clockwise positive.
        initial_angle: rad.
        initial_speed: rad/s, > 0 (also the nominal speed that scales the state).
    """

    name: ClassVar[str] = "torque"
    prescribed: ClassVar[bool] = False
    body: str = eqx.field(static=True)
    torque: float = 0.0
    initial_angle: float = 0.0
    initial_speed: float = 1.0

    def __check_init__(self):
        check_range("driver.torque", self.torque, unit="N m")
        check_range("driver.initial_speed", self.initial_speed, low=0.0, unit="rad/s")

    @property
    def speed_scale(self):
        return self.initial_speed


DRIVERS: dict[str, type[AbstractDriver]] = {d.name: d for d in (ConstantSpeed, SpeedProfile, Torque)}
