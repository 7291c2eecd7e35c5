"""Particles from shapes: lattice sites inside a shape, and wall layers along its boundary.

Particles sit at the centres of the cells of one square (2D) or cubic (3D) lattice of
spacing ``dx``, ``origin + (i + 1/2) dx`` for integers ``i``; a particle's volume is its
cell's, ``dx^d``.  Every shape sampled with the same ``dx`` and ``origin`` lies on that one
lattice, so bodies that touch (a fluid in its tank, a beam and its clamp) neither overlap
nor leave a gap.  ``N dx^d`` approaches the shape's measure as ``dx -> 0``: the sites whose
cells straddle the boundary lie within ``sqrt(d) dx / 2`` of it, so
``|N dx^d - measure| <= boundary_measure * sqrt(d) dx`` (to first order in ``dx``).

* :func:`fill` — the sites inside a shape;
* :func:`wall_layers` — ``layers`` rows of sites along a shape's boundary, outside it (the
  walls of a tank: ``open_top`` leaves out its lid) or inside it (an obstacle's surface);
* :func:`layers_for` — the number of layers that covers a kernel's support.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from sphjax._text import show

SIDES = ("outside", "inside")


@dataclasses.dataclass(frozen=True)
class Particles:
    """Sampled particles: ``position`` ``[N, d]``, ``volume`` ``[N]`` (``dx^d`` each), the
    spacing ``dx``."""

    position: np.ndarray
    volume: np.ndarray
    dx: float

    def __len__(self) -> int:
        return len(self.position)

    @property
    def dim(self) -> int:
        return self.position.shape[1]

    @property
    def total_volume(self) -> float:
        return float(self.volume.sum())


def _check_spacing(dx) -> float:
    try:
        value = float(dx)
    except (TypeError, ValueError):
        raise ValueError(f"dx must be a positive number, got {show(dx)}") from None
    if not (value > 0 and math.isfinite(value)):
        raise ValueError(f"dx must be a positive number, got {show(dx)}")
    return value


def _origin(origin, dim: int) -> np.ndarray:
    if origin is None:
        return np.zeros(dim)
    o = np.asarray(origin, dtype=float)
    if o.shape != (dim,) or not np.all(np.isfinite(o)):
        raise ValueError(f"origin must be {dim} finite numbers, got {show(origin)}")
    return o


MAX_SITES = 50_000_000


def _grid(lower, upper, dx, origin):
    """The lattice sites of the cells that overlap ``[lower, upper]``: ``(points, shape)``
    with the points in C order over ``shape`` (one count per axis)."""
    tol = 1e-9
    first = np.floor((lower - origin) / dx + tol).astype(int)
    last = np.ceil((upper - origin) / dx - tol).astype(int)
    counts = np.maximum(last - first, 1)
    if np.prod(counts.astype(float)) > MAX_SITES:
        raise ValueError(
            f"dx={dx:g} would put {np.prod(counts.astype(float)):.3g} lattice sites around the "
            "shape; use a larger dx"
        )
    starts = origin + first * dx
    axes = [s + (np.arange(n) + 0.5) * dx for s, n in zip(starts, counts, strict=True)]
    grid = np.meshgrid(*axes, indexing="ij")
    return np.stack([g.ravel() for g in grid], axis=-1), tuple(int(n) for n in counts)


def _particles(points, dx) -> Particles:
    dim = points.shape[1]
    return Particles(points, np.full(len(points), dx**dim), dx)


def fill(shape, dx, origin=None) -> Particles:
    """The lattice sites inside ``shape`` (see the module docstring).

    Args:
      shape: a shape of :mod:`sphjax.geometry.shapes`.
      dx: lattice spacing.
      origin: a corner of the lattice's cells (default the coordinate origin).
    """
    dx = _check_spacing(dx)
    origin = _origin(origin, shape.dim)
    lower, upper = shape.bounds
    points, _ = _grid(np.asarray(lower, float), np.asarray(upper, float), dx, origin)
    return _particles(points[shape.contains(points)], dx)


def layers_for(cutoff: float, dx: float) -> int:
    """Layers of wall particles that cover a kernel support ``cutoff``: ``ceil(cutoff/dx)``."""
    return int(math.ceil(cutoff / dx - 1e-9))


def wall_layers(shape, dx, layers: int, side: str = "outside", open_top=False, origin=None):
    """``layers`` rows of lattice sites along the boundary of ``shape``.

    ``side="outside"``: the sites outside the shape within ``layers`` lattice steps of a
    site inside it (steps along the axes and diagonals), i.e. the walls of a container
    whose inside is ``shape``; a box gets full corners.  ``side="inside"``: the sites
    inside the shape within ``layers`` steps of one outside it (the surface of an
    obstacle).  ``open_top=True`` (outside only) leaves out the sites above the shape's top
    along the last axis, an open tank.

    Returns :class:`Particles` on the lattice of :func:`fill` with the same ``dx`` and
    ``origin``.
    """
    dx = _check_spacing(dx)
    if isinstance(layers, bool) or not isinstance(layers, int | np.integer) or layers < 1:
        raise ValueError(f"layers must be a whole number >= 1, got {layers!r}")
    if side not in SIDES:
        raise ValueError(f"side must be 'outside' or 'inside', got {side!r}")
    if open_top and side != "outside":
        raise ValueError("open_top applies to walls outside a shape (side='outside')")
    origin = _origin(origin, shape.dim)
    lower, upper = (np.asarray(b, float) for b in shape.bounds)
    pad = (layers if side == "outside" else 1) * dx
    points, counts = _grid(lower - pad, upper + pad, dx, origin)
    inside = shape.contains(points).reshape(counts)
    from scipy import ndimage  # here: 0.05 s that every sphjax command would pay at import

    structure = np.ones((3,) * shape.dim, bool)
    if side == "outside":
        near = ndimage.binary_dilation(inside, structure, iterations=int(layers))
        wall = near & ~inside
    else:
        near = ndimage.binary_dilation(~inside, structure, iterations=int(layers))
        wall = near & inside
    wall = wall.ravel()
    if open_top:
        wall &= points[:, -1] < upper[-1]
    return _particles(points[wall], dx)
