"""Kernel-gradient correction (renormalisation) matrix, formulation eq. 15.

    L0_a = ( -sum_b V0_b grad0_a W(X_ab) X_ab^T )^-1,   V0_b = m0_b / rho0_b

``grad0_a W(X_ab)`` points from b to a, so the sum is close to ``-I`` on a full lattice;
the minus sign (VALIDATION.md, "Conventions that bite") makes ``L0 ~ I``.  With ``L0`` the
corrected gradient ``L0_a grad0_a W`` reproduces linear fields exactly, also at free
surfaces where the kernel support is truncated.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def correction_matrix(grad_w0: jax.Array, dX: jax.Array, volume_b: jax.Array) -> jax.Array:
    """Correction matrix ``L0_a`` (eq. 15).

    Args:
      grad_w0: ``[M, K, d]`` reference kernel gradients ``grad0_a W(X_ab)`` (0 on padding).
      dX: ``[M, K, d]`` reference pair vectors ``X_ab = X_a - X_b`` (0 on padding).
      volume_b: ``[M, K]`` neighbour reference volumes ``V0_b`` (0 on padding).
    Returns:
      ``[M, d, d]`` ``L0_a``.
    """
    moment = -jnp.einsum("mk,mki,mkj->mij", volume_b, grad_w0, dX)
    return jnp.linalg.inv(moment)


def corrected_kernel_gradient(L0: jax.Array, grad_w0: jax.Array) -> jax.Array:
    """``L0_a grad0_a W(X_ab)``: ``[M, d, d]`` and ``[M, K, d]`` -> ``[M, K, d]``."""
    return jnp.einsum("mij,mkj->mki", L0, grad_w0)
