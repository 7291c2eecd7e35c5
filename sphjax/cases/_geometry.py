"""Particle lattices for case set-ups (numpy, outside jit)."""

from __future__ import annotations

import math

import numpy as np

from sphjax._text import show


def lattice(lower, upper, dx) -> np.ndarray:
    """Cell-centred square/cubic lattice filling the box ``[lower, upper]`` with spacing dx.

    Returns ``[N, d]`` positions ``lower + (i + 1/2) dx``.
    """
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    counts = [max(1, int(round((hi - lo) / dx))) for lo, hi in zip(lower, upper, strict=True)]
    axes = [lo + (np.arange(n) + 0.5) * dx for lo, n in zip(lower, counts, strict=True)]
    grid = np.meshgrid(*axes, indexing="ij")
    return np.stack([g.ravel() for g in grid], axis=-1)


def wall_layers(cutoff: float, dx: float) -> int:
    """Layers of dummy particles needed to cover the kernel support."""
    return int(math.ceil(cutoff / dx - 1e-9))


def box_walls(inner_lower, inner_upper, dx, layers, open_top=False) -> np.ndarray:
    """Dummy particles in ``layers`` layers around the box (2D or 3D).

    The wall particles fill ``[lower - layers dx, upper + layers dx]`` minus the inside;
    ``open_top`` leaves out the layers above the last axis.
    """
    inner_lower, inner_upper = np.asarray(inner_lower, float), np.asarray(inner_upper, float)
    pad = layers * dx
    outer_upper = inner_upper + pad
    if open_top:
        outer_upper[-1] = inner_upper[-1]
    points = lattice(inner_lower - pad, outer_upper, dx)
    between = (points > inner_lower) & (points < inner_upper)
    if open_top:
        # a lattice row exactly at the top is open air, not a lid
        between[:, -1] = points[:, -1] > inner_lower[-1]
    inside = np.all(between, axis=-1)
    return points[~inside]


def check_positive(name: str, value) -> float:
    """``value`` as a float; a ValueError naming ``name`` unless it is finite and > 0."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number, got {show(value)}") from None
    if not number > 0 or not math.isfinite(number):
        raise ValueError(f"{name} must be a positive number, got {show(value)}")
    return number


def check_resolution(name: str, value, minimum: int = 2) -> int:
    """``value`` as an int; a ValueError naming ``name`` unless it is an integer >= minimum."""
    try:
        ok = int(value) == value and int(value) >= minimum
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise ValueError(
            f"{name} must be an integer >= {minimum} (particles across the case), got {show(value)}"
        )
    return int(value)
