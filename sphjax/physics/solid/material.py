"""St Venant-Kirchhoff material: formulation eqs. 17-19 and the PK1 stress.

    E = 1/2 (F^T F - I)                                   Green-Lagrange strain (eq. 17)
    S = lambda tr(E) I + 2 mu E                           2nd Piola-Kirchhoff  (eq. 18)
    mu = E / (2 (1 + nu)),  lambda = E nu / ((1 + nu)(1 - 2 nu))   Lamé (eq. 19)
    P = F S                                               1st Piola-Kirchhoff

In 2D these (three-dimensional) Lamé constants give plane strain.  The material is
frame-indifferent: a rigid rotation ``F = R`` gives ``E = 0`` and ``P = 0``.
Plane stress in 2D is the same law with the (E', nu') of :func:`plane_stress_equivalent`.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp


def lame_constants(young_modulus, poisson_ratio):
    """Lamé constants ``(lambda, mu)`` from ``E`` and ``nu`` (eq. 19)."""
    mu = young_modulus / (2.0 * (1.0 + poisson_ratio))
    lam = young_modulus * poisson_ratio / ((1.0 + poisson_ratio) * (1.0 - 2.0 * poisson_ratio))
    return lam, mu


def plane_stress_equivalent(young_modulus, poisson_ratio):
    """``(E', nu')`` whose plane-strain Lamé constants (eq. 19) are the plane-stress ones of
    ``(E, nu)``: ``mu`` unchanged and ``lambda* = E nu / (1 - nu^2)``, so that a 2D solid
    given ``E'`` and ``nu'`` is a thin sheet of ``(E, nu)`` free to contract through its
    thickness:

        E' = E (1 + 2 nu) / (1 + nu)^2,        nu' = nu / (1 + nu)

    A plate in 2D bends with ``E / (1 - nu^2)`` in plane strain and ``E`` in plane stress.
    """
    scaled = young_modulus * (1.0 + 2.0 * poisson_ratio) / (1.0 + poisson_ratio) ** 2
    return scaled, poisson_ratio / (1.0 + poisson_ratio)


def green_lagrange_strain(F: jax.Array) -> jax.Array:
    """``E = 1/2 (F^T F - I)`` (eq. 17) for ``[..., d, d]`` deformation gradients."""
    eye = jnp.eye(F.shape[-1], dtype=F.dtype)
    return 0.5 * (jnp.einsum("...ki,...kj->...ij", F, F) - eye)


def st_venant_kirchhoff_stress(strain: jax.Array, lam, mu) -> jax.Array:
    """Second Piola-Kirchhoff stress ``S = lambda tr(E) I + 2 mu E`` (eq. 18)."""
    eye = jnp.eye(strain.shape[-1], dtype=strain.dtype)
    trace = jnp.trace(strain, axis1=-2, axis2=-1)[..., None, None]
    return lam * trace * eye + 2.0 * mu * strain


def st_venant_kirchhoff_energy(strain: jax.Array, lam, mu) -> jax.Array:
    """Strain energy density ``psi = lambda / 2 tr(E)^2 + mu E : E`` per reference volume,
    whose derivative ``d psi / d E`` is the stress ``S`` of eq. 18."""
    trace = jnp.trace(strain, axis1=-2, axis2=-1)
    return 0.5 * lam * trace**2 + mu * jnp.sum(strain * strain, axis=(-2, -1))


def pk1_stress(F: jax.Array, S: jax.Array) -> jax.Array:
    """First Piola-Kirchhoff stress ``P = F S``."""
    return jnp.einsum("...ik,...kj->...ij", F, S)


@dataclasses.dataclass(frozen=True)
class StVenantKirchhoff:
    """St Venant-Kirchhoff material (eqs. 17-19) with ``young_modulus`` and
    ``poisson_ratio``; plane strain in 2D."""

    #: the Params fields the Lamé constants (eq. 19) read
    parameters = ("young_modulus", "poisson_ratio")

    def pk1(self, F, solid):
        """First Piola-Kirchhoff stress ``P = F S(E(F))``."""
        lam, mu = lame_constants(solid.young_modulus, solid.poisson_ratio)
        return pk1_stress(F, st_venant_kirchhoff_stress(green_lagrange_strain(F), lam, mu))
