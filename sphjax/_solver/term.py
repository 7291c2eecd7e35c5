"""The SPH right-hand side as a diffrax term (see :mod:`sphjax.diffrax_solver`)."""

from __future__ import annotations

import dataclasses

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from sphjax.integrate import _search
from sphjax.rhs import Neighbors, evaluate
from sphjax.state import Kind, Model, Params, State

Array = jax.Array


@dataclasses.dataclass(frozen=True)
class Phase:
    """Integrated variables: ``position [N, d]``, ``velocity [N, d]``, ``density [N]``."""

    position: Array
    velocity: Array
    density: Array


@dataclasses.dataclass(frozen=True)
class Rates:
    """Vector-field output: ``velocity``, ``acceleration``, ``density_rate``, the
    evaluated density (summation / wall / advanced continuity) and the transport-velocity
    ``shift_acceleration``, each per particle."""

    velocity: Array
    acceleration: Array
    density_rate: Array
    density: Array
    shift_acceleration: Array


@dataclasses.dataclass(frozen=True)
class SPHArgs:
    """``args`` of the diffrax solve: Params, constant State fields, neighbour template."""

    params: Params
    state: State
    neighbors: Neighbors


for _cls, _fields in (
    (Phase, ["position", "velocity", "density"]),
    (Rates, ["velocity", "acceleration", "density_rate", "density", "shift_acceleration"]),
    (SPHArgs, ["params", "state", "neighbors"]),
):
    jax.tree_util.register_dataclass(_cls, data_fields=_fields, meta_fields=[])

_OVERFLOW_MESSAGE = (
    "the neighbour list overflowed inside the diffrax vector field, where it cannot be "
    "re-allocated; raise Model.neighbor_capacity (e.g. "
    "case.replace(model=case.model.replace(neighbor_capacity=2.0)))"
)


class SPHTerm(diffrax.AbstractTerm):
    """The SPH right-hand side of ``model`` as a diffrax term (control: the time step)."""

    model: Model = eqx.field(static=True)

    def vf(self, t, y: Phase, args: SPHArgs) -> Rates:
        return self.rates(t, y, args)

    def rates(self, t, y: Phase, args: SPHArgs, density_step=None, shift_acceleration=None):
        """The right-hand side; with ``density_step`` the continuity density is first
        advanced by that step (see :func:`sphjax.evaluate`), as the KDK solver needs."""
        state = args.state.replace(
            position=y.position,
            velocity=y.velocity,
            density=y.density,
            time=jnp.asarray(t, y.position.dtype),
        )
        if shift_acceleration is not None:
            state = state.replace(shift_acceleration=shift_acceleration)
        neighbors = args.neighbors
        if neighbors.fluid is not None:
            fluid = _search(self.model).rebuild(y.position, neighbors.fluid)
            overflow = jnp.asarray(fluid.did_buffer_overflow)
            neighbors = dataclasses.replace(neighbors, fluid=fluid)
        state = evaluate(state, neighbors, self.model, args.params, density_step)
        velocity = state.velocity
        if self.model.clamped_motion is None:  # clamped particles stay put
            velocity = jnp.where((state.kind == Kind.CLAMPED)[:, None], 0.0, velocity)
        acceleration = state.acceleration
        if neighbors.fluid is not None:
            acceleration = eqx.error_if(acceleration, overflow, _OVERFLOW_MESSAGE)
        return Rates(
            velocity, acceleration, state.density_rate, state.density, state.shift_acceleration
        )

    def contr(self, t0, t1, **kwargs):
        return t1 - t0

    def prod(self, vf: Rates, control) -> Phase:
        return Phase(
            position=control * vf.velocity,
            velocity=control * vf.acceleration,
            density=control * vf.density_rate,
        )
