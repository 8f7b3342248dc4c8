"""The building blocks of the steady state (jaxcrank.numerics.shooting) on inputs whose
answers are known without a mechanism: the period test on section points, idle memories
and the Newton matrix, Floquet multipliers, batch means against a direct computation,
and the argument checks."""

import math

import numpy as np
import pytest
from scipy import stats

import jaxcrank as jc
from jaxcrank.numerics import shooting


def _section(pattern, repeats, m=3, noise=0.0, seed=0):
    """Section points cycling through ``pattern`` (rows of m dynamic entries) plus two
    work entries that grow every revolution (never compared)."""
    rng = np.random.default_rng(seed)
    pts = np.array([pattern[i % len(pattern)] for i in range(repeats)], dtype=float)
    pts = pts + noise * rng.standard_normal(pts.shape)
    works = np.cumsum(np.ones((repeats, 2)), axis=0)
    return np.concatenate([pts, works], axis=1)


@pytest.mark.parametrize("period", [1, 2, 3])
def test_recurrence_finds_the_smallest_period(period):
    pattern = [[float(k), -float(k), 0.5 * k] for k in range(period)]
    found, distances = shooting.recurrence(_section(pattern, 12), m=3, max_period=4, tol=1e-3)
    assert int(found) == period
    assert distances.shape == (4,) and distances[period - 1] == 0.0
    assert np.all(distances[: period - 1] >= 1.0)  # shorter lags are a whole pattern step apart


def test_recurrence_within_the_tolerance_and_beyond_it():
    """A period-2 cycle blurred by 1e-5: recurs at tolerance 1e-3, not at 1e-7; a period
    longer than max_period is not found; the work entries (after m) are not compared."""
    section = _section([[0.0, 1.0, 2.0], [1.0, 0.0, 2.0]], 10, noise=1e-5)
    assert int(shooting.recurrence(section, 3, 4, 1e-3)[0]) == 2
    assert int(shooting.recurrence(section, 3, 4, 1e-7)[0]) == 0
    five = _section([[float(k), 0.0, 0.0] for k in range(5)], 12)
    assert int(shooting.recurrence(five, 3, 4, 1e-3)[0]) == 0


def test_recurrence_is_batched_over_designs_and_never_recurs_on_nan():
    a = _section([[0.0, 1.0, 2.0]], 6)
    b = _section([[0.0, 1.0, 2.0], [3.0, 1.0, 2.0]], 6)
    c = a.copy()
    c[-1, 0] = np.nan
    period, distances = shooting.recurrence(np.stack([a, b, c]), 3, 3, 1e-3)
    assert period.tolist() == [1, 2, 0] and distances.shape == (3, 3)


def test_idle_rows_newton_matrix_and_multipliers():
    """A map whose third entry is carried unchanged (a unit row: an idle memory): idle
    finds it, the Newton matrix is I - M on the active entries and the identity on the
    idle one, and the multipliers are the eigenvalues of M on the active block, largest
    modulus first."""
    jac = np.array([[0.5, 0.2, 0.3], [-0.1, 0.25, 0.0], [0.0, 0.0, 1.0]])
    active = ~shooting.idle(jac)
    assert active.tolist() == [True, True, False]
    a = np.asarray(shooting.newton_matrix(jac, active))
    np.testing.assert_array_equal(a[:2, :2], np.eye(2) - jac[:2, :2])
    np.testing.assert_array_equal(a[2], [0.0, 0.0, 1.0])
    np.testing.assert_array_equal(a[:2, 2], [0.0, 0.0])
    mu = shooting.multipliers(jac, active)
    exact = np.linalg.eigvals(jac[:2, :2])
    np.testing.assert_allclose(sorted(np.abs(mu)), sorted(np.abs(exact)), rtol=1e-14)
    assert np.all(np.diff(np.abs(mu)) <= 0.0)


def test_batch_means_against_a_direct_computation():
    """Mean and RMS with Student-t 95 % intervals from batch means, the first values
    dropped to fill whole batches, against the formula written out here; a peak's ``max`` is
    the largest value of the run, the dropped ones included."""
    values = np.random.default_rng(1).normal(2.0, 0.3, 21)
    batch = 4
    kept = values[1:].reshape(5, 4)
    for rms, x in ((False, kept), (True, kept**2)):
        means = x.mean(axis=1)
        half = stats.t.ppf(0.975, 4) * means.std(ddof=1) / math.sqrt(5)
        got = shooting.batch_means(values, batch, rms)
        centre = means.mean()
        want = (
            (math.sqrt(centre), math.sqrt(centre - half), math.sqrt(centre + half))
            if rms
            else (centre, centre - half, centre + half)
        )
        np.testing.assert_allclose([got["value"], got["ci95_low"], got["ci95_high"]], want, rtol=1e-14)
        assert ("max" in got) == (not rms) and got.get("max", values.max()) == values.max()  # all 21 values
    with pytest.raises(jc.ParameterError, match="at least 2 batches"):
        shooting.batch_means(values[:7], 4, False)


@pytest.mark.parametrize(
    ("index", "value", "name"),
    [
        (0, 0, "settle_revolutions"),
        (1, 1.5, "max_period"),
        (2, -1e-3, "recurrence_tol"),
        (3, float("nan"), "newton_tol"),
        (4, -1, "max_newton"),
        (5, 3, "statistics_revolutions"),
        (7, 1, "samples_per_revolution"),
    ],
)
def test_argument_checks_name_the_argument(index, value, name):
    args = [20, 4, 1e-3, 1e-7, 8, 10, 2, 3600]
    shooting.check_arguments(*args)  # the defaults pass
    args[index] = value
    with pytest.raises(jc.ParameterError, match=name):
        shooting.check_arguments(*args)
