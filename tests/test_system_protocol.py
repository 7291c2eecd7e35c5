"""The set of systems is open: a system defined outside sphjax runs through evaluate and
simulate with nothing in sphjax changed (sphjax.physics.system).

The system here is a set of passive tracers dragged towards the fluid's velocity,
interpolated at their positions (Shepard: ``u(x_t) = sum_f V_f v_f W_tf / sum_f V_f W_tf``),
with ``Dv_t/Dt = (u(x_t) - v_t) / tau``.  It owns a kind of its own (4), has no update
stage, exerts nothing on the fluid, and is registered with one interaction function.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sphjax
from sphjax import cases
from sphjax.core import kernels
from sphjax.core.state import make_state
from sphjax.integration.timestep import stable_time_step
from sphjax.physics.fluid.system import FluidSystem
from sphjax.physics.interactions import INTERACTIONS
from sphjax.physics.rhs import build_neighbors, evaluate
from sphjax.physics.system import block_fields

TRACER = 4


@dataclasses.dataclass(frozen=True)
class Tracers:
    """Passive particles relaxing to the fluid's velocity in ``relaxation_time``."""

    relaxation_time: float = 0.005

    kinds = (TRACER,)
    current_configuration = True
    stage = 1
    params_group = "fluid"
    free_kinds = (TRACER,)

    def view(self, state, block, density_step=None):
        return block_fields(state, block)

    def boundary_view(self, view, params):
        return None  # the fluid does not see them

    def update(self, i, views, systems, pairs, ctx, density_step=None):
        return views[i]

    def body_acceleration(self, view, acceleration, params):
        return acceleration  # no gravity: they follow the fluid

    def held_kinds(self):
        return ()

    def prescribed_motion(self, time, state):
        return None

    def time_step_limits(self, v_max, params, model, cfl):
        return [0.5 * self.relaxation_time]

    def parameters(self):
        return frozenset()

    def unused_parameters(self):
        return {}


def _shepard_summand(pair, a, b, shared):
    w = b["V"] * pair.w
    return {"vw": w[..., None] * b["v"], "w": w}


def tracers_fluid(system, tracers, fluid_system, fluid, pairs, ctx):
    cols = {"x": fluid["x"], "v": fluid["v"], "V": fluid["m"] / fluid["rho"]}
    sums = ctx.pair_sum(_shepard_summand, {"x": tracers["x"]}, cols, pairs)
    u = sums["vw"] / sums["w"][:, None]
    return {"a": (u - tracers["v"]) / system.relaxation_time}


@pytest.fixture(scope="module")
def with_tracers():
    INTERACTIONS[(Tracers, FluidSystem)] = tracers_fluid
    yield
    del INTERACTIONS[(Tracers, FluidSystem)]


def _case_with_tracers(n_tracers=7, seed=3, disorder=0.45):
    base = cases.taylor_green(n=12, relax_iterations=0, disorder=disorder)
    rng = np.random.default_rng(seed)
    x_t = rng.uniform(0.05, 0.95, (n_tracers, 2))
    s = base.state
    tracers = make_state(x_t, 0.0, 1.0, 1.0, TRACER)
    state = jax.tree_util.tree_map(
        lambda a, b: jnp.concatenate([a, b]) if jnp.ndim(a) else a, s, tracers
    )
    model = base.model.replace(systems=(*base.model.systems, Tracers()))
    return base.replace(model=model, state=state), x_t


def test_a_system_defined_outside_sphjax_evaluates_like_its_equation(with_tracers):
    case, x_t = _case_with_tracers()
    neighbors = build_neighbors(case.state, case.model)
    out = evaluate(case.state, neighbors, case.model, case.params)
    n_fluid = case.state.kind.shape[0] - len(x_t)

    # the fluid is untouched by the tracers: the same accelerations as without them
    base = cases.taylor_green(n=12, relax_iterations=0)
    alone = evaluate(base.state, build_neighbors(base.state, base.model), base.model, base.params)
    np.testing.assert_allclose(out.acceleration[:n_fluid], alone.acceleration, rtol=1e-6, atol=1e-6)

    # the tracers' acceleration: Shepard interpolation by brute force over all fluid pairs
    x_f = np.asarray(base.state.position, float)
    v_f = np.asarray(base.state.velocity, float)
    volume = np.asarray(base.state.mass / alone.density, float)
    model = case.model
    expected = []
    for x in x_t:
        d = x - x_f
        d -= np.round(d)  # periodic unit box
        r = np.linalg.norm(d, axis=1)
        w = np.asarray(kernels.W(model.kernel, r, model.smoothing_length, 2)) * (r < model.cutoff)
        u = (volume * w) @ v_f / np.sum(volume * w)
        expected.append(u / Tracers().relaxation_time)  # tracers start at rest
    np.testing.assert_allclose(out.acceleration[n_fluid:], np.array(expected), rtol=1e-4, atol=1e-5)


def test_a_system_defined_outside_sphjax_runs_in_simulate(with_tracers):
    # a perfect lattice in uniform translation stays one (no forces), so the tracers, at
    # rest at first, relax to its velocity U
    case, x_t = _case_with_tracers(disorder=0.0)
    U = jnp.array([1.0, 0.5])
    n_fluid = case.state.kind.shape[0] - len(x_t)
    fluid = case.state.kind == 0
    state = case.state.replace(velocity=jnp.where(fluid[:, None], U, 0.0))
    tau = Tracers().relaxation_time
    n_steps = 20
    trajectory = sphjax.simulate(case, state=state, n_steps=n_steps, save_every=1)
    # kick-drift-kick of dv/dt = (U - v) / tau, the rate evaluated at the half-step
    # velocity as every rate in the step is
    dt, U_ = float(case.dt), np.asarray(U)
    v, x, a = np.zeros_like(x_t), x_t.copy(), np.broadcast_to(U_ / tau, x_t.shape)
    vs, xs = [v], [x]
    for _ in range(n_steps):
        half = v + 0.5 * dt * a
        x = np.mod(x + dt * half, 1.0)
        a = (U_ - half) / tau
        v = half + 0.5 * dt * a
        vs.append(v)
        xs.append(x)
    np.testing.assert_allclose(trajectory.states.velocity[:, n_fluid:], np.array(vs), atol=1e-5)
    np.testing.assert_allclose(trajectory.states.position[:, n_fluid:], np.array(xs), atol=1e-5)
    # and the continuous solution v = U (1 - e^{-t/tau}) at the end, to the scheme's error
    t = n_steps * dt
    np.testing.assert_allclose(
        vs[-1], np.broadcast_to(U_ * (1 - np.exp(-t / tau)), v.shape), rtol=0.05
    )
    # the fluid went on unchanged
    np.testing.assert_allclose(
        trajectory.states.velocity[-1, :n_fluid], state.velocity[:n_fluid], atol=1e-4
    )


def test_the_stable_step_is_the_smallest_of_every_systems_limits(with_tracers):
    case, _ = _case_with_tracers()
    fluid_dt = stable_time_step(case.state, case.model, case.params)
    fast = case.model.replace(systems=(case.model.systems[0], Tracers(relaxation_time=1e-4)))
    assert stable_time_step(case.state, case.model, case.params) == pytest.approx(fluid_dt)
    assert stable_time_step(case.state, fast, case.params) == pytest.approx(5e-5)
