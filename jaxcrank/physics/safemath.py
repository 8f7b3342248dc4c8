"""Small math helpers of the physics, in one place: norms, powers and steps whose values
and gradients stay finite everywhere (double ``where`` around every square root, power
and kink), planar vector operations, and the small linear solves of the equations of
motion written as plain array operations.

The kinematics work on scalars (pairs of them for planar vectors) that may be numbers
known at trace time: a mechanism's literal zeros (points on a body's frame axes, a
fixed guide's direction) then cost no operation, where XLA would keep a product with
zero ([`mul`][jaxcrank.physics.safemath.mul], [`vturn`][jaxcrank.physics.safemath.vturn]).
The same code runs on NumPy arrays (checks of a description) and on
[`Jet`][jaxcrank.physics.safemath.Jet]s, a value with its first two time derivatives.

Plain array operations keep XLA's solver loop on its one-kernel path (no LAPACK call
inside it, [`jaxcrank.numerics.runtime`][]), and the systems here are a few unknowns.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float


def safe_norm(v: Float[ArrayLike, "*shape n"], axis: int = -1) -> Float[Array, "*shape"]:
    """Euclidean norm with a zero (not NaN) gradient at v = 0."""
    sq = jnp.sum(v * v, axis=axis)
    positive = sq > 0.0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, sq, 1.0)), 0.0)


def safe_sqrt(x: Float[ArrayLike, "*shape"]) -> Float[Array, "*shape"]:
    """sqrt(x) for x > 0, else 0; gradient finite everywhere (zero where x <= 0)."""
    positive = x > 0.0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, x, 1.0)), 0.0)


def smoothstep(x: Float[ArrayLike, "*shape"]) -> Float[Array, "*shape"]:
    """C2 quintic step 10x^3 - 15x^4 + 6x^5 of x clipped to [0, 1]: 0 at x <= 0, 1 at x >= 1."""
    x = jnp.clip(x, 0.0, 1.0)
    return x**3 * (10.0 - 15.0 * x + 6.0 * x**2)


def positive_power(x: Float[ArrayLike, "*shape"], p) -> Float[Array, "*shape"]:
    """x**p for x > 0, else 0; finite gradient everywhere (p >= 1)."""
    positive = x > 0.0
    return jnp.where(positive, jnp.where(positive, x, 1.0) ** p, 0.0)


def perp(v: Float[ArrayLike, "*shape 2"]) -> Float[Array, "*shape 2"]:
    """Planar vector(s) rotated by +90 degrees."""
    v = jnp.asarray(v)
    return jnp.stack([-v[..., 1], v[..., 0]], axis=-1)


def cross(a: Float[ArrayLike, "*shape 2"], b: Float[ArrayLike, "*shape 2"]) -> Float[Array, "*shape"]:
    """Planar cross product a_x b_y - a_y b_x (the z component)."""
    a, b = jnp.asarray(a), jnp.asarray(b)
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


@jax.custom_jvp
def rotation(angle: Float[ArrayLike, ""]) -> tuple[Array, Array]:
    """(cos angle, sin angle). Its derivatives reuse the two values, so a kinematic chain
    differentiated twice in time evaluates each angle's cosine and sine once."""
    return jnp.cos(angle), jnp.sin(angle)


@rotation.defjvp
def _rotation_jvp(primals, tangents):
    c, s = rotation(primals[0])
    (dt,) = tangents
    return (c, s), (-s * dt, c * dt)


def known(v) -> bool:
    """Whether ``v`` is a number known at trace time (a Python or NumPy scalar, not a bool)."""
    return isinstance(v, (int, float, np.floating, np.integer)) and not isinstance(v, bool)


def known_zero(v) -> bool:
    """Whether ``v`` is a number known at trace time to be zero."""
    return known(v) and v == 0


def known_one(v) -> bool:
    return known(v) and v == 1


# --------------------------------------------------------------------------- scalars


def add(a, b):
    """a + b; a term known to be zero costs nothing."""
    if known_zero(a):
        return b
    if known_zero(b):
        return a
    return a + b


def sub(a, b):
    """a - b; a term known to be zero costs nothing."""
    if known_zero(b):
        return a
    if known_zero(a):
        return -b
    return a - b


def mul(a, b):
    """a b; a factor known to be zero gives 0.0, one known to be one the other factor."""
    if known_zero(a) or known_zero(b):
        return 0.0
    if known_one(a):
        return b
    if known_one(b):
        return a
    return a * b


def div(a, b):
    """a / b; a numerator known to be zero gives 0.0, a denominator known to be one ``a``."""
    if known_zero(a):
        return 0.0
    if known_one(b):
        return a
    return a / b


def total(terms) -> object:
    """The sum of ``terms`` in order, terms known to be zero left out (0.0 for none)."""
    out = 0.0
    for term in terms:
        out = add(out, term)
    return out


def _on_numpy(*xs) -> bool:
    return not any(isinstance(x, jax.Array) for x in xs)


def sqrt(x):
    """Square root of x >= 0 (the caller guards the sign)."""
    if isinstance(x, Jet):
        root = sqrt(x.value)
        rate = div(x.rate, mul(2.0, root))
        if x.second is None:
            return Jet(root, rate, None)
        return Jet(root, rate, div(sub(x.second, mul(2.0, mul(rate, rate))), mul(2.0, root)))
    if known(x):
        return math.sqrt(x)
    return np.sqrt(x) if _on_numpy(x) else jnp.sqrt(x)


def atan2(y, x):
    """The angle of the vector (x, y), rad."""
    if isinstance(x, Jet) or isinstance(y, Jet):
        y, x = Jet.of(y), Jet.of(x)
        angle = atan2(y.value, x.value)
        r2 = add(mul(x.value, x.value), mul(y.value, y.value))
        rate = div(sub(mul(x.value, y.rate), mul(y.value, x.rate)), r2)
        if x.second is None or y.second is None:
            return Jet(angle, rate, None)
        along = div(add(mul(x.value, x.rate), mul(y.value, y.rate)), r2)
        second = sub(div(sub(mul(x.value, y.second), mul(y.value, x.second)), r2), mul(2.0, mul(rate, along)))
        return Jet(angle, rate, second)
    if known(x) and known(y):
        return math.atan2(y, x)
    return np.arctan2(y, x) if _on_numpy(x, y) else jnp.arctan2(y, x)


def cos_sin(angle) -> tuple:
    """(cos angle, sin angle), each once ([`rotation`][jaxcrank.physics.safemath.rotation] for traced angles)."""
    if isinstance(angle, Jet):
        c, s = cos_sin(angle.value)
        if angle.second is None:
            return Jet(c, neg(mul(s, angle.rate)), None), Jet(s, mul(c, angle.rate), None)
        rate2 = mul(angle.rate, angle.rate)
        return (
            Jet(c, neg(mul(s, angle.rate)), sub(neg(mul(c, rate2)), mul(s, angle.second))),
            Jet(s, mul(c, angle.rate), sub(mul(c, angle.second), mul(s, rate2))),
        )
    if known(angle):
        return math.cos(angle), math.sin(angle)
    if _on_numpy(angle):
        return np.cos(angle), np.sin(angle)
    return rotation(angle)


def neg(a):
    """-a."""
    return 0.0 if known_zero(a) else -a


def where(condition, a, b):
    """``a`` where ``condition``, else ``b`` (a condition known at trace time picks one)."""
    if isinstance(a, Jet) or isinstance(b, Jet):
        a, b = Jet.of(a), Jet.of(b)
        second = None if a.second is None or b.second is None else where(condition, a.second, b.second)
        return Jet(where(condition, a.value, b.value), where(condition, a.rate, b.rate), second)
    if isinstance(condition, (bool, np.bool_)):
        return a if condition else b
    return np.where(condition, a, b) if _on_numpy(condition, a, b) else jnp.where(condition, a, b)


class Jet:
    """A scalar with its first two derivatives along one parameter (time, in the
    kinematics): ``(value, rate, second)``; ``second = None``: first derivatives only (the
    rate may then be an array, derivatives along several directions at once). Arithmetic
    and [`sqrt`][jaxcrank.physics.safemath.sqrt],
    [`atan2`][jaxcrank.physics.safemath.atan2], [`cos_sin`][jaxcrank.physics.safemath.cos_sin] propagate the
    derivatives by the chain rule in one pass (Taylor mode), so a closed form costs its
    value and two derivatives, not a derivative of a derivative. Comparisons look at the
    value. Numbers act as constants."""

    __slots__ = ("value", "rate", "second")

    def __init__(self, value, rate=0.0, second=0.0):
        self.value, self.rate, self.second = value, rate, second

    @staticmethod
    def of(x) -> Jet:
        return x if isinstance(x, Jet) else Jet(x)

    def __iter__(self):
        return iter((self.value, self.rate, self.second))

    def __add__(self, other):
        o = Jet.of(other)
        return Jet(add(self.value, o.value), add(self.rate, o.rate), _both(add, self.second, o.second))

    __radd__ = __add__

    def __sub__(self, other):
        o = Jet.of(other)
        return Jet(sub(self.value, o.value), sub(self.rate, o.rate), _both(sub, self.second, o.second))

    def __rsub__(self, other):
        return Jet.of(other) - self

    def __neg__(self):
        return Jet(neg(self.value), neg(self.rate), None if self.second is None else neg(self.second))

    def __mul__(self, other):
        a, b = self, Jet.of(other)
        rate = add(mul(a.value, b.rate), mul(a.rate, b.value))
        if a.second is None or b.second is None:
            return Jet(mul(a.value, b.value), rate, None)
        cross_term = mul(2.0, mul(a.rate, b.rate))
        return Jet(mul(a.value, b.value), rate, total([mul(a.value, b.second), cross_term, mul(a.second, b.value)]))

    __rmul__ = __mul__

    def __truediv__(self, other):
        a, b = self, Jet.of(other)
        value = div(a.value, b.value)
        rate = div(sub(a.rate, mul(value, b.rate)), b.value)
        if a.second is None or b.second is None:
            return Jet(value, rate, None)
        second = div(total([a.second, neg(mul(2.0, mul(rate, b.rate))), neg(mul(value, b.second))]), b.value)
        return Jet(value, rate, second)

    def __rtruediv__(self, other):
        return Jet.of(other) / self

    def __ge__(self, other):
        return self.value >= Jet.of(other).value


def _both(op, a, b):
    """``op(a, b)`` of two Jets' second derivatives; None (not tracked) where either is."""
    return None if a is None or b is None else op(a, b)


def stop_gradient(x):
    """``jax.lax.stop_gradient`` of traced values; numbers and NumPy arrays as they are."""
    return x if _on_numpy(x) else jax.lax.stop_gradient(x)


# --------------------------------------------------------------------------- planar vectors as pairs


def vadd(u: tuple, v: tuple) -> tuple:
    """u + v of planar vectors as pairs."""
    return add(u[0], v[0]), add(u[1], v[1])


def vsub(u: tuple, v: tuple) -> tuple:
    """u - v of planar vectors as pairs."""
    return sub(u[0], v[0]), sub(u[1], v[1])


def vscale(k, v: tuple) -> tuple:
    """k v of a planar vector as a pair."""
    return mul(k, v[0]), mul(k, v[1])


def vdot(u: tuple, v: tuple):
    """u . v of planar vectors as pairs."""
    return add(mul(u[0], v[0]), mul(u[1], v[1]))


def vcross(u: tuple, v: tuple):
    """u_x v_y - u_y v_x of planar vectors as pairs."""
    return sub(mul(u[0], v[1]), mul(u[1], v[0]))


def vperp(v: tuple) -> tuple:
    """A planar vector (a pair) turned by +90 degrees."""
    return neg(v[1]), v[0]


def vturn(rot: tuple, v) -> tuple:
    """``v`` (a pair, or an array (2,)) turned by ``rot`` = (cos, sin), as a pair; components
    known to be zero cost nothing."""
    c, s = rot
    x, y = v[0], v[1]
    return sub(mul(c, x), mul(s, y)), add(mul(s, x), mul(c, y))


def turn(rot: tuple, v) -> Array:
    """``v`` (an array (2,) or a pair of numbers) turned by the rotation ``rot`` = (cos, sin).
    Components known at trace time to be zero cost nothing (points on a body's frame axes)."""
    c, s = rot
    x, y = v[0], v[1]
    zx, zy = known_zero(x), known_zero(y)
    if zx and zy:
        return jnp.zeros(2)
    if zy:
        return jnp.stack([c * x, s * x])
    if zx:
        return jnp.stack([-s * y, c * y])
    return jnp.stack([c * x - s * y, s * x + c * y])


def rotate(angle: Float[ArrayLike, ""], v) -> Float[Array, " 2"]:
    """``v`` (an array (2,) or a pair of numbers) rotated by ``angle`` (rad)."""
    return turn(rotation(angle), v)


def direction(angle: Float[ArrayLike, ""]) -> Float[Array, " 2"]:
    """The unit vector at ``angle`` (rad)."""
    return jnp.stack(rotation(angle))


def solve_2x2(a: Float[ArrayLike, "2 2"], b: Float[ArrayLike, " 2"]) -> Float[Array, " 2"]:
    """a^-1 b for a 2 x 2 matrix a, in closed form."""
    det = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    return jnp.stack([a[1, 1] * b[0] - a[0, 1] * b[1], a[0, 0] * b[1] - a[1, 0] * b[0]]) / det


def solve_spd(a: Float[ArrayLike, "n n"], b: Float[ArrayLike, " n"], pattern: Sequence[Sequence[bool]]) -> Array:
    """a^-1 b for a small symmetric positive-definite matrix ``a`` (a generalised mass
    matrix), by an LDL^T factorisation without pivoting, unrolled.

    ``pattern[i][j]`` (static) says whether entry (i, j) can be nonzero; entries it rules
    out are never read and their fill-in is tracked, so a block-diagonal matrix costs its
    blocks alone. A diagonal matrix gives exactly ``b / diag(a)``.
    """
    n = len(pattern)
    x = ldl_solve(lambda i, j: a[i, j], [b[i] for i in range(n)], pattern)
    return jnp.stack([jnp.asarray(v, dtype=float) for v in x]) if n else jnp.zeros(0)


def ldl_solve(entry, b: Sequence, pattern: Sequence[Sequence[bool]]) -> list:
    """[`solve_spd`][jaxcrank.physics.safemath.solve_spd] on scalars: ``entry(i, j)`` gives the matrix's
    entry (i, j), ``b`` the right-hand side; returns x as a list."""
    n = len(pattern)
    nz = [[bool(pattern[i][j]) or i == j for j in range(n)] for i in range(n)]
    low = [[None] * n for _ in range(n)]  # L below the diagonal; None: structurally zero
    d = [None] * n
    for j in range(n):
        dj = entry(j, j)
        for k in range(j):
            if low[j][k] is not None:
                dj = sub(dj, mul(mul(low[j][k], low[j][k]), d[k]))
        d[j] = dj
        for i in range(j + 1, n):
            terms = [(k, low[i][k], low[j][k]) for k in range(j) if low[i][k] is not None and low[j][k] is not None]
            if not nz[i][j] and not terms:
                continue
            v = entry(i, j) if nz[i][j] else 0.0
            for k, lik, ljk in terms:
                v = sub(v, mul(mul(lik, ljk), d[k]))
            low[i][j] = div(v, dj)
    z = [None] * n
    for i in range(n):
        zi = b[i]
        for k in range(i):
            if low[i][k] is not None:
                zi = sub(zi, mul(low[i][k], z[k]))
        z[i] = zi
    x = [None] * n
    for i in reversed(range(n)):
        xi = div(z[i], d[i])
        for k in range(i + 1, n):
            if low[k][i] is not None:
                xi = sub(xi, mul(low[k][i], x[k]))
        x[i] = xi
    return x


def solve_dense(a: Float[ArrayLike, "n n"], b: Float[ArrayLike, "n ..."]) -> Array:
    """a^-1 b for a small square matrix by Gaussian elimination with partial pivoting,
    unrolled (for the loop-closure and joint-reaction systems, a few unknowns)."""
    a = jnp.asarray(a)
    b = jnp.asarray(b)
    n = a.shape[0]
    vec = b.ndim == 1
    m = jnp.concatenate([a, b[:, None] if vec else b], axis=1)
    rows = jnp.arange(n)
    for j in range(n):
        col = m[:, j]
        p = jnp.argmax(jnp.where(rows >= j, jnp.abs(col), -1.0))
        rj, rp = m[j], m[p]
        m = m.at[p].set(rj).at[j].set(rp)
        m = m.at[j].set(m[j] / m[j, j])
        factors = jnp.where(rows == j, 0.0, m[:, j])
        m = m - factors[:, None] * m[j][None, :]
    x = m[:, n:]
    return x[:, 0] if vec else x
