"""Viscous terms of the momentum equation (eq. 10), per pair.

* :class:`ArtificialViscosity` — Monaghan's ``Pi_ab`` (Monaghan 1992), active only for
  approaching pairs ``v_ab . r_ab < 0``; its effective kinematic viscosity is
  ``alpha h c0 / (2 (d + 2))``.  Parameters ``artificial_alpha``, ``artificial_beta``.
* :class:`MorrisViscosity` — a physical laminar viscosity after Morris, Fox & Zhu (1997)
  with kinematic viscosity ``kinematic_viscosity`` (dynamic ``mu = rho nu``).
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp

from sphjax.core.space import dot, scale

ETA2 = 0.01  # regularisation eta^2 = 0.01 h^2 in the pair denominators


def monaghan_pi(pair, v_ab, density_a, density_b, sound_speed, h, alpha, beta):
    """``Pi_ab = (-alpha c0 mu_ab + beta mu_ab^2) / rho_ab`` for ``v_ab . r_ab < 0``, else 0.

    ``mu_ab = h v_ab . r_ab / (r_ab^2 + 0.01 h^2)``, ``rho_ab = (rho_a + rho_b) / 2``.
    """
    vr = dot(v_ab, pair.dr)
    mu = h * vr / (pair.r**2 + ETA2 * h**2)
    mean_density = 0.5 * (density_a + density_b)
    pi = (-alpha * sound_speed * mu + beta * mu**2) / mean_density
    return jnp.where(vr < 0.0, pi, 0.0)


def morris_acceleration(pair, v_ab, mass_b, density_a, density_b, nu, h):
    """Morris et al. (1997) laminar viscosity per pair:

    ``m_b (mu_a + mu_b) / (rho_a rho_b) (r_ab . grad_a W_ab) / (r_ab^2 + 0.01 h^2) v_ab``
    with ``mu = rho nu``.
    """
    coefficient = mass_b * nu * (density_a + density_b) / (density_a * density_b)
    factor = coefficient * dot(pair.dr, pair.grad_w) / (pair.r**2 + ETA2 * h**2)
    return scale(factor, v_ab)


@dataclasses.dataclass(frozen=True)
class ArtificialViscosity:
    """Monaghan's artificial viscosity ``Pi_ab`` in eq. 10."""


@dataclasses.dataclass(frozen=True)
class MorrisViscosity:
    """Morris et al. (1997) laminar viscosity with ``Params.kinematic_viscosity``."""
