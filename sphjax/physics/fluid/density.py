"""Density by kernel summation (eq. 5) or by the continuity equation (eq. 11).

Per-pair terms (summed over neighbours by :func:`sphjax.physics.pairs.pair_sum`) and the
two formulation objects a :class:`~sphjax.FluidSystem` chooses between.
"""

from __future__ import annotations

import dataclasses

from sphjax.core.space import dot


def summation_term(pair, mass_b):
    """Eq. 5 per pair: ``m_b W_ab`` (the self term ``m_a W(0)`` is added by the caller)."""
    return mass_b * pair.w


def continuity_term(pair, mass_b, velocity_a, velocity_b):
    """Eq. 11 per pair: ``m_b (v_a - v_b) . grad_a W_ab``."""
    return mass_b * dot(velocity_a - velocity_b, pair.grad_w)


@dataclasses.dataclass(frozen=True)
class SummationDensity:
    """``rho_a = sum_b m_b W_ab`` (eq. 5), the self term included; not integrated."""


@dataclasses.dataclass(frozen=True)
class ContinuityDensity:
    """``Drho_a/Dt = sum_b m_b v_ab . grad_a W_ab`` (eq. 11), integrated in time."""
