"""Each joint's force vector (``force_<joint>_x``, ``force_<joint>_y``: on the pin or slider
side, world frame, N), checked against Newton's law and the reported magnitudes."""

from pathlib import Path

import jax
import numpy as np

import jaxcrank as jc
from jaxcrank import outputs
from jaxcrank.runs import config

LINKAGES = Path(__file__).resolve().parents[1] / "docs" / "linkages"


def _net_joint_force(cols, lk, body):
    """Sum of the joint forces on ``body``: + on a pin (slider) side, - on a hole (guide) side."""
    fx, fy = np.zeros_like(cols["t"]), np.zeros_like(cols["t"])
    for j, conn in lk.connections.items():
        hole, pin = conn.sites()
        for site, sign in ((pin, 1.0), (hole, -1.0)):
            if site.body == body:
                fx = fx + sign * cols[f"force_{j}_x"]
                fy = fy + sign * cols[f"force_{j}_y"]
    return fx, fy


def test_crank_shaper_joint_forces_close_newtons_law_and_match_the_magnitudes():
    """The crank-shaper (ideal pivots O2, O4 and slot, a clearance pin A), 20 ms through
    its start-up impacts: on every body the joint forces plus gravity equal m a (to
    1e-9 of the largest joint force); the clearance joint's force has the magnitude
    sqrt(normal^2 + friction^2) and an ideal joint's the reaction magnitude ``force_<j>_normal``."""
    mech = config.load(LINKAGES / "crank-shaper.toml")
    cols = outputs.trajectory(jc.simulate(mech, 0.02, n_samples=41))
    lk = mech.linkage()
    units = outputs.columns(mech)
    names = list(units)
    for j in lk.connections:
        assert units[f"force_{j}_x"] == units[f"force_{j}_y"] == "N"
        # after the joint's own columns, in order
        assert names.index(f"force_{j}_x") == names.index(f"slip_speed_{j}") + 1
        assert names.index(f"force_{j}_y") == names.index(f"force_{j}_x") + 1
    scale = max(np.max(np.hypot(cols[f"force_{j}_x"], cols[f"force_{j}_y"])) for j in lk.connections)
    assert scale > 100.0  # loads of hundreds of N: the check is not vacuous
    for b, body in lk.bodies.items():
        fx, fy = _net_joint_force(cols, lk, b)
        np.testing.assert_allclose(fx, body.mass * cols[f"{b}_ax"], rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(fy - body.mass * lk.gravity, body.mass * cols[f"{b}_ay"], rtol=0, atol=1e-9 * scale)
    for j, law in lk.joints.items():
        magnitude = np.hypot(cols[f"force_{j}_x"], cols[f"force_{j}_y"])
        expected = np.hypot(cols[f"force_{j}_normal"], cols[f"force_{j}_friction"])
        if not law.ideal:
            assert np.max(cols[f"force_{j}_normal"]) > 0.0, j  # the pin A touches its bore
        np.testing.assert_allclose(magnitude, expected, rtol=1e-12, atol=1e-9 * scale)


def test_an_all_ideal_four_bar_reports_the_inverse_dynamics_reactions():
    """Every joint of the crank-rocker ideal (its loop closed by a dyad): each joint's force
    vector equals the ideal mechanism's inverse dynamics, the force on the pin side
    (``jc.ideal.joint_reactions``), to 1e-9 of the largest."""
    mech = config.load(LINKAGES / "crank-rocker.toml")
    fields = ("bodies", "ground", "connections", "joints", "driver", "gravity", "outputs")
    mech = jc.Linkage(**{**{k: getattr(mech, k) for k in fields}, "joints": {j: jc.Ideal() for j in mech.joints}})
    sim = jc.simulate(mech, 0.02, n_samples=11)
    cols = outputs.trajectory(sim)
    forces, _ = jax.vmap(lambda t: jc.ideal.joint_reactions(mech, t))(sim.ts)
    scale = max(float(np.max(np.abs(np.asarray(f)))) for f in forces.values())
    for j, f in forces.items():
        f = np.asarray(f)
        np.testing.assert_allclose(cols[f"force_{j}_x"], f[:, 0], rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(cols[f"force_{j}_y"], f[:, 1], rtol=0, atol=1e-9 * scale)
