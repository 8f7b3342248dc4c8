import jax
import pytest

jax.config.update("jax_enable_x64", True)

import jaxcrank  # noqa: E402,F401


@pytest.fixture(scope="session")
def paper():
    return jaxcrank.paper()
