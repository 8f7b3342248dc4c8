"""jaxcrank: a differentiable simulator of planar linkages with joint clearances.

The public API is what ``__all__`` lists. The modules live in five layers, each
importing only from the ones before it:

- ``jaxcrank.physics``: the description (``linkage``, ``drivers``, ``presets``, ``joints``,
  ``laws``, ``memory``, ``wear``, ``params``, ``parameters``), its structure (``topology``,
  ``planner``, ``closure``, ``assembly``), the compiled model (``compiled``) and the
  equations (``state``, ``kinematics``, ``dynamics``, ``frame``, ``signals``, re-exported by
  ``model``; ``ideal``, ``reference``);
- ``jaxcrank.numerics``: ``results``, ``solve``, ``rosenbrock``, ``linalg``, ``tracking``, ``runtime``, ``shooting``,
  ``steady``, ``wear_run``;
- ``jaxcrank.analysis``: ``metrics``, ``outputs``, ``kinematic_summary``, ``life``, ``life_gradient``, and the
  validation rigs in ``analysis.validation`` (``wall_impact``, ``memory_audit``);
- ``jaxcrank.views``: ``geometry``, ``drawing`` (``draw``), ``animation`` (``animate``),
  on matplotlib;
- ``jaxcrank.runs``: ``sweep``, ``engines``, ``sampling``, ``spec``, ``config``, ``cache``, ``plots``, ``cli``,
  ``steady_cli``, ``regimes``, ``regimes_cli``, ``view_cli``, ``life_cli``, ``plots_life``.

Importing jaxcrank turns on float64 and adds two XLA CPU options to ``XLA_FLAGS``
([`jaxcrank.numerics.runtime`][]): a documented, process-wide decision; what it changes
for other JAX code in the process is measured in the docs ("XLA runtime options").

Each module is also reachable by its short name (``jaxcrank.outputs``,
``from jaxcrank import sweep``; the rigs as ``jaxcrank.impact`` and ``jaxcrank.audit``);
those not imported here load on first use.
"""

import os
import sys
from importlib.metadata import PackageNotFoundError, version
from typing import TYPE_CHECKING

from .numerics import runtime

runtime.configure()  # before anything starts JAX's backend: XLA reads XLA_FLAGS once
if "jax" in sys.modules:  # already imported: switch it to float64 now
    sys.modules["jax"].config.update("jax_enable_x64", True)
else:  # JAX reads this when it is imported (importing it here would delay the first output of every command)
    os.environ["JAX_ENABLE_X64"] = "1"

if TYPE_CHECKING:  # what type checkers and the API docs read; at run time each name loads on first use (_FROM)
    from .analysis import metrics, outputs
    from .analysis.kinematic_summary import kinematic_summary
    from .analysis.life import LifeOptions, life
    from .errors import CorruptFileError
    from .numerics import solve
    from .numerics.results import RESULTS, Regime
    from .numerics.shooting import SteadyOptions
    from .numerics.solve import DEFAULTS, SOLVERS, Simulation, SimulationError, SolveOptions, simulate, solver_from_name
    from .numerics.steady import SteadyState, SteadyStateError, steady_state
    from .physics import ideal, laws, model, params, presets
    from .physics.compiled import Model, compile_model
    from .physics.drivers import ConstantSpeed, SpeedProfile, Torque
    from .physics.joints import JOINT_LAWS, Clearance, Ideal
    from .physics.laws import CONTACT_LAWS, FRICTION_LAWS
    from .physics.linkage import (
        AbstractMechanism,
        Body,
        BodyVector,
        Linkage,
        Outputs,
        Point,
        Pose,
        Prismatic,
        Revolute,
        Site,
    )
    from .physics.memory import MEMORY_LAWS, FrozenMemory
    from .physics.parameters import get_parameter, parameter_value, set_parameter, set_parameters
    from .physics.params import Contact, Friction, Material, ParameterError
    from .physics.presets import PRESETS, FourBar, SliderCrank, four_bar, paper, preset, with_clearance
    from .physics.wear import Archard, Worn
    from .runs import config, sampling
    from .views.animation import animate
    from .views.drawing import draw

#: the public names, by the module (below ``jaxcrank``) each comes from; each loads on first use
_FROM = {
    "analysis": ("metrics", "outputs"),
    "errors": ("CorruptFileError",),
    "numerics": ("solve",),
    "numerics.results": ("RESULTS", "Regime"),
    "numerics.shooting": ("SteadyOptions",),
    "numerics.solve": (
        "DEFAULTS", "SOLVERS", "Simulation", "SimulationError", "SolveOptions", "simulate", "solver_from_name",
    ),
    "numerics.steady": ("SteadyState", "SteadyStateError", "steady_state"),
    "physics": ("ideal", "laws", "model", "params", "presets"),
    "physics.joints": ("JOINT_LAWS", "Clearance", "Ideal"),
    "physics.wear": ("Archard", "Worn"),
    "analysis.life": ("LifeOptions", "life"),
    "physics.laws": ("CONTACT_LAWS", "FRICTION_LAWS"),
    "physics.compiled": ("Model", "compile_model"),
    "physics.drivers": ("ConstantSpeed", "SpeedProfile", "Torque"),
    "physics.linkage": (
        "AbstractMechanism", "Body", "BodyVector", "Linkage", "Outputs", "Point", "Pose", "Prismatic", "Revolute",
        "Site",
    ),
    "physics.memory": ("MEMORY_LAWS", "FrozenMemory"),
    "physics.parameters": ("get_parameter", "parameter_value", "set_parameter", "set_parameters"),
    "physics.params": ("Contact", "Friction", "Material", "ParameterError"),
    "physics.presets": ("PRESETS", "FourBar", "SliderCrank", "four_bar", "paper", "preset", "with_clearance"),
    "runs": ("config", "sampling"),
    "views.drawing": ("draw",),
    "views.animation": ("animate",),
    "analysis.kinematic_summary": ("kinematic_summary",),
}  # fmt: skip
_ORIGIN = {name: module for module, names in _FROM.items() for name in names}

#: Short names of the modules that ``import jaxcrank`` does not load: each loads on first use.
_LAZY = {
    "reference": "physics.reference",
    "linalg": "numerics.linalg",
    "rosenbrock": "numerics.rosenbrock",
    "tracking": "numerics.tracking",
    "shooting": "numerics.shooting",
    "wear_run": "numerics.wear_run",
    "life_gradient": "analysis.life_gradient",
    "impact": "analysis.validation.wall_impact",
    "audit": "analysis.validation.memory_audit",
    "sweep": "runs.sweep",
    "spec": "runs.spec",
    "cache": "runs.cache",
    "plots": "runs.plots",
    "cli": "runs.cli",
}


def __getattr__(name: str):
    import importlib

    if name in _ORIGIN:
        module = importlib.import_module(f"{__name__}.{_ORIGIN[name]}")
        try:
            value = getattr(module, name)
        except AttributeError:  # a submodule of a package not imported yet
            value = importlib.import_module(f"{module.__name__}.{name}")
        globals()[name] = value
        return value
    if name in _LAZY:
        return importlib.import_module(f"{__name__}.{_LAZY[name]}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted({*globals(), *_ORIGIN, *_LAZY})


try:
    __version__ = version("jaxcrank")
except PackageNotFoundError:  # a source tree that was not installed
    __version__ = "0+unknown"

__all__ = [
    "life",
    "animate",
    "draw",
    "kinematic_summary",
    "CONTACT_LAWS",
    "DEFAULTS",
    "FRICTION_LAWS",
    "JOINT_LAWS",
    "MEMORY_LAWS",
    "PRESETS",
    "RESULTS",
    "SOLVERS",
    "AbstractMechanism",
    "Archard",
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
    "LifeOptions",
    "Linkage",
    "Material",
    "Model",
    "Outputs",
    "ParameterError",
    "Point",
    "Pose",
    "Prismatic",
    "Regime",
    "Revolute",
    "Site",
    "SliderCrank",
    "Worn",
    "SpeedProfile",
    "Torque",
    "four_bar",
    "compile_model",
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
