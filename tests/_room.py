"""Neighbour lists with room for a whole run, for the tests whose concrete runs would
otherwise outgrow them.

The chunked driver of ``sphjax.simulate`` sizes its lists tightly (``Model.neighbor_margin``
above the largest count at the start, 5 % by default) and, when a list overflows,
re-allocates it and repeats the chunk: results unchanged, but the chunk's program is
compiled a second time (seconds, where the test's run is seconds).  A test whose flow
crowds its particles (a lid-driven corner, a channel filling from its inflow, a disk
sinking through its fluid) starts with room instead (:func:`with_room`), and ``-W
error::sphjax.neighbors.NeighborOverflowWarning`` shows that no re-allocation is left.
The results are those of the tight lists to round-off (padding holds no neighbours; only
the order of a sum may change).  The tests of the re-allocation itself keep the tight
lists.
"""

from __future__ import annotations

#: ``Model.neighbor_margin`` for these tests, room above the largest neighbour count at
#: the start of a run: enough for the cavity's lid corners, the channel's buffers and the
#: settling disk (their runs pass with -W error::sphjax.neighbors.NeighborOverflowWarning)
ROOMY_MARGIN = 0.6

#: ``Model.neighbor_capacity`` for these tests: it sizes the compacted rows (the fluid's
#: rows against a wall, a body or a buffer, which gain members as the fluid moves) and
#: the search's cells
ROOMY_CAPACITY = 2.0


def with_room(case, capacity: float | None = ROOMY_CAPACITY, margin: float = ROOMY_MARGIN):
    """``case`` with ``Model.neighbor_margin = margin`` (its concrete runs size their
    neighbour lists ``1 + margin`` times the largest count at the start) and
    ``Model.neighbor_capacity = capacity`` (``None``: the case's)."""
    model = case.model.replace(neighbor_margin=margin)
    if capacity is not None:
        model = model.replace(neighbor_capacity=capacity)
    return case.replace(model=model)
