"""Generalised wall boundary of Adami, Hu & Adams (2012).

Each wall (dummy) particle ``w`` takes its pressure from its fluid neighbours ``f``:

    p_w = ( sum_f p_f W_wf + (g - a_w) . sum_f rho_f r_wf W_wf ) / sum_f W_wf

with ``r_wf = r_w - r_f``, and its density from the inverse equation of state (eq. 12).
For the no-slip viscous term the wall velocity is extrapolated,
``v_w = 2 v_wall - sum_f v_f W_wf / sum_f W_wf``; free slip uses the fluid's own velocity
(no shear across the wall).
"""

from __future__ import annotations

import jax.numpy as jnp


def wall_pressure(pressure, density, pairs_to_fluid, gravity, wall_acceleration):
    """Adami pressure of every row particle from its fluid neighbours.

    Args:
      pressure, density: ``[N]`` fluid pressure and density (only fluid entries are read).
      pairs_to_fluid: pairs restricted to fluid neighbours ``b``.
      gravity: ``[d]``; wall_acceleration: ``[N, d]`` prescribed wall acceleration.
    Returns:
      ``(p_w, weight_sum)``: ``[N]`` extrapolated pressures (0 where no fluid neighbour)
      and ``sum_f W_wf``.
    """
    j, w = pairs_to_fluid.j, jnp.where(pairs_to_fluid.mask, pairs_to_fluid.w, 0.0)
    weight_sum = jnp.sum(w, axis=1)
    pressure_sum = jnp.sum(pressure[j] * w, axis=1)
    rho_r_w = jnp.sum((density[j] * w)[..., None] * pairs_to_fluid.dr, axis=1)
    hydrostatic = jnp.sum((gravity - wall_acceleration) * rho_r_w, axis=-1)
    has_fluid = weight_sum > 0
    safe_sum = jnp.where(has_fluid, weight_sum, 1.0)
    return jnp.where(has_fluid, (pressure_sum + hydrostatic) / safe_sum, 0.0), weight_sum


def wall_velocity(velocity, wall_velocity_prescribed, pairs_to_fluid, weight_sum, no_slip):
    """Velocity of wall particles for the viscous terms (no-slip extrapolation)."""
    if not no_slip:
        return None
    w = jnp.where(pairs_to_fluid.mask, pairs_to_fluid.w, 0.0)
    smoothed = jnp.sum(w[..., None] * velocity[pairs_to_fluid.j], axis=1)
    has_fluid = (weight_sum > 0)[:, None]
    smoothed = jnp.where(has_fluid, smoothed / jnp.where(has_fluid, weight_sum[:, None], 1.0), 0.0)
    return 2.0 * wall_velocity_prescribed - smoothed
