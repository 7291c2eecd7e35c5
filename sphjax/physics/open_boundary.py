"""Open boundaries: an inflow and an outflow buffer zone, at fixed particle capacity.

A channel along ``x`` is cut by two planes: fluid enters at ``x_in`` and leaves at
``x_out``.  Upstream of ``x_in`` lies the **inflow buffer** ``[x_in - W_in, x_in)``,
downstream of ``x_out`` the **outflow buffer** ``[x_out, x_out + W_out)``; each at least
one kernel support wide, so that a fluid particle near a plane has full support.  The
buffer particles are the particles of an :class:`OpenBoundarySystem` (kind ``OPEN``);
which buffer a particle is in follows from its position.  After the buffer method of
Tafuni, Domínguez, Vacondio & Crespo (2018), as TrixiParticles.jl's open boundaries:

* inflow buffer: the velocity is prescribed, ``u = u_in(y)`` (uniform, or the parabola
  ``4 u_max y (H - y) / H^2``); the pressure is extrapolated from the fluid, to first
  order along the channel: ``p(x) = p_0 + (dp/dx) x`` fitted by least squares to the
  fluid's pressures within two buffer widths downstream of ``x_in`` (Tafuni et al.
  extrapolate from mirrored ghost nodes with a first-order corrected SPH interpolation;
  this is that extrapolation averaged over the channel's cross-section, exact for a
  pressure uniform across it);
* outflow buffer: the pressure is prescribed, ``p = Outflow.pressure`` (default 0, the
  fluid's reference; ``channel_flow`` uses a small positive one; density
  from the fluid's inverse equation of state); each particle keeps the speed along the
  channel it brought from the fluid, ``Du/Dt = 0``, and none across it (the convective
  outflow condition with the particles' own velocity, for a flow that leaves fully
  developed: its profile leaves unchanged).

Both buffers' particles move with their velocity (no kick changes it).  A fluid
particle sees them as fluid neighbours with that velocity, pressure and density: in its
density sums (:meth:`OpenBoundarySystem.boundary_view`) and in its momentum equation
(eq. 10 with the viscous terms, the interaction ``fluid_open``).

**Fixed capacity.**  JAX needs fixed shapes, so particles are recycled instead of
created and deleted (:meth:`OpenBoundarySystem.transfer`, once per step after the
drift).  When an inflow buffer particle has crossed ``x_in`` and an outflow buffer
particle has left the end of its buffer, they and the most downstream fluid particle
trade places:

* the fluid particle's slot takes the crossing inflow particle's state: a new fluid
  particle just past ``x_in``;
* the outflow particle's slot takes the fluid particle's state: a new outflow buffer
  particle at the fluid's downstream end, near ``x_out``;
* the inflow particle's slot goes back by the buffer width ``W_in``, the new particle
  at the upstream end of the inflow buffer (the buffer's lattice row goes on).

So every block keeps its size, and mass in equals mass out particle by particle.  The
fluid keeps its number of particles, so its downstream end sits where that number
fills the channel: at ``x_out`` for the initial density, a fraction of a spacing
upstream when the steady pressure compresses it (a fraction of a percent here).  An
inflow particle that cannot be matched in a step (a uniform inflow's column crosses at
once, the outflow's particles leave one by one) waits, going on into the fluid with its
prescribed velocity, as does an outflow particle beyond its buffer's end; each is
matched in the following steps.  The trade is a permutation of the particles' data
chosen from their positions: gradients flow through the data it moves (``jax.grad`` of
a run is that of the motion between trades, which do not depend on the parameters).
"""

from __future__ import annotations

import dataclasses
import math

import jax.numpy as jnp

from sphjax.core.state import Kind
from sphjax.physics.fluid.system import FluidSystem
from sphjax.physics.system import block_fields

PROFILES = ("uniform", "parabolic")


def _positive(owner: str, name: str, value, fix: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if not (number > 0 and math.isfinite(number)):
        raise ValueError(f"{owner}.{name} must be a positive number, got {value!r}; {fix}")
    return number


@dataclasses.dataclass(frozen=True)
class Inflow:
    """The inflow buffer ``[plane - width, plane)`` of a channel along ``x`` between walls
    at ``y = bottom`` and ``y = bottom + height``, and its velocity profile.

    Attributes:
      plane: ``x_in``, where the fluid begins.
      width: ``W_in``, the buffer's length along ``x`` (at least the kernel support).
      velocity: the mean inflow speed ``U`` (> 0, along ``+x``).
      profile: ``"uniform"`` (``u = U``) or ``"parabolic"`` (``u = 4 u_max y (H - y) /
        H^2`` with ``u_max = 1.5 U``, plane Poiseuille flow).
      bottom, height: the channel's walls, ``y`` in ``[bottom, bottom + height]``.
    """

    plane: float
    width: float
    velocity: float
    profile: str = "uniform"
    bottom: float = 0.0
    height: float = 1.0

    def __post_init__(self):
        _positive(
            "Inflow",
            "velocity",
            self.velocity,
            "give the mean inflow speed along +x (the flow enters at x = plane)",
        )
        _positive("Inflow", "width", self.width, "give the buffer's length along x")
        _positive("Inflow", "height", self.height, "give the channel's height")
        if self.profile not in PROFILES:
            raise ValueError(
                f"Inflow.profile must be 'uniform' or 'parabolic', got {self.profile!r}"
            )

    def velocity_at(self, y):
        """``u_in(y)``, the prescribed speed along ``x`` at heights ``y``."""
        if self.profile == "uniform":
            return jnp.full_like(y, self.velocity)
        s = jnp.clip((y - self.bottom) / self.height, 0.0, 1.0)
        return 6.0 * self.velocity * s * (1.0 - s)


@dataclasses.dataclass(frozen=True)
class Outflow:
    """The outflow buffer ``[plane, plane + width)``; its pressure is the fluid's
    reference (0).

    Attributes:
      plane: ``x_out``, where the fluid ends.
      width: ``W_out``, the buffer's length along ``x`` (at least the kernel support).
    """

    plane: float
    width: float
    pressure: float = 0.0

    def __post_init__(self):
        _positive("Outflow", "width", self.width, "give the buffer's length along x")
        if not math.isfinite(float(self.pressure)):
            raise ValueError(f"Outflow.pressure must be a finite number, got {self.pressure!r}")


@dataclasses.dataclass(frozen=True)
class OpenBoundarySystem:
    """The buffer particles (kind ``OPEN``) of an inflow and an outflow (module docstring).

    Attributes:
      inflow: :class:`Inflow`, the inflow buffer and its velocity profile.
      outflow: :class:`Outflow`, the outflow buffer.
    """

    inflow: Inflow
    outflow: Outflow

    kinds = (Kind.OPEN,)
    current_configuration = True
    #: after the fluid, whose pressures it extrapolates
    stage = 1
    #: the fluid's equation of state gives its densities
    params_group = "fluid"
    #: no kick changes a buffer particle's velocity (prescribed, or kept)
    free_kinds = ()

    def __post_init__(self):
        if not isinstance(self.inflow, Inflow):
            raise ValueError(f"OpenBoundarySystem.inflow must be Inflow(...), got {self.inflow!r}")
        if not isinstance(self.outflow, Outflow):
            raise ValueError(
                f"OpenBoundarySystem.outflow must be Outflow(...), got {self.outflow!r}"
            )
        if not self.outflow.plane > self.inflow.plane:
            raise ValueError(
                f"Outflow.plane ({self.outflow.plane}) must lie downstream of Inflow.plane "
                f"({self.inflow.plane}): the fluid flows along +x between them"
            )

    @property
    def middle(self) -> float:
        """Half-way between the planes: a buffer particle upstream of it belongs to the
        inflow, downstream to the outflow."""
        return 0.5 * (self.inflow.plane + self.outflow.plane)

    def check_support(self, cutoff: float) -> None:
        """A ValueError naming the buffer narrower than the kernel support ``cutoff``."""
        for name, zone in (("Inflow", self.inflow), ("Outflow", self.outflow)):
            if zone.width < cutoff * (1.0 - 1e-9):
                raise ValueError(
                    f"{name}.width = {zone.width:.6g} is narrower than the kernel support "
                    f"{cutoff:.6g}: give a buffer at least that wide (a fluid particle at "
                    "the plane needs full support)"
                )

    def parameters(self) -> frozenset[str]:
        """None of its own: the densities come from the fluid's equation of state, whose
        fields the fluid counts."""
        return frozenset()

    def unused_parameters(self) -> dict[str, str]:
        """No Params group of its own, so nothing to refuse."""
        return {}

    def replace(self, **changes) -> OpenBoundarySystem:
        return dataclasses.replace(self, **changes)

    # the system protocol (sphjax.physics.system)

    def view(self, state, block: slice, density_step=None) -> dict:
        """The buffer particles' ``x, v, m, rho``."""
        return block_fields(state, block)

    def boundary_view(self, view: dict, params) -> dict:
        """A fluid's density sums see the buffer particles as fluid (``x, m, v``)."""
        return {"x": view["x"], "m": view["m"], "v": view["v"]}

    def update(self, i: int, views: list, systems: tuple, pairs: dict, ctx, density_step=None):
        """Pressure (extrapolated from the fluid in the inflow buffer,
        ``Outflow.pressure`` in the outflow buffer) and density from the fluid's inverse
        equation of state."""
        view = views[i]
        j = next((k for k, s in enumerate(systems) if isinstance(s, FluidSystem)), None)
        if j is None:
            raise ValueError(
                "an OpenBoundarySystem needs a fluid: add a FluidSystem() to Model.systems"
            )
        fluid_system, fluid = systems[j], views[j]
        x = view["x"][:, 0]
        inflow = x < self.middle
        p_in = inflow_pressure(fluid["x"][:, 0], fluid["p"], self.inflow, x)
        pressure = jnp.where(inflow, p_in, self.outflow.pressure)
        density = fluid_system.equation_of_state.density(pressure, ctx.params.fluid)
        return {**view, "p": pressure, "rho": density}

    def body_acceleration(self, view: dict, acceleration, params):
        """No kick moves a buffer particle (``free_kinds`` is empty): nothing to add."""
        return acceleration

    def held_kinds(self) -> tuple:
        return ()

    def prescribed_motion(self, time, state):
        return None

    def time_step_limits(self, v_max: float, params, model, cfl: float) -> list[float]:
        """None of its own: the fluid's acoustic limit covers it."""
        return []

    def transfer(self, state):
        """The trade of places at fixed capacity (module docstring), after a drift: a
        State with the same particles per block."""
        return recycle(state, self.inflow, self.outflow)


def inflow_pressure(x_fluid, p_fluid, inflow: Inflow, x):
    """The fluid's pressure extrapolated to the inflow buffer positions ``x``: the least
    squares line ``p_0 + G x`` through the fluid's pressures within ``2 W_in`` downstream
    of ``x_in`` (module docstring); ``[n]`` for ``x`` ``[n]``."""
    near = (x_fluid >= inflow.plane) & (x_fluid < inflow.plane + 2.0 * inflow.width)
    w = near.astype(p_fluid.dtype)
    s = x_fluid - inflow.plane
    n = jnp.sum(w)
    mean_s = jnp.sum(w * s) / jnp.maximum(n, 1.0)
    mean_p = jnp.sum(w * p_fluid) / jnp.maximum(n, 1.0)
    ds = (s - mean_s) * w
    var = jnp.sum(ds * ds)
    safe = var > 0
    slope = jnp.where(safe, jnp.sum(ds * (p_fluid - mean_p)) / jnp.where(safe, var, 1.0), 0.0)
    return mean_p + slope * (x - inflow.plane - mean_s)


def _ranked(mask, key):
    """Indices with ``mask`` first, by ``key`` descending, and how many there are."""
    order = jnp.argsort(jnp.where(mask, -key, jnp.inf))
    return order, jnp.sum(mask)


def recycle(state, inflow: Inflow, outflow: Outflow):
    """Match the inflow buffer particles past ``x_in`` with the outflow buffer particles
    past its end and the most downstream fluid particles, furthest first, and trade
    their places (module docstring).  Fields other than the kind and the reference
    position move with the data; an outflow particle keeps only its speed along ``x``."""
    x = state.position[:, 0]
    is_open = state.kind == Kind.OPEN
    is_fluid = state.kind == Kind.FLUID
    end = outflow.plane + outflow.width
    middle = 0.5 * (inflow.plane + outflow.plane)
    entered, n_entered = _ranked(is_open & (x >= inflow.plane) & (x < middle), x)
    left, _ = _ranked(is_fluid, x)
    gone, n_gone = _ranked(is_open & (x >= end), x)
    n = x.shape[0]
    matched = jnp.arange(n) < jnp.minimum(n_entered, n_gone)
    fluid_slot = jnp.where(matched, left, n)
    outflow_slot = jnp.where(matched, gone, n)
    inflow_slot = jnp.where(matched, entered, n)
    source = jnp.arange(n)
    source = source.at[fluid_slot].set(entered, mode="drop")
    source = source.at[outflow_slot].set(left, mode="drop")
    back = jnp.zeros_like(x).at[inflow_slot].set(inflow.width, mode="drop")
    moved = {
        name: getattr(state, name)[source]
        for name in (
            "position",
            "velocity",
            "density",
            "mass",
            "volume",
            "acceleration",
            "density_rate",
            "pressure",
            "shift_acceleration",
        )
    }
    moved["position"] = moved["position"].at[:, 0].add(-back)
    # an outflow particle keeps its speed along the channel, not across it (it would
    # drift into the walls over its stay in the buffer)
    moved["velocity"] = moved["velocity"].at[outflow_slot, 1:].set(0.0, mode="drop")
    return state.replace(**moved)
