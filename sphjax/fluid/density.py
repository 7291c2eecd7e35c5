"""Density by kernel summation (eq. 5) or by the continuity equation (eq. 11)."""

from __future__ import annotations

import jax.numpy as jnp


def summation_density(mass, pairs, self_weight):
    """Eq. 5: ``rho_a = sum_b m_b W_ab``, the self term ``m_a W(0)`` included.

    Args:
      mass: ``[N]`` particle masses.
      pairs: :class:`sphjax.neighbors.Pairs` over the particles to sum.
      self_weight: ``W(0, h)``.
    """
    neighbour_sum = jnp.sum(jnp.where(pairs.mask, mass[pairs.j] * pairs.w, 0.0), axis=1)
    return mass * self_weight + neighbour_sum


def continuity_density_rate(mass, velocity, pairs):
    """Eq. 11: ``Drho_a/Dt = sum_b m_b (v_a - v_b) . grad_a W_ab``."""
    v_ab = velocity[:, None, :] - velocity[pairs.j]
    rate = jnp.sum(v_ab * pairs.grad_w, axis=-1)
    return jnp.sum(jnp.where(pairs.mask, mass[pairs.j] * rate, 0.0), axis=1)
