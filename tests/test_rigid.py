"""Rigid bodies (sphjax.physics.rigid): the rigid motion's accelerations, the fluid's
force on a body against Archimedes, and the gradient through a floating body's motion."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sphjax
from sphjax.cases import body_bottom, floating_body
from sphjax.cli import main
from sphjax.integration.stepper import stepper_for
from sphjax.io import read_trajectory
from sphjax.physics.rhs import build_neighbors, with_reference
from sphjax.physics.rigid.system import rigid_acceleration, rigid_motion


def _body(seed=0, n=9):
    rng = np.random.default_rng(seed)
    x = jnp.asarray(rng.uniform(-1.0, 1.0, (n, 2)))
    m = jnp.asarray(rng.uniform(0.5, 2.0, n))
    return x, m


def test_a_force_through_the_centre_of_mass_translates_the_body():
    x, m = _body()
    f = jnp.asarray([3.0, -1.0])
    force = m[:, None] / jnp.sum(m) * f  # resultant f, no torque about X
    a = rigid_acceleration(x, jnp.zeros_like(x), m, force, jnp.asarray([0.0, -9.81]))
    expected = np.asarray(f) / float(jnp.sum(m)) + np.array([0.0, -9.81])
    np.testing.assert_allclose(a, np.broadcast_to(expected, a.shape), atol=1e-12)


def test_a_couple_spins_the_body_and_a_spinning_body_feels_its_centripetal_acceleration():
    x, m = _body(1)
    X, _, _, r, inertia = rigid_motion(x, jnp.zeros_like(x), m)
    # a pure couple of torque tau: two opposite forces on particles 0 and 1
    f = jnp.asarray([0.0, 2.0])
    force = jnp.zeros_like(x).at[0].set(f).at[1].set(-f)
    tau = float(r[0, 0] * f[1] - r[1, 0] * f[1])
    a = rigid_acceleration(x, jnp.zeros_like(x), m, force, jnp.zeros(2))
    alpha = tau / float(inertia)
    expected = alpha * np.stack([-r[:, 1], r[:, 0]], -1)
    np.testing.assert_allclose(a, expected, atol=1e-12)
    # spinning at omega about X with no force: a_i = -omega^2 r_i
    omega, V = 1.7, jnp.asarray([0.3, -0.2])
    v = V + omega * jnp.stack([-r[:, 1], r[:, 0]], -1)
    _, V_got, omega_got, _, _ = rigid_motion(x, v, m)
    np.testing.assert_allclose(V_got, V, atol=1e-12)
    assert float(omega_got) == pytest.approx(omega, rel=1e-12)
    a = rigid_acceleration(x, v, m, jnp.zeros_like(x), jnp.zeros(2))
    np.testing.assert_allclose(a, -(omega**2) * r, atol=1e-12)


def _first_acceleration(case):
    neighbors = with_reference(case.state, build_neighbors(case.state, case.model), case.model)
    state, _ = stepper_for(case.model).init((case.state, neighbors), case.params)
    return np.asarray(state.acceleration[np.asarray(case.info["body_indices"])])


@pytest.mark.parametrize("density_ratio", [0.5, 0.3])
def test_the_water_at_rest_pushes_the_body_up_with_archimedes_force(density_ratio):
    # the body at rest, its bottom d0 below the surface in hydrostatic water: the
    # pressure on its bottom, rho0 g d0 over its width, less its weight, accelerates it:
    # A = g (rho0 d0 / (rho_b h) - 1), and no rotation (a level body, a symmetric load)
    case = floating_body(n=8, density_ratio=density_ratio, initial_draught=0.25)
    a = _first_acceleration(case)
    d0 = case.info["water_depth"] - case.info["initial_bottom"]
    g = 9.81
    expected = g * (d0 / (density_ratio * case.info["body_height"]) - 1.0)
    assert float(np.mean(a[:, 1])) == pytest.approx(expected, rel=0.05)
    assert float(np.max(np.abs(a[:, 1] - np.mean(a[:, 1])))) < 0.02 * g
    assert float(np.max(np.abs(a[:, 0]))) < 0.02 * g


def test_the_gradient_of_the_bodys_height_wrt_its_density_matches_finite_differences():
    case = floating_body(n=4, initial_draught=0.25)  # float64 (tests/conftest.py)

    def height(rho_b):
        params = case.params.replace(solid_density=rho_b)
        trajectory = sphjax.simulate(case, params, n_steps=20)
        return body_bottom(trajectory.states, case)[-1]

    rho_b = 500.0
    grad = float(jax.grad(height)(rho_b))
    step = 1.0
    fd = (float(height(rho_b + step)) - float(height(rho_b - step))) / (2 * step)
    assert grad < 0  # a denser body sinks faster
    assert grad == pytest.approx(fd, rel=1e-5)


def test_floating_body_runs_from_the_command_line(tmp_path):
    """``sphjax run floating_body`` (a case of ``sphjax.cases.CASES``): a short run at the
    coarsest resolution, the body's particles kept together as one body."""
    out = tmp_path / "body.h5"
    argv = ["run", "floating_body", "--n", "4", "--t-end", "0.005", "--quiet", "--out", str(out)]
    assert main(argv) == 0
    trajectory, meta = read_trajectory(out)
    assert meta["complete"] and meta["case"] == "floating_body" and meta["case_info"]["n"] == 4
    case = floating_body(n=4)
    body = np.asarray(case.info["body_indices"])
    x = np.asarray(trajectory.states.position)[:, body]
    moved = x - x[:1]
    assert np.all(np.isfinite(x)) and np.max(np.abs(moved)) > 0
    # a rigid motion: every particle moved as the body did (no rotation: a level body)
    np.testing.assert_allclose(moved, np.broadcast_to(moved[:, :1], moved.shape), atol=1e-6)
