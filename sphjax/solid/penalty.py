"""Hourglass penalty force for total-Lagrangian SPH (Ganzenmüller 2015; eq. 14, f^PF).

The deformation gradient (eq. 16) does not see zero-energy (hourglass) modes: particle
displacements that cancel in the kernel-weighted sum.  The penalty force pulls each pair
back towards the position its own ``F`` predicts (VALIDATION.md):

    f_a = 1/2 alpha sum_b [ V0_a V0_b W0(X_ab) / |X_ab|^2 ] (E delta_a + E delta_b) x_ab / |x_ab|
    eps_a = F_a X_ab - x_ab,   delta_a = eps_a . x_ab / |x_ab|   (delta_b likewise with F_b)

with ``E`` Young's modulus and ``alpha`` about 0.01-0.1.  The pair terms are antisymmetric,
so linear momentum is conserved; the acceleration is ``f_a / m0_a``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from sphjax.space import safe_norm


def penalty_force(
    F_a: jax.Array,
    F_b: jax.Array,
    dX: jax.Array,
    rX: jax.Array,
    w0: jax.Array,
    dx: jax.Array,
    volume_a: jax.Array,
    volume_b: jax.Array,
    mask: jax.Array,
    young_modulus,
    alpha,
) -> jax.Array:
    """Penalty force ``f_a^PF`` (a force, not an acceleration).

    Args:
      F_a: ``[M, d, d]`` deformation gradients of the rows.
      F_b: ``[M, K, d, d]`` deformation gradients of the neighbours.
      dX: ``[M, K, d]`` ``X_ab``; rX: ``[M, K]`` ``|X_ab|``; w0: ``[M, K]`` ``W0(X_ab)``.
      dx: ``[M, K, d]`` current ``x_ab``.
      volume_a: ``[M]`` ``V0_a``; volume_b: ``[M, K]`` ``V0_b``.
      mask: ``[M, K]`` True for real pairs.
    Returns:
      ``[M, d]`` ``f_a``.
    """
    rx = safe_norm(dx)
    ok = mask & (rx > 0) & (rX > 0)
    unit = jnp.where(ok[..., None], dx / jnp.where(ok, rx, 1.0)[..., None], 0.0)
    eps_a = jnp.einsum("mij,mkj->mki", F_a, dX) - dx
    eps_b = jnp.einsum("mkij,mkj->mki", F_b, dX) - dx
    delta = jnp.sum((eps_a + eps_b) * unit, axis=-1)
    weight = jnp.where(ok, volume_b * w0 / jnp.where(ok, rX, 1.0) ** 2, 0.0)
    pair = (0.5 * alpha * young_modulus) * weight * delta
    return volume_a[:, None] * jnp.sum(pair[..., None] * unit, axis=1)
