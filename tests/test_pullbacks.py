"""Hand-written per-pair pull-backs against ``jax.vjp`` of the summands they replace.

``sphjax.physics.pairs.define_pullback`` lets a pair sum's adjoint use a reverse mode
written out by hand; every registered one is checked here, per pair, against autodiff of
the forward summand for every combination of its switches (float64, random pairs with
approaching and receding velocities).
"""

import functools
import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sphjax.physics import interactions
from sphjax.physics.pairs import PairGeometry, _pullback_of

jax.config.update("jax_enable_x64", True)

N_ROWS, N_NEIGHBOURS, DIM = 5, 7, 2


def _pairs(key):
    k = jax.random.split(key, 3)
    dr = jax.random.normal(k[0], (N_ROWS, N_NEIGHBOURS, DIM))
    r = jnp.linalg.norm(dr, axis=-1)
    mask = jax.random.uniform(k[1], (N_ROWS, N_NEIGHBOURS)) < 0.8
    # independent inputs: the pull-back treats r, W and grad W as fields of their own
    w = jnp.exp(-r)
    grad_w = -dr * jnp.exp(-r)[..., None] + 0.1 * jax.random.normal(k[2], dr.shape)
    zero = ~mask
    return PairGeometry(
        dr=jnp.where(zero[..., None], 0.0, dr),
        r=jnp.where(zero, 0.0, r),
        w=jnp.where(zero, 0.0, w),
        grad_w=jnp.where(zero[..., None], 0.0, grad_w),
        mask=mask,
    )


def _fields(key, shape):
    k = jax.random.split(key, 6)
    return {
        "v": jax.random.normal(k[0], shape + (DIM,)),
        "vv": jax.random.normal(k[1], shape + (DIM,)),
        "dv": 0.1 * jax.random.normal(k[2], shape + (DIM,)),
        "rho": 1.0 + 0.1 * jax.random.uniform(k[3], shape),
        "p": jax.random.normal(k[4], shape),
        "m": 1.0 + 0.1 * jax.random.uniform(k[5], shape),
        # the per-particle P = p / rho^2 and i = 1 / rho of the momentum summand
        "P": jax.random.normal(k[4], shape) * 0.9,
        "i": 1.0 / (1.0 + 0.1 * jax.random.uniform(k[3], shape)) + 0.01,
    }


SWITCHES = list(itertools.product([False, True], repeat=5))


@pytest.mark.parametrize(
    "artificial, morris, stress, shift, viscous",
    SWITCHES,
    ids=["".join("amtsv"[i] if on else "-" for i, on in enumerate(s)) for s in SWITCHES],
)
def test_hydrodynamic_pullback_equals_autodiff(artificial, morris, stress, shift, viscous):
    summand = functools.partial(
        interactions._hydrodynamic_summand,
        h=0.7,
        artificial=artificial,
        morris=morris,
        stress=stress,
        shift=shift,
        viscous=viscous,
    )
    switches = (artificial, morris, stress, shift, viscous)
    seed = sum(2**i for i, on in enumerate(switches) if on)
    keys = jax.random.split(jax.random.PRNGKey(seed), 5)
    pair = _pairs(keys[0])
    shape = (N_ROWS, N_NEIGHBOURS)
    a, b = _fields(keys[1], shape), _fields(keys[2], shape)
    shared = interactions.FluidPairParameters(
        *(jnp.asarray(v) for v in (10.0, 0.3, 0.2, 0.05, 4.0))
    )
    out = summand(pair, a, b, shared)
    bar = jax.tree_util.tree_map(
        lambda o, k: jax.random.normal(k, o.shape),
        out,
        dict(zip(out, jax.random.split(keys[3], len(out)), strict=True)),
    )

    def forward(geometry, a, b, shared):
        dr, r, w, grad_w = geometry
        return summand(PairGeometry(dr, r, w, grad_w, pair.mask), a, b, shared)

    geometry = (pair.dr, pair.r, pair.w, pair.grad_w)
    _, pull = jax.vjp(forward, geometry, a, b, shared)
    geometry_ad, a_ad, b_ad, shared_ad = pull(bar)

    hand = _pullback_of(summand)
    geometry_hand, a_hand, b_hand, shared_hand = hand(pair, a, b, shared, bar)

    def close(expected, got, what):
        got = jnp.broadcast_to(jnp.asarray(got, expected.dtype), expected.shape)
        scale = float(jnp.max(jnp.abs(expected))) + 1e-30
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * scale, err_msg=what)

    for name, expected, got in zip(
        ("dr", "r", "w", "grad_w"), geometry_ad, geometry_hand, strict=True
    ):
        close(expected, got, f"pair.{name}")
    for name in a:
        close(a_ad[name], a_hand.get(name, 0.0), f"a[{name!r}]")
        close(b_ad[name], b_hand.get(name, 0.0), f"b[{name!r}]")
    for i, (expected, got) in enumerate(zip(shared_ad, shared_hand, strict=True)):
        close(expected, jnp.sum(jnp.broadcast_to(got, shape)), f"shared[{i}]")
    # the switches that matter must give a non-trivial cotangent somewhere
    assert float(jnp.max(jnp.abs(geometry_ad[3]))) > 0


def _check_against_autodiff(summand, shared, seed, fields=None):
    """The hand pull-back of ``summand`` against ``jax.vjp`` of it (float64, random pairs,
    coincident and out-of-support pairs included through the mask), to 1e-12 of scale."""
    keys = jax.random.split(jax.random.PRNGKey(seed), 5)
    pair = _pairs(keys[0])
    shape = (N_ROWS, N_NEIGHBOURS)
    fields = fields or _fields
    a, b = fields(keys[1], shape), fields(keys[2], shape)
    out = summand(pair, a, b, shared)
    leaves, treedef = jax.tree_util.tree_flatten(out)
    bar = jax.tree_util.tree_unflatten(
        treedef,
        [
            jax.random.normal(k, o.shape)
            for o, k in zip(leaves, jax.random.split(keys[3], len(leaves)), strict=True)
        ],
    )

    def forward(geometry, a, b, shared):
        dr, r, w, grad_w = geometry
        return summand(PairGeometry(dr, r, w, grad_w, pair.mask), a, b, shared)

    geometry = (pair.dr, pair.r, pair.w, pair.grad_w)
    _, pull = jax.vjp(forward, geometry, a, b, shared)
    geometry_ad, a_ad, b_ad, shared_ad = pull(bar)
    geometry_hand, a_hand, b_hand, shared_hand = _pullback_of(summand)(pair, a, b, shared, bar)

    def close(expected, got, what):
        got = jnp.broadcast_to(jnp.asarray(got, expected.dtype), expected.shape)
        scale = float(jnp.max(jnp.abs(expected))) + 1e-30
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * scale, err_msg=what)

    for name, expected, got in zip(
        ("dr", "r", "w", "grad_w"), geometry_ad, geometry_hand, strict=True
    ):
        close(expected, got, f"pair.{name}")
    for name in a:
        close(a_ad[name], a_hand.get(name, 0.0), f"a[{name!r}]")
        close(b_ad[name], b_hand.get(name, 0.0), f"b[{name!r}]")
    for i, (expected, got) in enumerate(zip(shared_ad, shared_hand, strict=True)):
        close(expected, jnp.sum(jnp.broadcast_to(got, shape)), f"shared[{i}]")
    return geometry_ad, a_ad, b_ad


def test_density_pullbacks_equal_autodiff():
    """Eq. 5's kernel summand and eq. 11's velocity divergence."""
    from sphjax.physics.fluid import density

    geometry, _, _ = _check_against_autodiff(density._kernel_summand, (), seed=11)
    assert float(jnp.max(jnp.abs(geometry[2]))) > 0
    geometry, a, b = _check_against_autodiff(density._velocity_divergence_summand, (), seed=12)
    assert float(jnp.max(jnp.abs(geometry[3]))) > 0 and float(jnp.max(jnp.abs(a["v"]))) > 0


def _solid_fields(key, shape):
    k = jax.random.split(key, 6)
    d = (DIM, DIM)
    return {
        "xc": jax.random.normal(k[0], shape + (DIM,)),
        "V": 1.0 + 0.1 * jax.random.uniform(k[1], shape),
        "L0": jnp.eye(DIM) + 0.1 * jax.random.normal(k[2], shape + d),
        "PL0": jax.random.normal(k[3], shape + d),
        "F": jnp.eye(DIM) + 0.1 * jax.random.normal(k[4], shape + d),
    }


@pytest.mark.parametrize("penalty", [False, True], ids=["elastic", "penalty"])
def test_solid_pullbacks_equal_autodiff(penalty):
    """Eq. 14 (with and without the penalty force) and eq. 16's deformation term, with
    the positions in a periodic box (minimum image)."""
    from sphjax.core.model import Domain
    from sphjax.physics.solid import system

    domain = Domain(lower=(0.0, 0.0), upper=(3.0, 3.0), periodic=(True, False))
    momentum = functools.partial(interactions._solid_summand, domain=domain, penalty=penalty)
    shared = interactions.SolidPairParameters(*(jnp.asarray(v) for v in (1000.0, 2.0e6, 0.1)))
    _, a, _ = _check_against_autodiff(momentum, shared, 21 + penalty, _solid_fields)
    assert float(jnp.max(jnp.abs(a["PL0"]))) > 0
    assert penalty == (float(jnp.max(jnp.abs(a["F"]))) > 0)
    deformation = functools.partial(system._deformation_summand, domain=domain)
    _, a, b = _check_against_autodiff(deformation, (), 23, _solid_fields)
    assert float(jnp.max(jnp.abs(a["L0"]))) > 0 and float(jnp.max(jnp.abs(b["V"]))) > 0


def _unmarked_deformation(pair, a, b, shared, *, domain):
    """Eq. 16's summand without the ``transpose_by_autodiff`` mark, so that its pair sum
    takes the hand pull-back (the path without ``parity``)."""
    from sphjax.physics.solid import system

    return system._deformation_summand(pair, a, b, shared, domain=domain)


def _unmarked_deformation_pullback(pair, a, b, shared, bar, *, domain):
    from sphjax.physics.solid import system

    return system._deformation_pullback(pair, a, b, shared, bar, domain=domain)


@pytest.mark.parametrize("adjoint", [True, False], ids=["custom_adjoint", "autodiff"])
def test_stored_reference_geometry_equals_computed(adjoint):
    """A solid's pair sums over its reference list with the pair geometry computed once
    (``PairList.geometry``, :func:`~sphjax.physics.pairs.stored_geometry`) give the same
    sums and the same cotangents (reference positions included, through the stored
    geometry) as with the geometry computed in the sum: eq. 14 with the penalty force
    (hand pull-back, antisymmetric), eq. 15's moment (autodiff's per-pair derivative,
    symmetric) and eq. 16 (hand pull-back, no symmetry).  Float64, to 1e-12 relative."""
    import sphjax
    from sphjax.physics import pairs as pair_sums
    from sphjax.physics import rhs
    from sphjax.physics.solid import system

    case = sphjax.cases.oscillating_plate(n=2, penalty_alpha=0.1)
    model = case.model
    neighbors = rhs.build_neighbors(case.state, model, margin=None)
    i = next(k for k, s in enumerate(model.systems) if isinstance(s, sphjax.SolidSystem))
    pairs = neighbors.pairs[(i, i)]
    start, stop = neighbors.blocks[i]
    geometry = pair_sums.Geometry.of(model)
    n = stop - start
    keys = jax.random.split(jax.random.PRNGKey(5), 6)
    X = case.state.reference_position[start:stop]
    rows = {
        "x": X,
        "xc": X + 0.01 * jax.random.normal(keys[0], X.shape),
        "V": case.state.volume[start:stop] * (1.0 + 0.1 * jax.random.uniform(keys[1], (n,))),
        "PL0": jax.random.normal(keys[2], (n, DIM, DIM)),
        "F": jnp.eye(DIM) + 0.1 * jax.random.normal(keys[3], (n, DIM, DIM)),
        "L0": jnp.eye(DIM) + 0.1 * jax.random.normal(keys[4], (n, DIM, DIM)),
    }
    shared = interactions.SolidPairParameters(*(jnp.asarray(v) for v in (1000.0, 2.0e6, 0.1)))
    domain = model.domain
    pair_sums.define_pullback(_unmarked_deformation, _unmarked_deformation_pullback)
    sums = [
        (functools.partial(interactions._solid_summand, domain=domain, penalty=True), "V", -1),
        (system._moment_summand, "V", 1),
        (functools.partial(_unmarked_deformation, domain=domain), None, None),
    ]
    for summand, weight, parity in sums:

        def total(rows, shared, store, summand=summand, weight=weight, parity=parity):
            listed = pairs
            if store:
                listed = pairs.replace(
                    geometry=pair_sums.stored_geometry(rows["x"], pairs, geometry)
                )
            return pair_sums.pair_sum(
                summand, rows, None, listed, geometry, shared,
                weight=weight, parity=parity, adjoint=adjoint,
            )  # fmt: skip

        def sum_and_bars(rows, shared, store, total=total):
            """The sum and its cotangents, one compiled program (the eager pull-back was
            some 270 small ones)."""
            out, pull = jax.vjp(functools.partial(total, store=store), rows, shared)
            cotangent = jax.tree.map(lambda o: jax.random.normal(keys[5], o.shape, o.dtype), out)
            return out, pull(cotangent)

        run = jax.jit(sum_and_bars, static_argnames="store")
        out, expected_bars = run(rows, shared, store=False)
        out_stored, got_bars = run(rows, shared, store=True)
        for got, expected in zip(jax.tree.leaves(out_stored), jax.tree.leaves(out), strict=True):
            np.testing.assert_allclose(
                got, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max()
            )
        leaves = zip(jax.tree.leaves(got_bars), jax.tree.leaves(expected_bars), strict=True)
        for got, expected in leaves:
            scale = max(float(jnp.max(jnp.abs(expected))), 1e-300)
            assert float(jnp.max(jnp.abs(got - expected))) <= 1e-12 * scale
        # the reference positions get their cotangent through the stored geometry
        assert float(jnp.max(jnp.abs(got_bars[0]["x"]))) > 0
