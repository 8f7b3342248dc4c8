"""Design samplers: tables of designs over named parameters, SI units.

Every sampler returns ``(names, designs)``, the parameter names (any name
[`jaxcrank.physics.parameters.set_parameter`][] accepts) and an array of shape
``(N, len(names))`` of their values, ready for [`jaxcrank.runs.sweep.run`][] or for a
design problem (`optim`).

- [`full_factorial`][jaxcrank.runs.sampling.full_factorial]: every combination of given levels;
- [`latin_hypercube`][jaxcrank.runs.sampling.latin_hypercube] ,
[`random_uniform`][jaxcrank.runs.sampling.random_uniform] : ``n`` designs in a box;
- [`one_at_a_time`][jaxcrank.runs.sampling.one_at_a_time]: one line per variable through a base design;
- [`monte_carlo`][jaxcrank.runs.sampling.monte_carlo]: manufactured parts, each parameter drawn from its
  [`Tolerance`][jaxcrank.runs.sampling.Tolerance].
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Mapping, Sequence

import numpy as np
from jaxtyping import Float

from ..physics.linkage import AbstractMechanism as Mechanism
from ..physics.parameters import get_parameter
from ..physics.params import ParameterError


def _ranges(ranges: Mapping[str, Sequence[float]]):
    names = list(ranges)
    lo = np.array([float(ranges[n][0]) for n in names])
    hi = np.array([float(ranges[n][1]) for n in names])
    bad = [n for n, a, b in zip(names, lo, hi) if not a <= b]
    if bad:
        raise ParameterError(f"range of {bad[0]!r} must be (lower, upper) with lower <= upper")
    return names, lo, hi


def full_factorial(levels: Mapping[str, Sequence[float]]) -> tuple[list[str], Float[np.ndarray, "designs params"]]:
    """Every combination of the given levels: ``(names, designs (N, k))``, SI."""
    names = list(levels)
    return names, np.array(list(itertools.product(*[np.asarray(levels[n], float) for n in names])), float)


def latin_hypercube(
    ranges: Mapping[str, Sequence[float]], n: int, seed: int = 0
) -> tuple[list[str], Float[np.ndarray, "designs params"]]:
    """``n`` Latin-hypercube samples in the box ``ranges`` (name -> (lower, upper)):
    each variable's range is cut into ``n`` equal strata, each used once."""
    names, lo, hi = _ranges(ranges)
    rng = np.random.default_rng(seed)
    u = (np.stack([rng.permutation(n) for _ in names], axis=1) + rng.random((n, len(names)))) / n
    return names, lo + u * (hi - lo)


def random_uniform(
    ranges: Mapping[str, Sequence[float]], n: int, seed: int = 0
) -> tuple[list[str], Float[np.ndarray, "designs params"]]:
    """``n`` independent uniform samples in the box ``ranges``."""
    names, lo, hi = _ranges(ranges)
    return names, lo + np.random.default_rng(seed).random((n, len(names))) * (hi - lo)


def one_at_a_time(
    base: Mechanism, ranges: Mapping[str, Sequence[float]], points: int = 11
) -> tuple[list[str], Float[np.ndarray, "designs params"]]:
    """One line per variable through ``base``: ``points`` equally spaced values of
    that variable over its range, the others at their ``base`` values."""
    names, lo, hi = _ranges(ranges)
    x0 = np.array([get_parameter(base, n) for n in names])
    rows = []
    for j in range(len(names)):
        for v in np.linspace(lo[j], hi[j], points):
            x = x0.copy()
            x[j] = v
            rows.append(x)
    return names, np.array(rows)


@dataclasses.dataclass(frozen=True)
class Tolerance:
    """A manufactured parameter: ``nominal`` (SI) within a band ``+-tolerance``.

    ``distribution = "uniform"``: uniform over the band; ``"normal"``: normal with
    the band as +-3 sigma (99.7 % of parts inside it, the usual process-capability
    reading of a tolerance)."""

    nominal: float
    tolerance: float
    distribution: str = "uniform"

    def __post_init__(self):
        if self.distribution not in ("uniform", "normal"):
            raise ParameterError(f"distribution {self.distribution!r} is unknown; valid: 'uniform', 'normal'")
        if not self.tolerance >= 0:
            raise ParameterError(f"tolerance = {self.tolerance:g} must be >= 0")

    @property
    def sigma(self) -> float:
        """Standard deviation, SI."""
        return self.tolerance / 3.0 if self.distribution == "normal" else self.tolerance / math.sqrt(3.0)

    def standard(self, rng: np.random.Generator, n: int) -> Float[np.ndarray, " n"]:
        """``n`` draws of the standardised variable (band = [-1, 1] for uniform, 3 sigma = 1 for normal)."""
        return rng.uniform(-1.0, 1.0, n) if self.distribution == "uniform" else rng.standard_normal(n) / 3.0


def monte_carlo(
    tolerances: Mapping[str, Tolerance], n: int, seed: int = 0
) -> tuple[list[str], Float[np.ndarray, "designs params"]]:
    """``n`` manufactured parts: every parameter drawn from its [`Tolerance`][jaxcrank.runs.sampling.Tolerance]."""
    rng = np.random.default_rng(seed)
    names = list(tolerances)
    cols = [tolerances[k].nominal + tolerances[k].tolerance * tolerances[k].standard(rng, n) for k in names]
    return names, np.stack(cols, axis=1)
