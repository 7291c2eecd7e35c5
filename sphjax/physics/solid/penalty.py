"""Hourglass penalty force for total-Lagrangian SPH (Ganzenmüller 2015; eq. 14, f^PF).

The deformation gradient (eq. 16) does not see zero-energy (hourglass) modes: particle
displacements that cancel in the kernel-weighted sum.  The penalty force pulls each pair
back towards the position its own ``F`` predicts:

    f_a = 1/2 alpha sum_b [ V0_a V0_b W0(X_ab) / |X_ab|^2 ] (E delta_a + E delta_b) x_ab / |x_ab|
    eps_a = F_a X_ab - x_ab,   delta_a = eps_a . x_ab / |x_ab|   (delta_b likewise with F_b)

with ``E`` Young's modulus and ``alpha`` about 0.01-0.1.  The pair terms are antisymmetric,
so linear momentum is conserved; the acceleration is ``f_a / m0_a``.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp

from sphjax.core.space import dot


def penalty_force(reference_pair, dx, F_a, F_b, volume_a, volume_b, young_modulus, alpha):
    """Per pair: the penalty force on ``a`` from ``b`` (a force, not an acceleration).

    Args:
      reference_pair: reference-configuration pair geometry (``X_ab``, ``|X_ab|``, ``W0``).
      dx: ``[..., d]`` current ``x_ab``.
      F_a, F_b: ``[..., d, d]`` deformation gradients.
      volume_a, volume_b: reference volumes ``V0``.
    """
    r2 = dot(dx, dx)
    rX = reference_pair.r
    ok = reference_pair.mask & (r2 > 0) & (rX > 0)
    rx = jnp.sqrt(jnp.where(ok, r2, 1.0))
    unit = jnp.where(ok[..., None], dx / rx[..., None], 0.0)
    dX = reference_pair.dr
    eps_a = jnp.einsum("...ij,...j->...i", F_a, dX) - dx
    eps_b = jnp.einsum("...ij,...j->...i", F_b, dX) - dx
    delta = dot(eps_a + eps_b, unit)
    weight = jnp.where(ok, volume_b * reference_pair.w / jnp.where(ok, rX, 1.0) ** 2, 0.0)
    pair = (0.5 * alpha * young_modulus) * weight * delta
    return (volume_a * pair)[..., None] * unit


@dataclasses.dataclass(frozen=True)
class PenaltyForce:
    """Ganzenmüller's (2015) hourglass penalty with ``Params.penalty_alpha``."""

    #: the Params fields the penalty force reads
    parameters = ("penalty_alpha", "young_modulus")
