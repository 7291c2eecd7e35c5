"""Geometry: shapes and the particles sampled from them (numpy, outside jit).

    from sphjax import geometry

    column = geometry.rectangle([0.0, 0.0], [0.3, 0.6])
    fluid = geometry.fill(column, dx=0.015)  # 20 x 40 lattice sites, volume dx^2 each
    tank = geometry.rectangle([0.0, 0.0], [1.5, 0.75])
    walls = geometry.wall_layers(tank, dx=0.015, layers=3, open_top=True)
    drop = geometry.fill(geometry.circle([0.75, 0.5], 0.1), dx=0.015)
    hull = geometry.fill(geometry.Mesh.from_stl("hull.stl"), dx=0.01)

Shapes (:mod:`sphjax.geometry.shapes`): :class:`Box` (:func:`rectangle`, :func:`box`),
:class:`Sphere` (:func:`circle`, :func:`sphere`), :class:`Cylinder`, :class:`Polygon` and
:class:`Mesh` (closed STL surfaces through trimesh).  Sampling
(:mod:`sphjax.geometry.sampling`): :func:`fill`, :func:`wall_layers`, :func:`layers_for`;
all shapes sampled with one ``dx`` and ``origin`` share one lattice.
"""

from sphjax.geometry.sampling import Particles, fill, layers_for, wall_layers
from sphjax.geometry.shapes import (
    Box,
    Cylinder,
    Mesh,
    Polygon,
    Sphere,
    box,
    circle,
    rectangle,
    sphere,
)

__all__ = [
    "Box",
    "Cylinder",
    "Mesh",
    "Particles",
    "Polygon",
    "Sphere",
    "box",
    "circle",
    "fill",
    "layers_for",
    "rectangle",
    "sphere",
    "wall_layers",
]
