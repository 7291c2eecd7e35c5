"""The SPH right-hand side as a diffrax term (see :mod:`sphjax.integration.diffrax`)."""

from __future__ import annotations

import dataclasses

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from sphjax.core.pytree import pytree_dataclass
from sphjax.core.state import State
from sphjax.integration.step import held_in_place
from sphjax.neighbors import Neighbors, overflow_message, overflowed, update_neighbors
from sphjax.physics.rhs import evaluate

Array = jax.Array


@pytree_dataclass
class Phase:
    """Integrated variables: ``position [N, d]``, ``velocity [N, d]``, ``density [N]``."""

    position: Array
    velocity: Array
    density: Array


@pytree_dataclass
class Rates:
    """Vector-field output: ``velocity``, ``acceleration``, ``density_rate``, the
    evaluated density (summation / wall / advanced continuity), pressure and the
    transport-velocity ``shift_acceleration``, each per particle."""

    velocity: Array
    acceleration: Array
    density_rate: Array
    density: Array
    pressure: Array
    shift_acceleration: Array


@pytree_dataclass
class SPHArgs:
    """``args`` of the diffrax solve: Params, constant State fields, neighbour template.

    ``density_step`` and ``shift_acceleration`` are set by :class:`sphjax.KickDriftKick`
    for its evaluation (continuity density advanced by the step; transport stress of the
    drift just taken); ``None`` gives the plain rates.
    """

    params: object
    state: State
    neighbors: Neighbors
    density_step: Array | None = None
    shift_acceleration: Array | None = None


_OVERFLOW_MESSAGE = overflow_message("inside the diffrax vector field")


class SPHTerm(diffrax.AbstractTerm):
    """The SPH right-hand side of ``model`` as a diffrax term (control: the time step)."""

    model: object = eqx.field(static=True)

    def vf(self, t, y: Phase, args: SPHArgs) -> Rates:
        state = args.state.replace(
            position=y.position,
            velocity=y.velocity,
            density=y.density,
            time=jnp.asarray(t, y.position.dtype),
        )
        if args.shift_acceleration is not None:
            state = state.replace(shift_acceleration=args.shift_acceleration)
        # no Verlet skin inside a vector field: rebuild at the current positions
        neighbors = update_neighbors(y.position, args.neighbors, rebuild=True)
        state = evaluate(state, neighbors, self.model, args.params, args.density_step)
        # walls and unmoved clamps stay put (their velocity is not a drift)
        velocity = jnp.where(held_in_place(state.kind, self.model), 0.0, state.velocity)
        acceleration = eqx.error_if(state.acceleration, overflowed(neighbors), _OVERFLOW_MESSAGE)
        return Rates(
            velocity,
            acceleration,
            state.density_rate,
            state.density,
            state.pressure,
            state.shift_acceleration,
        )

    def contr(self, t0, t1, **kwargs):
        return t1 - t0

    def prod(self, vf: Rates, control) -> Phase:
        return Phase(
            position=control * vf.velocity,
            velocity=control * vf.acceleration,
            density=control * vf.density_rate,
        )


def with_step(args: SPHArgs, density_step, shift_acceleration) -> SPHArgs:
    """``args`` for the evaluation inside a kick-drift-kick step."""
    return dataclasses.replace(
        args, density_step=density_step, shift_acceleration=shift_acceleration
    )
