"""Smoothing kernels ``W(r, h)`` and their gradients (formulation eqs. 1-4).

A kernel is a small frozen dataclass (hashable, so it can sit in the static Model) with

* ``support`` — the support radius in units of ``h`` (``W = 0`` for ``r >= support h``),
* ``shape(q)`` and ``shape_derivative(q)`` — the unnormalised profile ``f(q)``, ``q = r/h``,
* ``normalisation(dim)`` — ``sigma_d`` so that ``W = sigma_d / h^d f(r/h)`` integrates to 1.

``W(kernel, r, h, dim)`` evaluates the kernel and ``grad_W(kernel, dr, r, h, dim)`` its
gradient with respect to the first particle, ``grad_a W(r_a - r_b) = W'(r) dr / r``,
pointing from b to a.  Both are safe at ``r = 0`` (no NaN in values or gradients).
"""

from __future__ import annotations

import dataclasses
import math

import jax.numpy as jnp


@dataclasses.dataclass(frozen=True)
class Kernel:
    """Base class: subclasses define ``support``, ``shape``, ``shape_derivative``."""

    support = 2.0

    def shape(self, q):
        raise NotImplementedError

    def shape_derivative(self, q):
        raise NotImplementedError

    def normalisation(self, dim: int) -> float:
        raise NotImplementedError


def _pos(x):
    return jnp.maximum(x, 0.0)


@dataclasses.dataclass(frozen=True)
class CubicSpline(Kernel):
    """Cubic B-spline (Monaghan 1992), support ``2h``."""

    support = 2.0

    def shape(self, q):
        return 0.25 * _pos(2.0 - q) ** 3 - _pos(1.0 - q) ** 3

    def shape_derivative(self, q):
        return -0.75 * _pos(2.0 - q) ** 2 + 3.0 * _pos(1.0 - q) ** 2

    def normalisation(self, dim):
        return {1: 2.0 / 3.0, 2: 10.0 / (7.0 * math.pi), 3: 1.0 / math.pi}[dim]


@dataclasses.dataclass(frozen=True)
class QuinticSpline(Kernel):
    """Quintic spline (Morris, Fox & Zhu 1997), support ``3h``."""

    support = 3.0

    def shape(self, q):
        return _pos(3.0 - q) ** 5 - 6.0 * _pos(2.0 - q) ** 5 + 15.0 * _pos(1.0 - q) ** 5

    def shape_derivative(self, q):
        return -5.0 * (_pos(3.0 - q) ** 4 - 6.0 * _pos(2.0 - q) ** 4 + 15.0 * _pos(1.0 - q) ** 4)

    def normalisation(self, dim):
        return {1: 1.0 / 120.0, 2: 7.0 / (478.0 * math.pi), 3: 1.0 / (120.0 * math.pi)}[dim]


@dataclasses.dataclass(frozen=True)
class WendlandC2(Kernel):
    """Wendland C2 (Wendland 1995; Dehnen & Aly 2012 scaling), support ``2h``."""

    support = 2.0

    def shape(self, q):
        s = _pos(1.0 - 0.5 * q)
        return s**4 * (2.0 * q + 1.0)

    def shape_derivative(self, q):
        s = _pos(1.0 - 0.5 * q)
        return -5.0 * q * s**3

    def normalisation(self, dim):
        if dim == 1:
            raise ValueError("WendlandC2 is defined here for dim 2 and 3")
        return {2: 7.0 / (4.0 * math.pi), 3: 21.0 / (16.0 * math.pi)}[dim]


@dataclasses.dataclass(frozen=True)
class WendlandC4(Kernel):
    """Wendland C4, support ``2h``."""

    support = 2.0

    def shape(self, q):
        s = _pos(1.0 - 0.5 * q)
        return s**6 * (35.0 / 12.0 * q**2 + 3.0 * q + 1.0)

    def shape_derivative(self, q):
        s = _pos(1.0 - 0.5 * q)
        return -(14.0 / 3.0) * q * (1.0 + 2.5 * q) * s**5

    def normalisation(self, dim):
        if dim == 1:
            raise ValueError("WendlandC4 is defined here for dim 2 and 3")
        return {2: 9.0 / (4.0 * math.pi), 3: 495.0 / (256.0 * math.pi)}[dim]


KERNELS = {
    "cubic_spline": CubicSpline,
    "quintic_spline": QuinticSpline,
    "wendland_c2": WendlandC2,
    "wendland_c4": WendlandC4,
}


def kernel_by_name(name: str) -> Kernel:
    """Return the kernel called ``name`` (one of ``KERNELS``)."""
    try:
        return KERNELS[name]()
    except KeyError:
        raise ValueError(f"unknown kernel {name!r}; choose one of {sorted(KERNELS)}") from None


def as_kernel(kernel: Kernel | str) -> Kernel:
    """A kernel object from a kernel or its name (case factories accept both)."""
    return kernel_by_name(kernel) if isinstance(kernel, str) else kernel


def W(kernel: Kernel, r, h, dim: int):
    """Kernel value ``W(r, h) = sigma_d / h^d f(r / h)`` (eq. 4)."""
    return kernel.normalisation(dim) / h**dim * kernel.shape(r / h)


def dW_dr(kernel: Kernel, r, h, dim: int):
    """Radial derivative ``dW/dr``."""
    return kernel.normalisation(dim) / h ** (dim + 1) * kernel.shape_derivative(r / h)


def grad_W(kernel: Kernel, dr, r, h, dim: int):
    """Gradient ``grad_a W(r_a - r_b) = dW/dr (r_a - r_b) / r`` (eq. 2), zero at r = 0.

    Args:
      dr: ``[..., d]`` pair vector ``r_a - r_b``.
      r: ``[...]`` its length, already guarded (see :func:`sphjax.core.space.safe_norm`).
    """
    r_safe = jnp.where(r > 0, r, 1.0)
    factor = jnp.where(r > 0, dW_dr(kernel, r_safe, h, dim) / r_safe, 0.0)
    return factor[..., None] * dr
