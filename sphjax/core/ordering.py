"""Particles in cell order: a space-filling (Morton, Z-curve) order of each system's
particles, so that a particle's neighbours sit close to it in memory.

The pair sums gather the neighbours' fields ``q[j]`` for every row; when neighbours are
near in index their fields share cache lines.  :func:`cell_order` sorts each system's
block of the State (blocks stay where they are) by the Morton code of the particle's cell
(cells one kernel support wide); :func:`sphjax.simulate` runs in that order and hands
every output back in the user's order (:func:`permute`).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np


def _spread_bits(v: np.ndarray, dim: int) -> np.ndarray:
    """The bits of ``v`` (non-negative int64) spread ``dim`` apart: bit ``k`` to
    ``dim * k``."""
    v = v.astype(np.uint64)
    out = np.zeros_like(v)
    for k in range(64 // dim):
        out |= ((v >> np.uint64(k)) & np.uint64(1)) << np.uint64(dim * k)
    return out


def morton_codes(position: np.ndarray, cell: float) -> np.ndarray:
    """``[N]`` Morton codes of the cells (``cell`` wide) of ``position`` ``[N, d]``."""
    x = np.asarray(position, dtype=np.float64)
    if x.shape[0] == 0:
        return np.zeros(0, np.uint64)
    index = np.floor((x - x.min(0)) / cell).astype(np.int64)
    code = np.zeros(x.shape[0], np.uint64)
    for axis in range(x.shape[1]):
        code |= _spread_bits(index[:, axis], x.shape[1]) << np.uint64(axis)
    return code


def cell_order(position, blocks, cell: float) -> np.ndarray:
    """``[N]`` permutation that puts the particles of each ``(start, stop)`` block in
    Morton order of their cells (``state[perm]`` is the sorted State)."""
    x = np.asarray(position)
    perm = np.arange(x.shape[0])
    for start, stop in blocks:
        if stop - start > 1:
            order = np.argsort(morton_codes(x[start:stop], cell), kind="stable")
            perm[start:stop] = start + order
    return perm


def inverse(perm: np.ndarray) -> np.ndarray:
    """The inverse permutation: ``perm[inverse(perm)] = arange(N)``."""
    inv = np.empty_like(perm)
    inv[perm] = np.arange(perm.shape[0])
    return inv


def permute(tree, perm, axis: int = 0):
    """Every array of ``tree`` with ``N = len(perm)`` entries along ``axis`` taken in the
    order ``perm`` (scalars and other arrays are left as they are)."""
    n = perm.shape[0]
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    which = [i for i, a in enumerate(leaves) if getattr(a, "ndim", 0) > axis and a.shape[axis] == n]
    arrays = [leaves[i] for i in which]
    traced = any(isinstance(a, jax.core.Tracer) for a in arrays)
    if traced or jax.default_backend() != "cpu":
        taken = _take(arrays, jnp.asarray(perm), axis)
    else:  # concrete arrays in host memory: numpy, nothing to compile
        taken = [jax.device_put(np.take(np.asarray(a), perm, axis=axis)) for a in arrays]
    for i, a in zip(which, taken, strict=True):
        leaves[i] = a
    return jax.tree_util.tree_unflatten(treedef, leaves)


@functools.partial(jax.jit, static_argnums=2)
def _take(arrays, perm, axis: int):
    """Every array of the list ``arrays`` taken in the order ``perm`` along ``axis``: one
    compiled program for them all (one per array, compiled at first use, would cost a
    small run's start-up about a tenth of a second each)."""
    return [jnp.take(a, perm, axis=axis) for a in arrays]
