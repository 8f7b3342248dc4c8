"""The ideal mechanism assembled over a turn: the warm starts of its root finds
([`group_guesses`][jaxcrank.physics.assembly.group_guesses]) and the check that it can be
assembled at the driver's initial angle and, driven at a prescribed angle, over a whole
turn ([`check_assembly`][jaxcrank.physics.assembly.check_assembly]).
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from .closure import discriminants, group_frames, ideal_frames
from .linkage import Linkage
from .params import ParameterError
from .safemath import known
from .topology import Group, Plan

#: the warm starts of the ideal mechanism's groups: poses at this many driver angles a turn
GUESS_SAMPLES = 360


def group_guesses(lk: Linkage, plan: Plan, step: Group, signs, earlier=()):
    """The poses of the group ``step`` of the ideal plan at `GUESS_SAMPLES` driver angles
    over a turn from the initial angle, shape (samples, 3 bodies): the warm starts of its
    Newton's method, followed from its bodies' ``guess`` poses by continuation
    (stop-gradient). ``signs`` and ``earlier`` are the branches of the dyads and the warm
    starts of the groups before it.

    Raises:
        ParameterError: a body of the group without a ``guess`` pose.
    """
    missing = [b for b in step.bodies if lk.bodies[b].guess is None]
    if missing:
        raise ParameterError(
            f"bodies {', '.join(missing)} are placed by a root find (no dyad closes their loop): give each a "
            "guess pose [x, y, angle] at the driver's initial angle (`jaxcrank assemble` helps find one)"
        )
    start = jnp.concatenate([lk.bodies[b].guess.vector() for b in step.bodies])
    return jax.lax.stop_gradient(_continuation(lk, plan, step, tuple(signs), tuple(earlier), start))


@functools.partial(jax.jit, static_argnums=(1, 2))
def _continuation(lk, plan: Plan, step: Group, signs, earlier, start):
    """The poses of ``step``'s bodies over a turn, each Newton solve started from the last."""
    phi0 = lk.driver.initial_angle
    angles = phi0 + 2.0 * math.pi * jnp.arange(GUESS_SAMPLES, dtype=float) / GUESS_SAMPLES
    before = Plan(plan.driven, plan.pivot, plan.steps[: plan.steps.index(step)])

    def at(x, phi):
        frames = group_frames(lk, step, ideal_frames(lk, before, phi, signs[: len(before.dyads)], earlier), x)
        return jnp.concatenate([frames[b].pose() for b in step.bodies])

    def follow(x, phi):
        x = at(x, phi)
        return x, x

    return jax.lax.scan(follow, at(start, phi0), angles)[1]


def check_assembly(lk: Linkage, plan: Plan, signs, samples: int = 360) -> None:
    """Raise a [`ParameterError`][jaxcrank.physics.params.ParameterError] when the linkage
    (its values numbers, not traced) cannot be assembled at its driver's initial angle,
    or (for a prescribed driver) locks before a full turn. The dyads are evaluated in
    NumPy over the turn; a plan with groups is checked at its dyads before the first group.

    Raises:
        ParameterError: naming the dyad's joints and the angle; or the driven body's joints, when
            every one of them sits on its ground pivot (a crank of zero length turns alone).
    """
    _check_crank_length(lk, plan)
    dyads = []
    for step in plan.steps:
        if isinstance(step, Group):
            break
        dyads.append(step)
    if not dyads:
        return
    lk = jax.tree_util.tree_map(lambda leaf: _host_number(leaf), lk)  # NumPy: nothing is compiled
    head = Plan(plan.driven, plan.pivot, tuple(dyads))
    batch = max((np.ndim(leaf) for leaf in jax.tree_util.tree_leaves(lk)), default=0)
    phi0 = float(np.max(lk.driver.initial_angle))
    phis = phi0 + 2.0 * np.pi * np.arange(samples if lk.driver.prescribed else 1) / samples
    signs = tuple(np.asarray(s, dtype=float) if not known(s) else s for s in signs[: len(dyads)])
    discs = discriminants(lk, head, phis.reshape((-1,) + (1,) * batch), signs)
    shape = np.broadcast_shapes((phis.size,) + (1,) * batch, *(np.shape(d) for d in discs))
    table = np.stack([np.broadcast_to(np.asarray(d, dtype=float), shape) for d in discs], axis=1)
    ok = np.all(table >= 0.0, axis=tuple(range(2, table.ndim)))  # (angles, dyads)
    for step, d in zip(dyads, ok[0]):
        if not d:
            raise ParameterError(
                f"the linkage cannot be assembled at its start angle {np.degrees(phi0):g} deg: the links of "
                f"joints {step.outer}, {step.middle}, {step.other} cannot reach each other (check the lengths)"
            )
    bad = np.argwhere(~ok)
    if bad.size:
        i, k = bad[0]
        step = dyads[k]
        raise ParameterError(
            f"the linkage locks at driver angle {np.degrees(phis[i]):.1f} deg: the links of joints "
            f"{step.outer}, {step.middle}, {step.other} cannot reach each other there, so the driven body "
            f"{lk.driver.body!r} cannot make a full turn (check the lengths)"
        )


def _check_crank_length(lk: Linkage, plan: Plan) -> None:
    """The driven body turning on its ground pivot must carry another joint off the pivot."""
    if plan.pivot is None:
        return
    sites = [site for c in lk.connections.values() for site in c.sites() if site.body == plan.driven]
    here = next(site.point for site in lk.connections[plan.pivot].sites() if site.body == plan.driven)
    others = sorted({site.point for site in sites if site.point != here})
    points = lk.bodies[plan.driven].points

    def distance(name):
        a, b = points[name], points[here]
        return np.hypot(np.asarray(a.x, dtype=float) - np.asarray(b.x), np.asarray(a.y, dtype=float) - np.asarray(b.y))

    if others and all(np.any(distance(p) == 0.0) for p in others):
        raise ParameterError(
            f"the driven body {plan.driven!r}: its point(s) {', '.join(others)} sit on its ground pivot "
            f"{here!r} (distance 0 m), so it turns without moving the linkage (a crank of zero length): "
            "move them off the pivot"
        )


def _host_number(leaf):
    value = np.asarray(leaf, dtype=float)
    return float(value) if value.ndim == 0 else value
