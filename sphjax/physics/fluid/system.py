"""The weakly compressible fluid system (WCSPH) and its update stage.

Governing equations (formulation eqs. 5, 10-12):

    rho_a = sum_b m_b W_ab                                   (summation, eq. 5), or
    Drho_a/Dt = sum_b m_b v_ab . grad_a W_ab [+ D_a]         (continuity, eq. 11; delta-SPH,
                                                             Molteni & Colagrossi 2009 or
                                                             Antuono et al. 2010)
    p_a = p(rho_a)                                           (equation of state, eq. 12)
    Dv_a/Dt = - sum_b m_b (p_a / rho_a^2 + p_b / rho_b^2 + Pi_ab) grad_a W_ab
              + viscous terms + g                            (eq. 10)

The sums run over fluid neighbours and over boundary particles (walls), whose pressure,
density and velocity the boundary system provides.  The momentum terms are interactions
(:mod:`sphjax.physics.interactions`); this module holds the system and its update stage
(density and pressure).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from sphjax.core.params import FLUID_DEFAULTS, fields_read, refusal
from sphjax.core.state import Kind
from sphjax.physics.fluid.density import (
    ContinuityDensity,
    SummationDensity,
)
from sphjax.physics.fluid.density_diffusion import (
    Antuono,
    MolteniColagrossi,
)
from sphjax.physics.fluid.eos import TaitEOS
from sphjax.physics.fluid.momentum import TransportVelocity
from sphjax.physics.fluid.viscosity import ArtificialViscosity, MorrisViscosity
from sphjax.physics.system import block_fields


@dataclasses.dataclass(frozen=True)
class FluidSystem:
    """A weakly compressible fluid (kind ``FLUID``); its parameters are ``Params.fluid``.

    Attributes:
      equation_of_state: :class:`~sphjax.TaitEOS` or :class:`~sphjax.LinearEOS`.
      density: :class:`~sphjax.SummationDensity` (eq. 5) or
        :class:`~sphjax.ContinuityDensity` (eq. 11).
      viscosity: the viscous terms of eq. 10, a tuple of
        :class:`~sphjax.ArtificialViscosity` and/or :class:`~sphjax.MorrisViscosity`.
      density_diffusion: ``None``, :class:`~sphjax.MolteniColagrossi` or
        :class:`~sphjax.Antuono` (with continuity density).
      transport_velocity: ``None`` or :class:`~sphjax.TransportVelocity`.
    """

    equation_of_state: object = TaitEOS()
    density: object = SummationDensity()
    viscosity: tuple = ()
    density_diffusion: object = None
    transport_velocity: object = None

    kinds = (Kind.FLUID,)
    current_configuration = True
    #: its place in the update stage: fluids first (walls and solids read its pressure)
    stage = 0
    #: the Params group it reads
    params_group = "fluid"

    #: its own pair sums have compiled loops (``Model.pair_loop="native"``)
    native_pair_sums = True

    def __post_init__(self):
        if not isinstance(self.density, SummationDensity | ContinuityDensity):
            raise ValueError(
                "FluidSystem.density must be SummationDensity() or ContinuityDensity(), "
                f"got {self.density!r}"
            )
        viscosity = self.viscosity if isinstance(self.viscosity, tuple) else (self.viscosity,)
        if not all(isinstance(v, ArtificialViscosity | MorrisViscosity) for v in viscosity):
            raise ValueError(
                "FluidSystem.viscosity must be a tuple of ArtificialViscosity() and/or "
                f"MorrisViscosity(), got {self.viscosity!r}"
            )
        object.__setattr__(self, "viscosity", viscosity)
        if self.density_diffusion is not None:
            if not isinstance(self.density_diffusion, MolteniColagrossi | Antuono):
                raise ValueError(
                    "FluidSystem.density_diffusion must be None, MolteniColagrossi() or "
                    "Antuono(), "
                    f"got {self.density_diffusion!r}"
                )
            if not isinstance(self.density, ContinuityDensity):
                raise ValueError("FluidSystem.density_diffusion needs ContinuityDensity()")
        if self.transport_velocity is not None and not isinstance(
            self.transport_velocity, TransportVelocity
        ):
            raise ValueError(
                "FluidSystem.transport_velocity must be None or TransportVelocity(), "
                f"got {self.transport_velocity!r}"
            )
        if not hasattr(self.equation_of_state, "pressure"):
            raise ValueError(
                "FluidSystem.equation_of_state must be an equation of state such as "
                f"TaitEOS(gamma=7.0) or LinearEOS(), got {self.equation_of_state!r}"
            )

    @property
    def artificial_viscosity(self) -> bool:
        return any(isinstance(v, ArtificialViscosity) for v in self.viscosity)

    @property
    def physical_viscosity(self) -> bool:
        return any(isinstance(v, MorrisViscosity) for v in self.viscosity)

    def parameters(self) -> frozenset[str]:
        """The Params fields this fluid reads: ``gravity`` (eq. 10) and those its choices
        read (equation of state, viscosities, density diffusion, transport velocity)."""
        choices = (
            self.equation_of_state,
            *self.viscosity,
            self.density_diffusion,
            self.transport_velocity,
        )
        return fields_read(choices, own=("gravity",), group="fluid")

    def unused_parameters(self) -> dict[str, str]:
        """``{field: refusal}`` for the fluid fields this fluid does not read, each refusal
        naming the choice that would read it."""
        terms = [
            name
            for name, on in (
                ("artificial", self.artificial_viscosity),
                ("Morris", self.physical_viscosity),
            )
            if on
        ]
        viscosity = f"{' and '.join(terms)} viscosity only" if terms else "no viscosity"
        artificial = (viscosity, "add ArtificialViscosity() to the fluid's viscosity")
        continuity = isinstance(self.density, ContinuityDensity)
        hints = {
            "artificial_alpha": artificial,
            "artificial_beta": artificial,
            "kinematic_viscosity": (viscosity, "add MorrisViscosity() to the fluid's viscosity"),
            "transport_pressure": (
                "no transport velocity",
                "give the fluid transport_velocity=TransportVelocity()",
            ),
            "density_diffusion": (
                "no density diffusion",
                "give the fluid "
                + ("" if continuity else "ContinuityDensity() and ")
                + "density_diffusion=MolteniColagrossi() or Antuono()",
            ),
        }
        read = self.parameters()
        generic = ("its choices do not read it", "choose one that does")
        return {
            name: refusal(name, "fluid", *hints.get(name, generic))
            for name in FLUID_DEFAULTS
            if name not in read
        }

    def replace(self, **changes) -> FluidSystem:
        return dataclasses.replace(self, **changes)

    # the system protocol (sphjax.physics.system)

    #: the kinds whose velocity the integrators' kicks change
    free_kinds = (Kind.FLUID,)

    def held_kinds(self) -> tuple:
        """Fluid particles all move."""
        return ()

    def prescribed_motion(self, time, state):
        """No prescribed motion."""
        return None

    def time_step_limits(self, v_max: float, params, model, cfl: float) -> list[float]:
        """``CFL h / (c0 + |v|max)`` (acoustic), ``0.125 h^2 / nu`` (viscous, with
        :class:`~sphjax.MorrisViscosity`) and ``0.25 sqrt(h / |g|)`` (body force)."""
        h = model.smoothing_length
        limits = [cfl * h / (float(params.sound_speed) + v_max)]
        nu = float(params.kinematic_viscosity) if self.physical_viscosity else 0.0
        if nu > 0:
            limits.append(0.125 * h**2 / nu)
        g = float(np.linalg.norm(np.asarray(params.gravity)))
        if g > 0:
            limits.append(0.25 * math.sqrt(h / g))
        return limits

    def view(self, state, block: slice, density_step=None) -> dict:
        """The fluid's fields ``x, v, m, rho``; with the transport velocity inside a step
        (``density_step``), ``dv``: the half kick of the background-pressure
        acceleration the drift just took."""
        view = block_fields(state, block)
        if self.transport_velocity is not None and density_step is not None:
            view["dv"] = 0.5 * density_step * state.shift_acceleration[block]
        return view

    def boundary_view(self, view: dict, params) -> dict | None:
        """A fluid is no boundary of another system's density sums."""
        return None

    def update(self, i: int, views: list, systems: tuple, pairs: dict, ctx, density_step=None):
        """Update stage: density and pressure (:func:`update_fluid`), the fluid's own pairs
        and those against every system that is a boundary to it (``boundary_view``)."""
        boundaries = []
        for j, other in enumerate(systems):
            if j == i or (i, j) not in pairs or views[j]["x"].shape[0] == 0:
                continue
            seen = other.boundary_view(views[j], ctx.params)
            if seen is not None:
                boundaries.append((seen, pairs[(i, j)]))
        fluid_ctx = dataclasses.replace(ctx, fluid_pairs=pairs[(i, i)])
        return update_fluid(self, views[i], boundaries, fluid_ctx, density_step)

    def body_acceleration(self, view: dict, acceleration, params):
        """The interactions' acceleration plus gravity (eq. 10)."""
        return acceleration + params.gravity


def update_fluid(system: FluidSystem, fluid: dict, boundaries, ctx, density_step=None):
    """Update stage of a fluid: density (eq. 5 or 11 with delta-SPH) and pressure (eq. 12).

    Args:
      fluid: the fluid's fields ``x, v, m, rho`` (``[n, ...]``).
      boundaries: ``(fields, pairs)`` of each boundary system the fluid sees, ``fields``
        with ``x, v, m``, ``pairs`` the fluid's list against it.
      ctx: :class:`sphjax.physics.rhs.Context` (fluid-fluid pairs, geometry, params).
      density_step: with continuity density, advance the density by this step first.
    Returns:
      ``fluid`` with ``rho``, ``p`` and ``drho`` (the density rate, 0 for summation).
    """
    rows = {"x": fluid["x"], "m": fluid["m"], "v": fluid["v"], "rho": fluid["rho"]}
    density, rate = system.density.density_and_rate(
        rows, boundaries, ctx, system.density_diffusion, density_step
    )
    pressure = system.equation_of_state.pressure(density, ctx.params.fluid)
    return {**fluid, "rho": density, "p": pressure, "drho": rate}
