"""Wear: the worn profile's geometry, Archard's law spread over the Hertz patch, the
contact against a worn hole, and a new worn joint that is exactly the round one."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank.physics.joints import JointKinematics, clearance_contact
from jaxcrank.physics.params import ParameterError
from jaxcrank.physics.wear import (
    Archard,
    Worn,
    evaluate_profile,
    from_clearance,
    new_profile,
    patch_factor,
    patch_half_width,
    profile_on_grid,
    wear_rates,
    worn_contact,
)

R_H, R_P = 8e-3, 7.5e-3


def _kin(d, v=(0.0, 0.0), hole_angle=0.0, pin_angle=0.0, w_h=0.0, w_p=0.0):
    z = jnp.zeros(2)
    return JointKinematics(z, z, jnp.asarray(hole_angle), jnp.asarray(w_h), jnp.asarray(d, dtype=float),
                           jnp.asarray(v, dtype=float), jnp.asarray(pin_angle), jnp.asarray(w_p))  # fmt: skip


def _profile(rng, modes=6, size=1e-5):
    return jnp.asarray(rng.normal(size=2 * modes + 1) * size / np.arange(1, 2 * modes + 2))


def test_profile_derivatives_equal_differences_of_the_depth():
    """The slope and bend of a random profile equal central differences of its depth
    (step 1e-4 rad: error O(h^2) of 1e-8 relative; measured 1e-9)."""
    p = _profile(np.random.default_rng(0))
    theta = jnp.linspace(0.0, 2 * math.pi, 13)
    h = 1e-4
    s = evaluate_profile(p, (jnp.cos(theta), jnp.sin(theta)))
    up, down = profile_on_grid(p, theta + h), profile_on_grid(p, theta - h)
    np.testing.assert_allclose(s.slope, (up - down) / (2 * h), rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(s.bend, (up - 2 * s.depth + down) / h**2, rtol=1e-5, atol=1e-9)


def test_patch_factor_is_two_j1_over_x():
    """2 J_1(x)/x at tabulated values (J_1(1) = 0.4400505857, J_1(3) = 0.3390589585,
    J_1(3.8317059702) = 0)."""
    x = jnp.asarray([1e-12, 1.0, 3.0, 3.8317059702])
    want = np.array([1.0, 2 * 0.4400505857, 2 * 0.3390589585 / 3.0, 0.0])
    np.testing.assert_allclose(patch_factor(x), want, atol=1e-9)


def _worn(**kw):
    return Worn(hole_radius=R_H, pin_radius=R_P, **kw)


def test_new_worn_joint_is_the_round_joint_bit_for_bit():
    """Zero profiles: every field of the forces equals clearance_contact's exactly, in
    and out of contact, and the paper's mechanism runs the same trajectory."""
    rng = np.random.default_rng(1)
    worn = _worn()
    round_ = jc.Clearance(hole_radius=R_H, pin_radius=R_P)
    for _ in range(5):
        kin = _kin(rng.normal(size=2) * 4e-4, rng.normal(size=2) * 0.1, *rng.normal(size=2), *rng.normal(size=2) * 10)
        a, b = worn_contact(worn, kin, jnp.zeros(2)), clearance_contact(round_, kin, jnp.zeros(2))
        for name in a._fields[:-1]:
            assert np.array_equal(np.asarray(getattr(a, name)), np.asarray(getattr(b, name))), name
    mech = jc.paper()
    new = jc.preset("paper-wear")
    ts = jnp.linspace(0.0, 0.02, 21)
    ya = jc.simulate(mech, ts=ts).ys
    yb = jc.simulate(new, ts=ts).ys
    assert np.array_equal(np.asarray(ya), np.asarray(yb))


def test_a_uniformly_worn_hole_is_a_larger_hole():
    """A uniform wear depth w (a_0 = w) acts as a clearance larger by w: the same
    penetration and normal force as a round hole of radius R_h + w, at any angle."""
    w = 2e-5
    worn = _worn(hole_wear=new_profile(4).at[0].set(w), pin_wear=new_profile(4))
    bigger = jc.Clearance(hole_radius=R_H + w, pin_radius=R_P)
    for angle in (0.3, 2.0, -2.5):
        d = (R_H - R_P + w + 1e-6) * np.array([math.cos(angle), math.sin(angle)])
        a, b = worn_contact(worn, _kin(d), jnp.zeros(2)), clearance_contact(bigger, _kin(d), jnp.zeros(2))
        np.testing.assert_allclose(a.penetration, b.penetration, rtol=1e-9)
        np.testing.assert_allclose(a.force, b.force, rtol=1e-6)


def test_the_local_wear_is_read_in_the_hole_s_frame():
    """A dent at 90 deg in the hole's frame: with the hole's body turned by 90 deg, the pin
    pressed along world 180 deg meets the dent (penetration less by its depth), and along
    world 0 deg does not."""
    modes = 12
    theta = np.linspace(0.0, 2 * math.pi, 256, endpoint=False)
    dent = 1e-5 * np.exp(-((np.angle(np.exp(1j * (theta - math.pi / 2)))) ** 2) / 0.05)
    coeffs = np.fft.rfft(dent) / len(theta)
    profile = np.concatenate([[coeffs[0].real], 2 * coeffs[1 : modes + 1].real, -2 * coeffs[1 : modes + 1].imag])
    worn = _worn(hole_wear=jnp.asarray(profile), pin_wear=new_profile(modes))
    depth_at = float(profile_on_grid(jnp.asarray(profile), jnp.asarray([math.pi / 2]))[0])
    e = R_H - R_P + 5e-6
    hit = worn_contact(worn, _kin([-e, 0.0], hole_angle=math.pi / 2), jnp.zeros(2))
    miss = worn_contact(worn, _kin([e, 0.0], hole_angle=math.pi / 2), jnp.zeros(2))
    floor = float(profile_on_grid(jnp.asarray(profile), jnp.asarray([-math.pi / 2]))[0])
    np.testing.assert_allclose(float(hit.penetration), 5e-6 - depth_at, rtol=1e-9)
    np.testing.assert_allclose(float(miss.penetration), 5e-6 - floor, rtol=1e-9)
    assert depth_at > 5e-6 > floor


def test_archard_volume_rate_and_where_the_rate_falls():
    """The hole's mean depth rate times its area is Archard's k F |v| / H, the pin's too;
    the depth rate is largest at the contact's angle in each surface's frame."""
    wear = Archard(hole_coefficient=1e-6, pin_coefficient=2e-7, slip_smoothing=1e-9)
    worn = _worn(wear=wear)
    e = R_H - R_P + 3e-6
    angle = 1.1
    kin = _kin(e * np.array([math.cos(angle), math.sin(angle)]), hole_angle=0.4, pin_angle=-0.7, w_p=20.0)
    f = worn_contact(worn, kin, jnp.zeros(2))
    r = wear_rates(worn, kin, f)
    slip = abs(float(f.slip_speed))
    np.testing.assert_allclose(
        float(r.hole_volume), 1e-6 * float(f.normal_force) * slip / wear.hole_hardness, rtol=1e-6
    )
    area_h, area_p = 2 * math.pi * R_H * wear.length, 2 * math.pi * R_P * wear.length
    np.testing.assert_allclose(float(r.hole[0]) * area_h, float(r.hole_volume), rtol=1e-12)
    np.testing.assert_allclose(float(r.pin[0]) * area_p, float(r.pin_volume), rtol=1e-12)
    grid = jnp.linspace(-math.pi, math.pi, 3601)
    for rate, frame in ((r.hole, 0.4), (r.pin, -0.7)):
        peak = float(grid[jnp.argmax(profile_on_grid(rate, grid))])
        assert abs(np.angle(np.exp(1j * (peak - (angle - frame))))) < 2e-3
    b = float(patch_half_width(worn, f.normal_force))
    assert 0.0 < b < R_P


def test_contact_gradients_are_finite_at_the_centre_and_at_the_onset():
    """Forces and wear rates of a worn joint have finite gradients in the pin's position
    at zero eccentricity and at first touch."""
    rng = np.random.default_rng(2)
    worn = _worn(hole_wear=_profile(rng, 24), pin_wear=_profile(rng, 24, 1e-6))

    def f(d):
        kin = _kin(d, v=(0.1, -0.2))
        forces = worn_contact(worn, kin, jnp.zeros(2))
        return jnp.sum(forces.force) + jnp.sum(wear_rates(worn, kin, forces).hole) * 1e9

    for d in (jnp.zeros(2), jnp.array([R_H - R_P + float(worn.hole_wear[0]), 0.0])):
        g = jax.grad(f)(d)
        assert np.all(np.isfinite(np.asarray(g)))


@pytest.mark.parametrize(
    "kw",
    [dict(hole_wear=jnp.zeros(5), pin_wear=jnp.zeros(7)), dict(hole_wear=jnp.zeros(4), pin_wear=jnp.zeros(4))],
)
def test_bad_profiles_name_the_parameter(kw):
    with pytest.raises(ParameterError, match="hole_wear"):
        _worn(**kw)


def test_bad_hardness_and_length_name_the_parameter():
    for name in ("hole_hardness", "pin_hardness", "length"):
        with pytest.raises(ParameterError, match=name):
            Archard(**{name: 0.0})
    for name in ("hole_coefficient", "pin_coefficient"):
        with pytest.raises(ParameterError, match=name):
            Archard(**{name: -1e-6})


def test_life_needs_a_worn_joint():
    from jaxcrank.analysis.life import life

    with pytest.raises(ParameterError, match="worn"):
        life(jc.paper(), 1e6)


def test_only_a_dry_pin_in_hole_joint_wears():
    """Wear on another law (a lubricated joint, an ideal one) is refused in one line that names the law."""
    from jaxcrank.physics.lubrication import Lubricated

    for law, name in ((Lubricated(0.01, 0.0097, 0.05, 0.02), "'lubricated'"), (jc.Ideal(), "'ideal'")):
        with pytest.raises(ParameterError, match=f"its law {name} is not a dry revolute clearance joint") as err:
            from_clearance(law)
        assert "\n" not in str(err.value)


def test_from_clearance_keeps_the_joint_and_the_preset_is_registered():
    law = jc.paper().joints["B"]
    worn = from_clearance(law, modes=8)
    assert worn.modes == 8 and worn.hole_wear.shape == (17,)
    assert float(worn.clearance) == float(law.clearance)
    assert set(jc.preset("paper-wear").joints) == set(jc.paper().joints)
    assert jc.JOINT_LAWS["worn"] is Worn
    moved = eqx.tree_at(lambda w: w.hole_wear, worn, worn.hole_wear.at[0].set(1e-6))
    assert float(moved.hole_wear[0]) == 1e-6
