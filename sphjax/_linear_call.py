"""``custom_adjoint``: a function with JAX's own forward mode and a hand-written adjoint.

``jax.custom_vjp`` functions cannot be used in forward mode (``jax.jvp``, ``jacfwd``),
and a ``jax.custom_jvp`` rule is transposed by autodiff.  ``custom_adjoint(f, adjoint)``
gives both: its JVP is ``jax.jvp(f)`` wrapped in ``jax.custom_derivatives.linear_call``
with ``adjoint`` as the transpose, so forward mode is autodiff and reverse mode
(``grad``, ``vjp``) calls ``adjoint``.  JAX 0.10 has no batching rule for the
``linear_call`` primitive (``jax.vmap`` of ``jacfwd`` or of ``grad`` would fail); one is
registered here: both the linear function and its transpose are vmapped.

First derivatives only: ``linear_call`` has no derivative with respect to its residuals,
so second derivatives through ``custom_adjoint`` functions are not available; asking for
one raises a ``NotImplementedError`` that names ``Model(pair_adjoint=False)``.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
from jax._src.core import jaxpr_as_fun
from jax._src.custom_derivatives import linear_call_p
from jax._src.interpreters import ad, batching
from jax.custom_derivatives import SymbolicZero, linear_call


def _batch_linear_call(vals, dims, *, callee, transpose_thunk, num_callee_consts, num_res):
    """``vmap`` of ``linear_call``: the batched call of the vmapped function and transpose.

    Linear arguments are broadcast to the batch (so the transpose's outputs, batched,
    match them); residuals keep their own batching.
    """
    size = next(v.shape[d] for v, d in zip(vals, dims, strict=True) if d is not None)
    n_fixed = num_callee_consts + num_res
    vals = [v if d is None else jnp.moveaxis(v, d, 0) for v, d in zip(vals, dims, strict=True)]
    fixed, linear = vals[:n_fixed], vals[n_fixed:]
    fixed_axes = [None if d is None else 0 for d in dims[:n_fixed]]
    linear = [
        v if d is not None else jnp.broadcast_to(v, (size, *v.shape))
        for v, d in zip(linear, dims[n_fixed:], strict=True)
    ]
    transpose, transpose_consts = transpose_thunk()

    def batched_callee(fixed, linear):
        fn = jaxpr_as_fun(callee)
        return jax.vmap(lambda f, x: fn(*f, *x), in_axes=(fixed_axes, 0))(fixed, linear)

    def batched_transpose(fixed, cotangents):
        fn = jaxpr_as_fun(transpose)
        residuals = fixed[num_callee_consts:]
        return jax.vmap(
            lambda r, c: fn(*transpose_consts, *r, *c),
            in_axes=(fixed_axes[num_callee_consts:], 0),
        )(residuals, cotangents)

    out = linear_call(batched_callee, batched_transpose, list(fixed), list(linear))
    return out, [0] * len(out)


batching.primitive_batchers[linear_call_p] = _batch_linear_call

_linear_call_jvp = ad.primitive_jvps[linear_call_p]


def _jvp_linear_call_or_explain(primals, tangents, **params):
    """JAX's JVP of ``linear_call``, which asserts that the residuals carry no tangent;
    a second derivative through a ``custom_adjoint`` function would, so say so."""
    n_fixed = params["num_callee_consts"] + params["num_res"]
    if not all(type(t) is ad.Zero for t in tangents[:n_fixed]):
        raise NotImplementedError(
            "second derivatives (e.g. jax.hessian, jvp of grad) through sphjax's "
            "hand-derived adjoint of the fluid rates are not available; build the case "
            "with Model(pair_adjoint=False), e.g. "
            "case.replace(model=case.model.replace(pair_adjoint=False))"
        )
    return _linear_call_jvp(primals, tangents, **params)


ad.primitive_jvps[linear_call_p] = _jvp_linear_call_or_explain


def custom_adjoint(fun: Callable, adjoint: Callable, n_linear: int) -> Callable:
    """``fun(*linear, *static_arrays)`` with reverse mode given by ``adjoint``.

    Args:
      fun: the function; its first ``n_linear`` arguments are differentiable (floating
        point), the rest (e.g. integer neighbour indices) are not.
      adjoint: ``adjoint(args, cotangent) -> tuple`` of cotangents of the first
        ``n_linear`` arguments, ``args`` being all arguments of ``fun``.
      n_linear: number of differentiable leading arguments.
    """

    @jax.custom_jvp
    def wrapped(*args):
        return fun(*args)

    def _jvp(primals, tangents):
        # only the non-zero tangents are linear arguments: the transpose of linear_call
        # needs all of them to be unknowns of the linearisation
        active = [not isinstance(t, SymbolicZero) for t in tangents[:n_linear]]

        def tangent_map(args, tangents):
            tangents = iter(tangents)
            full = [
                next(tangents) if a else jnp.zeros_like(x)
                for x, a in zip(args[:n_linear], active, strict=True)
            ]
            rest = args[n_linear:]
            return jax.jvp(lambda *x: fun(*x, *rest), args[:n_linear], tuple(full))[1]

        def transpose(args, cotangent):
            bars = adjoint(args, cotangent)
            return tuple(b for b, a in zip(bars, active, strict=True) if a)

        linear = tuple(t for t, a in zip(tangents[:n_linear], active, strict=True) if a)
        out_tangent = linear_call(tangent_map, transpose, primals, linear)
        return fun(*primals), out_tangent

    wrapped.defjvp(_jvp, symbolic_zeros=True)
    return wrapped
