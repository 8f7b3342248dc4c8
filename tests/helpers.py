import equinox as eqx

import jaxcrank as jc


def frictionless(mech):
    return eqx.tree_at(lambda m: m.friction.coefficient, mech, 0.0)


def with_law(mech, law, restitution=None):
    """``mech`` with the contact law named ``law`` (a key of ``jc.laws.CONTACT_LAWS``)."""
    ce = mech.contact.restitution if restitution is None else restitution
    return eqx.tree_at(lambda m: m.contact, mech, jc.Contact(law=jc.laws.CONTACT_LAWS[law](), restitution=ce))
