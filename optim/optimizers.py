"""Optimisers as small Modules, passed to [`optim.optimize.optimize`][] in its
[`Settings`][optim.optimize.Settings] (names map to them only at the TOML/CLI boundary,
`OPTIMIZERS`).

Both work on the scaled design ``u`` in the unit box and keep it feasible:

- [`Projected`][optim.optimizers.Projected]: any ``optax.GradientTransformation`` (``optax.adam(0.1)`` by
  default), each step projected onto the feasible set, ``u <- P(u + update)``.
- [`LBFGS`][optim.optimizers.LBFGS]: ``optax.lbfgs`` with its zoom line search on the objective extended
  beyond the feasible set by ``f(P(u)) + penalty * |u - P(u)|^2`` (continuous, equal
  to f inside), the iterate projected after each step.
"""

from __future__ import annotations

import abc
import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import optax

from jaxcrank.physics.params import ParameterError


class AbstractOptimizer(eqx.Module):
    """An optimiser of [`optim.optimize.optimize`][]. Every subclass has a field
    ``label`` (str): its name in checkpoints, histories and reports (a resume checks it)."""

    @abc.abstractmethod
    def init(self, u: jax.Array):
        """The optimiser state at the scaled design ``u``."""

    @abc.abstractmethod
    def update(self, grad, state, u, value, f0, extended):
        """``(updates, state)`` at ``u`` with the scaled ``value`` and ``grad``;
        ``extended(u, f0) -> (value, grad)`` is the objective extended beyond the
        feasible set ([`optim.optimize.programs`][]), for a line search."""

    @abc.abstractmethod
    def settings(self) -> dict:
        """The settings as plain values (``method`` and its parameters), for the CLI's resolved configuration."""


class Projected(AbstractOptimizer):
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


class LBFGS(AbstractOptimizer):
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
    ([`optim.objective.Ensemble`][] with ``diffrax.ForwardMode``) has no reverse-mode
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


def adam(learning_rate: float = 0.1) -> Projected:
    """Projected Adam with step size ``learning_rate`` (scaled design units per iteration)."""
    if not learning_rate > 0:
        raise ParameterError(f"learning_rate = {learning_rate!r} must be > 0")
    return Projected(optax.adam(learning_rate), "adam", learning_rate)


#: the optimisers by name, for the TOML/CLI boundary: name -> (constructor, its keyword settings)
OPTIMIZERS = {"adam": (adam, ("learning_rate",)), "lbfgs": (LBFGS, ("penalty", "max_linesearch_steps"))}


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
