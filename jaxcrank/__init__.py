"""jaxcrank: a differentiable simulator of slider-crank mechanisms with joint clearances.

The public API is what ``__all__`` lists; the submodules (``laws``, ``model``,
``ideal``, ``metrics``, ``outputs``, ``sampling``, ``sweep``, ``spec``, ``config``)
are documented in the API reference.
"""

from importlib.metadata import PackageNotFoundError, version

import jax

from . import runtime

runtime.configure()  # before anything starts JAX's backend: XLA reads XLA_FLAGS once
jax.config.update("jax_enable_x64", True)

from . import config, ideal, laws, metrics, model, outputs, sampling  # noqa: E402
from .errors import CorruptFileError  # noqa: E402
from .laws import CONTACT_LAWS, FRICTION_LAWS  # noqa: E402
from .params import (  # noqa: E402
    Contact,
    Friction,
    Joint,
    Material,
    Mechanism,
    ParameterError,
    paper,
    with_clearance,
)
from .solve import DEFAULTS, SOLVERS, Simulation, SimulationError, SolveOptions, simulate  # noqa: E402

try:
    __version__ = version("jaxcrank")
except PackageNotFoundError:  # a source tree that was not installed
    __version__ = "0+unknown"

__all__ = [
    "CONTACT_LAWS",
    "DEFAULTS",
    "FRICTION_LAWS",
    "SOLVERS",
    "Contact",
    "CorruptFileError",
    "Friction",
    "Joint",
    "Material",
    "Mechanism",
    "ParameterError",
    "Simulation",
    "SimulationError",
    "SolveOptions",
    "config",
    "ideal",
    "laws",
    "metrics",
    "model",
    "outputs",
    "paper",
    "sampling",
    "simulate",
    "with_clearance",
    "__version__",
]
