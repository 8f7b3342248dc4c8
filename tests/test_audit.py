"""The approach-speed memory against the true normal speed at every contact onset of
a run (:mod:`jaxcrank.analysis.validation.memory_audit`); the 0.4 s distribution is in docs/numerics.md
(``python bench/audit_memory.py``)."""

import numpy as np

import jaxcrank as jc
from jaxcrank import audit, config


def test_every_onset_of_a_short_window_uses_the_true_approach_speed():
    # the setting; its first stale re-impact was C at 4.34 ms (+8 %, 32 us
    # after a separation) with the previous memory design
    mech = config.apply_overrides(jc.paper(), ["contact.law=hunt_crossley", "friction.law=ambrosio"])
    onsets = audit.onsets(mech, 5e-3, max_steps=20_000)
    floor = mech.joints["B"].memory.min_approach_speed
    assert floor == mech.joints["C"].memory.min_approach_speed
    fast = onsets.true > floor
    assert fast.sum() >= 8
    assert np.all(np.abs(onsets.relative_error[fast]) < 0.005)
    assert onsets.summary(min_speed=floor)["over_0.5%"] == 0
