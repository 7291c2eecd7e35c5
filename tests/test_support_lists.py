"""Two-level neighbour lists: the support lists compacted from the Verlet lists
(``sphjax.core.neighbors.support_list``, ``Neighbors.support_capacities``) change no
result, only how many pair slots every pair sum runs over."""

from __future__ import annotations

import functools
import importlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sphjax
from sphjax.core.neighbors import support_list
from sphjax.physics.rhs import build_neighbors, evaluate


def test_support_lists_are_narrower_and_give_the_same_rates():
    for case in [sphjax.cases.dam_break(n=6)]:
        state = case.state
        skin = build_neighbors(state, case.model, support=False)
        two = build_neighbors(state, case.model, support=True)
        (key, width), *_ = two.support_capacities
        assert width < skin.pairs[key].idx.shape[1]
        a = evaluate(state, skin, case.model, case.params)
        b = evaluate(state, two, case.model, case.params)
        for field in ("acceleration", "density_rate", "density", "pressure"):
            x, y = np.asarray(getattr(a, field)), np.asarray(getattr(b, field))
            assert np.abs(x - y).max() <= 1e-12 * max(1.0, np.abs(x).max()), (case.name, field)


def test_support_list_keeps_exactly_the_pairs_within_the_radius():
    rng = np.random.default_rng(0)
    x = jnp.asarray(rng.uniform(0, 1, (50, 2)))
    n = x.shape[0]
    idx = jnp.asarray(np.stack([rng.permutation(n)[:20] for _ in range(n)]), jnp.int32)
    idx = jnp.where(idx == jnp.arange(n)[:, None], n, idx)  # padding where self
    domain = sphjax.Domain((0.0, 0.0), (1.0, 1.0), (True, False))
    radius = 0.3
    out, overflow = support_list(idx, x, x, domain, radius, 20)
    assert not bool(overflow)
    for a in range(n):
        kept = [int(b) for b in np.asarray(out[a]) if b < n]
        want = []
        for b in np.asarray(idx[a]):
            if b < n:
                d = np.array(x[a] - x[b])
                d[0] -= np.round(d[0])  # periodic along x, period 1
                if d @ d < radius**2:
                    want.append(int(b))
        assert kept == want  # same pairs, same order
    most = int(np.max(np.sum(np.asarray(out) < n, axis=1)))
    assert bool(support_list(idx, x, x, domain, radius, most - 1)[1])  # overflow reported


def test_gradient_through_a_run_is_unchanged(monkeypatch):
    """A traced run (``jax.grad``) keeps its fluid list at two levels by default; the
    gradient equals the one through the Verlet list alone."""
    driver = importlib.import_module("sphjax.integration.simulate")
    case = sphjax.cases.dam_break(n=8)

    def loss(alpha):
        params = case.params.replace(artificial_alpha=alpha)
        final = sphjax.simulate(case, params, n_steps=40, checkpoint_every=10).final
        return jnp.sum(final.position[:, 0] * final.mass)

    alpha = jnp.asarray(case.params.artificial_alpha)
    with_support = jax.grad(loss)(alpha)
    monkeypatch.setattr(
        driver, "build_neighbors", functools.partial(driver.build_neighbors, support=False)
    )
    without = jax.grad(loss)(alpha)
    assert float(without) != 0.0
    assert float(with_support) == pytest.approx(float(without), rel=1e-10)
