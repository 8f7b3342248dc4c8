"""Mechanism descriptions with named dimensions: the offset slider-crank and the
four-bar, each a final [`AbstractMechanism`][jaxcrank.physics.linkage.AbstractMechanism] whose
[`linkage`][jaxcrank.physics.linkage.AbstractMechanism.linkage] writes it out body by body, and the named presets
built from them (`PRESETS`, what ``--mechanism NAME`` takes).

This module, [`jaxcrank.physics.catalogue`][] and the TOML files of user linkages are the
only places that name a mechanism's bodies and joints; everything downstream takes them
from the description.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import equinox as eqx
import numpy as np

from .drivers import AbstractDriver, ConstantSpeed
from .guide import GuideClearance
from .joints import AbstractJointLaw, Clearance, Ideal
from .linkage import (
    AbstractMechanism,
    Body,
    BodyVector,
    Linkage,
    Outputs,
    Point,
    Prismatic,
    Revolute,
    Site,
)
from .params import ParameterError, _concrete, check_range

RPM = 2.0 * math.pi / 60.0  # rad/s per rev/min


def _paper_joints() -> dict[str, AbstractJointLaw]:
    pin = Clearance(hole_radius=8e-3, pin_radius=7.5e-3)
    return {"A": Ideal(), "B": pin, "C": pin, "guide": Ideal()}


def _check_laws(joints: dict, expected: tuple[str, ...], what: str) -> None:
    if set(joints) != set(expected):
        raise ParameterError(f"a {what} has joints {', '.join(expected)}; got {', '.join(sorted(joints))}")
    for name, law in joints.items():
        if not isinstance(law, AbstractJointLaw):
            raise ParameterError(f"joint {name}: {law!r} is not a joint law (e.g. jaxcrank.Clearance(...))")


class SliderCrank(AbstractMechanism):
    """The offset slider-crank (model.md): a crank turning about the ground pivot A, a
    connecting rod from the crank pin B to the slider pin C, and a slider on the line
    y = offset (the prismatic joint ``guide``). Each joint has a law of its own: the
    paper's mechanism has clearance at B and C.

    Bodies: ``crank`` (frame at A, B at (L1, 0), centre of mass at (L1/2, 0)), ``rod``
    (frame at its centre of mass, B and C at -/+ L2/2 along it), ``slider`` (its pin C
    at its centre of mass). Reported: the rod's and the slider's x deviations, the
    slider's acceleration deviation, and the transmission angle between the rod and the
    normal to the slider's line (paper Eq. 17-18).

    Attributes:
        crank_length: L1, m.
        rod_length: L2, m; must exceed ``crank_length + |offset|``.
        offset: eccentricity e of the slider line y = e, m.
        crank_mass: m1, kg.
        rod_mass: m2, kg.
        slider_mass: m3, kg.
        crank_inertia: J1 about its centre of mass, kg m^2.
        rod_inertia: J2 about its centre of mass, kg m^2.
        slider_inertia: J3 about its centre of mass, kg m^2 (enters only where the
            slider can turn).
        joints: the law of each joint ``A``, ``B``, ``C`` and ``guide``.
        driver: what turns the crank (default: 600 rpm from theta1 = 0).
        gravity: g along -y, m/s^2.

    Raises:
        ParameterError: a dimension, mass or inertia that is not positive, or a rod too
            short for the crank to turn fully.
    """

    crank_length: float = 0.150
    rod_length: float = 0.403
    offset: float = 0.050
    crank_mass: float = 0.6967
    rod_mass: float = 1.5473
    slider_mass: float = 1.7964
    crank_inertia: float = 1.931e-3
    rod_inertia: float = 2.233e-4
    slider_inertia: float = 3.431e-4
    joints: dict[str, AbstractJointLaw] = eqx.field(default_factory=_paper_joints)
    driver: AbstractDriver = ConstantSpeed(body="crank", speed=600.0 * RPM)
    gravity: float = 9.81
    name: str = eqx.field(static=True, default="slider-crank")

    def __check_init__(self):
        for field in ("crank_length", "rod_length"):
            check_range(field, getattr(self, field), low=0.0, unit="m")
        check_range("offset", self.offset, unit="m")
        for field in ("crank_mass", "rod_mass", "slider_mass"):
            check_range(field, getattr(self, field), low=0.0, unit="kg")
        for field in ("crank_inertia", "rod_inertia", "slider_inertia"):
            check_range(field, getattr(self, field), low=0.0, unit="kg m^2")
        check_range("gravity", self.gravity, low=0.0, low_open=False, unit="m/s^2")
        _check_laws(self.joints, ("A", "B", "C", "guide"), "slider-crank")
        l1, l2, e = (_concrete(x) for x in (self.crank_length, self.rod_length, self.offset))
        if l1 is not None and l2 is not None and e is not None:
            margin = l2 - l1 - np.abs(e)
            if np.any(margin <= 0.0):
                i = np.unravel_index(np.argmin(margin), np.shape(margin)) if np.ndim(margin) else ()
                l1_, l2_, e_ = (np.broadcast_to(x, np.shape(margin))[i] for x in (l1, l2, e))
                raise ParameterError(
                    f"geometry is not assemblable for a full crank rotation: rod_length = {l2_:g} m "
                    f"must exceed crank_length + |offset| = {l1_:g} + {abs(e_):g} = "
                    f"{l1_ + abs(e_):g} m (valid range: rod_length > crank_length + |offset|)"
                )
        if self.driver.body != "crank":
            raise ParameterError(f"a slider-crank's driver turns the 'crank', not {self.driver.body!r}")

    def deviation_bounds(self, max_penetration) -> dict[str, float]:
        """Largest |x deviation| of slider and rod centre that the loop closure allows, m.

        Args:
            max_penetration: largest contact penetration of the run, m (>= 0).

        Closure, with ``d_B``, ``d_C`` the pin eccentricities (|d| <= rho = c + max_penetration
        at a clearance joint, 0 at an ideal one; the ground pivot's play adds to B's, as it
        moves the crank pin alike: rho_B + rho_A below) and ``D = d_B - d_C`` (|D| <= play =
        rho_B + rho_C):

        ```text
        dx3 = -D_x + L2 (cos theta2 - cos theta2_ideal),   L2 (sin theta2 - sin theta2_ideal) = D_y
        dx2 = -d_Bx + (L2 / 2) (cos theta2 - cos theta2_ideal)
        ```

        ``|sin theta2_ideal| <= s_m = (L1 + |e|) / L2``, and the cosine changes most at the
        steepest point: ``L2 |cos theta2 - cos theta2_ideal| <= L2 g(|D_y|)`` with
        ``g(y) = sqrt(1 - s_m^2) - sqrt(1 - min(1, s_m + y / L2)^2)``, convex in y, so below
        its secant ``k |D_y|``, ``k = L2 g(play) / play`` (k -> tan theta2_max for small play).
        Hence ``|dx3| <= play sqrt(1 + k^2)`` (Cauchy-Schwarz) and
        ``|dx2| <= rho_B + k play / 2``. (The clearances alone are not a bound: the rod-angle
        change adds up to k times the y play.)

        The guide is taken as ideal (its play is not in the bound).

        Returns:
            ``{"slider_x_m": ..., "rod_x_m": ...}``, m.
        """
        pen = float(max_penetration)
        rho = {j: 0.0 if self.joints[j].ideal else float(self.joints[j].clearance) + pen for j in "ABC"}
        rho["B"] += rho.pop("A")  # play at the ground pivot moves the crank pin as play at B does
        play = rho["B"] + rho["C"]
        l2 = float(self.rod_length)
        s_m = (float(self.crank_length) + abs(float(self.offset))) / l2
        s_hi = min(1.0, s_m + play / l2)
        k = l2 * (math.sqrt(1.0 - s_m**2) - math.sqrt(1.0 - s_hi**2)) / play if play > 0 else 0.0
        return {"slider_x_m": play * math.sqrt(1.0 + k**2), "rod_x_m": rho["B"] + k * play / 2.0}

    def linkage(self) -> Linkage:
        l1, l2 = self.crank_length, self.rod_length
        half = 0.5 * l2
        bodies = {
            "crank": Body(
                self.crank_mass,
                self.crank_inertia,
                {"A": Point(0.0, 0.0), "B": Point(l1, 0.0)},
                Point(0.5 * l1, 0.0),
            ),
            "rod": Body(self.rod_mass, self.rod_inertia, {"B": Point(-half, 0.0), "C": Point(half, 0.0)}),
            "slider": Body(self.slider_mass, self.slider_inertia, {"C": Point(0.0, 0.0)}),
        }
        connections = {
            "A": Revolute(hole=Site("ground", "A"), pin=Site("crank", "A")),
            "B": Revolute(hole=Site("rod", "B"), pin=Site("crank", "B")),
            "C": Revolute(hole=Site("rod", "C"), pin=Site("slider", "C")),
            "guide": Prismatic(guide=Site("ground", "guide"), slider=Site("slider", "C")),
        }
        outputs = Outputs(
            deviations=(("rod", "x"), ("slider", "x")),
            acceleration=("slider", "x"),
            transmission=(BodyVector("rod", "B", "C"), BodyVector("slider", angle=-0.5 * math.pi)),
        )
        return Linkage(
            bodies=bodies,
            ground={"A": Point(0.0, 0.0), "guide": Point(0.0, self.offset)},
            connections=connections,
            joints=dict(self.joints),
            driver=self.driver,
            gravity=self.gravity,
            outputs=outputs,
            name=self.name,
        )


def _four_bar_joints() -> dict[str, AbstractJointLaw]:
    pin = Clearance(hole_radius=8e-3, pin_radius=7.5e-3)
    return {"A": Ideal(), "B": pin, "C": pin, "D": Ideal()}


class FourBar(AbstractMechanism):
    """A four-bar linkage: the crank turns about the ground pivot A, the coupler joins the
    crank pin B to the rocker pin C, and the rocker turns about the ground pivot D.

    Bodies: ``crank`` (frame at A, B at (a, 0)), ``coupler`` (frame at B, C at (b, 0)),
    ``rocker`` (frame at D, C at (c, 0)), each with its centre of mass at mid-length
    (uniform bars by default). Ground: A at the origin, D at (d, 0). The assembly is the
    *open* one (C to the left of the line from B to D). Reported: the rocker's angle
    deviation and angular-acceleration deviation, and the transmission angle between
    coupler and rocker at C.

    Attributes:
        ground_length: d, m.
        crank_length: a, m.
        coupler_length: b, m.
        rocker_length: c, m.
        crank_mass: kg.
        coupler_mass: kg.
        rocker_mass: kg.
        crank_inertia: about its centre of mass, kg m^2.
        coupler_inertia: kg m^2.
        rocker_inertia: kg m^2.
        joints: the law of each joint ``A``, ``B``, ``C``, ``D``.
        driver: what turns the crank.
        gravity: g along -y, m/s^2.

    Raises:
        ParameterError: a length, mass or inertia that is not positive, or lengths that
            are not a crank-rocker (Grashof: s + l <= p + q with the crank shortest).
    """

    ground_length: float = 0.40
    crank_length: float = 0.10
    coupler_length: float = 0.35
    rocker_length: float = 0.30
    crank_mass: float = 0.5
    coupler_mass: float = 1.2
    rocker_mass: float = 1.0
    crank_inertia: float = 0.5 * 0.10**2 / 12.0
    coupler_inertia: float = 1.2 * 0.35**2 / 12.0
    rocker_inertia: float = 1.0 * 0.30**2 / 12.0
    joints: dict[str, AbstractJointLaw] = eqx.field(default_factory=_four_bar_joints)
    driver: AbstractDriver = ConstantSpeed(body="crank", speed=600.0 * RPM)
    gravity: float = 9.81
    name: str = eqx.field(static=True, default="four-bar")

    def __check_init__(self):
        lengths = ("ground_length", "crank_length", "coupler_length", "rocker_length")
        for field in lengths:
            check_range(field, getattr(self, field), low=0.0, unit="m")
        for part in ("crank", "coupler", "rocker"):
            check_range(f"{part}_mass", getattr(self, f"{part}_mass"), low=0.0, unit="kg")
            check_range(f"{part}_inertia", getattr(self, f"{part}_inertia"), low=0.0, unit="kg m^2")
        check_range("gravity", self.gravity, low=0.0, low_open=False, unit="m/s^2")
        _check_laws(self.joints, ("A", "B", "C", "D"), "four-bar")
        values = [_concrete(getattr(self, f)) for f in lengths]
        if all(v is not None for v in values):
            d, a, b, c = (float(np.max(v)) for v in values)
            if not grashof_crank_rocker(a, b, c, d):
                raise ParameterError(
                    f"the lengths are not a crank-rocker: with crank_length = {a:g}, coupler_length = {b:g}, "
                    f"rocker_length = {c:g}, ground_length = {d:g} m the crank must be the shortest link and "
                    "shortest + longest <= the sum of the other two (Grashof)"
                )
        if self.driver.body != "crank":
            raise ParameterError(f"a four-bar's driver turns the 'crank', not {self.driver.body!r}")

    def linkage(self) -> Linkage:
        a, b, c = self.crank_length, self.coupler_length, self.rocker_length
        bodies = {
            "crank": Body(self.crank_mass, self.crank_inertia, {"A": Point(), "B": Point(a, 0.0)}, Point(0.5 * a, 0.0)),
            "coupler": Body(
                self.coupler_mass, self.coupler_inertia, {"B": Point(), "C": Point(b, 0.0)}, Point(0.5 * b, 0.0)
            ),
            "rocker": Body(
                self.rocker_mass, self.rocker_inertia, {"D": Point(), "C": Point(c, 0.0)}, Point(0.5 * c, 0.0)
            ),
        }
        connections = {
            "A": Revolute(hole=Site("ground", "A"), pin=Site("crank", "A")),
            "B": Revolute(hole=Site("coupler", "B"), pin=Site("crank", "B")),
            "C": Revolute(hole=Site("coupler", "C"), pin=Site("rocker", "C")),
            "D": Revolute(hole=Site("ground", "D"), pin=Site("rocker", "D")),
        }
        outputs = Outputs(
            deviations=(("rocker", "angle"),),
            acceleration=("rocker", "angle"),
            transmission=(BodyVector("coupler", "C", "B"), BodyVector("rocker", "C", "D")),
        )
        return Linkage(
            bodies=bodies,
            ground={"A": Point(), "D": Point(self.ground_length, 0.0)},
            connections=connections,
            joints=dict(self.joints),
            driver=self.driver,
            gravity=self.gravity,
            outputs=outputs,
            name=self.name,
        )


def grashof_crank_rocker(crank, coupler, rocker, ground) -> bool:
    """Whether four link lengths (m) make a crank-rocker: the crank is the shortest link
    and shortest + longest <= sum of the other two (Grashof)."""
    lengths = [crank, coupler, rocker, ground]
    return crank <= min(lengths) and min(lengths) + max(lengths) <= sum(lengths) - min(lengths) - max(lengths)


# --------------------------------------------------------------------------- named presets


def paper() -> SliderCrank:
    """The paper's Table 1 mechanism as read in model.md.

    Assumptions (each a field the user can change):

    - offset e = L4 - L3 = 50 mm: the paper gives L3 = 450 and L4 = 500 mm but no e.
    - inertias: the table's "kg.mm^2" values read as kg m^2 (kg mm^2 would be
      physically impossible). J2 = 2.233e-4 kg m^2 is about 100x below a uniform
      0.403 m rod (0.021 kg m^2); the table value is kept.
    - materials: steel on steel, E = 207 GPa, nu = 0.3 (not given in the paper).
    - restitution c_e = 0.9, friction mu = 0.1 (dry steel), friction ramp
      v0 = 1e-4 m/s to v1 = 1e-2 m/s (not given in the paper; see ``Friction``).
    - crank speed 600 rpm, starting at theta1 = 0, pins centred in their holes and
      moving with the ideal mechanism's velocities.
    - gravity 9.81 m/s^2 along -y.
    """
    return SliderCrank()


#: the slider block of the paper's mechanism with a guide clearance (see paper_guide), m
_PAPER_SLIDER = dict(length=0.040, height=0.026, corner_radius=1e-3)


def paper_guide() -> SliderCrank:
    """The paper's mechanism ([`paper`][jaxcrank.physics.presets.paper]) with clearance in the slider's guide
    as well as at B and C: the slider is a 40 x 26 mm block (length x height) with 1 mm
    corner radii and 0.25 mm on each side between it and the guide's faces
    ([`GuideClearance`][jaxcrank.physics.guide.GuideClearance], steel on steel, the pins' restitution and
    friction).

    Assumptions (the paper's slider is a point on the guide line):

    - 40 x 26 mm: a uniform block of the slider's mass m3 = 1.7964 kg with these sides has
      m3 (L^2 + H^2) / 12 = 3.41e-4 kg m^2, the paper's J3 = 3.431e-4 kg m^2 within 1 %.
    - 0.25 mm on each side: half the pins' 0.5 mm radial clearance (a guide fit is
      usually closer than a pin's).
    - corner radius 1 mm: a broken edge; corner stiffness 4.8e9 N/m^1.5.
    """
    guide = GuideClearance(**_PAPER_SLIDER, clearance=2.5e-4)
    return SliderCrank(joints={**_paper_joints(), "guide": guide}, name="slider-crank-guide")


def four_bar() -> FourBar:
    """A crank-rocker four-bar (d, a, b, c = 400, 100, 350, 300 mm; uniform steel-like
    bars; 600 rpm) with the paper's 0.5 mm clearances at the coupler's pins B and C."""
    return FourBar()


def _catalogue(name: str) -> Callable[[], AbstractMechanism]:
    """The factory ``name`` of [`jaxcrank.physics.catalogue`][], imported on first use (it builds
    on this module's classes)."""

    def build():
        from . import catalogue

        return getattr(catalogue, name)()

    return build


#: preset name -> factory (``--mechanism NAME``)
PRESETS: dict[str, Callable[[], AbstractMechanism]] = {
    "paper": paper,
    "slider-crank": paper,
    "paper-guide": paper_guide,
    "slider-crank-A": _catalogue("slider_crank_ground_pivot"),
    "slider-crank-ABC": _catalogue("slider_crank_three_pins"),
    "four-bar": four_bar,
    "four-bar-ABCD": _catalogue("four_bar_four_pins"),
    "paper-lubricated": _catalogue("paper_lubricated"),
    "four-bar-lubricated": _catalogue("four_bar_lubricated"),
    "flores": _catalogue("flores"),
    "paper-wear": _catalogue("paper_wear"),
}


def preset(name: str) -> AbstractMechanism:
    """The preset mechanism named ``name`` (a key of `PRESETS`).

    Raises:
        ParameterError: for an unknown name (the message lists the valid ones).
    """
    if name not in PRESETS:
        raise ParameterError(f"unknown mechanism {name!r}; presets: {', '.join(PRESETS)}")
    return PRESETS[name]()


def _joint_kind(mech: AbstractMechanism, joint: str) -> str:
    """A joint's kind, without building the linkage (an all-ideal one does not hold together)."""
    if isinstance(mech, (SliderCrank, FourBar)):
        return "prismatic" if joint == "guide" else "revolute"
    return mech.linkage().connections[joint].kind


def with_clearance(mech: AbstractMechanism, **clearances) -> AbstractMechanism:
    """``mech`` with new clearances (m) at the named joints (``B=2e-4``): at a revolute
    joint the radial clearance, keeping the hole radius and shrinking the pin (an ideal
    one gets the paper's 8 mm hole); at a guide with clearance the gap on each side of the
    slider (an ideal guide gets the 40 x 26 mm slider of
    [`paper_guide`][jaxcrank.physics.presets.paper_guide]).

    Raises:
        ParameterError: an unknown joint, or a clearance outside (0, hole radius).
    """
    for joint, c in clearances.items():
        if joint not in mech.joints:
            raise ParameterError(f"unknown joint {joint!r}; joints: {', '.join(sorted(mech.joints))}")
        law = mech.joints[joint]
        if isinstance(law, GuideClearance):
            check_range(f"joint {joint} clearance", c, low=0.0, unit="m")
            mech = eqx.tree_at(lambda m, j=joint: m.joints[j].clearance, mech, c)
        elif law.ideal and _joint_kind(mech, joint) == "prismatic":
            mech = eqx.tree_at(lambda m, j=joint: m.joints[j], mech, GuideClearance(**_PAPER_SLIDER, clearance=c))
        elif law.ideal:
            law = Clearance(hole_radius=8e-3, pin_radius=8e-3 - c)
            mech = eqx.tree_at(lambda m, j=joint: m.joints[j], mech, law)
        else:
            mech = eqx.tree_at(lambda m, j=joint: m.joints[j].pin_radius, mech, law.hole_radius - c)
    return mech


__all__ = [
    "PRESETS",
    "FourBar",
    "SliderCrank",
    "four_bar",
    "grashof_crank_rocker",
    "paper",
    "paper_guide",
    "preset",
    "with_clearance",
]
