"""Fluid unit tests: equation of state, pair antisymmetry, conservation, wall pressure."""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sphjax
from sphjax import Kind, build_neighbors, kick_drift_kick
from sphjax.physics.fluid.eos import tait_density, tait_pressure


def test_tait_equation_of_state_and_inverse():
    rho = jnp.linspace(990.0, 1010.0, 11)
    p = tait_pressure(rho, 1000.0, 20.0, 7.0, 100.0, 30.0)
    # eq. 12 by hand at rho = rho0: p = p0 - p_background
    assert float(p[5]) == pytest.approx(70.0)
    expected = 1000.0 * 400.0 / 7.0 * ((rho / 1000.0) ** 7 - 1.0) + 70.0
    np.testing.assert_allclose(p, expected, rtol=1e-12)
    np.testing.assert_allclose(tait_density(p, 1000.0, 20.0, 7.0, 100.0, 30.0), rho, rtol=1e-12)


def _perturbed_periodic_case(n=10, seed=0, **case_args):
    case = sphjax.cases.taylor_green(n=n, artificial_alpha=0.1, density="continuity", **case_args)
    rng = np.random.default_rng(seed)
    dx = case.info["dx"]
    position = case.state.position + 0.2 * dx * rng.uniform(-1, 1, case.state.position.shape)
    velocity = case.state.velocity + 0.1 * rng.normal(size=case.state.position.shape)
    state = case.state.replace(
        position=jnp.mod(position, 1.0), velocity=velocity, reference_position=position
    )
    return case.replace(state=state)


def test_two_particle_forces_are_equal_and_opposite():
    model = sphjax.Model(
        dim=2,
        smoothing_length=0.1,
        domain=sphjax.Domain((0.0, 0.0), (1.0, 1.0), (True, True)),
        systems=(
            sphjax.FluidSystem(
                density=sphjax.ContinuityDensity(),
                viscosity=(sphjax.ArtificialViscosity(), sphjax.MorrisViscosity()),
            ),
        ),
    )
    params = sphjax.make_params(
        2, reference_density=1.0, sound_speed=10.0, artificial_alpha=0.5, kinematic_viscosity=0.01
    )
    state = sphjax.make_state(
        [[0.50, 0.50], [0.58, 0.53]],
        [[0.3, -0.1], [-0.2, 0.4]],
        [1.01, 0.99],
        [0.011, 0.009],
        Kind.FLUID,
    )
    neighbors = build_neighbors(state, model)
    rates = sphjax.evaluate(state, neighbors, model, params)
    force = state.mass[:, None] * rates.acceleration
    assert float(jnp.abs(force[0]).max()) > 1e-3  # the pair interacts
    np.testing.assert_allclose(force[0], -force[1], rtol=1e-12, atol=1e-16)


@pytest.mark.parametrize("transport_velocity", [False, True])
def test_periodic_flow_conserves_linear_momentum(transport_velocity):
    """Issue 2: total linear momentum conserved to 1e-10 relative (float64, no body force)."""
    case = _perturbed_periodic_case(transport_velocity=transport_velocity)
    traj = sphjax.simulate(case, n_steps=100, save_every=100)
    momentum = jnp.einsum("tn,tnd->td", traj.states.mass, traj.states.velocity)
    scale = float(jnp.sum(case.state.mass * jnp.linalg.norm(case.state.velocity, axis=-1)))
    drift = float(jnp.abs(momentum[-1] - momentum[0]).max()) / scale
    assert drift < 1e-10
    # the flow did change: momentum is conserved by antisymmetry, not by standing still
    assert float(jnp.abs(traj.states.velocity[-1] - traj.states.velocity[0]).max()) > 1e-3


def test_kick_drift_kick_step_is_pure_and_jittable():
    case = _perturbed_periodic_case(n=8)
    neighbors = build_neighbors(case.state, case.model)
    state = sphjax.evaluate(case.state, neighbors, case.model, case.params)
    step = jax.jit(kick_drift_kick, static_argnames="model")
    a, _ = step(state, neighbors, case.dt, case.model, case.params)
    b, _ = step(state, neighbors, case.dt, case.model, case.params)
    np.testing.assert_array_equal(a.position, b.position)
    assert float(a.time) == pytest.approx(case.dt)
    # called concretely it runs compiled too (one program, not op by op): the same step
    c, _ = kick_drift_kick(state, neighbors, case.dt, case.model, case.params)
    np.testing.assert_allclose(c.position, a.position, rtol=0, atol=1e-14)
    np.testing.assert_allclose(c.velocity, a.velocity, rtol=0, atol=1e-12)


def test_hydrostatic_wall_pressure_extrapolation():
    """Adami et al. (2012): wall pressure = fluid pressure + rho g . r_wf (exact for a
    linear hydrostatic field at rest)."""
    case = sphjax.cases.hydrostatic_tank(n=10)
    neighbors = build_neighbors(case.state, case.model)
    rates = sphjax.evaluate(case.state, neighbors, case.model, case.params)
    kind = np.asarray(case.state.kind)
    y = np.asarray(case.state.position[:, 1])
    x = np.asarray(case.state.position[:, 0])
    p = np.asarray(rates.pressure)
    g, H = case.info["gravity"], case.info["height"]
    # first wall layer below the bottom, away from the corners
    first_layer = (
        (kind == Kind.WALL) & np.isclose(y, -0.5 * case.info["dx"]) & (x > 0.3) & (x < 0.7)
    )
    expected = 1000.0 * g * (H - y[first_layer])
    np.testing.assert_allclose(p[first_layer], expected, rtol=0.02)


def test_wall_extrapolation_gradient_is_finite_at_the_edge_of_the_support():
    """A wall particle whose only fluid neighbour sits at the edge of the kernel support has
    a weight sum of ~1e-25 in float32: the Adami quotients (eq. of the wall pressure and
    the no-slip velocity) would have NaN derivatives there (``weight^2`` underflows); such
    a sum counts as no fluid (``sphjax.core.space.covered``), and the gradient stays finite
    (it poisoned solver-in-the-loop training on the dam break)."""
    from sphjax.physics.boundary.wall import wall_pressure, wall_velocity

    def extrapolated(weight):
        sums = {
            "weight": weight,
            "pressure": weight * 1e3,
            "rho_r": weight[:, None] * jnp.ones((1, 2), jnp.float32),
            "velocity": weight[:, None] * jnp.ones((1, 2), jnp.float32),
        }
        g = jnp.asarray([0.0, -9.81], jnp.float32)
        p = wall_pressure(sums, g, jnp.zeros((1, 2), jnp.float32))
        v = wall_velocity(sums, jnp.zeros((1, 2), jnp.float32))
        return jnp.sum(p) + jnp.sum(v)

    for weight in (1e-25, 1e-3):
        w = jnp.asarray([weight], jnp.float32)
        grad = jax.grad(extrapolated)(w)
        assert bool(jnp.all(jnp.isfinite(grad))), weight
    # a sum well inside the support still extrapolates: p_w = sum p W / sum W + ...
    assert float(extrapolated(jnp.asarray([1e-3], jnp.float32))) != 0.0


def test_switching_float64_off_and_on_within_a_session():
    """The cached jax-md functions hold constants of the precision they were built in;
    a session that turns ``jax_enable_x64`` off after a float64 run (the case the
    benchmarks and notebooks hit) must build new ones, not fail to lower."""
    old = jax.config.jax_enable_x64
    try:
        finals = {}
        for x64 in (True, False, True):
            jax.config.update("jax_enable_x64", x64)
            case = sphjax.cases.taylor_green(n=8)
            final = sphjax.simulate(case, n_steps=5).final
            assert final.position.dtype == (jnp.float64 if x64 else jnp.float32)
            finals.setdefault(x64, []).append(np.asarray(final.velocity))
        np.testing.assert_allclose(finals[False][0], finals[True][0], rtol=0, atol=1e-5)
        np.testing.assert_array_equal(finals[True][0], finals[True][1])
    finally:
        jax.config.update("jax_enable_x64", old)


def test_linear_equation_of_state_and_its_inverse():
    """``LinearEOS``: ``p = c0^2 (rho - rho0) + p0 - p_background`` and back."""
    params = sphjax.make_params(
        2,
        reference_density=1000.0,
        sound_speed=20.0,
        reference_pressure=100.0,
        background_pressure=30.0,
    ).fluid
    eos = sphjax.LinearEOS()
    rho = jnp.asarray([990.0, 1000.0, 1012.5])
    p = eos.pressure(rho, params)
    np.testing.assert_allclose(p, 400.0 * (rho - 1000.0) + 70.0, rtol=1e-12)
    np.testing.assert_allclose(eos.density(p, params), rho, rtol=1e-12)


def test_linear_eos_runs_like_tait_with_gamma_one():
    """Tait with ``gamma = 1`` is the linear law, so a Taylor-Green run with
    ``LinearEOS`` reproduces it to round-off; ``gamma = 7`` differs (the test could fail)."""
    case = sphjax.cases.taylor_green(n=8, gamma=1.0)
    fluid = case.model.systems[0]

    def final(eos):
        model = case.model.replace(systems=(fluid.replace(equation_of_state=eos),))
        return sphjax.simulate(case.replace(model=model), n_steps=20).final.velocity

    linear = final(sphjax.LinearEOS())
    np.testing.assert_allclose(linear, final(sphjax.TaitEOS(gamma=1.0)), rtol=1e-5, atol=1e-7)
    assert float(jnp.max(jnp.abs(linear - final(sphjax.TaitEOS(gamma=7.0))))) > 1e-4


def test_fluid_rows_against_walls_are_compacted_without_changing_the_run():
    """The fluid's list against its walls covers only the fluid particles near a wall
    (``PairList.members``) in the chunked driver; a run with it equals the run without it
    (the traced driver, which does not compact) to round-off, and when the front spreads
    along the floor and more particles reach a wall than there is room for, the list is
    re-allocated (a warning) rather than losing pairs, once: sized from the counts the
    lists met, not grown step by step (each growth is a compilation), and the run goes on
    from the step before the overflow, not from the start of its chunk (the chunk is 1400
    steps here; the front reaches that far along the floor after step 500).
    Float64, dam break n = 10."""
    case = sphjax.cases.dam_break(n=10)
    compact = build_neighbors(case.state, case.model, compact_rows=True)
    ((pair, members),) = compact.member_capacities
    assert pair == (0, 1) and members < 0.6 * 200  # 102 of the 200 fluid particles
    n_steps = 1400  # t = 0.32 s: the front has run along the floor
    with pytest.warns(UserWarning, match="re-allocated") as grown:
        chunked = sphjax.simulate(case, n_steps=n_steps).final
    (message,) = [str(w.message) for w in grown if "re-allocated" in str(w.message)]
    overflow, resumed = (int(x) for x in re.findall(r"step (\d+)", message))
    assert resumed == overflow - 1 > 500
    traced = jax.jit(lambda p: sphjax.simulate(case, p, n_steps=n_steps).final)(case.params)
    moved = float(jnp.max(jnp.abs(traced.position - case.state.position)))
    assert moved > 0.05  # the column has collapsed
    assert float(jnp.max(jnp.abs(chunked.position - traced.position))) < 1e-10
    assert float(jnp.max(jnp.abs(chunked.velocity - traced.velocity))) < 1e-8


def test_an_overflowing_list_grows_by_a_factor_and_a_floor():
    """After an overflow the chunked driver re-allocates each list that overflowed to the
    largest of what it needed, 1.25 times its old size and 16 (every re-allocation is a
    compilation: a fluid reaching an elastic obstacle took the CI-size obstacle run
    through 8 of them, 64 of its 66 s, when lists grew to their need alone); the lists
    that did not overflow keep what they need."""
    from sphjax.neighbors import ListSizes, grown

    old = ListSizes(48, {(0, 0): 41, (0, 2): 1, (1, 0): 20}, {(0, 2): 1, (0, 1): 90})
    needed = ListSizes(0, {(0, 0): 48, (0, 2): 5, (1, 0): 19}, {(0, 2): 3, (0, 1): 120})
    sizes = grown(old, needed)
    assert sizes.widths == {(0, 0): 52, (0, 2): 16, (1, 0): 19}
    assert sizes.members == {(0, 2): 16, (0, 1): 120}
    assert sizes.search == needed.search


@pytest.mark.parametrize("n", [5, 20, 21])
def test_dam_break_tank_is_open_at_the_top(n):
    """No wall particle closes the tank: at odd n a lattice row fell exactly on the tank's
    height and became a lid of wall particles (105 of them at n = 21)."""
    case = sphjax.cases.dam_break(n=n)
    x, kind = np.asarray(case.state.position), np.asarray(case.state.kind)
    top = 1.25 * case.info["column_height"]
    lid = (kind == Kind.WALL) & (x[:, 1] >= top - 1e-9)
    lid &= (x[:, 0] > 0.0) & (x[:, 0] < case.info["tank_length"])
    assert int(lid.sum()) == 0
    # side walls still reach the top
    assert float(x[kind == Kind.WALL, 1].max()) == pytest.approx(top, abs=case.info["dx"])
