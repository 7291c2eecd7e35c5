"""Radius graphs for the learned simulator, through the package's neighbour search.

:class:`RadiusGraph` wraps :class:`sphjax.neighbors.NeighborSearch` (jax-md cell list,
dense format ``idx[i, k]``: the ``k``-th neighbour, sender, of particle ``i``, receiver;
padded with ``N``), built for the geometry of a Model whose kernel support is the
connectivity radius and whose domain is the dataset's box.  So the surrogate and the
solver share one neighbour search: the minimum image on periodic axes, the padded box on
closed axes and the Verlet skin (the list holds every pair within ``radius + skin``; the
features mask pairs beyond ``radius``).  The capacity ``K`` is set when the graph is
allocated (outside ``jit``); inside ``jit`` the graph is updated for new positions and
reports an overflow, and the caller re-allocates (never silently).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from sphjax.core.kernels import WendlandC2
from sphjax.core.model import Domain, Model
from sphjax.neighbors import NeighborSearch, SearchGeometry
from sphjax.physics.fluid.system import FluidSystem


@dataclasses.dataclass(frozen=True)
class RadiusGraph:
    """Neighbour search within ``radius`` in the box ``bounds`` (``[[lo, hi]] * d``)."""

    bounds: tuple[tuple[float, float], ...]
    periodic: tuple[bool, ...]
    radius: float
    capacity_multiplier: float = 1.5

    @property
    def model(self) -> Model:
        """A Model whose support radius is ``radius`` (Wendland C2, support ``2h``)."""
        kernel = WendlandC2()
        return Model(
            dim=len(self.bounds),
            smoothing_length=float(self.radius) / kernel.support,
            kernel=kernel,
            domain=Domain(
                tuple(float(lo) for lo, _ in self.bounds),
                tuple(float(hi) for _, hi in self.bounds),
                tuple(bool(p) for p in self.periodic),
            ),
            systems=(FluidSystem(),),
            neighbor_capacity=float(self.capacity_multiplier),
        )

    @property
    def search(self) -> NeighborSearch:
        geometry = SearchGeometry.of(self.model)
        return NeighborSearch(geometry, x64=bool(jax.config.jax_enable_x64))

    def allocate(self, position, extra_capacity: int = 0):
        """A neighbour list for concrete ``[N, d]`` positions (outside ``jit``)."""
        return self.search.allocate(jnp.asarray(position), extra_capacity)

    def update(self, position, neighbors):
        """Neighbours at ``position`` with the capacity of ``neighbors`` (jittable; always
        rebuilt: successive calls see unrelated windows in training)."""
        return self.search.rebuild(position, neighbors)


def overflowed(neighbors) -> jax.Array:
    return jnp.any(neighbors.did_buffer_overflow)


def capacity(neighbors) -> int:
    return int(neighbors.idx.shape[-1])
