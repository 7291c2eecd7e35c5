"""The wall system (boundary dummy particles, Adami, Hu & Adams 2012) and its update stage.

Wall particles never move (the integrators keep their positions); their state velocity
is the prescribed velocity of the wall's surface, ``v_wall`` below, so a wall may slide
along itself (the lid of a driven cavity, a conveyor belt) while its particles stay put.
In the update stage each takes its pressure from the fluid around it,

    p_w = ( sum_f p_f W_wf + (g - a_w) . sum_f rho_f r_wf W_wf ) / sum_f W_wf,

its density from the fluid's inverse equation of state, and, for no-slip walls, the
velocity ``v_w = 2 v_wall - sum_f v_f W_wf / sum_f W_wf`` the viscous terms see.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp

from sphjax.core.state import Kind
from sphjax.physics.boundary.wall import (
    AdamiBoundary,
    extrapolation_summand,
    wall_pressure,
    wall_velocity,
)
from sphjax.physics.fluid.system import FluidSystem
from sphjax.physics.system import block_fields


@dataclasses.dataclass(frozen=True)
class WallSystem:
    """Boundary particles (kind ``WALL``) with a boundary model.

    Attributes:
      boundary: :class:`~sphjax.AdamiBoundary` (``no_slip=True`` or ``False``).
    """

    boundary: AdamiBoundary = AdamiBoundary()

    kinds = (Kind.WALL,)
    current_configuration = True
    #: its place in the update stage: after the fluid whose pressure it extrapolates
    stage = 1
    #: the Params group it reads (the fluid's equation of state and gravity)
    params_group = "fluid"

    def __post_init__(self):
        if not isinstance(self.boundary, AdamiBoundary):
            raise ValueError(
                f"WallSystem.boundary must be AdamiBoundary(...), got {self.boundary!r}"
            )

    def parameters(self) -> frozenset[str]:
        """The Params fields the walls read: ``gravity`` (the wall pressure); the fluid's
        equation of state they use is the fluid's, counted there."""
        return frozenset({"gravity"})

    def unused_parameters(self) -> dict[str, str]:
        """No Params group of its own, so nothing to refuse."""
        return {}

    def replace(self, **changes) -> WallSystem:
        return dataclasses.replace(self, **changes)

    # the system protocol (sphjax.physics.system)

    #: the kinds whose velocity the integrators' kicks change: none (a wall's velocity
    #: is its surface velocity)
    free_kinds = ()

    def held_kinds(self) -> tuple:
        """Wall particles never move."""
        return (Kind.WALL,)

    def prescribed_motion(self, time, state):
        """No prescribed motion (a sliding wall slides along itself)."""
        return None

    def time_step_limits(self, v_max: float, params, model, cfl: float) -> list[float]:
        """Walls set no limit of their own."""
        return []

    def view(self, state, block: slice, density_step=None) -> dict:
        """The walls' fields ``x, v, m, rho`` (``v``: the surface velocity)."""
        return block_fields(state, block)

    def boundary_view(self, view: dict, params) -> dict:
        """Walls are a boundary to a fluid with their own ``x, m, v``."""
        return view

    def update(self, i: int, views: list, systems: tuple, pairs: dict, ctx, density_step=None):
        """Update stage: pressure, density and viscous velocity extrapolated from each
        fluid it has a list against (:func:`update_wall`)."""
        view = views[i]
        for j, fluid in enumerate(systems):
            if (i, j) in pairs and isinstance(fluid, FluidSystem):
                view = update_wall(self, view, fluid, views[j], pairs[(i, j)], ctx)
        return view

    def body_acceleration(self, view: dict, acceleration, params):
        """Walls do not move: no gravity."""
        return acceleration


def update_wall(system: WallSystem, wall: dict, fluid_system, fluid: dict, pairs, ctx):
    """Update stage of a wall: pressure, density and viscous velocity from the fluid.

    Args:
      wall: the wall's fields ``x, v``; fluid: the updated fluid fields ``x, v, p, rho``.
      pairs: the wall's list against the fluid.
    Returns:
      ``wall`` with ``p``, ``rho`` and ``v_viscous``.
    """
    cols = {"x": fluid["x"], "p": fluid["p"], "rho": fluid["rho"], "v": fluid["v"]}
    sums = ctx.pair_sum(extrapolation_summand, {"x": wall["x"]}, cols, pairs)
    pressure = wall_pressure(sums, ctx.params.gravity, jnp.zeros_like(wall["x"]))
    density = fluid_system.equation_of_state.density(pressure, ctx.params.fluid)
    v_viscous = wall_velocity(sums, wall["v"]) if system.boundary.no_slip else wall["v"]
    return {**wall, "p": pressure, "rho": density, "v_viscous": v_viscous}
