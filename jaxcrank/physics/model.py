"""The slider-crank with clearance joints (model.md, Eq. 14): one name for the model,
its parts in modules of their own.

The solver state is the *deviation from the ideal mechanism* in generalized
coordinates s, so s = 0 is the ideal motion and the zero-clearance limit is exact
in floating point. Which coordinates exist depends on which joints are ideal:

========================  ====================================================
clearance at B and C      s = (dx2, dy2, dtheta2, dx3): 4 degrees of freedom
ideal B, clearance at C   s = (dtheta2, dx3): rod end B follows the crank pin
clearance at B, ideal C   s = (dtheta2, dx3): rod end C follows the slider pin
both ideal                no s: the closed-form mechanism
========================  ====================================================

The parts:

- [`jaxcrank.physics.joints`][]: the joints B and C as objects (parameters, pin and
  hole motion), so the rest loops over them;
- [`jaxcrank.physics.state`][]: the state vector and its scales;
- [`jaxcrank.physics.kinematics`][]: full coordinates Q = (x2, y2, theta2, x3) from s,
  their rates, the eccentricities;
- [`jaxcrank.physics.memory`][]: the approach-speed memory law;
- [`jaxcrank.physics.contact`][]: contact in one joint;
- [`jaxcrank.physics.dynamics`][]: the equations of motion and the vector field;
- [`jaxcrank.physics.frame`][]: every physical quantity at one (t, y) ([`evaluate`][jaxcrank.physics.frame.evaluate]);
  all outputs use it, so outputs are functions of the solution.

This module re-exports their public names.
"""

from __future__ import annotations

from .contact import JointContact, approach_memory_rate, joint_contact
from .dynamics import Dynamics, dynamics, vector_field
from .frame import Frame, evaluate
from .joints import JOINTS, AbstractJointSite, JointMotion, clearance_joints, clearance_sites
from .kinematics import (
    coordinates,
    eccentricities,
    full_positions,
    joint_eccentricities,
    state_from_eccentricities,
)
from .memory import freeze_coordinate, memory_relaxation, memory_target, memory_target_rate, memory_tracking
from .state import State, auxiliary, initial_state, length_scale, n_dof, state_scales, state_size, unpack

__all__ = [
    "JOINTS",
    "AbstractJointSite",
    "Dynamics",
    "Frame",
    "JointContact",
    "JointMotion",
    "State",
    "approach_memory_rate",
    "auxiliary",
    "clearance_joints",
    "clearance_sites",
    "coordinates",
    "dynamics",
    "eccentricities",
    "evaluate",
    "freeze_coordinate",
    "full_positions",
    "initial_state",
    "joint_contact",
    "joint_eccentricities",
    "length_scale",
    "memory_relaxation",
    "memory_target",
    "memory_target_rate",
    "memory_tracking",
    "n_dof",
    "state_from_eccentricities",
    "state_scales",
    "state_size",
    "unpack",
    "vector_field",
]
