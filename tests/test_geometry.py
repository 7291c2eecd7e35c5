"""Geometry primitives: particle counts and volumes against the exact shapes.

Every site of the lattice whose cell straddles a shape's boundary lies within
``sqrt(d) dx / 2`` of it, so ``|N dx^d - measure| <= boundary_measure * sqrt(d) * dx`` (the
volume of that band, to first order in dx): the tolerance used below, at two resolutions.
Numpy only; about 3 s in all.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from sphjax import geometry
from sphjax.cases._geometry import box_walls, lattice

SHAPES = {
    "rectangle": (geometry.rectangle([0.1, -0.2], [0.43, 0.5]), 0.01),
    "box": (geometry.box([0.0, 0.0, 0.0], [0.3, 0.5, 0.7]), 0.05),
    "circle": (geometry.circle([0.3, 0.2], 0.1), 0.005),
    "sphere": (geometry.sphere([0.0, 0.1, 0.0], 0.5), 0.04),
    "cylinder_z": (geometry.Cylinder([0.0, 0.0, 0.0], [0, 0, 1], 0.3, 1.0), 0.04),
    "cylinder_tilted": (geometry.Cylinder([0.1, 0.0, 0.2], [1, 2, 0.5], 0.2, 0.8), 0.03),
    # an L-shaped hexagon and a non-convex "arrow" (a vertex pointing inwards)
    "polygon_L": (geometry.Polygon([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]]), 0.02),
    "polygon_arrow": (geometry.Polygon([[0, 0], [2, 0.7], [0, 1.4], [0.6, 0.7]]), 0.01),
}


@pytest.mark.parametrize("name", sorted(SHAPES))
@pytest.mark.parametrize("refine", [1, 2])
def test_volume_matches_the_exact_shape(name, refine):
    shape, dx = SHAPES[name]
    dx = dx / refine
    particles = geometry.fill(shape, dx)
    assert np.all(particles.volume == dx**shape.dim)
    assert np.all(shape.contains(particles.position))
    tolerance = shape.boundary_measure * math.sqrt(shape.dim) * dx
    assert abs(len(particles) * dx**shape.dim - shape.measure) <= tolerance
    # the exact measures these shapes have (so measure itself is tested)
    exact = {
        "rectangle": 0.33 * 0.7,
        "box": 0.3 * 0.5 * 0.7,
        "circle": math.pi * 0.01,
        "sphere": 4 / 3 * math.pi * 0.125,
        "cylinder_z": math.pi * 0.09,
        "cylinder_tilted": math.pi * 0.04 * 0.8,
        "polygon_L": 3.0,
        "polygon_arrow": 0.5 * 2 * 1.4 - 0.5 * 0.6 * 1.4,
    }[name]
    assert shape.measure == pytest.approx(exact, rel=1e-12)


def test_aligned_boxes_are_filled_exactly():
    # sides that are whole numbers of dx: N dx^d is the volume to round-off
    dam = geometry.fill(geometry.rectangle([0.0, 0.0], [0.3, 0.6]), 0.015)
    assert len(dam) == 20 * 40
    cube = geometry.fill(geometry.box([-0.5, 0.0, 1.0], [0.5, 0.4, 1.2]), 0.05)
    assert len(cube) == 20 * 8 * 4
    assert cube.total_volume == pytest.approx(1.0 * 0.4 * 0.2, rel=1e-12)
    # the same sites as the lattice the built-in cases use
    assert np.array_equal(dam.position, lattice([0.0, 0.0], [0.3, 0.6], 0.015))


def test_shapes_on_one_lattice_do_not_overlap():
    dx = 0.02
    left = geometry.fill(geometry.rectangle([0.0, 0.0], [0.5, 0.5]), dx)
    right = geometry.fill(geometry.rectangle([0.5, 0.0], [1.0, 0.5]), dx)
    both = geometry.fill(geometry.rectangle([0.0, 0.0], [1.0, 0.5]), dx)
    union = np.concatenate([left.position, right.position])
    assert len(union) == len(both)
    assert np.allclose(np.sort(union, axis=0), np.sort(both.position, axis=0))
    # sites are origin + (i + 1/2) dx: shifting the origin by half a cell puts them on the
    # grid lines of the unshifted lattice, and one column fewer fits in the rectangle
    shifted = geometry.fill(geometry.rectangle([0.0, 0.0], [1.0, 0.5]), dx, origin=[0.01, 0.0])
    index = shifted.position[:, 0] / dx
    assert np.allclose(index, np.round(index), atol=1e-9)
    assert len(shifted) == len(both) - 25


# ---------------------------------------------------------------------------- STL meshes


def _stl(tmp_path, mesh, name):
    path = tmp_path / f"{name}.stl"
    mesh.export(path)
    return geometry.Mesh.from_stl(path)


def _inside_convex(mesh, points):
    """Exact inside test of a convex closed mesh: behind every face plane."""
    normals = mesh.face_normals
    offsets = np.sum(normals * mesh.triangles[:, 0], axis=1)
    inside = [np.all(chunk @ normals.T < offsets, axis=1) for chunk in np.array_split(points, 64)]
    return np.concatenate(inside)


def _sites(points, dx, origin):
    """Lattice indices of sites, sorted (comparable whatever their rounding)."""
    keys = np.round((points - np.asarray(origin)) / dx - 0.5).astype(int)
    return keys[np.lexsort(keys.T[::-1])]


@pytest.mark.parametrize(
    "name, mesh, dx",
    [
        ("icosphere", trimesh.creation.icosphere(subdivisions=2, radius=0.5), 0.03),
        ("box", trimesh.creation.box(extents=[0.4, 0.6, 0.2]), 0.02),
        ("capsule", trimesh.creation.capsule(height=0.6, radius=0.2, count=[12, 12]), 0.03),
    ],
)
def test_stl_sampling_is_exact_for_convex_meshes(tmp_path, name, mesh, dx):
    shape = _stl(tmp_path, mesh, name)
    assert shape.measure == pytest.approx(mesh.volume, rel=1e-6)  # STL is float32
    lower, upper = shape.bounds
    # the lattice around the mesh, both at cell centres (the box's face diagonals pass
    # through lattice columns: the shared-edge rule is exercised) and shifted
    for origin in ([0.0, 0.0, 0.0], [0.007, -0.003, 0.011]):
        particles = geometry.fill(shape, dx, origin)
        grid = geometry.fill(geometry.Box(lower - dx, upper + dx), dx, origin).position
        exact = _inside_convex(shape.mesh, grid)
        assert len(particles) == int(exact.sum())
        assert np.array_equal(
            _sites(particles.position, dx, origin), _sites(grid[exact], dx, origin)
        )
        tolerance = shape.boundary_measure * math.sqrt(3) * dx
        assert abs(len(particles) * dx**3 - shape.measure) <= tolerance


def test_stl_sampling_of_a_non_convex_ring(tmp_path):
    ring = trimesh.creation.annulus(r_min=0.2, r_max=0.5, height=0.3, sections=24)
    shape = _stl(tmp_path, ring, "ring")
    dx, origin = 0.02, [0.0, 0.0, 0.005]  # no site on the end faces z = +-0.15
    particles = geometry.fill(shape, dx, origin)
    # the ring is the outer 24-gon prism minus the inner one
    outer = trimesh.creation.cylinder(radius=0.5, height=0.3, sections=24)
    inner = trimesh.creation.cylinder(radius=0.2, height=0.3, sections=24)
    lower, upper = shape.bounds
    grid = geometry.fill(geometry.Box(lower - dx, upper + dx), dx, origin).position
    exact = _inside_convex(outer, grid) & ~_inside_convex(inner, grid)
    assert len(particles) == int(exact.sum())
    tolerance = shape.boundary_measure * math.sqrt(3) * dx
    assert abs(len(particles) * dx**3 - ring.volume) <= tolerance


def test_open_stl_surface_is_refused(tmp_path):
    mesh = trimesh.creation.box(extents=[1, 1, 1])
    mesh.update_faces(np.arange(len(mesh.faces)) != 0)  # remove one triangle
    path = tmp_path / "open.stl"
    mesh.export(path)
    with pytest.raises(ValueError, match=r"open.stl'.*not closed \(3 edges.*fill_holes"):
        geometry.Mesh.from_stl(path)
    with pytest.raises(ValueError, match="does not exist"):
        geometry.Mesh.from_stl(tmp_path / "missing.stl")
    (tmp_path / "junk.stl").write_bytes(b"solid x\n facet nonsense\n")
    with pytest.raises(ValueError, match="junk.stl"):
        geometry.Mesh.from_stl(tmp_path / "junk.stl")


# ---------------------------------------------------------------------------- wall layers


@pytest.mark.parametrize("layers", [1, 3])
def test_tank_walls_count_and_thickness(layers):
    dx, (nx, ny) = 0.05, (30, 12)
    tank = geometry.rectangle([0.0, 0.0], [nx * dx, ny * dx])
    closed = geometry.wall_layers(tank, dx, layers)
    assert len(closed) == (nx + 2 * layers) * (ny + 2 * layers) - nx * ny
    open_top = geometry.wall_layers(tank, dx, layers, open_top=True)
    assert len(open_top) == (nx + 2 * layers) * (ny + layers) - nx * ny
    for walls in (closed, open_top):
        x = walls.position
        assert not np.any(tank.contains(x))
        gap = np.maximum(np.maximum(-x, x - np.array([nx, ny]) * dx), 0).max(axis=1)
        assert gap.max() < layers * dx  # L-infinity distance to the tank
        assert np.all(walls.volume == dx**2)
    cube = geometry.wall_layers(geometry.box([0, 0, 0], [0.5, 0.5, 0.5]), 0.1, 2)
    assert len(cube) == 9**3 - 5**3


def test_tank_walls_are_the_cases_walls():
    # the built-in tanks' walls at even resolutions, bit for bit (at odd n the dam break's
    # lattice puts an extra row across the top of its tank; the primitive does not)
    for n in (4, 10, 20, 32):
        dx = 0.3 / n
        tank_length = dx * round(5 * 0.3 / dx)
        ours = geometry.wall_layers(
            geometry.rectangle([0, 0], [tank_length, 0.75]), dx, 3, open_top=True
        )
        assert np.array_equal(ours.position, box_walls([0, 0], [tank_length, 0.75], dx, 3, True))


def test_walls_around_and_inside_a_circle():
    dx, radius, layers = 0.01, 0.2, 3
    disc = geometry.circle([0.0, 0.0], radius)
    for side, sign in (("outside", 1), ("inside", -1)):
        walls = geometry.wall_layers(disc, dx, layers, side=side)
        r = np.linalg.norm(walls.position, axis=1)
        assert np.all(sign * (r - radius) > 0)
        # L-infinity steps: within layers dx along the axes, layers dx sqrt(2) diagonally
        assert np.all(np.abs(r - radius) < layers * dx * math.sqrt(2) + 1e-12)
        # the ring between r and r +- layers dx is covered: its area is a lower bound
        inner, outer = sorted([radius, radius + sign * layers * dx])
        ring = math.pi * (outer**2 - inner**2)
        assert len(walls) * dx**2 >= ring - 2 * math.pi * (inner + outer) * math.sqrt(2) * dx
    fluid = geometry.fill(disc, dx)
    inside = geometry.wall_layers(disc, dx, layers, side="inside")
    assert len(inside) < len(fluid)


def test_kernel_support_layers():
    assert geometry.layers_for(3 * 0.015, 0.015) == 3
    assert geometry.layers_for(2.4 * 0.01, 0.01) == 3


@pytest.mark.parametrize(
    "build, message",
    [
        (lambda: geometry.rectangle([0, 0], [1, 0]), r"upper \[1.0, 0.0\] must exceed lower"),
        (lambda: geometry.rectangle([0, 0, 0], [1, 1, 1]), "a rectangle has 2 coordinates"),
        (lambda: geometry.circle([0, 0], -1), "radius must be a positive number"),
        (lambda: geometry.sphere([0, 0], 1), "a sphere's centre has 3 coordinates"),
        (lambda: geometry.Cylinder([0, 0, 0], [0, 0, 0], 1, 1), "axis must be a non-zero"),
        (lambda: geometry.Polygon([[0, 0], [1, 1], [1, 0], [0, 1]]), "not form a simple polygon"),
        (lambda: geometry.Polygon([[0, 0], [1, 1]]), "at least 3"),
        (lambda: geometry.fill(geometry.circle([0, 0], 1), 0), "dx must be a positive number"),
        (lambda: geometry.fill(geometry.circle([0, 0], 1), 1e-5), "use a larger dx"),
        (
            lambda: geometry.wall_layers(geometry.circle([0, 0], 1), 0.1, 0),
            "layers must be a whole number >= 1",
        ),
        (
            lambda: geometry.wall_layers(geometry.circle([0, 0], 1), 0.1, 2, side="in"),
            "side must be 'outside' or 'inside'",
        ),
    ],
)
def test_bad_shapes_name_the_argument(build, message):
    with pytest.raises(ValueError, match=message):
        build()
