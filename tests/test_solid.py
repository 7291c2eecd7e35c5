"""Unit tests of the total-Lagrangian solid (formulation eqs. 14-19).

Patch-test numbers are copied from VALIDATION.md ("Solid cases", patch tests): 9 x 9
lattice, spacing 0.1, cubic spline, h = 0.12, centre particle; lambda = mu = 1 and
F = diag(2, 3) give S = diag(8.5, 13.5), P = diag(17, 40.5); a rotation gives P = 0.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sphjax
from sphjax import (
    Case,
    Domain,
    Kind,
    Model,
    PenaltyForce,
    SolidSystem,
    build_neighbors,
    evaluate,
    make_params,
    make_state,
)
from sphjax.core.kernels import CubicSpline, WendlandC2
from sphjax.physics.rhs import update_stage
from sphjax.physics.solid.material import (
    green_lagrange_strain,
    lame_constants,
    pk1_stress,
    plane_stress_equivalent,
    st_venant_kirchhoff_stress,
)

SPACING, H, CENTRE = 0.1, 0.12, 40  # 9 x 9 lattice, centre particle (VALIDATION.md)
ROTATION = 0.3


def _rotation(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def _lattice(n, dim=2):
    g = np.arange(n) * SPACING
    return np.stack(np.meshgrid(*[g] * dim, indexing="ij"), -1).reshape(-1, dim)


def _setup(n=9, dim=2, kernel=None, h=H, penalty=False, **params):
    X = _lattice(n, dim)
    kernel = CubicSpline() if kernel is None else kernel
    model = Model(
        dim=dim,
        smoothing_length=h,
        kernel=kernel,
        domain=Domain((-10.0,) * dim, (10.0,) * dim, (False,) * dim),
        systems=(SolidSystem(penalty=PenaltyForce() if penalty else None),),
    )
    # lambda = mu = 1  <=>  E = 2.5, nu = 0.25 (eq. 19)
    kw = dict(young_modulus=2.5, poisson_ratio=0.25, solid_density=1.0)
    kw.update(params)
    p = make_params(dim, **kw)
    state = make_state(X, 0.0, kw["solid_density"], kw["solid_density"] * SPACING**dim, Kind.SOLID)
    return X, state, build_neighbors(state, model), model, p


@functools.partial(jax.jit, static_argnums=2)
def solid_fields(state, neighbors, model, params):
    """The solid's fields after the update stage (``L0``, ``F``, ``P``): one compiled
    program per patch, not one per operation and shape."""
    return update_stage(state, neighbors, model, params)[0]


def solid_acceleration(state, neighbors, model, params):
    return evaluate(state, neighbors, model, params).acceleration


def _deform(state, X, A, shift=0.05):
    return state.replace(position=jnp.asarray(X @ np.asarray(A).T + shift))


def test_lame_constants_eq19():
    lam, mu = lame_constants(2.5, 0.25)
    assert lam == pytest.approx(1.0) and mu == pytest.approx(1.0)
    lam, mu = lame_constants(2.0e6, 0.3975)
    assert mu == pytest.approx(2.0e6 / (2 * 1.3975))
    assert lam == pytest.approx(2.0e6 * 0.3975 / (1.3975 * (1 - 0.795)))


def test_plane_stress_equivalent_gives_the_plane_stress_lame_constants():
    """Plane stress (sigma_zz = 0) of (E, nu): mu unchanged, lambda* = E nu / (1 - nu^2);
    a uniaxial stress sigma_xx then strains x by sigma_xx / E and y by -nu sigma_xx / E."""
    for E, nu in [(12.0e6, 0.4), (2.0e6, 0.3975), (1.0, 0.0), (7.8e6, 0.47)]:
        lam, mu = lame_constants(*plane_stress_equivalent(E, nu))
        assert mu == pytest.approx(E / (2 * (1 + nu)), rel=1e-12)
        assert lam == pytest.approx(E * nu / (1 - nu**2), rel=1e-12, abs=1e-12)
        compliance = np.linalg.inv([[lam + 2 * mu, lam], [lam, lam + 2 * mu]])
        np.testing.assert_allclose(compliance[:, 0] * E, [1.0, -nu], rtol=1e-12, atol=1e-15)


def test_svk_stress_patch_numbers():
    F = jnp.diag(jnp.array([2.0, 3.0]))
    S = st_venant_kirchhoff_stress(green_lagrange_strain(F), 1.0, 1.0)
    np.testing.assert_allclose(S, np.diag([8.5, 13.5]), atol=1e-14)
    np.testing.assert_allclose(pk1_stress(F, S), np.diag([17.0, 40.5]), atol=1e-13)


def test_correction_matrix_is_identity_like_and_F_is_identity_undeformed():
    X, state, nb, model, params = _setup()
    fields = solid_fields(state, nb, model, params)
    L0 = np.asarray(fields["L0"])
    # sign convention of eq. 15: L0 ~ +I in the bulk (exactly I only in the continuum)
    np.testing.assert_allclose(L0[CENTRE], np.eye(2), atol=0.02)
    assert np.all(np.linalg.eigvalsh(0.5 * (L0 + L0.transpose(0, 2, 1))) > 0)
    # F == I on the reference configuration, for every particle (surface included)
    np.testing.assert_allclose(
        fields["F"], np.broadcast_to(np.eye(2), fields["F"].shape), atol=1e-12
    )
    np.testing.assert_allclose(fields["P"], 0.0, atol=1e-12)


@pytest.mark.parametrize(
    "A",
    [
        np.diag([2.0, 1.0]),
        np.diag([2.0, 3.0]),
        _rotation(ROTATION),
        np.array([[1.3, 0.4], [-0.2, 0.8]]),
    ],
    ids=["stretch21", "stretch23", "rotation", "general"],
)
def test_patch_deformation_gradient(A):
    X, state, nb, model, params = _setup()
    fields = solid_fields(_deform(state, X, A), nb, model, params)
    np.testing.assert_allclose(fields["F"][CENTRE], A, atol=1e-10)
    # the correction makes F exact for every particle, the free surface included
    np.testing.assert_allclose(fields["F"], np.broadcast_to(A, fields["F"].shape), atol=1e-10)


def test_patch_stress():
    X, state, nb, model, params = _setup()
    fields = solid_fields(_deform(state, X, np.diag([2.0, 3.0])), nb, model, params)
    np.testing.assert_allclose(fields["P"][CENTRE], np.diag([17.0, 40.5]), atol=1e-9)
    fields = solid_fields(_deform(state, X, _rotation(ROTATION)), nb, model, params)
    np.testing.assert_allclose(fields["P"][CENTRE], 0.0, atol=1e-10)


def _interior(n, margin):
    ij = np.stack(np.meshgrid(np.arange(n), np.arange(n), indexing="ij"), -1).reshape(-1, 2)
    return np.flatnonzero(np.all((ij >= margin) & (ij < n - margin), axis=1))


@pytest.mark.parametrize("A", [np.diag([2.0, 3.0]), np.array([[1.3, 0.4], [-0.2, 0.8]])])
def test_patch_affine_interior_has_no_acceleration(A):
    # interior = particles whose neighbours' neighbourhoods are complete (2 supports,
    # i.e. 4 lattice steps from the edge): the centre of 9 x 9, a 5 x 5 block of 13 x 13
    for n in (9, 13):
        X, state, nb, model, params = _setup(n=n)
        acc = np.asarray(solid_acceleration(_deform(state, X, A), nb, model, params))
        inner = _interior(n, 4)
        assert len(inner) == (n - 8) ** 2
        np.testing.assert_allclose(acc[inner], 0.0, atol=1e-9)
        # ... while the surface is loaded (the test could fail)
        assert np.abs(acc).max() > 1.0


def test_rotation_gives_no_acceleration_anywhere():
    X, state, nb, model, params = _setup()
    acc = solid_acceleration(_deform(state, X, _rotation(ROTATION)), nb, model, params)
    np.testing.assert_allclose(acc, 0.0, atol=1e-10)


def test_gravity_is_added():
    X, state, nb, model, params = _setup(gravity=(0.0, -2.0))
    acc = solid_acceleration(state, nb, model, params)
    np.testing.assert_allclose(acc, np.broadcast_to([0.0, -2.0], acc.shape), atol=1e-12)


def test_penalty_force_vanishes_for_affine_and_restores_a_kink():
    X, state, nb, model, params = _setup(penalty=True, penalty_alpha=0.1)
    _, _, _, plain, _ = _setup(penalty=False)
    deformed = _deform(state, X, np.array([[1.3, 0.4], [-0.2, 0.8]]))
    with_penalty = solid_acceleration(deformed, nb, model, params)
    without = solid_acceleration(deformed, nb, plain, params)
    np.testing.assert_allclose(with_penalty, without, atol=1e-10)
    # displace the centre particle: the penalty adds a force pulling it back
    kick = np.zeros_like(X)
    kick[CENTRE] = [0.01, 0.005]
    kinked = state.replace(position=jnp.asarray(X + kick))
    extra = solid_acceleration(kinked, nb, model, params) - solid_acceleration(
        kinked, nb, plain, params
    )
    assert float(jnp.dot(extra[CENTRE], kick[CENTRE])) < 0
    np.testing.assert_allclose(jnp.sum(extra, axis=0), 0.0, atol=1e-12)  # antisymmetric


def test_3d_patch_and_undeformed():
    X, state, nb, model, params = _setup(n=5, dim=3, kernel=WendlandC2(), h=0.13)
    fields = solid_fields(state, nb, model, params)
    np.testing.assert_allclose(
        fields["F"], np.broadcast_to(np.eye(3), fields["F"].shape), atol=1e-12
    )
    A = np.array([[1.2, 0.1, 0.0], [0.0, 0.9, 0.2], [0.1, 0.0, 1.1]])
    fields = solid_fields(_deform(state, X, A), nb, model, params)
    np.testing.assert_allclose(fields["F"], np.broadcast_to(A, fields["F"].shape), atol=1e-10)
    acc = solid_acceleration(_deform(state, X, A), nb, model, params)
    assert acc.shape == (len(X), 3) and bool(jnp.all(jnp.isfinite(acc)))


def test_clamped_particles_take_part_but_do_not_move():
    X = _lattice(6)
    kind = np.where(X[:, 0] < 0.15, Kind.CLAMPED, Kind.SOLID)
    model = Model(
        dim=2,
        smoothing_length=H,
        kernel=CubicSpline(),
        domain=Domain((-10.0, -10.0), (10.0, 10.0), (False, False)),
        systems=(SolidSystem(),),
    )
    params = make_params(2, young_modulus=2.5, poisson_ratio=0.25, solid_density=1.0)
    state = make_state(X, 0.0, 1.0, SPACING**2, kind)
    moved = state.replace(position=state.position.at[:, 0].multiply(1.1))
    nb = build_neighbors(state, model)
    out = evaluate(moved, nb, model, params)
    clamped = kind == Kind.CLAMPED
    np.testing.assert_array_equal(np.asarray(out.acceleration)[clamped], 0.0)
    assert np.abs(np.asarray(out.acceleration)[~clamped]).max() > 0
    # clamped F is computed from the same sums: a uniform stretch gives F = diag(1.1, 1)
    fields = solid_fields(moved, nb, model, params)
    np.testing.assert_allclose(
        fields["F"], np.broadcast_to(np.diag([1.1, 1.0]), fields["F"].shape), atol=1e-12
    )
    case = Case("clamped", moved, model, params, dt=1e-3, t_end=1.0)
    traj = sphjax.simulate(case, n_steps=20, save_every=20)
    np.testing.assert_array_equal(
        np.asarray(traj.final.position)[clamped], np.asarray(moved.position)[clamped]
    )


def _free_body(penalty):
    rng = np.random.default_rng(0)
    X = _lattice(8)[:48] * 0.5  # 6 x 8 block, spacing 0.05
    model = Model(
        dim=2,
        smoothing_length=0.06,
        kernel=WendlandC2(),
        domain=Domain((-10.0, -10.0), (10.0, 10.0), (False, False)),
        systems=(SolidSystem(penalty=PenaltyForce() if penalty else None),),
    )
    params = make_params(
        2,
        young_modulus=1.0e3,
        poisson_ratio=0.3,
        solid_density=1.0,
        penalty_alpha=0.1 if penalty else 0.0,
    )
    centre = X.mean(0)
    spin = 2.0 * np.stack([-(X[:, 1] - centre[1]), X[:, 0] - centre[0]], -1)
    velocity = spin + np.array([0.3, -0.1]) + 0.05 * rng.standard_normal(X.shape)
    state = make_state(X, velocity, 1.0, 0.05**2, Kind.SOLID)
    state = state.replace(position=state.position + 0.002 * rng.standard_normal(X.shape))
    case = Case("free", state, model, params, dt=0.0, t_end=1.0)
    dt = sphjax.stable_time_step(state, model, params)
    return case.replace(dt=dt)


def _momenta(state):
    m = np.asarray(state.mass)[:, None]
    x, v = np.asarray(state.position), np.asarray(state.velocity)
    linear = np.sum(m * v, axis=0)
    angular = np.sum(m[:, 0] * (x[:, 0] * v[:, 1] - x[:, 1] * v[:, 0]))
    return linear, angular


@pytest.mark.parametrize("penalty", [False, True], ids=["plain", "penalty"])
def test_free_body_conserves_momenta(penalty):
    case = _free_body(penalty)
    traj = sphjax.simulate(case, n_steps=1000, save_every=500)
    p0, l0 = _momenta(traj.frame(0))
    p1, l1 = _momenta(traj.final)
    scale = float(np.sum(np.asarray(case.state.mass) * np.linalg.norm(case.state.velocity, axis=1)))
    assert np.abs(p1 - p0).max() < 1e-13 * scale
    assert abs(l1 - l0) / abs(l0) < 1e-6
    # the body really deformed and moved (the test could fail)
    moved = np.abs(np.asarray(traj.final.position - case.state.position)).max()
    assert moved > 0.05


def test_gradient_of_plate_tip_wrt_young_modulus_is_finite():
    case = sphjax.cases.oscillating_plate(n=3)
    tip = sphjax.cases.tip_displacement

    def loss(E):
        params = case.params.replace(young_modulus=E)
        traj = sphjax.simulate(case, params, n_steps=60, save_every=60)
        return tip(traj, case)[-1, 1]

    value, grad = jax.value_and_grad(loss)(case.params.young_modulus)
    assert np.isfinite(float(grad)) and float(grad) != 0.0
    assert float(value) > 0  # the tip moved upwards

    def loss_density(rho):
        traj = sphjax.simulate(
            case, case.params.replace(solid_density=rho), n_steps=50, save_every=50
        )
        return tip(traj, case)[-1, 1]

    assert np.isfinite(float(jax.grad(loss_density)(case.params.solid_density)))
