"""The equations of motion of a mechanism with clearance joints: one name for the model,
its parts in modules of their own.

The solver state is the *deviation from the ideal mechanism* in the tree's generalized
coordinates s ([`jaxcrank.physics.topology`][]), so s = 0 is the ideal motion and the
zero-clearance limit is exact in floating point. Which coordinates exist depends on
which joints are ideal: every ideal joint is held by the tree, every other joint is a
force element whose two sides move apart.

The parts:

- [`jaxcrank.physics.linkage`][]: the description (bodies, joints, driver, outputs);
- [`jaxcrank.physics.joints`][]: the joint laws (ideal, clearance) and their interface;
- [`jaxcrank.physics.topology`][]: the tree and the assembly plan, from the names;
- [`jaxcrank.physics.closure`][]: loops of ideal joints closed (dyads in closed form, root
  finds), the ideal mechanism's poses;
- [`jaxcrank.physics.compiled`][]: the compiled model (a description's structure beside its
  numbers), which every function below takes;
- [`jaxcrank.physics.state`][]: the state vector and its scales;
- [`jaxcrank.physics.kinematics`][]: body poses from s, their rates, the joints' motion;
- [`jaxcrank.physics.memory`][]: the approach-speed memory laws;
- [`jaxcrank.physics.dynamics`][]: the equations of motion and the vector field;
- [`jaxcrank.physics.frame`][]: every physical quantity at one (t, y)
  ([`evaluate`][jaxcrank.physics.frame.evaluate]); all outputs use it, so outputs are functions
  of the solution;
- [`jaxcrank.physics.signals`][]: the mechanism's signals and metrics, named from its description.

This module re-exports their public names.
"""

from __future__ import annotations

from .compiled import Model, Structure, as_model, compile_model
from .dynamics import Dynamics, dynamics, vector_field
from .frame import Frame, evaluate
from .kinematics import (
    coordinates,
    frame_poses,
    ideal_poses,
    joint_eccentricities,
    joint_motion,
    positions,
    state_from_eccentricities,
)
from .loops import closure_residuals, newton_poses
from .state import (
    State,
    auxiliary,
    initial_state,
    law_slices,
    law_state_names,
    length_scale,
    n_dof,
    state_names,
    state_scales,
    state_size,
    unpack,
)

__all__ = [
    "Dynamics",
    "Frame",
    "Model",
    "State",
    "Structure",
    "as_model",
    "auxiliary",
    "closure_residuals",
    "compile_model",
    "coordinates",
    "dynamics",
    "evaluate",
    "frame_poses",
    "ideal_poses",
    "initial_state",
    "joint_eccentricities",
    "joint_motion",
    "newton_poses",
    "law_slices",
    "law_state_names",
    "length_scale",
    "n_dof",
    "positions",
    "state_from_eccentricities",
    "state_names",
    "state_scales",
    "state_size",
    "unpack",
    "vector_field",
]
