"""jaxcrank: a differentiable simulator of planar linkages with joint clearances.

The public API is what ``__all__`` lists. The modules live in four layers, each
importing only from the ones before it:

- ``jaxcrank.physics``: the description (``linkage``, ``presets``, ``joints``, ``laws``,
  ``memory``, ``params``, ``parameters``), its structure (``topology``, ``closure``) and
  the model (``state``, ``kinematics``, ``dynamics``, ``frame``, ``signals``, re-exported by
  ``model``; ``ideal``, ``reference``);
- ``jaxcrank.numerics``: ``results``, ``solve``, ``rosenbrock``, ``linalg``, ``tracking``, ``runtime``, ``shooting``,
  ``steady``;
- ``jaxcrank.analysis``: ``metrics``, ``outputs``, and the validation rigs in
  ``analysis.validation`` (``wall_impact``, ``memory_audit``);
- ``jaxcrank.runs``: ``sweep``, ``engines``, ``sampling``, ``spec``, ``config``, ``cache``, ``plots``, ``cli``,
  ``steady_cli``, ``regimes``, ``regimes_cli``.

Importing jaxcrank turns on float64 and adds two XLA CPU options to ``XLA_FLAGS``
([`jaxcrank.numerics.runtime`][]): a documented, process-wide decision; what it changes
for other JAX code in the process is measured in the docs ("XLA runtime options").

Each module is also reachable by its short name (``jaxcrank.outputs``,
``from jaxcrank import sweep``; the rigs as ``jaxcrank.impact`` and ``jaxcrank.audit``);
those not imported here load on first use.
"""

from importlib.metadata import PackageNotFoundError, version

import jax

from .numerics import runtime

runtime.configure()  # before anything starts JAX's backend: XLA reads XLA_FLAGS once
jax.config.update("jax_enable_x64", True)

from .analysis import metrics, outputs  # noqa: E402
from .errors import CorruptFileError  # noqa: E402
from .numerics import solve  # noqa: E402
from .numerics.results import RESULTS, Regime  # noqa: E402
from .numerics.shooting import SteadyOptions  # noqa: E402
from .numerics.solve import (  # noqa: E402
    DEFAULTS,
    SOLVERS,
    Simulation,
    SimulationError,
    SolveOptions,
    simulate,
    solver_from_name,
)
from .numerics.steady import SteadyState, SteadyStateError, steady_state  # noqa: E402
from .physics import ideal, laws, model, params, presets  # noqa: E402
from .physics.joints import JOINT_LAWS, Clearance, Ideal  # noqa: E402
from .physics.laws import CONTACT_LAWS, FRICTION_LAWS  # noqa: E402
from .physics.linkage import (  # noqa: E402
    AbstractMechanism,
    Body,
    BodyVector,
    ConstantSpeed,
    Linkage,
    Outputs,
    Point,
    Pose,
    Prismatic,
    Revolute,
    Site,
    SpeedProfile,
    Torque,
)
from .physics.memory import MEMORY_LAWS, FrozenMemory  # noqa: E402
from .physics.parameters import get_parameter, parameter_value, set_parameter, set_parameters  # noqa: E402
from .physics.params import Contact, Friction, Material, ParameterError  # noqa: E402
from .physics.presets import PRESETS, FourBar, SliderCrank, four_bar, paper, preset, with_clearance  # noqa: E402
from .runs import config, sampling  # noqa: E402

#: Short names of the modules that ``import jaxcrank`` does not load: each loads on first use.
_LAZY = {
    "reference": "physics.reference",
    "linalg": "numerics.linalg",
    "rosenbrock": "numerics.rosenbrock",
    "tracking": "numerics.tracking",
    "shooting": "numerics.shooting",
    "impact": "analysis.validation.wall_impact",
    "audit": "analysis.validation.memory_audit",
    "sweep": "runs.sweep",
    "spec": "runs.spec",
    "cache": "runs.cache",
    "plots": "runs.plots",
    "cli": "runs.cli",
}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return importlib.import_module(f"{__name__}.{_LAZY[name]}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


try:
    __version__ = version("jaxcrank")
except PackageNotFoundError:  # a source tree that was not installed
    __version__ = "0+unknown"

__all__ = [
    "CONTACT_LAWS",
    "DEFAULTS",
    "FRICTION_LAWS",
    "JOINT_LAWS",
    "MEMORY_LAWS",
    "PRESETS",
    "RESULTS",
    "SOLVERS",
    "AbstractMechanism",
    "Body",
    "BodyVector",
    "Clearance",
    "ConstantSpeed",
    "Contact",
    "CorruptFileError",
    "FourBar",
    "Friction",
    "FrozenMemory",
    "Ideal",
    "Linkage",
    "Material",
    "Outputs",
    "ParameterError",
    "Point",
    "Pose",
    "Prismatic",
    "Regime",
    "Revolute",
    "Site",
    "SliderCrank",
    "SpeedProfile",
    "Torque",
    "four_bar",
    "get_parameter",
    "parameter_value",
    "preset",
    "presets",
    "set_parameter",
    "set_parameters",
    "Simulation",
    "SimulationError",
    "SolveOptions",
    "SteadyOptions",
    "SteadyState",
    "SteadyStateError",
    "config",
    "ideal",
    "laws",
    "metrics",
    "model",
    "outputs",
    "paper",
    "params",
    "sampling",
    "simulate",
    "solve",
    "solver_from_name",
    "steady_state",
    "with_clearance",
    "__version__",
]
