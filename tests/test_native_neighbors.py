"""``Model.pair_loop="native"``: the neighbour search's rebuild as a compiled cell list
(:func:`sphjax.native.cell_list_rebuild`) gives jax-md's list, row by row, in float32 and
float64, periodic or walled, 2D and 3D; reports overflow as jax-md does; runs and their
derivatives follow the XLA runs."""

from __future__ import annotations

import contextlib
import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sphjax
from sphjax import native
from sphjax.neighbors import NeighborSearch, SearchGeometry, neighbor_search

pytestmark = pytest.mark.skipif(
    native.compiler() is None, reason="no C++ compiler to build sphjax.native"
)

CASES = {
    "taylor_green": lambda: sphjax.cases.taylor_green(
        n=16, h_factor=1.0, transport_velocity=False, relax_iterations=10
    ),
    "dam_break": lambda: sphjax.cases.dam_break(n=10),
    # 3D, fewer than 3 cells per axis: jax-md searches all pairs
    "abc_flow_3d": lambda: sphjax.cases.abc_flow_3d(
        n=8, transport_velocity=False, relax_iterations=5
    ),
    # 3D with jax-md's cell list
    "abc_flow_3d_cells": lambda: sphjax.cases.abc_flow_3d(
        n=15, transport_velocity=False, relax_iterations=0
    ),
}


@contextlib.contextmanager
def precision(x64: bool):
    previous = jax.config.jax_enable_x64
    jax.config.update("jax_enable_x64", x64)
    try:
        yield
    finally:
        jax.config.update("jax_enable_x64", previous)


def searches(model):
    geometry = SearchGeometry.of(model)
    assert not geometry.native
    return neighbor_search(geometry), neighbor_search(dataclasses.replace(geometry, native=True))


def assert_same_list(ours, theirs):
    """The same neighbours per row (as sets), the same error bits; and, where jax-md
    used a cell list, the same order too."""
    a, b = np.asarray(ours.idx), np.asarray(theirs.idx)
    assert a.shape == b.shape and a.dtype == b.dtype == np.int32
    np.testing.assert_array_equal(np.sort(a, axis=1), np.sort(b, axis=1))
    if theirs.cell_list_capacity is not None:
        np.testing.assert_array_equal(a, b)
    assert int(ours.error.code) == int(theirs.error.code)
    np.testing.assert_array_equal(ours.reference_position, theirs.reference_position)


@pytest.mark.parametrize("x64", [False, True], ids=["float32", "float64"])
@pytest.mark.parametrize("name", sorted(CASES))
def test_the_native_rebuild_is_jax_mds(name, x64):
    """At the case's start and after the particles moved (up to a tenth of the support
    radius per axis, at random): the rebuilt list equals jax-md's; so do the updates, one
    within half the skin (not rebuilt) and one past it."""
    with precision(x64):
        case = CASES[name]()
        xla, loops = searches(case.model)
        x = case.state.position
        assert x.dtype == (jnp.float64 if x64 else jnp.float32)
        neighbors = xla.allocate(x)
        assert (neighbors.cell_list_capacity is None) == (name == "abc_flow_3d")
        shake = jax.random.uniform(jax.random.PRNGKey(0), x.shape, x.dtype, -1.0, 1.0)
        moved = x + 0.1 * case.model.cutoff * shake
        for position in (x, moved):
            assert_same_list(
                jax.jit(loops.rebuild)(position, neighbors),
                jax.jit(xla.rebuild)(position, neighbors),
            )
        # update: rebuilt only past half the skin, as jax-md's
        small = x + 0.1 * xla.skin
        for position in (small, moved):
            ours = jax.jit(loops.update)(position, neighbors)
            theirs = jax.jit(xla.update)(position, neighbors)
            assert_same_list(ours, theirs)
        assert np.array_equal(
            jax.jit(loops.update)(small, neighbors).reference_position, neighbors.reference_position
        )


def test_overflow_is_reported_as_jax_md_reports_it():
    """A list too narrow for the rows, and a cell list too small for the cells: the same
    error bits as jax-md's, ``did_buffer_overflow`` set."""
    case = CASES["taylor_green"]()
    xla, loops = searches(case.model)
    x = case.state.position
    neighbors = xla.allocate(x)
    most = int(np.max(np.sum(np.asarray(neighbors.idx) < x.shape[0], axis=1)))
    width = most - 2
    narrow = neighbors.set(idx=neighbors.idx[:, :width], max_occupancy=width)
    crowded = neighbors.set(cell_list_capacity=3)
    for list_ in (narrow, crowded):
        ours, theirs = (jax.jit(s.rebuild)(x, list_) for s in (loops, xla))
        assert bool(theirs.did_buffer_overflow)
        assert bool(ours.did_buffer_overflow)
        assert int(ours.error.code) == int(theirs.error.code)
    assert int(jax.jit(loops.rebuild)(x, narrow).error.code) == 1  # NEIGHBOR_LIST_OVERFLOW
    assert int(jax.jit(loops.rebuild)(x, crowded).error.code) == 2  # CELL_LIST_OVERFLOW
    # the widest row, counted past the list's width
    idx, sizes = native.cell_list_rebuild(loops.to_box(x), width, capacity=None, **loops._grid)
    assert int(sizes[0]) == most


def test_the_native_rebuild_batches_under_vmap():
    case = CASES["dam_break"]()
    xla, loops = searches(case.model)
    x = case.state.position
    neighbors = xla.allocate(x)
    xs = jnp.stack([x, x + 0.2 * xla.skin * jnp.sin(9.0 * x)])
    batched = jax.vmap(loops.rebuild, in_axes=(0, None))(xs, neighbors)
    for k in range(2):
        np.testing.assert_array_equal(batched.idx[k], loops.rebuild(xs[k], neighbors).idx)


def with_small_skin(case, pair_loop):
    model = dataclasses.replace(case.model, neighbor_skin=0.04, pair_loop=pair_loop)
    return case.replace(model=model)


def test_a_native_run_with_native_rebuilds_follows_the_xla_run(monkeypatch):
    """100 steps of the Taylor-Green vortex (float64) with a small skin: the native
    rebuild runs (counted), the positions stay within 1e-10 of XLA's run."""
    case = CASES["taylor_green"]()
    rebuilds = []
    original = NeighborSearch._native_rebuild

    def counted(self, x, neighbors):
        jax.debug.callback(lambda: rebuilds.append(1))
        return original(self, x, neighbors)

    monkeypatch.setattr(NeighborSearch, "_native_rebuild", counted)
    xla = sphjax.simulate(with_small_skin(case, "xla"), n_steps=100)
    loops = sphjax.simulate(with_small_skin(case, "native"), n_steps=100)
    assert len(rebuilds) >= 3
    difference = np.abs(np.asarray(loops.final.position - xla.final.position)).max()
    assert float(difference) < 1e-10


def test_derivatives_through_native_rebuilds_are_xlas():
    """``jax.grad`` w.r.t. the viscosity through 20 checkpointed steps with a small skin
    (rebuilds inside): the native run's equals the XLA run's to 1e-10."""
    case = CASES["taylor_green"]()

    def loss(case, nu):
        params = case.params.replace(kinematic_viscosity=nu)
        final = sphjax.simulate(case, params, n_steps=20, checkpoint_every=5).final
        return jnp.sum(final.mass * jnp.sum(final.velocity**2, -1))

    nu = case.params.kinematic_viscosity
    grads = [jax.grad(loss, argnums=1)(with_small_skin(case, p), nu) for p in ("xla", "native")]
    assert float(grads[0]) < 0
    assert abs(float(grads[1]) - float(grads[0])) < 1e-10 * abs(float(grads[0]))
