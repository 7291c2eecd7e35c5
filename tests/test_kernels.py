"""Kernels: normalisation on a lattice and gradients against automatic differentiation.

VALIDATION.md ("Kernels"): a kernel must integrate to 1 and its gradient must match
automatic differentiation of W.  Tolerance 1e-4 relative (issue 2) on a lattice with
spacing h / 4, fine enough that the lattice sum converges to the integral well below it.
"""

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sphjax import kernels
from sphjax.core.space import safe_norm

KERNELS = [
    kernels.CubicSpline(),
    kernels.QuinticSpline(),
    kernels.WendlandC2(),
    kernels.WendlandC4(),
]


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: type(k).__name__)
@pytest.mark.parametrize("dim", [2, 3])
def test_kernel_integrates_to_one(kernel, dim):
    h = 1.0
    spacing = h / 4 if dim == 2 else h / 3
    reach = int(np.ceil(kernel.support * h / spacing)) + 1
    axis = np.arange(-reach, reach + 1) * spacing
    points = np.array(list(itertools.product(axis, repeat=dim)))
    r = np.linalg.norm(points, axis=1)
    total = float(jnp.sum(kernels.W(kernel, jnp.asarray(r), h, dim))) * spacing**dim
    assert abs(total - 1.0) < 1e-4


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: type(k).__name__)
@pytest.mark.parametrize("dim", [2, 3])
def test_gradient_matches_autodiff(kernel, dim):
    h = 0.7
    rng = np.random.default_rng(0)
    dr = rng.uniform(-1, 1, size=(200, dim)) * kernel.support * h / np.sqrt(dim)

    def w_of_vector(d):
        return kernels.W(kernel, safe_norm(d), h, dim)

    auto = jax.vmap(jax.grad(w_of_vector))(jnp.asarray(dr))
    analytic = kernels.grad_W(kernel, jnp.asarray(dr), safe_norm(jnp.asarray(dr)), h, dim)
    np.testing.assert_allclose(analytic, auto, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: type(k).__name__)
def test_kernel_vanishes_beyond_support_and_is_safe_at_zero(kernel):
    h = 0.5
    r = jnp.array([kernel.support * h, kernel.support * h * 1.5])
    np.testing.assert_array_equal(np.asarray(kernels.W(kernel, r, h, 2)), 0.0)
    grad_at_zero = jax.grad(lambda d: kernels.W(kernel, safe_norm(d), h, 2))(jnp.zeros(2))
    assert np.all(np.isfinite(np.asarray(grad_at_zero)))
    g = kernels.grad_W(kernel, jnp.zeros((1, 2)), jnp.zeros(1), h, 2)
    np.testing.assert_array_equal(np.asarray(g), 0.0)


def test_unknown_kernel_name_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown kernel 'gauss'"):
        kernels.kernel_by_name("gauss")
