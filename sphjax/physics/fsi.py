"""Fluid-structure interaction: an elastic (TLSPH) solid in a weakly compressible fluid.

The solid's particles are moving boundary particles for the fluid (Adami, Hu & Adams
2012), as wall particles are, with the solid's own motion in place of the prescribed one:

    p_s = ( sum_f p_f W_sf + (g - a_s) . sum_f rho_f r_sf W_sf ) / sum_f W_sf
    rho_s^fluid = rho(p_s)                           (the fluid's inverse EOS, eq. 12)
    v_s^viscous = 2 v_s - sum_f v_f W_sf / sum_f W_sf  (no-slip)
    m_s^fluid = rho0_fluid V0_s                      ("hydrodynamic mass")

with ``a_s`` the solid particle's acceleration of the last evaluation and ``v_s`` its
velocity.  The fluid sees them in its density (eqs. 5, 11, with ``m_s^fluid`` and
``v_s``) and in its momentum equation (eq. 10 and the viscous terms), exactly as walls.

The fluid pushes back: every fluid-solid pair force acts equal and opposite on the solid
particle.  With ``g_fs`` the fluid's acceleration per unit boundary mass due to ``s``
(the summand of eq. 10 between ``f`` and ``s``),

    Dv_f/Dt += sum_s m_s^fluid g_fs,        Dv_s/Dt += -sum_f (m_f m_s^fluid / m_s) g_fs,

so ``m_f (m_s^fluid g_fs) + m_s (-(m_f m_s^fluid / m_s) g_fs) = 0`` pair by pair, and the
total momentum of fluid and solid is conserved to round-off.  The solid's side is the same
per-pair function with the roles swapped (:func:`reaction_summand`), so its adjoint comes
from :func:`sphjax.physics.pairs.pair_sum` like every other term's.

This module holds the update stage (:func:`update_solid_boundary`), the fluid's view of
the solid (:func:`fluid_view_of_solid`) and the reaction term; the two interaction
functions are ``fluid_solid`` and ``solid_fluid`` in :mod:`sphjax.physics.interactions`.
"""

from __future__ import annotations

import jax.numpy as jnp

from sphjax.physics.boundary.wall import extrapolation_summand, wall_pressure, wall_velocity


def hydrodynamic_mass(solid: dict, fluid_params):
    """``m_s^fluid = rho0_fluid V0_s``: the mass a solid particle has for the fluid."""
    return fluid_params.reference_density * solid["V"]


def fluid_view_of_solid(solid: dict, fluid_params) -> dict:
    """The solid as a boundary in the fluid's density sums: ``x``, ``m^fluid`` and ``v``."""
    return {"x": solid["x"], "m": hydrodynamic_mass(solid, fluid_params), "v": solid["v"]}


def update_solid_boundary(system, solid: dict, fluid_system, fluid: dict, pairs, ctx) -> dict:
    """Update stage of a solid next to a fluid: its boundary pressure, density and
    viscous velocity (Adami et al. 2012 with the solid's own acceleration and velocity).

    Args:
      system: the :class:`~sphjax.SolidSystem` (its ``boundary`` choices).
      solid: the solid's fields ``x, v, V, a`` (``a`` the last acceleration).
      fluid: the updated fluid fields ``x, v, p, rho``.
      pairs: the solid's current-configuration list against the fluid.
    Returns:
      ``solid`` with ``p`` (boundary pressure), ``rho_fluid`` (its density for the
      fluid), ``m_fluid`` (hydrodynamic mass) and ``v_viscous``.
    """
    cols = {"x": fluid["x"], "p": fluid["p"], "rho": fluid["rho"], "v": fluid["v"]}
    sums = ctx.pair_sum(extrapolation_summand, {"x": solid["x"]}, cols, pairs)
    acceleration = solid["a"] if system.boundary.acceleration else jnp.zeros_like(solid["x"])
    pressure = wall_pressure(sums, ctx.params.gravity, acceleration)
    fluid_params = ctx.params.fluid
    density = fluid_system.equation_of_state.density(pressure, fluid_params)
    no_slip = system.boundary.no_slip
    v_viscous = wall_velocity(sums, solid["v"]) if no_slip else solid["v"]
    return {
        **solid,
        "p": pressure,
        "rho_fluid": density,
        "m_fluid": hydrodynamic_mass(solid, fluid_params),
        "v_viscous": v_viscous,
    }


def solid_as_boundary_columns(solid: dict) -> dict:
    """The solid's fields the fluid's momentum summand reads as its neighbour ``b``."""
    return {
        "x": solid["x"],
        "m": solid["m_fluid"],
        "rho": solid["rho_fluid"],
        "p": solid["p"],
        "vv": solid["v_viscous"],
    }


def reaction_summand(pair, a, b, shared, *, fluid_term):
    """The solid's side of a fluid-solid pair, per unit fluid mass (``pair_sum``
    multiplies by ``m_f``): ``-(m_s^fluid / m_s) g_fs``, with ``g_fs = fluid_term`` evaluated
    with the roles swapped (the fluid particle ``b`` as its row, the solid ``a`` as its
    neighbour), so that it is the same number as the fluid's side, of opposite sign.

    ``a``: the solid's fields, :func:`solid_as_boundary_columns` and ``m_solid`` (its
    material mass ``rho0_s V0_s``); ``b``: the fluid's.
    """
    g_fs = fluid_term(pair.swapped(), b, a, shared)["a"]
    ratio = a["m"] / a["m_solid"]
    return {"a": -ratio[..., None] * g_fs}
