"""Generalised wall boundary of Adami, Hu & Adams (2012), per pair.

Each wall (dummy) particle ``w`` takes its pressure from its fluid neighbours ``f``:

    p_w = ( sum_f p_f W_wf + (g - a_w) . sum_f rho_f r_wf W_wf ) / sum_f W_wf

with ``r_wf = r_w - r_f``, and its density from the fluid's inverse equation of state
(eq. 12).  For the no-slip viscous term the wall velocity is extrapolated,
``v_w = 2 v_wall - sum_f v_f W_wf / sum_f W_wf``; with free slip the walls take no part in
the viscous terms.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp

from sphjax import native
from sphjax.core.space import covered, scale
from sphjax.physics import pairs as pair_sums


def extrapolation_terms(pair, pressure_f, density_f, velocity_f):
    """Per wall-fluid pair: ``W_wf``, ``p_f W_wf``, ``rho_f r_wf W_wf`` and ``v_f W_wf``."""
    return {
        "weight": pair.w,
        "pressure": pressure_f * pair.w,
        "rho_r": scale(density_f * pair.w, pair.dr),
        "velocity": scale(pair.w, velocity_f),
    }


def extrapolation_summand(pair, a, b, shared):
    """The pair summand of the Adami extrapolation onto a wall or solid boundary particle
    ``a`` from its fluid neighbour ``b`` (:func:`extrapolation_terms`)."""
    return extrapolation_terms(pair, b["p"], b["rho"], b["v"])


# measured: autodiff's transpose keeps the quotient's sums and costs less than half the
# custom adjoint's (benchmarks/pair_costs.py, docs/performance_gradients.md)
pair_sums.transpose_by_autodiff(extrapolation_summand)


def _extrapolation_loop(keywords, geometry, weight, parity, cross, stored):
    """The compiled loop of :func:`extrapolation_summand` (onto another system only)."""
    if weight is not None or not cross:
        return None

    def loop(rows, cols, idx, shared, stored):
        sums = native.extrapolation(rows, idx, geometry, cols)
        dim = rows["x"].shape[-1]
        return {
            "weight": sums[:, 0],
            "pressure": sums[:, 1],
            "rho_r": sums[:, 2 : 2 + dim],
            "velocity": sums[:, 2 + dim :],
        }

    return loop


pair_sums.define_native(extrapolation_summand, _extrapolation_loop)


def wall_pressure(sums, gravity, wall_acceleration):
    """Adami pressure ``p_w`` from the summed :func:`extrapolation_terms` (0 where a wall
    particle has no fluid neighbour, or only one at the very edge of the support: see
    :func:`sphjax.core.space.covered`)."""
    weight = sums["weight"]
    hydrostatic = jnp.sum((gravity - wall_acceleration) * sums["rho_r"], axis=-1)
    has_fluid = covered(weight)
    safe = jnp.where(has_fluid, weight, 1.0)
    return jnp.where(has_fluid, (sums["pressure"] + hydrostatic) / safe, 0.0)


def wall_velocity(sums, prescribed_velocity):
    """No-slip wall velocity ``2 v_wall - sum_f v_f W_wf / sum_f W_wf`` (the sum taken as 0
    where :func:`sphjax.core.space.covered` finds no fluid weight)."""
    weight = sums["weight"][:, None]
    has_fluid = covered(weight)
    smoothed = jnp.where(has_fluid, sums["velocity"] / jnp.where(has_fluid, weight, 1.0), 0.0)
    return 2.0 * prescribed_velocity - smoothed


@dataclasses.dataclass(frozen=True)
class AdamiBoundary:
    """Adami, Hu & Adams (2012) pressure extrapolation; ``no_slip`` walls take part in the
    viscous terms with the extrapolated velocity, free-slip ones do not."""

    no_slip: bool = True
