"""Antuono et al. (2010, 2012) density diffusion (``sphjax.Antuono``): the per-pair term
against a double loop over its equations, exact cancellation of linear density fields,
mass conservation, the adjoint, and a hydrostatic column that stays at rest.  About 100 s in
all (load average 6), a third of it the tank."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sphjax
from sphjax import Kind, build_neighbors
from sphjax.core import kernels

DX, H = 0.1, 0.13
DELTA, C0 = 0.1, 20.0


def _particles(n=9, jitter=0.2, seed=1):
    rng = np.random.default_rng(seed)
    g = (np.arange(n) + 0.5) * DX
    x = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    return x + jitter * DX * rng.uniform(-1, 1, x.shape)


def _model(diffusion):
    return sphjax.Model(
        dim=2,
        smoothing_length=H,
        kernel=kernels.WendlandC2(),
        domain=sphjax.Domain((-1.0, -1.0), (2.0, 2.0), (False, False)),
        systems=(
            sphjax.FluidSystem(
                equation_of_state=sphjax.TaitEOS(gamma=1.0),
                density=sphjax.ContinuityDensity(),
                density_diffusion=diffusion,
            ),
        ),
    )


def _rate(x, rho, mass, diffusion=None, gravity=(0.0, 0.0)):
    """``Drho/Dt`` of particles at rest (continuity term 0): the diffusion alone."""
    model = _model(sphjax.Antuono() if diffusion is None else diffusion)
    params = sphjax.make_params(
        2,
        reference_density=1000.0,
        sound_speed=C0,
        density_diffusion=DELTA,
        gravity=gravity,
    )
    state = sphjax.make_state(x, 0.0, rho, mass, Kind.FLUID)
    rates = sphjax.evaluate(state, build_neighbors(state, model), model, params)
    return np.asarray(rates.density_rate)


def _direct(x, rho, volume):
    """The equations of the module docstring of sphjax.physics.fluid.density_diffusion,
    one pair at a time (numpy)."""
    kernel = kernels.WendlandC2()
    n = len(x)
    r_all = x[:, None, :] - x[None, :, :]
    dist = np.linalg.norm(r_all, axis=-1) + np.eye(n)
    dw = np.asarray(kernels.dW_dr(kernel, jnp.asarray(dist), H, 2))

    def grad_w(a, b):
        return dw[a, b] * r_all[a, b] / dist[a, b]

    near = [[b for b in range(n) if b != a and dist[a, b] < kernel.support * H] for a in range(n)]
    gradient = np.zeros((n, 2))
    for a in range(n):
        m = sum(volume[b] * np.outer(grad_w(a, b), x[b] - x[a]) for b in near[a])
        s = sum((rho[b] - rho[a]) * grad_w(a, b) * volume[b] for b in near[a])
        gradient[a] = np.linalg.solve(m, s)
    rate = np.zeros(n)
    for a in range(n):
        for b in near[a]:
            r_ba = x[b] - x[a]
            psi = 2 * (rho[b] - rho[a]) * r_ba / (r_ba @ r_ba) - (gradient[a] + gradient[b])
            rate[a] += psi @ grad_w(a, b) * volume[b]
    return DELTA * H * C0 * rate


def test_matches_the_equations_pair_by_pair_and_conserves_mass():
    x = _particles()
    rng = np.random.default_rng(2)
    rho = 1000.0 * (1 + 0.01 * rng.standard_normal(len(x)))
    mass = rho * DX**2 * (1 + 0.05 * rng.uniform(-1, 1, len(x)))
    rate = _rate(x, rho, mass)
    expected = _direct(x, rho, mass / rho)
    np.testing.assert_allclose(rate, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())
    assert np.abs(rate).max() > 1.0  # not trivially zero
    # sum_a V_a D_a = 0 (psi_ab symmetric, grad W antisymmetric)
    volume = mass / rho
    assert abs(np.sum(volume * rate)) < 1e-10 * np.sum(volume * np.abs(rate))


def test_linear_density_field_does_not_diffuse():
    """A linear field (the hydrostatic one) gives D = 0 at every particle, those at the
    edge of the patch included, on an irregular distribution; Molteni & Colagrossi's
    term without its hydrostatic correction does not vanish."""
    x = _particles(jitter=0.3)
    rho = 1000.0 + x @ np.array([3.0, -2.0])
    mass = rho * DX**2
    molteni = _rate(x, rho, mass, sphjax.MolteniColagrossi())
    assert np.abs(molteni).max() > 1.0
    assert np.abs(_rate(x, rho, mass)).max() < 1e-9 * np.abs(molteni).max()


@pytest.mark.parametrize("k", [1, 2])
def test_a_density_wave_diffuses(k):
    """A cosine density perturbation decays: D has the sign of -(rho - rho0) at the
    interior crests and troughs."""
    x = _particles(n=15, jitter=0.0)
    wave = np.cos(2 * np.pi * k * x[:, 0] / (15 * DX))
    rho = 1000.0 * (1 + 1e-3 * wave)
    rate = _rate(x, rho, rho * DX**2)
    interior = np.all((x > 3 * DX) & (x < 12 * DX), axis=-1) & (np.abs(wave) > 0.9)
    assert interior.sum() > 4
    assert np.all(rate[interior] * wave[interior] < 0)


def test_hydrostatic_column_stays_at_rest():
    """With Antuono's diffusion (no hydrostatic correction needed) the tank of
    test_validation_fluid holds still as with Molteni's: after 1 s (H = 1 m, 16 particles
    over the depth) the largest speed is below 1 % of sqrt(g H), the bottom pressure within
    3 % of rho0 g H, and the mean density stays within 0.1 % of its start."""
    case = sphjax.cases.hydrostatic_tank(n=16, density_diffusion="antuono", t_end=1.0)
    assert isinstance(case.model.systems[0].density_diffusion, sphjax.Antuono)
    n_steps = int(round(1.0 / case.dt))
    n_steps -= n_steps % 2
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=n_steps // 2)
    info = case.info
    g, H = info["gravity"], info["height"]
    fluid = np.asarray(case.state.kind) == Kind.FLUID
    final = traj.final
    x = np.asarray(final.position)[fluid]
    p = np.asarray(final.pressure)[fluid]
    speeds = np.linalg.norm(np.asarray(final.velocity)[fluid], axis=-1)
    assert speeds.max() < 0.01 * np.sqrt(g * H)
    _, bottom = np.polyfit(x[:, 1], p, 1)
    assert bottom == pytest.approx(1000.0 * g * H, rel=0.03)
    rho = np.asarray(traj.states.density)[:, fluid]
    assert np.mean(rho[-1]) == pytest.approx(np.mean(rho[0]), rel=1e-3)
    assert np.all(np.isfinite(rho))


def test_pair_adjoint_equals_autodiff():
    """The gradient through Antuono's term (two pair sums, the per-particle solve, the
    diffusion pair sum) with pair_sum's custom adjoint equals JAX's autodiff
    (``Model(pair_adjoint=False)``) to round-off, w.r.t. positions, velocities, masses,
    densities and the parameters ``density_diffusion`` and ``sound_speed``."""
    x = _particles(jitter=0.3)
    rng = np.random.default_rng(3)
    rho = 1000.0 * (1 + 0.01 * rng.standard_normal(len(x)))
    state = sphjax.make_state(x, 0.1 * rng.standard_normal(x.shape), rho, rho * DX**2, Kind.FLUID)
    params = sphjax.make_params(
        2, reference_density=1000.0, sound_speed=C0, density_diffusion=DELTA
    )
    weights = jnp.asarray(rng.standard_normal(len(x)))

    def gradient(pair_adjoint):
        model = _model(sphjax.Antuono()).replace(pair_adjoint=pair_adjoint)
        neighbors = build_neighbors(state, model)

        def loss(position, velocity, mass, density, delta, c0):
            s = state.replace(position=position, velocity=velocity, mass=mass, density=density)
            p = params.replace(density_diffusion=delta, sound_speed=c0)
            rates = sphjax.evaluate(s, neighbors, model, p)
            return jnp.sum(weights * rates.density_rate) + jnp.sum(rates.pressure**2) * 1e-6

        args = (state.position, state.velocity, state.mass, state.density, DELTA, C0)
        # one program, not one per operation
        return jax.jit(jax.grad(loss, argnums=tuple(range(6))))(*args)

    custom, auto = gradient(True), gradient(False)
    for c, a in zip(custom, auto, strict=True):
        scale = float(jnp.max(jnp.abs(a)))
        assert scale > 0
        assert float(jnp.max(jnp.abs(c - a))) < 1e-10 * scale
