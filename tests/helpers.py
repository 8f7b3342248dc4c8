import equinox as eqx

import jaxcrank as jc


def frictionless(mech):
    return eqx.tree_at(lambda m: m.friction.coefficient, mech, 0.0)


def with_law(mech, law, restitution=None):
    """``mech`` with the contact law named ``law`` (a key of ``jc.laws.CONTACT_LAWS``)."""
    ce = mech.contact.restitution if restitution is None else restitution
    return eqx.tree_at(lambda m: m.contact, mech, jc.Contact(law=jc.laws.CONTACT_LAWS[law](), restitution=ce))


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
