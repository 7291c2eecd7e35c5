"""The SPH right-hand side as a diffrax vector field, and ``diffeqsolve_case``.

diffrax integrates ``dy/dt = f(t, y, args)``.  Here

* ``y`` is a :class:`Phase` — the integrated per-particle variables ``(position,
  velocity, density)``;
* ``args`` is an :class:`SPHArgs` — the differentiable :class:`~sphjax.Params`, the
  constant per-particle arrays of the initial :class:`~sphjax.State` (mass, kind,
  reference positions, volumes) and a neighbour-list template that fixes the capacity;
* the term :class:`SPHTerm` evaluates :func:`sphjax.evaluate` (eqs. 5, 10-12, 14-19) at
  ``y``, with neighbour lists rebuilt at ``y``.  Its vector field returns :class:`Rates`
  (velocity, acceleration, density rate and the evaluated density — summation density
  and wall extrapolation are algebraic, not integrated); ``prod(rates, dt)`` turns them
  into an increment of ``y``, so any explicit diffrax solver can integrate it too.

Neighbours inside the vector field: the fluid list is rebuilt at the current positions
with the fixed capacity of the template (jax-md cell list, no Verlet skin); a list that
runs out of room stops the solve with an error naming ``Model.neighbor_capacity``.
Solids use their fixed reference-configuration neighbours.

:func:`diffeqsolve_case` runs a :class:`~sphjax.Case` with :class:`KickDriftKick` (our
kick-drift-kick, identical to :func:`sphjax.simulate` for the same step), ``SaveAt`` for
frames and, by default, ``RecursiveCheckpointAdjoint`` for reverse-mode gradients.
"""

from __future__ import annotations

import functools
import math

import diffrax
import jax

from sphjax.core.case import Case
from sphjax.core.params import Params
from sphjax.core.state import State
from sphjax.integration._kdk import KickDriftKick
from sphjax.integration._term import Phase, Rates, SPHArgs, SPHTerm
from sphjax.integration.simulate import _is_traced
from sphjax.physics.rhs import build_neighbors, check_system_params
from sphjax.physics.solid.system import SolidSystem


def phase_of(state: State) -> Phase:
    """The integrated variables of ``state``."""
    return Phase(state.position, state.velocity, state.density)


def state_of(phase: Phase, template: State) -> State:
    """A State with the variables of ``phase`` (may carry a leading time axis)."""
    return template.replace(position=phase.position, velocity=phase.velocity, density=phase.density)


def sph_args(case: Case, params: Params | None = None, state: State | None = None) -> SPHArgs:
    """``args`` for a diffrax solve of ``case`` (neighbour template from ``case.state``)."""
    params = case.params if params is None else params
    state = case.state_for(params) if state is None else state
    with jax.ensure_compile_time_eval():
        neighbors = build_neighbors(case.state, case.model)
    return SPHArgs(params=params, state=state, neighbors=neighbors)


def initial_phase(case: Case, args: SPHArgs) -> Phase:
    """``y0``: the initial State with its density evaluated, as :func:`sphjax.simulate`
    does before its first step (summation density, wall extrapolation).  One compiled
    program for concrete ``args`` (evaluated operation by operation it compiled about 100
    small programs per case, seconds before the solve), traced into the caller's
    program otherwise."""
    return _initial_phase(case.model, args)


@functools.partial(jax.jit, static_argnums=0)
def _initial_phase(model, args: SPHArgs) -> Phase:
    rates = SPHTerm(model).vf(0.0, phase_of(args.state), args)
    return Phase(args.state.position, args.state.velocity, rates.density)


def diffeqsolve_case(
    case: Case,
    params: Params | None = None,
    t1: float | None = None,
    dt: float | None = None,
    *,
    state: State | None = None,
    saveat: diffrax.SaveAt | None = None,
    adjoint: diffrax.AbstractAdjoint | None = None,
    solver: diffrax.AbstractSolver | None = None,
    max_steps: int | None = None,
) -> diffrax.Solution:
    """Solve ``case`` from ``t = 0`` to ``t1`` with ``diffrax.diffeqsolve``.

    Args:
      case: from ``sphjax.cases``.
      params: differentiable parameters (default ``case.params``).
      t1: end time (default ``case.t_end``).
      dt: fixed step (default ``case.dt``); ``ConstantStepSize``.
      state: initial State (default ``case.state``); may be traced.
      saveat: ``diffrax.SaveAt`` (default: the final state only).
      adjoint: default ``diffrax.RecursiveCheckpointAdjoint()`` (reverse mode with
        binomial checkpointing, memory ``O(checkpoints)``).
      solver: default :class:`KickDriftKick`; any explicit diffrax solver also works.
      max_steps: default ``ceil(t1 / dt) + 1``.
    Returns:
      ``diffrax.Solution``; ``sol.ys`` is a :class:`Phase` with a leading time axis
      (``state_of(sol.ys, case.state)`` gives States).
    """
    dt = case.dt if dt is None else dt
    t1 = case.t_end if t1 is None else t1
    solid = case.model.system(SolidSystem)
    if solid is not None and solid.substeps > 1:
        raise ValueError(
            f"SolidSystem.substeps={solid.substeps}: split integration runs in sphjax.simulate "
            "only; use simulate, or set substeps=1 (and the solid's time step) for diffrax"
        )
    for system in case.model.systems:
        if getattr(system, "transfer", None) is not None:
            raise ValueError(
                f"{type(system).__name__}: particles that enter and leave (open boundaries) "
                "run in sphjax.simulate only (the diffrax state has no room for the trade of "
                "places); use simulate"
            )
    if not _is_traced(dt, t1):
        if not float(dt) > 0:
            raise ValueError(f"dt must be positive, got {dt}")
        if not float(t1) > 0:
            raise ValueError(f"t1 must be positive, got {t1}")
        if max_steps is None:
            max_steps = int(math.ceil(float(t1) / float(dt) - 1e-9)) + 1
    args = sph_args(case, params, state)
    if not _is_traced(args.params):
        check_system_params(case.model, args.params)
    y0 = initial_phase(case, args)
    return diffrax.diffeqsolve(
        SPHTerm(case.model),
        KickDriftKick() if solver is None else solver,
        t0=0.0,
        t1=t1,
        dt0=dt,
        y0=y0,
        args=args,
        saveat=diffrax.SaveAt(t1=True) if saveat is None else saveat,
        stepsize_controller=diffrax.ConstantStepSize(),
        adjoint=diffrax.RecursiveCheckpointAdjoint() if adjoint is None else adjoint,
        max_steps=4096 if max_steps is None else max_steps,
    )


__all__ = [
    "KickDriftKick",
    "Phase",
    "Rates",
    "SPHArgs",
    "SPHTerm",
    "diffeqsolve_case",
    "initial_phase",
    "phase_of",
    "sph_args",
    "state_of",
]
