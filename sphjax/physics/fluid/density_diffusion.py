"""Density diffusion for the continuity equation (delta-SPH), per pair.

Molteni & Colagrossi (2009): ``D_a = delta h c0 sum_b 2 (rho_a - rho_b)
(r_ab . grad_a W_ab) / (r_ab^2 + 0.01 h^2) V_b`` added to ``Drho_a/Dt`` (eq. 11).  With
gravity the hydrostatic part of the density difference is removed first (Fourtakas et al.
2019), so that a fluid at rest stays at rest: ``rho^H_a - rho^H_b = rho0 g . r_ab / c0^2``.

Antuono, Colagrossi, Marrone & Molteni (2010), Comput. Phys. Commun. 181, 532-549, and
Antuono, Colagrossi & Marrone (2012), Comput. Phys. Commun. 183, 2570-2580 (eq. 4) subtract
the renormalised density gradients instead:

    D_a = delta h c0 sum_b psi_ab . grad_a W_ab V_b,
    psi_ab = 2 (rho_b - rho_a) r_ba / |r_ba|^2 - (<grad rho>_a + <grad rho>_b),
    <grad rho>_a = L_a sum_b (rho_b - rho_a) grad_a W_ab V_b,
    L_a = ( sum_b V_b grad_a W_ab r_ba^T )^-1,          r_ba = r_b - r_a,

so that any linear density field (the hydrostatic one in particular) gives ``D = 0`` pair
by pair, on irregular particle distributions and truncated supports too; no hydrostatic
correction is needed.  ``psi_ab = psi_ba`` and ``grad_a W_ab = -grad_b W_ba``, so
``sum_a V_a D_a = 0``: the diffusion moves mass between particles and conserves it.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax.numpy as jnp

from sphjax import native
from sphjax.core.space import dot
from sphjax.physics import pairs as pair_sums
from sphjax.physics.fluid.density import continuity_term
from sphjax.physics.fluid.viscosity import ETA2


def molteni_term(pair, density_a, density_b, volume_b, hydrostatic_drho, delta, h, sound_speed):
    """Density-diffusion rate per pair (sum over ``b`` gives ``D_a``)."""
    drho = density_a - density_b - hydrostatic_drho
    term = 2.0 * drho * dot(pair.dr, pair.grad_w) / (pair.r**2 + ETA2 * h**2) * volume_b
    return delta * h * sound_speed * term


def renormalisation_terms(pair, density_a, density_b):
    """Per pair, to be summed with the weight ``V_b``: ``grad_a W_ab r_ba^T`` (``[..., d,
    d]``, the matrix whose inverse is ``L_a``) and ``(rho_b - rho_a) grad_a W_ab``.
    Both are symmetric under ``a <-> b``."""
    r_ba = -pair.dr
    return {
        "matrix": pair.grad_w[..., :, None] * r_ba[..., None, :],
        "moment": (density_b - density_a)[..., None] * pair.grad_w,
    }


def renormalised_gradient(matrix, moment):
    """``<grad rho>_a = L_a sum_b (rho_b - rho_a) grad_a W_ab V_b`` (``[N, d]``) from the
    summed :func:`renormalisation_terms`.  A particle whose matrix is (nearly) singular,
    ``|det| < 0.01 max|entry|^d`` (fewer neighbours than dimensions, or all on one line: a
    splash), gets a zero gradient, i.e. Molteni & Colagrossi's term for its pairs."""
    dim = matrix.shape[-1]
    det = jnp.linalg.det(matrix)
    scale = jnp.max(jnp.abs(matrix), axis=(-2, -1)) ** dim
    invertible = jnp.abs(det) > 1e-2 * scale
    safe = jnp.where(invertible[:, None, None], matrix, jnp.eye(dim, dtype=matrix.dtype))
    gradient = jnp.linalg.solve(safe, moment[..., None])[..., 0]
    return jnp.where(invertible[:, None], gradient, 0.0)


def antuono_term(pair, density_a, density_b, gradient_a, gradient_b, volume_b, delta, h, c0):
    """Density-diffusion rate per pair of Antuono et al. (module docstring):
    ``delta h c0 psi_ab . grad_a W_ab V_b``.  No ``0.01 h^2`` in the denominator (it would
    spoil the exact cancellation of linear fields); coincident particles contribute 0."""
    r_ba = -pair.dr
    apart = pair.r > 0
    r2 = jnp.where(apart, pair.r**2, 1.0)
    psi = 2.0 * ((density_b - density_a) / r2)[..., None] * r_ba - (gradient_a + gradient_b)
    term = jnp.where(apart, dot(psi, pair.grad_w), 0.0) * volume_b
    return delta * h * c0 * term


class MolteniParameters(NamedTuple):
    """What every pair of :func:`_continuity_with_diffusion` sees, by name."""

    gravity: object
    reference_density: object
    sound_speed: object
    density_diffusion: object


class AntuonoParameters(NamedTuple):
    """What every pair of :func:`_continuity_with_antuono` sees, by name."""

    sound_speed: object
    density_diffusion: object


def _continuity_with_diffusion(pair, a, b, shared, *, h):
    """Eq. 11 plus Molteni & Colagrossi's diffusion per pair, hydrostatic part removed."""
    gravity, rho0 = shared.gravity, shared.reference_density
    c0, delta = shared.sound_speed, shared.density_diffusion
    rate = continuity_term(pair, b["m"], a["v"], b["v"])
    hydrostatic = rho0 * sum(gravity[i] * pair.dr[..., i] for i in range(pair.dr.shape[-1])) / c0**2
    volume_b = b["m"] / b["rho"]
    return rate + molteni_term(pair, a["rho"], b["rho"], volume_b, hydrostatic, delta, h, c0)


def _molteni_loop(keywords, geometry, weight, parity, cross, stored):
    """The compiled loop of :func:`_continuity_with_diffusion` (both roles of each pair;
    within one fluid only)."""
    if weight is not None or cross:
        return None

    def loop(rows, cols, idx, shared, stored):
        parameters = (
            shared.gravity,
            shared.reference_density,
            shared.sound_speed,
            shared.density_diffusion,
        )
        return native.continuity_molteni(rows, idx, geometry, parameters)

    return loop


pair_sums.define_native(_continuity_with_diffusion, _molteni_loop)


def _renormalisation_summand(pair, a, b, shared):
    """Per pair, times the weight ``V_b``: the sums of the renormalised density gradient
    (Antuono et al. 2010); symmetric under ``a <-> b``."""
    return renormalisation_terms(pair, a["rho"], b["rho"])


def _continuity_with_antuono(pair, a, b, shared, *, h):
    """Eq. 11 plus Antuono et al.'s diffusion per pair, with the renormalised density
    gradients ``a["grad_rho"]``, ``b["grad_rho"]`` of the update stage."""
    c0, delta = shared.sound_speed, shared.density_diffusion
    rate = continuity_term(pair, b["m"], a["v"], b["v"])
    volume_b = b["m"] / b["rho"]
    return rate + antuono_term(
        pair, a["rho"], b["rho"], a["grad_rho"], b["grad_rho"], volume_b, delta, h, c0
    )


def density_gradient(fluid: dict, ctx):
    """Renormalised density gradient ``<grad rho>_a`` over the fluid neighbours
    (Antuono et al. 2010), ``[n, d]``: one pair sum (the matrix and the moment of
    :func:`renormalisation_terms`), then a ``d x d`` solve per particle."""
    rows = {"x": fluid["x"], "rho": fluid["rho"], "V": fluid["m"] / fluid["rho"]}
    sums = ctx.pair_sum(_renormalisation_summand, rows, None, ctx.fluid_pairs, weight="V", parity=1)
    return renormalised_gradient(sums["matrix"], sums["moment"])


@dataclasses.dataclass(frozen=True)
class MolteniColagrossi:
    """Molteni & Colagrossi (2009) delta-SPH with the hydrostatic correction;
    coefficient ``Params.density_diffusion``."""

    #: the Params fields the diffusion term and its hydrostatic correction read
    parameters = ("density_diffusion", "sound_speed", "reference_density", "gravity")

    def continuity_rate(self, rows: dict, ctx):
        """Eq. 11 with this diffusion over the fluid's own pairs (``rows``: ``x, m, v,
        rho``)."""
        fluid = ctx.params.fluid
        summand = functools.partial(_continuity_with_diffusion, h=ctx.geometry.smoothing_length)
        shared = MolteniParameters(
            ctx.params.gravity, fluid.reference_density, fluid.sound_speed, fluid.density_diffusion
        )
        return ctx.pair_sum(summand, rows, None, ctx.fluid_pairs, shared)


@dataclasses.dataclass(frozen=True)
class Antuono:
    """Antuono et al. (2010, 2012) delta-SPH: Molteni & Colagrossi's term less the
    renormalised density gradients, computed in the fluid's update stage; coefficient
    ``Params.density_diffusion`` (0.1 in the papers)."""

    #: the Params fields the diffusion term reads
    parameters = ("density_diffusion", "sound_speed")

    def continuity_rate(self, rows: dict, ctx):
        """Eq. 11 with this diffusion over the fluid's own pairs, the renormalised
        density gradients (:func:`density_gradient`) computed first."""
        fluid = ctx.params.fluid
        summand = functools.partial(_continuity_with_antuono, h=ctx.geometry.smoothing_length)
        with_gradient = {**rows, "grad_rho": density_gradient(rows, ctx)}
        shared = AntuonoParameters(fluid.sound_speed, fluid.density_diffusion)
        return ctx.pair_sum(summand, with_gradient, None, ctx.fluid_pairs, shared)
