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


# Second-order-consistent reference gradient (the static choice
# ``SolidSystem(gradient_correction="second_order")``).
#
# For particle ``a`` the weighted least-squares fit of the quadratic Taylor polynomial
# ``u_b - u_a ~ grad u . X_ba + 1/2 X_ba^T H X_ba`` to its reference neighbours, weight
# ``V0_b omega_ab``, ``omega_ab = -W0'(|X_ab|) / |X_ab|``, gives the gradient as
#
#     grad u_a = sum_b V0_b (u_b - u_a) psi_ab,     psi_ab = G_a omega_ab p(X_ba),
#     p(X) = (X_1 .. X_d, X_i X_j / h for i <= j),   M_a = sum_b V0_b omega_ab p p^T,
#     G_a = the first d rows of M_a^-1,
#
# exact for every polynomial of degree <= 2, also where the support is cut by a free
# surface (generalised finite differences, Liszka & Orkisz 1980; in SPH the second-order
# corrections of Zhang & Batra 2004 and Fatehi & Manzari 2011 are of this kind).  With
# this weight ``omega_ab X_ba = grad0_a W(X_ab)``: the linear block of ``M_a`` is the
# inverse of eq. 15's ``L0_a``, and where the neighbourhood is symmetric (the odd moments
# vanish) ``psi_ab = L0_a grad0_a W`` as in the first-order correction.  ``G_a`` is kept as
# its linear block ``[d, d]`` and its quadratic block ``[d, d (d + 1) / 2]``.  The
# quadratic monomials are divided by ``h`` so that ``M_a`` is uniform in units.


def _quadratic_pairs(d: int):
    return [(i, j) for i in range(d) for j in range(i, d)]


def quadratic_weights(reference_pair, h):
    """Per pair ``omega_ab X_ba,i X_ba,j / h`` for ``i <= j`` (``[..., d (d + 1) / 2]``):
    the quadratic part of ``omega_ab p(X_ba)``, whose linear part is ``grad0_a W(X_ab)``.
    The same for the pair seen from ``b`` (even in ``X``)."""
    g, dX = reference_pair.grad_w, reference_pair.dr
    d = g.shape[-1]
    # omega X_ba = grad0_a W(X_ab), X_ba = -X_ab
    return jnp.stack([-g[..., i] * dX[..., j] / h for i, j in _quadratic_pairs(d)], axis=-1)


def second_order_moment(reference_pair, volume_b, h):
    """Per pair ``V0_b omega_ab p(X_ba) p(X_ba)^T`` (``[..., m, m]``, ``m = d + d (d + 1)
    / 2``); summed and solved by :func:`second_order_matrices`."""
    dX = reference_pair.dr
    d = dX.shape[-1]
    weighted = jnp.concatenate(
        [reference_pair.grad_w, quadratic_weights(reference_pair, h)], axis=-1
    )
    basis = jnp.concatenate(
        [-dX] + [(dX[..., i] * dX[..., j] / h)[..., None] for i, j in _quadratic_pairs(d)],
        axis=-1,
    )
    return volume_b[..., None, None] * weighted[..., :, None] * basis[..., None, :]


def second_order_matrices(moment_sum):
    """``(G_lin, G_quad)``: the first ``d`` rows of ``M_a^-1`` (summed
    :func:`second_order_moment`, ``[M, m, m]``), split into ``[M, d, d]`` and
    ``[M, d, m - d]``."""
    m = moment_sum.shape[-1]
    d = int(round((-3 + (9 + 8 * m) ** 0.5) / 2))
    rhs = jnp.broadcast_to(jnp.eye(m, d, dtype=moment_sum.dtype), moment_sum.shape[:-1] + (d,))
    rows = jnp.swapaxes(jnp.linalg.solve(moment_sum, rhs), -1, -2)
    return rows[..., :d], rows[..., d:]


def second_order_kernel_gradient(G_lin, G_quad, reference_pair, h):
    """``psi_ab = G_a omega_ab p(X_ba)`` (``[..., d]``), the corrected gradient of
    ``a``'s pair with ``b``."""
    return jnp.einsum("...ij,...j->...i", G_lin, reference_pair.grad_w) + jnp.einsum(
        "...ij,...j->...i", G_quad, quadratic_weights(reference_pair, h)
    )
