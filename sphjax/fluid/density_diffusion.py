"""Density diffusion for the continuity equation (delta-SPH).

Molteni & Colagrossi (2009): ``D_a = delta h c0 sum_b 2 (rho_a - rho_b)
(r_ab . grad_a W_ab) / (r_ab^2 + 0.01 h^2) V_b`` added to ``Drho_a/Dt`` (eq. 11).  With
gravity the hydrostatic part of the density difference is removed first (Fourtakas et al.
2019), so that a fluid at rest stays at rest.
"""

from __future__ import annotations

import jax.numpy as jnp

from sphjax.fluid.viscosity import ETA2


def molteni_density_diffusion(density, volume_b, pairs, hydrostatic_drho, delta, h, sound_speed):
    """Density-diffusion rate ``D_a`` per particle.

    Args:
      density: ``[N]`` densities.
      volume_b: ``[N, K]`` neighbour volumes ``m_b / rho_b``.
      pairs: fluid-fluid pairs.
      hydrostatic_drho: ``[N, K]`` hydrostatic density difference ``rho^H_a - rho^H_b``
        (zero without gravity).
    """
    drho = density[:, None] - density[pairs.j] - hydrostatic_drho
    rdotgrad = jnp.sum(pairs.dr * pairs.grad_w, axis=-1)
    term = 2.0 * drho * rdotgrad / (pairs.r**2 + ETA2 * h**2) * volume_b
    return delta * h * sound_speed * jnp.sum(jnp.where(pairs.mask, term, 0.0), axis=1)
