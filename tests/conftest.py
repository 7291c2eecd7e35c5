"""Test configuration: every test runs in float64 (gradient and conservation checks)."""

import jax

jax.config.update("jax_enable_x64", True)
