"""``Model.pair_loop="native"`` for an elastic solid: the compiled loops of the
deformation gradient (eq. 16) and of the momentum equation with Ganzenmüller's penalty
force (eq. 14; ``sphjax/native/solid_sums.cc``) give XLA's pair sums to round-off, for
every kernel, in 2D and 3D, across a periodic axis; runs follow XLA's; derivatives are
XLA's."""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np
import pytest

from sphjax import Domain, Kind, Model, SolidSystem, make_state, native
from sphjax.core.kernels import KERNELS
from sphjax.physics import interactions, rhs
from sphjax.physics import pairs as pair_sums
from sphjax.physics.solid import system as solid_system

pytestmark = pytest.mark.skipif(
    native.compiler() is None, reason="no C++ compiler to build sphjax.native"
)

SPACING = 0.1


def relative(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


def jittered_block(dim, kernel, periodic):
    """A solid of 6^d particles on a jittered lattice, its first axis periodic (the
    block spans the box: pairs across its ends) or not; its reference quantities and a
    smooth deformation plus noise as the current positions."""
    n = 6
    rng = np.random.default_rng(0)
    grid = np.arange(n) * SPACING + 0.5 * SPACING
    X = np.stack(np.meshgrid(*[grid] * dim, indexing="ij"), -1).reshape(-1, dim)
    X = X + 0.1 * SPACING * rng.standard_normal(X.shape)
    axes = (periodic,) + (False,) * (dim - 1)
    lower = tuple(0.0 if p else -1.0 for p in axes)
    upper = tuple(n * SPACING if p else 2.0 for p in axes)
    X[:, 0] = np.mod(X[:, 0], upper[0]) if periodic else X[:, 0]
    model = Model(
        dim=dim,
        smoothing_length=1.2 * SPACING,
        kernel=KERNELS[kernel](),
        domain=Domain(lower, upper, axes),
        systems=(SolidSystem(),),
    )
    state = make_state(X, 0.0, 1000.0, 1000.0 * SPACING**dim, Kind.SOLID)
    neighbors = rhs.with_reference(state, rhs.build_neighbors(state, model), model)
    X = state.reference_position
    x = (
        X
        + 0.2 * SPACING * jnp.sin(3.0 * X[:, ::-1])
        + 0.03 * SPACING * rng.standard_normal(X.shape)
    )
    if periodic:
        x = x.at[:, 0].set(jnp.mod(x[:, 0], upper[0]))  # moved across the periodic end
    pairs = rhs.reference_pairs(neighbors)[(0, 0)]
    assert pairs.geometry is not None  # XLA reads the stored reference geometry
    return model, state.replace(position=x), neighbors.reference[0]["L0"], pairs


@pytest.mark.parametrize("periodic", [False, True])
@pytest.mark.parametrize("kernel", sorted(KERNELS))
@pytest.mark.parametrize("dim", [2, 3])
def test_native_solid_sums_equal_xla_to_round_off(dim, kernel, periodic):
    """``F`` (eq. 16) and eq. 14's pair terms with and without the penalty force, from
    the compiled loops (the reference geometry recomputed from ``X``) and from XLA's pair
    sums (the stored geometry): within 1e-12 of each other, relative to the largest
    entry (float64)."""
    model, state, L0, pairs = jittered_block(dim, kernel, periodic)
    geometry = pair_sums.Geometry.of(model)
    X, x, V = state.reference_position, state.position, state.volume
    deformation = functools.partial(solid_system._deformation_summand, domain=model.domain)
    F = pair_sums.pair_sum(deformation, {"x": X, "xc": x, "V": V, "L0": L0}, None, pairs, geometry)
    assert relative(F, jnp.broadcast_to(jnp.eye(dim), F.shape)) > 1e-2  # deformed
    assert relative(native.solid_deformation(X, x, V, L0, pairs.idx, geometry), F) < 1e-12

    PL0 = jnp.asarray(np.random.default_rng(1).standard_normal(F.shape)) * 1e4
    shared = interactions.SolidPairParameters(*map(jnp.asarray, (1000.0, 2.0e6, 0.1)))
    rows = {"x": X, "xc": x, "V": V, "PL0": PL0, "F": F}
    accelerations = []
    for penalty in (False, True):
        summand = functools.partial(
            interactions._solid_summand, domain=model.domain, penalty=penalty
        )
        xla = pair_sums.pair_sum(
            summand, rows, None, pairs, geometry, shared, weight="V", parity=-1
        )
        loop = native.solid_momentum(X, x, V, PL0, F, pairs.idx, geometry, shared, penalty=penalty)
        assert relative(loop, xla["a"]) < 1e-12, penalty
        accelerations.append(xla["a"])
    assert relative(accelerations[1], accelerations[0]) > 1e-2  # the penalty force counts
