"""Two-level neighbour lists: the support lists compacted from the Verlet lists
(``sphjax.neighbors.search.support_list``, ``Neighbors.support_capacities``) change no
result, only how many pair slots every pair sum runs over."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

import sphjax
from sphjax.neighbors.search import support_list
from sphjax.physics.rhs import build_neighbors, evaluate


def test_support_list_keeps_exactly_the_pairs_within_the_radius():
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 1, (50, 2))
    n = x.shape[0]
    idx = np.stack([rng.permutation(n)[:20] for _ in range(n)]).astype(np.int32)
    idx = np.where(idx == np.arange(n)[:, None], n, idx)  # padding where self
    domain = sphjax.Domain((0.0, 0.0), (1.0, 1.0), (True, False))
    radius = 0.3
    out, overflow = support_list(
        jnp.asarray(idx), jnp.asarray(x), jnp.asarray(x), domain, radius, 20
    )
    out = np.asarray(out)
    assert not bool(overflow)
    for a in range(n):
        kept = [int(b) for b in out[a] if b < n]
        want = []
        for b in idx[a]:
            if b < n:
                d = x[a] - x[b]
                d[0] -= np.round(d[0])  # periodic along x, period 1
                if d @ d < radius**2:
                    want.append(int(b))
        assert kept == want  # same pairs, same order
    most = int(np.max(np.sum(out < n, axis=1)))
    x, idx = jnp.asarray(x), jnp.asarray(idx)
    assert bool(support_list(idx, x, x, domain, radius, most - 1)[1])  # overflow reported


def test_support_lists_follow_the_particles_between_rebuilds():
    """Inside ``jit`` the support lists are kept while every particle has moved less than
    half their own skin and compacted again from the Verlet list after that; either way the
    rates equal those over the Verlet list alone.  (Every gradient test runs through them:
    traced runs keep their fluid lists at two levels.)"""
    from sphjax.neighbors import SUPPORT_SKIN, update_neighbors

    case = sphjax.cases.dam_break(n=6)
    model, state = case.model, case.state
    two = build_neighbors(state, model, support=True)
    one = build_neighbors(state, model, support=False)
    (key, width), *_ = two.support_capacities
    assert width < one.pairs[key].idx.shape[1]  # narrower than the Verlet list
    update = jax.jit(update_neighbors)
    rates = jax.jit(functools.partial(evaluate, model=model, params=case.params))
    fluid = np.asarray(state.kind) == 0
    direction = np.random.default_rng(1).normal(size=state.position.shape)
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    # 0.4 and then 0.8 of the support lists' skin: first kept, then compacted again; both
    # below half the Verlet skin, so the Verlet lists are not rebuilt
    for move, compacted in ((0.4, False), (0.8, True)):
        assert move * SUPPORT_SKIN < 0.5 * model.neighbor_skin
        step = move * SUPPORT_SKIN * model.cutoff * direction * fluid[:, None]
        moved = state.replace(position=state.position + step)
        two_now, one_now = update(moved.position, two), update(moved.position, one)
        origin_changed = not np.array_equal(two_now.support_origin, two.support_origin)
        assert origin_changed == compacted
        a, b = rates(moved, one_now), rates(moved, two_now)
        for field in ("acceleration", "density_rate"):
            x, y = np.asarray(getattr(a, field)), np.asarray(getattr(b, field))
            assert np.abs(x - y).max() <= 1e-12 * max(1.0, np.abs(x).max()), (move, field)
