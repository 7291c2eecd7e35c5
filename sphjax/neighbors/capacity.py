"""The one capacity policy of the neighbour lists, and its overflow error.

Every list has a fixed capacity, set when it is allocated (outside ``jit``) from the
neighbour counts measured then: the largest count times a multiplier, plus an extra
(:func:`sized`).  Inside ``jit`` a list that runs out of room says so (an overflow flag);
what happens then is one policy:

- a concrete (chunked) run re-allocates: each list that overflowed grows to what it met,
  and at least :data:`OVERFLOW_GROWTH` times its old size and :data:`OVERFLOW_MIN_SIZE`
  (:func:`grown`), and the lost chunk is repeated (:class:`NeighborOverflowWarning`);
- a traced run (``jax.grad``, ``jit``, ``vmap``, the diffrax term) cannot: it stops with a
  :class:`NeighborOverflowError` whose message (:func:`overflow_message`) names the
  setting to raise, ``Model.neighbor_capacity``; a caller that can repeat the whole run
  (a dataset's batch) raises it (:func:`grown_multiplier`) and does.

Every caller recognises an overflow with one function, :func:`is_neighbor_overflow`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

__all__ = [
    "NEIGHBOR_MARGIN",
    "OVERFLOW_GROWTH",
    "OVERFLOW_MIN_SIZE",
    "TRACED_GROWTH",
    "ListSizes",
    "NeighborOverflowError",
    "NeighborOverflowWarning",
    "grown",
    "grown_multiplier",
    "is_neighbor_overflow",
    "overflow_message",
    "pair_sized",
    "sized",
    "widest",
]

#: room above the largest neighbour count in the lists of a concrete (chunked) run, which
#: re-allocates on overflow: the default of ``Model.neighbor_margin``; traced runs (grad,
#: jit) cannot and keep ``Model.neighbor_capacity``
NEIGHBOR_MARGIN = 0.05
#: a list that overflows in the chunked driver grows to at least this factor times its
#: old size, and to at least ``OVERFLOW_MIN_SIZE`` slots (rows) (:func:`grown`)
OVERFLOW_GROWTH = 1.25
OVERFLOW_MIN_SIZE = 16
#: a whole traced run that overflowed is repeated with ``Model.neighbor_capacity`` this
#: many times larger (:func:`grown_multiplier`)
TRACED_GROWTH = 1.5


class NeighborOverflowError(RuntimeError):
    """The neighbour list ran out of room where it cannot be re-allocated.

    Raised from inside a compiled run (a traced ``simulate``, the diffrax term) it reaches
    the caller wrapped in JAX's runtime error, its type lost: :func:`is_neighbor_overflow`
    recognises it either way, by its message's :attr:`MARK`."""

    #: the words every neighbour-overflow message contains
    MARK = "the neighbour list overflowed"


class NeighborOverflowWarning(UserWarning):
    """A concrete run's neighbour list overflowed and was re-allocated (the chunk is
    repeated with wider lists, a new compilation); the results are unaffected."""


def is_neighbor_overflow(error: BaseException) -> bool:
    """Whether ``error`` is a neighbour-list overflow, raised here or from inside a
    compiled computation (where JAX re-raises it as its own runtime error, whose message
    carries :func:`overflow_message`)."""
    return isinstance(error, NeighborOverflowError) or NeighborOverflowError.MARK in str(error)


def overflow_message(where: str) -> str:
    """The message of an overflow ``where`` (e.g. "inside the diffrax vector field") that
    cannot be re-allocated: the setting to raise, and how."""
    return (
        f"{NeighborOverflowError.MARK} {where}, where it cannot be re-allocated; raise "
        "Model.neighbor_capacity (e.g. "
        "case.replace(model=case.model.replace(neighbor_capacity=2.0)))"
    )


def grown_multiplier(neighbor_capacity: float) -> float:
    """``Model.neighbor_capacity`` for repeating a traced run that overflowed."""
    return TRACED_GROWTH * neighbor_capacity


def sized(count: int, multiplier: float, extra: int = 0) -> int:
    """The capacity for a measured ``count``: ``ceil(count * multiplier) + extra``, at
    least 1."""
    return max(1, int(math.ceil(count * multiplier)) + int(extra))


def pair_sized(count: int, multiplier: float, extra: int = 0, grows: bool = False) -> int:
    """The size of a list between two systems (its width, or its compacted rows) for a
    measured ``count``: :func:`sized`, and with ``grows`` (a list that the chunked driver
    re-allocates when it overflows) at least :data:`OVERFLOW_MIN_SIZE` while it is empty
    (a fluid's list against an obstacle it has not reached): its first overflow, when
    the fluid arrives, would grow it to that size anyway (:func:`grown`) and compile the
    run anew."""
    if grows and count == 0:
        return max(OVERFLOW_MIN_SIZE, sized(count, multiplier, extra))
    return sized(count, multiplier, extra)


class ListSizes(NamedTuple):
    """The sizes a neighbour allocation chose: slots per particle of the search, width
    per pair of systems, compacted rows per pair
    (:func:`sphjax.neighbors.lists.allocate`)."""

    search: int
    widths: dict
    members: dict


def widest(*sizes: ListSizes) -> ListSizes:
    """Component-wise the largest of ``sizes``."""

    def most(dicts):
        return {k: max(d.get(k, 0) for d in dicts) for d in dicts for k in d}

    return ListSizes(
        max(s.search for s in sizes),
        most([s.widths for s in sizes]),
        most([s.members for s in sizes]),
    )


def grown(old: ListSizes, needed: ListSizes) -> ListSizes:
    """The sizes to re-allocate to after an overflow: what each list needed, and a list
    that overflowed at least :data:`OVERFLOW_GROWTH` times its old size and
    :data:`OVERFLOW_MIN_SIZE`.  A list that overflowed once tends to again (a flow
    spreading along a wall, or reaching a structure, brings ever more particles to it)
    and every re-allocation compiles the chunk anew: growing by a factor keeps the
    number of re-allocations logarithmic in the growth, and the floor spares the lists
    between two systems that start nearly empty (a fluid's against an obstacle that a
    few of its particles have reached) one re-allocation per few particles that arrive;
    a list that starts empty is allocated at the floor (:func:`pair_sized`).
    Widths stay capped by the search's (:func:`sphjax.neighbors.lists.allocate`)."""

    def grow(before: dict, after: dict) -> dict:
        return {
            key: max(need, math.ceil(OVERFLOW_GROWTH * before.get(key, 0)), OVERFLOW_MIN_SIZE)
            if need > before.get(key, 0)
            else need
            for key, need in after.items()
        }

    return ListSizes(
        needed.search, grow(old.widths, needed.widths), grow(old.members, needed.members)
    )
