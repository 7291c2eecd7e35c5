"""Radius graphs for the learned simulator, with the minimum image on periodic axes.

A jax-md cell list in dense format: ``idx[i, k]`` is the ``k``-th neighbour (sender) of
particle ``i`` (receiver) within ``radius``, padded with ``N``.  The capacity ``K`` is set
when the graph is allocated (outside ``jit``); inside ``jit`` the graph is rebuilt for new
positions and reports an overflow, and the caller re-allocates (never silently).  Closed
axes get a box padded by twice the radius so no image reaches across them.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
from jax_md import partition
from jax_md import space as jmd_space


@dataclasses.dataclass(frozen=True)
class RadiusGraph:
    """Neighbour search within ``radius`` in the box ``bounds`` (``[[lo, hi]] * d``)."""

    bounds: tuple[tuple[float, float], ...]
    periodic: tuple[bool, ...]
    radius: float
    capacity_multiplier: float = 1.5

    @property
    def box(self) -> np.ndarray:
        size = np.array([hi - lo for lo, hi in self.bounds])
        return np.where(np.array(self.periodic), size, size + 4.0 * self.radius)

    def _to_box(self, x):
        lo = np.array([lo for lo, _ in self.bounds])
        offset = np.where(np.array(self.periodic), -lo, -lo + 2.0 * self.radius)
        return jnp.mod(x + offset.astype(x.dtype), self.box.astype(x.dtype))

    def _fns(self):
        displacement, _ = jmd_space.periodic(self.box)
        return partition.neighbor_list(
            displacement,
            self.box,
            r_cutoff=self.radius,
            dr_threshold=0.0,
            capacity_multiplier=self.capacity_multiplier,
            format=partition.Dense,
        )

    def allocate(self, position, extra_capacity: int = 0):
        """A neighbour list for concrete ``[N, d]`` positions (outside ``jit``)."""
        x = self._to_box(jnp.asarray(position, jnp.float32))
        return self._fns().allocate(x, extra_capacity=extra_capacity)

    def update(self, position, neighbors):
        """Rebuild for ``position`` with the capacity of ``neighbors`` (jittable)."""
        return self._fns().update(self._to_box(position), neighbors)


def overflowed(neighbors) -> jax.Array:
    return jnp.any(neighbors.did_buffer_overflow)


def capacity(neighbors) -> int:
    return int(neighbors.idx.shape[-1])
