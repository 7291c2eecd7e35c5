"""Solid momentum equation (formulation eq. 14) composed from eqs. 15-19.

    Dv_a/Dt = sum_b m0_b (P_a L0_a / rho0_a^2 + P_b L0_b / rho0_b^2) grad0_a W(X_ab)
              + f_a^PF / m0_a + g

``m0 = rho0 V0`` with ``rho0 = params.solid_density`` and ``V0 = state.volume``, so
gradients with respect to the solid density flow.  This form is the variational
(energy-conserving) discretisation of the St Venant-Kirchhoff energy ``sum_a V0_a Psi(F_a)``:
pair forces are antisymmetric (linear momentum is conserved exactly) and the energy is
frame-indifferent (angular momentum is conserved by the symplectic kick-drift-kick step).

Rows are the ``M`` members (solid and clamped particles); neighbours come from the
reference configuration (``[M, K]`` global indices padded with ``N``, self excluded).
Clamped particles take part as neighbours with their own ``F``; the caller ignores their
accelerations.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from sphjax.neighbors import Pairs, pair_geometry
from sphjax.solid.correction import corrected_kernel_gradient, correction_matrix
from sphjax.solid.deformation import deformation_gradient
from sphjax.solid.material import (
    green_lagrange_strain,
    lame_constants,
    pk1_stress,
    st_venant_kirchhoff_stress,
)
from sphjax.solid.penalty import penalty_force
from sphjax.space import displacement_fn
from sphjax.state import Model, Params, State


class SolidFields(NamedTuple):
    """Per-member solid fields of one configuration (rows follow ``members``).

    Attributes:
      L0: ``[M, d, d]`` correction matrices (eq. 15).
      F: ``[M, d, d]`` deformation gradients (eq. 16).
      P: ``[M, d, d]`` first Piola-Kirchhoff stresses ``F S`` (eqs. 17-19).
      reference: reference-configuration :class:`~sphjax.neighbors.Pairs` (``[M, K]``).
      dx: ``[M, K, d]`` current pair vectors ``x_ab`` (0 on padding).
      neighbor_row: ``[M, K]`` member row of each neighbour (``M`` on padding).
    """

    L0: jax.Array
    F: jax.Array
    P: jax.Array
    reference: Pairs
    dx: jax.Array
    neighbor_row: jax.Array


def solid_fields(
    state: State, members: jax.Array, solid_idx: jax.Array, model: Model, params: Params
) -> SolidFields:
    """Correction matrix, deformation gradient and PK1 stress of every member."""
    displacement = displacement_fn(model.domain)
    X, x = state.reference_position, state.position
    n, m = X.shape[0], members.shape[0]
    reference = pair_geometry(X[members], X, solid_idx, displacement, model)
    mask = reference.mask
    volume_b = jnp.where(mask, state.volume[reference.j], 0.0)
    L0 = correction_matrix(reference.grad_w, reference.dr, volume_b)
    dx = displacement(x[members][:, None, :], x[reference.j])
    dx = jnp.where(mask[..., None], dx, 0.0)
    F = deformation_gradient(dx, corrected_kernel_gradient(L0, reference.grad_w), volume_b)
    lam, mu = lame_constants(params.young_modulus, params.poisson_ratio)
    P = pk1_stress(F, st_venant_kirchhoff_stress(green_lagrange_strain(F), lam, mu))
    row_of = jnp.full((n,), m, dtype=jnp.int32).at[members].set(jnp.arange(m, dtype=jnp.int32))
    neighbor_row = jnp.where(mask, row_of[reference.j], m)
    return SolidFields(L0=L0, F=F, P=P, reference=reference, dx=dx, neighbor_row=neighbor_row)


def _gather_rows(values: jax.Array, rows: jax.Array) -> jax.Array:
    """``values[rows]`` with row ``M`` (padding) reading zeros."""
    padded = jnp.concatenate([values, jnp.zeros_like(values[:1])], axis=0)
    return padded[rows]


def solid_acceleration(
    state: State, members: jax.Array, solid_idx: jax.Array, model: Model, params: Params
) -> jax.Array:
    """``Dv/Dt`` of the members (eq. 14), ``[M, d]``; gravity included.

    Args:
      state: the current State (``position``, ``reference_position``, ``volume``).
      members: ``[M]`` indices of solid and clamped particles.
      solid_idx: ``[M, K]`` reference neighbours, global indices padded with ``N``.
      model: ``solid_penalty`` switches the penalty force on.
      params: ``young_modulus``, ``poisson_ratio``, ``solid_density``, ``penalty_alpha``,
        ``gravity``.
    """
    fields = solid_fields(state, members, solid_idx, model, params)
    reference = fields.reference
    rho0 = params.solid_density
    mass_b = rho0 * jnp.where(reference.mask, state.volume[reference.j], 0.0)
    stress_a = jnp.einsum("mij,mjk->mik", fields.P, fields.L0) / rho0**2
    stress_b = _gather_rows(stress_a, fields.neighbor_row)
    pair = stress_a[:, None] + stress_b
    acceleration = jnp.einsum("mk,mkij,mkj->mi", mass_b, pair, reference.grad_w)
    if model.solid_penalty:
        volume_a = state.volume[members]
        force = penalty_force(
            fields.F,
            _gather_rows(fields.F, fields.neighbor_row),
            reference.dr,
            reference.r,
            reference.w,
            fields.dx,
            volume_a,
            jnp.where(reference.mask, state.volume[reference.j], 0.0),
            reference.mask,
            params.young_modulus,
            params.penalty_alpha,
        )
        acceleration = acceleration + force / (rho0 * volume_a)[:, None]
    return acceleration + params.gravity
