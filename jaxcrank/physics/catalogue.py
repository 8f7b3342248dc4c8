"""More named mechanisms, built on the classes of [`jaxcrank.physics.presets`][] (each a
preset: ``--mechanism NAME``, [`jaxcrank.physics.presets.preset`][]):

- ``slider-crank-A`` ([`slider_crank_ground_pivot`][jaxcrank.physics.catalogue.slider_crank_ground_pivot]):
  the paper's slider-crank with play at the crank's ground pivot alone;
- ``slider-crank-ABC`` ([`slider_crank_three_pins`][jaxcrank.physics.catalogue.slider_crank_three_pins]):
  with play at all three revolute joints;
- ``four-bar-ABCD`` ([`four_bar_four_pins`][jaxcrank.physics.catalogue.four_bar_four_pins]): the
  four-bar with play at all four joints;
- ``paper-lubricated`` ([`paper_lubricated`][jaxcrank.physics.catalogue.paper_lubricated]) and
  ``four-bar-lubricated`` ([`four_bar_lubricated`][jaxcrank.physics.catalogue.four_bar_lubricated]):
  the paper's slider-crank and the four-bar with oil in the bearings of B and C;
- ``paper-wear`` ([`paper_wear`][jaxcrank.physics.catalogue.paper_wear]): the paper's slider-crank
  whose pins B and C wear ([`Worn`][jaxcrank.physics.wear.Worn], Archard's law);
- ``flores`` ([`flores`][jaxcrank.physics.catalogue.flores]): Flores and Ambrósio's high-speed
  slider-crank with a clearance joint at the slider pin, the benchmark of the
  clearance-joint literature.

Any other choice of joints is one call of [`with_clearance`][jaxcrank.physics.presets.with_clearance]
away (an all-ideal mechanism included).
"""

from __future__ import annotations

from .drivers import ConstantSpeed
from .joints import Clearance, Ideal
from .laws import Ambrosio, LankaraniNikravesh
from .lubrication import Lubricated
from .params import Contact, Friction, Material
from .presets import RPM, FourBar, SliderCrank, with_clearance
from .wear import Archard, from_clearance


def slider_crank_ground_pivot() -> SliderCrank:
    """The paper's slider-crank ([`jaxcrank.physics.presets.paper`][]) with play at the crank's
    ground pivot A alone: A is a clearance joint with the paper's 8 / 7.5 mm pin (0.5 mm
    radial clearance) and the paper's contact and friction settings; B, C and the guide
    are ideal. The crank's angle stays prescribed; its pivot moves in its bearing."""
    ideal = {j: Ideal() for j in ("A", "B", "C", "guide")}
    return with_clearance(SliderCrank(joints=ideal, name="slider-crank-A"), A=5e-4)


def slider_crank_three_pins() -> SliderCrank:
    """The paper's slider-crank with its 0.5 mm clearance (8 / 7.5 mm pins) at the ground
    pivot A as well as at B and C; the guide ideal."""
    return with_clearance(SliderCrank(name="slider-crank-ABC"), A=5e-4)


def four_bar_four_pins() -> FourBar:
    """The four-bar of [`jaxcrank.physics.presets.four_bar`][] with 0.5 mm radial clearance
    (8 / 7.5 mm pins) at all four joints: the ground pivots A and D as well as B and C."""
    return with_clearance(FourBar(name="four-bar-ABCD"), A=5e-4, D=5e-4)


#: the oil of the lubricated presets: dynamic viscosity, Pa s, and bearing length, m
OIL_VISCOSITY = 0.4
BEARING_LENGTH = 8e-3


def _oiled(dry: Clearance) -> Lubricated:
    """``dry`` with ``OIL_VISCOSITY`` in a bearing of ``BEARING_LENGTH``."""
    return Lubricated.oiled(dry, OIL_VISCOSITY, BEARING_LENGTH)


def paper_lubricated() -> SliderCrank:
    """The paper's slider-crank ([`jaxcrank.physics.presets.paper`][]) with lubricated pins at B
    and C ([`Lubricated`][jaxcrank.physics.lubrication.Lubricated]): the same 8 / 7.5 mm radii,
    dry contact and friction laws (which take over at high eccentricity), plus an oil film
    of viscosity 0.4 Pa s (400 cP, the value of the lubricated slider-crank studies of
    Flores, Ambrósio, Claro and Lankarani, as recalled, not checked against the papers: an
    SAE 40 oil near 40 C) over a bearing length of 8 mm (L / D = 0.5, where the
    short-bearing solution holds; the paper gives no bearing length)."""
    base = SliderCrank()
    joints = {**base.joints, "B": _oiled(base.joints["B"]), "C": _oiled(base.joints["C"])}
    return SliderCrank(joints=joints, name="slider-crank-lubricated")


#: the wear law of ``paper-wear``: every value assumed (the paper gives no wear data), see paper_wear
PAPER_WEAR = Archard(hole_coefficient=1e-7, pin_coefficient=1e-8, hole_hardness=0.64e9, pin_hardness=1.6e9, length=0.02)


def paper_wear() -> SliderCrank:
    """The paper's slider-crank ([`jaxcrank.physics.presets.paper`][]) whose pins at B and C
    wear: each a [`Worn`][jaxcrank.physics.wear.Worn] joint, new (round), with the paper's 8 / 7.5 mm
    radii, laws and materials, 24 Fourier modes per profile and the wear law ``PAPER_WEAR``.

    The paper gives no wear data; every wear value is assumed:

    - a bronze bushing (the hole) on a steel pin: hardness 0.64 GPa (65 HB, the bearing
      bronze C93200's data sheet) and 1.6 GPa (163 HB, AISI 1045's);
    - dimensionless wear coefficients 1e-7 (bushing) and 1e-8 (pin): mild wear, the low end
      of the dry range (Archard & Hirst's dry coefficients span about 1e-7 to 1e-2);
    - a bearing 20 mm long (the paper gives none).

    The elastic constants stay the paper preset's steel on steel (E = 207 GPa), so that a
    new ``paper-wear`` moves exactly as ``paper``."""
    base = SliderCrank()
    worn = {j: from_clearance(base.joints[j], PAPER_WEAR) for j in ("B", "C")}
    return SliderCrank(joints={**base.joints, **worn}, name="slider-crank-wear")


def four_bar_lubricated() -> FourBar:
    """The four-bar of [`jaxcrank.physics.presets.four_bar`][] with lubricated pins at B and C:
    the oil and bearing length of [`paper_lubricated`][jaxcrank.physics.catalogue.paper_lubricated]."""
    base = FourBar()
    joints = {**base.joints, "B": _oiled(base.joints["B"]), "C": _oiled(base.joints["C"])}
    return FourBar(joints=joints, name="four-bar-lubricated")


def flores() -> SliderCrank:
    """Flores and Ambrósio's slider-crank: crank 0.05 m, connecting rod 0.12 m, in line
    (no offset), the crank at a constant 5000 rpm from top dead centre, and a dry
    revolute clearance joint of 0.5 mm radial clearance between the connecting rod and
    the slider (joint C); the crank pivot A, the crank pin B and the slider's guide ideal.

    What was read: the COMSOL Application Gallery model "Slider Crank Mechanism with
    Joint Clearance" (model 89951, doc.comsol.com), which reproduces this benchmark: four
    rigid bodies (support, crank, connecting rod, slider), hinges at the crank pivot and
    the crank pin, the rod-slider connection run ideal and with a 0.5 mm clearance, the
    slider moving along x. That page confirms the clearance's place and its 0.5 mm only
    (its crank speed and its parameter file were not seen). Every other value below was
    not read in a source: they are the values of the table commonly reproduced from
    Flores et al. (e.g. Nonlinear Dynamics 2010, doi:10.1007/s11071-010-9676-8, whose
    abstract alone was seen; the 2008 Springer book by Flores, Ambrósio, Claro and
    Lankarani), as recalled, **not checked against the papers**:

    - crank length 0.05 m, rod length 0.12 m (table as recalled);
    - crank speed 5000 rpm (523.6 rad/s), constant, from top dead centre (crank angle 0)
      (as recalled; the start is the usual one);
    - crank mass 0.30 kg, inertia 1e-5 kg m^2 (as recalled; 1e-5 or 1e-4 is uncertain;
      with the crank's motion prescribed it enters only the driving torque);
    - rod mass 0.21 kg, inertia 2.5e-4 kg m^2 (as recalled; a uniform bar's inertia);
    - slider mass 0.14 kg, inertia 1e-4 kg m^2 (as recalled; the slider does not turn,
      so its inertia does not enter);
    - bearing / journal radius at C 10.0 / 9.5 mm (radii as recalled; c = 0.5 mm is the
      confirmed value);
    - contact law Lankarani-Nikravesh with the Hertz stiffness of internal cylinders
      (6.61e10 N/m^1.5 here), restitution 0.9, E = 207 GPa and nu = 0.3 for journal and
      bearing (as recalled);
    - friction: modified Coulomb with Ambrosio's linear ramp, v0 = 1e-4 m/s, v1 = 1e-3 m/s
      (as recalled), mu = 0.01 (a choice: the recalled values run from 0, in the
      frictionless cases, to 0.03);
    - offset 0 (the published figures show an in-line slider);
    - centres of mass at mid-length of crank and rod, the slider's at its pin (assumed);
    - gravity 9.81 m/s^2 along -y (assumed; about 1e-3 of the inertial loads at 5000 rpm);
    - start: pin C centred, every body moving with the ideal mechanism (the usual
      assumption).

    Not taken over: the papers' Baumgarte stabilisation (alpha = beta = 5) and Gear
    integrator (jaxcrank integrates in minimal coordinates, no constraint drift).

    The ideal mechanism's slider acceleration (closed form
    ``a = -r w^2 (cos t + lam cos 2t / D + lam^3 sin^2 2t / (4 D^3))``, ``D = sqrt(1 - lam^2
    sin^2 t)``, lam = r / l = 5 / 12, r w^2 = 13 707.8 m/s^2) is -19 419 m/s^2 at top dead
    centre, +9 696 m/s^2 at 122 and 238 deg (the extremes of the positive lobe) and
    +7 996 m/s^2 at bottom dead centre.

    Each value is a field the user can change (``--set``, TOML, ``equinox.tree_at``).
    """
    steel = Material(youngs_modulus=207e9, poisson_ratio=0.3)
    pin = Clearance(
        hole_radius=10.0e-3,
        pin_radius=9.5e-3,
        contact=Contact(law=LankaraniNikravesh(), restitution=0.9),
        friction=Friction(law=Ambrosio(), coefficient=0.01, stick_speed=1e-4, slip_speed=1e-3),
        pin_material=steel,
        hole_material=steel,
    )
    return SliderCrank(
        crank_length=0.05,
        rod_length=0.12,
        offset=0.0,
        crank_mass=0.30,
        rod_mass=0.21,
        slider_mass=0.14,
        crank_inertia=1e-5,
        rod_inertia=2.5e-4,
        slider_inertia=1e-4,
        joints={"A": Ideal(), "B": Ideal(), "C": pin, "guide": Ideal()},
        driver=ConstantSpeed(body="crank", speed=5000.0 * RPM, initial_angle=0.0),
        gravity=9.81,
        name="flores",
    )


__all__ = [
    "flores",
    "four_bar_four_pins",
    "four_bar_lubricated",
    "paper_lubricated",
    "slider_crank_ground_pivot",
    "slider_crank_three_pins",
]
