"""Forward kinematics of the tree, written out: every body's pose, velocity, bias
acceleration and Jacobian columns, propagated from the ground outwards.

For tree coordinates q (absolute angles, slides, floating bodies' centre-of-mass poses),
their rates, their known second rates (everything but the unknown s''), and the driver
angle phi with its rates, [`forward`][jaxcrank.physics.forward.forward] returns each body's
frame state. The Jacobian columns are ``d(.)/dq_k`` for the n coordinates and, last,
``d(.)/dphi`` at fixed q. Each body's rotation is evaluated once and every derivative is
the rigid-body formula (``v = v_O + omega perp(r)``, ``a = a_O + alpha perp(r) - omega^2
r``), so a solver stage pays for the kinematics once, not once per order of
differentiation.

Everything is a scalar or a pair of scalars ([`jaxcrank.physics.safemath`][]): entries
the tree makes constant (a floating body's Jacobian columns, a fixed guide's direction,
the ground's motion) are numbers, and cost nothing downstream.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array

from .linkage import GROUND, Linkage
from .safemath import add, cos_sin, known_zero, mul, sub, vadd, vperp, vscale, vsub, vturn
from .topology import Placement, Tree


class BodyState(NamedTuple):
    """One body frame's motion (SI; world frame; pairs of scalars for vectors).

    Attributes:
        frame: its [`Placed`][jaxcrank.physics.forward.Placed] frame (origin, m; angle, rad; its
            rotation).
        velocity: of the origin, m/s.
        angular_velocity: rad/s.
        acceleration: of the origin, with the known second rates only (s'' = 0), m/s^2.
        angular_acceleration: likewise, rad/s^2.
        position_jacobian: d(origin)/d(q_k) by column k (k = n: d/dphi), the columns
            the tree makes nonzero only, each a pair.
        angle_jacobian: d(angle)/d(q_k) likewise, scalars.
    """

    frame: Placed
    velocity: tuple
    angular_velocity: object
    acceleration: tuple
    angular_acceleration: object
    position_jacobian: dict
    angle_jacobian: dict


class Placed(NamedTuple):
    """A body frame placed in the world: its origin (a pair, m), its angle (rad) and
    ``rot`` = (cos angle, sin angle)."""

    origin: tuple
    angle: object
    rot: tuple

    @staticmethod
    def at(origin: tuple, angle) -> Placed:
        """The frame with this origin and angle (its rotation evaluated once)."""
        return Placed(tuple(origin), angle, cos_sin(angle))

    def point(self, local) -> tuple:
        """World position of the point ``local`` (a pair, m) of the frame, as a pair."""
        return vadd(self.origin, vturn(self.rot, local))

    def pose(self) -> Array:
        """(x, y, angle) as an array (3,)."""
        return jnp.stack([jnp.asarray(v, dtype=float) for v in (*self.origin, self.angle)])


#: the ground's frame
GROUND_FRAME = Placed((0.0, 0.0), 0.0, (1.0, 0.0))


#: the ground's state
GROUND_STATE = BodyState(GROUND_FRAME, (0.0, 0.0), 0.0, (0.0, 0.0), 0.0, {}, {})


def _combine(a: dict, b: dict, scale=1.0) -> dict:
    """Sparse columns of pairs a + scale * b."""
    out = dict(a)
    for k, v in b.items():
        v = vscale(scale, v)
        out[k] = vadd(out[k], v) if k in out else v
    return out


def local_point(lk: Linkage, site) -> tuple:
    """A site's point in its body's frame (or the ground's), a pair, m."""
    return (lk.ground if site.body == GROUND else lk.bodies[site.body].points)[site.point].pair()


def point_of(state: BodyState, local) -> tuple[tuple, tuple, tuple, dict]:
    """(position, velocity, bias acceleration, Jacobian columns) of a body point given in
    its frame (a pair), as pairs."""
    u = vturn(state.frame.rot, local)
    w = vperp(u)
    omega = state.angular_velocity
    return (
        vadd(state.frame.origin, u),
        vadd(state.velocity, vscale(omega, w)),
        vsub(vadd(state.acceleration, vscale(state.angular_acceleration, w)), vscale(mul(omega, omega), u)),
        _combine(state.position_jacobian, {k: vscale(v, w) for k, v in state.angle_jacobian.items()}),
    )


def _place(state_point, angle, rot, omega, alpha, jt, local) -> BodyState:
    """A body whose point ``local`` moves as ``state_point`` (position, velocity, bias
    acceleration, Jacobian) with the given angle, rotation and angle rates."""
    pos, vel, acc, jac = state_point
    u = vturn(rot, local)
    w = vperp(u)
    return BodyState(
        Placed(vsub(pos, u), angle, rot),
        vsub(vel, vscale(omega, w)),
        omega,
        vadd(vsub(acc, vscale(alpha, w)), vscale(mul(omega, omega), u)),
        alpha,
        _combine(jac, {k: vscale(v, w) for k, v in jt.items()}, -1.0),
        jt,
    )


def forward(
    lk: Linkage, tree: Tree, q, qd, qdd, phi, phid, phidd, closed=None, columns: bool = True
) -> dict[str, BodyState]:
    """Every body's [`BodyState`][jaxcrank.physics.forward.BodyState] (and the ground's), for tree coordinates
    ``q`` (a sequence of scalars) with rates ``qd`` and known second rates ``qdd``, and
    the driver angle ``phi`` (rad) with its rates (used where the driver prescribes a
    body's angle). ``closed(step, states)`` gives the states of the bodies a closure step
    of the tree places ([`jaxcrank.physics.loops.closed_states`][]) from those placed
    before it. ``columns=False`` leaves the Jacobian columns out (empty): the motion alone."""
    m = tree.n + 1
    out = {GROUND: GROUND_STATE}

    def angle_of(own, driven):
        if driven and len(own) == 0:
            return phi, phid, phidd, ({m - 1: 1.0} if columns else {})
        k = own[0]
        return q[k], qd[k], qdd[k], ({k: 1.0} if columns else {})

    for p in tree.steps:
        if not isinstance(p, Placement):
            out.update(closed(p, out))
            continue
        own = list(p.coordinates)
        if p.kind == "floating":  # its coordinates are its centre of mass and angle
            ix, iy = own[0], own[1]
            angle, omega, alpha, jt = angle_of(own[2:], p.driven)
            jp = {ix: (1.0, 0.0), iy: (0.0, 1.0)} if columns else {}
            centre = ((q[ix], q[iy]), (qd[ix], qd[iy]), (qdd[ix], qdd[iy]), jp)
            local = lk.bodies[p.body].centre_of_mass.pair()
            out[p.body] = _place(centre, angle, cos_sin(angle), omega, alpha, jt, local)
            continue
        conn = lk.connections[p.joint]
        parent = out[p.parent]
        if p.kind == "revolute":
            child_site, parent_site = (conn.pin, conn.hole) if conn.pin.body == p.body else (conn.hole, conn.pin)
            anchor = point_of(parent, local_point(lk, parent_site))
            angle, omega, alpha, jt = angle_of(own, p.driven)
            out[p.body] = _place(anchor, angle, cos_sin(angle), omega, alpha, jt, local_point(lk, child_site))
            continue
        k = own[0]
        lam, lam_d, lam_dd = q[k], qd[k], qdd[k]
        forward_slide = conn.slider.body == p.body
        sign = 1.0 if forward_slide else -1.0
        parent_angle = parent.frame.angle
        angle = add(parent_angle, conn.angle) if forward_slide else sub(parent_angle, conn.angle)
        d = cos_sin(add(parent_angle if forward_slide else angle, conn.direction))
        dperp = vperp(d)
        omega, alpha, jt = parent.angular_velocity, parent.angular_acceleration, parent.angle_jacobian
        base = point_of(parent, local_point(lk, conn.guide if forward_slide else conn.slider))
        d_dot = vscale(omega, dperp)
        d_ddot = vsub(vscale(alpha, dperp), vscale(mul(omega, omega), d))
        slide_acc = vadd(vadd(vscale(lam_dd, d), vscale(mul(2.0, lam_d), d_dot)), vscale(lam, d_ddot))
        point = (
            vadd(base[0], vscale(mul(sign, lam), d)),
            vadd(base[1], vscale(sign, vadd(vscale(lam_d, d), vscale(lam, d_dot)))),
            vadd(base[2], vscale(sign, slide_acc)),
            _combine(
                base[3],
                _combine({k: d} if columns else {}, {j: vscale(mul(lam, v), dperp) for j, v in jt.items()}),
                sign,
            ),
        )
        rot = cos_sin(angle)
        local = local_point(lk, conn.slider if forward_slide else conn.guide)
        out[p.body] = _place(point, angle, rot, omega, alpha, jt, local)
    return out


class Centres(NamedTuple):
    """Centre-of-mass poses Q (x, y, angle per body, flattened) as lists of scalars, their
    rates, bias accelerations, and the Jacobian as a dict (row, column) -> scalar of the
    entries the tree makes nonzero (column n: the driver angle)."""

    q: list
    qd: list
    qdd: list
    jacobian: dict


def centres(lk: Linkage, tree: Tree, states: dict[str, BodyState]) -> Centres:
    """The bodies' [`Centres`][jaxcrank.physics.forward.Centres] from their frame states, in sorted body order."""
    q, qd, qdd, jac = [], [], [], {}
    for i, b in enumerate(tree.bodies):
        st = states[b]
        pos, vel, acc, jp = point_of(st, lk.bodies[b].centre_of_mass.pair())
        q += [pos[0], pos[1], st.frame.angle]
        qd += [vel[0], vel[1], st.angular_velocity]
        qdd += [acc[0], acc[1], st.angular_acceleration]
        for k, col in jp.items():
            jac[(3 * i, k)], jac[(3 * i + 1, k)] = col[0], col[1]
        for k, v in st.angle_jacobian.items():
            jac[(3 * i + 2, k)] = v
    return Centres(q, qd, qdd, {rk: v for rk, v in jac.items() if not known_zero(v)})
