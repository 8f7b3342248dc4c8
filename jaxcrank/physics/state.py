"""The state vector of a mechanism with clearance joints and its scales.

The solver state is the *deviation from the ideal mechanism* in the tree's generalized
coordinates ([`jaxcrank.physics.topology.Tree`][]): s = q - q_ideal(phi), so s = 0 is the
ideal motion and pins centred in their holes. Every entry is dimensionless
([`state_scales`][jaxcrank.physics.state.state_scales]):

``y = (s, s', the joint laws' states (joint by joint, sorted), driver work, dissipated work)``.

Every function takes a compiled [`Model`][jaxcrank.physics.compiled.Model] (or a
mechanism, which it compiles first).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .compiled import Model, as_model
from .linkage import GROUND, AbstractMechanism, Linkage
from .safemath import div, known, mul, sqrt, stop_gradient, vdot, vsub

Mechanism = AbstractMechanism | Model


def n_dof(model: Mechanism) -> int:
    """Number of generalized coordinates s (static)."""
    return as_model(model).structure.n


def law_slices(model: Mechanism) -> dict[str, slice]:
    """Where each cut joint's law state sits in the state vector (static)."""
    return as_model(model).structure.law_slices


def law_state_names(model: Mechanism) -> tuple[str, ...]:
    """Names of the law state entries, ``<joint>.<entry>`` in state order (static)."""
    return as_model(model).structure.law_state_names


def state_size(model: Mechanism) -> int:
    """Length of the state vector (static): s, s', the law states, two works."""
    return as_model(model).structure.state_size


def state_names(model: Mechanism) -> tuple[str, ...]:
    """A name for every state entry (static): ``<body>.<coordinate>``, ``d/dt <body>.<coordinate>``,
    ``<joint>.<law entry>``, ``driver_work``, ``dissipated_work``."""
    return as_model(model).structure.state_names


class State(NamedTuple):
    """The entries of a state vector in SI units ([`unpack`][jaxcrank.physics.state.unpack]); each with the
    state's leading axes, if any."""

    deviation: jax.Array  # s, generalized-coordinate deviations from the ideal mechanism (m, rad)
    deviation_rate: jax.Array  # s', m/s and rad/s
    law_state: jax.Array  # the joint laws' states (law_state_names), SI
    driver_work: jax.Array  # work done by the driver, J
    dissipated_work: jax.Array  # work dissipated by the joint laws, J


def unpack(model: Mechanism, y: Float[ArrayLike, "*batch state"]) -> State:
    """The scaled state ``y`` (shape (..., [`state_size`][jaxcrank.physics.state.state_size])) as a
    [`State`][jaxcrank.physics.state.State] in SI units."""
    model = as_model(model)
    phys = y * state_scales(model)
    n = model.structure.n
    return State(phys[..., :n], phys[..., n : 2 * n], phys[..., 2 * n : -2], phys[..., -2], phys[..., -1])


def auxiliary(model: Mechanism, y: Float[ArrayLike, "*batch state"]) -> Float[Array, "*batch aux"]:
    """The state entries after the coordinates and their rates (the law states, then
    driver and dissipated work), in SI units."""
    model = as_model(model)
    return (y * state_scales(model))[..., 2 * model.structure.n :]


def _largest(values):
    """The largest of some scalars (a number when they all are)."""
    out = values[0]
    for v in values[1:]:
        out = max(out, v) if known(out) and known(v) else jnp.maximum(out, v)
    return out


def _length_scale(model: Model):
    lk = model.linkage
    clearances = [lk.joints[j].clearance for j in model.tree.cut]
    return stop_gradient(_largest(clearances)) if clearances else 1.0


def length_scale(model: Mechanism) -> Float[Array, ""]:
    """Reference length of the deviations, m: the largest clearance of a cut joint (1 m if none)."""
    return jnp.asarray(_length_scale(as_model(model)), dtype=float)


def body_sizes(lk: Linkage) -> dict[str, Array]:
    """Each body's size, m: the largest distance between two of its points and its
    centre of mass (stop-gradient; it only scales angles). A body with a single point
    takes the largest size of the others."""
    sizes = {}
    for name, body in lk.bodies.items():
        pts = [p.pair() for p in body.points.values()] + [body.centre_of_mass.pair()]
        d = [sqrt(vdot(vsub(a, b), vsub(a, b))) for i, a in enumerate(pts) for b in pts[i + 1 :]]
        sizes[name] = stop_gradient(_largest(d)) if d else 0.0
    biggest = _largest(list(sizes.values()))
    return {k: v if known(v) and v > 0.0 else jnp.where(v > 0.0, v, biggest) for k, v in sizes.items()}


def reference_momentum(lk: Linkage) -> Array:
    """Mass times length that scales the works, kg m: the driven body's size times the
    largest mass jointed to it (the coupler's, in a slider-crank or four-bar)."""
    driven = lk.driver.body
    neighbours = {
        s.body for c in lk.connections.values() if driven in {t.body for t in c.sites()} for s in c.sites()
    } - {driven, GROUND}
    masses = [lk.bodies[b].mass for b in sorted(neighbours)] or [lk.bodies[driven].mass]
    return stop_gradient(mul(_largest(masses), body_sizes(lk)[driven]))


def scales(model: Model) -> list:
    """[`state_scales`][jaxcrank.physics.state.state_scales] as a list of scalars (numbers
    where the model's values are)."""
    lk, tree = model.linkage, model.tree
    ell = _length_scale(model)
    omega = stop_gradient(lk.driver.speed_scale)
    sizes = body_sizes(lk)
    q = [div(ell, sizes[b]) if kind == "angle" else ell for b, kind in tree.coordinates]
    laws = [s for j in tree.cut for s in lk.joints[j].state_scales(mul(ell, omega))]
    work = mul(mul(mul(reference_momentum(lk), omega), ell), omega)
    return [*q, *(mul(v, omega) for v in q), *laws, work, work]


def state_scales(model: Mechanism) -> Float[Array, " state"]:
    """Physical value of one unit of each state entry.

    Lengths in clearances l, angles in l / (the body's size) rad, rates in those times
    the driver's nominal speed omega, law states as each law declares (the approach-speed
    memory in l omega m/s), work in (mass x length) omega x l omega J
    ([`reference_momentum`][jaxcrank.physics.state.reference_momentum]). The scales carry no gradient: they only
    condition the error control, so a scalar ``rtol``/``atol`` means the same for every
    entry and every mechanism.
    """
    return jnp.stack([jnp.asarray(v, dtype=float) for v in scales(as_model(model))])


def initial_state(model: Mechanism) -> Float[Array, " state"]:
    """Pins centred and moving with the ideal mechanism; law states at their initial
    values; works zero."""
    model = as_model(model)
    lk, tree = model.linkage, model.tree
    laws = [lk.joints[j].initial_state() for j in tree.cut]
    laws = jnp.concatenate(laws) if laws else jnp.zeros(0)
    phys = jnp.concatenate([jnp.zeros(2 * tree.n), laws, jnp.zeros(2)])
    return phys / state_scales(model)
