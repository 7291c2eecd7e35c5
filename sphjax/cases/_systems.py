"""Systems from the case factories' plain arguments (strings and flags), and the Case
they end with."""

from __future__ import annotations

from sphjax.core.case import Case
from sphjax.integration.timestep import stable_time_step
from sphjax.physics.boundary.system import WallSystem
from sphjax.physics.boundary.wall import AdamiBoundary
from sphjax.physics.fluid.density import ContinuityDensity, SummationDensity
from sphjax.physics.fluid.density_diffusion import Antuono, MolteniColagrossi
from sphjax.physics.fluid.eos import TaitEOS
from sphjax.physics.fluid.momentum import TransportVelocity
from sphjax.physics.fluid.system import FluidSystem
from sphjax.physics.fluid.viscosity import ArtificialViscosity, MorrisViscosity

DENSITIES = {"summation": SummationDensity(), "continuity": ContinuityDensity()}
DIFFUSIONS = {None: None, "molteni": MolteniColagrossi(), "antuono": Antuono()}
SLIPS = ("no_slip", "free_slip")


def fluid_system(
    *,
    density: str = "summation",
    gamma: float = 7.0,
    artificial_viscosity: bool = False,
    physical_viscosity: bool = False,
    density_diffusion: str | None = None,
    transport_velocity: bool = False,
    transport_pressure_factor: float = 1.0,
) -> FluidSystem:
    """A :class:`FluidSystem` from a case's arguments (``density`` is ``"summation"`` or
    ``"continuity"``, ``density_diffusion`` ``None``, ``"molteni"`` or ``"antuono"``)."""
    if density not in DENSITIES:
        raise ValueError(f"density must be 'summation' or 'continuity', got {density!r}")
    if density_diffusion not in DIFFUSIONS:
        raise ValueError(
            f"density_diffusion must be None, 'molteni' or 'antuono', got {density_diffusion!r}"
        )
    viscosity = (ArtificialViscosity(),) * bool(artificial_viscosity) + (MorrisViscosity(),) * bool(
        physical_viscosity
    )
    return FluidSystem(
        equation_of_state=TaitEOS(gamma=float(gamma)),
        density=DENSITIES[density],
        viscosity=viscosity,
        density_diffusion=DIFFUSIONS[density_diffusion],
        transport_velocity=(
            TransportVelocity(pressure_factor=transport_pressure_factor)
            if transport_velocity
            else None
        ),
    )


def wall_system(wall_slip: str = "no_slip") -> WallSystem:
    """A :class:`WallSystem` with Adami walls, ``"no_slip"`` or ``"free_slip"``."""
    if wall_slip not in SLIPS:
        raise ValueError(f"wall_slip must be 'no_slip' or 'free_slip', got {wall_slip!r}")
    return WallSystem(AdamiBoundary(no_slip=wall_slip == "no_slip"))


def finish_case(name, state, model, params, t_end, info, dt=None, initial_state=None) -> Case:
    """The factories' Case, with the stable time step unless ``dt`` is given."""
    dt = stable_time_step(state, model, params) if dt is None else dt
    return Case(
        name=name,
        state=state,
        model=model,
        params=params,
        dt=dt,
        t_end=t_end,
        info=info,
        initial_state=initial_state,
    )
