"""The ideal mechanism (every joint ideal, every loop closed) as a function of the
driver's angle.

[`ideal_poses`][jaxcrank.physics.closure.ideal_poses] places the driven body on its ground pivot at the angle phi,
then follows the assembly [`Plan`][jaxcrank.physics.topology.Plan]:

- **dyads in closed form.** An RRR dyad (two bodies pinned to known bodies and to each
  other) puts their common pin at an intersection of two circles; an RRP dyad (one of
  them sliding on a known guide) at an intersection of a circle and a line. The slider-
  crank and the four-bar are one dyad each. Which intersection (the assembly mode) is
  chosen once, at the driver's initial angle, as the one nearer the bodies'
  ``guess`` poses (the first when there is none), and kept for every angle.
- **Newton's method** closes whatever the dyads do not reach: from the bodies' guesses
  at the initial angle, continued in steps to phi, then polished; its derivatives come
  from the implicit function theorem (``jax.custom_jvp``), so they are exact whatever
  the iterations did.

Everything is differentiable in the linkage's parameters and in phi, to any order; the
dyads also run on [`Jet`][jaxcrank.physics.safemath.Jet]s (a value with its first two time derivatives,
in one pass) and on NumPy arrays (the assembly check, over a whole turn at once).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .forward import GROUND_FRAME, Placed
from .linkage import GROUND, AbstractMechanism, Linkage, Prismatic
from .params import ParameterError, _concrete
from .safemath import (
    add,
    atan2,
    cos_sin,
    div,
    known,
    known_zero,
    mul,
    solve_dense,
    sqrt,
    stop_gradient,
    sub,
    vadd,
    vcross,
    vdot,
    vperp,
    vscale,
    vsub,
    vturn,
    where,
)
from .topology import Plan, Skeleton, plan_of, tree_of

#: Newton steps of the loop closure: continuation steps from the initial angle, and
#: iterations per step and at the end (quadratic convergence: a guess within a few
#: degrees of crank angle is polished to rounding in these).
CONTINUATION_STEPS = 24
ITERATIONS = 4


def _local(lk: Linkage, site) -> tuple:
    return (lk.ground if site.body == GROUND else lk.bodies[site.body].points)[site.point].pair()


def _site_world(lk: Linkage, frames: dict, site) -> tuple:
    return frames[site.body].point(_local(lk, site))


def _placed_by_point(world: tuple, local: tuple, angle, rot=None) -> Placed:
    """The frame of a body at ``angle`` (rotation ``rot``, default its cosine and sine)
    whose point ``local`` sits at ``world``."""
    rot = cos_sin(angle) if rot is None else rot
    return Placed(vsub(world, vturn(rot, local)), angle, rot)


def _turning(local: tuple, world: tuple, length) -> tuple:
    """The rotation (cos, sin) that turns the body vector ``local`` into the world vector
    ``world``, both of length ``length`` (a link of a dyad): no cosine of an arctangent."""
    scale = mul(length, length)
    return div(vdot(local, world), scale), div(vcross(local, world), scale)


def _other_site(conn, body):
    a, b = conn.sites()
    return (b, a) if a.body == body else (a, b)


def _slide_line(lk: Linkage, frames: dict, conn: Prismatic, body: str, local_point) -> tuple:
    """For ``body`` held by the prismatic ``conn`` to a known body: its angle, and the
    line ``B0 + lam d`` its point ``local_point`` moves on (B0, d), as pairs."""
    if conn.slider.body == body:  # it slides on a known guide
        guide = frames[conn.guide.body]
        angle = add(guide.angle, conn.angle)
        d_angle = add(guide.angle, conn.direction)
        g = _site_world(lk, frames, conn.guide)
        own = _local(lk, conn.slider)
    else:  # it is the guide, moving along a known slider
        slider = frames[conn.slider.body]
        angle = sub(slider.angle, conn.angle)
        d_angle = add(angle, conn.direction)
        g = _site_world(lk, frames, conn.slider)
        own = _local(lk, conn.guide)
    b0 = vadd(g, vturn(cos_sin(angle), vsub(local_point, own)))
    return angle, b0, cos_sin(d_angle)


def _sqrt_or_nan(x):
    ok = x >= 0.0
    return where(ok, sqrt(where(ok, x, 1.0)), math.nan)


def _length(v: tuple):
    """|v| of a body vector (a pair): |v_x| when v_y is known to be zero."""
    if known_zero(v[1]):
        return v[0] if known(v[0]) and v[0] >= 0 else sqrt(mul(v[0], v[0]))
    return sqrt(add(mul(v[0], v[0]), mul(v[1], v[1])))


def _dyad(lk: Linkage, frames: dict, step, sign) -> tuple[dict, object]:
    """Place the two bodies of one dyad; returns the new frames and the discriminant of
    its intersection (negative: it cannot be assembled)."""
    outer, middle, other = (lk.connections[j] for j in (step.outer, step.middle, step.other))
    u, v = step.first, step.second
    u_site, k1 = _other_site(outer, u)[::-1]
    p1 = _site_world(lk, frames, k1)
    a_u = _local(lk, u_site)
    m_u, m_v = (_other_site(middle, v)[0], _other_site(middle, u)[0])  # middle's site on u, on v
    b_u, b_v = _local(lk, m_u), _local(lk, m_v)
    link_u = vsub(b_u, a_u)
    r1 = _length(link_u)
    if step.kind == "RRR":
        v_site, k2 = _other_site(other, v)[::-1]
        p3 = _site_world(lk, frames, k2)
        c_v = _local(lk, v_site)
        link_v = vsub(b_v, c_v)
        r2 = _length(link_v)
        w = vsub(p3, p1)
        dist2 = vdot(w, w)
        along = (dist2 + r1 * r1 - r2 * r2) / (2.0 * dist2)
        disc = r1 * r1 / dist2 - along * along
        across = mul(sign, _sqrt_or_nan(disc))
        b = vadd(vadd(p1, vscale(along, w)), vscale(across, vperp(w)))
        arm_v = vsub(b, p3)
        angle_v = sub(atan2(arm_v[1], arm_v[0]), atan2(link_v[1], link_v[0]))
        frame_v = _placed_by_point(p3, c_v, angle_v, _turning(link_v, arm_v, r2))
    else:
        angle_v, b0, d = _slide_line(lk, frames, other, v, b_v)
        w = vsub(b0, p1)
        dw = vdot(d, w)
        disc = dw * dw - vdot(w, w) + r1 * r1
        lam = sub(mul(sign, _sqrt_or_nan(disc)), dw)
        b = vadd(b0, vscale(lam, d))
        frame_v = _placed_by_point(b, b_v, angle_v)
    arm_u = vsub(b, p1)
    angle_u = sub(atan2(arm_u[1], arm_u[0]), atan2(link_u[1], link_u[0]))
    out = dict(frames)
    out[u] = _placed_by_point(p1, a_u, angle_u, _turning(link_u, arm_u, r1))
    out[v] = frame_v
    return out, disc


def _driven_frame(lk: Linkage, plan: Plan, phi) -> Placed:
    conn = lk.connections[plan.pivot]
    body_site, ground_site = _other_site(conn, GROUND)
    return _placed_by_point(_local(lk, ground_site), _local(lk, body_site), phi)


def _guess_point(lk: Linkage, body: str, local) -> tuple | None:
    guess = lk.bodies[body].guess
    return None if guess is None else Placed.at((guess.x, guess.y), guess.angle).point(local)


def _dyad_chain(lk: Linkage, plan: Plan, phi, signs=None):
    """Frames ([`Placed`][jaxcrank.physics.forward.Placed]) after the dyads (and the
    discriminants); ``signs`` None: choose each dyad's branch by the bodies' guesses
    (returns the chosen signs). ``phi`` a number, an array (traced or NumPy, any shape)
    or a [`Jet`][jaxcrank.physics.safemath.Jet]."""
    frames = {GROUND: GROUND_FRAME, plan.driven: _driven_frame(lk, plan, phi)}
    discs, chosen = [], []
    for i, step in enumerate(plan.steps):
        if signs is not None:
            sign = signs[i]
        else:
            middle = lk.connections[step.middle]
            m_u = _other_site(middle, step.second)[0]
            m_v = _other_site(middle, step.first)[0]
            target = _guess_point(lk, step.first, _local(lk, m_u))
            if target is None:
                target = _guess_point(lk, step.second, _local(lk, m_v))
            if target is None:
                sign = 1.0
            else:
                plus, _ = _dyad(lk, frames, step, 1.0)
                minus, _ = _dyad(lk, frames, step, -1.0)
                gap_plus = vsub(plus[step.first].point(_local(lk, m_u)), target)
                gap_minus = vsub(minus[step.first].point(_local(lk, m_u)), target)
                nearer = vdot(gap_plus, gap_plus) <= vdot(gap_minus, gap_minus)
                sign = stop_gradient(where(nearer, 1.0, -1.0))
            chosen.append(sign)
        frames, disc = _dyad(lk, frames, step, sign)
        discs.append(disc)
    return frames, discs, chosen


def branch_signs(lk: Linkage, plan: Plan) -> tuple:
    """Each dyad's branch (+1 or -1), chosen at the driver's initial angle (numbers
    where the linkage's values are)."""
    if not plan.steps:
        return ()
    if all(lk.bodies[b].guess is None for st in plan.steps for b in (st.first, st.second)):
        return (1.0,) * len(plan.steps)
    return tuple(_dyad_chain(lk, plan, lk.driver.initial_angle)[2])


def ideal_frames(lk: Linkage, plan: Plan, phi, signs: tuple | None = None) -> dict[str, Placed]:
    """The ideal mechanism's body frames ([`Placed`][jaxcrank.physics.forward.Placed], and the ground's) at the
    driver angle ``phi`` (rad: a number, an array or a [`Jet`][jaxcrank.physics.safemath.Jet]), with the dyads'
    branches ``signs`` (default [`branch_signs`][jaxcrank.physics.closure.branch_signs]); bodies no dyad reaches
    by the loop-closure Newton solve (not for a Jet)."""
    signs = branch_signs(lk, plan) if signs is None else signs
    frames, _, _ = _dyad_chain(lk, plan, phi, signs)
    if plan.rest:
        known_poses = {b: f.pose() for b, f in frames.items() if b != GROUND}
        x = _closed(lk, plan, jnp.asarray(phi, dtype=float), known_poses)
        for i, body in enumerate(plan.rest):
            frames[body] = Placed.at((x[3 * i], x[3 * i + 1]), x[3 * i + 2])
    return frames


# --------------------------------------------------------------------------- Newton


def _frames_of(known: dict, plan: Plan, x) -> dict:
    frames = {b: Placed.at((p[0], p[1]), p[2]) for b, p in known.items()}
    frames[GROUND] = GROUND_FRAME
    for i, body in enumerate(plan.rest):
        frames[body] = Placed.at((x[3 * i], x[3 * i + 1]), x[3 * i + 2])
    return frames


def _rest_residual(lk, plan, known, x):
    frames = _frames_of(known, plan, x)
    out = []
    for j in plan.constraints:
        conn = lk.connections[j]
        if isinstance(conn, Prismatic):
            g = _site_world(lk, frames, conn.guide)
            s = _site_world(lk, frames, conn.slider)
            guide_angle = frames[conn.guide.body].angle
            out += [
                vcross(cos_sin(guide_angle + conn.direction), vsub(s, g)),
                frames[conn.slider.body].angle - guide_angle - conn.angle,
            ]
        else:
            out += list(vsub(_site_world(lk, frames, conn.hole), _site_world(lk, frames, conn.pin)))
    return jnp.stack([jnp.asarray(v, dtype=float) for v in out])


def _newton(lk, plan, known, x, iterations):
    for _ in range(iterations):
        r = _rest_residual(lk, plan, known, x)
        jac = jax.jacfwd(lambda z: _rest_residual(lk, plan, known, z))(x)
        x = x - solve_dense(jac, r)
    return x


def _rest_guess(lk: Linkage, plan: Plan) -> Array:
    missing = [b for b in plan.rest if lk.bodies[b].guess is None]
    if missing:
        raise ParameterError(
            f"bodies {', '.join(missing)} are not placed by a dyad: give each a guess pose (x, y, angle) "
            "at the driver's initial angle, for the loop-closure solve to start from"
        )
    return jnp.concatenate([lk.bodies[b].guess.vector() for b in plan.rest])


def _poses(frames: dict) -> dict:
    return {b: f.pose() for b, f in frames.items() if b != GROUND}


def _closed(lk: Linkage, plan: Plan, phi, known: dict) -> Array:
    """Poses of the bodies the dyads do not reach, by Newton's method, with exact
    derivatives by the implicit function theorem; ``known``: the other bodies' poses
    (x, y, angle) arrays by name."""

    @jax.custom_jvp
    def solve(lk_, phi_, known_):
        phi0 = lk_.driver.initial_angle
        signs = branch_signs(lk_, plan)
        x = jax.lax.stop_gradient(_rest_guess(lk_, plan))
        start, _, _ = _dyad_chain(lk_, plan, phi0, signs)
        x = _newton(lk_, plan, jax.lax.stop_gradient(_poses(start)), x, 2 * ITERATIONS)

        def step(i, x):
            a = phi0 + (phi_ - phi0) * (i + 1) / CONTINUATION_STEPS
            kn, _, _ = _dyad_chain(lk_, plan, a, signs)
            return _newton(lk_, plan, _poses(kn), x, ITERATIONS)

        x = jax.lax.fori_loop(0, CONTINUATION_STEPS, step, x)
        return jax.lax.stop_gradient(_newton(lk_, plan, known_, x, ITERATIONS))

    @solve.defjvp
    def solve_jvp(primals, tangents):
        lk_, phi_, known_ = primals
        x = solve(lk_, phi_, known_)
        jac = jax.jacfwd(lambda z: _rest_residual(lk_, plan, known_, z))(x)
        _, dr = jax.jvp(lambda lk2, k: _rest_residual(lk2, plan, k, x), (lk_, known_), (tangents[0], tangents[2]))
        return x, -solve_dense(jac, dr)

    return solve(lk, phi, known)


# --------------------------------------------------------------------------- public


def ideal_poses(mech: AbstractMechanism, phi: Float[ArrayLike, ""]) -> Float[Array, "bodies 3"]:
    """Frame poses (x, y in m; angle in rad) of every body of the ideal mechanism at the
    driver's angle ``phi`` (rad), in sorted body order (the order of every per-body
    array)."""
    lk = mech.linkage()
    sk = Skeleton.of(lk)
    frames = ideal_frames(lk, plan_of(sk), jnp.asarray(phi, dtype=float))
    return jnp.stack([frames[b].pose() for b in tree_of(sk).bodies])


def newton_poses(mech: AbstractMechanism, phi: Float[ArrayLike, ""]) -> Float[Array, "bodies 3"]:
    """The same poses as [`ideal_poses`][jaxcrank.physics.closure.ideal_poses], every body placed by the
    loop-closure Newton solve alone (no dyads): the reference the closed forms are tested
    against. Every body needs a ``guess``."""
    lk = mech.linkage()
    sk = Skeleton.of(lk)
    plan = plan_of(sk)
    bare = Plan(
        plan.driven,
        plan.pivot,
        (),
        tuple(b for b in sk.bodies if b != plan.driven),
        tuple(j for j in sorted(lk.connections) if j != plan.pivot),
    )
    phi = jnp.asarray(phi, dtype=float)
    poses = {plan.driven: _driven_frame(lk, bare, phi).pose()}
    x = _closed(lk, bare, phi, poses)
    for i, body in enumerate(bare.rest):
        poses[body] = x[3 * i : 3 * i + 3]
    return jnp.stack([poses[b] for b in sk.bodies])


def assembly_discriminants(mech: AbstractMechanism, phi: Float[ArrayLike, ""]) -> Float[Array, " dyads"]:
    """The discriminant of each dyad's intersection at ``phi`` (rad): negative where the
    dyad's links cannot reach (the linkage cannot be assembled there)."""
    lk = mech.linkage()
    plan = plan_of(Skeleton.of(lk))
    _, discs, _ = _dyad_chain(lk, plan, jnp.asarray(phi, dtype=float), branch_signs(lk, plan))
    return jnp.stack([jnp.asarray(d, dtype=float) for d in discs]) if discs else jnp.zeros(0)


def check_assembly(lk: Linkage, samples: int = 360) -> None:
    """Raise a [`ParameterError`][jaxcrank.physics.params.ParameterError] when the linkage cannot be assembled at
    its driver's initial angle, or (for a prescribed driver) locks before a full turn.
    Does nothing while any parameter is traced.

    Raises:
        ParameterError: naming the dyad's joints and the angle.
    """
    leaves = jax.tree_util.tree_leaves(lk)
    if any(_concrete(leaf) is None for leaf in leaves):
        return
    values = tuple(float(np.asarray(leaf)) if np.ndim(leaf) == 0 else tuple(np.ravel(leaf)) for leaf in leaves)
    _check_assembly_cached(lk, Skeleton.of(lk), values, samples)


_CHECKED: dict = {}


def _check_assembly_cached(lk: Linkage, sk: Skeleton, values: tuple, samples: int) -> None:
    key = (sk, jax.tree_util.tree_structure(lk), values, samples)
    if key in _CHECKED:
        return
    _check_assembly(lk, sk, samples)
    if len(_CHECKED) > 1024:
        _CHECKED.clear()
    _CHECKED[key] = True


def _host_number(leaf):
    value = np.asarray(leaf, dtype=float)
    return float(value) if value.ndim == 0 else value


def _check_assembly(lk: Linkage, sk: Skeleton, samples: int) -> None:
    plan = plan_of(sk)
    if not plan.steps:
        return
    lk = jax.tree_util.tree_map(_host_number, lk)  # numbers: the dyads evaluate in NumPy, nothing is compiled
    batch = max((np.ndim(leaf) for leaf in jax.tree_util.tree_leaves(lk)), default=0)
    phi0 = float(lk.driver.initial_angle)
    phis = phi0 + 2.0 * np.pi * np.arange(samples if lk.driver.prescribed else 1) / samples
    _, discs, _ = _dyad_chain(lk, plan, phis.reshape((-1,) + (1,) * batch), branch_signs(lk, plan))
    shape = np.broadcast_shapes((phis.size,) + (1,) * batch, *(np.shape(d) for d in discs))
    table = np.stack([np.broadcast_to(np.asarray(d, dtype=float), shape) for d in discs], axis=1)
    ok = np.all(table >= 0.0, axis=tuple(range(2, table.ndim)))  # (angles, dyads)
    for step, d in zip(plan.steps, ok[0]):
        if not d:
            raise ParameterError(
                f"the linkage cannot be assembled at its start angle {np.degrees(phi0):g} deg: the links of "
                f"joints {step.outer}, {step.middle}, {step.other} cannot reach each other (check the lengths)"
            )
    bad = np.argwhere(~ok)
    if bad.size:
        i, k = bad[0]
        step = plan.steps[k]
        raise ParameterError(
            f"the linkage locks at driver angle {np.degrees(phis[i]):.1f} deg: the links of joints "
            f"{step.outer}, {step.middle}, {step.other} cannot reach each other there, so the driven body "
            f"{lk.driver.body!r} cannot make a full turn (check the lengths)"
        )
