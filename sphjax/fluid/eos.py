"""Tait equation of state (formulation eq. 12) and its inverse."""

from __future__ import annotations

import jax.numpy as jnp


def tait_pressure(
    density, reference_density, sound_speed, gamma, reference_pressure=0.0, background_pressure=0.0
):
    """Pressure from density, eq. 12.

    ``p = rho0 c^2 / gamma ((rho / rho0)^gamma - 1) + p0 - p_background``.
    ``gamma = 1`` gives the linear law ``c^2 (rho - rho0)``.
    """
    stiffness = reference_density * sound_speed**2 / gamma
    return stiffness * ((density / reference_density) ** gamma - 1.0) + (
        reference_pressure - background_pressure
    )


def tait_density(
    pressure, reference_density, sound_speed, gamma, reference_pressure=0.0, background_pressure=0.0
):
    """Density from pressure: the inverse of eq. 12 (used for wall particles and set-up).

    The base of the power is clipped at a small positive number so that a strongly
    negative pressure never produces NaN (nor a NaN gradient).
    """
    stiffness = reference_density * sound_speed**2 / gamma
    base = (pressure - reference_pressure + background_pressure) / stiffness + 1.0
    base = jnp.maximum(base, 1e-6)
    return reference_density * base ** (1.0 / gamma)
