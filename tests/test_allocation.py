"""Neighbour-list allocation: sphjax counts the cell capacity and builds the list in one
compiled program (``NeighborSearch._allocate``) instead of jax-md's eager allocation (some
40 small programs compiled at first use); the list must be jax-md's own, entry for entry."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sphjax
from sphjax.neighbors import SearchGeometry, neighbor_search

CASES = [
    ("taylor_green", dict(n=20)),  # periodic
    ("poiseuille", dict()),  # periodic along x, a narrow box (float32 cell count)
    ("dam_break", dict(n=10)),  # walls, padded box
    ("hydrostatic_fsi_plate", dict(n=2, length=0.3, depth=0.1)),
    ("abc_flow_3d", dict(n=8)),  # a box too small for a cell list
    ("dam_break_3d", dict(n=4)),
]


def _jax_md_allocation(search, position, extra_capacity=0):
    fns = search._functions(search.skin)
    return fns.allocate(search.to_box(jnp.asarray(position)), extra_capacity=extra_capacity)


@pytest.mark.parametrize(("name", "arguments"), CASES, ids=[c for c, _ in CASES])
def test_allocation_is_jax_mds(name, arguments):
    case = sphjax.cases.get(name, **arguments)
    search = neighbor_search(SearchGeometry.of(case.model))
    ours = search.allocate(case.state.position)
    theirs = _jax_md_allocation(search, case.state.position)
    assert np.array_equal(np.asarray(ours.idx), np.asarray(theirs.idx))
    assert ours.max_occupancy == theirs.max_occupancy
    assert ours.cell_list_capacity == theirs.cell_list_capacity
    assert ours.cell_size == theirs.cell_size
    assert np.array_equal(
        np.asarray(ours.reference_position), np.asarray(theirs.reference_position)
    )
    assert int(ours.error.code) == 0
    # and it updates as jax-md's does, inside jit, after a move of a third of the skin
    update = jax.jit(search.update)
    moved = case.state.position + 0.3 * search.skin
    a, b = update(moved, ours), update(moved, theirs)
    assert np.array_equal(np.asarray(a.idx), np.asarray(b.idx))


def test_extra_capacity_and_float32():
    """(The tests run in float64; the cases' own runs are float32.)"""
    case = sphjax.cases.get("dam_break", n=10)
    search = neighbor_search(SearchGeometry.of(case.model))
    ours = search.allocate(case.state.position, extra_capacity=3)
    theirs = _jax_md_allocation(search, case.state.position, extra_capacity=3)
    assert ours.max_occupancy == theirs.max_occupancy and np.array_equal(
        np.asarray(ours.idx), np.asarray(theirs.idx)
    )
    jax.config.update("jax_enable_x64", False)  # the autouse fixture restores it
    for name, arguments in CASES[:3]:
        case = sphjax.cases.get(name, **arguments)
        search = neighbor_search(SearchGeometry.of(case.model))
        ours = search.allocate(case.state.position)
        theirs = _jax_md_allocation(search, case.state.position)
        assert ours.reference_position.dtype == jnp.float32
        assert np.array_equal(np.asarray(ours.idx), np.asarray(theirs.idx)), name
