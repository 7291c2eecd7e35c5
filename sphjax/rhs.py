"""The right-hand side: compose the physics for the particle kinds a Model contains.

``evaluate(state, neighbors, model, params)`` returns the State with ``acceleration``
(``Dv/Dt``), ``density_rate`` (``Drho/Dt``), ``pressure`` and, for summation density,
``density`` filled in.  It is pure: arrays and neighbour indices in, arrays out.  Kinds
absent from ``model.particle_kinds`` are not traced at all.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from sphjax import kernels
from sphjax.boundary.wall import wall_pressure, wall_velocity
from sphjax.fluid import adjoint as hand_adjoint
from sphjax.fluid.density import continuity_density_rate, summation_density
from sphjax.fluid.density_diffusion import molteni_density_diffusion
from sphjax.fluid.eos import tait_density, tait_pressure
from sphjax.fluid.momentum import pressure_acceleration, transport_stress_acceleration
from sphjax.fluid.viscosity import monaghan_pi, morris_acceleration
from sphjax.neighbors import pair_geometry
from sphjax.space import displacement_fn
from sphjax.state import Kind, Model, Params, State


@dataclasses.dataclass(frozen=True)
class Neighbors:
    """Neighbour data of one simulation.

    Attributes:
      fluid: jax-md dense neighbour list over all particles (current configuration), or
        ``None`` when the model has no fluid.
      solid_members: ``[M]`` indices of solid and clamped particles, or ``None``.
      solid_idx: ``[M, K]`` their reference-configuration neighbours (global indices,
        padded with ``N``), or ``None``.
    """

    fluid: object = None
    solid_members: jax.Array | None = None
    solid_idx: jax.Array | None = None


jax.tree_util.register_dataclass(
    Neighbors, data_fields=["fluid", "solid_members", "solid_idx"], meta_fields=[]
)


def has_kind(model: Model, kind: Kind) -> bool:
    return int(kind) in tuple(int(k) for k in model.particle_kinds)


def evaluate(
    state: State, neighbors: Neighbors, model: Model, params: Params, density_step=None
) -> State:
    """Rates of change of ``state`` (eqs. 5, 10-12 for fluids; 14-19 for solids).

    ``density_step``: with continuity density (eq. 11), first advance the density by
    ``density_step * Drho/Dt`` evaluated at the given positions and velocities, then
    compute pressure and accelerations from the new density.  The integrator passes
    ``dt`` here, which staggers density and velocity in time (density at whole steps,
    velocity at half steps), the stable leapfrog for the acoustic system.  ``None``
    evaluates the plain rates (the ODE right-hand side).
    """
    acceleration = jnp.zeros_like(state.position)
    density_rate = jnp.zeros_like(state.density)
    density, pressure = state.density, state.pressure
    shift_acceleration = state.shift_acceleration
    if has_kind(model, Kind.FLUID):
        fluid = fluid_rates(state, neighbors.fluid.idx, model, params, density_step)
        acceleration, density_rate, density, pressure, shift_acceleration = fluid
    if has_kind(model, Kind.SOLID):
        from sphjax.solid.rhs import solid_acceleration

        members = neighbors.solid_members
        solid_acc = solid_acceleration(state, members, neighbors.solid_idx, model, params)
        is_solid = (state.kind[members] == Kind.SOLID)[:, None]
        acceleration = acceleration.at[members].set(jnp.where(is_solid, solid_acc, 0.0))
    return state.replace(
        acceleration=acceleration,
        density_rate=density_rate,
        density=density,
        pressure=pressure,
        shift_acceleration=shift_acceleration,
    )


def fluid_rates(state: State, idx, model: Model, params: Params, density_step=None):
    """Fluid (and wall) rates.

    Returns ``(acceleration, density_rate, density, pressure, shift_acceleration)``.

    Rows of non-fluid particles are zero in ``acceleration`` and ``density_rate``; wall
    rows of ``density`` and ``pressure`` hold the Adami extrapolation.  Models that
    :func:`sphjax.fluid.adjoint.supports` go through :func:`sphjax.fluid.adjoint.fluid_rates`
    (the same terms with a hand-derived adjoint) unless ``model.pair_adjoint`` is off.
    """
    if model.pair_adjoint and hand_adjoint.supports(model):
        delta_v = None
        if model.transport_velocity and density_step is not None:
            delta_v = 0.5 * density_step * state.shift_acceleration
        acceleration, shift, density, pressure = hand_adjoint.fluid_rates(
            state.position, state.velocity, state.mass, delta_v, params, idx, model
        )
        acceleration = acceleration + params.gravity
        return acceleration, jnp.zeros_like(density), density, pressure, shift
    h, dim = model.smoothing_length, model.dim
    displacement = displacement_fn(model.domain)
    pairs = pair_geometry(state.position, state.position, idx, displacement, model)
    kind = state.kind
    is_fluid = kind == Kind.FLUID
    is_wall = kind == Kind.WALL
    with_walls = has_kind(model, Kind.WALL)
    # a fluid-only model needs no per-pair kind lookup
    fluid_nb = is_fluid[pairs.j] if len(model.particle_kinds) > 1 else True
    pairs_fluid = pairs.restrict(fluid_nb)
    pairs_hydro = pairs.restrict(fluid_nb | is_wall[pairs.j]) if with_walls else pairs_fluid

    rho0, c0, gamma = params.reference_density, params.sound_speed, model.gamma
    p0, p_bg = params.reference_pressure, params.background_pressure
    mass = state.mass
    density = state.density
    velocity = state.velocity
    density_rate = jnp.zeros_like(density)
    if model.density == "summation":
        self_weight = kernels.W(model.kernel, 0.0, h, dim)
        density = jnp.where(is_fluid, summation_density(mass, pairs_hydro, self_weight), density)
    else:
        density_rate = continuity_density_rate(mass, velocity, pairs_hydro)
        if model.density_diffusion is not None:
            j = pairs.j
            hydrostatic = rho0 * jnp.sum(params.gravity * pairs.dr, axis=-1) / c0**2
            volume_b = mass[j] / density[j]
            density_rate = density_rate + molteni_density_diffusion(
                density, volume_b, pairs_fluid, hydrostatic, params.density_diffusion, h, c0
            )
        density_rate = jnp.where(is_fluid, density_rate, 0.0)
        if density_step is not None:
            density = density + density_step * density_rate
    pressure = tait_pressure(density, rho0, c0, gamma, p0, p_bg)

    viscous_velocity = velocity
    if with_walls:
        # Adami et al. (2012): wall pressure from the fluid, fixed walls (a_w = 0).
        zero_acc = jnp.zeros_like(state.position)
        p_wall, weight_sum = wall_pressure(pressure, density, pairs_fluid, params.gravity, zero_acc)
        pressure = jnp.where(is_wall, p_wall, pressure)
        density = jnp.where(is_wall, tait_density(p_wall, rho0, c0, gamma, p0, p_bg), density)
        v_wall = wall_velocity(
            velocity, velocity, pairs_fluid, weight_sum, model.wall_slip == "no_slip"
        )
        if v_wall is not None:
            viscous_velocity = jnp.where(is_wall[:, None], v_wall, velocity)
    # Viscous terms see walls only with no-slip walls.
    pairs_viscous = pairs_hydro if model.wall_slip == "no_slip" else pairs_fluid
    v_ab = viscous_velocity[:, None, :] - viscous_velocity[pairs.j]

    j = pairs.j
    pi_ab = 0.0
    if model.artificial_viscosity:
        pi_ab = monaghan_pi(
            v_ab,
            pairs,
            density[:, None],
            density[j],
            c0,
            h,
            params.artificial_alpha,
            params.artificial_beta,
        )
        pi_ab = jnp.where(pairs_viscous.mask, pi_ab, 0.0)
    acceleration = pressure_acceleration(mass, density, pressure, pairs_hydro, pi_ab)
    if model.physical_viscosity:
        visc = morris_acceleration(
            v_ab, pairs, mass[j], density[:, None], density[j], params.kinematic_viscosity, h
        )
        acceleration = acceleration + jnp.sum(
            jnp.where(pairs_viscous.mask[..., None], visc, 0.0), axis=1
        )
    acceleration = acceleration + params.gravity

    shift = jnp.zeros_like(acceleration)
    if model.transport_velocity:
        # Adami et al. (2013): eq. 10 with the uniform background pressure p_b ...
        p_b = jnp.broadcast_to(params.transport_pressure, pressure.shape)
        shift = pressure_acceleration(mass, density, p_b, pairs_hydro, 0.0)
        if density_step is not None:
            # ... and the momentum flux A = rho v (v~ - v)^T of the transport velocity
            # v~ - v = dt/2 a_b of the drift just taken.
            delta_v = 0.5 * density_step * state.shift_acceleration
            acceleration = acceleration + transport_stress_acceleration(
                mass, density, velocity, delta_v, pairs_fluid
            )

    acceleration = jnp.where(is_fluid[:, None], acceleration, 0.0)
    density_rate = jnp.where(is_fluid, density_rate, 0.0)
    shift = jnp.where(is_fluid[:, None], shift, 0.0)
    return acceleration, density_rate, density, pressure, shift
