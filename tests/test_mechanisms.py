"""Mechanisms as data: the named presets, every choice of clearance joints on the
slider-crank (A, B, C) and the four-bar (A, B, C, D), and Flores and Ambrósio's
high-speed slider-crank (its ideal slider acceleration against the closed form)."""

import argparse
import dataclasses
import itertools
import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank import cli, ideal, model, outputs
from jaxcrank.physics.linkage import GROUND, Prismatic
from jaxcrank.runs import config

#: the joints with clearance of the presets this file is about
CUT = {
    "slider-crank-A": ("A",),
    "slider-crank-ABC": ("A", "B", "C"),
    "four-bar-ABCD": ("A", "B", "C", "D"),
    "flores": ("C",),
}


@pytest.mark.parametrize("name", list(jc.PRESETS))
def test_every_preset_builds_its_linkage(name):
    mech = jc.preset(name)
    lk, tree = model.compile_model(mech).linkage, model.compile_model(mech).tree
    assert set(lk.joints) == set(lk.connections) and tree.cut
    if name in CUT:
        assert tree.cut == CUT[name]
        clearance = 5e-4 if name != "flores" else 0.5e-3
        for j in tree.cut:
            assert abs(float(mech.joints[j].clearance) - clearance) < 1e-15


def test_the_command_line_takes_the_new_presets():
    p = argparse.ArgumentParser()
    config.add_mechanism_arguments(p, "simulate")
    for name in CUT:
        mech = config.mechanism_from_arguments(p.parse_args(["--mechanism", name]))
        assert model.compile_model(mech).tree.cut == CUT[name]


# --------------------------------------------------------------------------- every subset of clearance joints

REVOLUTES = {"slider-crank": "ABC", "four-bar": "ABCD"}
#: run in the default suite; the other subsets (about 8 s of compilation each) are `slow`
QUICK = {("slider-crank", ("A",)), ("four-bar", ("A", "B", "C", "D"))}


def _variant(kind: str, subset: tuple[str, ...]):
    """The slider-crank (paper) or four-bar with 0.5 mm clearance at the joints of
    ``subset`` and every other joint ideal."""
    base = jc.paper() if kind == "slider-crank" else jc.four_bar()
    ideal_joints = {**base.joints, **{j: jc.Ideal() for j in REVOLUTES[kind]}}
    base = eqx.tree_at(lambda m: m.joints, base, ideal_joints)
    return jc.with_clearance(base, **{j: 5e-4 for j in subset})


def _subsets():
    for kind, names in REVOLUTES.items():
        for k in range(1, len(names) + 1):
            for subset in itertools.combinations(names, k):
                marks = () if (kind, subset) in QUICK else (pytest.mark.slow,)
                yield pytest.param(kind, subset, marks=marks, id=f"{kind}-{''.join(subset)}")


def _site_world(lk, tree, q, site):
    """World position of a joint site (m) from the centre-of-mass poses q (bodies, 3)."""
    if site.body == GROUND:
        return np.asarray(lk.ground[site.point].vector())
    body = lk.bodies[site.body]
    x, y, angle = np.asarray(q[tree.bodies.index(site.body)])
    local = np.asarray(body.points[site.point].vector() - body.centre_of_mass.vector())
    c, s = np.cos(angle), np.sin(angle)
    return np.array([x + c * local[0] - s * local[1], y + s * local[0] + c * local[1]])


@pytest.mark.parametrize(("kind", "subset"), list(_subsets()))
def test_every_subset_of_clearance_joints_simulates(kind, subset):
    """4 ms from the pins-centred start (the first impacts come from about 1.2 ms on): the
    solve succeeds; the tree has 3 coordinates per body less 2 per ideal joint (a
    prismatic joint holds 2 as a revolute one does) less the prescribed crank angle;
    at every sample every ideal joint stays closed (its two sites coincide, a slider
    stays on its guide line) and every clearance joint's eccentricity is its pin site
    minus its hole site, to 1e-12 m."""
    mech = _variant(kind, subset)
    lk, tree = model.compile_model(mech).linkage, model.compile_model(mech).tree
    assert tree.cut == subset
    n_ideal = len(lk.connections) - len(subset)
    assert tree.n == 3 * len(lk.bodies) - 2 * n_ideal - 1
    sim = jc.simulate(mech, 4e-3, n_samples=9)
    frames = outputs.frames(sim)
    assert np.all(np.isfinite(np.asarray(sim.ys)))
    for i in range(sim.ts.shape[0]):
        q = frames.q[i]
        for k, j in enumerate(tree.joints):
            conn = lk.connections[j]
            hole, pin = (_site_world(lk, tree, q, s) for s in conn.sites())
            if isinstance(conn, Prismatic):
                normal = np.array([-np.sin(conn.direction), np.cos(conn.direction)])  # the guide is the ground
                assert abs(np.dot(pin - hole, normal)) < 1e-12, (j, float(sim.ts[i]))
            elif j in subset:
                np.testing.assert_allclose(np.asarray(frames.eccentricity[i, k]), pin - hole, rtol=0, atol=1e-12)
            else:
                assert np.linalg.norm(pin - hole) < 1e-12, (j, float(sim.ts[i]))


@pytest.mark.parametrize("kind", list(REVOLUTES))
def test_a_mechanism_with_every_joint_ideal_moves_as_the_ideal_mechanism(kind):
    """With every joint ideal the loop is closed in the dynamics by a dyad: no coordinate
    is left, and the motion is the ideal mechanism's (poses to 1e-12 m and rad); each
    joint's reaction equals the ideal mechanism's inverse dynamics (to 1e-9 of the largest)
    and so does the driving moment."""
    mech = _variant(kind, ())
    compiled = model.compile_model(mech)
    assert compiled.tree.n == 0 and len(compiled.tree.closures) == 1
    sim = jc.simulate(mech, 0.02, n_samples=21)
    frames = outputs.frames(sim)
    np.testing.assert_allclose(np.asarray(frames.q), np.asarray(frames.ideal_q), rtol=0, atol=1e-12)
    forces, torques = jax.vmap(lambda t: ideal.joint_reactions(mech, t))(sim.ts)
    expected = np.stack([np.linalg.norm(np.asarray(forces[j]), axis=-1) for j in compiled.tree.joints], axis=1)
    scale = np.max(expected)
    np.testing.assert_allclose(np.asarray(frames.normal_force), expected, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(np.asarray(frames.driving_moment), np.asarray(torques), rtol=0, atol=1e-9 * scale)


# --------------------------------------------------------------------------- Flores and Ambrósio's slider-crank

#: the ideal slider acceleration of the closed form (model note), m/s^2, at crank angles in deg
FLORES_EXTREMES = {0.0: -19419.0, 122.0: 9696.0, 180.0: 7996.0, 238.0: 9696.0}


def _flores_closed_form(theta):
    """Slider acceleration (m/s^2) of the in-line slider-crank r = 0.05 m, l = 0.12 m at
    5000 rpm: a = -r w^2 (cos t + lam cos 2t / D + lam^3 sin^2 2t / (4 D^3)), D = sqrt(1 - lam^2 sin^2 t)."""
    r, lam, w = 0.05, 0.05 / 0.12, 5000.0 * 2.0 * np.pi / 60.0
    d = np.sqrt(1.0 - lam**2 * np.sin(theta) ** 2)
    return -r * w**2 * (np.cos(theta) + lam * np.cos(2 * theta) / d + lam**3 * np.sin(2 * theta) ** 2 / (4 * d**3))


@jax.jit
def _slider_acceleration(mech, degrees):
    i = ideal.body_index(mech, "slider")
    ts = jnp.radians(degrees) / mech.driver.speed
    return jax.vmap(lambda t: ideal.kinematics(mech, t)[2][i, 0])(ts)


def _flores_slider_acceleration(degrees):
    return np.asarray(_slider_acceleration(jc.preset("flores"), jnp.asarray(degrees, dtype=float)))


def test_flores_ideal_slider_acceleration_extremes_within_half_a_percent():
    """The zero-clearance limit of the preset (its ideal mechanism) gives the slider's
    acceleration at top dead centre, at the positive lobe's maxima (122 and 238 deg) and at
    bottom dead centre within 0.5 % of the closed-form values (measured: 0.003 % at most,
    the values' own rounding to 1 m/s^2), and the lobe's maximum lies at 122.0 deg."""
    got = _flores_slider_acceleration(list(FLORES_EXTREMES))
    for (deg, expected), a in zip(FLORES_EXTREMES.items(), got):
        assert abs(a / expected - 1.0) < 5e-3, (deg, a)
    lobe = np.linspace(100.0, 140.0, 4001)
    assert abs(lobe[np.argmax(_flores_slider_acceleration(lobe))] - 122.0) < 0.05


def test_flores_ideal_slider_acceleration_equals_the_closed_form():
    """Over a revolution, to 1e-9 of r w^2 (forward-mode derivatives of the dyad's closed form)."""
    degrees = np.linspace(0.0, 360.0, 73)
    a = _flores_slider_acceleration(degrees)
    scale = 0.05 * (5000.0 * 2.0 * np.pi / 60.0) ** 2
    assert np.max(np.abs(a - _flores_closed_form(np.radians(degrees)))) < 1e-9 * scale


def test_flores_simulates_its_first_impacts():
    """3 ms (a quarter turn at 5000 rpm): the solve succeeds and pin C hits its bearing."""
    mech = jc.preset("flores")
    sim = jc.simulate(mech, 3e-3, n_samples=31)
    k = model.compile_model(mech).tree.joints.index("C")
    force = np.asarray(outputs.frames(sim).normal_force[:, k])
    assert np.all(np.isfinite(np.asarray(sim.ys))) and force.max() > 0.0


def test_cli_simulate_runs_the_four_bar_preset(tmp_path):
    """``jaxcrank simulate --mechanism four-bar`` (10 ms): the trajectory has the four-bar's
    bodies and the eccentricity of each clearance joint, the metrics name the rocker (the
    output link) and no slider, the figures show each clearance joint's pin trajectory and
    contact force and the rocker's deviations, and config.toml runs the same four-bar again."""
    out = tmp_path / "run"
    args = ["simulate", "--mechanism", "four-bar", "--out", str(out), "--t1", "0.01", "--samples-per-degree", "1"]
    assert cli.main([*args, "--quiet"]) == 0
    header = (out / "trajectory.csv").read_text().splitlines()[0].split(",")
    assert {"rocker_angle", "ideal_rocker_angle", "ecc_B_x", "ecc_C_y", "transmission_angle"} <= set(header)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["solver"]["steps"] > 0 and "rms_rocker_angle_deviation_deg" in summary["metrics"]
    assert not any("slider" in k for k in summary["metrics"]) and summary["units"]["rocker_angle"] == "deg"
    figures = {p.name for p in (out / "figures").glob("*.png")}
    assert {"pin_trajectories.png", "contact_force.png", "rocker_angle.png", "rocker_acceleration.png"} <= figures
    again, preset = config.load(out / "config.toml"), jc.four_bar()
    assert isinstance(again, jc.FourBar) and jax.tree.structure(again) == jax.tree.structure(preset)
    assert [float(v) for v in jax.tree.leaves(again)] == [float(v) for v in jax.tree.leaves(preset)]


def test_cli_metrics_of_a_torque_driven_run_start_where_its_crank_completes_a_turn(tmp_path):
    """A free-running slider-crank (zero torque, every joint ideal) slows from its initial
    speed, so its first turn takes longer than one nominal period: ``simulate``'s metrics
    window starts where the crank angle in ``trajectory.csv`` first reaches its start plus
    360 deg (within one sample interval), not at 2 pi / initial speed."""
    mech = jc.SliderCrank(driver=jc.Torque(body="crank", torque=0.0, initial_speed=150.0))
    mech = dataclasses.replace(mech, joints={name: jc.Ideal() for name in mech.joints})
    config.save(mech, tmp_path / "free.toml")
    out = tmp_path / "run"
    args = ["simulate", "--config", str(tmp_path / "free.toml"), "--out", str(out), "--t1", "0.12", "--no-figures"]
    assert cli.main([*args, "--quiet"]) == 0
    table = np.genfromtxt(out / "trajectory.csv", delimiter=",", names=True)
    turned = np.abs(table["crank_angle"] - table["crank_angle"][0])
    i = int(np.argmax(turned >= 360.0))
    assert turned[i] >= 360.0 and i > 0
    summary = json.loads((out / "summary.json").read_text())
    start = summary["metrics"]["window_start_s"]
    assert table["t"][i - 1] <= start <= table["t"][i], (start, table["t"][i - 1 : i + 1])
    assert start > 1.1 * (2 * np.pi / 150.0) and summary["metrics_window"].startswith("after the first revolution")
