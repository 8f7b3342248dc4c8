"""Closing loops of ideal joints: the dyads in closed form, a root find for the rest, and
the ideal mechanism (every joint ideal) as a function of the driver's angle.

- **Dyads** ([`Dyad`][jaxcrank.physics.topology.Dyad]) in closed form: RRR puts the middle
  pin at an intersection of two circles, RRP of a circle and a line, RPR (a block on a
  turning guide: the crank-shaper, the oscillating cylinder) turns the guide so that its
  line passes through the block's pin, and PRP meets two lines. Each of the first three
  has two branches (``sign`` +1 or -1): [`branch`][jaxcrank.physics.closure.branch] reads
  a pose's branch, [`branch_signs`][jaxcrank.physics.closure.branch_signs] chooses the
  ideal mechanism's once, at the driver's initial angle (a joint's ``branch``, else the
  bodies' ``guess`` poses, else +1).
- **Groups** ([`Group`][jaxcrank.physics.topology.Group]) by Newton's method in a loop that
  XLA runs as a loop, from a warm start, to a tolerance; derivatives by the implicit
  function theorem (``jax.custom_jvp``), exact whatever the iterations did.

Everything is differentiable in the linkage's parameters and in the driver's angle, to any
order; the dyads also run on [`Jet`][jaxcrank.physics.safemath.Jet]s (a value with its first
two time derivatives, in one pass) and on NumPy arrays (the assembly check, over a whole
turn at once).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from .forward import GROUND_FRAME, Placed, local_point
from .linkage import GROUND, Linkage
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
from .topology import Dyad, Group, Plan

#: Newton's method of a group: iterations at most, and the step (m, rad) below which it stops
ITERATIONS = 40
TOLERANCE = 1e-13

_SIGNS = {"+": 1.0, "positive": 1.0, "-": -1.0, "negative": -1.0}


def _site_world(lk: Linkage, frames: dict, site) -> tuple:
    return frames[site.body].point(local_point(lk, site))


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


def _sides(conn, body: str) -> tuple:
    """(the site of ``conn`` on ``body``, the site on its other side)."""
    a, b = conn.sites()
    return (a, b) if a.body == body else (b, a)


def _slide_line(lk: Linkage, frames: dict, conn, body: str, local_point_) -> tuple:
    """For ``body`` held by the prismatic ``conn`` to a placed body: its angle, and the
    line ``B0 + lam d`` its point ``local_point_`` moves on (B0, d), as pairs."""
    if conn.slider.body == body:  # it slides on a placed guide
        guide = frames[conn.guide.body]
        angle = add(guide.angle, conn.angle)
        d_angle = add(guide.angle, conn.direction)
        g = _site_world(lk, frames, conn.guide)
        own = local_point(lk, conn.slider)
    else:  # it is the guide, moving along a placed slider
        slider = frames[conn.slider.body]
        angle = sub(slider.angle, conn.angle)
        d_angle = add(angle, conn.direction)
        g = _site_world(lk, frames, conn.slider)
        own = local_point(lk, conn.guide)
    b0 = vadd(g, vturn(cos_sin(angle), vsub(local_point_, own)))
    return angle, b0, cos_sin(d_angle)


def _sqrt_or_nan(x):
    ok = x >= 0.0
    return where(ok, sqrt(where(ok, x, 1.0)), math.nan)


def _length(v: tuple):
    """|v| of a body vector (a pair): |v_x| when v_y is known to be zero."""
    if known_zero(v[1]):
        return v[0] if known(v[0]) and v[0] >= 0 else sqrt(mul(v[0], v[0]))
    return sqrt(add(mul(v[0], v[0]), mul(v[1], v[1])))


def place_dyad(lk: Linkage, frames: dict, step: Dyad, sign) -> tuple[dict, object]:
    """Place the two bodies of one dyad on the branch ``sign``; returns the new frames and
    the discriminant of its intersection (negative: it cannot be assembled)."""
    outer, middle, other = (lk.connections[j] for j in step.joints)
    u, v = step.first, step.second
    u_site, k1 = _sides(outer, u)
    p1 = _site_world(lk, frames, k1)
    a_u = local_point(lk, u_site)
    out = dict(frames)
    if step.kind == "RPR":
        v_site, k2 = _sides(other, v)
        p2 = _site_world(lk, frames, k2)
        c_v = local_point(lk, v_site)
        e = cos_sin(middle.direction)  # the guide's line in the frame of u, which carries it
        w = vturn(cos_sin(middle.angle), vsub(local_point(lk, middle.slider), c_v))
        h = vcross(e, vsub(vadd(a_u, w), local_point(lk, middle.guide)))
        arm = vsub(p2, p1)
        arm2 = vdot(arm, arm)
        disc = sub(arm2, mul(h, h))
        along = mul(sign, _sqrt_or_nan(disc))
        d = vscale(div(1.0, arm2), vadd(vscale(along, arm), vscale(h, vperp(arm))))  # the line's direction
        rot = (vdot(e, d), vcross(e, d))
        angle_u = atan2(rot[1], rot[0])
        out[u] = _placed_by_point(p1, a_u, angle_u, rot)
        out[v] = _placed_by_point(p2, c_v, add(angle_u, middle.angle))
        return out, disc
    m_u, m_v = _sides(middle, u)
    b_u, b_v = local_point(lk, m_u), local_point(lk, m_v)
    if step.kind == "PRP":
        angle_u, b0_u, d_u = _slide_line(lk, frames, outer, u, b_u)
        angle_v, b0_v, d_v = _slide_line(lk, frames, other, v, b_v)
        disc = vcross(d_u, d_v)  # zero: parallel lines
        lam = div(vcross(vsub(b0_v, b0_u), d_v), disc)
        b = vadd(b0_u, vscale(lam, d_u))
        out[u] = _placed_by_point(b, b_u, angle_u)
        out[v] = _placed_by_point(b, b_v, angle_v)
        return out, mul(disc, disc)
    link_u = vsub(b_u, a_u)
    r1 = _length(link_u)
    if step.kind == "RRR":
        v_site, k2 = _sides(other, v)
        p3 = _site_world(lk, frames, k2)
        c_v = local_point(lk, v_site)
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
    else:  # RRP
        angle_v, b0, d = _slide_line(lk, frames, other, v, b_v)
        w = vsub(b0, p1)
        dw = vdot(d, w)
        disc = dw * dw - vdot(w, w) + r1 * r1
        lam = sub(mul(sign, _sqrt_or_nan(disc)), dw)
        b = vadd(b0, vscale(lam, d))
        frame_v = _placed_by_point(b, b_v, angle_v)
    arm_u = vsub(b, p1)
    angle_u = sub(atan2(arm_u[1], arm_u[0]), atan2(link_u[1], link_u[0]))
    out[u] = _placed_by_point(p1, a_u, angle_u, _turning(link_u, arm_u, r1))
    out[v] = frame_v
    return out, disc


def branch(lk: Linkage, frames: dict, step: Dyad):
    """The branch (+1 or -1, as ``sign`` of the dyad's closed form) that ``frames`` (every
    body of the dyad and its parents placed) are on; +1 for a PRP dyad, which has one."""
    u, v = step.first, step.second
    outer, middle, other = (lk.connections[j] for j in step.joints)
    p1 = _site_world(lk, frames, _sides(outer, u)[1])
    if step.kind == "PRP":
        return 1.0
    if step.kind == "RPR":
        d = cos_sin(add(frames[u].angle, middle.direction))
        value = vdot(d, vsub(_site_world(lk, frames, _sides(other, v)[1]), p1))
    else:
        b = _site_world(lk, frames, _sides(middle, u)[0])
        if step.kind == "RRR":
            value = vcross(vsub(_site_world(lk, frames, _sides(other, v)[1]), p1), vsub(b, p1))
        else:
            _, _, d = _slide_line(lk, frames, other, v, local_point(lk, _sides(middle, v)[0]))
            value = vdot(d, vsub(b, p1))
    return stop_gradient(where(value >= 0.0, 1.0, -1.0))


def middle_point(lk: Linkage, frames: dict, step: Dyad) -> tuple:
    """Where a dyad's middle joint is (its first body's point), m, a pair."""
    return _site_world(lk, frames, _sides(lk.connections[step.middle], step.first)[0])


def joint_branch(lk: Linkage, step: Dyad, sign):
    """The branch a joint's ``branch`` setting names, as seen from the dyad's own sign
    (the two agree but where a RRR dyad's first body holds the middle joint's pin)."""
    if step.kind == "RRR" and lk.connections[step.middle].pin.body == step.first:
        return -sign
    return sign


def _guess_point(lk: Linkage, body: str, local) -> tuple | None:
    guess = lk.bodies[body].guess
    return None if guess is None else Placed.at((guess.x, guess.y), guess.angle).point(local)


def _chosen_sign(lk: Linkage, frames: dict, step: Dyad):
    """The branch of a dyad of the ideal mechanism: its middle joint's ``branch``, else the
    one whose middle joint lies nearer the bodies' guesses, else +1."""
    named = lk.connections[step.middle].branch
    if named is not None:
        return joint_branch(lk, step, _SIGNS[named])
    m_u, m_v = _sides(lk.connections[step.middle], step.first)
    target = _guess_point(lk, step.first, local_point(lk, m_u))
    if target is None:
        target = _guess_point(lk, step.second, local_point(lk, m_v))
    if target is None or step.kind == "PRP":
        return 1.0
    plus, _ = place_dyad(lk, frames, step, 1.0)
    minus, _ = place_dyad(lk, frames, step, -1.0)
    gap_plus = vsub(plus[step.first].point(local_point(lk, m_u)), target)
    gap_minus = vsub(minus[step.first].point(local_point(lk, m_u)), target)
    return stop_gradient(where(vdot(gap_plus, gap_plus) <= vdot(gap_minus, gap_minus), 1.0, -1.0))


def _driven_frame(lk: Linkage, plan: Plan, phi) -> Placed:
    body_site, ground_site = _sides(lk.connections[plan.pivot], plan.driven)
    return _placed_by_point(local_point(lk, ground_site), local_point(lk, body_site), phi)


def _walk(lk: Linkage, plan: Plan, phi, signs, guesses):
    """(frames, discriminants, signs) of the ideal mechanism at ``phi``; ``signs`` None:
    each dyad's branch chosen on the way ([`_chosen_sign`][])."""
    frames = {GROUND: GROUND_FRAME, plan.driven: _driven_frame(lk, plan, phi)}
    discs, chosen = [], []
    dyads = None if signs is None else iter(signs)
    groups = iter(guesses)
    for step in plan.steps:
        if isinstance(step, Group):
            value = phi.value if hasattr(phi, "value") else phi
            frames = group_frames(lk, step, frames, guess_at(next(groups), lk.driver.initial_angle, value))
            continue
        sign = _chosen_sign(lk, frames, step) if dyads is None else next(dyads)
        chosen.append(sign)
        frames, disc = place_dyad(lk, frames, step, sign)
        discs.append(disc)
    return frames, discs, tuple(chosen)


def ideal_frames(lk: Linkage, plan: Plan, phi, signs, guesses=()) -> dict:
    """The ideal mechanism's frames ([`Placed`][jaxcrank.physics.forward.Placed], and the
    ground's) at the driver angle ``phi`` (rad: a number, an array of any shape, traced or
    NumPy, or a [`Jet`][jaxcrank.physics.safemath.Jet]).

    Args:
        lk: the linkage.
        plan: its assembly plan.
        phi: the driver's angle, rad.
        signs: each dyad's branch, in the order of ``plan.dyads``
            ([`branch_signs`][jaxcrank.physics.closure.branch_signs]).
        guesses: per group of the plan, its poses over a turn
            ([`group_guesses`][jaxcrank.physics.assembly.group_guesses]): the warm starts.
    """
    return _walk(lk, plan, phi, signs, guesses)[0]


def discriminants(lk: Linkage, plan: Plan, phi, signs, guesses=()) -> list:
    """Each dyad's discriminant at ``phi`` (rad): negative where its links cannot reach."""
    return _walk(lk, plan, phi, signs, guesses)[1]


def branch_signs(lk: Linkage, plan: Plan, guesses=()) -> tuple:
    """Each dyad's branch (+1 or -1) of the ideal mechanism, in the order of ``plan.dyads``,
    chosen at the driver's initial angle: the middle joint's ``branch``, else the one nearer
    the bodies' guesses, else +1 (numbers where the linkage's values are)."""
    if not plan.dyads:
        return ()
    if all(lk.connections[st.middle].branch is None for st in plan.dyads) and all(
        lk.bodies[b].guess is None for st in plan.dyads for b in st.bodies
    ):
        return (1.0,) * len(plan.dyads)
    return _walk(lk, plan, lk.driver.initial_angle, None, guesses)[2]


# --------------------------------------------------------------------------- groups


def _frames_with(frames: dict, bodies, x) -> dict:
    out = dict(frames)
    for i, body in enumerate(bodies):
        out[body] = Placed.at((x[3 * i], x[3 * i + 1]), x[3 * i + 2])
    return out


def residuals(lk: Linkage, frames: dict, joints) -> list:
    """Each ideal joint's two closure equations at ``frames`` (m and rad): zero where the
    joint holds ([`Revolute.residual`][jaxcrank.physics.linkage.Revolute.residual],
    [`Prismatic.residual`][jaxcrank.physics.linkage.Prismatic.residual])."""
    out = []
    for j in joints:
        conn = lk.connections[j]
        a, b = conn.sites()
        out += list(conn.residual(frames[a.body], frames[b.body], local_point(lk, a), local_point(lk, b)))
    return out


def _parent_poses(frames: dict, step) -> jax.Array:
    parents = [b for b in step.parents if b != GROUND]
    return jnp.stack([jnp.asarray(v, dtype=float) for b in parents for v in (*frames[b].origin, frames[b].angle)])


def group_frames(lk: Linkage, step: Group, frames: dict, guess) -> dict:
    """``frames`` with the bodies of the group ``step`` placed by Newton's method from
    ``guess`` (their poses (x, y, angle) flattened), in a loop of at most `ITERATIONS`
    that stops once a step is below `TOLERANCE`; derivatives by the implicit function
    theorem. A group that does not close gives NaN poses."""
    parents = [b for b in step.parents if b != GROUND]
    p = _parent_poses(frames, step) if parents else jnp.zeros(0)

    def residual(lk_, p_, x):
        fr = {GROUND: GROUND_FRAME}
        for i, b in enumerate(parents):
            fr[b] = Placed.at((p_[3 * i], p_[3 * i + 1]), p_[3 * i + 2])
        fr = _frames_with(fr, step.bodies, x)
        return jnp.stack([jnp.asarray(v, dtype=float) for v in residuals(lk_, fr, step.joints)])

    @jax.custom_jvp
    def solve(lk_, p_):
        def cond(carry):
            i, _, size = carry
            return (i < ITERATIONS) & (size > TOLERANCE)

        def body(carry):
            i, x, _ = carry
            dx = solve_dense(jax.jacfwd(lambda z: residual(lk_, p_, z))(x), residual(lk_, p_, x))
            return i + 1, x - dx, jnp.max(jnp.abs(dx))

        x0 = jax.lax.stop_gradient(jnp.asarray(guess, dtype=float))
        _, x, size = jax.lax.while_loop(cond, body, (0, x0, jnp.asarray(jnp.inf)))
        return jax.lax.stop_gradient(jnp.where(size <= TOLERANCE * 1e3, x, jnp.nan))

    @solve.defjvp
    def solve_jvp(primals, tangents):
        lk_, p_ = primals
        x = solve(lk_, p_)
        jac = jax.jacfwd(lambda z: residual(lk_, p_, z))(x)
        _, dr = jax.jvp(lambda a, b: residual(a, b, x), primals, tangents)
        return x, -solve_dense(jac, dr)

    return _frames_with(frames, step.bodies, solve(lk, p))


def guess_at(table, phi0, phi):
    """The row of a group's guess table ([`group_guesses`][jaxcrank.physics.assembly.group_guesses])
    nearest the driver angle ``phi`` (rad), stop-gradient."""
    table = jnp.asarray(table)
    samples = table.shape[0]
    turns = (jax.lax.stop_gradient(jnp.asarray(phi, dtype=float)) - phi0) / (2.0 * math.pi)
    index = jnp.round(turns * samples).astype(int) % samples
    return jax.lax.stop_gradient(table[index])
