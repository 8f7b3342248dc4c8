"""``jaxcrank assemble``: how a linkage is put together at a driver angle.

It prints each body's frame pose (m, rad), and for each dyad of the ideal mechanism the
joint where its two links meet, the branch it is on and how that branch was chosen (the
joint's ``branch``, the bodies' ``guess`` poses, or the default ``"+"``), with where that
joint would sit on the other branch; then the ``branch`` and ``guess`` lines that pin this
assembly down in the file.
"""

from __future__ import annotations

import math


def add_arguments(p) -> None:
    """Add ``assemble``'s options to its parser ``p``."""
    from . import config

    p.description = (
        "Assemble a linkage (its ideal mechanism) at its driver's initial angle or --angle and print the "
        "poses found, each dyad's branch, and the branch and guess lines that keep this assembly."
    )
    config.add_mechanism_arguments(p, "assemble")
    p.add_argument("--angle", type=config.angle_deg, help="the driver's angle, deg (default: its initial angle)")


def _how(lk, step) -> str:
    if lk.connections[step.middle].branch is not None:
        return f'branch = "{lk.connections[step.middle].branch}" at joint {step.middle}'
    if any(lk.bodies[b].guess is not None for b in step.bodies):
        return "the guess poses"
    return "the default"


def run(args) -> int:
    import jax.numpy as jnp
    import numpy as np

    from ..physics import closure
    from ..physics.compiled import compile_model
    from . import config

    mech = config.mechanism_from_arguments(args)
    model = compile_model(mech)
    lk, plan, tree = model.linkage, model.plan, model.tree
    phi = float(lk.driver.initial_angle) if args.angle is None else math.radians(args.angle)
    signs = tuple(float(s) for s in model.signs)
    frames = closure.ideal_frames(lk, plan, jnp.asarray(phi), signs, model.guesses)
    print(f"{lk.name}: assembled at driver angle {math.degrees(phi):g} deg ({lk.driver.body})")
    print(f"  {'body':<14}{'x [m]':>12}{'y [m]':>12}{'angle [rad]':>14}")
    poses = {b: np.asarray(frames[b].pose()) for b in tree.bodies}
    for b in tree.bodies:
        x, y, angle = poses[b]
        print(f"  {b:<14}{x:>12.6f}{y:>12.6f}{angle:>14.6f}")
    dyads = [s for s in plan.steps if hasattr(s, "middle")]
    lines = []
    for i, step in enumerate(dyads):
        if step.kind == "PRP":
            print(f"dyad {' + '.join(step.bodies)} (joints {', '.join(step.joints)}): one way to assemble")
            continue
        named = "+" if closure.joint_branch(lk, step, signs[i]) > 0 else "-"
        other = tuple(-s if k == i else s for k, s in enumerate(signs))
        there = closure.ideal_frames(lk, plan, jnp.asarray(phi), other, model.guesses)
        here_at = np.asarray(jnp.stack(closure.middle_point(lk, frames, step)))
        there_at = np.asarray(jnp.stack(closure.middle_point(lk, there, step)))
        flip = "-" if named == "+" else "+"
        print(
            f"dyad {' + '.join(step.bodies)} (joints {', '.join(step.joints)}, {step.kind}): branch {named} at joint "
            f"{step.middle}, from {_how(lk, step)}; joint {step.middle} at ({here_at[0]:.6f}, {here_at[1]:.6f}) m "
            f"(branch {flip}: ({there_at[0]:.6f}, {there_at[1]:.6f}) m)"
        )
        lines.append(f'[joints.{step.middle}]\nbranch = "{named}"')
    if lines:
        print("\nto keep this assembly, add to the joints' tables:\n" + "\n".join(lines))
    start = closure.ideal_frames(lk, plan, jnp.asarray(float(lk.driver.initial_angle)), signs, model.guesses)
    print("\nor give the bodies these guess poses ([x, y, angle] at the driver's initial angle):")
    for b in tree.bodies:
        if b != plan.driven:
            print(f"[bodies.{b}]\nguess = [{', '.join(f'{float(v):.6g}' for v in start[b].pose())}]")
    return 0
