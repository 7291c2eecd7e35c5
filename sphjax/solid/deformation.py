"""Deformation gradient, formulation eq. 16 (the slides call it ``J``; here ``F``).

    F_a = -sum_b V0_b x_ab (L0_a grad0_a W(X_ab))^T,   x_ab = x_a - x_b

The slides write ``x_ba (L0_a grad0_a W)^T`` with ``x_ba = x_b - x_a``: the same thing.
With ``L0`` from eq. 15, ``F`` reproduces any affine map ``x = A X + c`` exactly
(``F = A``), in particular ``F = I`` on the reference configuration.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def deformation_gradient(
    dx: jax.Array, corrected_grad_w0: jax.Array, volume_b: jax.Array
) -> jax.Array:
    """Deformation gradient ``F_a`` (eq. 16).

    Args:
      dx: ``[M, K, d]`` current pair vectors ``x_ab = x_a - x_b`` (0 on padding).
      corrected_grad_w0: ``[M, K, d]`` ``L0_a grad0_a W(X_ab)``.
      volume_b: ``[M, K]`` neighbour reference volumes ``V0_b`` (0 on padding).
    Returns:
      ``[M, d, d]`` ``F_a``, ``F_ij = dx_i / dX_j``.
    """
    return -jnp.einsum("mk,mki,mkj->mij", volume_b, dx, corrected_grad_w0)
