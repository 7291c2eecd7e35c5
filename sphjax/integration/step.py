"""The one time step both drivers use: kick-drift-kick (velocity Verlet).

    v_{n+1/2} = v_n + dt/2 a_n
    x_{n+1}   = x_n + dt v_{n+1/2}        (+ dt^2/2 a_b with the transport velocity)
    rho_{n+1} = rho_n + dt Drho(x_{n+1}, v_{n+1/2})          (continuity, eq. 11)
    a_{n+1}   = a(x_{n+1}, v_{n+1/2}, rho_{n+1})
    v_{n+1}   = v_{n+1/2} + dt/2 a_{n+1}

Density lives at whole steps and velocity at half steps, the staggered leapfrog that is
stable for the acoustic waves of weakly compressible SPH up to the usual Courant limit.
For forces that depend on positions only (elastic solids, inviscid fluids with summation
density) this is the symplectic Störmer-Verlet scheme.  The rates of the last evaluation
are kept in the State, so a step costs one right-hand-side evaluation.

:func:`kick_drift_kick` takes the evaluation as a function, so the ``lax.scan`` driver
(:func:`sphjax.simulate`, with its neighbour lists) and the diffrax solver
(:class:`sphjax.KickDriftKick`, through the term's vector field) run the same step.
"""

from __future__ import annotations

from collections.abc import Callable

import jax.numpy as jnp

from sphjax.core.space import wrap_fn
from sphjax.core.state import State


def _any_kind(kind, kinds):
    """``[N, 1]`` True where ``kind`` is one of ``kinds`` (a static tuple)."""
    mask = jnp.zeros(kind.shape, bool)
    for k in kinds:
        mask = mask | (kind == k)
    return mask[:, None]


def _free(kind, model):
    """``[N, 1]`` True for the particles whose velocity the kicks change (each system's
    ``free_kinds``)."""
    return _any_kind(kind, tuple(k for s in model.systems for k in s.free_kinds))


def held_in_place(kind, model):
    """``[N, 1]`` True for the particles whose positions no integrator changes (each
    system's ``held_kinds()``): walls (their velocity is the surface velocity the no-slip
    terms see, not a drift) and clamped particles without a prescribed motion
    (``SolidSystem.clamped_motion``).  The one rule for both drivers (this step and the
    diffrax term)."""
    return _any_kind(kind, tuple(k for s in model.systems for k in s.held_kinds()))


def kick_drift(state: State, dt, model) -> State:
    """First half of a step: half kick with the stored rates, then a full drift.

    Returns the State at ``t + dt`` with half-step velocities; its rates are still those
    of ``t``.  Wall particles never move: their velocity is the prescribed velocity of
    the wall's surface, which the no-slip viscous terms see (a lid sliding along itself,
    a conveyor belt), not a drift; with the transport-velocity formulation fluid
    particles are advected with ``v~ = v_{n+1/2} + dt/2 a_b`` (Adami et al. 2013); clamped
    particles follow ``SolidSystem.clamped_motion`` or stay put.  Last, a system with a
    ``transfer`` (open boundaries) trades the places of particles that entered or left
    its zones, at fixed capacity.
    """
    kind = state.kind
    half = 0.5 * dt
    velocity = jnp.where(
        _free(kind, model), state.velocity + half * state.acceleration, state.velocity
    )
    position = state.position + dt * (velocity + half * state.shift_acceleration)
    time = state.time + dt
    position = jnp.where(held_in_place(kind, model), state.position, position)
    for system in model.systems:
        motion = system.prescribed_motion(time, state)
        if motion is not None:
            moved, target = motion
            velocity = jnp.where(moved, (target - state.position) / dt, velocity)
            position = jnp.where(moved, target, position)
    position = wrap_fn(model.domain)(position)
    state = state.replace(position=position, velocity=velocity, time=time)
    for system in model.systems:
        transfer = getattr(system, "transfer", None)
        if transfer is not None:  # particles that enter and leave (open boundaries)
            state = transfer(state)
    return state


def closing_kick(state: State, dt, model) -> State:
    """Second half of a step: half kick with the freshly evaluated accelerations."""
    velocity = jnp.where(
        _free(state.kind, model), state.velocity + 0.5 * dt * state.acceleration, state.velocity
    )
    return state.replace(velocity=velocity)


def kick_drift_kick(state: State, dt, model, rates: Callable[[State, object], State]) -> State:
    """Advance one step of size ``dt``.

    Args:
      rates: ``rates(state, density_step) -> state`` with ``acceleration``,
        ``density_rate``, ``density``, ``pressure`` and ``shift_acceleration`` evaluated at
        the drifted state, the continuity density first advanced by ``density_step``
        (:func:`sphjax.evaluate`).
    """
    return closing_kick(rates(kick_drift(state, dt, model), dt), dt, model)
