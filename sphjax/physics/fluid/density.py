"""Density by kernel summation (eq. 5) or by the continuity equation (eq. 11).

Per-pair terms (summed over neighbours by :func:`sphjax.physics.pairs.pair_sum`) and the
two formulation objects a :class:`~sphjax.FluidSystem` chooses between; each object owns
its part of the fluid's update stage (``density_and_rate``).
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp

from sphjax import native
from sphjax.core import kernels
from sphjax.core.space import dot, scale
from sphjax.physics import pairs as pair_sums


def summation_term(pair, mass_b):
    """Eq. 5 per pair: ``m_b W_ab`` (the self term ``m_a W(0)`` is added by the caller)."""
    return mass_b * pair.w


def continuity_term(pair, mass_b, velocity_a, velocity_b):
    """Eq. 11 per pair: ``m_b (v_a - v_b) . grad_a W_ab``."""
    return mass_b * dot(velocity_a - velocity_b, pair.grad_w)


def _kernel_summand(pair, a, b, shared):
    """``W_ab``; times the weight ``m_b`` it is eq. 5's pair term."""
    return summation_term(pair, 1.0)


def _kernel_pullback(pair, a, b, shared, bar):
    """Reverse mode of :func:`_kernel_summand`: ``W_ab`` gets the cotangent itself."""
    cot = pair_sums.Cotangents()
    cot.pair(w=bar)
    return cot.result(len(shared))


pair_sums.define_pullback(_kernel_summand, _kernel_pullback)
# measured on the CPU (docs/performance_gradients.md): alone, autodiff's transpose of this
# sum (9.6 ms) beats the custom adjoint in blocks (14.0 ms) at Taylor-Green 10k, but in a
# whole gradient the two cost the same (18.5 and 18.9 CPU-s), and without blocks
# (``Model.pair_block`` at least the particle count, as the Taylor-Green case sets) the
# custom adjoint fuses with the momentum sum's and the gradient costs 15.5 CPU-s


def _velocity_divergence_summand(pair, a, b, shared):
    """``(v_a - v_b) . grad_a W_ab``; times the weight ``m_b`` it is eq. 11's pair term."""
    return continuity_term(pair, 1.0, a["v"], b["v"])


def _velocity_divergence_pullback(pair, a, b, shared, bar):
    """Reverse mode of :func:`_velocity_divergence_summand`: with ``s = v_ab . grad W``,
    ``grad W`` gets ``bar v_ab``, ``v_a`` gets ``bar grad W`` and ``v_b`` its negative."""
    cot = pair_sums.Cotangents()
    flux = scale(bar, pair.grad_w)
    cot.pair(grad_w=scale(bar, a["v"] - b["v"]))
    cot.a(v=flux)
    cot.b(v=-flux)
    return cot.result(len(shared))


pair_sums.define_pullback(_velocity_divergence_summand, _velocity_divergence_pullback)


def _kernel_loop(keywords, geometry, weight, parity, cross, stored):
    """The compiled loop of :func:`_kernel_summand` weighted by the mass (eq. 5), within
    the fluid or against a boundary."""
    if weight != "m":
        return None
    return lambda rows, cols, idx, shared, stored: native.kernel_sum(rows, idx, geometry, cols)


def _velocity_divergence_loop(keywords, geometry, weight, parity, cross, stored):
    """The compiled loop of :func:`_velocity_divergence_summand` weighted by the mass
    (eq. 11), within the fluid or against a boundary."""
    if weight != "m":
        return None
    return lambda rows, cols, idx, shared, stored: native.velocity_divergence(
        rows, idx, geometry, cols
    )


pair_sums.define_native(_kernel_summand, _kernel_loop)
pair_sums.define_native(_velocity_divergence_summand, _velocity_divergence_loop)


def velocity_divergence(rows: dict, ctx):
    """Eq. 11 over the fluid's own pairs, ``sum_b m_b v_ab . grad_a W_ab``."""
    return ctx.pair_sum(
        _velocity_divergence_summand, rows, None, ctx.fluid_pairs, weight="m", parity=1
    )


def _boundary(fields):
    return {"x": fields["x"], "m": fields["m"], "v": fields["v"]}


@dataclasses.dataclass(frozen=True)
class SummationDensity:
    """``rho_a = sum_b m_b W_ab`` (eq. 5), the self term included; not integrated."""

    def density_and_rate(self, rows: dict, boundaries, ctx, diffusion=None, density_step=None):
        """``(rho, 0)``: eq. 5 over the fluid's own pairs and every boundary's
        (``boundaries``: ``(fields, pairs)`` with ``x, m, v``), the self term
        ``m_a W(0)`` included."""
        geometry = ctx.geometry
        own = ctx.pair_sum(_kernel_summand, rows, None, ctx.fluid_pairs, weight="m", parity=1)
        for cols, pairs in boundaries:
            own = own + ctx.pair_sum(_kernel_summand, rows, _boundary(cols), pairs, weight="m")
        self_weight = kernels.W(geometry.kernel, 0.0, geometry.smoothing_length, geometry.dim)
        return rows["m"] * self_weight + own, jnp.zeros_like(rows["rho"])


@dataclasses.dataclass(frozen=True)
class ContinuityDensity:
    """``Drho_a/Dt = sum_b m_b v_ab . grad_a W_ab`` (eq. 11), integrated in time."""

    def density_and_rate(self, rows: dict, boundaries, ctx, diffusion=None, density_step=None):
        """``(rho, Drho/Dt)``: eq. 11 over the fluid's own pairs (with ``diffusion``'s
        term, its ``continuity_rate``, if any) and every boundary's; ``rho`` advanced by
        ``density_step`` (the integrator's step) where given."""
        if diffusion is None:
            rate = velocity_divergence(rows, ctx)
        else:
            rate = diffusion.continuity_rate(rows, ctx)
        for cols, pairs in boundaries:
            rate = rate + ctx.pair_sum(
                _velocity_divergence_summand, rows, _boundary(cols), pairs, weight="m"
            )
        density = rows["rho"]
        if density_step is not None:
            density = density + density_step * rate
        return density, rate
