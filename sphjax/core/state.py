"""Per-particle state of a simulation and its saved frames.

* :class:`State` — a pytree of per-particle arrays (positions, velocities, density, ...).
  Fixed shapes, so one compiled step serves the whole run.  Particles are grouped by
  system in contiguous blocks (fluid, then walls, then solids; see :class:`Kind`): each
  system of the :class:`~sphjax.Model` owns one block of every array, as the systems of
  TrixiParticles.jl own views into one state vector.
* :class:`Trajectory` — saved States with a leading time axis, and their times.
"""

from __future__ import annotations

import enum

import jax
import jax.numpy as jnp
import numpy as np

from sphjax._host import is_traced
from sphjax.core.pytree import pytree_dataclass

Array = jax.Array


class Kind(enum.IntEnum):
    """Particle kind tags stored in ``State.kind``; each system owns one or two kinds."""

    FLUID = 0  # weakly compressible fluid (FluidSystem)
    WALL = 1  # boundary dummy particle (Adami et al. 2012); fixed, velocity = wall surface's
    SOLID = 2  # total-Lagrangian elastic solid particle (SolidSystem)
    CLAMPED = 3  # solid particle whose motion is prescribed (fixed by default; SolidSystem)
    RIGID = 4  # particle of a rigid body (RigidSystem)
    OPEN = 5  # buffer particle of an inflow or outflow (OpenBoundarySystem)


@pytree_dataclass
class State:
    """Per-particle arrays of a simulation, ``N`` particles in ``d`` dimensions.

    Attributes:
      position: ``[N, d]`` current positions ``r_a``.
      velocity: ``[N, d]`` velocities ``v_a``.
      density: ``[N]`` densities ``rho_a`` (fluid; for solids the current density is
        ``rho0 / det F`` and this field holds the reference density).
      mass: ``[N]`` particle masses ``m_a``.
      kind: ``[N]`` int32 :class:`Kind` tags.
      reference_position: ``[N, d]`` reference (initial) positions ``X_a``; used by
        solids (eq. 15-16) and as the anchor of prescribed (clamped, wall) motion.
      volume: ``[N]`` reference volumes ``V0_a = m0_a / rho0_a``.
      acceleration: ``[N, d]`` ``Dv/Dt`` from the last right-hand-side evaluation,
        kept so the kick-drift-kick integrator evaluates forces once per step.
      density_rate: ``[N]`` ``Drho/Dt`` from the last evaluation (continuity, eq. 11).
      pressure: ``[N]`` pressure from the last evaluation (fluid and wall particles).
      shift_acceleration: ``[N, d]`` background-pressure acceleration of the transport
        velocity (Adami, Hu & Adams 2013); zero unless ``Model.transport_velocity``.
      time: scalar simulated time.
    """

    position: Array
    velocity: Array
    density: Array
    mass: Array
    kind: Array
    reference_position: Array
    volume: Array
    acceleration: Array
    density_rate: Array
    pressure: Array
    shift_acceleration: Array
    time: Array

    @property
    def n_particles(self) -> int:
        return self.position.shape[-2]

    @property
    def dim(self) -> int:
        return self.position.shape[-1]


def make_state(position, velocity, density, mass, kind, volume=None) -> State:
    """Build a :class:`State` with zero rates; reference positions are the positions.

    Particles must come grouped by kind in ascending order (fluid, wall, solid; solid and
    clamped particles together in any order), one contiguous block per system.

    Concrete arguments are combined in numpy and handed over in one transfer per array
    (no program to compile); traced ones (a case's ``initial_state`` under ``jax.grad``
    or ``jit``) in jax.numpy.
    """
    traced = is_traced(position, velocity, density, mass, kind, volume)
    xp = jnp if traced else np
    dtype = jnp.result_type(float)
    position = xp.asarray(position, dtype=dtype)
    n, d = position.shape
    velocity = xp.broadcast_to(xp.asarray(velocity, dtype), (n, d))
    density = xp.broadcast_to(xp.asarray(density, dtype), (n,))
    mass = xp.broadcast_to(xp.asarray(mass, dtype), (n,))
    kind = xp.broadcast_to(xp.asarray(kind, np.int32), (n,))
    order = np.asarray(kind) if not isinstance(kind, jax.core.Tracer) else np.zeros(0)
    system_of = np.minimum(order, int(Kind.SOLID))  # solid and clamped: one system
    if order.size and not np.all(np.diff(system_of) >= 0):
        raise ValueError(
            "make_state: particles must be grouped by kind (fluid, then wall, then solid "
            "and clamped particles): sort them by kind before building the State"
        )
    volume = mass / density if volume is None else xp.broadcast_to(xp.asarray(volume, dtype), (n,))
    fields = dict(
        position=position,
        velocity=velocity,
        density=density,
        mass=mass,
        kind=kind,
        volume=volume,
        acceleration=xp.zeros((n, d), dtype),
        density_rate=xp.zeros((n,), dtype),
        pressure=xp.zeros((n,), dtype),
        shift_acceleration=xp.zeros((n, d), dtype),
        time=xp.zeros((), dtype),
    )
    if not traced:
        fields = {name: jax.device_put(np.array(a)) for name, a in fields.items()}
    return State(reference_position=fields["position"], **fields)


@pytree_dataclass
class Trajectory:
    """Saved frames: ``states`` is a State whose arrays have a leading time axis."""

    states: State
    times: Array

    def __len__(self) -> int:
        return int(self.times.shape[0])

    def frame(self, i: int) -> State:
        return jax.tree_util.tree_map(lambda x: x[i], self.states)

    @property
    def final(self) -> State:
        return self.frame(-1)
