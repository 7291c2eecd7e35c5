"""Fluid momentum equation (eq. 10) and the transport-velocity terms, per pair."""

from __future__ import annotations

import dataclasses

from sphjax.core.space import dot, scale


def pressure_coefficient(pressure, density):
    """``P = p / rho^2``, per particle: the pressure term of eq. 10 is a sum of two."""
    return pressure / density**2


def pressure_acceleration(pair, mass_b, coefficient_a, coefficient_b, pi_ab=0.0):
    """Eq. 10 without gravity and laminar viscosity, per pair:

    ``- m_b (p_a / rho_a^2 + p_b / rho_b^2 + Pi_ab) grad_a W_ab``, with the per-particle
    coefficients ``P = p / rho^2`` (:func:`pressure_coefficient`) as arguments, so that
    no pair divides.
    """
    term = coefficient_a + coefficient_b + pi_ab
    return scale(-(mass_b * term), pair.grad_w)


def pressure_acceleration_pullback(pair, mass_b, coefficient_a, coefficient_b, pi_ab, bar):
    """Reverse mode of :func:`pressure_acceleration` for the cotangent ``bar`` of its
    output ``-m_b T grad_a W``, ``T = P_a + P_b + Pi_ab``:

        bar(grad_a W) = -m_b T bar,     bar(T) = -m_b (bar . grad_a W),
        bar(m_b) = -T (bar . grad_a W),  bar(P_a) = bar(P_b) = bar(Pi_ab) = bar(T).

    Returns a dict of cotangents keyed by the arguments' names.
    """
    term = coefficient_a + coefficient_b + pi_ab
    along = dot(bar, pair.grad_w)
    term_bar = -mass_b * along
    return {
        "grad_w": scale(-(mass_b * term), bar),
        "mass_b": -term * along,
        "coefficient": term_bar,
    }


def transport_stress_acceleration(
    pair, mass_b, inverse_density_a, inverse_density_b, v_a, v_b, dv_a, dv_b
):
    """Transport-velocity momentum flux (Adami, Hu & Adams 2013), in the form of eq. 10:

    ``m_b (A_a / rho_a^2 + A_b / rho_b^2) . grad_a W_ab`` with ``A = rho v (v~ - v)^T``,
    i.e. ``A / rho^2 . grad W = v ((v~ - v) . grad W) / rho``; the reciprocal densities
    ``1 / rho`` are per-particle arguments.
    """
    flux_a = scale(dot(dv_a, pair.grad_w) * inverse_density_a, v_a)
    flux_b = scale(dot(dv_b, pair.grad_w) * inverse_density_b, v_b)
    return scale(mass_b, flux_a + flux_b)


def transport_stress_acceleration_pullback(
    pair, mass_b, inverse_density_a, inverse_density_b, v_a, v_b, dv_a, dv_b, bar
):
    """Reverse mode of :func:`transport_stress_acceleration` for the cotangent ``bar`` of
    ``m_b (v_a g_a i_a + v_b g_b i_b)``, ``g = (v~ - v) . grad_a W``, ``i = 1 / rho``:

        bar(v_a) = m_b g_a i_a bar,   bar(g_a) = m_b (bar . v_a) i_a,
        bar(i_a) = m_b (bar . v_a) g_a,   bar(dv_a) = bar(g_a) grad_a W,
        bar(grad_a W) = bar(g_a) dv_a + bar(g_b) dv_b,   bar(m_b) = bar . (v_a g_a i_a
        + v_b g_b i_b)   (``b`` likewise).
    """
    g_a = dot(dv_a, pair.grad_w)
    g_b = dot(dv_b, pair.grad_w)
    along_a = dot(bar, v_a)
    along_b = dot(bar, v_b)
    g_a_bar = mass_b * along_a * inverse_density_a
    g_b_bar = mass_b * along_b * inverse_density_b
    return {
        "grad_w": scale(g_a_bar, dv_a) + scale(g_b_bar, dv_b),
        "mass_b": along_a * g_a * inverse_density_a + along_b * g_b * inverse_density_b,
        "inverse_density_a": mass_b * along_a * g_a,
        "inverse_density_b": mass_b * along_b * g_b,
        "v_a": scale(mass_b * g_a * inverse_density_a, bar),
        "v_b": scale(mass_b * g_b * inverse_density_b, bar),
        "dv_a": scale(g_a_bar, pair.grad_w),
        "dv_b": scale(g_b_bar, pair.grad_w),
    }


@dataclasses.dataclass(frozen=True)
class TransportVelocity:
    """Advect fluid particles with the transport velocity of Adami, Hu & Adams (2013),
    ``v~ = v + dt/2 a_b``, where ``a_b`` is eq. 10's pressure term with a uniform
    background pressure; keeps the particle distribution regular (needed for
    Taylor-Green).

    The background pressure is evaluated from Params at every right-hand side,

        p_b = pressure_factor * rho0 c0^2 + Params.transport_pressure,

    so that it follows ``params.replace(sound_speed=...)`` (and ``jax.grad`` with respect
    to ``sound_speed`` or ``reference_density`` sees it).  The default ``pressure_factor=1``
    is Adami et al.'s ``p_b = rho0 c0^2``; ``pressure_factor=0`` makes ``p_b`` the
    parameter ``Params.transport_pressure`` alone.
    """

    pressure_factor: float = 1.0

    #: the Params fields ``p_b`` reads
    parameters = ("transport_pressure", "reference_density", "sound_speed")

    def __post_init__(self):
        try:
            factor = float(self.pressure_factor)
        except (TypeError, ValueError):
            factor = float("nan")
        if not (factor >= 0.0 and factor < float("inf")):
            raise ValueError(
                "TransportVelocity.pressure_factor must be a finite number >= 0 "
                f"(p_b = factor * rho0 c0^2 + transport_pressure), got {self.pressure_factor!r}"
            )
        object.__setattr__(self, "pressure_factor", factor)

    def background_pressure(self, fluid):
        """``p_b = pressure_factor * rho0 c0^2 + transport_pressure`` from ``Params.fluid``."""
        return (
            self.pressure_factor * fluid.reference_density * fluid.sound_speed**2
            + fluid.transport_pressure
        )
