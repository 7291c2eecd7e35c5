"""Neighbour search: jax-md cell lists, and neighbour lists per pair of systems.

Systems that interact in the current configuration (fluid, walls) search their neighbours
together with jax-md cell lists (``jax_md.partition.neighbor_list``, dense format
``[N, K]``) and a Verlet skin: the list is rebuilt inside ``jit`` only when some particle
has moved half the skin.  At each rebuild it is split into one list per interacting pair of
systems (:func:`split_list`), each with a capacity sized from the neighbour counts measured
when it was allocated, so that pairs that do not interact (wall-wall) are never formed.
Capacities are fixed when allocated, outside ``jit``.  An overflow is never silent:
:func:`sphjax.simulate` re-allocates with more room and repeats the lost chunk, or, under
``jax.grad`` / ``jit``, stops with an error naming ``Model.neighbor_capacity``.

Solids use their reference-configuration neighbours, found once
(:func:`reference_neighbors`; eqs. 15-16).
"""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
from jax_md import partition
from jax_md import space as jmd_space

from sphjax.core.space import minimum_image

_CELL_LIST_FNS: dict = {}


@dataclasses.dataclass(frozen=True)
class NeighborSearch:
    """jax-md cell-list neighbour search for a Model (built once, outside ``jit``).

    Positions are shifted into the box jax-md expects (``[0, L)`` per axis).  Non-periodic
    axes get a padded box (``size + 2 (cutoff + skin)``) so that no image across them is
    ever within the cutoff.

    ``x64`` is the ``jax_enable_x64`` setting the jax-md functions are built under: they
    hold constants of that precision, so a session that switches it needs another search.
    """

    model: object
    x64: bool = False

    @property
    def skin(self) -> float:
        return self.model.neighbor_skin * self.model.cutoff

    @property
    def _padding(self) -> float:
        return 2.0 * (self.model.cutoff + self.skin)

    @property
    def box(self) -> np.ndarray:
        domain = self.model.domain
        return np.array(
            [
                size if periodic else size + 2.0 * self._padding
                for size, periodic in zip(domain.size, domain.periodic, strict=True)
            ]
        )

    def to_box(self, position):
        domain = self.model.domain
        offset = np.array(
            [
                -lo if periodic else -lo + self._padding
                for lo, periodic in zip(domain.lower, domain.periodic, strict=True)
            ]
        )
        shifted = position + offset.astype(position.dtype)
        box = self.box.astype(position.dtype)
        return jnp.mod(shifted, box)

    @functools.cache  # noqa: B019 (one NeighborSearch per Model, cached in integrate)
    def _functions(self, dr_threshold: float):
        # jax-md computes a few constants (box, cutoffs) with jax.numpy when the functions
        # are built.  The first call may happen inside a trace (``rebuild`` under
        # ``jax.grad``); build them eagerly so the cache never holds a tracer that would
        # leak into later traces (UnexpectedTracerError).
        with jax.ensure_compile_time_eval():
            displacement, _ = jmd_space.periodic(self.box)
            return partition.neighbor_list(
                displacement,
                self.box,
                r_cutoff=self.model.cutoff + (self.skin if dr_threshold == 0 else 0.0),
                dr_threshold=dr_threshold,
                capacity_multiplier=self.model.neighbor_capacity,
                format=partition.Dense,
            )

    def allocate(self, position, extra_capacity: int = 0):
        """A new neighbour list for concrete ``position`` (outside ``jit``)."""
        fns = self._functions(self.skin)
        neighbors = fns.allocate(self.to_box(jnp.asarray(position)), extra_capacity=extra_capacity)
        # The update and cell-list functions are static (pytree metadata) in the list: new
        # function objects at every allocation would make every jitted step recompile.
        # ``_functions`` is cached; jax-md makes a new cell-list function object at each
        # allocation, so keep the first one (same box, cell size and multiplier).
        cell_list_fn = _CELL_LIST_FNS.setdefault(self, neighbors.cell_list_fn)
        return neighbors.set(cell_list_fn=cell_list_fn)

    def update(self, position, neighbors):
        """Update inside ``jit``: rebuilt only if a particle moved more than half the skin."""
        return neighbors.update(self.to_box(position))

    def rebuild(self, position, neighbors):
        """Force a rebuild at ``position`` with the capacity of ``neighbors`` (jittable)."""
        fns = self._functions(0.0)
        return fns.update(self.to_box(position), neighbors)


def capacity(neighbors) -> int:
    """Neighbour slots per particle of a jax-md dense neighbour list."""
    return int(neighbors.idx.shape[-1])


def reference_neighbors(reference_position, members, model) -> np.ndarray:
    """Reference-configuration neighbour indices among ``members`` (computed once, numpy).

    Args:
      reference_position: ``[N, d]`` reference positions ``X``.
      members: ``[M]`` indices of the particles taking part (e.g. solid and clamped).
    Returns:
      ``[M, K]`` int32 global neighbour indices within the kernel support (self
      excluded), padded with ``N``.
    """
    X = np.asarray(reference_position, dtype=np.float64)
    members = np.asarray(members)
    n = X.shape[0]
    Xm = X[members]
    cutoff = model.cutoff
    domain = model.domain
    size = np.array(domain.size)
    periodic = np.array(domain.periodic)
    # cell binning on the reference configuration
    cell = np.floor((Xm - Xm.min(0)) / cutoff).astype(np.int64)
    buckets: dict[tuple, list[int]] = {}
    for k, c in enumerate(map(tuple, cell)):
        buckets.setdefault(c, []).append(k)
    offsets = (
        np.array(np.meshgrid(*[[-1, 0, 1]] * X.shape[1], indexing="ij")).reshape(X.shape[1], -1).T
    )
    lists = []
    for k, c in enumerate(cell):
        cand = []
        for off in offsets:
            cand.extend(buckets.get(tuple(c + off), ()))
        cand = np.array([q for q in cand if q != k], dtype=np.int64)
        if cand.size:
            dr = Xm[k] - Xm[cand]
            if periodic.any():
                dr = minimum_image(dr, size, periodic)
            close = np.sum(dr * dr, axis=1) < cutoff**2
            cand = cand[close]
        lists.append(members[cand] if cand.size else np.zeros(0, np.int64))
    width = max(1, max(len(x) for x in lists))
    idx = np.full((len(members), width), n, dtype=np.int32)
    for k, x in enumerate(lists):
        idx[k, : len(x)] = x
    return idx


def split_list(union_idx, rows: tuple[int, int], cols: tuple[int, int], capacity: int):
    """The neighbours of the particles ``rows`` among the particles ``cols``.

    Args:
      union_idx: ``[N, K]`` a jax-md dense list over the particles of several systems
        (indices into them, padded with ``N``).
      rows, cols: ``(start, stop)`` of the two systems' blocks within those particles.
      capacity: the width of the result.
    Returns:
      ``(idx, overflow)``: ``[rows, capacity]`` indices local to ``cols`` (padded with the
      size of ``cols``) and whether some row had more than ``capacity`` such neighbours.
    """
    block = union_idx[rows[0] : rows[1]]
    n_cols = cols[1] - cols[0]
    inside = (block >= cols[0]) & (block < cols[1])
    local = jnp.where(inside, block - cols[0], n_cols).astype(jnp.int32)
    overflow = jnp.any(jnp.sum(inside, axis=1) > capacity)
    if capacity >= block.shape[1]:
        pad = capacity - block.shape[1]
        return jnp.pad(local, ((0, 0), (0, pad)), constant_values=n_cols), overflow
    order = jnp.argsort(~inside, axis=1, stable=True)[:, :capacity]
    return jnp.take_along_axis(local, order, axis=1), overflow


def measured_capacity(union_idx, rows, cols, multiplier: float, extra: int = 0) -> int:
    """List width for ``rows`` against ``cols``: the largest neighbour count in
    ``union_idx`` (concrete) times ``multiplier``, plus ``extra``."""
    block = np.asarray(union_idx[rows[0] : rows[1]])
    inside = (block >= cols[0]) & (block < cols[1])
    most = int(inside.sum(axis=1).max(initial=0))
    return max(1, int(math.ceil(most * multiplier)) + int(extra))


def compact_rows(idx, n_cols: int, capacity: int):
    """The rows of a list ``idx`` (``[n_rows, K]``, padded with ``n_cols``) that have
    neighbours, packed into ``capacity`` rows.

    Returns ``(members, packed, position, overflow)``: ``members`` ``[capacity]`` the row
    indices (padded with ``n_rows``), ``packed`` ``[capacity, K]`` their rows of ``idx``
    (padding rows empty), ``position`` ``[n_rows + 1]`` each row's place in ``members``
    (``capacity`` for rows without neighbours and for the padding index ``n_rows``), and
    whether more than ``capacity`` rows have neighbours.
    """
    n_rows = idx.shape[0]
    has = jnp.any(idx < n_cols, axis=1)
    members = jnp.nonzero(has, size=capacity, fill_value=n_rows)[0].astype(jnp.int32)
    real = members < n_rows
    packed = jnp.where(real[:, None], idx[jnp.minimum(members, n_rows - 1)], n_cols)
    position = (
        jnp.full(n_rows + 1, capacity, jnp.int32)
        .at[members]
        .set(jnp.arange(capacity, dtype=jnp.int32), mode="drop")
    )
    position = position.at[n_rows].set(capacity)
    return members, packed.astype(jnp.int32), position, jnp.sum(has) > capacity


def measured_members(union_idx, rows, cols, multiplier: float, extra: int = 0) -> int:
    """How many rows of ``rows`` have a neighbour in ``cols`` (concrete ``union_idx``),
    times ``multiplier``, plus ``extra``: the capacity of :func:`compact_rows`."""
    block = np.asarray(union_idx[rows[0] : rows[1]])
    inside = (block >= cols[0]) & (block < cols[1])
    count = int(inside.any(axis=1).sum())
    return max(1, int(math.ceil(count * multiplier)) + int(extra))
