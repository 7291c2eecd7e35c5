"""Fluid momentum equation (eq. 10)."""

from __future__ import annotations

import jax.numpy as jnp


def pressure_acceleration(mass, density, pressure, pairs, pi_ab):
    """Eq. 10 without gravity and laminar viscosity:

    ``Dv_a/Dt = - sum_b m_b (p_a / rho_a^2 + p_b / rho_b^2 + Pi_ab) grad_a W_ab``.

    ``pi_ab`` is ``[N, K]`` (Monaghan artificial viscosity) or 0.
    """
    j = pairs.j
    term = pressure[:, None] / density[:, None] ** 2 + pressure[j] / density[j] ** 2 + pi_ab
    pair_force = (mass[j] * term)[..., None] * pairs.grad_w
    return -jnp.sum(jnp.where(pairs.mask[..., None], pair_force, 0.0), axis=1)
