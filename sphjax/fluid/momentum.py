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


def transport_stress_acceleration(mass, density, velocity, delta_v, pairs):
    """Transport-velocity momentum flux (Adami, Hu & Adams 2013), in the form of eq. 10:

    ``sum_b m_b (A_a / rho_a^2 + A_b / rho_b^2) . grad_a W_ab`` with
    ``A = rho v (v~ - v)^T``, i.e. ``A / rho^2 . grad W = v ((v~ - v) . grad W) / rho``.
    """
    j = pairs.j
    flux_a = velocity[:, None, :] * jnp.sum(delta_v[:, None, :] * pairs.grad_w, -1)[..., None]
    flux_b = velocity[j] * jnp.sum(delta_v[j] * pairs.grad_w, -1)[..., None]
    term = flux_a / density[:, None, None] + flux_b / density[j][..., None]
    pair = mass[j][..., None] * term
    return jnp.sum(jnp.where(pairs.mask[..., None], pair, 0.0), axis=1)
