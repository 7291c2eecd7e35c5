"""Particle packing in a periodic box, and masses that give a prescribed summation density.

* :func:`relax_periodic` moves particles under the background-pressure force of the
  transport-velocity formulation (Adami, Hu & Adams 2013) with unit masses,

      a_a = -(n_mean / 2) sum_b (1 / n_a^2 + 1 / n_b^2) grad_a W_ab,   n_a = sum_b W_ab,

  i.e. the gradient of the total particle volume ``sum_a 1 / n_a``, which is largest for
  a uniform number density.  The pseudo-time steps are ``d <- momentum d + step h^2 a``,
  ``x <- x + d`` (steepest ascent by default, ``momentum = 0``; a heavy ball otherwise).
  Started from a strongly disordered lattice and stopped after a finite number of steps,
  it leaves an isotropic, disordered distribution whose number density is uniform to
  about half a percent: the relaxed start of Adami et al. (2013) for the Taylor-Green
  vortex.  Relaxed much further (with momentum, say) the particles return towards the
  lattice, which the vortices then break up (docs/design.md).
* :func:`summation_masses` solves ``sum_b m_b W_ab = rho_a`` (eq. 5, self term included)
  for the masses by conjugate gradients (the matrix ``W_ab`` is symmetric positive
  definite for the spline and Wendland kernels), so that summation density reproduces
  a prescribed density field exactly from the first step.

Both run outside ``jit`` on the case's fixed geometry; :func:`summation_masses` is
written with ``jax.numpy`` so that masses derived from parameters stay differentiable.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from sphjax import kernels
from sphjax._host import device_array
from sphjax.neighbors.search import points_within


def periodic_neighbours(x, box: float, radius: float) -> np.ndarray:
    """``[N, K]`` indices of the particles within ``radius`` (minimum image in the square
    periodic box ``[0, box)^d``, distance ``<= radius``), padded with ``N``; the particle
    itself is left out.  Each row lists its neighbours in increasing index order."""
    x = np.mod(np.asarray(x, float), box)
    dim = x.shape[1]
    box = (float(box),) * dim
    return points_within(x, radius, (0.0,) * dim, box, (True,) * dim, closed=True)


def _pair_weights(x, idx, box, kernel, h):
    """``W_ab`` and ``grad_a W_ab`` over ``idx`` (minimum image), zero on padding."""
    n = x.shape[0]
    valid = idx < n
    j = jnp.where(valid, idx, 0)
    dr = x[:, None, :] - x[j]
    dr = dr - box * jnp.round(dr / box)
    r = jnp.sqrt(jnp.sum(dr**2, axis=-1))
    inside = valid & (r < kernel.support * h)
    r_safe = jnp.where(inside, r, 1.0)
    dim = x.shape[-1]
    w = jnp.where(inside, kernels.W(kernel, r_safe, h, dim), 0.0)
    grad = jnp.where(inside[..., None], kernels.grad_W(kernel, dr, r_safe, h, dim), 0.0)
    return j, w, grad


@functools.partial(jax.jit, static_argnames=("kernel", "h", "box", "step", "momentum"))
def _relax_block(x, d, idx, count, *, kernel, h, box, step, momentum):
    dim = x.shape[-1]
    self_weight = kernels.W(kernel, 0.0, h, dim)

    def number_density(x):
        j, w, grad = _pair_weights(x, idx, box, kernel, h)
        return j, self_weight + jnp.sum(w, axis=1), grad

    def one(_, carry):
        x, d = carry
        j, number, grad = number_density(x)
        q = 1.0 / number**2
        a = -0.5 * jnp.mean(number) * jnp.sum((q[:, None] + q[j])[..., None] * grad, axis=1)
        d = momentum * d + step * h**2 * a
        return jnp.mod(x + d, box), d

    x, d = jax.lax.fori_loop(0, count, one, (x, d))
    number = number_density(x)[1]
    return x, d, jnp.std(number) / jnp.mean(number)


def relax_periodic(
    x,
    box: float,
    kernel,
    h: float,
    iterations: int,
    step: float = 0.1,
    momentum: float = 0.0,
    rebuild_every: int = 50,
):
    """Relax positions ``x`` (``[N, d]``) in the periodic box ``[0, box)^d``.

    Returns ``(x, spread)``: the relaxed positions (numpy float64 holding float32 values:
    the packing runs in float32 in every session) and the relative standard
    deviation of the number density ``sum_b W_ab`` after the last step.  The neighbour
    lists are rebuilt every ``rebuild_every`` steps with a skin of one ``h`` (a block in
    which some particle moves more than half the skin is repeated in halves).
    """
    # float32 whatever jax_enable_x64 says, so that a case builds the same positions in
    # float32 and float64 sessions
    # (numpy arguments: the jitted block takes them without an eager conversion program)
    x = np.mod(np.asarray(x, float), box).astype(np.float32)
    d = np.zeros_like(x)
    spread = float("nan")
    done = 0
    count = rebuild_every
    while done < iterations:
        count = min(count, iterations - done)
        idx = periodic_neighbours(np.asarray(x), box, (kernel.support + 1.0) * h)
        # pad the neighbour count to a multiple of 16 so that few shapes are compiled
        pad = -idx.shape[1] % 16
        idx = np.pad(idx, ((0, 0), (0, pad)), constant_values=len(idx))
        x_new, d_new, spread_new = _relax_block(
            x,
            d,
            idx,
            np.int32(count),
            kernel=kernel,
            h=float(h),
            box=float(box),
            step=float(step),
            momentum=float(momentum),
        )
        moved = np.asarray(x_new) - np.asarray(x)
        moved -= box * np.round(moved / box)
        if np.max(np.linalg.norm(moved, axis=-1)) > 0.5 * h and count > 1:
            count //= 2  # beyond half the skin: repeat with a shorter block
            continue
        x, d, spread = x_new, d_new, float(spread_new)
        done += count
        count = rebuild_every
    return np.asarray(x, np.float64), float(spread)


def summation_masses(x, idx, box: float, kernel, h: float, density, tol: float | None = None):
    """Masses ``m`` with ``m_a W(0) + sum_b m_b W_ab = density_a`` (eq. 5), jax.numpy.

    Args:
      x: ``[N, d]`` positions; idx: their neighbours (:func:`periodic_neighbours`).
      density: ``[N]`` prescribed densities (may be traced).
      tol: relative residual of the conjugate gradients (default 1e-6 in float32,
        1e-12 in float64).
    Returns:
      ``[N]`` masses (conjugate gradients from ``density * V_a``, ``V_a = 1 / sum_b W_ab``).
    """
    density = device_array(density)
    if tol is None:
        tol = 1e-12 if density.dtype == jnp.float64 else 1e-6
    return _solve_masses(
        device_array(x, density.dtype),
        device_array(idx),
        density,
        kernel=kernel,
        h=float(h),
        box=float(box),
        tol=float(tol),
    )


@functools.partial(jax.jit, static_argnames=("kernel", "h", "box", "tol"))
def _solve_masses(x, idx, density, *, kernel, h, box, tol):
    j, w, _ = _pair_weights(x, idx, box, kernel, h)
    self_weight = kernels.W(kernel, 0.0, h, x.shape[-1])

    def matvec(m):
        return self_weight * m + jnp.sum(w * m[j], axis=1)

    volume = 1.0 / (self_weight + jnp.sum(w, axis=1))
    masses, _ = jax.scipy.sparse.linalg.cg(
        matvec, density, x0=density * volume, tol=tol, maxiter=1000
    )
    return masses
