"""Impacts of a free pin on a bearing wall (jaxcrank.analysis.validation.wall_impact) through
the clearance joint law, with the frozen and the forgetting memory: every contact law's
achieved restitution against the exact relation chi (1 + e) = ln((1 + chi) / (1 - chi e))
(model.md), to 1 % of e."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcrank.analysis.validation import wall_impact
from jaxcrank.physics import laws, memory
from jaxcrank.physics.joints import Clearance
from jaxcrank.physics.params import Contact, Friction

MEMORY_LAWS = {"frozen": memory.FrozenMemory(), "forgetting": memory.ForgettingMemory()}
SPEEDS = np.geomspace(3e-3, 1.0, 6)  # m/s
RESTITUTIONS = (0.3, 0.9)


def _joint(law, memory_law, restitution=0.5):
    """The paper's steel joint (8 / 7.5 mm), frictionless, with the named contact law."""
    contact = Contact(law=laws.CONTACT_LAWS[law](), restitution=restitution)
    return Clearance(
        hole_radius=8e-3, pin_radius=7.5e-3, contact=contact, friction=Friction(coefficient=0.0), memory=memory_law
    )


def _exact_restitution(law, restitution):
    return laws.achieved_restitution(float(laws.CONTACT_LAWS[law]().hysteresis_factor(restitution)))


@pytest.mark.parametrize("memory_name", list(MEMORY_LAWS))
@pytest.mark.parametrize("law", list(laws.CONTACT_LAWS))
def test_isolated_impacts_from_3_mm_s_to_1_m_s_follow_exact_relation(law, memory_name):
    """A 1 kg pin hits the fixed wall at 3 mm/s to 1 m/s: the impact (under 1.5 ms at
    3 mm/s) ends before the forgetting memory's dwell time, so both memories latch the
    approach speed for the whole impact and the rebound follows the exact relation."""
    memory_law = MEMORY_LAWS[memory_name]

    def ratio(speed, restitution):
        return wall_impact.rebound_ratio(_joint(law, memory_law, restitution), speed)

    speeds, ces = (jnp.asarray(a) for a in np.meshgrid(SPEEDS, RESTITUTIONS, indexing="ij"))
    achieved = np.asarray(jax.vmap(ratio)(speeds.ravel(), ces.ravel())).reshape(speeds.shape)
    expected = np.array([_exact_restitution(law, ce) for ce in RESTITUTIONS])
    assert np.all(np.abs(achieved / expected - 1.0) < 0.01), achieved / expected - 1.0


def test_forgetting_memory_latches_through_the_slowest_isolated_impact():
    """The slowest impact of the sweep (hybrid law, 3 mm/s, about 1.3 ms at c_e = 0.5) ends
    with the dwell clock reading its duration (to the freeze blend before onset, under
    0.1 us) below t_dwell, and the memory still at the approach speed."""
    law = memory.ForgettingMemory()
    impact = wall_impact.single_impact(_joint("hybrid", law), 3e-3)
    memory_end, dwell_end = impact.law_state_at_separation
    assert impact.duration < law.t_dwell
    assert abs(dwell_end - impact.duration) < 1e-7
    assert abs(memory_end / 3e-3 - 1.0) < 1e-9


@pytest.mark.parametrize("memory_name", list(MEMORY_LAWS))
def test_reimpact_within_20_us_follows_exact_relation(memory_name):
    """A pin rebounds from the wall at 0.5 m/s and is caught again at 0.2 m/s a few
    microseconds after separating: the memory must hold 0.2 m/s at the second onset,
    not part of the first impact's speed, and the forgetting memory's dwell clock must
    have restarted (at the separation it reads the second impact's duration alone)."""
    second = wall_impact.reimpact(_joint("hybrid", MEMORY_LAWS[memory_name]))
    assert second.since_separation < 20e-6
    assert abs(second.memory_at_onset / second.approach_speed - 1) < 0.005
    assert abs(second.restitution / _exact_restitution("hybrid", 0.5) - 1) < 0.01
    if memory_name == "forgetting":
        assert abs(second.law_state_at_separation[1] - second.duration) < 1e-7


@pytest.mark.parametrize("memory_name", list(MEMORY_LAWS))
def test_slow_decelerating_approach_follows_exact_relation(memory_name):
    """An impact at 0.02 m/s after 10 us of 1000 m/s^2 normal deceleration: the memory
    must follow delta_dot to the onset."""
    hit = wall_impact.slow_approach(_joint("hybrid", MEMORY_LAWS[memory_name]), approach_speed=0.02)
    assert abs(hit.approach_speed - 0.02) < 1e-9
    assert abs(hit.memory_at_onset / hit.approach_speed - 1) < 0.005
    assert abs(hit.restitution / _exact_restitution("hybrid", 0.5) - 1) < 0.01
