"""The cell-blocked pair loop of :mod:`sphjax.native` (a sum within one system over the
pairs found through a grid of cells, no neighbour list): it gives XLA's sums and those of
the loop over the list to round-off, on periodic boxes, walled ones and boxes periodic
along one axis, in 2D and 3D, with one thread and two; where no grid serves the loop over
the list runs instead."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sphjax
from sphjax import native
from sphjax.core.kernels import WendlandC2
from sphjax.core.model import Domain
from sphjax.neighbors.lists import PairList
from sphjax.physics import pairs as pair_sums
from sphjax.physics import rhs
from sphjax.physics.fluid.density import _kernel_summand

pytestmark = pytest.mark.skipif(
    native.compiler() is None, reason="no C++ compiler to build sphjax.native"
)

FIELDS = ("acceleration", "density", "density_rate", "pressure")


def relative(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


def natively(case):
    return case.replace(model=dataclasses.replace(case.model, pair_loop="native"))


CASES = {
    # periodic square, 2304 particles: two threads over stripes of cells (Morris, quintic)
    "taylor_green": lambda: sphjax.cases.taylor_green(
        n=48, h_factor=1.0, transport_velocity=False, relax_iterations=0
    ),
    # walls all round: the grid spans the fluid; Molteni's diffusion (both roles per pair)
    "dam_break": lambda: sphjax.cases.dam_break(n=10),
    # periodic along x, walls across y
    "poiseuille": lambda: sphjax.cases.poiseuille(n=12),
    # 3D periodic cube (cells of the whole support), Wendland C4
    "abc_flow_3d": lambda: sphjax.cases.abc_flow_3d(
        n=12, kernel="wendland_c4", transport_velocity=False, relax_iterations=0
    ),
    # 3D, walls all round
    "dam_break_3d": lambda: sphjax.cases.dam_break_3d(n=6),
    # an elastic plate with the penalty force: the solid's momentum over its reference
    # positions
    "oscillating_plate_penalty": lambda: sphjax.cases.oscillating_plate(n=8, penalty_alpha=0.1),
}


def evaluate(case, monkeypatch, cells: bool):
    """One evaluation (float64) from the case's start with uneven masses, perturbed
    velocities and positions moved by up to 3 % of the support (so that the forces are
    not the round-off of a state at rest); ``cells``: the cell-blocked loop (else the
    loop over the list)."""
    monkeypatch.setenv("SPHJAX_NATIVE_CELLS", "1" if cells else "0")
    s, support = case.state, case.model.cutoff
    state = s.replace(
        position=s.position + 0.03 * support * jnp.sin(37.0 * s.position[:, ::-1] / support),
        mass=s.mass * (1.0 + 0.05 * jnp.sin(7.0 * s.position[:, 0])),
        velocity=s.velocity + 0.01 * jnp.cos(29.0 * s.position / support),
    )
    neighbors = rhs.build_neighbors(state, case.model)
    # (the loops read the variable when they run: wait for them before it changes)
    return state, jax.block_until_ready(rhs.evaluate(state, neighbors, case.model, case.params))


@pytest.mark.parametrize("name", sorted(CASES))
def test_cell_blocked_sums_equal_xla_and_the_list_loop(name, monkeypatch):
    """Both loops within 1e-12 of XLA (relative to the largest entry); the two differ in
    their last bits somewhere (they add the pairs in another order), which shows that the
    cell-blocked loop ran."""
    case = CASES[name]()
    state, xla = evaluate(case, monkeypatch, cells=True)
    _, cells = evaluate(natively(case), monkeypatch, cells=True)
    _, listed = evaluate(natively(case), monkeypatch, cells=False)
    differ = False
    for field in FIELDS:
        expected = getattr(xla, field)
        if np.abs(np.asarray(expected)).max() == 0:
            continue
        assert relative(getattr(cells, field), expected) < 1e-12, field
        assert relative(getattr(listed, field), expected) < 1e-12, field
        differ |= not np.array_equal(getattr(cells, field), getattr(listed, field))
    assert differ, "the cell-blocked loop gave the list loop's sums bit for bit"


def test_a_periodic_box_too_small_for_the_grid_takes_the_list(monkeypatch):
    """A periodic box of fewer than 2 R + 1 = 5 cells along an axis (cells of half the
    support in 2D) cannot hold each pair once in its half shells: the loop over the list
    runs, bit for bit."""
    case = sphjax.cases.taylor_green(
        n=7, h_factor=1.0, transport_velocity=False, relax_iterations=0
    )
    _, cells = evaluate(natively(case), monkeypatch, cells=True)
    _, listed = evaluate(natively(case), monkeypatch, cells=False)
    for field in FIELDS:
        np.testing.assert_array_equal(getattr(cells, field), getattr(listed, field))


def test_a_float32_run_follows_the_list_loop(monkeypatch):
    """100 float32 steps of the Taylor-Green vortex (2304 particles, two threads):
    positions within float32 round-off of the list loop's run."""
    jax.config.update("jax_enable_x64", False)
    case = natively(CASES["taylor_green"]())

    def run(cells: bool):
        monkeypatch.setenv("SPHJAX_NATIVE_CELLS", "1" if cells else "0")
        final = jax.block_until_ready(sphjax.simulate(case, n_steps=100).final)
        assert final.position.dtype == jnp.float32
        return np.asarray(final.position), np.asarray(final.velocity)

    (x_cells, v_cells), (x_list, v_list) = run(True), run(False)
    assert np.abs(x_cells - x_list).max() < 1e-5
    assert relative(v_cells, v_list) < 1e-4


def _two_clusters(gap: float):
    """Two 20 x 20 lattices of particles (spacing 1, h = 1.2, support 2.4: Wendland C2)
    ``gap`` apart along x in a walled box, their masses uneven, and their dense
    neighbour list by brute force (``[N, K]``, padded with ``N``)."""
    side = np.arange(20.0)
    block = np.stack(np.meshgrid(side, side, indexing="ij"), -1).reshape(-1, 2)
    block = block + 0.2 * np.sin(3.0 * block[:, ::-1])
    x = np.concatenate([block, block + [gap + 20.0, 0.0]])
    n, cutoff = len(x), 2.4
    near = np.sum((x[:, None] - x[None]) ** 2, -1) < cutoff**2
    np.fill_diagonal(near, False)
    width = int(near.sum(1).max())
    idx = np.full((n, width), n, np.int32)
    for a in range(n):
        found = np.flatnonzero(near[a])
        idx[a, : len(found)] = found
    domain = Domain((-10.0, -10.0), (gap + 50.0, 30.0), (False, False))
    geometry = pair_sums.Geometry(WendlandC2(), 1.2, 2, cutoff, domain)
    rows = {"x": jnp.asarray(x), "m": jnp.asarray(1.0 + 0.1 * np.cos(x[:, 0]))}
    return rows, jnp.asarray(idx), geometry


@pytest.mark.parametrize("gap", [5.0, 1.0e7])
def test_the_grid_spans_the_particles_or_the_list_runs(gap, monkeypatch):
    """Two clusters 5 apart: the grid spans both (the loops differ in their last bits);
    1e7 apart: a grid over both would need far more than 4 N + 4096 cells, so the loop
    over the list runs (bit for bit).  Either way the kernel sum is XLA's to 1e-13."""
    rows, idx, geometry = _two_clusters(gap)
    pairs = PairList(idx, None, idx.shape[0], idx.shape[0])
    xla = pair_sums.pair_sum(_kernel_summand, rows, None, pairs, geometry, weight="m")
    sums = {}
    for cells in ("1", "0"):
        monkeypatch.setenv("SPHJAX_NATIVE_CELLS", cells)
        sums[cells] = np.asarray(jax.block_until_ready(native.kernel_sum(rows, idx, geometry)))
        assert relative(sums[cells], xla) < 1e-13
    assert np.array_equal(sums["1"], sums["0"]) == (gap > 1e6)
