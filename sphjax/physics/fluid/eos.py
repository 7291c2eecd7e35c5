"""Equations of state (formulation eq. 12): Tait and linear, and their inverses.

An equation of state is a small hashable object with ``pressure(density, fluid_params)``
and ``density(pressure, fluid_params)``; :class:`~sphjax.FluidSystem` takes one.
"""

from __future__ import annotations

import dataclasses

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


def linear_pressure(
    density, reference_density, sound_speed, reference_pressure=0.0, background_pressure=0.0
):
    """Linear equation of state ``p = c0^2 (rho - rho0) + p0 - p_background``."""
    return sound_speed**2 * (density - reference_density) + reference_pressure - background_pressure


def linear_density(
    pressure, reference_density, sound_speed, reference_pressure=0.0, background_pressure=0.0
):
    """Inverse of :func:`linear_pressure`: ``rho = rho0 + (p - p0 + p_background) / c0^2``."""
    return (
        reference_density + (pressure - reference_pressure + background_pressure) / sound_speed**2
    )


@dataclasses.dataclass(frozen=True)
class TaitEOS:
    """Tait equation of state, eq. 12, with exponent ``gamma`` (7 for free surfaces, 1 for
    internal flows)."""

    gamma: float = 7.0

    #: the Params fields eq. 12 reads
    parameters = ("reference_density", "sound_speed", "reference_pressure", "background_pressure")

    def _constants(self, fluid):
        """``(rho0, c0, gamma, p0, p_background)`` of eq. 12 from the fluid's Params."""
        return (
            fluid.reference_density,
            fluid.sound_speed,
            self.gamma,
            fluid.reference_pressure,
            fluid.background_pressure,
        )

    def pressure(self, density, fluid):
        return tait_pressure(density, *self._constants(fluid))

    def density(self, pressure, fluid):
        return tait_density(pressure, *self._constants(fluid))


@dataclasses.dataclass(frozen=True)
class LinearEOS:
    """Linear equation of state ``p = c0^2 (rho - rho0) + p0 - p_background``."""

    #: the Params fields eq. 12 reads
    parameters = ("reference_density", "sound_speed", "reference_pressure", "background_pressure")

    def _constants(self, fluid):
        """``(rho0, c0, p0, p_background)`` from the fluid's Params."""
        return (
            fluid.reference_density,
            fluid.sound_speed,
            fluid.reference_pressure,
            fluid.background_pressure,
        )

    def pressure(self, density, fluid):
        return linear_pressure(density, *self._constants(fluid))

    def density(self, pressure, fluid):
        return linear_density(pressure, *self._constants(fluid))
