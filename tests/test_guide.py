"""The prismatic clearance joint (physics/guide.py) against hand calculations, symmetry,
the sign of its dissipation, its power balance and finite gradients."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcrank.physics import laws, presets
from jaxcrank.physics.guide import CORNERS, GuideClearance, corner_stiffness
from jaxcrank.physics.joints import Ideal, JointAccelerations, JointKinematics
from jaxcrank.physics.memory import ForgettingMemory, FrozenMemory
from jaxcrank.physics.params import Contact, Friction, Material, ParameterError

STEEL = 2.0 * (1.0 - 0.3**2) / 207e9  # s1 + s2, 1/Pa


def _law(**kw):
    """The guide of these tests: one approach-speed memory entry per corner (the frozen
    memory law), so a corner's state is its memory; the default law is checked apart."""
    base = dict(length=0.040, height=0.026, clearance=2.5e-4, corner_radius=1e-3, memory=FrozenMemory())
    base.update(kw)
    return GuideClearance(**base)


def _rot(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def _perp(v):
    return np.array([-v[1], v[0]])


class Motion:
    """A guide and a slider moving with constant accelerations (world frame); the slider's
    pose is given in the guide's frame at t = 0: centre (x, y), tilt, and their rates."""

    def __init__(self, local=(0.01, 0.0), tilt=0.0, local_rate=(0.8, 0.03), tilt_rate=-1.0):
        self.g, self.vg, self.ag = np.array([0.1, -0.2]), np.array([0.3, -0.1]), np.array([2.0, 5.0])
        self.th, self.wg, self.alg = 0.4, 2.0, -30.0
        rg = _rot(self.th)
        self.p = self.g + rg @ np.asarray(local)
        self.vp = self.vg + self.wg * _perp(self.p - self.g) + rg @ np.asarray(local_rate)
        self.ap = np.array([-40.0, 25.0])
        self.ths, self.ws, self.als = self.th + tilt, self.wg + tilt_rate, 50.0

    def at(self, t):
        """(g, guide angle, p, slider angle) at time t, numpy."""
        return (
            self.g + self.vg * t + 0.5 * self.ag * t**2,
            self.th + self.wg * t + 0.5 * self.alg * t**2,
            self.p + self.vp * t + 0.5 * self.ap * t**2,
            self.ths + self.ws * t + 0.5 * self.als * t**2,
        )

    def kin(self, t=0.0):
        g, th, p, ths = self.at(t)
        f = lambda v: jnp.asarray(v, dtype=float)
        return JointKinematics(
            f(g), f(self.vg + self.ag * t), f(th), f(self.wg + self.alg * t),
            f(p), f(self.vp + self.ap * t), f(ths), f(self.ws + self.als * t),
        )  # fmt: skip

    def acc(self, t=0.0):
        f = lambda v: jnp.asarray(v, dtype=float)
        return JointAccelerations(f(self.ag), f(self.alg), f(self.ap), f(self.als))


def _hand_corners(law, g, th, p, ths):
    """Penetrations and contact points (slider frame, m) of the four rounded corners, by hand
    in the guide frame."""
    r, half_l, half_h = law.corner_radius, 0.5 * law.length, 0.5 * law.height
    centre = _rot(-th) @ (p - g)
    out, local = [], []
    for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1)):
        rounding = np.array([sx * (half_l - r), sy * (half_h - r)])
        y = centre[1] + (_rot(ths - th) @ rounding)[1]
        out.append(sy * y + r - (half_h + law.clearance))
        # the contact point in the slider's frame: on the rounding circle, nearest the face
        local.append(rounding + r * sy * (_rot(th - ths) @ np.array([0.0, 1.0])))
    return np.array(out), np.array(local)


def _hand_axial(law, motion, local, t):
    """Axial coordinate in the guide frame of the slider's material points ``local``."""
    g, th, p, ths = motion.at(t)
    return np.array([(_rot(-th) @ (p + _rot(ths) @ q - g))[0] for q in local])


def _central(f, h=1e-6):
    """df/dt at t = 0: central differences at h and h / 2, Richardson-extrapolated (error O(h^4))."""
    coarse, fine = (f(h) - f(-h)) / (2.0 * h), (f(0.5 * h) - f(-0.5 * h)) / h
    return (4.0 * fine - coarse) / 3.0


# --------------------------------------------------------------------------- stiffness


def test_corner_stiffness_is_the_plane_limit_of_eq3():
    r = 1e-3
    k = float(corner_stiffness(r, STEEL))
    assert k == pytest.approx(4.0 / 3.0 / STEEL * math.sqrt(r), rel=1e-14)
    assert k == pytest.approx(4.7957e9, rel=1e-4)  # the value the docstring quotes
    # R_h R_p / (R_h - R_p) = r for R_h = r, R_p = r / 2: Eq. 3 exactly
    assert k == pytest.approx(float(laws.hertz_stiffness(r, 0.5 * r, STEEL)), rel=1e-14)
    # a hole 1000 times the corner radius is nearly flat: Eq. 3 within 5e-4
    assert abs(float(laws.hertz_stiffness(1e3 * r, r, STEEL)) / k - 1.0) < 5.1e-4


# --------------------------------------------------------------------------- forces by hand


@pytest.mark.parametrize("law_name", ["lankarani_nikravesh", "flores", "hybrid"])
def test_forces_match_the_contact_law_at_each_corner(law_name):
    """Upper corners pressed into the upper face (20 and 5 um), lower ones clear: every
    corner's force from the Hertz-type law with R_h = r, R_p = r / 2 (the corner
    stiffness) and friction -mu F_n sign(slip), summed into one wrench by hand."""
    contact_law = laws.CONTACT_LAWS[law_name]()
    law = _law(
        contact=Contact(law=contact_law, restitution=0.7),
        friction=Friction(coefficient=0.1),
        slider_material=Material(youngs_modulus=200e9, poisson_ratio=0.29),
    )
    half_arm = 0.5 * law.length - law.corner_radius
    tilt = math.asin(7.5e-6 / half_arm)
    y = law.clearance + 12.5e-6 + (0.5 * law.height - law.corner_radius) * (1.0 - math.cos(tilt))
    motion = Motion(local=(0.01, y), tilt=tilt)
    memory = jnp.array([0.5, 0.3, 0.2, 0.1])
    out = law.forces(motion.kin(), memory)

    delta, local = _hand_corners(law, *motion.at(0.0))
    np.testing.assert_allclose(delta, [20e-6, 5e-6, delta[2], delta[3]], rtol=1e-9)
    assert np.all(delta[2:] < -4e-4)
    rate = _central(lambda t: _hand_corners(law, *motion.at(t))[0])
    slip = _central(lambda t: _hand_axial(law, motion, local, t))
    assert np.all(np.abs(slip) > 0.1)  # full slip: c_d = 1

    s = Material(200e9, 0.29).compliance + Material().compliance
    geometry = dict(hole_radius=law.corner_radius, pin_radius=0.5 * law.corner_radius, compliance_sum=s)
    hertz = laws.LankaraniNikravesh()
    g, th, p, ths = motion.at(0.0)
    e, n = np.array([math.cos(th), math.sin(th)]), np.array([-math.sin(th), math.cos(th)])
    force, moment, f_sum = np.zeros(2), 0.0, 0.0
    for k, sy in enumerate((1, 1, -1, -1)):
        # K delta^1.5 of the Hertz law at R_h = r, R_p = r / 2, with this law's damping
        elastic = float(hertz.elastic_force(delta[k], **geometry))
        chi = float(contact_law.hysteresis_factor(0.7))
        f_n = max(elastic * (1.0 + chi * rate[k] / float(memory[k])), 0.0) if delta[k] > 0 else 0.0
        if law_name == "lankarani_nikravesh":  # the law's own normal_force at R_h = r, R_p = r / 2
            by_law = hertz.normal_force(delta[k], rate[k], memory[k], 0.7, **geometry)[0]
            assert f_n == pytest.approx(float(by_law), rel=1e-12, abs=1e-12)
        f_t = -0.1 * f_n * math.copysign(1.0, slip[k])
        f = -sy * f_n * n + f_t * e
        force += f
        arm = _rot(ths) @ local[k]
        moment += arm[0] * f[1] - arm[1] * f[0]
        f_sum += f_n
    assert f_sum > 100.0
    np.testing.assert_allclose(out.aux[1], rate, rtol=1e-8)
    np.testing.assert_allclose(out.force, force, rtol=1e-8)
    assert float(out.pin_moment) == pytest.approx(moment, rel=1e-8)
    assert float(out.hole_moment) == -float(out.pin_moment)
    np.testing.assert_array_equal(out.pin_point, out.hole_point)
    np.testing.assert_allclose(out.pin_point, p, rtol=1e-15)
    assert float(out.normal_force) == pytest.approx(f_sum, rel=1e-8)
    assert float(out.penetration) == pytest.approx(20e-6, rel=1e-9)
    np.testing.assert_allclose(out.aux[0], delta, rtol=1e-9, atol=1e-15)
    # eccentricity: (lateral offset, tilt x half length), guide frame
    np.testing.assert_allclose(out.eccentricity, [y, 0.5 * law.length * tilt], rtol=1e-12)


# --------------------------------------------------------------------------- symmetry


def test_no_contact_no_force():
    law = _law()
    for local, tilt in [((0.0, 0.0), 0.0), ((0.03, 1e-4), 5e-3), ((-0.02, -2e-4), -2e-3)]:
        out = law.forces(Motion(local=local, tilt=tilt).kin(), jnp.full(4, 0.3))
        for field in ("force", "pin_moment", "dissipation", "elastic_energy", "normal_force", "friction_force"):
            np.testing.assert_array_equal(getattr(out, field), 0.0)
        assert float(out.penetration) < 0.0
    centred = law.forces(Motion(local=(0.0, 0.0), tilt=0.0).kin(), jnp.full(4, 0.3))
    assert float(centred.penetration) == pytest.approx(-law.clearance, rel=1e-12)


def _mirror(kin: JointKinematics) -> JointKinematics:
    """The joint reflected across its axis (the line through the guide point along the
    axis direction, at this instant)."""
    th = kin.hole_angle
    e = jnp.stack([jnp.cos(th), jnp.sin(th)])
    reflect = 2.0 * jnp.outer(e, e) - jnp.eye(2)
    g = kin.hole_position
    return JointKinematics(
        g, reflect @ kin.hole_velocity, th, -kin.hole_angular_velocity,
        g + reflect @ (kin.pin_position - g), reflect @ kin.pin_velocity,
        2.0 * th - kin.pin_angle, -kin.pin_angular_velocity,
    )  # fmt: skip


@pytest.mark.parametrize("tilt", [2e-3, -1.5e-3])
def test_mirrored_states_give_mirrored_forces(tilt):
    law = _law()
    y = law.clearance - 0.5 * law.length * abs(tilt) + 2e-5
    kin = Motion(local=(0.01, y), tilt=tilt, local_rate=(-0.4, -0.02), tilt_rate=0.7).kin()
    memory = jnp.array([0.5, 0.3, 0.2, 0.1])
    out = law.forces(kin, memory)
    mirrored = law.forces(_mirror(kin), memory[jnp.array([3, 2, 1, 0])])  # upper <-> lower corners
    assert float(out.normal_force) > 100.0
    th = kin.hole_angle
    e = jnp.stack([jnp.cos(th), jnp.sin(th)])
    reflect = 2.0 * jnp.outer(e, e) - jnp.eye(2)
    np.testing.assert_allclose(mirrored.force, reflect @ out.force, rtol=1e-10, atol=1e-9)
    assert float(mirrored.pin_moment) == pytest.approx(-float(out.pin_moment), rel=1e-10)
    for field in ("dissipation", "elastic_energy", "penetration", "normal_force", "friction_force", "slip_speed"):
        assert float(getattr(mirrored, field)) == pytest.approx(float(getattr(out, field)), rel=1e-10)
    np.testing.assert_allclose(mirrored.eccentricity, -out.eccentricity, rtol=1e-10)
    np.testing.assert_allclose(mirrored.aux[0], out.aux[0][jnp.array([3, 2, 1, 0])], rtol=1e-10)


# --------------------------------------------------------------------------- energy


def _random_states(n, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        motion = Motion(
            local=(rng.uniform(-0.02, 0.02), rng.uniform(-3e-4, 3e-4)),
            tilt=rng.uniform(-2e-2, 2e-2),
            local_rate=rng.uniform(-0.5, 0.5, 2),
            tilt_rate=rng.uniform(-20.0, 20.0),
        )
        out.append((motion, jnp.asarray(rng.uniform(1e-4, 1.0, 4))))
    return out


@pytest.mark.parametrize("law_name", sorted(laws.CONTACT_LAWS))
def test_dissipation_is_never_negative(law_name):
    law = _law(contact=Contact(law=laws.CONTACT_LAWS[law_name](), restitution=0.5))
    states = _random_states(200)
    kins = jax.tree.map(lambda *x: jnp.stack(x), *[m.kin() for m, _ in states])
    memory = jnp.stack([s for _, s in states])
    out = jax.vmap(law.forces)(kins, memory)
    assert int(jnp.sum(out.normal_force > 0.0)) > 50  # most states in contact
    assert float(jnp.min(out.dissipation)) >= 0.0


def test_power_balance():
    """The wrench's power on the relative motion equals -dE/dt - dissipation, E the
    stored elastic energy (difference quotient along the motion, within 1e-6)."""
    law = _law(contact=Contact(law=laws.Gonthier(), restitution=0.6))
    checked = 0
    for motion, memory in _random_states(40, seed=1):
        out = law.forces(motion.kin(), memory)
        if float(out.normal_force) == 0.0:
            continue
        kin = motion.kin()
        arm = np.asarray(kin.pin_position - kin.hole_position)
        v_guide = kin.hole_velocity + kin.hole_angular_velocity * _perp(arm)
        power = float(jnp.dot(out.force, kin.pin_velocity - v_guide))
        power += float(out.pin_moment * kin.pin_angular_velocity + out.hole_moment * kin.hole_angular_velocity)
        # the memory held fixed: E depends on positions only
        energy = lambda t, motion=motion, memory=memory: float(law.forces(motion.kin(t), memory).elastic_energy)
        energy_rate = _central(energy, h=2e-7)
        scale = abs(energy_rate) + float(out.dissipation)
        assert abs(power + energy_rate + float(out.dissipation)) < 1e-6 * scale
        checked += 1
    assert checked > 10


def test_memory_tracks_each_corners_normal_acceleration():
    """Away from the faces with the memory on its target, FrozenMemory's rate is the
    target's rate: the corner's normal acceleration (central difference, within 1e-7)."""
    law = _law()
    motion = Motion(local=(0.005, 5e-5), tilt=1e-3)
    target = law.forces(motion.kin(), jnp.zeros(4)).aux[1]
    out = law.forces(motion.kin(), target)
    rate = law.state_rate(motion.kin(), motion.acc(), target, out)
    expected = _central(lambda t: np.asarray(law.forces(motion.kin(t), target).aux[1]))
    assert np.all(np.abs(expected) > 1.0)
    np.testing.assert_allclose(rate, expected, rtol=1e-7)


# --------------------------------------------------------------------------- gradients


def _scalar(law, kin, memory, acc):
    out = law.forces(kin, memory)
    rate = law.state_rate(kin, acc, memory, out)
    total = jnp.sum(out.force) + out.pin_moment + out.dissipation + out.elastic_energy + out.penetration
    return total + jnp.sum(out.eccentricity) + out.friction_force + out.slip_speed + jnp.sum(rate)


@pytest.mark.parametrize("where", ["centred at rest", "touching", "in contact, no slip"])
def test_gradients_are_finite(where):
    law = _law()
    rest = dict(local_rate=(0.0, 0.0), tilt_rate=0.0)
    if where == "centred at rest":
        motion = Motion(local=(0.0, 0.0), tilt=0.0, **rest)
    elif where == "touching":
        motion = Motion(local=(0.0, law.clearance), tilt=0.0, **rest)
    else:
        motion = Motion(local=(0.0, law.clearance + 1e-5), tilt=0.0, local_rate=(0.0, 0.01), tilt_rate=0.0)
    memory = jnp.zeros(4)
    g_kin = jax.grad(lambda k: _scalar(law, k, memory, motion.acc()))(motion.kin())
    as_arrays = jax.tree.map(lambda v: jnp.asarray(v, dtype=float), law)
    g_law = eqx.filter_grad(lambda m: _scalar(m, motion.kin(), memory, motion.acc()))(as_arrays)
    g_mem = jax.grad(lambda m: _scalar(law, motion.kin(), m, motion.acc()))(memory)
    for leaf in jax.tree.leaves((g_kin, g_law, g_mem)):
        assert bool(jnp.all(jnp.isfinite(leaf)))
    assert len(jax.tree.leaves(g_law)) == len(jax.tree.leaves(law)) == 18  # every parameter differentiated
    assert float(g_law.clearance) != 0.0


def test_clearance_is_a_leaf_and_the_property():
    law = _law(clearance=3e-4)
    assert law.clearance == 3e-4
    d = jax.grad(lambda c: eqx.tree_at(lambda m: m.clearance, law, c).forces(Motion().kin(), jnp.zeros(4)).penetration)
    assert float(d(3e-4)) == pytest.approx(-1.0, rel=1e-12)


def test_state_layout():
    law = _law()
    assert law.state_names() == tuple(f"{c}.approach_memory" for c in CORNERS)
    assert law.state_scales(2.0) == (2.0,) * 4
    np.testing.assert_array_equal(law.initial_state(), np.zeros(4))
    # the default memory law (the forgetting one) gives each corner a memory and a dwell clock
    default = GuideClearance(length=0.040, height=0.026, clearance=2.5e-4)
    assert default.memory == ForgettingMemory()
    entries = ("approach_memory", "contact_dwell")
    assert default.state_names() == tuple(f"{c}.{e}" for c in CORNERS for e in entries)
    assert [float(s) for s in default.state_scales(2.0)] == [2.0, ForgettingMemory().t_dwell] * 4


@pytest.mark.parametrize("where", ["touching", "in contact, no slip"])
def test_default_memory_law_gradients_are_finite(where):
    """The default guide (forgetting memory: a memory and a dwell clock per corner), with
    a corner in contact long enough for its gate to be open."""
    law = GuideClearance(length=0.040, height=0.026, clearance=2.5e-4, corner_radius=1e-3)
    rate = (0.0, 0.01) if where != "touching" else (0.0, 0.0)
    motion = Motion(local=(0.0, law.clearance + (1e-5 if where != "touching" else 0.0)), tilt=0.0, local_rate=rate)
    state = jnp.tile(jnp.array([0.05, 2.0 * law.memory.t_dwell]), 4)
    g_state = jax.grad(lambda s: _scalar(law, motion.kin(), s, motion.acc()))(state)
    g_kin = jax.grad(lambda k: _scalar(law, k, state, motion.acc()))(motion.kin())
    for leaf in jax.tree.leaves((g_state, g_kin)):
        assert bool(jnp.all(jnp.isfinite(leaf)))
    assert float(jnp.abs(g_state[::2]).sum()) > 0.0  # the memories set the damping of the corner in contact


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    ("kw", "name"),
    [
        (dict(length=0.0), "length"),
        (dict(height=-1e-3), "height"),
        (dict(clearance=0.0), "clearance"),
        (dict(clearance=float("nan")), "clearance"),
        (dict(corner_radius=0.0), "corner_radius"),
        (dict(corner_radius=0.013), "corner_radius"),
        (dict(memory="frozen"), "memory"),
    ],
)
def test_bad_parameters_are_named(kw, name):
    with pytest.raises(ParameterError, match=name):
        _law(**kw)


# --------------------------------------------------------------------------- preset


def test_paper_guide_preset():
    from jaxcrank.physics import dynamics, state

    mech = presets.preset("paper-guide")
    guide = mech.joints["guide"]
    assert isinstance(guide, GuideClearance)
    assert (guide.length, guide.height, guide.clearance) == (0.040, 0.026, 2.5e-4)
    # the block's inertia is the paper's J3 within 1 % (the preset's reason for 40 x 26 mm)
    block = mech.slider_mass * (guide.length**2 + guide.height**2) / 12.0
    assert abs(block / mech.slider_inertia - 1.0) < 0.01
    assert isinstance(mech.joints["B"], type(presets.paper().joints["B"]))
    names = state.state_names(mech)
    assert "slider.angle" in names and "guide.front_upper.approach_memory" in names
    rate = dynamics.vector_field(0.0, state.initial_state(mech), mech)
    assert bool(jnp.all(jnp.isfinite(rate)))
    assert presets.with_clearance(mech, guide=1e-4).joints["guide"].clearance == 1e-4
    ideal_guide = presets.with_clearance(presets.paper(), guide=2e-4).joints["guide"]
    assert isinstance(ideal_guide, GuideClearance) and ideal_guide.clearance == 2e-4
    with pytest.raises(ParameterError, match="clearance"):
        presets.with_clearance(mech, guide=-1e-4)


def test_memory_law_settings_apply_to_every_corner():
    law = _law(memory=FrozenMemory(min_approach_speed=0.2))
    motion = Motion(local=(0.0, law.clearance + 1e-5), tilt=0.0, local_rate=(0.0, 0.05), tilt_rate=0.0)
    low = law.forces(motion.kin(), jnp.zeros(4))
    high = law.forces(motion.kin(), jnp.full(4, 0.2))
    assert float(low.normal_force) == pytest.approx(float(high.normal_force), rel=1e-14)


# --------------------------------------------------------------------------- motion


def _solve(mech, t1, tol, n=51):
    """A run from the ideal motion (pins and slider centred) to t1 (s); the frames at n
    instants."""
    import diffrax

    from jaxcrank.physics import dynamics, frame, state

    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(dynamics.vector_field),
        diffrax.Tsit5(),
        0.0,
        t1,
        1e-7,
        state.initial_state(mech),
        args=mech,
        stepsize_controller=diffrax.PIDController(rtol=tol, atol=tol),
        max_steps=200_000,
        saveat=diffrax.SaveAt(ts=jnp.linspace(0.0, t1, n)),
    )
    return jax.vmap(lambda t, y: frame.evaluate(mech, t, y))(sol.ts, sol.ys)


def _index(mech, what, name):
    from jaxcrank.physics import compiled

    return getattr(compiled.compile_model(mech).tree, what).index(name)


@pytest.mark.slow  # compiles a solve and the output frame: about a minute
def test_work_energy_balance_closes():
    """The paper's slider-crank with clearance at B, C and the guide, 10 ms from the ideal
    motion: driver work - dissipated work = change of kinetic + potential + stored contact
    energy, within 1e-7 of the driver's work (rtol = atol = 1e-8)."""
    mech = presets.paper_guide()
    fr = _solve(mech, 0.01, 1e-8, n=2)
    guide = _index(mech, "joints", "guide")
    energy = fr.kinetic_energy + fr.potential_energy + fr.contact_energy
    residual = (fr.driver_work[-1] - fr.dissipated_work[-1]) - (energy[-1] - energy[0])
    assert float(fr.driver_work[-1]) > 10.0 and float(fr.dissipated_work[-1]) > 1.0
    assert abs(float(residual)) < 1e-7 * float(fr.driver_work[-1])
    assert bool(jnp.all(jnp.isfinite(fr.penetration[:, guide])))


@pytest.mark.slow  # compiles a solve and the output frame: about a minute
def test_zero_clearance_limit_is_the_ideal_slider():
    """Only the guide has clearance (A, B, C ideal): as its clearance shrinks and its
    contact stiffens, the slider follows the ideal slider-crank's. Its lateral offset never
    exceeds clearance + penetration (the corners bound it)."""
    deviations = []
    for clearance, modulus in ((1e-4, 207e9), (1e-6, 207e11)):
        steel = Material(youngs_modulus=modulus)
        law = _law(clearance=clearance, slider_material=steel, guide_material=steel)
        mech = presets.SliderCrank(joints={"A": Ideal(), "B": Ideal(), "C": Ideal(), "guide": law})
        fr = _solve(mech, 0.01, 1e-7)
        slider, rod, guide = (
            _index(mech, "bodies", "slider"),
            _index(mech, "bodies", "rod"),
            _index(mech, "joints", "guide"),
        )
        dev = jnp.abs(fr.q - fr.ideal_q)
        lateral = dev[:, slider, 1]
        assert bool(jnp.all(lateral <= clearance + jnp.maximum(fr.penetration[:, guide], 0.0) + 1e-12))
        assert float(jnp.max(fr.penetration[:, guide])) > 0.0  # the slider reaches a face
        deviations.append((float(jnp.max(dev[:, slider, 0])), float(jnp.max(dev[:, rod, 2]))))
    (x_wide, rod_wide), (x_tight, rod_tight) = deviations
    assert x_tight < 1e-6 and x_tight < x_wide / 20.0
    assert rod_tight < rod_wide / 20.0
