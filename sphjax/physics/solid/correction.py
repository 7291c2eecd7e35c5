"""Kernel-gradient correction (renormalisation) matrix, formulation eq. 15.

    L0_a = ( -sum_b V0_b grad0_a W(X_ab) X_ab^T )^-1,   V0_b = m0_b / rho0_b

``grad0_a W(X_ab)`` points from b to a, so the sum is close to ``-I`` on a full lattice;
the minus sign makes ``L0 ~ I``.  With ``L0`` the corrected gradient ``L0_a grad0_a W``
reproduces linear fields exactly, also at free surfaces where the kernel support is
truncated.
"""

from __future__ import annotations

import jax.numpy as jnp


def correction_moment(reference_pair, volume_b):
    """Per pair: ``-V0_b grad0_a W(X_ab) X_ab^T`` (``[..., d, d]``); summed and inverted by
    :func:`correction_matrix`."""
    return (
        -volume_b[..., None, None]
        * reference_pair.grad_w[..., :, None]
        * reference_pair.dr[..., None, :]
    )


def correction_matrix(moment_sum):
    """``L0_a`` (eq. 15) from the summed :func:`correction_moment`, ``[M, d, d]``."""
    return jnp.linalg.inv(moment_sum)


def corrected_kernel_gradient(L0_a, grad_w0):
    """``L0_a grad0_a W(X_ab)``: ``[..., d, d]`` and ``[..., d]`` -> ``[..., d]``."""
    return jnp.einsum("...ij,...j->...i", L0_a, grad_w0)
