import os

import jax
import pytest

# no test writes to the user's cache folder (tests/test_cache.py names its own)
os.environ["JAXCRANK_CACHE_DIR"] = "off"

jax.config.update("jax_enable_x64", True)
# No implicit promotion between dtypes (int and float arrays, bool and float): every
# conversion in jaxcrank and optim is written out (Python scalars still adapt). The
# exception: the tests that run optax's optimisers, whose own update (adam's bias
# correction) mixes its int32 step count with Python floats, which strict promotion
# refuses (optax 0.2.x); they keep JAX's standard promotion.
STANDARD_PROMOTION = (
    "test_optimize.py",
    "test_design.py",
    "test_roundtrip.py",
    "test_starts.py",
    "test_optimizers.py",
    "test_budget.py",
)
jax.config.update("jax_numpy_dtype_promotion", "strict")

import jaxcrank  # noqa: E402,F401


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """Each test, its fixtures included, under the promotion its module allows."""
    mode = "standard" if item.path.name in STANDARD_PROMOTION else "strict"
    jax.config.update("jax_numpy_dtype_promotion", mode)
    yield


@pytest.fixture(scope="session")
def paper():
    return jaxcrank.paper()
