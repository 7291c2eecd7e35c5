"""Pair geometry in a box with optional periodic axes.

Like ``jax_md.space``, a space is a pair of functions: ``displacement(Ra, Rb)`` returns
the minimum-image vector ``r_a - r_b`` and ``shift(R, dR)`` moves particles and wraps
them back into the box along periodic axes.  ``safe_norm`` returns ``|dr|`` with a
gradient that stays finite at ``dr = 0`` (the double-where idiom).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np


def minimum_image(dr, size, periodic):
    """``dr`` wrapped to the nearest image on the periodic axes (numpy or jax arrays).

    Args:
      dr: ``[..., d]`` differences of positions.
      size: ``[d]`` box lengths; periodic: ``[d]`` bools.
    """
    xp = np if isinstance(dr, np.ndarray) else jnp
    periodic = xp.asarray(periodic, dtype=bool)
    size = xp.asarray(size, dtype=dr.dtype)
    return xp.where(periodic, dr - size * xp.round(dr / size), dr)


def displacement_fn(domain):
    """Return ``displacement(Ra, Rb) -> r_a - r_b`` with the minimum image on periodic axes."""
    size = jnp.asarray(domain.size)
    periodic = jnp.asarray(domain.periodic)

    def displacement(Ra, Rb):
        dr = Ra - Rb
        if not any(domain.periodic):
            return dr
        return minimum_image(dr, size, periodic)

    return displacement


def wrap_fn(domain):
    """Return ``wrap(R)`` that maps positions into ``[lower, upper)`` on periodic axes."""
    lower = jnp.asarray(domain.lower)
    size = jnp.asarray(domain.size)
    periodic = jnp.asarray(domain.periodic)

    def wrap(R):
        if not any(domain.periodic):
            return R
        lo, L = lower.astype(R.dtype), size.astype(R.dtype)
        return jnp.where(periodic, lo + jnp.mod(R - lo, L), R)

    return wrap


def safe_norm(dr, axis=-1):
    """``|dr|`` along ``axis`` whose gradient is 0 (not NaN) where ``dr = 0``."""
    r2 = jnp.sum(dr * dr, axis=axis)
    positive = r2 > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, r2, 1.0)), 0.0)


def covered(weight):
    """``weight > sqrt(tiny)``: where a kernel-weight sum (a Shepard denominator) is large
    enough to divide by.  A fluid particle at the very edge of the support gives a weight
    of order 1e-25 in float32; the quotient itself is fine, but its derivative
    ``-num / weight^2`` overflows (``weight^2`` underflows to 0) and, times the kernel's
    vanishing slope there, gives NaN gradients.  Below this floor the sum counts as empty."""
    return weight > jnp.sqrt(jnp.finfo(jnp.result_type(weight)).tiny)


@jax.custom_jvp
def dot(a, b):
    """``a . b`` over the last (spatial) axis, written out: XLA on the CPU ends a loop
    fusion at a reduction, even over two or three components.

    Its derivative is written as a product and a sum over the axis, so that its transpose
    (reverse mode) is the element-wise ``cotangent * b`` rather than one padded array per
    component."""
    return sum(a[..., i] * b[..., i] for i in range(a.shape[-1]))


def _dot_jvp(primals, tangents):
    a, b = primals
    da, db = tangents
    zero = jax.custom_derivatives.SymbolicZero
    terms = [
        t
        for t in (
            None if isinstance(da, zero) else da * b,
            None if isinstance(db, zero) else a * db,
        )
        if t is not None
    ]
    if not terms:
        return dot(a, b), jnp.zeros(jnp.broadcast_shapes(a.shape, b.shape)[:-1], a.dtype)
    return dot(a, b), jnp.sum(sum(terms), axis=-1)


dot.defjvp(_dot_jvp, symbolic_zeros=True)


@jax.custom_jvp
def scale(s, v):
    """``s[..., None] * v``: a scalar field times a vector field.

    Its derivative is written per component (a stack of products), so that its transpose
    is element-wise code rather than a reduction over the spatial axis, which would end
    XLA's loop fusion on the CPU."""
    return s[..., None] * v


def _scale_jvp(primals, tangents):
    s, v = primals
    ds, dv = tangents
    zero = jax.custom_derivatives.SymbolicZero
    d = v.shape[-1]
    out = scale(s, v)
    shape = jnp.broadcast_shapes(s.shape + (1,), v.shape)
    tangent = jnp.zeros(shape, out.dtype)
    if not isinstance(ds, zero):
        tangent = tangent + jnp.stack(
            [jnp.broadcast_to(ds * v[..., i], shape[:-1]) for i in range(d)], axis=-1
        )
    if not isinstance(dv, zero):
        tangent = tangent + s[..., None] * dv
    return out, tangent


scale.defjvp(_scale_jvp, symbolic_zeros=True)
