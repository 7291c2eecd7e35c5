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


def monaghan_pi_pullback(pair, v_ab, density_a, density_b, sound_speed, h, alpha, beta, pi_bar):
    """Reverse mode of :func:`monaghan_pi` for the cotangent ``pi_bar`` of ``Pi_ab``
    (zero for receding pairs): with ``D = r^2 + 0.01 h^2`` and ``rho_ab`` the mean density,

        bar(mu) = bar(Pi) (-alpha c0 + 2 beta mu) / rho_ab,   bar(rho_ab) = -bar(Pi) Pi / rho_ab,
        bar(v_ab . r_ab) = bar(mu) h / D,   bar(D) = -bar(mu) mu / D,   bar(r) = 2 r bar(D),
        bar(alpha) = -bar(Pi) c0 mu / rho_ab,   bar(c0) = -bar(Pi) alpha mu / rho_ab,
        bar(beta) = bar(Pi) mu^2 / rho_ab.
    """
    vr = dot(v_ab, pair.dr)
    denominator = pair.r**2 + ETA2 * h**2
    mu = h * vr / denominator
    mean_density = 0.5 * (density_a + density_b)
    pi = (-alpha * sound_speed * mu + beta * mu**2) / mean_density
    pi_bar = jnp.where(vr < 0.0, pi_bar, 0.0) / mean_density
    mu_bar = pi_bar * (-alpha * sound_speed + 2.0 * beta * mu)
    vr_bar = mu_bar * h / denominator
    mean_density_bar = -pi_bar * pi
    return {
        "dr": scale(vr_bar, v_ab),
        "r": -2.0 * pair.r * mu_bar * mu / denominator,
        "v_ab": scale(vr_bar, pair.dr),
        "density_a": 0.5 * mean_density_bar,
        "density_b": 0.5 * mean_density_bar,
        "sound_speed": -pi_bar * alpha * mu,
        "alpha": -pi_bar * sound_speed * mu,
        "beta": pi_bar * mu**2,
    }


def morris_acceleration(pair, v_ab, mass_b, inverse_density_a, inverse_density_b, nu, h):
    """Morris et al. (1997) laminar viscosity per pair:

    ``m_b (mu_a + mu_b) / (rho_a rho_b) (r_ab . grad_a W_ab) / (r_ab^2 + 0.01 h^2) v_ab``
    with ``mu = rho nu``, i.e. ``m_b nu (1 / rho_a + 1 / rho_b) ...``; the reciprocal
    densities are per-particle arguments.
    """
    coefficient = mass_b * nu * (inverse_density_a + inverse_density_b)
    factor = coefficient * dot(pair.dr, pair.grad_w) / (pair.r**2 + ETA2 * h**2)
    return scale(factor, v_ab)


def morris_acceleration_pullback(
    pair, v_ab, mass_b, inverse_density_a, inverse_density_b, nu, h, bar
):
    """Reverse mode of :func:`morris_acceleration` for the cotangent ``bar`` of
    ``C (r_ab . grad_a W) / D v_ab``, ``C = m_b nu (1 / rho_a + 1 / rho_b)``,
    ``D = r^2 + 0.01 h^2``:

        bar(v_ab) = C q / D bar,   bar(q) = C (bar . v_ab) / D,   bar(r_ab) = bar(q) grad_a W,
        bar(grad_a W) = bar(q) r_ab,   bar(r) = -2 r C q (bar . v_ab) / D^2,
        bar(C) = q (bar . v_ab) / D   (then m_b, nu and the reciprocal densities through C).
    """
    inverse_densities = inverse_density_a + inverse_density_b
    coefficient = mass_b * nu * inverse_densities
    q = dot(pair.dr, pair.grad_w)
    inverse_denominator = 1.0 / (pair.r**2 + ETA2 * h**2)
    along = dot(bar, v_ab)
    coefficient_bar = q * along * inverse_denominator
    q_bar = coefficient * along * inverse_denominator
    return {
        "v_ab": scale(coefficient * q * inverse_denominator, bar),
        "dr": scale(q_bar, pair.grad_w),
        "grad_w": scale(q_bar, pair.dr),
        "r": -2.0 * pair.r * q_bar * q * inverse_denominator,
        "mass_b": coefficient_bar * nu * inverse_densities,
        "nu": coefficient_bar * mass_b * inverse_densities,
        "inverse_density": coefficient_bar * mass_b * nu,
    }


@dataclasses.dataclass(frozen=True)
class ArtificialViscosity:
    """Monaghan's artificial viscosity ``Pi_ab`` in eq. 10."""

    #: the Params fields ``Pi_ab`` reads
    parameters = ("artificial_alpha", "artificial_beta", "sound_speed")


@dataclasses.dataclass(frozen=True)
class MorrisViscosity:
    """Morris et al. (1997) laminar viscosity with ``Params.kinematic_viscosity``."""

    #: the Params field the laminar term reads
    parameters = ("kinematic_viscosity",)
