"""Deformation gradient, formulation eq. 16 (the slides call it ``J``; here ``F``).

    F_a = -sum_b V0_b x_ab (L0_a grad0_a W(X_ab))^T,   x_ab = x_a - x_b

The slides write ``x_ba (L0_a grad0_a W)^T`` with ``x_ba = x_b - x_a``: the same thing.
With ``L0`` from eq. 15, ``F`` reproduces any affine map ``x = A X + c`` exactly
(``F = A``), in particular ``F = I`` on the reference configuration.
"""

from __future__ import annotations


def deformation_term(dx, corrected_grad_w0, volume_b):
    """Per pair: ``-V0_b x_ab (L0_a grad0_a W)^T`` (``[..., d, d]``, ``F_ij = dx_i / dX_j``);
    the sum over ``b`` is ``F_a``."""
    return -volume_b[..., None, None] * dx[..., :, None] * corrected_grad_w0[..., None, :]
