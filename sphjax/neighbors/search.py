"""The neighbour search: geometry only.

A search is described by a :class:`SearchGeometry`: the kernel support radius, the Verlet
skin, the domain (its box and periodic axes) and the capacity multiplier, nothing of the
physics.  Particles that interact in the current configuration search their neighbours
with jax-md cell lists (``jax_md.partition.neighbor_list``, dense format ``[N, K]``,
:class:`NeighborSearch`) and a Verlet skin: the list is rebuilt inside ``jit`` only when
some particle has moved half the skin.  With ``SearchGeometry.native`` (a model with
``pair_loop="native"``) a rebuild runs as the compiled cell list of :mod:`sphjax.native`
instead, which writes jax-md's list entry for entry and sets the same error bits.  The
helpers here cut such a list into the neighbours of one block of particles among another
(:func:`split_list`), pack its rows that have neighbours (:func:`compact_rows`), keep only
the neighbours inside the support (:func:`support_list`), and measure the counts an
allocation is sized from (:func:`measured_capacity`, :func:`measured_members`,
:func:`measured_support`; the sizing rule is :func:`sphjax.neighbors.capacity.sized`).

Solids use their reference-configuration neighbours, found once
(:func:`reference_neighbors`; eqs. 15-16), by a vectorised numpy cell list
(:func:`points_within`).
"""

from __future__ import annotations

import collections
import dataclasses
import functools
import hashlib

import jax
import jax.numpy as jnp
import numpy as np

from sphjax._jax_md import modules as _jax_md_modules
from sphjax.core.space import displacement_fn
from sphjax.neighbors.capacity import pair_sized, sized

partition, jmd_space = _jax_md_modules("partition", "space")

_CELL_LIST_FNS: dict = {}


@dataclasses.dataclass(frozen=True)
class SearchGeometry:
    """What a neighbour search needs (hashable): the kernel support radius ``cutoff``,
    the Verlet skin as a fraction of it (``skin_fraction``), the ``domain``
    (:class:`sphjax.core.model.Domain`), the multiplier on the measured neighbour
    count that sizes a list (``capacity_multiplier``) and whether a rebuild runs as the
    compiled cell list of :mod:`sphjax.native` (``native``) rather than jax-md's in XLA."""

    cutoff: float
    skin_fraction: float
    domain: object
    capacity_multiplier: float
    native: bool = False

    @classmethod
    def of(cls, model) -> SearchGeometry:
        """The geometry of a Model: ``cutoff``, ``neighbor_skin``, ``domain``,
        ``neighbor_capacity``; ``native`` with ``pair_loop="native"``."""
        return cls(
            model.cutoff,
            model.neighbor_skin,
            model.domain,
            model.neighbor_capacity,
            model.pair_loop == "native",
        )

    @property
    def skin(self) -> float:
        """The Verlet skin, a length."""
        return self.skin_fraction * self.cutoff


_SEARCHES: dict = {}


def neighbor_search(geometry: SearchGeometry) -> NeighborSearch:
    """The jax-md search of ``geometry`` (one per geometry and float precision)."""
    key = (geometry, bool(jax.config.jax_enable_x64))
    if key not in _SEARCHES:
        _SEARCHES[key] = NeighborSearch(geometry, x64=key[1])
    return _SEARCHES[key]


@dataclasses.dataclass(frozen=True)
class NeighborSearch:
    """jax-md cell-list neighbour search of a :class:`SearchGeometry` (built once, outside
    ``jit``).

    Positions are shifted into the box jax-md expects (``[0, L)`` per axis).  Non-periodic
    axes get a padded box (``size + 2 (cutoff + skin)``) so that no image across them is
    ever within the cutoff.

    ``x64`` is the ``jax_enable_x64`` setting the jax-md functions are built under: they
    hold constants of that precision, so a session that switches it needs another search.
    """

    geometry: SearchGeometry
    x64: bool = False

    @property
    def skin(self) -> float:
        return self.geometry.skin

    @property
    def _padding(self) -> float:
        return 2.0 * (self.geometry.cutoff + self.skin)

    @property
    def box(self) -> np.ndarray:
        domain = self.geometry.domain
        return np.array(
            [
                size if periodic else size + 2.0 * self._padding
                for size, periodic in zip(domain.size, domain.periodic, strict=True)
            ]
        )

    def to_box(self, position):
        """``position`` in jax-md's box (numpy for a numpy array, else jax.numpy)."""
        domain = self.geometry.domain
        offset = np.array(
            [
                -lo if periodic else -lo + self._padding
                for lo, periodic in zip(domain.lower, domain.periodic, strict=True)
            ]
        )
        shifted = position + offset.astype(position.dtype)
        box = self.box.astype(position.dtype)
        return (np.mod if isinstance(position, np.ndarray) else jnp.mod)(shifted, box)

    @functools.cache  # noqa: B019 (one NeighborSearch per geometry: neighbor_search)
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
                r_cutoff=self.geometry.cutoff + (self.skin if dr_threshold == 0 else 0.0),
                dr_threshold=dr_threshold,
                capacity_multiplier=self.geometry.capacity_multiplier,
                format=partition.Dense,
            )

    def allocate(
        self,
        position,
        extra_capacity: int = 0,
        margin: float | None = None,
        at_least: int = 0,
    ):
        """A new neighbour list for concrete ``position`` (outside ``jit``).

        ``margin``: ``None`` sizes the list ``capacity_multiplier`` times the largest
        neighbour count now, plus ``extra_capacity``; a number sizes it the largest count
        times ``1 + margin``, plus ``extra_capacity`` (for a driver that re-allocates on
        overflow: fewer padded slots, each of which costs as much as a neighbour).
        ``at_least``: the fewest slots per particle (a size measured elsewhere, e.g. where
        an earlier list overflowed).
        """
        x = self.to_box(np.asarray(position))
        neighbors = self._allocate(x, extra_capacity)
        if capacity(neighbors) < at_least:
            more = extra_capacity + at_least - capacity(neighbors)
            neighbors = self._allocate(x, more)
        if margin is not None:
            idx = np.asarray(neighbors.idx)
            most = int(np.max(np.sum(idx < idx.shape[0], axis=1), initial=0))
            width = max(sized(most, 1.0 + margin, extra_capacity), at_least)
            if width < capacity(neighbors):
                # jax-md packs each row's neighbours first: the columns cut hold padding
                neighbors = neighbors.set(idx=jax.device_put(idx[:, :width]), max_occupancy=width)
        return neighbors

    def _allocate(self, x, extra_capacity: int):
        """jax-md's dense allocation for the concrete boxed positions ``x`` (numpy), the
        same list, in one compiled program instead of jax-md's eager set-up (some 40
        small programs compiled on first use, most of a small run's start-up): the cell
        capacity is counted here as jax-md counts it (the fullest cell times
        ``capacity_multiplier``, plus ``extra_capacity``), the list is built by the
        jitted rebuild at the full width of the candidates (which cannot overflow), and
        cut to jax-md's width, its largest row times the multiplier plus the extra."""
        fns = self._functions(self.skin)
        n, dim = x.shape
        cutoff = self.geometry.cutoff + self.skin
        box = self.box.astype(np.float32)  # jax-md's cell list takes the box in float32
        cells = np.floor(box / cutoff)
        if not np.all(cutoff < box / 3.0):  # jax-md searches without a cell list
            neighbors = fns.allocate(jnp.asarray(x), extra_capacity=extra_capacity)
            return neighbors.set(
                cell_list_fn=_CELL_LIST_FNS.setdefault(self, neighbors.cell_list_fn)
            )
        cell_size = box / cells
        index = np.mod((x / cell_size).astype(np.int32), cells.astype(np.int32))
        strides = np.cumprod(np.concatenate([[1], cells[:-1]])).astype(np.int64)
        fullest = np.bincount(index @ strides, minlength=int(np.prod(cells))).max()
        cell_capacity = int(fullest * self.geometry.capacity_multiplier) + int(extra_capacity)
        # The update and cell-list functions are static (pytree metadata) in the list: new
        # function objects at every allocation would make every jitted step recompile;
        # ``_functions`` is cached, and so is the cell-list function (same box, cell size
        # and multiplier).
        cell_list_fn = _CELL_LIST_FNS.setdefault(
            self, partition.cell_list(box, cutoff, self.geometry.capacity_multiplier)
        )
        width = 3**dim * cell_capacity
        # numpy leaves: the compiled program then runs on them even inside a trace (an
        # allocation inside jax.grad or jit)
        template = partition.NeighborList(
            np.zeros((n, width), np.int32),
            x,
            partition.PartitionError(np.zeros((), np.uint8)),
            cell_capacity,
            width,
            partition.Dense,
            cutoff,
            cell_list_fn,
            fns.update,
        )
        full = _build(self, x.shape, x.dtype.str, cell_capacity)(x, template)
        idx = np.asarray(full.idx)
        most = int(np.max(np.sum(idx < n, axis=1), initial=0))
        occupancy = int(most * self.geometry.capacity_multiplier + extra_capacity)
        occupancy = min(occupancy, width, n - 1)
        return full.set(
            idx=jax.device_put(np.ascontiguousarray(idx[:, :occupancy])),
            max_occupancy=occupancy,
            reference_position=jax.device_put(x),
        )

    def update(self, position, neighbors):
        """Update inside ``jit``: rebuilt only if a particle moved more than half the skin."""
        x = self.to_box(position)
        if not self.geometry.native:
            return neighbors.update(x)
        # jax-md's test: the squared periodic distance of some particle from its position
        # at the last rebuild above (skin / 2)^2, the threshold in float32 as jax-md has it
        displacement, _ = jmd_space.periodic(self.box)
        moved = jax.vmap(lambda a, b: jmd_space.square_distance(displacement(a, b)))(
            x, neighbors.reference_position
        )
        threshold = (np.float32(self.skin) / np.float32(2)) ** 2
        return jax.lax.cond(
            jnp.any(moved > threshold),
            lambda: self._native_rebuild(x, neighbors),
            lambda: neighbors,
        )

    def rebuild(self, position, neighbors):
        """Force a rebuild at ``position`` with the capacity of ``neighbors`` (jittable)."""
        if self.geometry.native:
            return self._native_rebuild(self.to_box(position), neighbors)
        fns = self._functions(0.0)
        return fns.update(self.to_box(position), neighbors)

    @functools.cached_property
    def _grid(self) -> dict:
        """The compiled cell list's grid and radius (:func:`sphjax.native.cell_list_rebuild`):
        jax-md's grid (cells of the float32 box over the search radius, in float32), an
        axis of fewer than 3 cells searched as one; the squared radius in the default
        float precision, as jax-md squares it."""
        radius = self.geometry.cutoff + self.skin
        box = self.box.astype(np.float32)
        with np.errstate(divide="ignore", invalid="ignore"):
            cells = np.floor(box / np.float32(radius))
            size = box / cells
        used = cells >= 3
        r = np.asarray(radius, np.float64 if self.x64 else np.float32)
        return dict(
            box=self.box,
            cell_size=np.where(used, size, box).astype(np.float64),
            cells=np.where(used, cells, 1).astype(np.int64),
            radius2=float(r * r),
        )

    def _native_rebuild(self, x, neighbors):
        """jax-md's rebuild of ``neighbors`` at the boxed positions ``x``, by the compiled
        cell list: the same neighbours per row, the same error bits (a row wider than the
        list; a cell fuller than jax-md's cell list holds, where it has one)."""
        from sphjax import native

        idx, sizes = native.cell_list_rebuild(
            x, neighbors.idx.shape[-1], capacity=neighbors.cell_list_capacity, **self._grid
        )
        codes = partition.PartitionErrorCode
        error = neighbors.error.update(
            codes.NEIGHBOR_LIST_OVERFLOW, sizes[0] > neighbors.max_occupancy
        )
        if neighbors.cell_list_capacity is not None:
            error = error.update(codes.CELL_LIST_OVERFLOW, sizes[1] > neighbors.cell_list_capacity)
        return neighbors.set(idx=idx, reference_position=x, error=error)


@functools.lru_cache(maxsize=32)
def _build(search: NeighborSearch, shape: tuple, dtype: str, cell_capacity: int):
    """The compiled forced rebuild of ``search`` (``Compiled(x, template) -> list``) for
    positions of ``shape`` and ``dtype`` at the full candidate width of ``cell_capacity``;
    kept for later allocations of the same shape (the chunked driver's, a calibration's)."""
    rebuild = search._functions(0.0).update  # a zero threshold always rebuilds
    width = 3 ** shape[1] * cell_capacity
    template = partition.NeighborList(
        jax.ShapeDtypeStruct((shape[0], width), np.int32),
        jax.ShapeDtypeStruct(shape, np.dtype(dtype)),
        partition.PartitionError(jax.ShapeDtypeStruct((), np.uint8)),
        cell_capacity,
        width,
        partition.Dense,
        search.geometry.cutoff + search.skin,
        _CELL_LIST_FNS[search],
        search._functions(search.skin).update,
    )
    position = jax.ShapeDtypeStruct(shape, np.dtype(dtype))
    return jax.jit(rebuild).lower(position, template).compile()


def capacity(neighbors) -> int:
    """Neighbour slots per particle of a jax-md dense neighbour list."""
    return int(neighbors.idx.shape[-1])


#: reference neighbour lists already built, by content (a loop over ``simulate`` calls,
#: calibration or data generation, searches its solid's reference configuration once)
_REFERENCE_LISTS: collections.OrderedDict = collections.OrderedDict()
_REFERENCE_LISTS_KEPT = 8


def reference_neighbors(reference_position, members, geometry: SearchGeometry) -> np.ndarray:
    """Reference-configuration neighbour indices among ``members`` (numpy; built once per
    reference configuration and kept for later calls with the same positions, support
    radius and domain).

    A vectorised cell list: the members are sorted by cell, and every member's candidates
    are the members of its own and the adjacent cells, filtered by distance (minimum
    image on periodic axes).  Each row lists its neighbours in increasing index order.

    Args:
      reference_position: ``[N, d]`` reference positions ``X``.
      members: ``[M]`` indices of the particles taking part (e.g. solid and clamped).
    Returns:
      ``[M, K]`` int32 global neighbour indices within the kernel support (self
      excluded), padded with ``N``.
    """
    X = np.asarray(reference_position, dtype=np.float64)
    members = np.asarray(members, dtype=np.int64)
    digest = hashlib.sha1(X.tobytes())
    digest.update(members.tobytes())
    key = (geometry.cutoff, geometry.domain, X.shape, digest.hexdigest())
    if key in _REFERENCE_LISTS:
        _REFERENCE_LISTS.move_to_end(key)
        return _REFERENCE_LISTS[key]
    idx = _reference_search(X, members, geometry)
    idx.setflags(write=False)
    _REFERENCE_LISTS[key] = idx
    if len(_REFERENCE_LISTS) > _REFERENCE_LISTS_KEPT:
        _REFERENCE_LISTS.popitem(last=False)
    return idx


def _reference_search(X, members, geometry: SearchGeometry) -> np.ndarray:
    """:func:`reference_neighbors` without the cache: a vectorised cell list."""
    n = X.shape[0]
    if members.shape[0] == 0:
        return np.full((0, 1), n, dtype=np.int32)
    domain = geometry.domain
    local = points_within(X[members], geometry.cutoff, domain.lower, domain.size, domain.periodic)
    padded = np.append(members, n).astype(np.int32)  # the padding (m) becomes n
    return padded[local]


def points_within(x, radius: float, lower, size, periodic, closed: bool = False) -> np.ndarray:
    """``[M, K]`` indices of the points of ``x`` (``[M, d]``, numpy) closer than
    ``radius`` to each (``closed``: or at ``radius``; minimum image on the ``periodic``
    axes of the box ``lower``, ``size``), the point itself left out; each row in
    increasing index order, padded with ``M``.

    A vectorised cell list: the points are sorted by cell, and every point's candidates
    are the points of its own and the adjacent cells, filtered by distance; up to
    ``DENSE_SEARCH_PAIRS`` pairs, all pairs are filtered (faster at that size).
    """
    Xm = np.asarray(x, dtype=np.float64)
    m, dim = Xm.shape
    if m == 0:
        return np.full((0, 1), 0, dtype=np.int32)
    cutoff = float(radius)
    size = np.array(size, dtype=np.float64)
    periodic = np.array(periodic, dtype=bool)
    if m * m <= DENSE_SEARCH_PAIRS:
        r2 = _squared_distances(Xm[:, None, :], Xm[None, :, :], size, periodic)
        close = (r2 <= cutoff**2) if closed else (r2 < cutoff**2)
        np.fill_diagonal(close, False)
        return _padded_rows(*np.nonzero(close), m)
    lower = np.where(periodic, np.array(lower, dtype=np.float64), Xm.min(0))
    extent = np.where(periodic, size, Xm.max(0) - lower)
    # cells at least ``cutoff`` wide; a periodic axis with fewer than 3 cells is one cell
    n_cells = np.maximum(1, np.floor(extent / cutoff).astype(np.int64))
    n_cells = np.where(periodic & (n_cells < 3), 1, n_cells)
    width = np.where(periodic, extent / n_cells, cutoff)
    cell = np.floor((Xm - lower) / width).astype(np.int64)
    cell = np.where(periodic, np.mod(cell, n_cells), np.clip(cell, 0, None))
    n_cells = np.maximum(n_cells, cell.max(0) + 1)
    strides = np.cumprod(np.concatenate([[1], n_cells[:-1]]))
    key = cell @ strides
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    axes = [[0] if (periodic[i] and n_cells[i] == 1) else [-1, 0, 1] for i in range(dim)]
    offsets = np.array(np.meshgrid(*axes, indexing="ij")).reshape(dim, -1).T
    rows, cols = [], []
    chunk = max(1, 2_000_000 // max(1, len(offsets)))
    for lo in range(0, m, chunk):
        k = np.arange(lo, min(m, lo + chunk))
        for off in offsets:
            c = cell[k] + off
            inside = np.all(periodic | ((c >= 0) & (c < n_cells)), axis=1)
            c = np.where(periodic, np.mod(c, n_cells), c)
            ck = c @ strides
            first = np.searchsorted(sorted_key, ck, side="left")
            count = np.where(inside, np.searchsorted(sorted_key, ck, side="right") - first, 0)
            total = int(count.sum())
            if total == 0:
                continue
            row = np.repeat(k, count)
            start = np.repeat(first - np.cumsum(count) + count, count)
            col = order[start + np.arange(total)]
            rows.append(row)
            cols.append(col)
    row = np.concatenate(rows)
    col = np.concatenate(cols)
    r2 = _squared_distances(Xm[row], Xm[col], size, periodic)
    close = ((r2 <= cutoff**2) if closed else (r2 < cutoff**2)) & (row != col)
    row, col = row[close], col[close]
    pair_order = np.argsort(row * m + col)
    return _padded_rows(row[pair_order], col[pair_order], m)


#: the most pairs :func:`points_within` filters all at once rather than by cells
DENSE_SEARCH_PAIRS = 1_000_000


def _squared_distances(a, b, size, periodic) -> np.ndarray:
    """``|a - b|^2`` (numpy, broadcast over the leading axes), minimum image on the
    ``periodic`` axes; summed axis by axis as ``np.sum`` would."""
    r2 = 0.0
    for k in range(a.shape[-1]):
        d = a[..., k] - b[..., k]
        if periodic[k]:
            d = d - size[k] * np.round(d / size[k])
        r2 = r2 + d * d
    return r2


def _padded_rows(row, col, m: int) -> np.ndarray:
    """``[m, K]`` rows of the pairs ``(row, col)`` (sorted by row, then col), padded
    with ``m``."""
    counts = np.bincount(row, minlength=m)
    width = max(1, int(counts.max(initial=0)))
    slot = np.arange(row.shape[0]) - np.repeat(np.cumsum(counts) - counts, counts)
    idx = np.full((m, width), m, dtype=np.int32)
    idx[row, slot] = col
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


def measured_capacity(
    union_idx, rows, cols, multiplier: float, extra: int = 0, grows: bool = False
) -> int:
    """List width for ``rows`` against ``cols``: the largest neighbour count in
    ``union_idx`` (concrete) times ``multiplier``, plus ``extra``; ``grows``: see
    :func:`sphjax.neighbors.capacity.pair_sized`."""
    block = np.asarray(union_idx[rows[0] : rows[1]])
    inside = (block >= cols[0]) & (block < cols[1])
    return pair_sized(int(inside.sum(axis=1).max(initial=0)), multiplier, extra, grows)


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


def measured_members(
    union_idx, rows, cols, multiplier: float, extra: int = 0, grows: bool = False
) -> int:
    """How many rows of ``rows`` have a neighbour in ``cols`` (concrete ``union_idx``),
    times ``multiplier``, plus ``extra``: the capacity of :func:`compact_rows`;
    ``grows``: see :func:`sphjax.neighbors.capacity.pair_sized`."""
    block = np.asarray(union_idx[rows[0] : rows[1]])
    inside = (block >= cols[0]) & (block < cols[1])
    return pair_sized(int(inside.any(axis=1).sum()), multiplier, extra, grows)


def support_list(idx, x_rows, x_cols, domain, cutoff: float, width: int):
    """The neighbours of a Verlet list ``idx`` that are inside the kernel support now.

    A list with a skin holds, besides the neighbours within ``cutoff``, those that may
    come within it before the next rebuild (in 2D about 60 % more slots with a skin of a
    quarter of the support radius); every pair term costs as much in those slots as in a
    real neighbour's.  This keeps, per row and in the same order, only the columns with
    ``|r_ab|^2 < cutoff^2`` (minimum image), packed into ``width`` slots: the second level
    of a two-level list.  With ``cutoff`` the kernel support radius, the dropped pairs have
    ``W = 0`` and ``grad W = 0``, so sums over the result equal sums over ``idx``; with a
    slightly larger one the result stays valid until a particle has moved half the
    difference.

    Args:
      idx: ``[n_rows, K]`` column indices, padded with ``n_cols``.
      x_rows, x_cols: ``[n_rows, d]``, ``[n_cols, d]`` positions.
      width: slots per row of the result (static).
    Returns:
      ``(support, overflow)``: ``[n_rows, width]`` int32 column indices padded with
      ``n_cols``, and whether some row has more than ``width`` neighbours in the support.
    """
    n_rows, n_cols = idx.shape[0], x_cols.shape[0]
    real = idx < n_cols
    dr = displacement_fn(domain)(x_rows[:, None, :], x_cols[jnp.where(real, idx, 0)])
    r2 = sum(dr[..., i] * dr[..., i] for i in range(dr.shape[-1]))
    inside = real & (r2 < cutoff**2)
    slot = jnp.cumsum(inside, axis=1, dtype=jnp.int32) - 1
    overflow = jnp.any(slot[:, -1] >= width) if idx.shape[1] else jnp.asarray(False)
    slot = jnp.where(inside, slot, width)  # out of range: dropped by the scatter
    rows = jnp.broadcast_to(jnp.arange(n_rows, dtype=jnp.int32)[:, None], idx.shape)
    support = (
        jnp.full((n_rows, width), n_cols, jnp.int32)
        .at[rows, slot]
        .set(idx.astype(jnp.int32), mode="drop")
    )
    return support, overflow


def measured_support(idx, x_rows, x_cols, domain, cutoff: float, multiplier: float, extra=0):
    """Width of :func:`support_list` for concrete arrays: the largest count of neighbours
    in the support now times ``multiplier``, plus ``extra``."""
    n_cols = x_cols.shape[0]
    real = np.asarray(idx) < n_cols
    dr = displacement_fn(domain)(
        jnp.asarray(x_rows)[:, None, :], jnp.asarray(x_cols)[jnp.where(real, idx, 0)]
    )
    inside = real & (np.asarray(jnp.sum(dr * dr, axis=-1)) < cutoff**2)
    return sized(int(inside.sum(axis=1).max(initial=0)), multiplier, extra)
