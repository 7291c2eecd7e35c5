"""Test configuration: every test runs in float64 (gradient and conservation checks)."""

import jax
import pytest

jax.config.update("jax_enable_x64", True)


@pytest.fixture(autouse=True)
def float64():
    """Every test starts in float64, whatever an earlier test switched, and the setting
    is restored afterwards."""
    previous = jax.config.jax_enable_x64
    jax.config.update("jax_enable_x64", True)
    yield
    jax.config.update("jax_enable_x64", previous)
