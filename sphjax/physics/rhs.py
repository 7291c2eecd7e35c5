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
(:func:`neighbor_pairs`): the current configuration for fluid and walls, split from one
jax-md cell list, and the reference configuration within a solid.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.ad_checkpoint import checkpoint_name

from sphjax._host import concrete_call, is_traced
from sphjax.core.neighbors import (
    NeighborSearch,
    capacity,
    compact_rows,
    measured_capacity,
    measured_members,
    measured_support,
    reference_neighbors,
    split_list,
    support_list,
)
from sphjax.core.pytree import pytree_dataclass
from sphjax.core.space import displacement_fn
from sphjax.core.state import State
from sphjax.physics import pairs as pairs_module
from sphjax.physics.interactions import INTERACTIONS, UPDATE_PAIRS
from sphjax.physics.pairs import Geometry, PairList

NEIGHBOR_IDX = "sphjax_neighbor_idx"
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


@pytree_dataclass(
    static=("blocks", "union", "capacities", "member_capacities", "support_capacities")
)
class Neighbors:
    """Neighbour data of one simulation.

    Attributes:
      search: the jax-md dense list over the particles of the systems that interact in
        the current configuration (``None`` when there are none).
      pairs: ``{(i, j): PairList}`` for every pair of systems of :func:`neighbor_pairs`.
      overflow: True when a split list ran out of room.
      blocks: each system's ``(start, stop)`` in the State.
      union: ``(start, stop)`` of the particles in ``search``.
      capacities: ``((i, j), width)`` of each split list.
      member_capacities: ``((i, j), M)`` for the lists whose rows are compacted to the
        ``M`` particles of system ``i`` that have neighbours in system ``j`` at all (a
        fluid against its walls: :attr:`PairList.members`).
      reference: ``None``, or ``{i: fields}`` the reference-configuration quantities of
        each solid ``i`` (its correction matrix ``L0`` and the pair geometry of its list,
        ``geometry``), computed once per run from the initial State by
        :func:`with_reference`; ``None``: each evaluation computes them.
      support_capacities: ``((i, i), width)`` of the lists kept at two levels: ``skin``
        holds the Verlet list (neighbours within the support plus the skin, rebuilt
        rarely), ``pairs`` those within ``(1 + SUPPORT_SKIN)`` times the support radius,
        compacted from it (:func:`sphjax.core.neighbors.support_list`) whenever it is
        rebuilt or a particle has moved half of that small skin; every pair sum runs
        over them.
      skin: ``{(i, i): PairList}`` the skin level of those lists.
      support_origin: ``[N, d]`` the positions at which they were last compacted.
      counts: ``[len(capacities) + len(member_capacities)]`` the most neighbours a row of
        each split list has had since the allocation, then the most rows with neighbours
        each compacted list has had (:func:`split_counts`): what a re-allocation needs.
    """

    search: object
    pairs: dict
    overflow: jax.Array
    blocks: tuple
    union: tuple | None
    capacities: tuple
    member_capacities: tuple = ()
    reference: dict | None = None
    support_capacities: tuple = ()
    skin: dict | None = None
    support_origin: jax.Array | None = None
    counts: jax.Array | None = None


#: compact a list's rows when at most this fraction of them has neighbours
_COMPACT_BELOW = 0.6


_SEARCHES: dict = {}

#: the support lists' own skin, a fraction of the support radius: they hold the
#: neighbours within ``(1 + SUPPORT_SKIN) cutoff`` and are compacted again from the Verlet
#: list when a particle has moved half of it (or the Verlet list was rebuilt)
SUPPORT_SKIN = 0.1


def neighbor_search(model) -> NeighborSearch:
    """The jax-md search of ``model`` (one per Model and float precision)."""
    key = (model, bool(jax.config.jax_enable_x64))
    if key not in _SEARCHES:
        _SEARCHES[key] = NeighborSearch(model, x64=key[1])
    return _SEARCHES[key]


def _current(model):
    """Systems in the current-configuration search: those that interact in the current
    configuration, and those with a pair against one of them (a solid next to a fluid;
    its own pairs stay in the reference configuration)."""
    own = {i for i, s in enumerate(model.systems) if s.current_configuration}
    cross = {
        k for i, j in neighbor_pairs(model) if i != j and (i in own or j in own) for k in (i, j)
    }
    return sorted(own | cross)


def _searched_pair(model, i, j) -> bool:
    """Whether the list of systems ``i`` against ``j`` comes from the current search."""
    return i != j or model.systems[i].current_configuration


def _local(block, union):
    return (block[0] - union[0], block[1] - union[0])


def build_neighbors(
    state: State,
    model,
    extra_capacity: int = 0,
    compact_rows: bool = False,
    margin: float | None = None,
    support: bool | None = None,
    at_least: ListSizes | None = None,
) -> Neighbors:
    """Allocate neighbour data for concrete ``state`` (outside ``jit``).

    ``compact_rows``: a list whose rows mostly have no neighbours (a fluid against its
    walls) covers only the rows that do (:attr:`PairList.members`), sized from their
    count now; when more rows gain neighbours the list overflows, which the chunked
    driver answers by re-allocating, but a traced run (``grad``, ``jit``) cannot, so
    only the chunked driver asks for it.

    ``margin``: ``None`` sizes every list ``Model.neighbor_capacity`` times its largest
    neighbour count now; a number sizes it that count times ``1 + margin`` (the chunked
    driver, which re-allocates on overflow, asks for a small one).

    ``support``: keep a system's list with itself at two levels, the Verlet list and the
    neighbours within ``(1 + SUPPORT_SKIN)`` times the support radius compacted from it
    (:attr:`Neighbors.support_capacities`), sized like the others from the count now.
    ``None``: only for lists sized by ``Model.neighbor_capacity`` (``margin=None``, the
    traced runs, whose Verlet lists hold about 60 % more slots than neighbours in the
    support; measured on the 10,000-particle Taylor-Green: reverse mode about 15 %
    cheaper).  The chunked driver's lists are already tight, and there the compaction
    costs about what it saves.

    ``at_least``: lists no smaller than these :class:`ListSizes` (same model): the chunked
    driver passes the sizes measured where a chunk overflowed, so that one re-allocation
    is enough.
    """
    floor = at_least if at_least is not None else ListSizes(0, {}, {})
    blocks = system_blocks(state.kind, model)
    wanted = neighbor_pairs(model)
    current = [i for i in _current(model) if blocks[i][1] > blocks[i][0]]
    search, union, capacities = None, None, []
    multiplier = model.neighbor_capacity if margin is None else 1.0 + margin
    if current:
        union = (blocks[current[0]][0], blocks[current[-1]][1])
        search = neighbor_search(model).allocate(
            state.position[union[0] : union[1]], extra_capacity, margin, floor.search
        )
        for i, j in wanted:
            if i in current and j in current and len(current) > 1 and _searched_pair(model, i, j):
                width = measured_capacity(
                    search.idx,
                    _local(blocks[i], union),
                    _local(blocks[j], union),
                    multiplier,
                    extra_capacity,
                )
                width = max(width, floor.widths.get((i, j), 0))
                capacities.append(((i, j), min(width, capacity(search))))
    member_capacities = []
    for (i, j), _ in capacities if compact_rows else ():
        if i < j:
            members = measured_members(
                search.idx,
                _local(blocks[i], union),
                _local(blocks[j], union),
                model.neighbor_capacity,
                extra_capacity,
            )
            members = max(members, floor.members.get((i, j), 0))
            if members < _COMPACT_BELOW * _size(blocks[i]):
                member_capacities.append(((i, j), members))
    neighbors = Neighbors(
        search=search,
        pairs={},
        overflow=np.asarray(False),
        blocks=blocks,
        union=union,
        capacities=tuple(capacities),
        member_capacities=tuple(member_capacities),
    )
    pair_lists = _split(neighbors, model)
    for i, j in wanted:
        system = model.systems[i]
        if not system.current_configuration and i == j:
            start, stop = blocks[i]
            members = np.arange(start, stop)
            idx = reference_neighbors(state.reference_position, members, model)
            n = state.position.shape[0]
            local = np.where(idx < n, idx - start, stop - start).astype(np.int32)
            pair_lists[(i, j)] = PairList(jnp.asarray(local), None, stop - start, stop - start)
    support_capacities = []
    if support is None:
        support = margin is None
    for key in pair_lists if support else ():
        i, j = key
        if i == j and model.systems[i].current_configuration:
            skin_idx = pair_lists[key].idx
            x = state.position[blocks[i][0] : blocks[i][1]]
            width = measured_support(
                skin_idx, x, x, model.domain, _support_radius(model), multiplier, extra_capacity
            )
            if width < skin_idx.shape[1]:
                support_capacities.append((key, width))
    counts = split_counts(neighbors)
    neighbors = dataclasses.replace(
        neighbors,
        pairs=pair_lists,
        overflow=_counts_overflow(counts, neighbors),
        support_capacities=tuple(support_capacities),
        counts=counts,
    )
    supported, overflow = _support(pair_lists, state.position, neighbors, model)
    return dataclasses.replace(
        neighbors,
        pairs={**pair_lists, **supported},
        skin={k: pair_lists[k] for k in supported} or None,
        overflow=neighbors.overflow | overflow,
        support_origin=jnp.asarray(state.position) if supported else None,
    )


class ListSizes(NamedTuple):
    """The sizes a neighbour allocation chose: slots per particle of the search, width
    per pair of systems, compacted rows per pair (:func:`build_neighbors`)."""

    search: int
    widths: dict
    members: dict


def list_sizes(neighbors: Neighbors) -> ListSizes:
    """The :class:`ListSizes` of ``neighbors``; a list not compacted counts all its rows
    (so that an allocation held to it does not compact it either)."""
    search = 0 if neighbors.search is None else capacity(neighbors.search)
    members = {(i, j): _size(neighbors.blocks[i]) for (i, j), _ in neighbors.capacities if i < j}
    members.update(neighbors.member_capacities)
    return ListSizes(search, dict(neighbors.capacities), members)


def widest(*sizes: ListSizes) -> ListSizes:
    """Component-wise the largest of ``sizes``."""

    def most(dicts):
        return {k: max(d.get(k, 0) for d in dicts) for d in dicts for k in d}

    return ListSizes(
        max(s.search for s in sizes),
        most([s.widths for s in sizes]),
        most([s.members for s in sizes]),
    )


def _support_radius(model) -> float:
    return model.cutoff * (1.0 + SUPPORT_SKIN)


def _support(pair_lists: dict, position, neighbors: Neighbors, model):
    """The lists of ``neighbors.support_capacities`` compacted to the support at
    ``position`` from their skin level in ``pair_lists``, and whether one overflowed."""
    if not neighbors.support_capacities:
        return {}, np.asarray(False)
    out, flags = {}, []
    for key, width in neighbors.support_capacities:
        start, stop = neighbors.blocks[key[0]]
        x = position[start:stop]
        skin = pair_lists[key]
        idx, overflow = support_list(skin.idx, x, x, model.domain, _support_radius(model), width)
        out[key] = dataclasses.replace(skin, idx=idx)
        flags.append(overflow)
    return out, jnp.any(jnp.stack(flags))


def _split(neighbors: Neighbors, model) -> dict:
    """The current-configuration PairLists from ``neighbors.search``."""
    if neighbors.search is None:
        return {}
    blocks, union = neighbors.blocks, neighbors.union
    widths = dict(neighbors.capacities)
    idx = neighbors.search.idx
    members = dict(neighbors.member_capacities)
    out = {}
    for i, j in neighbor_pairs(model):
        if (i, j) in widths:
            n_i, n_j = blocks[i][1] - blocks[i][0], blocks[j][1] - blocks[j][0]
            forward, _ = split_list(
                idx, _local(blocks[i], union), _local(blocks[j], union), widths[(i, j)]
            )
            backward, _ = split_list(
                idx, _local(blocks[j], union), _local(blocks[i], union), widths[(j, i)]
            )
            if (i, j) in members:
                rows, forward, position, _ = compact_rows(forward, n_j, members[(i, j)])
                out[(i, j)] = PairList(forward, position[backward], n_i, n_j, members=rows)
            elif (j, i) in members:
                rows, backward, position, _ = compact_rows(backward, n_i, members[(j, i)])
                out[(i, j)] = PairList(forward, backward, n_i, n_j, transpose_members=rows)
            else:
                out[(i, j)] = PairList(forward, backward, n_i, n_j)
        elif i == j and model.systems[i].current_configuration and blocks[i][1] > blocks[i][0]:
            n = blocks[i][1] - blocks[i][0]
            out[(i, j)] = PairList(idx.astype(jnp.int32), None, n, n)
    return out


def _current_keys(neighbors: Neighbors, model):
    return {k for k in neighbors.pairs if _searched_pair(model, *k)}


def split_counts(neighbors: Neighbors) -> jax.Array:
    """The most neighbours a row of each split list has in ``neighbors.search`` now (in
    the order of ``neighbors.capacities``), then how many rows of each compacted list
    have neighbours (order of ``neighbors.member_capacities``)."""
    idx = None if neighbors.search is None else neighbors.search.idx
    xp = jnp if is_traced(idx) else np  # numpy at an allocation: nothing to compile
    if idx is None:
        return np.zeros(0, np.int32)
    blocks, union, idx = neighbors.blocks, neighbors.union, xp.asarray(idx)

    def inside(i, j):
        rows, cols = _local(blocks[i], union), _local(blocks[j], union)
        block = idx[rows[0] : rows[1]]
        return (block >= cols[0]) & (block < cols[1])

    widths = [xp.max(xp.sum(inside(i, j), axis=1), initial=0) for (i, j), _ in neighbors.capacities]
    rows = [xp.sum(xp.any(inside(i, j), axis=1)) for (i, j), _ in neighbors.member_capacities]
    return xp.asarray(widths + rows, np.int32).reshape(-1)


def _counts_overflow(counts, neighbors: Neighbors):
    """Whether ``counts`` (:func:`split_counts`) exceed the capacities of ``neighbors``."""
    sizes = [w for _, w in neighbors.capacities] + [m for _, m in neighbors.member_capacities]
    xp = jnp if is_traced(counts) else np
    return xp.any(counts > np.asarray(sizes, np.int32).reshape(-1))


def with_reference(state: State, neighbors: Neighbors, model) -> Neighbors:
    """``neighbors`` with each solid's reference-configuration quantities computed from
    ``state``: the pair geometry of its list (``X_ab``, ``|X_ab|``, ``W0``, ``grad0 W``;
    :attr:`~sphjax.physics.pairs.PairList.geometry`) and ``L0`` (eq. 15).

    They depend only on the reference positions and volumes, which no step changes, so a
    run computes them once (:func:`sphjax.simulate`) instead of at every evaluation; as
    they are computed from ``state`` (traced under ``jax.grad``), derivatives through them
    are those of the per-step computation.
    """
    ctx = Context(None, Geometry.of(model), model.pair_adjoint, model.pair_block)
    reference = {}
    for i, system in enumerate(model.systems):
        if not system.current_configuration and _size(neighbors.blocks[i]):
            view = system.view(state, slice(*neighbors.blocks[i]))
            reference[i] = system.reference_quantities(view, neighbors.pairs[(i, i)], ctx)
    return dataclasses.replace(neighbors, reference=reference or None)


def reference_pairs(neighbors: Neighbors) -> dict:
    """``neighbors.pairs`` with each solid's own list carrying the pair geometry of its
    reference configuration (:func:`with_reference`), so that its pair sums read it."""
    pairs = dict(neighbors.pairs)
    for i, fields in (neighbors.reference or {}).items():
        if "geometry" in fields:
            pairs[(i, i)] = pairs[(i, i)].replace(geometry=fields["geometry"])
    return pairs


def update_neighbors(position, neighbors: Neighbors, model, rebuild=False) -> Neighbors:
    """Neighbours at ``position`` (inside ``jit``): the jax-md list is updated (rebuilt
    when a particle moved half the skin, or always with ``rebuild``) and, when it was
    rebuilt, split again into the lists per pair of systems; the lists kept at two levels
    are compacted again when needed (:func:`_update_support`)."""
    if neighbors.search is None:
        return neighbors
    search = neighbor_search(model)
    union = neighbors.union
    x = position[union[0] : union[1]]
    old = neighbors.search
    new = (search.rebuild if rebuild else search.update)(x, old)
    new = new.set(idx=checkpoint_name(new.idx, NEIGHBOR_IDX))
    refreshed = dataclasses.replace(neighbors, search=new)
    skin = neighbors.skin or {}
    rebuilt = True if rebuild else jnp.any(new.reference_position != old.reference_position)
    counts = neighbors.counts
    if not neighbors.capacities:
        current, overflow = _split(refreshed, model), neighbors.overflow
    else:

        def split(_):
            return _split(refreshed, model), split_counts(refreshed)

        def keep(_):
            keys = _current_keys(neighbors, model)
            current = {k: skin.get(k, v) for k, v in neighbors.pairs.items() if k in keys}
            return current, neighbors.counts

        if rebuild:
            current, counts = split(None)
        else:
            current, counts = jax.lax.cond(rebuilt, split, keep, None)
        current = jax.tree_util.tree_map(lambda a: checkpoint_name(a, NEIGHBOR_IDX), current)
        counts = jnp.maximum(counts, neighbors.counts)
        overflow = _counts_overflow(counts, neighbors) | neighbors.overflow
    refreshed = dataclasses.replace(
        refreshed, pairs={**neighbors.pairs, **current}, overflow=overflow, counts=counts
    )
    if not neighbors.support_capacities:
        return refreshed
    return _update_support(position, refreshed, current, neighbors.pairs, rebuilt, model)


def _update_support(position, neighbors: Neighbors, skin: dict, last: dict, rebuilt, model):
    """The support lists at ``position``: compacted again from the Verlet lists ``skin``
    when those were rebuilt or a particle has moved more than half the support lists'
    own skin since they were last compacted; else the ``last`` ones are kept."""
    moved = displacement_fn(model.domain)(position, neighbors.support_origin)
    half_skin = 0.5 * SUPPORT_SKIN * model.cutoff
    far = jnp.max(jnp.sum(moved * moved, axis=-1), initial=0.0) > half_skin**2
    keys = [key for key, _ in neighbors.support_capacities]

    def compact(_):
        supported, overflow = _support(skin, position, neighbors, model)
        return supported, overflow, position

    def keep(_):
        return {k: last[k] for k in keys}, jnp.asarray(False), neighbors.support_origin

    supported, overflow, origin = jax.lax.cond(rebuilt | far, compact, keep, None)
    supported = jax.tree_util.tree_map(lambda a: checkpoint_name(a, NEIGHBOR_IDX), supported)
    return dataclasses.replace(
        neighbors,
        pairs={**neighbors.pairs, **supported},
        skin={k: skin[k] for k in keys},
        overflow=neighbors.overflow | overflow,
        support_origin=origin,
    )


def overflowed(neighbors: Neighbors):
    """True when any neighbour list of ``neighbors`` ran out of room."""
    if neighbors.search is None:
        return jnp.asarray(False)
    return jnp.asarray(neighbors.search.did_buffer_overflow) | neighbors.overflow


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
    ctx = Context(params, Geometry.of(model), model.pair_adjoint, model.pair_block)
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
        ctx = Context(params, Geometry.of(model), model.pair_adjoint, model.pair_block)
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
