"""The right-hand side: each system's update stage, then a sum over interactions.

``evaluate(state, neighbors, model, params)`` returns the State with ``acceleration``
(``Dv/Dt``), ``density_rate`` (``Drho/Dt``), ``pressure``, ``shift_acceleration`` and, for
summation density and walls, ``density`` filled in.  It is pure: arrays and neighbour
indices in, arrays out.

1. **Update stage**, in a fixed order: the fluid's density and pressure (eqs. 5/11, 12),
   the walls' pressure, density and velocity extrapolated from the fluid (Adami et al.
   2012), the solid's correction matrix, deformation gradient and stress (eqs. 15-19).
2. **Interactions**: for every ordered pair of systems with an entry in
   :data:`sphjax.physics.interactions.INTERACTIONS`, the accelerations of the first
   system's particles due to the second's, summed; then gravity.

Each system owns one contiguous block of the State's particles (:func:`system_blocks`).
Neighbour lists exist only for the pairs of systems that interact
(:func:`neighbor_pairs`, :func:`neighbor_plan`): the current configuration for fluid and
walls, split from one jax-md cell list, and the reference configuration within a solid;
the package :mod:`sphjax.neighbors` forms them from that plan and the geometry alone.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax.ad_checkpoint import checkpoint_name

from sphjax._host import concrete_call
from sphjax.core.state import State
from sphjax.neighbors import (
    ListPlan,
    Neighbors,
    PairList,
    SearchGeometry,
    allocate,
    reference_pairs,
)
from sphjax.physics import pairs as pairs_module
from sphjax.physics.interactions import INTERACTIONS, UPDATE_PAIRS
from sphjax.physics.pairs import Geometry

#: name of the per-particle fields of the update stage (density, pressure) that reverse
#: mode keeps instead of recomputing their pair sums (see ``sphjax.simulate``)
UPDATE_FIELDS = "sphjax_update_fields"


# ---------------------------------------------------------------------------- layout


def system_blocks(kind, model) -> tuple[tuple[int, int], ...]:
    """``(start, stop)`` of each system's particles in the State (concrete ``kind``)."""
    kind = np.asarray(kind)
    blocks, start = [], 0
    for system in model.systems:
        count = int(np.isin(kind, [int(k) for k in system.kinds]).sum())
        own = kind[start : start + count]
        if count and not np.isin(own, [int(k) for k in system.kinds]).all():
            raise ValueError(
                "the State's particles must be grouped by system in the order of "
                "Model.systems (fluid, wall, solid); sort them by kind"
            )
        blocks.append((start, start + count))
        start += count
    if start != kind.shape[0]:
        present = sorted(set(kind.tolist()))
        raise ValueError(
            f"the State has particle kinds {present} but Model.systems own the kinds "
            f"{list(model.particle_kinds)}; add the missing system to Model.systems"
        )
    return tuple(blocks)


def neighbor_pairs(model) -> tuple[tuple[int, int], ...]:
    """Ordered pairs ``(i, j)`` of systems whose neighbour list is needed: those of an
    interaction or an update stage, and their transposes (the list of ``j`` against
    ``i`` is what the adjoint of a sum over ``i`` against ``j`` runs over)."""
    return tuple(
        (i, j)
        for i, a in enumerate(model.systems)
        for j, b in enumerate(model.systems)
        if _acts(a, b) or _acts(b, a)
    )


def _acts(system, other) -> bool:
    """Whether ``system`` needs a neighbour list against ``other``: an update pair, or a
    registered interaction that is active for these two (an interaction function may
    carry ``active(system, other)``, e.g. wall contact only where the body has one)."""
    if (type(system), type(other)) in UPDATE_PAIRS:
        return True
    interaction = INTERACTIONS.get((type(system), type(other)))
    return interaction is not None and getattr(interaction, "active", _always)(system, other)


def _always(system, other) -> bool:
    return True


# ---------------------------------------------------------------------------- neighbours


def neighbor_plan(model) -> ListPlan:
    """The neighbour lists ``model`` needs (:class:`sphjax.neighbors.ListPlan`): its search
    geometry, which systems' lists follow the particles, and :func:`neighbor_pairs` (read
    anew at each call: a user may register an interaction at any time)."""
    return ListPlan(
        SearchGeometry.of(model),
        tuple(bool(system.current_configuration) for system in model.systems),
        neighbor_pairs(model),
    )


def build_neighbors(state: State, model, **options) -> Neighbors:
    """Allocate the neighbour lists of ``model`` for concrete ``state`` (outside ``jit``):
    :func:`sphjax.neighbors.allocate` with the systems' blocks (:func:`system_blocks`)
    and :func:`neighbor_plan`; ``options`` are its (``compact_rows``, ``margin``,
    ``support``, ``extra_capacity``, ``at_least``)."""
    return allocate(state, system_blocks(state.kind, model), neighbor_plan(model), **options)


def with_reference(state: State, neighbors: Neighbors, model) -> Neighbors:
    """``neighbors`` with each solid's reference-configuration quantities computed from
    ``state``: the pair geometry of its list (``X_ab``, ``|X_ab|``, ``W0``, ``grad0 W``;
    :attr:`~sphjax.neighbors.PairList.geometry`) and ``L0`` (eq. 15).

    They depend only on the reference positions and volumes, which no step changes, so a
    run computes them once (:func:`sphjax.simulate`) instead of at every evaluation; as
    they are computed from ``state`` (traced under ``jax.grad``), derivatives through them
    are those of the per-step computation.
    """
    ctx = Context.of(model, None)
    reference = {}
    for i, system in enumerate(model.systems):
        if not system.current_configuration and _size(neighbors.blocks[i]):
            view = system.view(state, slice(*neighbors.blocks[i]))
            reference[i] = system.reference_quantities(view, neighbors.pairs[(i, i)], ctx)
    return dataclasses.replace(neighbors, reference=reference or None)


# ---------------------------------------------------------------------------- evaluation


@dataclasses.dataclass(frozen=True)
class Context:
    """What the stages share: Params, pair geometry and the pair-sum settings."""

    params: object
    geometry: Geometry
    adjoint: bool
    block: int | None
    fluid_pairs: PairList | None = None
    reference: dict | None = None
    #: pair sums within one system by the compiled loops of :mod:`sphjax.native`
    native: bool = False

    @classmethod
    def of(cls, model, params) -> Context:
        """The context of ``model``'s pair sums (its geometry and pair-sum settings)."""
        return cls(
            params,
            Geometry.of(model),
            model.pair_adjoint,
            model.pair_block,
            native=model.pair_loop == "native",
        )

    def pair_sum(self, f, rows, cols, pairs, shared=(), weight=None, parity=None):
        return pairs_module.pair_sum(
            f,
            rows,
            cols,
            pairs,
            self.geometry,
            shared,
            weight=weight,
            parity=parity,
            adjoint=self.adjoint,
            block=self.block,
            native=self.native,
        )


def check_params(model, params):
    """Raise a ValueError if ``params`` lacks the group a system of ``model`` needs."""
    for system in model.systems:
        group = system.params_group
        if object.__getattribute__(params, group) is None:
            raise ValueError(
                f"the model has a {type(system).__name__} but Params has no {group} "
                f"parameters; build them with make_params(dim, {group}=True, ...)"
            )


def check_system_params(model, params):
    """Each system's own refusal of concrete ``params`` (its optional ``check_params``,
    e.g. :meth:`sphjax.RigidSystem.check_params`); the drivers call it before the first
    step, outside any trace."""
    for system in model.systems:
        if hasattr(system, "check_params"):
            system.check_params(params)


def evaluate(state: State, neighbors: Neighbors, model, params, density_step=None) -> State:
    """Rates of change of ``state`` (eqs. 5, 10-12 for fluids; 14-19 for solids).

    ``density_step``: with continuity density (eq. 11), first advance the density by
    ``density_step * Drho/Dt`` evaluated at the given positions and velocities, then
    compute pressure and accelerations from the new density.  The integrator passes
    ``dt`` here, which staggers density and velocity in time (density at whole steps,
    velocity at half steps), the stable leapfrog for the acoustic system; it also adds
    the transport-velocity stress of the drift just taken.  ``None`` evaluates the plain
    rates (the ODE right-hand side).

    Called with concrete arrays outside any trace (``jit``, ``grad``, ``vmap``), it runs
    as one compiled program, kept per model and shapes, rather than operation by
    operation (some 450 small programs, about 20 s on two CPU cores, for a rigid body in
    a tank); inside a trace it is part of the caller's program.
    """
    if concrete_call(state, neighbors, params, density_step):
        return _evaluate_compiled(state, neighbors, params, density_step, model=model)
    return _evaluate(state, neighbors, model, params, density_step)


def _evaluate(state: State, neighbors: Neighbors, model, params, density_step=None) -> State:
    """:func:`evaluate` itself (traced into the caller's program)."""
    ctx = Context.of(model, params)
    views = update_stage(state, neighbors, model, params, density_step, ctx)
    return _assemble(state, views, interaction_stage(views, neighbors, model, ctx))


@functools.partial(jax.jit, static_argnames="model")
def _evaluate_compiled(state, neighbors, params, density_step, *, model):
    return _evaluate(state, neighbors, model, params, density_step)


def update_stage(state: State, neighbors: Neighbors, model, params, density_step=None, ctx=None):
    """Stage 1: each system's fields after its update (``system.update``), in the order of
    their ``stage`` (fluids, then walls, then solids).  Returns one dict per system
    (``x, v, m, rho`` and what its update adds: fluid ``p, drho``; wall ``p, rho,
    v_viscous``; solid ``L0, F, P, PL0``)."""
    check_params(model, params)
    if ctx is None:
        ctx = Context.of(model, params)
    ctx = dataclasses.replace(ctx, reference=neighbors.reference)
    pairs, blocks = reference_pairs(neighbors), neighbors.blocks
    views = [
        system.view(state, slice(*block), density_step)
        for system, block in zip(model.systems, blocks, strict=True)
    ]
    for i in sorted(range(len(model.systems)), key=lambda i: model.systems[i].stage):
        if _size(blocks[i]):
            views[i] = model.systems[i].update(i, views, model.systems, pairs, ctx, density_step)
    return [_named(view) for view in views]


def _named(view):
    """The update stage's per-particle outputs, named for the checkpoint policy."""
    named = ("rho", "p", "v_viscous", "PL0", "PL0q", "F")
    return {k: checkpoint_name(v, UPDATE_FIELDS) if k in named else v for k, v in view.items()}


def interaction_stage(views, neighbors: Neighbors, model, ctx):
    """Stage 2: ``(acceleration, shift)`` of each system, summed over its interactions,
    gravity included (walls excepted; clamped solid particles get none)."""
    neighbors = dataclasses.replace(neighbors, pairs=reference_pairs(neighbors))
    blocks, dtype = neighbors.blocks, views[0]["x"].dtype
    rates = []
    for i, system in enumerate(model.systems):
        n = _size(blocks[i])
        acceleration = jnp.zeros((n, model.dim), dtype)
        shift = jnp.zeros_like(acceleration)
        for j, other in enumerate(model.systems):
            interaction = INTERACTIONS.get((type(system), type(other)))
            if interaction is None or (i, j) not in neighbors.pairs or not n:
                continue
            if not _size(blocks[j]):
                continue
            out = interaction(system, views[i], other, views[j], neighbors.pairs[(i, j)], ctx)
            acceleration = acceleration + out["a"]
            if "shift" in out:
                shift = shift + out["shift"]
        rates.append((system.body_acceleration(views[i], acceleration, ctx.params), shift))
    return rates


def _size(block):
    return block[1] - block[0]


def _assemble(state: State, views, rates) -> State:
    acceleration = jnp.concatenate([a for a, _ in rates], axis=0)
    shift = jnp.concatenate([s for _, s in rates], axis=0)

    def field(name):
        return jnp.concatenate([v.get(name, jnp.zeros_like(v["rho"])) for v in views])

    return state.replace(
        acceleration=acceleration,
        density_rate=field("drho"),
        density=field("rho"),
        pressure=field("p"),
        shift_acceleration=shift,
    )
