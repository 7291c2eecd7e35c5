"""The three things a simulation is made of: State, Params and Model.

* ``State`` — a pytree of per-particle arrays (positions, velocities, density, ...).
  Fixed shapes, so one compiled step serves the whole run.
* ``Params`` — a pytree of the floats ``jax.grad`` may see: reference density, sound
  speed, gravity, viscosities, Young's modulus, Poisson's ratio, penalty coefficient.
  ``params.replace(young_modulus=...)`` returns a new Params.
* ``Model`` — the static, hashable configuration: dimension, kernel, smoothing length,
  domain, density and viscosity formulations, boundary treatment.  Choosing another
  model recompiles; changing a parameter does not.

Particle kinds are integer tags in ``State.kind`` (see :class:`Kind`).  Kinds that do
not occur in a case cost nothing at run time: the right-hand side is composed in Python
from ``Model`` before tracing.
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from sphjax.kernels import Kernel, QuinticSpline

Array = jax.Array


class Kind(enum.IntEnum):
    """Particle kind tags stored in ``State.kind``."""

    FLUID = 0
    WALL = 1  # boundary dummy particle (Adami et al. 2012), moves with its wall
    SOLID = 2  # total-Lagrangian elastic solid particle
    CLAMPED = 3  # solid particle whose motion is prescribed (fixed by default)


def _pytree_dataclass(cls):
    """Freeze ``cls`` as a dataclass and register every field as a pytree child."""
    cls = dataclasses.dataclass(frozen=True)(cls)
    names = [f.name for f in dataclasses.fields(cls)]
    jax.tree_util.register_dataclass(cls, data_fields=names, meta_fields=[])
    cls.replace = lambda self, **changes: dataclasses.replace(self, **changes)
    return cls


@_pytree_dataclass
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
    """Build a :class:`State` with zero rates; reference positions are the positions."""
    position = jnp.asarray(position, dtype=jnp.result_type(float))
    n, d = position.shape
    dtype = position.dtype
    velocity = jnp.broadcast_to(jnp.asarray(velocity, dtype), (n, d))
    density = jnp.broadcast_to(jnp.asarray(density, dtype), (n,))
    mass = jnp.broadcast_to(jnp.asarray(mass, dtype), (n,))
    kind = jnp.broadcast_to(jnp.asarray(kind, jnp.int32), (n,))
    volume = (
        mass / density if volume is None else jnp.broadcast_to(jnp.asarray(volume, dtype), (n,))
    )
    return State(
        position=position,
        velocity=velocity,
        density=density,
        mass=mass,
        kind=kind,
        reference_position=position,
        volume=volume,
        acceleration=jnp.zeros((n, d), dtype),
        density_rate=jnp.zeros((n,), dtype),
        pressure=jnp.zeros((n,), dtype),
        shift_acceleration=jnp.zeros((n, d), dtype),
        time=jnp.zeros((), dtype),
    )


@_pytree_dataclass
class Params:
    """Differentiable parameters.  Every float ``jax.grad`` should see lives here.

    Attributes:
      reference_density: fluid rest density ``rho0`` (eq. 12).
      sound_speed: fluid artificial sound speed ``c0`` (eq. 12).
      gravity: ``[d]`` body acceleration ``g`` (eq. 10, 14), e.g. ``(0, -9.81)`` or a
        driving body force per unit mass.
      artificial_alpha: Monaghan artificial viscosity ``alpha`` (``Pi_ab`` in eq. 10).
      artificial_beta: Monaghan ``beta`` (quadratic term).
      kinematic_viscosity: physical kinematic viscosity ``nu`` (Morris et al. 1997).
      background_pressure: ``p_background`` subtracted in eq. 12.
      transport_pressure: background pressure ``p_b`` of the transport-velocity
        formulation (Adami, Hu & Adams 2013); used when ``Model.transport_velocity``.
      reference_pressure: ``p0`` added in eq. 12.
      density_diffusion: delta-SPH coefficient ``delta`` (used when the Model enables it).
      young_modulus: solid Young's modulus ``E`` (eq. 19).
      poisson_ratio: solid Poisson's ratio ``nu`` (eq. 19).
      solid_density: solid reference density ``rho0`` (eq. 14).
      penalty_alpha: hourglass penalty coefficient (eq. 14, Ganzenmüller 2015).
    """

    reference_density: Array
    sound_speed: Array
    gravity: Array
    artificial_alpha: Array
    artificial_beta: Array
    kinematic_viscosity: Array
    background_pressure: Array
    transport_pressure: Array
    reference_pressure: Array
    density_diffusion: Array
    young_modulus: Array
    poisson_ratio: Array
    solid_density: Array
    penalty_alpha: Array


def make_params(
    dim: int,
    *,
    reference_density=1000.0,
    sound_speed=10.0,
    gravity=None,
    artificial_alpha=0.0,
    artificial_beta=0.0,
    kinematic_viscosity=0.0,
    background_pressure=0.0,
    transport_pressure=0.0,
    reference_pressure=0.0,
    density_diffusion=0.1,
    young_modulus=1.0e6,
    poisson_ratio=0.3,
    solid_density=1000.0,
    penalty_alpha=0.0,
) -> Params:
    """Params with defaults; every value becomes a float array of the default dtype."""
    dtype = jnp.result_type(float)
    gravity = jnp.zeros(dim, dtype) if gravity is None else jnp.asarray(gravity, dtype)
    if gravity.shape != (dim,):
        raise ValueError(f"gravity must have shape ({dim},), got {gravity.shape}")
    scalars = dict(
        reference_density=reference_density,
        sound_speed=sound_speed,
        artificial_alpha=artificial_alpha,
        artificial_beta=artificial_beta,
        kinematic_viscosity=kinematic_viscosity,
        background_pressure=background_pressure,
        transport_pressure=transport_pressure,
        reference_pressure=reference_pressure,
        density_diffusion=density_diffusion,
        young_modulus=young_modulus,
        poisson_ratio=poisson_ratio,
        solid_density=solid_density,
        penalty_alpha=penalty_alpha,
    )
    for name in ("reference_density", "solid_density", "young_modulus"):
        if not float(scalars[name]) > 0:
            raise ValueError(f"{name} must be positive, got {scalars[name]}")
    if not float(scalars["sound_speed"]) > 0:
        raise ValueError(f"sound_speed must be positive, got {scalars['sound_speed']}")
    if not -1.0 < float(scalars["poisson_ratio"]) < 0.5:
        raise ValueError(f"poisson_ratio must lie in (-1, 0.5), got {scalars['poisson_ratio']}")
    return Params(gravity=gravity, **{k: jnp.asarray(v, dtype) for k, v in scalars.items()})


@dataclasses.dataclass(frozen=True)
class Domain:
    """Axis-aligned simulation box ``[lower, upper)`` with per-axis periodicity.

    Non-periodic axes still need bounds: a particle that leaves them stops the run.
    """

    lower: tuple[float, ...]
    upper: tuple[float, ...]
    periodic: tuple[bool, ...]

    def __post_init__(self):
        if not len(self.lower) == len(self.upper) == len(self.periodic):
            raise ValueError("Domain.lower, upper and periodic must have one entry per axis")
        for lo, hi in zip(self.lower, self.upper, strict=True):
            if not hi > lo:
                raise ValueError(f"Domain upper bound {hi} must exceed lower bound {lo}")

    @property
    def dim(self) -> int:
        return len(self.lower)

    @property
    def size(self) -> tuple[float, ...]:
        return tuple(hi - lo for lo, hi in zip(self.lower, self.upper, strict=True))


@dataclasses.dataclass(frozen=True)
class Model:
    """Static configuration of a simulation (hashable; passed as a static argument).

    Attributes:
      dim: spatial dimension, 2 or 3.
      kernel: smoothing kernel (see :mod:`sphjax.kernels`).
      smoothing_length: ``h``; the support radius is ``kernel.support * h``.
      domain: the simulation box and its periodic axes.
      density: ``"summation"`` (eq. 5) or ``"continuity"`` (eq. 11).
      gamma: exponent of the Tait equation of state (eq. 12); 7 for free surfaces, 1
        for internal flows.
      artificial_viscosity: include Monaghan's ``Pi_ab`` (eq. 10).
      physical_viscosity: include the Morris laminar viscosity (kinematic ``nu``).
      transport_velocity: advect fluid particles with the transport velocity of Adami,
        Hu & Adams (2013), ``v~ = v + dt/2 a_b`` with the background-pressure acceleration
        ``a_b`` (pressure ``Params.transport_pressure``), which keeps the particle
        distribution regular (needed for Taylor-Green).
      density_diffusion: ``None`` or ``"molteni"`` (Molteni & Colagrossi delta-SPH, with
        the hydrostatic density difference removed).
      wall_slip: ``"no_slip"`` or ``"free_slip"`` for the Adami wall viscous term.
      solid_penalty: include the hourglass penalty force of eq. 14.
      clamped_motion: ``None`` (clamped particles stay put) or a hashable function
        ``(t, X) -> x`` giving the prescribed positions of clamped particles.
      particle_kinds: the :class:`Kind` values present; the right-hand side is composed
        for these only.
      neighbor_capacity: multiplier on the neighbour-list capacity; raise it if a run
        reports a neighbour-list overflow.
      neighbor_skin: Verlet skin as a fraction of the support radius; the list is
        rebuilt only when a particle has moved half the skin.
      pair_adjoint: reverse mode through the fluid rates uses the hand-derived adjoint of
        :mod:`sphjax.fluid.adjoint` where it covers the model (fluid only, summation
        density, no artificial viscosity or density diffusion): gradients ~1.5x faster
        than with autodiff's transpose.  It gives first derivatives only; set ``False``
        for second derivatives (``jax.hessian``) through a simulation, and for work in
        forward mode only (``jax.jvp``, ``jacfwd``), which is ~10 % faster without it.
    """

    dim: int
    smoothing_length: float
    domain: Domain
    kernel: Kernel = QuinticSpline()
    density: str = "summation"
    gamma: float = 7.0
    artificial_viscosity: bool = True
    physical_viscosity: bool = False
    transport_velocity: bool = False
    density_diffusion: str | None = None
    wall_slip: str = "no_slip"
    solid_penalty: bool = False
    clamped_motion: Callable[[Any, Any], Any] | None = None
    particle_kinds: tuple[int, ...] = (0,)
    neighbor_capacity: float = 1.25
    neighbor_skin: float = 0.25
    pair_adjoint: bool = True

    def __post_init__(self):
        if self.dim not in (2, 3):
            raise ValueError(f"Model.dim must be 2 or 3, got {self.dim}")
        if self.domain.dim != self.dim:
            raise ValueError(f"Model.domain has {self.domain.dim} axes but dim={self.dim}")
        if not self.smoothing_length > 0:
            raise ValueError(
                f"Model.smoothing_length must be positive, got {self.smoothing_length}"
            )
        if self.density not in ("summation", "continuity"):
            raise ValueError(
                f"Model.density must be 'summation' or 'continuity', got {self.density!r}"
            )
        if self.density_diffusion not in (None, "molteni"):
            raise ValueError(
                f"Model.density_diffusion must be None or 'molteni', got {self.density_diffusion!r}"
            )
        if self.wall_slip not in ("no_slip", "free_slip"):
            raise ValueError(
                f"Model.wall_slip must be 'no_slip' or 'free_slip', got {self.wall_slip!r}"
            )
        object.__setattr__(
            self, "particle_kinds", tuple(sorted({int(k) for k in self.particle_kinds}))
        )
        if not self.neighbor_capacity >= 1.0:
            raise ValueError("Model.neighbor_capacity must be >= 1")
        if not isinstance(self.pair_adjoint, bool):
            raise ValueError(f"Model.pair_adjoint must be True or False, got {self.pair_adjoint!r}")

    @property
    def cutoff(self) -> float:
        """Kernel support radius ``k h``."""
        return self.kernel.support * self.smoothing_length

    def replace(self, **changes) -> Model:
        return dataclasses.replace(self, **changes)
