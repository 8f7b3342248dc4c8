"""Derived geometric variables: design variables that set several mechanism parameters at once,
so that a designer's geometric intent holds at every design.

- [`Length`][optim.geometry.Length]: a link's length on a written-out linkage, moving an
  attachment point along the body and carrying its mass properties by a declared rule.
- [`SliderCrankStroke`][optim.geometry.SliderCrankStroke]: a slider-crank's rod length and
  minimum transmission angle, with crank length and offset solved for a target stroke. The
  stroke ``S = sqrt((L1 + L2)^2 - e^2) - sqrt((L2 - L1)^2 - e^2)`` is held exactly and the
  minimum transmission angle ``alpha_min = arccos((L1 + |e|) / L2)`` is a variable bounded
  below by the floor, so both constraints are bounds of the box (assemblability
  ``L2 - L1 - e = L2 (1 - cos alpha_min) > 0`` follows). With ``a = L1 + e = L2 cos(alpha_min)``
  the stroke is strictly increasing in ``d = L1 - e`` on ``(-a, a]``; ``d`` follows from
  bisection to machine precision and one Newton step whose derivative is the implicit
  function theorem's. ``rod_inertia_ratio`` sets ``J2 = ratio m2 L2^2`` (a uniform bar: 1/12).
- [`CrankRocker`][optim.geometry.CrankRocker]: a four-bar's coupler b and rocker c and the
  extremes of its transmission angle, mu_0 (crank angle 0) and mu_pi; crank and ground follow
  in closed form, ``a = (e_pi - e_0) / 2``, ``d = (e_pi + e_0) / 2`` with
  ``e^2 = b^2 + c^2 - 2 b c cos(mu)``. Every design with ``0 < mu_0 < mu_pi < 180 deg`` is a
  Grashof crank-rocker whose transmission angle runs over ``[mu_0, mu_pi]``, so Grashof's
  condition and the transmission bound are bounds of the box. With ``scale_links`` each link
  keeps its section: mass x r, inertia x r^3.

A derived group is declared once per problem (``[derived]`` in a problem file); its variables
are named among the problem's.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from jaxcrank.physics.linkage import GROUND, Linkage
from jaxcrank.physics.parameters import get_parameter
from jaxcrank.physics.params import ParameterError
from jaxcrank.physics.presets import FourBar, SliderCrank

#: how a length variable carries its body's mass properties along
CARRY = {
    "keep": "mass, centre of mass and inertia unchanged",
    "scale": "a bar of constant section: the centre of mass moves with the length, mass x r, inertia x r^3",
    "uniform_bar": "the centre of mass at the middle of the two points, inertia = mass x length^2 / 12",
}


@dataclasses.dataclass(frozen=True)
class Length:
    """A derived variable: the distance between two points of one body, m. Setting it moves
    ``to`` along the line from ``start`` (the attachment point slides along the body) and
    carries the body's mass properties by the rule ``carry`` (`CARRY`).

    Attributes:
        name: the variable's name.
        body: the body (``"ground"`` for two ground points: the frame's length, ``carry`` ignored).
        start: the point that stays, a point name of the body.
        to: the point that moves.
        carry: ``"keep"``, ``"scale"`` or ``"uniform_bar"``.
    """

    name: str
    body: str
    start: str
    to: str
    carry: str = "keep"

    def points(self, lk: Linkage) -> dict:
        return lk.ground if self.body == GROUND else lk.bodies[self.body].points

    def check(self, base) -> None:
        """ParameterError naming the variable, for a preset base, an unknown body or point, an
        unknown rule or coinciding points."""
        if not isinstance(base, Linkage):
            raise ParameterError(
                f"variable {self.name!r}: a length variable needs a written-out linkage (mechanism = "
                f'"linkage"); a preset has its lengths as parameters (<link>_length)'
            )
        if self.body != GROUND and self.body not in base.bodies:
            raise ParameterError(f"variable {self.name!r}: unknown body {self.body!r}; bodies: {sorted(base.bodies)}")
        pts = self.points(base)
        for p in (self.start, self.to):
            if p not in pts:
                raise ParameterError(
                    f"variable {self.name!r}: body {self.body!r} has no point {p!r}; its points: {sorted(pts)}"
                )
        if self.carry not in CARRY:
            raise ParameterError(f"variable {self.name!r}: carry = {self.carry!r} is unknown; valid: {list(CARRY)}")
        if self.base_length(base) <= 0.0:
            raise ParameterError(f"variable {self.name!r}: points {self.start} and {self.to} coincide")

    def base_length(self, base: Linkage) -> float:
        """The base's distance between the two points, m."""
        pts = self.points(base)
        a, b = pts[self.start], pts[self.to]
        return math.hypot(float(b.x) - float(a.x), float(b.y) - float(a.y))

    def apply(self, base: Linkage, mech: Linkage, length) -> tuple[list[str], list]:
        """The parameter names and values (traceable) that set this length on ``mech``."""
        prefix = GROUND if self.body == GROUND else f"bodies.{self.body}"
        pts = self.points(mech)
        a, b = pts[self.start], pts[self.to]
        r = length / self.base_length(base)
        names = [f"{prefix}.points.{self.to}.x", f"{prefix}.points.{self.to}.y"]
        if self.body == GROUND:
            names = [f"{GROUND}.{self.to}.x", f"{GROUND}.{self.to}.y"]
        bx, by = a.x + (b.x - a.x) * r, a.y + (b.y - a.y) * r
        values = [bx, by]
        if self.body == GROUND or self.carry == "keep":
            return names, values
        body = mech.bodies[self.body]
        com = body.centre_of_mass
        names += [f"{prefix}.centre_of_mass.x", f"{prefix}.centre_of_mass.y", f"{prefix}.inertia"]
        if self.carry == "scale":
            names.append(f"{prefix}.mass")
            com_x, com_y = a.x + (com.x - a.x) * r, a.y + (com.y - a.y) * r
            return names, values + [com_x, com_y, body.inertia * r**3, body.mass * r]
        return names, values + [0.5 * (a.x + bx), 0.5 * (a.y + by), body.mass * length**2 / 12.0]


# ---------------------------------------------------------------------------------------- slider-crank


def ideal_stroke(l1, l2, e):
    """Ideal slider stroke (distance between the dead centres), m:
    ``sqrt((L1 + L2)^2 - e^2) - sqrt((L2 - L1)^2 - e^2)``. Needs ``L2 > L1 + |e|``."""
    return jnp.sqrt((l2 + l1) ** 2 - e**2) - jnp.sqrt((l2 - l1) ** 2 - e**2)


def min_transmission_angle(l1, l2, e):
    """Ideal slider-crank's minimum transmission angle, rad: ``arccos((L1 + |e|) / L2)``. Needs
    ``L2 > L1 + |e|``."""
    return jnp.arccos((l1 + jnp.abs(e)) / l2)


def _stroke_in_d(l2, a, d):
    return jnp.sqrt((l2 + a) * (l2 + d)) - jnp.sqrt((l2 - a) * (l2 - d))


def _stroke_in_d_slope(l2, a, d):
    return 0.5 * (jnp.sqrt((l2 + a) / (l2 + d)) + jnp.sqrt((l2 - a) / (l2 - d)))


def crank_and_offset(l2, alpha, stroke, iterations: int = 64):
    """Crank length L1 and offset e (m) with rod length ``l2`` (m), minimum transmission angle
    ``alpha`` (rad, in (0, pi/2)) and ideal stroke ``stroke`` (m): ``S(d) = stroke`` solved for
    ``d = L1 - e`` on ``[-a, a]``, ``a = l2 cos(alpha)``, by bisection and one Newton step whose
    derivative is the implicit function's. Needs ``0 < stroke <= 2 a``; traceable."""
    l2, alpha, stroke = (jnp.asarray(v, dtype=float) for v in (l2, alpha, stroke))
    a = l2 * jnp.cos(alpha)
    sg = jax.lax.stop_gradient
    l2c, ac, sc = sg(l2), sg(a), sg(stroke)

    def bisect(_, bracket):
        lo, hi = bracket
        mid = 0.5 * (lo + hi)
        high = _stroke_in_d(l2c, ac, mid) > sc
        return jnp.where(high, lo, mid), jnp.where(high, mid, hi)

    lo, hi = jax.lax.fori_loop(0, iterations, bisect, (-ac, ac))
    d0 = 0.5 * (lo + hi)
    d = d0 - (_stroke_in_d(l2, a, d0) - stroke) / sg(_stroke_in_d_slope(l2c, ac, d0))
    return 0.5 * (a + d), 0.5 * (a - d)


def _range(problem, name, fixed):
    if name in problem.names:
        i = problem.names.index(name)
        return float(problem.lower[i]), float(problem.upper[i])
    return fixed[name], fixed[name]


@dataclasses.dataclass(frozen=True)
class SliderCrankStroke:
    """The slider-crank's stroke-holding reparametrisation (module docstring).

    Attributes:
        stroke: target ideal stroke, m (held exactly).
        stroke_tolerance: the stroke error a design may show, m (reports and ``feasible``).
        min_transmission_deg: the floor of the minimum transmission angle, deg, in (0, 90).

    Variables: ``rod_length`` (m) and ``min_transmission_angle`` (rad), both required;
    ``rod_inertia_ratio`` (1) optional. ``crank_length``, ``offset``, ``rod_inertia`` with the
    ratio, and ``driver.*`` cannot be variables beside them.
    """

    stroke: float = 0.240
    stroke_tolerance: float = 1e-4
    min_transmission_deg: float = 40.0

    kind = "slider_crank_stroke"
    VALUES = ("stroke",)  # traceable: a compiled program takes it as an input (optim.problem.problem_values)
    #: the variables this group owns (name -> SI unit)
    OWNED = {"rod_length": "m", "min_transmission_angle": "rad", "rod_inertia_ratio": "1"}

    def check_variable(self, name: str) -> None:
        if name in ("crank_length", "offset") or name.startswith("driver."):
            raise ParameterError(
                f"{name!r} cannot be a variable with the slider-crank stroke reparametrisation: crank_length and "
                "offset follow from the stroke (its variables are rod_length and min_transmission_angle), the driver "
                "fixes the objective's sample grid"
            )

    def check(self, problem) -> None:
        if not isinstance(problem.base, SliderCrank):
            raise ParameterError(
                f"the slider-crank stroke reparametrisation needs a slider-crank base (jaxcrank.SliderCrank), not "
                f"{type(problem.base).__name__}"
            )
        for req in ("rod_length", "min_transmission_angle"):
            if req not in problem.names:
                raise ParameterError(f"the slider-crank stroke reparametrisation needs the variable {req!r}")
        if "rod_inertia" in problem.names and "rod_inertia_ratio" in problem.names:
            raise ParameterError("give rod_inertia or rod_inertia_ratio, not both")
        if not self.stroke > 0:
            raise ParameterError(f"stroke = {self.stroke:g} m must be > 0")
        if not 0 < self.min_transmission_deg < 90:
            raise ParameterError(f"min_transmission_deg = {self.min_transmission_deg:g} must be in (0, 90) deg")
        i_a, i_l = problem.names.index("min_transmission_angle"), problem.names.index("rod_length")
        lo_a, hi_a = problem.lower[i_a], problem.upper[i_a]
        if lo_a < math.radians(self.min_transmission_deg) - 1e-12 or hi_a >= math.pi / 2:
            raise ParameterError(
                f"bounds of min_transmission_angle = [{lo_a:g}, {hi_a:g}] rad must lie in "
                f"[{math.radians(self.min_transmission_deg):g}, {math.pi / 2:g}) rad "
                f"(min_transmission_deg = {self.min_transmission_deg:g})"
            )
        reach = 2.0 * problem.lower[i_l] * math.cos(hi_a)
        if self.stroke > reach:
            raise ParameterError(
                f"stroke = {self.stroke:g} m is out of reach at the box corner rod_length = {problem.lower[i_l]:g} m, "
                f"min_transmission_angle = {hi_a:g} rad (largest stroke 2 L2 cos(alpha) = {reach:g} m); "
                "valid: raise the lower rod_length or lower the upper min_transmission_angle"
            )

    def describe(self, problem) -> str:
        return (
            f"design: {problem.n} variables, stroke {self.stroke * 1e3:g} mm, "
            f"transmission >= {self.min_transmission_deg:g} deg"
        )

    def default_start(self, problem, name, lo, hi) -> float:
        return 0.5 * (lo + hi) if name in ("min_transmission_angle", "rod_inertia_ratio") else None

    def physical(self, problem, x) -> tuple[list[str], list]:
        """crank_length, rod_length, offset and (with ``rod_inertia_ratio``) rod_inertia at SI
        design ``x`` (traceable)."""
        get = lambda nm: x[problem.names.index(nm)]
        l2 = get("rod_length")
        l1, e = crank_and_offset(l2, get("min_transmission_angle"), self.stroke)
        names, values = ["crank_length", "rod_length", "offset"], [l1, l2, e]
        if "rod_inertia_ratio" in problem.names:
            m2 = get("rod_mass") if "rod_mass" in problem.names else problem.base.rod_mass
            names.append("rod_inertia")
            values.append(get("rod_inertia_ratio") * m2 * l2**2)
        return names, values

    def constraints(self, problem, x) -> dict:
        """``stroke_m``, ``stroke_error_m``, ``min_transmission_angle_deg``, ``assembly_margin_m``
        (``L2 - L1 - |e|``) and the derived ``crank_length_m``, ``rod_length_m``, ``offset_m`` at
        SI design(s) ``x`` (..., n), numpy, in closed form."""
        xs = jnp.atleast_2d(jnp.asarray(x, dtype=float))
        i_l, i_a = problem.names.index("rod_length"), problem.names.index("min_transmission_angle")
        l2 = xs[:, i_l]
        l1, e = jax.vmap(lambda a, b: crank_and_offset(a, b, self.stroke))(l2, xs[:, i_a])
        s = ideal_stroke(l1, l2, e)
        out = {
            "stroke_m": s,
            "stroke_error_m": s - self.stroke,
            "min_transmission_angle_deg": jnp.degrees(min_transmission_angle(l1, l2, e)),
            "assembly_margin_m": l2 - l1 - jnp.abs(e),
            "crank_length_m": l1,
            "rod_length_m": l2,
            "offset_m": e,
        }
        shape = np.shape(x)[:-1]
        return {k: np.asarray(v).reshape(shape) for k, v in out.items()}

    def feasible(self, problem, x, c) -> np.ndarray:
        return (
            (np.abs(c["stroke_error_m"]) <= self.stroke_tolerance)
            & (c["min_transmission_angle_deg"] >= self.min_transmission_deg - 1e-9)
            & (c["assembly_margin_m"] > 0)
        )


# ---------------------------------------------------------------------------------------- crank-rocker

#: the crank-rocker reparametrisation's variables (name -> SI unit)
ROCKER_VARIABLES = {
    "coupler_length": "m",
    "rocker_length": "m",
    "min_transmission_angle": "rad",
    "max_transmission_angle": "rad",
}
#: the links whose length it sets (their masses and inertias scale with ``scale_links``)
LINKS = ("crank", "coupler", "rocker")


def transmission_extremes(a, b, c, d):
    """Smallest and largest transmission angle of the ideal four-bar over a revolution, rad:
    ``arccos((b^2 + c^2 - (d -+ a)^2) / (2 b c))`` (lengths a crank, b coupler, c rocker, d
    ground, m; a crank-rocker)."""
    two_bc = 2.0 * b * c
    low = jnp.arccos(jnp.clip((b**2 + c**2 - (d - a) ** 2) / two_bc, -1.0, 1.0))
    high = jnp.arccos(jnp.clip((b**2 + c**2 - (d + a) ** 2) / two_bc, -1.0, 1.0))
    return low, high


def crank_and_ground(b, c, mu_0, mu_pi):
    """Crank and ground lengths (m) of the crank-rocker with coupler ``b`` and rocker ``c`` (m)
    whose transmission angle runs over ``[mu_0, mu_pi]`` (rad). Traceable."""
    e_0 = jnp.sqrt(b**2 + c**2 - 2.0 * b * c * jnp.cos(mu_0))
    e_pi = jnp.sqrt(b**2 + c**2 - 2.0 * b * c * jnp.cos(mu_pi))
    return 0.5 * (e_pi - e_0), 0.5 * (e_pi + e_0)


def grashof_margins(a, b, c, d):
    """Grashof's crank-rocker condition as three margins, each >= 0 when met (m)."""
    return c + d - a - b, b + d - a - c, b + c - a - d


@dataclasses.dataclass(frozen=True)
class CrankRocker:
    """The four-bar's crank-rocker reparametrisation (module docstring).

    Attributes:
        min_transmission_deg: the transmission angle stays within
            ``[min_transmission_deg, 180 - min_transmission_deg]`` deg, in (0, 90).
        scale_links: each link's mass scales with its length and its inertia with mass x
            length^2 (True), or they stay the base's (False).

    Variables: any of `ROCKER_VARIABLES` (those left out stay at the base's values);
    ``crank_length``, ``ground_length``, ``driver.*`` and, with ``scale_links``, the links'
    masses and inertias cannot be variables beside them.
    """

    min_transmission_deg: float = 40.0
    scale_links: bool = True

    kind = "crank_rocker"
    OWNED = ROCKER_VARIABLES

    def check_variable(self, name: str) -> None:
        if name in ("crank_length", "ground_length") or name.startswith("driver."):
            raise ParameterError(
                f"{name!r} cannot be a variable with the crank-rocker reparametrisation: crank_length and "
                f"ground_length follow from {', '.join(ROCKER_VARIABLES)}; the driver fixes the objective's sample grid"
            )
        if self.scale_links and name in {f"{k}_{q}" for k in LINKS for q in ("mass", "inertia")}:
            raise ParameterError(f"{name!r} follows from the link lengths (scale_links = true); set scale_links false")

    def base_geometry(self, problem) -> dict[str, float]:
        """The reparametrisation's values of the base mechanism (SI)."""
        a, b, c, d = (
            float(get_parameter(problem.base, f"{k}_length")) for k in ("crank", "coupler", "rocker", "ground")
        )
        with jax.ensure_compile_time_eval():
            low, high = transmission_extremes(a, b, c, d)
        return {
            "coupler_length": b,
            "rocker_length": c,
            "min_transmission_angle": float(low),
            "max_transmission_angle": float(high),
        }

    def check(self, problem) -> None:
        if not isinstance(problem.base, FourBar):
            raise ParameterError(
                f"the crank-rocker reparametrisation needs a four-bar base (jaxcrank.FourBar), not "
                f"{type(problem.base).__name__}"
            )
        if not 0.0 < self.min_transmission_deg < 90.0:
            raise ParameterError(f"min_transmission_deg = {self.min_transmission_deg:g} must be in (0, 90) deg")
        bound, fixed = math.radians(self.min_transmission_deg), self.base_geometry(problem)
        lo0, hi0 = _range(problem, "min_transmission_angle", fixed)
        lo_pi, hi_pi = _range(problem, "max_transmission_angle", fixed)
        if lo0 < bound - 1e-12 or hi_pi > math.pi - bound + 1e-12 or not hi0 < lo_pi:
            raise ParameterError(
                f"min_transmission_angle in [{lo0:g}, {hi0:g}] rad and max_transmission_angle in "
                f"[{lo_pi:g}, {hi_pi:g}] rad must satisfy {bound:g} <= min_transmission_angle < "
                f"max_transmission_angle <= {math.pi - bound:g} rad (min_transmission_deg = "
                f"{self.min_transmission_deg:g}; the upper bound of the first below the lower bound of the second)"
            )
        for name in ("coupler_length", "rocker_length"):
            if _range(problem, name, fixed)[0] <= 0.0:
                raise ParameterError(f"bounds of {name} must be > 0 m")

    def describe(self, problem) -> str:
        return f"four-bar: {problem.n} variables, transmission within {self.min_transmission_deg:g} deg of its limits"

    def default_start(self, problem, name, lo, hi) -> float:
        return self.base_geometry(problem)[name]

    def physical(self, problem, x) -> tuple[list[str], list]:
        """The four lengths and (``scale_links``) the links' masses and inertias at SI design
        ``x`` (traceable)."""
        fixed = self.base_geometry(problem)
        geo = {k: x[problem.names.index(k)] if k in problem.names else jnp.asarray(fixed[k]) for k in ROCKER_VARIABLES}
        b, c = geo["coupler_length"], geo["rocker_length"]
        a, d = crank_and_ground(b, c, geo["min_transmission_angle"], geo["max_transmission_angle"])
        names = ["crank_length", "coupler_length", "rocker_length", "ground_length"]
        values = [a, b, c, d]
        if self.scale_links:
            for link, length in {"crank": a, "coupler": b, "rocker": c}.items():
                ratio = length / get_parameter(problem.base, f"{link}_length")
                names += [f"{link}_mass", f"{link}_inertia"]
                values += [
                    get_parameter(problem.base, f"{link}_mass") * ratio,
                    get_parameter(problem.base, f"{link}_inertia") * ratio**3,
                ]
        return names, values

    def constraints(self, problem, x) -> dict:
        """``crank_length_m``, ``coupler_length_m``, ``rocker_length_m``, ``ground_length_m``,
        ``grashof_margin_m`` (the smallest of [`grashof_margins`][optim.geometry.grashof_margins])
        and the transmission angle's extremes (deg), recomputed from the derived lengths at SI
        design(s) ``x`` (..., n), numpy."""
        xs = np.atleast_2d(np.asarray(x, dtype=float))
        rows = [dict(zip(*problem.physical(row))) for row in xs]
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

    def feasible(self, problem, x, c) -> np.ndarray:
        return (
            (c["grashof_margin_m"] > 0.0)
            & (c["min_transmission_angle_deg"] >= self.min_transmission_deg - 1e-9)
            & (c["max_transmission_angle_deg"] <= 180.0 - self.min_transmission_deg + 1e-9)
        )
