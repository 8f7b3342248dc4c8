"""The four-bar design problem: the link lengths of a crank-rocker
([`jaxcrank.FourBar`][jaxcrank.physics.presets.FourBar]) under Grashof's condition and a
bound on the transmission angle, both held at every iterate by a reparametrisation that
makes them bounds of the design box (as [`optim.design`][] does for the slider-crank).

With crank a, coupler b, rocker c and ground d (m), the distance e from the crank pin B to
the rocker pivot D obeys ``e^2 = a^2 + d^2 - 2 a d cos(phi)`` (phi the crank angle), and
the transmission angle mu at C (between coupler and rocker) obeys
``cos(mu) = (b^2 + c^2 - e^2) / (2 b c)``. mu grows with e, so over a revolution it runs
between its extremes at phi = 0 (``e = d - a``) and phi = pi (``e = d + a``):

- ``mu_0 = arccos((b^2 + c^2 - (d - a)^2) / (2 b c))`` the smallest transmission angle,
- ``mu_pi = arccos((b^2 + c^2 - (d + a)^2) / (2 b c))`` the largest.

**The constraints.** Grashof's crank-rocker condition (the crank shortest, shortest +
longest <= the sum of the other two) is, written smoothly in the lengths, the three linear
inequalities ``a + b <= c + d``, ``a + c <= b + d``, ``a + d <= b + c`` (together they
imply that the crank is the shortest link). The transmission bound asks the transmission
angle to stay within ``[mu_min, 180 deg - mu_min]``: ``mu_0 >= mu_min`` and
``mu_pi <= 180 deg - mu_min``.

**The reparametrisation.** The variables are the coupler and rocker lengths
(``coupler_length``, ``rocker_length``, m) and the two extreme transmission angles
(``min_transmission_angle`` = mu_0, ``max_transmission_angle`` = mu_pi, rad). The two
triangles B C D at the dead centres give ``e_0 = sqrt(b^2 + c^2 - 2 b c cos(mu_0))`` and
``e_pi = sqrt(b^2 + c^2 - 2 b c cos(mu_pi))``, hence ``a = (e_pi - e_0) / 2`` and
``d = (e_pi + e_0) / 2`` in closed form (smooth: ``e_0 > 0`` for ``mu_0 > 0``). Every
design with ``0 < mu_0 < mu_pi < 180 deg`` is a crank-rocker whose transmission angle runs
exactly over ``[mu_0, mu_pi]``: ``d - a = e_0 > |b - c|`` and ``d + a = e_pi < b + c``
(strict triangles) are Grashof's first two inequalities, which imply the third. So the box
``mu_0 >= mu_min``, ``mu_pi <= 180 deg - mu_min``, ``upper(mu_0) < lower(mu_pi)`` holds
both constraints at every design in it (checked on construction); the projection onto the
box is all the optimiser needs. [`FourBarProblem.constraints`][optim.four_bar.FourBarProblem.constraints]
recomputes the constraints from the derived lengths.

**Masses.** With ``scale_links`` (default) each link keeps the base's cross-section and
shape: its mass scales with its length and its inertia about its centre of mass with
``mass x length^2`` (uniform bars stay uniform bars).

Objective: the RMS transmission-angle error (``rms_transmission_angle_error_deg``, Eq. 19's
measure, degrees) by the problem's objective, by default over one period of the periodic
orbit ([`optim.steady.Steady`][]), plus the clearance cost term when clearances are variables.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from jaxcrank.physics.parameters import get_parameter, set_parameters
from jaxcrank.physics.params import ParameterError
from jaxcrank.physics.presets import FourBar, four_bar

from .objective import EQ19, AbstractObjective
from .problem import AbstractProblem, known_parameter
from .steady import STEADY_OBJECTIVE, Steady

#: the geometry's variables (name -> SI unit); crank and ground lengths follow from them
GEOMETRY = {
    "coupler_length": "m",
    "rocker_length": "m",
    "min_transmission_angle": "rad",
    "max_transmission_angle": "rad",
}

#: the links whose length the geometry sets (their masses and inertias scale with ``scale_links``)
LINKS = ("crank", "coupler", "rocker")


def transmission_extremes(a, b, c, d):
    """The smallest and largest transmission angle of the ideal four-bar over a revolution,
    rad: ``arccos((b^2 + c^2 - (d -+ a)^2) / (2 b c))`` at crank angles 0 and pi (lengths
    a crank, b coupler, c rocker, d ground, m; a crank-rocker)."""
    two_bc = 2.0 * b * c
    low = jnp.arccos(jnp.clip((b**2 + c**2 - (d - a) ** 2) / two_bc, -1.0, 1.0))
    high = jnp.arccos(jnp.clip((b**2 + c**2 - (d + a) ** 2) / two_bc, -1.0, 1.0))
    return low, high


def crank_and_ground(b, c, mu_0, mu_pi):
    """Crank and ground lengths (m) of the crank-rocker with coupler ``b`` and rocker ``c``
    (m) whose transmission angle runs over ``[mu_0, mu_pi]`` (rad, ``0 < mu_0 < mu_pi < pi``):
    ``((e_pi - e_0) / 2, (e_pi + e_0) / 2)`` with ``e^2 = b^2 + c^2 - 2 b c cos(mu)``. Traceable."""
    e_0 = jnp.sqrt(b**2 + c**2 - 2.0 * b * c * jnp.cos(mu_0))
    e_pi = jnp.sqrt(b**2 + c**2 - 2.0 * b * c * jnp.cos(mu_pi))
    return 0.5 * (e_pi - e_0), 0.5 * (e_pi + e_0)


def grashof_margins(a, b, c, d):
    """Grashof's crank-rocker condition as three linear inequalities, each margin >= 0 when
    met (m): ``c + d - a - b``, ``b + d - a - c``, ``b + c - a - d``."""
    return c + d - a - b, b + d - a - c, b + c - a - d


@dataclasses.dataclass(frozen=True)
class FourBarProblem(AbstractProblem):
    """A four-bar crank-rocker's link lengths with Grashof's condition and the
    transmission bound held by the box (module docstring).

    Attributes (besides [`AbstractProblem`][optim.problem.AbstractProblem]'s):
        min_transmission_deg: the transmission angle stays within
            ``[min_transmission_deg, 180 - min_transmission_deg]`` deg, in (0, 90).
        scale_links: each link's mass scales with its length and its inertia with
            mass x length^2 from the base's values (True), or they stay the base's (False).

    Variable names: any of `GEOMETRY` (those left out stay at the base's values) and any
    other name [`jaxcrank.physics.parameters.set_parameter`][] accepts except
    ``crank_length`` and ``ground_length`` (derived), ``driver.*`` (the sample grid) and,
    with ``scale_links``, the links' masses and inertias. The base must be a
    [`jaxcrank.FourBar`][jaxcrank.physics.presets.FourBar].
    """

    min_transmission_deg: float = 40.0
    scale_links: bool = True

    def check_variable(self, name: str) -> None:
        if name in ("crank_length", "ground_length") or name.startswith("driver."):
            raise ParameterError(
                f"{name!r} cannot be a FourBarProblem variable: crank_length and ground_length follow from "
                f"{', '.join(GEOMETRY)}; the driver fixes the objective's sample grid"
            )
        if self.scale_links and name in {f"{k}_{q}" for k in LINKS for q in ("mass", "inertia")}:
            raise ParameterError(f"{name!r} follows from the link lengths (scale_links = True); set scale_links=False")
        if name not in GEOMETRY:
            known_parameter(self.base, name)

    def check(self) -> None:
        if not isinstance(self.base, FourBar):
            raise ParameterError(f"a FourBarProblem's base must be a jaxcrank.FourBar, not {type(self.base).__name__}")
        if not 0.0 < self.min_transmission_deg < 90.0:
            raise ParameterError(f"min_transmission_deg = {self.min_transmission_deg:g} must be in (0, 90) deg")
        bound = math.radians(self.min_transmission_deg)
        lo0, hi0 = self.range_of("min_transmission_angle")
        lo_pi, hi_pi = self.range_of("max_transmission_angle")
        if lo0 < bound - 1e-12 or hi_pi > math.pi - bound + 1e-12 or not hi0 < lo_pi:
            raise ParameterError(
                f"min_transmission_angle in [{lo0:g}, {hi0:g}] rad and max_transmission_angle in "
                f"[{lo_pi:g}, {hi_pi:g}] rad must satisfy {bound:g} <= min_transmission_angle < "
                f"max_transmission_angle <= {math.pi - bound:g} rad (min_transmission_deg = "
                f"{self.min_transmission_deg:g}; the upper bound of the first below the lower bound of the second)"
            )
        for name in ("coupler_length", "rocker_length"):
            if self.range_of(name)[0] <= 0.0:
                raise ParameterError(f"bounds of {name} must be > 0 m")

    @property
    def description(self) -> str:
        return self.title

    # ------------------------------------------------------------------ geometry
    def base_geometry(self) -> dict[str, float]:
        """The `GEOMETRY` values of the base mechanism (SI)."""
        a, b, c, d = (float(get_parameter(self.base, f"{k}_length")) for k in ("crank", "coupler", "rocker", "ground"))
        with jax.ensure_compile_time_eval():  # concrete values, also while a design is traced
            low, high = transmission_extremes(a, b, c, d)
        return {
            "coupler_length": b,
            "rocker_length": c,
            "min_transmission_angle": float(low),
            "max_transmission_angle": float(high),
        }

    def range_of(self, name: str) -> tuple[float, float]:
        """The bounds of a `GEOMETRY` variable, or its base value twice when it is fixed (SI)."""
        if name in self.names:
            i = self.names.index(name)
            return float(self.lower[i]), float(self.upper[i])
        value = self.base_geometry()[name]
        return value, value

    def physical(self, x):
        """Mechanism parameter names and their values (SI, traceable) at design ``x``: the
        direct variables, then the four lengths and (``scale_links``) the links' masses and
        inertias."""
        x = jnp.asarray(x, dtype=float)
        fixed = self.base_geometry()
        geo = {k: x[self.names.index(k)] if k in self.names else jnp.asarray(fixed[k]) for k in GEOMETRY}
        names = [nm for nm in self.names if nm not in GEOMETRY]
        values = [x[self.names.index(nm)] for nm in names]
        b, c = geo["coupler_length"], geo["rocker_length"]
        a, d = crank_and_ground(b, c, geo["min_transmission_angle"], geo["max_transmission_angle"])
        lengths = {"crank": a, "coupler": b, "rocker": c}
        names += ["crank_length", "coupler_length", "rocker_length", "ground_length"]
        values += [a, b, c, d]
        if self.scale_links:
            for link, length in lengths.items():
                ratio = length / get_parameter(self.base, f"{link}_length")
                names += [f"{link}_mass", f"{link}_inertia"]
                values += [
                    get_parameter(self.base, f"{link}_mass") * ratio,
                    get_parameter(self.base, f"{link}_inertia") * ratio**3,
                ]
        return tuple(names), jnp.stack(values)

    def mechanism(self, x):
        names, values = self.physical(x)
        return set_parameters(self.base, names, values)

    def default_start(self) -> list[float]:
        fixed = self.base_geometry()
        return [fixed[nm] if nm in GEOMETRY else float(get_parameter(self.base, nm)) for nm in self.names]

    def constraints(self, x) -> dict:
        """The constraints at SI design(s) ``x`` (..., n), numpy, recomputed from the derived
        lengths: ``crank_length_m``, ``coupler_length_m``, ``rocker_length_m``,
        ``ground_length_m``, ``grashof_margin_m`` (the smallest of
        [`grashof_margins`][optim.four_bar.grashof_margins], >= 0 for a crank-rocker),
        ``min_transmission_angle_deg`` and ``max_transmission_angle_deg`` (closed form,
        [`transmission_extremes`][optim.four_bar.transmission_extremes])."""
        xs = np.atleast_2d(np.asarray(x, dtype=float))
        rows = [dict(zip(*self.physical(row))) for row in xs]
        a, b, c, d = (jnp.asarray([r[f"{k}_length"] for r in rows]) for k in ("crank", "coupler", "rocker", "ground"))
        low, high = transmission_extremes(a, b, c, d)
        out = {
            "crank_length_m": a,
            "coupler_length_m": b,
            "rocker_length_m": c,
            "ground_length_m": d,
            "grashof_margin_m": jnp.min(jnp.stack(grashof_margins(a, b, c, d)), axis=0),
            "min_transmission_angle_deg": jnp.degrees(low),
            "max_transmission_angle_deg": jnp.degrees(high),
        }
        shape = np.shape(x)[:-1]
        return {k: np.asarray(v).reshape(shape) for k, v in out.items()}

    def feasible(self, x, tol=1e-12):
        """Bounds, linear constraints, Grashof's crank-rocker condition and the transmission
        bound (within 1e-9 deg)."""
        c = self.constraints(x)
        return (
            self.box_feasible(x, tol)
            & (c["grashof_margin_m"] > 0.0)
            & (c["min_transmission_angle_deg"] >= self.min_transmission_deg - 1e-9)
            & (c["max_transmission_angle_deg"] <= 180.0 - self.min_transmission_deg + 1e-9)
        )

    # ------------------------------------------------------------------ objective
    def loss(self, rms: dict) -> Float[Array, ""]:
        return rms[EQ19]

    def objective_value(self, x):
        return self.loss(self.objective.rms(self.mechanism(x))) + self.cost(x)


#: the four-bar preset's variables: (name, lower, upper), SI; the start is the base's design
FOUR_BAR_VARIABLES = (
    ("coupler_length", 0.25, 0.45),
    ("rocker_length", 0.20, 0.40),
    ("min_transmission_angle", math.radians(40.0), math.radians(80.0)),
    ("max_transmission_angle", math.radians(100.0), math.radians(140.0)),
)


#: revolutions settled from rest before the steady-state search of the four-bar preset: its motion
#: from rest settles slowly (after Adam's first step from the preset it is not yet recurrent after 20
#: revolutions, and periodic with leading Floquet multiplier 0.25 after 40)
FOUR_BAR_SETTLE = 40


def four_bar_problem(
    objective: AbstractObjective | None = None,
    start: Sequence[float] | None = None,
    min_transmission_deg: float = 40.0,
) -> FourBarProblem:
    """The four-bar preset ([`jaxcrank.four_bar`][jaxcrank.physics.presets.four_bar]: 600 rpm, 0.5 mm radial
    clearance at B and C) with its four link lengths varying (`FOUR_BAR_VARIABLES`: coupler
    250-450 mm, rocker 200-400 mm, the transmission angle's extremes within 40-80 and 100-140
    deg; crank and ground follow), links scaled as uniform bars, minimising the RMS
    transmission-angle error of the periodic orbit (``objective``: default
    [`optim.steady.Steady`][] settling `FOUR_BAR_SETTLE` revolutions from rest). Start: the
    preset's lengths (a = 100, b = 350, c = 300, d = 400 mm; transmission 54.3-100.3 deg)."""
    return FourBarProblem(
        base=four_bar(),
        names=tuple(v[0] for v in FOUR_BAR_VARIABLES),
        lower=tuple(v[1] for v in FOUR_BAR_VARIABLES),
        upper=tuple(v[2] for v in FOUR_BAR_VARIABLES),
        start=None if start is None else tuple(start),
        objective=Steady(options=STEADY_OBJECTIVE.replace(settle_revolutions=FOUR_BAR_SETTLE))
        if objective is None
        else objective,
        title=f"four-bar: RMS transmission-angle error over the link lengths, transmission in "
        f"[{min_transmission_deg:g}, {180 - min_transmission_deg:g}] deg",
        min_transmission_deg=min_transmission_deg,
    )
