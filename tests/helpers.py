import equinox as eqx

import jaxcrank as jc


def _clearance_joints(mech):
    """Names of the joints whose law has contact settings (dry clearance joints)."""
    return [j for j in sorted(mech.joints) if hasattr(mech.joints[j], "contact")]


def frictionless(mech):
    """``mech`` with friction coefficient 0 in every joint that has friction."""
    return jc.set_parameter(mech, "friction.coefficient", 0.0)


def with_law(mech, law, restitution=None):
    """``mech`` with the contact law named ``law`` (a key of ``jc.laws.CONTACT_LAWS``) in
    every dry clearance joint, at restitution ``restitution`` (default: each joint's own)."""
    for j in _clearance_joints(mech):
        old = mech.joints[j].contact
        ce = old.restitution if restitution is None else restitution
        contact = jc.Contact(law=jc.laws.CONTACT_LAWS[law](), restitution=ce)
        mech = eqx.tree_at(lambda m, j=j: m.joints[j].contact, mech, contact)
    return mech


def with_ideal(mech, *names):
    """``mech`` with the joints ``names`` ideal."""
    for j in names:
        mech = eqx.tree_at(lambda m, j=j: m.joints[j], mech, jc.Ideal())
    return mech


def body_index(mech, body):
    """Position of ``body`` in the per-body arrays of a frame."""
    return jc.ideal.body_index(mech, body)


def tree_allclose(x, y, *, rtol=1e-5, atol=1e-8, equal_nan=False):
    """Whether two pytrees have the same structure and leaves that are equal (non-array
    leaves) or ``numpy.allclose`` (array leaves, with the same shapes and dtypes)."""
    import jax
    import numpy as np

    xs, x_def = jax.tree_util.tree_flatten(x)
    ys, y_def = jax.tree_util.tree_flatten(y)
    if x_def != y_def:
        return False
    for a, b in zip(xs, ys):
        if isinstance(a, (jax.Array, np.ndarray, np.generic)) or isinstance(b, (jax.Array, np.ndarray, np.generic)):
            a, b = np.asarray(a), np.asarray(b)
            if a.shape != b.shape or a.dtype != b.dtype:
                return False
            if not np.allclose(a, b, rtol=rtol, atol=atol, equal_nan=equal_nan):
                return False
        elif a != b:
            return False
    return True
