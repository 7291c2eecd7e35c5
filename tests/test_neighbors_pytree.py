"""``Neighbors`` as a pytree: a system alone in the search has the search's own list as
its list, stored once among the leaves and linked again when the tree is rebuilt
(``sphjax/neighbors/lists.py``); every other list is a leaf of its own.  Flattening and
rebuilding, also through a compiled program, gives back the same lists."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import sphjax
from sphjax.neighbors import lists
from sphjax.physics import rhs

CASES = {
    "taylor_green": lambda: sphjax.cases.taylor_green(n=12),
    "dam_break": lambda: sphjax.cases.dam_break(n=10),
    "oscillating_plate": lambda: sphjax.cases.oscillating_plate(n=4),
}


def neighbours(name, **options):
    case = CASES[name]()
    built = rhs.build_neighbors(case.state, case.model, **options)
    return rhs.with_reference(case.state, built, case.model)


def same_lists(a, b):
    assert a.pairs.keys() == b.pairs.keys()
    for key in a.pairs:
        left, right = (
            jax.tree_util.tree_leaves(a.pairs[key]),
            jax.tree_util.tree_leaves(b.pairs[key]),
        )
        assert len(left) == len(right), key
        for x, y in zip(left, right, strict=True):
            assert np.asarray(x).dtype == np.asarray(y).dtype, key
            assert np.array_equal(np.asarray(x), np.asarray(y)), key
        assert (a.pairs[key].n_rows, a.pairs[key].n_cols) == (
            b.pairs[key].n_rows,
            b.pairs[key].n_cols,
        )


@pytest.mark.parametrize("support", [True, False], ids=["two-level", "one-level"])
@pytest.mark.parametrize("name", sorted(CASES))
def test_neighbours_rebuilt_from_their_leaves_are_the_same(name, support):
    """The lists after flattening and rebuilding, and after a compiled identity, equal
    the lists before, leaf by leaf (values and dtypes); with the lists kept at two
    levels (the default outside a run) and at one (a run's allocation, with a margin)."""
    before = neighbours(name, support=support)
    leaves, tree = jax.tree_util.tree_flatten(before)
    same_lists(jax.tree_util.tree_unflatten(tree, leaves), before)
    same_lists(jax.jit(lambda n: n)(before), before)
    # JAX also builds trees of other leaves (axes, None: vmap's in_axes, checkpointing)
    specs = jax.tree_util.tree_unflatten(tree, [None] * len(leaves))
    assert jax.tree_util.tree_leaves(specs) == []


def test_a_fluid_alone_in_the_search_stores_its_list_once():
    """Taylor-Green's one fluid (lists at one level, as a run allocates them) has the
    search's list as its own: one ``[N, K]`` leaf of that shape, not two; kept at two
    levels, or in the dam break, whose fluid shares the search with its walls, its list
    is a leaf of its own."""
    tg = neighbours("taylor_green", support=False)
    assert lists._search_lists(tg) == ((0, 0),)
    shape = tg.search.idx.shape
    assert sum(np.shape(leaf) == shape for leaf in jax.tree_util.tree_leaves(tg)) == 1
    assert lists._search_lists(neighbours("taylor_green")) == ()
    assert lists._search_lists(neighbours("dam_break", support=False)) == ()
