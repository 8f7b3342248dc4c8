"""Validation rig, audit of the approach-speed memory: at every contact onset of a run,
the approach speed the damping uses against the true normal speed just before onset.

The contact laws divide by ``delta_dot_minus``, the normal speed at the onset of an
impact (model.md); every dry clearance joint ([`Clearance`][jaxcrank.physics.joints.Clearance]) carries it as the
first entry of its memory law's state ([`jaxcrank.physics.memory`][]).
[`onsets`][jaxcrank.analysis.validation.memory_audit.onsets] solves a run as
[`jaxcrank.simulate`][jaxcrank.numerics.solve.simulate] does (same solver, controller and tolerances), keeps every
accepted step and the solver's dense output, finds each step in which a penetration
delta of a clearance joint crosses zero upwards, locates the crossing by bisection on the
dense output, and there compares

* ``used``: the approach speed the joint's memory law gives the contact law
  ([`approach_speed`][jaxcrank.physics.memory.AbstractMemoryLaw.approach_speed]: the memory floored at its
  ``min_approach_speed``), which the memory holds through the impact, with
* ``true``: delta_dot at the crossing, the true normal speed just before onset.
"""

from __future__ import annotations

from typing import NamedTuple

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float

from ...physics import model
from ...physics.joints import Clearance
from ...physics.linkage import AbstractMechanism
from ...physics.safemath import safe_norm
from .events import crossings, dense_solve


class Onsets(NamedTuple):
    """The contact onsets of a run, one entry per onset, sorted by time (numpy arrays).

    Attributes:
        joint: joint name per onset (a clearance joint of the mechanism).
        t: onset time, s.
        true: delta_dot at onset, m/s (the true approach speed).
        used: the approach speed the damping uses, m/s (the joint's memory floored at
            its memory law's ``min_approach_speed``).
        since_separation: time since the same joint's previous separation, s
            (inf for its first onset).
        max_gap: the largest gap -delta, m, at the solver's steps since that
            separation (from the start for a first onset): how far the pin got
            from the wall before coming back.
        num_steps: accepted steps of the solve.
    """

    joint: np.ndarray
    t: np.ndarray
    true: np.ndarray
    used: np.ndarray
    since_separation: np.ndarray
    max_gap: np.ndarray
    num_steps: int

    @property
    def relative_error(self) -> Float[np.ndarray, " onsets"]:
        """``used / true - 1`` per onset."""
        return self.used / self.true - 1.0

    def summary(self, t_min=0.0, min_speed=None):
        """Counts of onsets after ``t_min`` (s) with true approach speed above
        ``min_speed`` (m/s; default: none excluded) whose relative error exceeds
        0.5 %, 1 % and 10 %, with the median and the worst case (its joint, time,
        used and true speeds)."""
        keep = self.t > t_min
        if min_speed is not None:
            keep &= self.true > min_speed
        err = np.abs(self.relative_error[keep])
        out = {
            "onsets": int(keep.sum()),
            "over_0.5%": int((err > 0.005).sum()),
            "over_1%": int((err > 0.01).sum()),
            "over_10%": int((err > 0.1).sum()),
            "median_abs_error": float(np.median(err)) if err.size else 0.0,
            "num_steps": self.num_steps,
        }
        if err.size:
            i = np.flatnonzero(keep)[np.argmax(err)]
            out["worst"] = {
                "joint": str(self.joint[i]),
                "t_s": float(self.t[i]),
                "used_m_s": float(self.used[i]),
                "true_m_s": float(self.true[i]),
                "relative_error": float(self.relative_error[i]),
                "since_separation_s": float(self.since_separation[i]),
                "max_gap_m": float(self.max_gap[i]),
            }
        return out


def audited_joints(mech: AbstractMechanism) -> tuple[str, ...]:
    """Names of the mechanism's dry clearance joints (cut joints whose law is a
    [`Clearance`][jaxcrank.physics.joints.Clearance]), in state order (static)."""
    compiled = model.compile_model(mech)
    return tuple(j for j in compiled.tree.cut if isinstance(compiled.linkage.joints[j], Clearance))


def _joint_state(mech: AbstractMechanism, t, y):
    """(penetration [m], penetration rate [m/s], approach speed used [m/s]) per audited
    joint at (t, y), shape (k,) each (rate 0 where the pin is centred)."""
    compiled = model.compile_model(mech)
    lk, tree = compiled.linkage, compiled.tree
    d_all, d_rate_all = model.joint_eccentricities(mech, t, y)
    law_state = model.unpack(mech, y).law_state
    slices = model.law_slices(mech)
    offset = 2 * tree.n
    pen, rate, used = [], [], []
    for j in audited_joints(mech):
        k = tree.cut.index(j)
        d, d_rate = d_all[k], d_rate_all[k]
        law = lk.joints[j]
        eps = safe_norm(d)
        pen.append(eps - law.clearance)
        rate.append(jnp.dot(d, d_rate) / jnp.where(eps > 0.0, eps, 1.0))
        sl = slices[j]
        used.append(law.memory.approach_speed(law_state[..., sl.start - offset : sl.stop - offset]))
    if not pen:
        z = jnp.zeros(0)
        return z, z, z
    return jnp.stack(pen), jnp.stack(rate), jnp.stack(used)


def onsets(
    mech: AbstractMechanism,
    t1: Float[ArrayLike, ""],
    *,
    t0: Float[ArrayLike, ""] = 0.0,
    y0: Float[ArrayLike, " state"] | None = None,
    options=None,
    max_steps=200_000,
    bisections=60,
) -> Onsets:
    """Every contact onset of the mechanism's clearance joints in the run of ``mech`` from
    ``t0`` to ``t1`` (s) with the numerical settings ``options``
    ([`jaxcrank.SolveOptions`][jaxcrank.numerics.solve.SolveOptions], default: the defaults of
    [`jaxcrank.simulate`][jaxcrank.numerics.solve.simulate]; the step budget is ``max_steps``, which also sizes
    the stored steps). Returns [`Onsets`][jaxcrank.analysis.validation.memory_audit.Onsets].

    Raises:
        SimulationError: the solve did not finish.
    """
    from ...numerics import solve  # the solver settings; imported here, the rig itself needs only the physics

    options = solve.DEFAULTS if options is None else options
    solver = options.solver
    controller = solve.step_size_controller(solver, options.rtol, options.atol)
    y0 = model.initial_state(mech) if y0 is None else y0
    t0_, t1_ = jnp.asarray(t0, dtype=float), jnp.asarray(t1, dtype=float)
    sol = dense_solve(model.vector_field, solver, t0_, t1_, options.dt0, y0, mech, controller, max_steps, steps=True)
    if sol.result != diffrax.RESULTS.successful:
        raise solve.SimulationError(f"audit solve failed: {sol.result}")
    n = int(sol.stats["num_accepted_steps"])
    ts = np.concatenate([[float(t0)], np.asarray(sol.ts[:n])])
    ys = np.concatenate([np.asarray(y0)[None], np.asarray(sol.ys[:n])])
    state_at = jax.jit(jax.vmap(lambda t: _joint_state(mech, t, sol.evaluate(t))))
    pen, _, _ = jax.jit(jax.vmap(lambda t, y: _joint_state(mech, t, y)))(ts, ys)
    pen = np.asarray(pen)
    joints = audited_joints(mech)
    records = []
    for j, name in enumerate(joints):
        p = pen[:, j]
        up = np.flatnonzero((p[:-1] < 0.0) & (p[1:] >= 0.0))
        down = np.flatnonzero((p[:-1] >= 0.0) & (p[1:] < 0.0))
        if up.size == 0:
            continue
        _, hi = crossings(lambda t, j=j: np.asarray(state_at(jnp.asarray(t))[0][:, j]), ts, p, bisections=bisections)
        _, rate, used = state_at(jnp.asarray(hi))
        # separation times: located to step precision (enough for "time since")
        sep_t = 0.5 * (ts[down] + ts[down + 1])
        for k, t_on in enumerate(hi):
            prev = sep_t[sep_t < t_on]
            first = down[sep_t < t_on][-1] + 1 if prev.size else 0
            gap = -float(p[first : up[k] + 1].min())
            records.append(
                (
                    name,
                    t_on,
                    float(rate[k, j]),
                    float(used[k, j]),
                    t_on - prev[-1] if prev.size else np.inf,
                    gap,
                )
            )
    records.sort(key=lambda r: r[1])
    cols = list(zip(*records)) if records else [[]] * 6
    return Onsets(
        joint=np.asarray(cols[0], dtype=str),
        t=np.asarray(cols[1], dtype=float),
        true=np.asarray(cols[2], dtype=float),
        used=np.asarray(cols[3], dtype=float),
        since_separation=np.asarray(cols[4], dtype=float),
        max_gap=np.asarray(cols[5], dtype=float),
        num_steps=n,
    )
