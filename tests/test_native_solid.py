"""``Model.pair_loop="native"`` for an elastic solid: the compiled loops of the
deformation gradient (eq. 16) and of the momentum equation (eq. 14; ``sphjax/native/
solid_sums.cc``), row by row over the reference kernel gradients stored once per run and,
with Ganzenmüller's penalty force, each pair once, give XLA's pair sums to round-off, for
every kernel, in 2D and 3D, across a periodic axis; runs follow XLA's; derivatives are
XLA's."""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sphjax
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


# every kernel once, two in each dimension (the suite's time: each case compiles anew)
KERNEL_DIMS = [
    (2, "cubic_spline"),
    (2, "wendland_c2"),
    (3, "quintic_spline"),
    (3, "wendland_c4"),
]


@pytest.mark.parametrize("periodic", [False, True])
@pytest.mark.parametrize(("dim", "kernel"), KERNEL_DIMS)
def test_native_solid_sums_equal_xla_to_round_off(dim, kernel, periodic):
    """``F`` (eq. 16) and eq. 14's pair terms with and without the penalty force, from
    the compiled loops (row by row over the stored kernel gradients; eq. 14 with the
    penalty also each pair once, the reference geometry recomputed from ``X``) and from
    XLA's pair sums (the stored geometry): within 1e-12 of each other, relative to the
    largest entry (float64)."""
    model, state, L0, pairs = jittered_block(dim, kernel, periodic)
    geometry = pair_sums.Geometry.of(model)
    X, x, V = state.reference_position, state.position, state.volume
    grad_w = pairs.geometry.grad_w
    deformation = functools.partial(solid_system._deformation_summand, domain=model.domain)
    F = pair_sums.pair_sum(deformation, {"x": X, "xc": x, "V": V, "L0": L0}, None, pairs, geometry)
    assert relative(F, jnp.broadcast_to(jnp.eye(dim), F.shape)) > 1e-2  # deformed
    by_rows = native.deformation_by_rows(x, V, L0, grad_w, pairs.idx, model.domain)
    assert relative(by_rows, F) < 1e-12

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
        if not penalty:
            by_rows = native.elastic_by_rows(V, PL0, grad_w, pairs.idx, shared.solid_density)
            assert relative(by_rows, xla["a"]) < 1e-12
        accelerations.append(xla["a"])
    assert relative(accelerations[1], accelerations[0]) > 1e-2  # the penalty force counts


def natively(case):
    return case.replace(model=dataclasses.replace(case.model, pair_loop="native"))


def compiled_loops(case) -> set:
    """The compiled loops one evaluation of ``case`` calls (the FFI targets in its
    program)."""
    neighbors = rhs.with_reference(
        case.state, rhs.build_neighbors(case.state, case.model), case.model
    )
    program = str(
        jax.make_jaxpr(lambda s: rhs.evaluate(s, neighbors, case.model, case.params))(case.state)
    )
    return {target for target in native.TARGETS if target in program}


def plate(penalty_alpha=0.1, **options):
    """The oscillating plate at 4 particles through its thickness (float64), by default
    with Ganzenmüller's penalty force (``penalty_alpha=None``: without)."""
    if penalty_alpha is not None:
        options["penalty_alpha"] = penalty_alpha
    return sphjax.cases.oscillating_plate(n=4, **options)


#: the plate with the penalty force (eq. 14 each pair once) and without (row by row)
PENALTIES = pytest.mark.parametrize("penalty_alpha", [0.1, None], ids=["penalty", "plain"])


def test_which_solid_sums_are_compiled():
    """The deformation gradient goes row by row over the stored kernel gradients; the
    momentum too without the penalty force, with it each pair once."""
    assert compiled_loops(natively(plate())) == {
        "sphjax_deformation_by_rows",
        "sphjax_solid_momentum",
    }
    assert compiled_loops(natively(plate(None))) == {
        "sphjax_deformation_by_rows",
        "sphjax_elastic_by_rows",
    }


@PENALTIES
def test_a_native_plate_run_follows_the_xla_run(penalty_alpha):
    """60 steps of the plate: positions and velocities within 1e-10 of XLA's run,
    relative to their largest entries (float64); the plate has moved."""
    case = plate(penalty_alpha)
    xla = sphjax.simulate(case, n_steps=60).final
    loops = sphjax.simulate(natively(case), n_steps=60).final
    assert relative(xla.position, case.state.position) > 1e-4
    assert relative(loops.position, xla.position) < 1e-10
    assert relative(loops.velocity, xla.velocity) < 1e-10


@PENALTIES
def test_derivatives_through_a_native_plate_run_are_xlas(penalty_alpha):
    """Reverse mode through 10 steps of the plate (checkpointed) with respect to Young's
    modulus, the initial positions and the reference positions (from which the
    reference geometry and ``L0`` are computed) equals XLA's to 1e-10."""
    case = plate(penalty_alpha)

    def loss(case, young_modulus, position, reference):
        params = case.params.replace(young_modulus=young_modulus)
        state = case.state.replace(position=position, reference_position=reference)
        final = sphjax.simulate(case, params, n_steps=10, state=state, checkpoint_every=5).final
        return jnp.sum(final.mass * jnp.sum(final.velocity**2, -1))

    arguments = (
        case.params.young_modulus,
        case.state.position,
        case.state.reference_position,
    )
    grads = [jax.grad(loss, argnums=(1, 2, 3))(c, *arguments) for c in (case, natively(case))]
    for native_grad, xla_grad in zip(grads[1], grads[0], strict=True):
        assert float(np.abs(np.asarray(xla_grad)).max()) > 0
        assert relative(native_grad, xla_grad) < 1e-10


def test_the_second_order_correction_is_refused_under_native():
    """``gradient_correction="second_order"`` has no compiled loop, so a solid-only model
    with it is refused under ``pair_loop="native"`` in one line naming the fix."""
    case = plate()
    solid = case.model.systems[0].replace(gradient_correction="second_order")
    with pytest.raises(ValueError, match=r"first-order correction.* use pair_loop='xla'"):
        dataclasses.replace(case.model, systems=(solid,), pair_loop="native")


def test_native_solid_sums_batch_under_vmap():
    """``jax.vmap`` over two Young's moduli of a deformed plate: each row equals its own
    native evaluation, and the rows differ (the modulus reached the loops)."""
    case = natively(plate())
    state = case.state.replace(
        position=case.state.position + 1e-3 * jnp.sin(40.0 * case.state.position[:, ::-1])
    )
    neighbors = rhs.with_reference(state, rhs.build_neighbors(state, case.model), case.model)

    def acceleration(young_modulus):
        params = case.params.replace(young_modulus=young_modulus)
        return rhs.evaluate(state, neighbors, case.model, params).acceleration

    moduli = jnp.stack([case.params.young_modulus, 3.0 * case.params.young_modulus])
    batched = jax.vmap(acceleration)(moduli)
    for k in range(2):
        assert relative(batched[k], acceleration(moduli[k])) < 1e-12
    assert relative(batched[0], batched[1]) > 1e-2


def test_a_native_fsi_run_follows_the_xla_run():
    """The dam break against an elastic obstacle with the penalty force (fluid, walls,
    solid; CI size): 40 steps with ``pair_loop="native"`` (the fluid's and the solid's
    own momentum sums compiled) equal XLA's run to 1e-10."""
    case = sphjax.cases.dam_break_elastic_obstacle(n=2, column_width=0.036, plate_length=0.03)
    fluid, wall, solid = case.model.systems
    model = dataclasses.replace(
        case.model, systems=(fluid, wall, solid.replace(penalty=sphjax.PenaltyForce()))
    )
    params = case.params.for_model(model).replace(penalty_alpha=0.1)
    case = case.replace(model=model, params=params)
    assert {"sphjax_solid_momentum", "sphjax_momentum"} <= compiled_loops(natively(case))
    xla = sphjax.simulate(case, n_steps=40).final
    loops = sphjax.simulate(natively(case), n_steps=40).final
    assert relative(loops.position, xla.position) < 1e-10
    assert relative(loops.velocity, xla.velocity) < 1e-10


def test_a_native_plate_run_in_float32_agrees_with_xla_to_its_round_off():
    """The plate without the penalty force in float32 (both sums row by row): positions
    within 1e-5 of XLA's after 60 steps, relative to their largest entry (a few ulps of
    float32 per step, summed in another order)."""
    previous = jax.config.jax_enable_x64
    jax.config.update("jax_enable_x64", False)
    try:
        case = plate(None)
        xla = sphjax.simulate(case, n_steps=60).final
        loops = sphjax.simulate(natively(case), n_steps=60).final
        assert loops.position.dtype == jnp.float32
        assert relative(xla.position, case.state.position) > 1e-4
        assert relative(loops.position, xla.position) < 1e-5
    finally:
        jax.config.update("jax_enable_x64", previous)
