"""Antuono et al. (2010, 2012) density diffusion (sphjax.fluid.density_diffusion_antuono).

Checked against a direct double loop over the equations of the module docstring, for the
exact cancellation of linear density fields, and for conservation of mass.  Fast (< 5 s).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from sphjax import kernels
from sphjax.fluid.density_diffusion_antuono import (
    antuono_density_diffusion,
    renormalised_density_gradient,
)
from sphjax.neighbors import pair_geometry
from sphjax.space import displacement_fn
from sphjax.state import Domain, Model

DX, H = 0.1, 0.13
DELTA, C0 = 0.1, 20.0


def _particles(n=9, jitter=0.2, seed=1):
    rng = np.random.default_rng(seed)
    g = (np.arange(n) + 0.5) * DX
    x = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    return x + jitter * DX * rng.uniform(-1, 1, x.shape)


def _pairs(x):
    kernel = kernels.WendlandC2()
    model = Model(
        dim=2,
        smoothing_length=H,
        kernel=kernel,
        domain=Domain((-1.0, -1.0), (2.0, 2.0), (False, False)),
    )
    n = len(x)
    others = np.arange(n - 1)
    idx = others[None, :] + (others[None, :] >= np.arange(n)[:, None])
    pairs = pair_geometry(
        jnp.asarray(x), jnp.asarray(x), jnp.asarray(idx), displacement_fn(model.domain), model
    )
    return pairs, kernel


def _direct(x, rho, volume, kernel):
    """The equations of the module docstring, one pair at a time (numpy)."""
    n = len(x)
    cutoff = kernel.support * H
    r_all = x[:, None, :] - x[None, :, :]
    dist = np.linalg.norm(r_all, axis=-1) + np.eye(n)
    dw = np.asarray(kernels.dW_dr(kernel, jnp.asarray(dist), H, 2))

    def grad_w(a, b):
        return dw[a, b] * r_all[a, b] / dist[a, b]

    near = [
        [b for b in range(n) if b != a and np.linalg.norm(x[a] - x[b]) < cutoff] for a in range(n)
    ]
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
    return DELTA * H * C0 * rate, gradient


def test_matches_the_equations_pair_by_pair():
    x = _particles()
    rng = np.random.default_rng(2)
    rho = 1000.0 * (1 + 0.01 * rng.standard_normal(len(x)))
    volume = DX**2 * (1 + 0.05 * rng.uniform(-1, 1, len(x)))
    pairs, kernel = _pairs(x)
    volume_b = jnp.asarray(volume)[pairs.j]
    rate = antuono_density_diffusion(jnp.asarray(rho), volume_b, pairs, DELTA, H, C0)
    gradient = renormalised_density_gradient(jnp.asarray(rho), volume_b, pairs)
    expected_rate, expected_gradient = _direct(x, rho, volume, kernel)
    np.testing.assert_allclose(gradient, expected_gradient, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(
        rate, expected_rate, rtol=1e-9, atol=1e-9 * np.abs(expected_rate).max()
    )
    # mass conservation: sum_a V_a D_a = 0 (psi_ab symmetric, grad W antisymmetric)
    assert abs(float(jnp.sum(volume * rate))) < 1e-10 * float(jnp.sum(volume * jnp.abs(rate)))
    assert float(jnp.abs(rate).max()) > 1.0  # not trivially zero


def test_linear_density_field_does_not_diffuse():
    """A linear field (the hydrostatic one) has D = 0 at every particle, surface ones
    included, on an irregular distribution; Molteni's term alone would not vanish."""
    x = _particles(jitter=0.3)
    g = np.array([3.0, -2.0])
    rho = 1000.0 + x @ g
    pairs, _ = _pairs(x)
    volume_b = jnp.full(pairs.j.shape, DX**2)
    gradient = renormalised_density_gradient(jnp.asarray(rho), volume_b, pairs)
    np.testing.assert_allclose(gradient, np.broadcast_to(g, gradient.shape), rtol=1e-9)
    rate = antuono_density_diffusion(jnp.asarray(rho), volume_b, pairs, DELTA, H, C0)
    without = antuono_density_diffusion(
        jnp.asarray(rho), volume_b, pairs, DELTA, H, C0, gradient=jnp.zeros_like(gradient)
    )
    assert float(jnp.abs(without).max()) > 1.0
    assert float(jnp.abs(rate).max()) < 1e-9 * float(jnp.abs(without).max())


@pytest.mark.parametrize("k", [1, 2])
def test_a_density_bump_diffuses(k):
    """A cosine density perturbation decays: D has the opposite sign of rho - rho0 at the
    interior crests and troughs."""
    x = _particles(n=15, jitter=0.0)
    wave = np.cos(2 * np.pi * k * x[:, 0] / (15 * DX))
    rho = 1000.0 * (1 + 1e-3 * wave)
    pairs, _ = _pairs(x)
    volume_b = jnp.full(pairs.j.shape, DX**2)
    rate = np.asarray(antuono_density_diffusion(jnp.asarray(rho), volume_b, pairs, DELTA, H, C0))
    interior = np.all((x > 3 * DX) & (x < 12 * DX), axis=-1) & (np.abs(wave) > 0.9)
    assert interior.sum() > 4
    assert np.all(rate[interior] * wave[interior] < 0)
