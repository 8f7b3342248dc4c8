"""jaxcrank: a differentiable simulator of slider-crank mechanisms with joint clearances."""

import jax

from . import runtime

runtime.configure()  # before anything starts JAX's backend: XLA reads XLA_FLAGS once
jax.config.update("jax_enable_x64", True)

from . import ideal, laws, model  # noqa: E402
from .params import (  # noqa: E402
    CONTACT_LAWS,
    FRICTION_LAWS,
    Contact,
    Friction,
    Joint,
    Material,
    Mechanism,
    ParameterError,
    paper,
    with_clearance,
)
from .solve import SOLVERS, Simulation, SimulationError, simulate  # noqa: E402

__version__ = "0.1.0"
