"""Neighbour search and pair geometry.

Fluids (and walls) search their neighbours in the current configuration with jax-md
cell lists (``jax_md.partition.neighbor_list``, dense format ``[N, K]``) and a Verlet
skin: the list is rebuilt inside ``jit`` only when some particle has moved half the skin.
Its capacity ``K`` is fixed when allocated, outside ``jit``.  An overflow is never silent:
:func:`sphjax.simulate` re-allocates with more room and repeats the lost chunk, or, under
``jax.grad`` / ``jit``, stops with an error naming ``Model.neighbor_capacity``.

Solids use their reference-configuration neighbours, found once (eq. 15-16).

:class:`Pairs` holds the per-pair geometry of one step: neighbour index ``j``, mask,
``r_ab = r_a - r_b``, ``|r_ab|``, ``W_ab`` and ``grad_a W_ab``, each ``[N, K, ...]``.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax_md import partition
from jax_md import space as jmd_space

from sphjax import kernels
from sphjax.space import minimum_image, safe_norm
from sphjax.state import Model


@dataclasses.dataclass(frozen=True)
class Pairs:
    """Pair geometry for particles ``a`` (rows) and neighbours ``b = j[a, k]``.

    Attributes:
      j: ``[N, K]`` int neighbour indices (padding entries point at particle 0).
      mask: ``[N, K]`` True for a real neighbour inside the kernel support.
      dr: ``[N, K, d]`` ``r_a - r_b`` (minimum image).
      r: ``[N, K]`` ``|r_ab|`` (0 on padding).
      w: ``[N, K]`` ``W(r_ab, h)`` (0 on padding).
      grad_w: ``[N, K, d]`` ``grad_a W(r_ab, h)`` (0 on padding).
    """

    j: jax.Array
    mask: jax.Array
    dr: jax.Array
    r: jax.Array
    w: jax.Array
    grad_w: jax.Array

    def restrict(self, keep):
        """Pairs whose mask is also ``keep`` (``[N, K]`` bool), e.g. fluid neighbours only."""
        return dataclasses.replace(self, mask=self.mask & keep)


jax.tree_util.register_dataclass(
    Pairs, data_fields=["j", "mask", "dr", "r", "w", "grad_w"], meta_fields=[]
)


def pair_geometry(position_a, position_b, idx, displacement, model: Model) -> Pairs:
    """Pair geometry of ``a`` in ``position_a`` with neighbours ``position_b[idx]``.

    ``idx`` is ``[Na, K]``; entries ``>= len(position_b)`` are padding.
    """
    n_b = position_b.shape[0]
    valid = idx < n_b
    j = jnp.where(valid, idx, 0)
    dr = displacement(position_a[:, None, :], position_b[j])
    r = safe_norm(dr)
    h = model.smoothing_length
    mask = valid & (r < model.cutoff)
    r = jnp.where(mask, r, 0.0)
    dr = jnp.where(mask[..., None], dr, 0.0)
    w = jnp.where(mask, kernels.W(model.kernel, r, h, model.dim), 0.0)
    grad_w = kernels.grad_W(model.kernel, dr, r, h, model.dim)
    grad_w = jnp.where(mask[..., None], grad_w, 0.0)
    return Pairs(j=j, mask=mask, dr=dr, r=r, w=w, grad_w=grad_w)


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

    model: Model
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


def reference_neighbors(reference_position, members, model: Model) -> np.ndarray:
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
