"""Optimisers as small Modules, passed to [`optim.optimize.optimize`][] in its
[`Settings`][optim.optimize.Settings] (names map to them only at the TOML/CLI boundary,
`OPTIMIZERS`).

All work on the scaled design ``u`` in the unit box and keep it feasible. Two kinds:
[`AbstractUpdateOptimizer`][optim.optimizers.AbstractUpdateOptimizer] (one evaluation per iteration, the
loop applies and projects the update) and
[`AbstractLineSearchOptimizer`][optim.optimizers.AbstractLineSearchOptimizer] (an iteration evaluates the
trial points of its own line search).

- [`Projected`][optim.optimizers.Projected]: any ``optax.GradientTransformation`` (``optax.adam(0.1)`` by
  default), each step projected onto the feasible set, ``u <- P(u + update)``.
- [`LBFGS`][optim.optimizers.LBFGS]: ``optax.lbfgs`` with its zoom line search on the objective extended
  beyond the feasible set by ``f(P(u)) + penalty * |u - P(u)|^2`` (continuous, equal
  to f inside), the iterate projected after each step.
- [`ProjectedLBFGS`][optim.optimizers.ProjectedLBFGS]: L-BFGS on the working set's face of the feasible
  set with an Armijo search along the projection arc ([`optim.quasi_newton`][]); every trial point is
  feasible, and a trial the regime guard refuses shortens the step. It also runs on the host-evaluated
  steady-state objective.
"""

from __future__ import annotations

import abc
import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import optax

from jaxcrank.physics.params import ParameterError

from . import quasi_newton as qn


class AbstractOptimizer(eqx.Module):
    """An optimiser of [`optim.optimize.optimize`][]. Every subclass has a field
    ``label`` (str): its name in checkpoints, histories and reports (a resume checks it)."""

    @abc.abstractmethod
    def init(self, u: jax.Array):
        """The optimiser state at the scaled design ``u``."""

    @abc.abstractmethod
    def settings(self) -> dict:
        """The settings as plain values (``method`` and its parameters), for the CLI's resolved configuration."""


class AbstractUpdateOptimizer(AbstractOptimizer):
    """An optimiser whose iteration is one update from one evaluation; the loop applies
    it and projects the result onto the feasible set."""

    @abc.abstractmethod
    def update(self, grad, state, u, value, f0, extended):
        """``(updates, state)`` at ``u`` with the scaled ``value`` and ``grad``;
        ``extended(u, f0) -> (value, grad)`` is the objective extended beyond the
        feasible set ([`optim.optimize.programs`][]), for a line search."""


class AbstractLineSearchOptimizer(AbstractOptimizer):
    """An optimiser whose iteration evaluates its own trial points, each feasible.

    Attributes:
        ftol: the loop also stops when an accepted step changes the scaled value by at most
            ``ftol * max(|f_k|, |f_k+1|, 1)`` ([`optim.quasi_newton.value_change_converged`][]).
    """

    ftol: eqx.AbstractVar[float]

    @abc.abstractmethod
    def step(self, fun, feasible, u, value, grad, state) -> qn.Step:
        """One iteration from the scaled design ``u`` with its scaled ``value`` and ``grad``:
        ``fun(u) -> (value, grad)`` evaluates a trial point (None: refused, a failed trial),
        ``feasible`` is the scaled feasible set ([`optim.problem.FeasibleSet`][]). Returns
        [`optim.quasi_newton.Step`][] (the new iterate, its value and gradient, the state,
        whether it succeeded, the evaluations it made)."""


class Projected(AbstractUpdateOptimizer):
    """Projected steps of an optax ``GradientTransformation``.

    Attributes:
        transformation: the optax transformation (e.g. ``optax.adam(0.1)``); its updates
            are in scaled design units.
        label: its name (default ``"adam"``).
        learning_rate: the step size the transformation was built with, for reports
            (None when not known).
    """

    transformation: optax.GradientTransformation = eqx.field(static=True)
    label: str = eqx.field(static=True, default="adam")
    learning_rate: float | None = eqx.field(static=True, default=None)

    def init(self, u):
        return self.transformation.init(u)

    def update(self, grad, state, u, value, f0, extended):
        return self.transformation.update(grad, state, u)

    def settings(self) -> dict:
        return {"method": self.label, "learning_rate": self.learning_rate}


class LBFGS(AbstractUpdateOptimizer):
    """``optax.lbfgs`` with its zoom line search on the extended objective.

    Attributes:
        penalty: weight of the out-of-set penalty of the extension, > 0.
        max_linesearch_steps: line-search budget per iteration, >= 1.
        label: its name (``"lbfgs"``).
    """

    penalty: float = eqx.field(static=True, default=10.0)
    max_linesearch_steps: int = eqx.field(static=True, default=6)
    label: str = eqx.field(static=True, default="lbfgs")

    def __check_init__(self):
        if not self.penalty > 0 or self.max_linesearch_steps < 1:
            raise ParameterError(
                f"LBFGS: penalty = {self.penalty!r} must be > 0 and "
                f"max_linesearch_steps = {self.max_linesearch_steps!r} >= 1"
            )

    def transformation(self) -> optax.GradientTransformationExtraArgs:
        """The optax L-BFGS transformation."""
        return optax.lbfgs(
            linesearch=optax.scale_by_zoom_linesearch(
                max_linesearch_steps=self.max_linesearch_steps, initial_guess_strategy="one"
            )
        )

    def init(self, u):
        return self.transformation().init(u)

    def update(self, grad, state, u, value, f0, extended):
        return _lbfgs_update(self, extended)(grad, state, u, value, jnp.asarray(f0, jnp.float64))

    def settings(self) -> dict:
        return {"method": self.label, "penalty": self.penalty, "max_linesearch_steps": self.max_linesearch_steps}


@functools.lru_cache(maxsize=8)
def _lbfgs_update(opt: LBFGS, extended):
    """L-BFGS's update step ``(grad, state, u, value, f0) -> (updates, state)`` for the
    extension program ``extended``, jitted once per program and settings: optax's zoom
    line search traces the objective inside a while loop, which compiled eagerly would
    compile the whole objective again at every iteration."""
    transformation = opt.transformation()
    line = _line_search_function(extended)

    @jax.jit
    def update(grad, state, u, value, f0):
        return transformation.update(grad, state, u, value=value, grad=grad, value_fn=lambda v: line(v, f0))

    return update


def _line_search_function(extended):
    """``extended``'s value as a function whose reverse-mode derivative is ``extended``'s
    own gradient.

    Why: optax's zoom line search (``optax.scale_by_zoom_linesearch``, checked against
    optax 0.2.8) differentiates ``value_fn`` with ``jax.value_and_grad`` and offers no
    argument for a function that returns value and gradient; a forward-mode objective
    ([`optim.ensemble.Ensemble`][] with ``diffrax.ForwardMode``) has no reverse-mode
    derivative. A ``jax.custom_vjp`` (public JAX API) hands the line search the
    gradient the objective's own program computes."""

    @jax.custom_vjp
    def line(u, f0):
        return extended(u, f0)[0]

    def forward(u, f0):
        value, grad = extended(u, f0)
        return value, grad

    def backward(grad, cotangent):
        return cotangent * grad, jnp.zeros(())

    line.defvjp(forward, backward)
    return line


class ProjectedLBFGS(AbstractLineSearchOptimizer):
    """Projected L-BFGS with an Armijo search along the projection arc ([`optim.quasi_newton`][]):
    the quasi-Newton step on the face of the feasible set the active constraints with
    nonnegative multipliers span, every trial point projected onto the set; a trial with
    a non-finite value or one the evaluation refuses (the regime guard) fails the Armijo
    test and the step shrinks.

    Attributes:
        memory_size: pairs ``(s, y)`` kept, >= 1.
        max_linesearch_steps: trial points per arc, >= 1 (after a failed quasi-Newton arc
            the projected-gradient arc gets as many).
        initial_step: the first step's (and every projected-gradient arc's) largest change
            of a scaled variable at ``t = 1``, > 0.
        ftol: relative value-change test (``AbstractLineSearchOptimizer``), >= 0.
        armijo: sufficient-decrease constant, in (0, 0.5).
        curvature_eps: a pair is stored only when ``s . y > curvature_eps * y . y``, >= 0.
        active_tol: a constraint whose slack (scaled) is at most this is active, >= 0.
        label: its name (``"projected_lbfgs"``).

    Raises:
        ParameterError: for a setting outside its range.
    """

    memory_size: int = eqx.field(static=True, default=20)
    max_linesearch_steps: int = eqx.field(static=True, default=10)
    initial_step: float = eqx.field(static=True, default=0.05)
    ftol: float = eqx.field(static=True, default=1e-9)
    armijo: float = eqx.field(static=True, default=1e-4)
    curvature_eps: float = eqx.field(static=True, default=1e-10)
    active_tol: float = eqx.field(static=True, default=1e-9)
    label: str = eqx.field(static=True, default="projected_lbfgs")

    def __check_init__(self):
        checks = {
            "memory_size": (self.memory_size >= 1, ">= 1"),
            "max_linesearch_steps": (self.max_linesearch_steps >= 1, ">= 1"),
            "initial_step": (self.initial_step > 0, "> 0"),
            "ftol": (self.ftol >= 0, ">= 0"),
            "armijo": (0 < self.armijo < 0.5, "in (0, 0.5)"),
            "curvature_eps": (self.curvature_eps >= 0, ">= 0"),
            "active_tol": (self.active_tol >= 0, ">= 0"),
        }
        for name, (ok, valid) in checks.items():
            if not ok:
                raise ParameterError(f"ProjectedLBFGS: {name} = {getattr(self, name)!r} must be {valid}")

    def init(self, u):
        return qn.init_state(u, self.memory_size)

    def step(self, fun, feasible, u, value, grad, state) -> qn.Step:
        return qn.step(self, fun, feasible, u, value, grad, state)

    def settings(self) -> dict:
        return {"method": self.label, **{k: getattr(self, k) for k in _PROJECTED_LBFGS_SETTINGS}}


_PROJECTED_LBFGS_SETTINGS = ("memory_size", "max_linesearch_steps", "initial_step", "ftol")


def adam(learning_rate: float = 0.1) -> Projected:
    """Projected Adam with step size ``learning_rate`` (scaled design units per iteration)."""
    if not learning_rate > 0:
        raise ParameterError(f"learning_rate = {learning_rate!r} must be > 0")
    return Projected(optax.adam(learning_rate), "adam", learning_rate)


#: the optimisers by name, for the TOML/CLI boundary: name -> (constructor, its keyword settings)
OPTIMIZERS = {
    "adam": (adam, ("learning_rate",)),
    "lbfgs": (LBFGS, ("penalty", "max_linesearch_steps")),
    "projected_lbfgs": (ProjectedLBFGS, _PROJECTED_LBFGS_SETTINGS),
}


def from_settings(method: str, **kwargs) -> AbstractOptimizer:
    """The optimiser named ``method`` (`OPTIMIZERS`) with its keyword settings.

    Raises:
        ParameterError: for an unknown name or a setting it does not take.
    """
    if method not in OPTIMIZERS:
        raise ParameterError(f"optimiser method {method!r} is unknown; valid: {', '.join(OPTIMIZERS)}")
    make, accepted = OPTIMIZERS[method]
    bad = {k for k, v in kwargs.items() if v is not None} - set(accepted)
    if bad:
        raise ParameterError(f"optimiser {method!r} takes {list(accepted)}, not {sorted(bad)}")
    return make(**{k: v for k, v in kwargs.items() if v is not None})
