"""Neighbours: a geometry-only search, the lists per pair of systems, one capacity policy.

Three layers, each a module:

- :mod:`~sphjax.neighbors.search`: the jax-md cell-list search, which needs a
  :class:`SearchGeometry` only (support radius, Verlet skin, domain, capacity
  multiplier, and whether its rebuild is the compiled cell list of :mod:`sphjax.native`),
  and the reference-configuration search of a solid;
- :mod:`~sphjax.neighbors.lists`: :class:`Neighbors`, one :class:`PairList` per ordered
  pair of interacting systems, split from the search whenever it is rebuilt, allocated
  for a :class:`ListPlan` (which pairs, which systems follow the particles) outside
  ``jit`` (:func:`allocate`) and updated inside it (:func:`update_neighbors`);
- :mod:`~sphjax.neighbors.capacity`: how lists are sized, what happens when one
  overflows (a concrete run re-allocates and repeats its chunk, a traced run stops with a
  :class:`NeighborOverflowError` naming ``Model.neighbor_capacity``), and
  :func:`is_neighbor_overflow`, the one test of an error every caller uses.

Nothing here imports the physics: which systems interact is the physics' decision
(:func:`sphjax.physics.rhs.neighbor_plan`, :func:`sphjax.build_neighbors`), handed over as
a hashable :class:`ListPlan`.
"""

from __future__ import annotations

from sphjax.neighbors.capacity import (
    NEIGHBOR_MARGIN,
    OVERFLOW_GROWTH,
    OVERFLOW_MIN_SIZE,
    ListSizes,
    NeighborOverflowError,
    NeighborOverflowWarning,
    grown,
    grown_multiplier,
    is_neighbor_overflow,
    overflow_message,
    widest,
)
from sphjax.neighbors.lists import (
    NEIGHBOR_IDX,
    SUPPORT_SKIN,
    ListPlan,
    Neighbors,
    PairList,
    allocate,
    list_sizes,
    needed_sizes,
    overflowed,
    reference_pairs,
    update_neighbors,
)
from sphjax.neighbors.search import NeighborSearch, SearchGeometry, neighbor_search

__all__ = [
    "NEIGHBOR_IDX",
    "NEIGHBOR_MARGIN",
    "OVERFLOW_GROWTH",
    "OVERFLOW_MIN_SIZE",
    "SUPPORT_SKIN",
    "ListPlan",
    "ListSizes",
    "NeighborOverflowError",
    "NeighborOverflowWarning",
    "NeighborSearch",
    "Neighbors",
    "PairList",
    "SearchGeometry",
    "allocate",
    "grown",
    "grown_multiplier",
    "is_neighbor_overflow",
    "list_sizes",
    "needed_sizes",
    "neighbor_search",
    "overflow_message",
    "overflowed",
    "reference_pairs",
    "update_neighbors",
    "widest",
]
