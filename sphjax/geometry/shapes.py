"""Shapes: regions of space that particles are sampled from.

A shape has a dimension ``dim``, axis-aligned ``bounds`` ``(lower, upper)``, an exact
``measure`` (area in 2D, volume in 3D) and ``contains(points) -> bool[N]``, the test of
whether each point of a ``[N, dim]`` array lies inside it (numpy, outside jit).

* :class:`Box` — rectangle (2D) or box (3D), ``lower < x < upper``;
* :class:`Sphere` — circle (2D) or sphere (3D), ``|x - c| < r``;
* :class:`Cylinder` — a circular cylinder in 3D of any axis direction;
* :class:`Polygon` — a simple polygon in 2D (even-odd rule);
* :class:`Mesh` — a closed triangulated surface in 3D (an STL file, through trimesh).

:func:`rectangle`, :func:`box`, :func:`circle` and :func:`sphere` build the first two with a
check of the dimension.  Bad input raises a ValueError that names the argument.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from sphjax._text import show


def _vector(name: str, value, dim: int | None = None) -> tuple[float, ...]:
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a list of numbers, got {show(value)}") from None
    if array.ndim != 1 or (dim is None and array.size not in (2, 3)):
        raise ValueError(f"{name} must be a list of 2 or 3 numbers (x, y[, z]), got {show(value)}")
    if dim is not None and array.size != dim:
        raise ValueError(f"{name} must have {dim} numbers (one per axis), got {show(value)}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite, got {show(value)}")
    return tuple(float(v) for v in array)


def _positive(name: str, value) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number, got {show(value)}") from None
    if not (number > 0 and math.isfinite(number)):
        raise ValueError(f"{name} must be a positive number, got {show(value)}")
    return number


def _points(points, dim: int) -> np.ndarray:
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] != dim:
        raise ValueError(f"points must be an [N, {dim}] array, got shape {points.shape}")
    return points


@dataclasses.dataclass(frozen=True)
class Box:
    """The rectangle (2D) or box (3D) ``lower < x < upper``; measure ``prod(upper - lower)``."""

    lower: tuple[float, ...]
    upper: tuple[float, ...]

    def __post_init__(self):
        lower = _vector("lower", self.lower)
        upper = _vector("upper", self.upper, len(lower))
        if not all(hi > lo for lo, hi in zip(lower, upper, strict=True)):
            raise ValueError(f"upper {list(upper)} must exceed lower {list(lower)} on every axis")
        object.__setattr__(self, "lower", lower)
        object.__setattr__(self, "upper", upper)

    @property
    def dim(self) -> int:
        return len(self.lower)

    @property
    def bounds(self):
        return np.array(self.lower), np.array(self.upper)

    @property
    def measure(self) -> float:
        return float(np.prod(np.subtract(self.upper, self.lower)))

    @property
    def boundary_measure(self) -> float:
        """Perimeter (2D) or surface area (3D)."""
        side = np.subtract(self.upper, self.lower)
        if self.dim == 2:
            return float(2 * side.sum())
        return float(2 * (side[0] * side[1] + side[1] * side[2] + side[0] * side[2]))

    def contains(self, points) -> np.ndarray:
        x = _points(points, self.dim)
        return np.all((x > np.array(self.lower)) & (x < np.array(self.upper)), axis=-1)


@dataclasses.dataclass(frozen=True)
class Sphere:
    """The disc (2D) or ball (3D) ``|x - centre| < radius``; measure ``pi r^2`` or
    ``4/3 pi r^3``."""

    centre: tuple[float, ...]
    radius: float

    def __post_init__(self):
        object.__setattr__(self, "centre", _vector("centre", self.centre))
        object.__setattr__(self, "radius", _positive("radius", self.radius))

    @property
    def dim(self) -> int:
        return len(self.centre)

    @property
    def bounds(self):
        c = np.array(self.centre)
        return c - self.radius, c + self.radius

    @property
    def measure(self) -> float:
        r = self.radius
        return math.pi * r**2 if self.dim == 2 else 4.0 / 3.0 * math.pi * r**3

    @property
    def boundary_measure(self) -> float:
        r = self.radius
        return 2 * math.pi * r if self.dim == 2 else 4 * math.pi * r**2

    def contains(self, points) -> np.ndarray:
        x = _points(points, self.dim)
        return np.sum((x - np.array(self.centre)) ** 2, axis=-1) < self.radius**2


@dataclasses.dataclass(frozen=True)
class Cylinder:
    """A circular cylinder in 3D: the points within ``radius`` of the segment from ``base``
    to ``base + length * axis`` (``axis`` normalised), between its two end planes;
    measure ``pi r^2 L``."""

    base: tuple[float, ...]
    axis: tuple[float, ...]
    radius: float
    length: float

    def __post_init__(self):
        base = _vector("base", self.base, 3)
        axis = np.array(_vector("axis", self.axis, 3))
        norm = float(np.linalg.norm(axis))
        if not norm > 0:
            raise ValueError(f"axis must be a non-zero direction, got {list(self.axis)}")
        object.__setattr__(self, "base", base)
        object.__setattr__(self, "axis", tuple(float(v) for v in axis / norm))
        object.__setattr__(self, "radius", _positive("radius", self.radius))
        object.__setattr__(self, "length", _positive("length", self.length))

    dim = 3

    @property
    def bounds(self):
        a, b = np.array(self.base), np.array(self.base) + self.length * np.array(self.axis)
        # the end discs reach r sqrt(1 - axis_i^2) along axis i
        reach = self.radius * np.sqrt(np.clip(1.0 - np.array(self.axis) ** 2, 0.0, 1.0))
        return np.minimum(a, b) - reach, np.maximum(a, b) + reach

    @property
    def measure(self) -> float:
        return math.pi * self.radius**2 * self.length

    @property
    def boundary_measure(self) -> float:
        return 2 * math.pi * self.radius * (self.radius + self.length)

    def contains(self, points) -> np.ndarray:
        x = _points(points, 3) - np.array(self.base)
        t = x @ np.array(self.axis)
        radial = np.sum(x**2, axis=-1) - t**2
        return (t > 0) & (t < self.length) & (radial < self.radius**2)


def _segments_cross(p, q, r, s) -> bool:
    """Whether the closed segments ``pq`` and ``rs`` share a point."""

    def orient(a, b, c):
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])

    def on(a, b, c):  # c on segment ab, given collinear
        return min(a[0], b[0]) <= c[0] <= max(a[0], b[0]) and min(a[1], b[1]) <= c[1] <= max(
            a[1], b[1]
        )

    d1, d2, d3, d4 = orient(r, s, p), orient(r, s, q), orient(p, q, r), orient(p, q, s)
    if ((d1 > 0) != (d2 > 0)) and ((d3 > 0) != (d4 > 0)) and d1 and d2 and d3 and d4:
        return True
    return (
        (d1 == 0 and on(r, s, p))
        or (d2 == 0 and on(r, s, q))
        or (d3 == 0 and on(p, q, r))
        or (d4 == 0 and on(p, q, s))
    )


@dataclasses.dataclass(frozen=True)
class Polygon:
    """A simple polygon in 2D (vertices in order, either orientation, not repeated at the
    end); inside by the even-odd rule; measure by the shoelace formula."""

    vertices: tuple[tuple[float, float], ...]

    def __post_init__(self):
        try:
            v = np.asarray(self.vertices, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(
                f"vertices must be a list of [x, y] pairs, got {self.vertices!r}"
            ) from None
        if v.ndim != 2 or v.shape[1] != 2 or len(v) < 3:
            raise ValueError(
                f"vertices must be a list of at least 3 [x, y] pairs, got {self.vertices!r}"
            )
        if not np.all(np.isfinite(v)):
            raise ValueError("vertices must be finite numbers")
        if np.allclose(v[0], v[-1]):
            v = v[:-1]  # a closing repeat of the first vertex
        n = len(v)
        for i in range(n):
            for j in range(i + 1, n):
                if j == i + 1 or (i == 0 and j == n - 1):
                    continue  # neighbouring edges share a vertex
                if _segments_cross(v[i], v[(i + 1) % n], v[j], v[(j + 1) % n]):
                    raise ValueError(
                        f"vertices do not form a simple polygon: edge {i} ({list(v[i])} -> "
                        f"{list(v[(i + 1) % n])}) crosses edge {j}; list the vertices in order "
                        "around the boundary"
                    )
        if abs(self._signed_area(v)) == 0:
            raise ValueError("vertices enclose no area")
        object.__setattr__(self, "vertices", tuple((float(x), float(y)) for x, y in v))

    dim = 2

    @staticmethod
    def _signed_area(v) -> float:
        x, y = v[:, 0], v[:, 1]
        return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))

    @property
    def bounds(self):
        v = np.array(self.vertices)
        return v.min(axis=0), v.max(axis=0)

    @property
    def measure(self) -> float:
        return abs(self._signed_area(np.array(self.vertices)))

    @property
    def boundary_measure(self) -> float:
        v = np.array(self.vertices)
        return float(np.sum(np.linalg.norm(np.roll(v, -1, axis=0) - v, axis=-1)))

    def contains(self, points) -> np.ndarray:
        """Even-odd rule: a ray in +x crosses the boundary an odd number of times."""
        x = _points(points, 2)
        v = np.array(self.vertices)
        a, b = v, np.roll(v, -1, axis=0)
        inside = np.zeros(len(x), bool)
        for (ax, ay), (bx, by) in zip(a, b, strict=True):
            # edges that straddle the ray's height (half-open in y: each vertex counted once)
            straddle = (ay > x[:, 1]) != (by > x[:, 1])
            with np.errstate(divide="ignore", invalid="ignore"):
                crossing = ax + (x[:, 1] - ay) * (bx - ax) / (by - ay)
            inside ^= straddle & (x[:, 0] < crossing)
        return inside


class Mesh:
    """A closed (watertight) triangulated surface in 3D, e.g. from an STL file.

    The surface is read and checked with trimesh (``trimesh.load``; closed, consistently
    wound); its ``measure`` is the enclosed volume (divergence theorem over the
    triangles).  ``contains`` casts a ray in ``+z`` from every point and adds the signed
    crossings of the triangles above it (a generalised winding number along lattice
    columns): inside where the sum is non-zero.  A point on a shared edge or vertex of the
    projected triangles is given to exactly one of them (the top-left rule of
    rasterisation, with each edge's line function evaluated in one canonical vertex order),
    so a closed surface is never counted twice or missed.
    """

    dim = 3

    def __init__(self, mesh, name: str = "mesh"):
        import trimesh

        if not isinstance(mesh, trimesh.Trimesh):
            raise ValueError(f"{name}: expected a trimesh.Trimesh, got {type(mesh).__name__}")
        if len(mesh.faces) == 0:
            raise ValueError(f"{name}: the surface has no triangles")
        if not mesh.is_watertight:
            open_edges = int(np.sum(np.bincount(mesh.edges_unique_inverse) == 1))
            raise ValueError(
                f"{name}: the surface is not closed ({open_edges} edges belong to one triangle "
                "only); close its holes (e.g. trimesh's fill_holes) before sampling it"
            )
        self.mesh = mesh
        self.name = name
        self._triangles = np.asarray(mesh.triangles, dtype=float)

    @classmethod
    def from_stl(cls, path) -> Mesh:
        """The closed surface in the STL file ``path`` (ASCII or binary)."""
        import trimesh

        path = Path(path)
        if not path.is_file():
            raise ValueError(f"'{path}' does not exist (give the path of an STL file)")
        try:
            mesh = trimesh.load(path, file_type="stl", force="mesh")
        except Exception as err:  # trimesh raises many kinds on a damaged file
            raise ValueError(f"'{path}' cannot be read as STL: {err}") from None
        return cls(mesh, name=f"'{path}'")

    @property
    def bounds(self):
        return self._triangles.reshape(-1, 3).min(axis=0), self._triangles.reshape(-1, 3).max(
            axis=0
        )

    @property
    def measure(self) -> float:
        return abs(float(self.mesh.volume))

    @property
    def boundary_measure(self) -> float:
        return float(self.mesh.area)

    def contains(self, points) -> np.ndarray:
        x = _points(points, 3)
        columns, column_of = np.unique(x[:, :2], axis=0, return_inverse=True)
        column_of = column_of.ravel()
        col, z, sign = _column_crossings(self._triangles, columns)
        return _winding_above(col, z, sign, column_of, x[:, 2], len(columns)) != 0


def _edge_function(u, v, p):
    """``cross(v - u, p - u)`` evaluated with the endpoints in lexicographic order, so that
    the two triangles sharing an edge get exactly opposite values."""
    swap = (u[:, 0] > v[:, 0]) | ((u[:, 0] == v[:, 0]) & (u[:, 1] > v[:, 1]))
    lo = np.where(swap[:, None], v, u)
    hi = np.where(swap[:, None], u, v)
    f = (hi[:, 0] - lo[:, 0]) * (p[:, 1] - lo[:, 1]) - (hi[:, 1] - lo[:, 1]) * (p[:, 0] - lo[:, 0])
    return np.where(swap, -f, f)


def _owns(f, u, v):
    """Top-left rule: a point with ``f > 0`` is inside the edge ``u -> v`` of a
    counter-clockwise triangle; one on its line (``f == 0``) only for a left edge
    (``dy < 0``) or a top edge (``dy == 0``, ``dx > 0``)."""
    dx, dy = v[:, 0] - u[:, 0], v[:, 1] - u[:, 1]
    return (f > 0) | ((f == 0) & ((dy < 0) | ((dy == 0) & (dx > 0))))


def _column_crossings(triangles, columns, chunk: int = 2_000_000):
    """Crossings of the vertical lines through ``columns`` (``[C, 2]``) with the triangles:
    ``(column index, z, sign)``, sign +1 for a triangle facing up (counter-clockwise seen
    from above) and -1 facing down; triangles seen edge-on have none."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    area = _edge_function(a[:, :2], b[:, :2], c[:, :2])
    keep = area != 0
    a, b, c, area = a[keep], b[keep], c[keep], area[keep]
    # counter-clockwise in projection; the sign says which way the triangle faced
    flip = area < 0
    b, c = np.where(flip[:, None], c, b), np.where(flip[:, None], b, c)
    sign = np.where(flip, -1, 1)
    # candidate columns: those inside each triangle's x range (columns sorted by x)
    order = np.argsort(columns[:, 0], kind="stable")
    xs = columns[order, 0]
    tri_lo = np.minimum(np.minimum(a, b), c)
    tri_hi = np.maximum(np.maximum(a, b), c)
    first = np.searchsorted(xs, tri_lo[:, 0], side="left")
    last = np.searchsorted(xs, tri_hi[:, 0], side="right")
    counts = last - first
    out_col, out_z, out_sign = [], [], []
    tri_index = np.repeat(np.arange(len(a)), counts)
    offsets = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    for start in range(0, len(tri_index), chunk):
        t = tri_index[start : start + chunk]
        k = order[first[t] + offsets[start : start + chunk]]
        p = columns[k]
        inside_y = (p[:, 1] >= tri_lo[t, 1]) & (p[:, 1] <= tri_hi[t, 1])
        t, k, p = t[inside_y], k[inside_y], p[inside_y]
        ta, tb, tc = a[t], b[t], c[t]
        f_ab = _edge_function(ta[:, :2], tb[:, :2], p)
        f_bc = _edge_function(tb[:, :2], tc[:, :2], p)
        f_ca = _edge_function(tc[:, :2], ta[:, :2], p)
        hit = (
            _owns(f_ab, ta[:, :2], tb[:, :2])
            & _owns(f_bc, tb[:, :2], tc[:, :2])
            & _owns(f_ca, tc[:, :2], ta[:, :2])
        )
        total = f_ab + f_bc + f_ca  # twice the projected area
        z = (f_bc * ta[:, 2] + f_ca * tb[:, 2] + f_ab * tc[:, 2]) / total
        out_col.append(k[hit])
        out_z.append(z[hit])
        out_sign.append(sign[t][hit])
    if not out_col:
        return np.zeros(0, int), np.zeros(0), np.zeros(0, int)
    return np.concatenate(out_col), np.concatenate(out_z), np.concatenate(out_sign)


def _winding_above(col, z, sign, point_col, point_z, n_columns):
    """For each point, the sum of the signs of its column's crossings above it."""
    n_cross = len(col)
    keys_col = np.concatenate([col, point_col])
    keys_z = np.concatenate([z, point_z])
    is_point = np.concatenate([np.zeros(n_cross, int), np.ones(len(point_col), int)])
    weight = np.concatenate([sign, np.zeros(len(point_col), int)])
    order = np.lexsort((is_point, keys_z, keys_col))  # crossings first at equal heights
    before = np.cumsum(weight[order]) - weight[order]  # sum over everything sorted earlier
    sorted_col = keys_col[order]
    column_start = np.searchsorted(sorted_col, sorted_col, side="left")
    below = before - before[column_start]  # crossings at or below, same column
    total = np.bincount(col, weights=sign, minlength=n_columns).astype(int)
    winding = np.empty(len(point_col), int)
    points = is_point[order] == 1
    winding[order[points] - n_cross] = total[sorted_col[points]] - below[points]
    return winding


def rectangle(lower, upper) -> Box:
    """The rectangle ``lower < x < upper`` in 2D."""
    shape = Box(lower, upper)
    if shape.dim != 2:
        raise ValueError(f"a rectangle has 2 coordinates per corner, got {list(lower)}")
    return shape


def box(lower, upper) -> Box:
    """The box ``lower < x < upper`` in 3D."""
    shape = Box(lower, upper)
    if shape.dim != 3:
        raise ValueError(f"a box has 3 coordinates per corner, got {list(lower)}")
    return shape


def circle(centre, radius) -> Sphere:
    """The disc ``|x - centre| < radius`` in 2D."""
    shape = Sphere(centre, radius)
    if shape.dim != 2:
        raise ValueError(f"a circle's centre has 2 coordinates, got {list(centre)}")
    return shape


def sphere(centre, radius) -> Sphere:
    """The ball ``|x - centre| < radius`` in 3D."""
    shape = Sphere(centre, radius)
    if shape.dim != 3:
        raise ValueError(f"a sphere's centre has 3 coordinates, got {list(centre)}")
    return shape
