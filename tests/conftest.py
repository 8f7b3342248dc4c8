import os

import jax
import pytest

# no test writes to the user's cache folder (tests/test_cache.py names its own)
os.environ["JAXCRANK_CACHE_DIR"] = "off"

jax.config.update("jax_enable_x64", True)

import jaxcrank  # noqa: E402,F401


@pytest.fixture(scope="session")
def paper():
    return jaxcrank.paper()
