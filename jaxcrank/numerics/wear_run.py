"""Wear accumulated over a stretch of motion: the equations of motion with the worn
joints' Archard rates ([`jaxcrank.physics.wear.wear_rates`][]) integrated beside them.

[`wear_solve`][jaxcrank.numerics.wear_run.wear_solve] integrates the scaled state together with,
for every [`Worn`][jaxcrank.physics.wear.Worn] joint, the change of its hole and pin profiles
(Fourier coefficients, m) and of its two worn volumes (m^3). The wear entries ride the
steps the motion chooses: the step-size controller measures the error of the motion's
state only, so with zero wear coefficients the motion is exactly that of
[`simulate`][jaxcrank.numerics.solve.simulate].

Two uses:

- ``feedback=False``: the profiles stay as the mechanism gives them; the result is the
  wear over the stretch at frozen geometry (one period of a steady orbit, in
  [`jaxcrank.analysis.life`][]);
- ``feedback=True``: the contact acts against the profiles as they wear, the brute-force
  reference (a transient run whose wear feeds back at every step).
"""

from __future__ import annotations

from typing import NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Float

from ..physics import model
from ..physics.dynamics import terms
from ..physics.kinematics import joint_motion
from ..physics.linkage import AbstractMechanism as Mechanism
from ..physics.params import ParameterError
from ..physics.wear import Worn, wear_rates, worn_volume
from .results import RESULTS
from .shooting import STEADY_DEFAULTS, lax_solver
from .solve import SolveOptions, step_size_controller


def worn_joints(mech: Mechanism) -> tuple[str, ...]:
    """The names of the joints whose law is [`Worn`][jaxcrank.physics.wear.Worn], sorted (static)."""
    return tuple(sorted(j for j, law in mech.joints.items() if isinstance(law, Worn)))


def with_wear(mech: Mechanism, joints, where: str = "wear") -> Mechanism:
    """``mech`` with each of ``joints`` (names of dry revolute clearance joints) made a new
    [`Worn`][jaxcrank.physics.wear.Worn] joint ([`from_clearance`][jaxcrank.physics.wear.from_clearance],
    the default [`Archard`][jaxcrank.physics.wear.Archard] law, or the joint's own when it is worn already).

    Raises:
        ParameterError: naming ``where``, for a joint ``mech`` does not have or one that is not a
            dry revolute clearance joint."""
    from ..physics.wear import from_clearance

    for j in joints:
        if j not in mech.joints:
            raise ParameterError(f"{where}: unknown joint {j!r}; joints: {', '.join(sorted(mech.joints))}")
        try:
            law = from_clearance(mech.joints[j])
        except ParameterError as err:
            raise ParameterError(f"{where}: joint {j!r}: {err}") from None
        mech = eqx.tree_at(lambda m, j=j: m.joints[j], mech, law)
    return mech


def _layout(mech):
    out, start = {}, 0
    for j in worn_joints(mech):
        size = 2 * mech.joints[j].modes + 1
        out[j] = (slice(start, start + size), slice(start + size, start + 2 * size), start + 2 * size)
        start += 2 * size + 2
    return out


def _scales(mech):
    parts = []
    for j in worn_joints(mech):
        law = mech.joints[j]
        c = law.clearance
        volume = c * law.hole_radius * law.wear.length
        parts += [jnp.full(2 * (2 * law.modes + 1), c), jnp.stack([volume, volume])]
    return jnp.concatenate(parts) if parts else jnp.zeros(0)


class Wear(NamedTuple):
    """A worn joint's wear over a stretch (SI): the change of its hole and pin profiles
    (Fourier coefficients, m) and its worn volumes (m^3)."""

    hole: Array
    pin: Array
    hole_volume: Array
    pin_volume: Array


def unpack_wear(mech: Mechanism, w: Float[Array, "... wear"]) -> dict[str, Wear]:
    """The wear entries ``w`` (SI, as [`WearSolve.wear`][jaxcrank.numerics.wear_run.WearSolve]) by joint."""
    return {j: Wear(w[..., h], w[..., p], w[..., v], w[..., v + 1]) for j, (h, p, v) in _layout(mech).items()}


def with_profiles(mech: Mechanism, profiles: dict) -> Mechanism:
    """``mech`` with the worn joints' profiles set: ``profiles[joint] = (hole, pin)`` (m)."""
    for j, (hole, pin) in profiles.items():
        mech = eqx.tree_at(lambda m, j=j: m.joints[j], mech, mech.joints[j].worn(hole, pin))
    return mech


def profiles_of(mech: Mechanism) -> dict:
    """The worn joints' profiles, ``joint -> (hole, pin)`` (m)."""
    return {j: (mech.joints[j].hole_wear, mech.joints[j].pin_wear) for j in worn_joints(mech)}


def _worn_motion(compiled, t, y, joints):
    """The equations of motion at (t, y) and each worn joint's kinematics from them."""
    e = terms(compiled, t, y)
    rots = {b: st.frame.rot for b, st in e.motion.states.items()}
    return e, {j: joint_motion(compiled, j, e.motion.q, e.motion.qd, rots=rots)[0] for j in joints}


def _field(mech, n, feedback):
    base = profiles_of(mech)
    layout = _layout(mech)
    scale = _scales(mech)

    def field(t, ya, args):
        compiled = args
        y, w = ya[:n], ya[n:] * scale
        if feedback:
            current = {j: (base[j][0] + w[h], base[j][1] + w[p]) for j, (h, p, _) in layout.items()}
            compiled = eqx.tree_at(lambda m: m.mechanism, compiled, with_profiles(compiled.mechanism, current))
        e, kins = _worn_motion(compiled, t, y, layout)
        rates = []
        for j, kin in kins.items():
            r = wear_rates(compiled.linkage.joints[j], kin, e.forces[j])
            rates += [r.hole, r.pin, jnp.stack([r.hole_volume, r.pin_volume])]
        return jnp.concatenate([e.state_rate, jnp.concatenate(rates) / scale])

    return field


class WearSolve(eqx.Module):
    """The result of [`wear_solve`][jaxcrank.numerics.wear_run.wear_solve].

    Attributes:
        ts: the save times, s.
        ys: the scaled state at ``ts`` (as [`simulate`][jaxcrank.numerics.solve.simulate]'s).
        wear: the wear entries at ``ts``, SI (m for profile coefficients, m^3 for
            volumes; [`unpack_wear`][jaxcrank.numerics.wear_run.unpack_wear] names them), zero at the start.
        result: [`RESULTS`][jaxcrank.numerics.results.RESULTS] item.
        num_steps: accepted steps.
    """

    ts: Array
    ys: Array
    wear: Array
    result: RESULTS
    num_steps: Array

    @property
    def ok(self):
        return self.result == RESULTS.successful


@eqx.filter_jit
def _wear_solve(mech, y0, ts, solver, rtol, atol, dt0, max_steps, adjoint, feedback):
    compiled = model.compile_model(mech)
    n = model.state_size(compiled)
    scale = _scales(mech)
    ya0 = jnp.concatenate([y0, jnp.zeros_like(scale)])
    controller = step_size_controller(solver, rtol, atol)
    controller = eqx.tree_at(lambda c: c.norm, controller, lambda e: optx.rms_norm(e[:n]))
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(_field(mech, n, feedback)),
        solver,
        ts[0],
        ts[-1],
        dt0,
        ya0,
        args=compiled,
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=controller,
        adjoint=adjoint,
        max_steps=max_steps,
        throw=False,
    )
    return WearSolve(
        sol.ts, sol.ys[:, :n], sol.ys[:, n:] * scale, RESULTS.promote(sol.result), sol.stats["num_accepted_steps"]
    )


def wear_solve(
    mech: Mechanism,
    y0: Float[Array, " state"],
    ts: Float[Array, " n"],
    *,
    options: SolveOptions = STEADY_DEFAULTS,
    feedback: bool = False,
    adjoint=None,
) -> WearSolve:
    """The motion from the scaled state ``y0`` at ``ts[0]`` with the worn joints' wear
    integrated beside it, saved at ``ts`` (s).

    Args:
        mech: a mechanism with at least one [`Worn`][jaxcrank.physics.wear.Worn] joint.
        y0: the scaled state at ``ts[0]`` (e.g. a steady orbit's section state).
        ts: save times, s, increasing (at least two).
        options: the solve's settings (default ``STEADY_DEFAULTS``: tsit5, 1e-10).
        feedback: the contact acts against the profiles as they wear (True), or against
            ``mech``'s profiles throughout (False).
        adjoint: diffrax adjoint (default ``diffrax.ForwardMode()``: forward-mode
            derivatives, ``jax.jvp``/``jax.jacfwd``).

    Returns:
        A [`WearSolve`][jaxcrank.numerics.wear_run.WearSolve]; inspect ``.ok`` (no exception on a failed solve).

    Raises:
        ParameterError: a mechanism without a worn joint, or fewer than two save times.
    """
    if not worn_joints(mech):
        raise ParameterError('the mechanism has no worn joint: give a clearance joint law = "worn" (jaxcrank.Worn)')
    ts = jnp.asarray(ts, dtype=float)
    if ts.ndim != 1 or ts.shape[0] < 2:
        raise ParameterError(f"ts must be 1-D with at least two times; got shape {ts.shape}")
    adjoint = diffrax.ForwardMode() if adjoint is None else adjoint
    return _wear_solve(
        mech, jnp.asarray(y0, dtype=float), ts, lax_solver(options), options.rtol, options.atol, options.dt0,
        options.max_steps, adjoint, feedback,
    )  # fmt: skip


def contact_samples(mech: Mechanism, ts: Float[Array, " n"], ys: Float[Array, "n state"]) -> dict:
    """Where and how hard each worn joint touches at the samples ``(ts, ys)`` (s, scaled
    states): ``joint -> dict`` of ``hole_angle_rad`` and ``pin_angle_rad`` (the contact's
    direction in each surface's frame, in [-pi, pi)), ``normal_force_N``, ``slip_speed_m_s``
    and ``wear_power_W`` (normal force times slip speed, Archard's load times sliding
    speed), each of shape (n,)."""
    from ..physics.wear import contact_point

    compiled = model.compile_model(mech)

    def one(t, y):
        e, kins = _worn_motion(compiled, t, y, worn_joints(mech))
        out = {}
        for j, kin in kins.items():
            cp = contact_point(compiled.linkage.joints[j], kin)
            f = e.forces[j]
            out[j] = {
                "hole_angle_rad": jnp.arctan2(cp.hole_dir[1], cp.hole_dir[0]),
                "pin_angle_rad": jnp.arctan2(cp.pin_dir[1], cp.pin_dir[0]),
                "normal_force_N": f.normal_force,
                "slip_speed_m_s": f.slip_speed,
                "wear_power_W": f.normal_force * jnp.abs(f.slip_speed),
            }
        return out

    return eqx.filter_jit(jax.vmap(one))(jnp.asarray(ts, dtype=float), jnp.asarray(ys, dtype=float))


def volumes(mech: Mechanism) -> dict[str, tuple]:
    """Each worn joint's worn volumes ``(hole, pin)`` (m^3) from its profiles' mean depths."""
    out = {}
    for j in worn_joints(mech):
        law = mech.joints[j]
        out[j] = (
            worn_volume(law.hole_wear, law.hole_radius, law.wear.length),
            worn_volume(law.pin_wear, law.pin_radius, law.wear.length),
        )
    return out


__all__ = [
    "Wear",
    "WearSolve",
    "contact_samples",
    "profiles_of",
    "unpack_wear",
    "volumes",
    "wear_solve",
    "with_profiles",
    "with_wear",
    "worn_joints",
]
