"""Neighbour lists per pair of systems: allocated outside ``jit``, updated inside.

The systems of a simulation own contiguous blocks of the particles (``blocks``: each
system's ``(start, stop)``); which ordered pairs of them need a list, and which systems'
lists follow the particles, is a :class:`ListPlan` (hashable: the physics decides it,
:func:`sphjax.physics.rhs.neighbor_plan`; nothing of the physics is imported here).  The
systems whose lists follow the particles (fluid, walls) share one jax-md search
(:mod:`sphjax.neighbors.search`); whenever it is rebuilt it is split into one
:class:`PairList` per pair of systems, each sized from the neighbour counts measured at
allocation (:mod:`sphjax.neighbors.capacity`), so pairs that do not interact (wall-wall)
are never formed.  A system whose lists do not follow the particles (a solid) has its
reference-configuration list, found once.

:func:`allocate` builds the lists for a concrete State; :func:`update_neighbors` brings
them to new positions inside ``jit``; :func:`overflowed` says whether one ran out of room,
which the driver answers by the capacity policy (:mod:`sphjax.neighbors.capacity`).
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
from jax.ad_checkpoint import checkpoint_name

from sphjax._host import is_traced
from sphjax.core.pytree import pytree_dataclass
from sphjax.core.space import displacement_fn
from sphjax.neighbors.capacity import NEIGHBOR_MARGIN, ListSizes
from sphjax.neighbors.search import (
    SearchGeometry,
    capacity,
    compact_rows,
    measured_capacity,
    measured_members,
    measured_support,
    neighbor_search,
    reference_neighbors,
    split_list,
    support_list,
)

#: name of the neighbour indices that reverse mode keeps instead of recomputing them
#: (see ``sphjax.simulate``)
NEIGHBOR_IDX = "sphjax_neighbor_idx"


@dataclasses.dataclass(frozen=True)
class ListPlan:
    """Which neighbour lists a simulation has (hashable, static).

    Attributes:
      geometry: the :class:`~sphjax.neighbors.search.SearchGeometry` of the search.
      current: per system, whether its lists follow the particles (the current
        configuration: fluid, walls) or stay in the reference configuration (a solid's
        list with itself, found once).
      pairs: the ordered pairs ``(i, j)`` of systems that need a list of ``i`` against
        ``j`` (with each pair its transpose).
    """

    geometry: SearchGeometry
    current: tuple[bool, ...]
    pairs: tuple[tuple[int, int], ...]


@pytree_dataclass(static=("n_rows", "n_cols"))
class PairList:
    """Neighbours of the particles of one system (rows) among those of another (columns).

    Attributes:
      idx: ``[n_rows, K]`` column indices, padded with ``n_cols`` (``[M, K]`` for the
        ``members`` only, when given).
      transpose: ``[n_cols, K']`` row indices of each column particle's neighbours, padded
        with ``n_rows`` (the same pairs seen from the columns), or ``None`` when rows and
        columns are the same particles (the list is then its own transpose).  With
        ``members`` its entries are positions in ``members`` (padded with ``M``); with
        ``transpose_members`` its rows are those columns only.
      members: ``None``, or ``[M]`` the rows that have neighbours at all (padded with
        ``n_rows``): a fluid's list against a wall covers only the fluid particles near
        the wall, so the sum costs ``M`` rows, not ``n_rows``.
      transpose_members: ``None``, or ``[M']`` the columns the rows of ``transpose`` are
        (padded with ``n_cols``).
      geometry: ``None``, or the pair geometry (``[n_rows, K, ...]``; opaque here:
        :class:`sphjax.physics.pairs.PairGeometry`) of a list within one system whose
        positions never change (a solid's reference configuration): computed once per
        run (:func:`sphjax.physics.pairs.stored_geometry`), pair
        sums over the list read it instead of computing it at every evaluation, and
        reverse mode returns its cotangent (to the positions it was computed from).
    """

    idx: jax.Array
    transpose: jax.Array | None
    n_rows: int
    n_cols: int
    members: jax.Array | None = None
    transpose_members: jax.Array | None = None
    geometry: object | None = None


@dataclasses.dataclass(frozen=True)
class Neighbors:
    """Neighbour data of one simulation.

    Attributes:
      search: the jax-md dense list over the particles of the systems that interact in
        the current configuration (``None`` when there are none).
      pairs: ``{(i, j): PairList}`` for every pair of systems of ``plan.pairs``.
      overflow: True when a split list ran out of room.
      plan: the :class:`ListPlan` the lists were allocated for.
      blocks: each system's ``(start, stop)`` in the State.
      union: ``(start, stop)`` of the particles in ``search``.
      capacities: ``((i, j), width)`` of each split list.
      member_capacities: ``((i, j), M)`` for the lists whose rows are compacted to the
        ``M`` particles of system ``i`` that have neighbours in system ``j`` at all (a
        fluid against its walls: :attr:`PairList.members`).
      reference: ``None``, or ``{i: fields}`` the reference-configuration quantities of
        each solid ``i`` (its correction matrix ``L0`` and the pair geometry of its list,
        ``geometry``), computed once per run from the initial State by
        :func:`sphjax.physics.rhs.with_reference`; ``None``: each evaluation computes
        them.
      support_capacities: ``((i, i), width)`` of the lists kept at two levels: ``skin``
        holds the Verlet list (neighbours within the support plus the skin, rebuilt
        rarely), ``pairs`` those within ``(1 + SUPPORT_SKIN)`` times the support radius,
        compacted from it (:func:`sphjax.neighbors.search.support_list`) whenever it is
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
    plan: ListPlan
    blocks: tuple
    union: tuple | None
    capacities: tuple
    member_capacities: tuple = ()
    reference: dict | None = None
    support_capacities: tuple = ()
    skin: dict | None = None
    support_origin: jax.Array | None = None
    counts: jax.Array | None = None

    def replace(self, **changes) -> Neighbors:
        return dataclasses.replace(self, **changes)


# Neighbors as a pytree.  A system alone in the search (one fluid, say) has the search's
# list itself as its list (:func:`_split`): as a pytree it is one leaf, its PairList made
# again from the search's list when the tree is rebuilt.  Two leaves would be two buffers
# of XLA, and a loop of steps would copy the list from one into the other every step
# (8 MB a step at 40,000 particles).
_NEIGHBORS_STATIC = (
    "plan",
    "blocks",
    "union",
    "capacities",
    "member_capacities",
    "support_capacities",
)
_NEIGHBORS_DATA = ("search", "pairs", "overflow", "reference", "skin", "support_origin", "counts")


def _search_list(idx, block) -> PairList:
    """The list of a system alone in the search (rows ``block``): the search's own list
    ``idx`` (:func:`_split`, and :func:`_unflatten_neighbors` making it again, where
    ``idx`` may be any leaf JAX puts in a tree: an axis, ``None``; so it is used as is)."""
    n = block[1] - block[0]
    return PairList(idx, None, n, n)


def _search_lists(neighbors: Neighbors) -> tuple:
    """The keys of ``neighbors.pairs`` whose lists are the search's own (:func:`_split`:
    a non-empty system in the current configuration whose list is neither split,
    compacted nor kept at two levels)."""
    if neighbors.search is None:
        return ()
    kept = dict(neighbors.capacities) | dict(neighbors.member_capacities)
    kept |= dict(neighbors.support_capacities)
    blocks = neighbors.blocks
    return tuple(
        (i, j)
        for i, j in neighbors.pairs
        if i == j
        and neighbors.plan.current[i]
        and blocks[i][1] > blocks[i][0]
        and (i, j) not in kept
    )


def _flatten_neighbors(neighbors: Neighbors):
    derived = _search_lists(neighbors)
    pairs = {k: v for k, v in neighbors.pairs.items() if k not in derived}
    data = [pairs if name == "pairs" else getattr(neighbors, name) for name in _NEIGHBORS_DATA]
    static = tuple(getattr(neighbors, name) for name in _NEIGHBORS_STATIC)
    return data, (static, derived)


def _unflatten_neighbors(aux, data) -> Neighbors:
    static, derived = aux
    fields = dict(zip(_NEIGHBORS_DATA, data, strict=True))
    fields.update(zip(_NEIGHBORS_STATIC, static, strict=True))
    pairs = dict(fields["pairs"])
    for i, j in derived:
        pairs[(i, j)] = _search_list(fields["search"].idx, fields["blocks"][i])
    fields["pairs"] = {k: pairs[k] for k in sorted(pairs)}
    return Neighbors(**fields)


jax.tree_util.register_pytree_node(Neighbors, _flatten_neighbors, _unflatten_neighbors)


#: compact a list's rows when at most this fraction of them has neighbours
_COMPACT_BELOW = 0.6


#: the support lists' own skin, a fraction of the support radius: they hold the
#: neighbours within ``(1 + SUPPORT_SKIN) cutoff`` and are compacted again from the Verlet
#: list when a particle has moved half of it (or the Verlet list was rebuilt)
SUPPORT_SKIN = 0.1


def _current(plan: ListPlan):
    """Systems in the current-configuration search: those that interact in the current
    configuration, and those with a pair against one of them (a solid next to a fluid;
    its own pairs stay in the reference configuration)."""
    own = {i for i, current in enumerate(plan.current) if current}
    cross = {k for i, j in plan.pairs if i != j and (i in own or j in own) for k in (i, j)}
    return sorted(own | cross)


def _searched_pair(plan: ListPlan, i, j) -> bool:
    """Whether the list of systems ``i`` against ``j`` comes from the current search."""
    return i != j or plan.current[i]


def _local(block, union):
    return (block[0] - union[0], block[1] - union[0])


def allocate(
    state,
    blocks: tuple[tuple[int, int], ...],
    plan: ListPlan,
    extra_capacity: int = 0,
    compact_rows: bool = False,
    margin: float | None = None,
    support: bool | None = None,
    at_least: ListSizes | None = None,
) -> Neighbors:
    """Allocate neighbour data for concrete ``state`` (outside ``jit``): its
    ``position`` and, for lists in the reference configuration, ``reference_position``;
    ``blocks`` each system's ``(start, stop)`` in it.

    ``compact_rows``: a list whose rows mostly have no neighbours (a fluid against its
    walls) covers only the rows that do (:attr:`PairList.members`), sized from their
    count now; when more rows gain neighbours the list overflows, which the chunked
    driver answers by re-allocating, but a traced run (``grad``, ``jit``) cannot, so
    only the chunked driver asks for it.

    ``margin``: ``None`` sizes every list ``plan.geometry.capacity_multiplier``
    (``Model.neighbor_capacity``) times its largest neighbour count now; a number sizes
    it that count times ``1 + margin`` (the chunked driver, which re-allocates on
    overflow, asks for a small one), and a list between two systems that is empty now
    (a fluid against an obstacle it has not reached) at least ``OVERFLOW_MIN_SIZE``,
    what its first overflow would grow it to
    (:func:`sphjax.neighbors.capacity.pair_sized`).

    ``support``: keep a system's list with itself at two levels, the Verlet list and the
    neighbours within ``(1 + SUPPORT_SKIN)`` times the support radius compacted from it
    (:attr:`Neighbors.support_capacities`), sized like the others from the count now.
    ``None``: only for lists sized by the multiplier (``margin=None``, the traced runs,
    whose Verlet lists hold about 60 % more slots than neighbours in the
    support; measured on the 10,000-particle Taylor-Green: reverse mode about 15 %
    cheaper).  The chunked driver's lists are already tight, and there the compaction
    costs about what it saves.

    ``at_least``: lists no smaller than these :class:`ListSizes` (same plan): the chunked
    driver passes the sizes measured where a chunk overflowed, so that one re-allocation
    is enough.
    """
    floor = at_least if at_least is not None else ListSizes(0, {}, {})
    geometry, wanted = plan.geometry, plan.pairs
    current = [i for i in _current(plan) if blocks[i][1] > blocks[i][0]]
    search, union, capacities = None, None, []
    multiplier = geometry.capacity_multiplier if margin is None else 1.0 + margin
    if current:
        union = (blocks[current[0]][0], blocks[current[-1]][1])
        search = neighbor_search(geometry).allocate(
            state.position[union[0] : union[1]], extra_capacity, margin, floor.search
        )
        for i, j in wanted:
            if i in current and j in current and len(current) > 1 and _searched_pair(plan, i, j):
                width = measured_capacity(
                    search.idx,
                    _local(blocks[i], union),
                    _local(blocks[j], union),
                    multiplier,
                    extra_capacity,
                    grows=margin is not None,
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
                geometry.capacity_multiplier,
                extra_capacity,
                grows=margin is not None,
            )
            members = max(members, floor.members.get((i, j), 0))
            if members < _COMPACT_BELOW * _size(blocks[i]):
                member_capacities.append(((i, j), members))
    neighbors = Neighbors(
        search=search,
        pairs={},
        overflow=np.asarray(False),
        plan=plan,
        blocks=blocks,
        union=union,
        capacities=tuple(capacities),
        member_capacities=tuple(member_capacities),
    )
    pair_lists = _split(neighbors)
    for i, j in wanted:
        if not plan.current[i] and i == j:
            start, stop = blocks[i]
            members = np.arange(start, stop)
            idx = reference_neighbors(state.reference_position, members, geometry)
            n = state.position.shape[0]
            local = np.where(idx < n, idx - start, stop - start).astype(np.int32)
            pair_lists[(i, j)] = PairList(jnp.asarray(local), None, stop - start, stop - start)
    support_capacities = []
    if support is None:
        support = margin is None
    for key in pair_lists if support else ():
        i, j = key
        if i == j and plan.current[i]:
            skin_idx = pair_lists[key].idx
            x = state.position[blocks[i][0] : blocks[i][1]]
            width = measured_support(
                skin_idx,
                x,
                x,
                geometry.domain,
                _support_radius(geometry),
                multiplier,
                extra_capacity,
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
    supported, overflow = _support(pair_lists, state.position, neighbors)
    return dataclasses.replace(
        neighbors,
        pairs={**pair_lists, **supported},
        skin={k: pair_lists[k] for k in supported} or None,
        overflow=neighbors.overflow | overflow,
        support_origin=jnp.asarray(state.position) if supported else None,
    )


def list_sizes(neighbors: Neighbors) -> ListSizes:
    """The :class:`ListSizes` of ``neighbors``; a list not compacted counts all its rows
    (so that an allocation held to it does not compact it either)."""
    search = 0 if neighbors.search is None else capacity(neighbors.search)
    members = {(i, j): _size(neighbors.blocks[i]) for (i, j), _ in neighbors.capacities if i < j}
    members.update(neighbors.member_capacities)
    return ListSizes(search, dict(neighbors.capacities), members)


def _support_radius(geometry: SearchGeometry) -> float:
    return geometry.cutoff * (1.0 + SUPPORT_SKIN)


def _support(pair_lists: dict, position, neighbors: Neighbors):
    """The lists of ``neighbors.support_capacities`` compacted to the support at
    ``position`` from their skin level in ``pair_lists``, and whether one overflowed."""
    if not neighbors.support_capacities:
        return {}, np.asarray(False)
    out, flags = {}, []
    for key, width in neighbors.support_capacities:
        start, stop = neighbors.blocks[key[0]]
        x = position[start:stop]
        skin = pair_lists[key]
        geometry = neighbors.plan.geometry
        idx, overflow = support_list(
            skin.idx, x, x, geometry.domain, _support_radius(geometry), width
        )
        out[key] = dataclasses.replace(skin, idx=idx)
        flags.append(overflow)
    return out, jnp.any(jnp.stack(flags))


def _split(neighbors: Neighbors) -> dict:
    """The current-configuration PairLists from ``neighbors.search``."""
    if neighbors.search is None:
        return {}
    blocks, union = neighbors.blocks, neighbors.union
    widths = dict(neighbors.capacities)
    idx = neighbors.search.idx
    members = dict(neighbors.member_capacities)
    out = {}
    for i, j in neighbors.plan.pairs:
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
        elif i == j and neighbors.plan.current[i] and blocks[i][1] > blocks[i][0]:
            out[(i, j)] = _search_list(idx, blocks[i])  # (the search's list is int32)
    return out


def _current_keys(neighbors: Neighbors):
    return {k for k in neighbors.pairs if _searched_pair(neighbors.plan, *k)}


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


def reference_pairs(neighbors: Neighbors) -> dict:
    """``neighbors.pairs`` with each solid's own list carrying the pair geometry of its
    reference configuration (:func:`sphjax.physics.rhs.with_reference`), so that its
    pair sums read it."""
    pairs = dict(neighbors.pairs)
    for i, fields in (neighbors.reference or {}).items():
        if "geometry" in fields:
            pairs[(i, i)] = pairs[(i, i)].replace(geometry=fields["geometry"])
    return pairs


def update_neighbors(position, neighbors: Neighbors, rebuild=False) -> Neighbors:
    """Neighbours at ``position`` (inside ``jit``): the jax-md list is updated (rebuilt
    when a particle moved half the skin, or always with ``rebuild``) and, when it was
    rebuilt, split again into the lists per pair of systems; the lists kept at two levels
    are compacted again when needed (:func:`_update_support`)."""
    if neighbors.search is None:
        return neighbors
    search = neighbor_search(neighbors.plan.geometry)
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
        current, overflow = _split(refreshed), neighbors.overflow
    else:

        def split(_):
            return _split(refreshed), split_counts(refreshed)

        def keep(_):
            keys = _current_keys(neighbors)
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
    return _update_support(position, refreshed, current, neighbors.pairs, rebuilt)


def _update_support(position, neighbors: Neighbors, skin: dict, last: dict, rebuilt):
    """The support lists at ``position``: compacted again from the Verlet lists ``skin``
    when those were rebuilt or a particle has moved more than half the support lists'
    own skin since they were last compacted; else the ``last`` ones are kept."""
    geometry = neighbors.plan.geometry
    moved = displacement_fn(geometry.domain)(position, neighbors.support_origin)
    half_skin = 0.5 * SUPPORT_SKIN * geometry.cutoff
    far = jnp.max(jnp.sum(moved * moved, axis=-1), initial=0.0) > half_skin**2
    keys = [key for key, _ in neighbors.support_capacities]

    def compact(_):
        supported, overflow = _support(skin, position, neighbors)
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


def _size(block):
    return block[1] - block[0]


def needed_sizes(neighbors: Neighbors, extra: int, margin: float = NEIGHBOR_MARGIN) -> ListSizes:
    """The split and compacted list sizes for the counts ``neighbors`` met (sized as an
    allocation of the chunked driver with ``margin``, ``Model.neighbor_margin``, sizes
    them from the counts it measures), for :func:`sphjax.neighbors.capacity.grown`."""
    counts = [int(c) for c in np.asarray(neighbors.counts)]
    width = len(neighbors.capacities)
    widths = {
        key: int(math.ceil(c * (1.0 + margin))) + extra
        for (key, _), c in zip(neighbors.capacities, counts[:width], strict=True)
    }
    multiplier = neighbors.plan.geometry.capacity_multiplier
    members = {
        key: int(math.ceil(c * multiplier)) + extra
        for (key, _), c in zip(neighbors.member_capacities, counts[width:], strict=True)
    }
    return ListSizes(0, widths, members)
