"""Many-variable design problems with nonlinear constraints held at every iterate.

A [`DesignProblem`][optim.design.DesignProblem] is a problem ([`AbstractProblem`][optim.problem.AbstractProblem]) whose
geometry is
reparametrised so that the mechanism-design constraints become bounds of the
design box, which the optimiser's projection (and any box-bounded baseline)
already keeps:

- **stroke** ``S = sqrt((L1 + L2)^2 - e^2) - sqrt((L2 - L1)^2 - e^2)`` of the ideal
  mechanism (closed form, the slider's distance between the two dead centres)
  held at ``stroke`` (m);
- **minimum transmission angle** of the ideal mechanism,
  ``alpha_min = arccos((L1 + |e|) / L2)`` (closed form: the crank angle where the
  slider line is farthest from the crank pin), at least ``min_transmission_deg``;
- **assemblability** ``L2 >= L1 + |e|`` (full crank rotation), implied by
  ``alpha_min > 0``.

The geometry's design variables are the rod length ``rod_length`` (L2, m) and the
minimum transmission angle ``min_transmission_angle`` (rad). With
``a = L1 + e = L2 cos(alpha_min)`` fixed, the stroke is strictly increasing in
``d = L1 - e`` on ``(-a, a]``,
``S(d) = sqrt((L2 + a)(L2 + d)) - sqrt((L2 - a)(L2 - d))``, from 0 to ``2 a``; so
the crank length and offset ``L1 = (a + d) / 2``, ``e = (a - d) / 2 >= 0`` follow from
a monotone 1-D solve (bisection to machine precision, then one Newton step whose
derivative is the implicit function theorem's: first derivatives exact). Every
design in the box has the target stroke exactly (to rounding), ``alpha_min`` in
its bounds (lower bound >= 40 deg) and ``L2 - L1 - e = L2 (1 - cos alpha_min) > 0``,
provided ``stroke <= 2 L2 cos(alpha_max)`` at the smallest L2 (checked).

Inertia: ``rod_inertia_ratio`` (dimensionless) sets ``J2 = ratio * m2 * L2^2``, the rod's
inertia about its centre of mass for its mass and length (a uniform bar is 1/12;
a rod with heavy bearing bosses at both ends more, up to the dumbbell's 1/4).
Bounding the ratio keeps J2 physically consistent with the rod's mass and length.

Objective (degrees, the Eq. 19 unit): Eq. 19 plus weighted terms from the same
simulation, ``sum_i w_i m_i + cost``, the metrics ``m_i`` in `TERMS` and
the weights ``w_i`` in degrees per metric unit, plus the reciprocal clearance
cost of [`cost`][optim.problem.AbstractProblem.cost]. All terms are RMS values over the evaluation window
(time averages of squares), so the ensemble gradient applies to each (the windows'
sums of squares come from [`optim.sensitivity.window_sums`][]).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from jaxcrank.physics.compiled import compile_model
from jaxcrank.physics.parameters import get_parameter, set_parameters
from jaxcrank.physics.params import ParameterError
from jaxcrank.physics.presets import SliderCrank, paper

from .objective import EQ19, AbstractObjective, safe_sqrt
from .problem import AbstractProblem, known_parameter
from .steady import Steady

#: design variables that are not mechanism fields (name -> SI unit)
DERIVED = {"min_transmission_angle": "rad", "rod_inertia_ratio": "1"}

#: objective terms (name -> meaning); units in the suffix
TERMS = {
    "rms_transmission_angle_error_deg": "RMS of actual - ideal transmission angle (paper Eq. 19), weight 1",
    "rms_rod_x_deviation_m": "RMS of rod-centre x - ideal",
    "rms_slider_x_deviation_m": "RMS of slider x - ideal (the slider's positioning accuracy)",
    "rms_driving_moment_deviation_N_m": "RMS of driving moment - ideal driving moment (clearance-induced fluctuation)",
    "rms_contact_force_N": "RMS normal contact force over the clearance joints (bearing wear proxy)",
}


def ideal_stroke(l1, l2, e):
    """Ideal slider stroke (distance between the dead centres), m:
    ``sqrt((L1 + L2)^2 - e^2) - sqrt((L2 - L1)^2 - e^2)``. Needs ``L2 > L1 + |e|``."""
    return jnp.sqrt((l2 + l1) ** 2 - e**2) - jnp.sqrt((l2 - l1) ** 2 - e**2)


def min_transmission_angle(l1, l2, e):
    """Ideal mechanism's minimum transmission angle, rad: ``arccos((L1 + |e|) / L2)``
    (the transmission angle ``arccos((L1 sin theta1 - e) / L2)`` folded to (0, 90] deg,
    smallest over a revolution). Needs ``L2 > L1 + |e|``."""
    return jnp.arccos((l1 + jnp.abs(e)) / l2)


def _stroke_in_d(l2, a, d):
    return jnp.sqrt((l2 + a) * (l2 + d)) - jnp.sqrt((l2 - a) * (l2 - d))


def _stroke_in_d_slope(l2, a, d):
    return 0.5 * (jnp.sqrt((l2 + a) / (l2 + d)) + jnp.sqrt((l2 - a) / (l2 - d)))


def geometry(l2, alpha, stroke, iterations: int = 64):
    """Crank length L1 and offset e (m) with rod length ``l2`` (m), minimum
    transmission angle ``alpha`` (rad, in (0, pi/2)) and ideal stroke ``stroke`` (m).

    Solves ``S(d) = stroke`` for ``d = L1 - e`` on ``[-a, a]``, ``a = l2 cos(alpha)``
    (S strictly increasing there) by bisection, then one Newton step through which
    the derivative is the implicit function's: ``dd/dp = -(dS/dp) / (dS/dd)``.
    Needs ``0 < stroke <= 2 a`` (the caller checks it on concrete bounds); traceable."""
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


def terms(rms: dict, joints: Sequence[str]) -> dict[str, Float[Array, ""]]:
    """The `TERMS` (name -> value in the unit of its name) from the RMS metrics of
    an objective ([`optim.objective.AbstractObjective.rms`][]), by name: the contact
    force term is the RMS over the clearance ``joints`` (the paper's B and C),
    ``sqrt(mean_j F_j^2)``."""
    out = {k: rms[k] for k in TERMS if k != "rms_contact_force_N"}
    out["rms_contact_force_N"] = safe_sqrt(sum(rms[f"rms_contact_force_{j}_N"] ** 2 for j in joints) / len(joints))
    return out


@dataclasses.dataclass(frozen=True)
class DesignProblem(AbstractProblem):
    """A problem over a reparametrised geometry with the stroke, transmission and
    assembly constraints built into its box (module docstring).

    Attributes (besides [`AbstractProblem`][optim.problem.AbstractProblem]'s):
        stroke: target ideal slider stroke, m (held exactly by the reparametrisation;
            the tolerance band below is what the tests and reports check).
        stroke_tolerance: allowed stroke error, m (0.1 mm).
        min_transmission_deg: smallest allowed minimum transmission angle, deg.
        weights: ``(term, weight)`` pairs for the `TERMS` besides Eq. 19 (which
            has weight 1), weight in degrees per unit of the term.

    Variable names: ``rod_length`` and ``min_transmission_angle`` (both required),
    ``rod_inertia_ratio`` (optional, then ``rod_inertia`` is derived), and any other
    name [`jaxcrank.physics.parameters.set_parameter`][] accepts except ``crank_length``,
    ``offset``, ``rod_inertia`` and ``driver.*`` (derived or fixing the sample grid).
    The base must be a [`jaxcrank.SliderCrank`][jaxcrank.physics.presets.SliderCrank].

    In [`optim.optimize.optimize`][]'s history, ``objective_without_cost_deg`` is the
    objective minus the cost term: the weighted sum of all `TERMS`, not Eq. 19 alone.
    """

    stroke: float = 0.240
    stroke_tolerance: float = 1e-4
    min_transmission_deg: float = 40.0
    weights: tuple[tuple[str, float], ...] = ()

    def check_variable(self, name: str) -> None:
        if name in ("crank_length", "offset") or name.startswith("driver."):
            raise ParameterError(
                f"{name!r} cannot be a DesignProblem variable: crank_length and offset "
                "follow from the stroke (the geometry's variables are rod_length and min_transmission_angle), "
                "the driver fixes the objective's sample grid"
            )
        if name not in DERIVED:
            known_parameter(self.base, name)

    def check(self) -> None:
        if not isinstance(self.base, SliderCrank):
            raise ParameterError(
                f"a DesignProblem's base must be a slider-crank (jaxcrank.SliderCrank), not {type(self.base).__name__}"
            )
        for req in ("rod_length", "min_transmission_angle"):
            if req not in self.names:
                raise ParameterError(
                    f"a DesignProblem needs the variable {req!r} (its geometry is "
                    "parametrised by rod_length and min_transmission_angle)"
                )
        if "rod_inertia" in self.names and "rod_inertia_ratio" in self.names:
            raise ParameterError("give rod_inertia or rod_inertia_ratio, not both")
        if not self.stroke > 0:
            raise ParameterError(f"stroke = {self.stroke:g} m must be > 0")
        if not 0 < self.min_transmission_deg < 90:
            raise ParameterError(f"min_transmission_deg = {self.min_transmission_deg:g} must be in (0, 90) deg")
        i_a, i_l = self.names.index("min_transmission_angle"), self.names.index("rod_length")
        lo_a, hi_a = self.lower[i_a], self.upper[i_a]
        if lo_a < math.radians(self.min_transmission_deg) - 1e-12 or hi_a >= math.pi / 2:
            raise ParameterError(
                f"bounds of min_transmission_angle = [{lo_a:g}, {hi_a:g}] rad must lie in "
                f"[{math.radians(self.min_transmission_deg):g}, {math.pi / 2:g}) rad "
                f"(min_transmission_deg = {self.min_transmission_deg:g})"
            )
        reach = 2.0 * self.lower[i_l] * math.cos(hi_a)
        if self.stroke > reach:
            raise ParameterError(
                f"stroke = {self.stroke:g} m is out of reach at the box corner rod_length = {self.lower[i_l]:g} m, "
                f"min_transmission_angle = {hi_a:g} rad (largest stroke 2 L2 cos(alpha) = {reach:g} m); "
                "valid: raise the lower rod_length or lower the upper min_transmission_angle"
            )
        for entry in self.weights:
            if len(entry) != 2 or entry[0] not in TERMS or entry[0] == EQ19:
                raise ParameterError(
                    f"weights entry {entry!r} must be (term, weight) with term one of {list(TERMS)[1:]}"
                )
            if not entry[1] >= 0:
                raise ParameterError(f"weight of {entry[0]} = {entry[1]:g} must be >= 0")
        if len({e[0] for e in self.weights}) != len(self.weights):
            raise ParameterError("weights names a term twice")

    @property
    def description(self) -> str:
        """``title``, or else the number of variables, the stroke and the transmission-angle floor."""
        return self.title or (
            f"design: {self.n} variables, stroke {self.stroke * 1e3:g} mm, "
            f"transmission >= {self.min_transmission_deg:g} deg"
        )

    # ------------------------------------------------------------------ model
    def weight_of(self) -> dict[str, float]:
        """Weight of each of the `TERMS`, degrees per unit of the term (Eq. 19: 1)."""
        w = dict(self.weights)
        return {t: 1.0 if t == EQ19 else float(w.get(t, 0.0)) for t in TERMS}

    def _get(self, x, name, default):
        return x[self.names.index(name)] if name in self.names else default

    def physical(self, x):
        """Mechanism parameter names and their values (SI, traceable) at design ``x``:
        the direct variables, then crank_length, rod_length, offset and (with
        ``rod_inertia_ratio``) rod_inertia."""
        x = jnp.asarray(x, dtype=float)
        names = [nm for nm in self.names if nm not in DERIVED and nm != "rod_length"]
        values = [x[self.names.index(nm)] for nm in names]
        l2 = x[self.names.index("rod_length")]
        l1, e = geometry(l2, x[self.names.index("min_transmission_angle")], self.stroke)
        names += ["crank_length", "rod_length", "offset"]
        values += [l1, l2, e]
        if "rod_inertia_ratio" in self.names:
            m2 = self._get(x, "rod_mass", self.base.rod_mass)
            names.append("rod_inertia")
            values.append(x[self.names.index("rod_inertia_ratio")] * m2 * l2**2)
        return tuple(names), jnp.stack(values)

    def mechanism(self, x):
        names, values = self.physical(x)
        return set_parameters(self.base, names, values)

    def default_start(self) -> list[float]:
        return [
            0.5 * (lo + hi) if nm in DERIVED else float(get_parameter(self.base, nm))
            for nm, lo, hi in zip(self.names, self.lower, self.upper)
        ]

    def constraints(self, x) -> dict:
        """The nonlinear constraints at SI design(s) ``x`` (..., n), numpy: ``stroke_m``,
        ``stroke_error_m`` (vs ``stroke``), ``min_transmission_angle_deg`` and
        ``assembly_margin_m`` (``L2 - L1 - |e|``, > 0 when assemblable), each
        computed in closed form from the derived L1, L2, e (``crank_length_m``,
        ``rod_length_m``, ``offset_m``)."""
        xs = jnp.atleast_2d(jnp.asarray(x, dtype=float))
        i_l, i_a = self.names.index("rod_length"), self.names.index("min_transmission_angle")
        l2 = xs[:, i_l]
        l1, e = jax.vmap(lambda a, b: geometry(a, b, self.stroke))(l2, xs[:, i_a])
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

    def feasible(self, x, tol=1e-12):
        """Bounds, linear constraints and the nonlinear constraints (stroke within
        ``stroke_tolerance``, minimum transmission angle, assemblability)."""
        ok = self.box_feasible(x, tol)
        c = self.constraints(x)
        return (
            ok
            & (np.abs(c["stroke_error_m"]) <= self.stroke_tolerance)
            & (c["min_transmission_angle_deg"] >= self.min_transmission_deg - 1e-9)
            & (c["assembly_margin_m"] > 0)
        )

    # ------------------------------------------------------------------ objective
    def terms(self, x) -> dict[str, Float[Array, ""]]:
        """`TERMS` at SI design ``x`` by the problem's objective (name -> value)."""
        return terms(self.objective.rms(self.mechanism(x)), self.clearance_joints)

    @property
    def clearance_joints(self) -> tuple[str, ...]:
        """The base mechanism's clearance joints (the tree's cut joints), whose RMS contact
        forces make the ``rms_contact_force_N`` term."""
        return compile_model(self.base).tree.cut

    def loss(self, rms: dict) -> Float[Array, ""]:
        w = self.weight_of()
        t = terms(rms, self.clearance_joints)
        return sum(w[k] * t[k] for k in TERMS)

    def objective_value(self, x):
        return self.loss(self.objective.rms(self.mechanism(x))) + self.cost(x)


#: the design preset's variables: (name, lower, upper, start), SI
DESIGN_VARIABLES = (
    ("rod_length", 0.360, 0.440, 0.400),
    ("min_transmission_angle", math.radians(40.0), math.radians(70.0), math.radians(60.0)),
    ("clearance_B", 1e-4, 5e-4, 4e-4),
    ("clearance_C", 1e-4, 5e-4, 4e-4),
    ("rod_mass", 1.0, 2.5, 1.5473),
    ("rod_inertia_ratio", 0.05, 0.125, 1.0 / 12.0),
    ("slider_mass", 1.0, 2.5, 1.7964),
    ("friction.coefficient", 0.02, 0.15, 0.1),
    ("hole_material.youngs_modulus", 100e9, 210e9, 207e9),
)

#: the design preset's term weights, degrees per unit of each term
DESIGN_WEIGHTS = (
    ("rms_slider_x_deviation_m", 10.0),
    ("rms_driving_moment_deviation_N_m", 2e-3),
    ("rms_contact_force_N", 2e-5),
)


def design_problem(
    objective: AbstractObjective | None = None,
    cost_weight: float = 0.005,
    start: Sequence[float] | None = None,
    variables: Sequence[str] | None = None,
    weights=DESIGN_WEIGHTS,
) -> DesignProblem:
    """A mechanism designer's problem with nine variables (`DESIGN_VARIABLES`):
    rod length 360-440 mm and minimum transmission angle 40-70 deg (crank length
    and offset follow from the 240 mm stroke), radial clearances at B and C
    0.1-0.5 mm (with the reciprocal manufacturing cost, reference 0.5 mm), rod
    mass 1-2.5 kg, rod inertia ratio ``J2 / (m2 L2^2)`` 0.05-0.125 (a uniform bar
    is 1/12), slider mass 1-2.5 kg, the bearings' friction coefficient 0.02-0.15
    (lubricated to dry steel) and the rod bearings' Young's modulus 100-210 GPa
    (bronze to steel bushings; ``hole_material.youngs_modulus``, the rod being the hole at
    both clearance joints). Minimises Eq. 19 + `DESIGN_WEIGHTS` terms +
    cost. ``objective``: default the steady state ([`optim.steady.Steady`][], the
    terms over one period of the periodic orbit). ``variables``: a subset of the names
    (the others stay at their start values, folded into the base mechanism)."""
    unknown = set(variables or ()) - {v[0] for v in DESIGN_VARIABLES}
    if unknown:
        raise ParameterError(f"unknown design variables {sorted(unknown)}; valid: {[v[0] for v in DESIGN_VARIABLES]}")
    chosen = [v for v in DESIGN_VARIABLES if variables is None or v[0] in variables]
    base = paper()
    fixed = [v for v in DESIGN_VARIABLES if v not in chosen]
    direct = [(nm, x0) for nm, _, _, x0 in fixed if nm not in DERIVED]
    if direct:
        base = set_parameters(base, [d[0] for d in direct], [d[1] for d in direct])
    if "rod_inertia_ratio" not in [v[0] for v in chosen]:
        ratio = next(v[3] for v in DESIGN_VARIABLES if v[0] == "rod_inertia_ratio")
        l2 = next(v[3] for v in DESIGN_VARIABLES if v[0] == "rod_length")
        base = set_parameters(base, ["rod_inertia"], [ratio * float(base.rod_mass) * l2**2])
    has_clearance = any(v[0].startswith("clearance_") for v in chosen)
    return DesignProblem(
        base=base,
        names=tuple(v[0] for v in chosen),
        lower=tuple(v[1] for v in chosen),
        upper=tuple(v[2] for v in chosen),
        start=tuple(v[3] for v in chosen) if start is None else tuple(start),
        objective=Steady() if objective is None else objective,
        cost_weight=cost_weight if has_clearance else 0.0,
        cost_reference=5e-4,
        stroke=0.240,
        weights=tuple(weights),
    )
