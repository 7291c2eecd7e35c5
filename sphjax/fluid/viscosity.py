"""Viscous terms of the momentum equation (eq. 10).

* Monaghan's artificial viscosity ``Pi_ab`` (Monaghan 1992), active only for
  approaching pairs ``v_ab . r_ab < 0``; its effective kinematic viscosity is
  ``alpha h c0 / (2 (d + 2))``.
* A physical laminar viscosity after Morris, Fox & Zhu (1997) with kinematic viscosity
  ``nu`` (dynamic ``mu = rho nu``).
"""

from __future__ import annotations

import jax.numpy as jnp

ETA2 = 0.01  # regularisation eta^2 = 0.01 h^2 in the pair denominators


def monaghan_pi(v_ab, pairs, density_a, density_b, sound_speed, h, alpha, beta):
    """``Pi_ab = (-alpha c0 mu_ab + beta mu_ab^2) / rho_ab`` for ``v_ab . r_ab < 0``, else 0.

    ``mu_ab = h v_ab . r_ab / (r_ab^2 + 0.01 h^2)``, ``rho_ab = (rho_a + rho_b) / 2``.
    """
    vr = jnp.sum(v_ab * pairs.dr, axis=-1)
    mu = h * vr / (pairs.r**2 + ETA2 * h**2)
    mean_density = 0.5 * (density_a + density_b)
    pi = (-alpha * sound_speed * mu + beta * mu**2) / mean_density
    return jnp.where(vr < 0.0, pi, 0.0)


def morris_acceleration(v_ab, pairs, mass_b, density_a, density_b, nu, h):
    """Morris et al. (1997) laminar viscosity, per pair (sum over b outside).

    ``m_b (mu_a + mu_b) / (rho_a rho_b) (r_ab . grad_a W_ab) / (r_ab^2 + 0.01 h^2) v_ab``
    with ``mu = rho nu``.
    """
    rdotgrad = jnp.sum(pairs.dr * pairs.grad_w, axis=-1)
    coefficient = mass_b * nu * (density_a + density_b) / (density_a * density_b)
    factor = coefficient * rdotgrad / (pairs.r**2 + ETA2 * h**2)
    return factor[..., None] * v_ab
