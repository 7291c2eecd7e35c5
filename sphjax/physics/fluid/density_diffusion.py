"""Density diffusion for the continuity equation (delta-SPH), per pair.

Molteni & Colagrossi (2009): ``D_a = delta h c0 sum_b 2 (rho_a - rho_b)
(r_ab . grad_a W_ab) / (r_ab^2 + 0.01 h^2) V_b`` added to ``Drho_a/Dt`` (eq. 11).  With
gravity the hydrostatic part of the density difference is removed first (Fourtakas et al.
2019), so that a fluid at rest stays at rest: ``rho^H_a - rho^H_b = rho0 g . r_ab / c0^2``.
"""

from __future__ import annotations

import dataclasses

from sphjax.core.space import dot
from sphjax.physics.fluid.viscosity import ETA2


def molteni_term(pair, density_a, density_b, volume_b, hydrostatic_drho, delta, h, sound_speed):
    """Density-diffusion rate per pair (sum over ``b`` gives ``D_a``)."""
    drho = density_a - density_b - hydrostatic_drho
    term = 2.0 * drho * dot(pair.dr, pair.grad_w) / (pair.r**2 + ETA2 * h**2) * volume_b
    return delta * h * sound_speed * term


@dataclasses.dataclass(frozen=True)
class MolteniColagrossi:
    """Molteni & Colagrossi (2009) delta-SPH with the hydrostatic correction;
    coefficient ``Params.density_diffusion``."""
