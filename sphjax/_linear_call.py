"""``custom_adjoint``: a function with JAX's own forward mode and a hand-written adjoint.

``jax.custom_vjp`` functions cannot be used in forward mode (``jax.jvp``, ``jacfwd``),
and a ``jax.custom_jvp`` rule is transposed by autodiff.  ``custom_adjoint(f, adjoint)``
gives both: its JVP is ``jax.jvp(f)`` wrapped in the public
``jax.custom_derivatives.linear_call`` with ``adjoint`` as the transpose, so forward mode is
autodiff and reverse mode (``grad``, ``vjp``) calls ``adjoint``.

``jax.vmap`` of such a function in forward mode (``jacfwd`` is a vmapped ``jvp``) needs a
batching rule for ``linear_call``, which JAX up to 0.10 does not have.  The one hook into
JAX's internals is isolated here, through public modules only (the primitive is read from
a traced program, the rule goes into ``jax.interpreters.batching``): on first use, and only
for the JAX versions it was tested with (:data:`TESTED_JAX`), a batching rule is *added*
for that primitive if JAX has none (no existing rule is replaced; programs that do not
call ``linear_call`` are not affected).  For any other JAX version, or if the hook cannot
be installed, ``custom_adjoint`` returns ``f`` unchanged: plain autodiff, slower in
reverse mode, same results.

First derivatives only: ``linear_call`` has no derivative with respect to its residuals;
asking for a second derivative raises a ``NotImplementedError`` that names
``Model(pair_adjoint=False)``.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable

import jax
import jax.numpy as jnp
from jax.custom_derivatives import SymbolicZero, linear_call

#: (major, minor) JAX versions the batching hook was tested with
TESTED_JAX = ((0, 10),)

_HIGHER_ORDER_TRACERS = ("JVPTracer", "LinearizeTracer")


def _jax_version() -> tuple[int, int]:
    major, minor = (
        int("".join(c for c in p if c.isdigit()) or 0) for p in jax.__version__.split(".")[:2]
    )
    return major, minor


def _linear_call_primitive():
    """The primitive behind ``linear_call``, read from a traced program (public API only);
    ``None`` if it cannot be found."""
    try:
        jaxpr = jax.make_jaxpr(lambda x: linear_call(lambda r, t: t, lambda r, c: c, (), x))(1.0)
        primitive = jaxpr.eqns[0].primitive
    except Exception:  # noqa: BLE001 (any failure means: no hook, plain autodiff)
        return None
    return primitive if primitive.name == "linear_call" else None


@functools.cache
def hook_installed() -> bool:
    """Install the ``linear_call`` batching rule if this JAX lacks one; False (with one
    warning per process, naming the version and the cost) if unavailable."""
    installed = _install_hook()
    if not installed:
        tested = ", ".join(f"{major}.{minor}" for major, minor in TESTED_JAX) or "none"
        warnings.warn(
            f"sphjax: the custom adjoint of the pair sums is not available on JAX "
            f"{jax.__version__} (tested with JAX {tested}); reverse mode falls back to "
            "JAX's own transpose of the pair sums: same gradients, slower (up to 2.5 "
            "times per momentum pair sum; docs/performance_gradients.md)",
            stacklevel=3,
        )
    return installed


def _install_hook() -> bool:
    if _jax_version() not in TESTED_JAX:
        return False
    try:
        from jax.extend.core import jaxpr_as_fun
        from jax.interpreters import batching
    except ImportError:
        return False
    linear_call_p = _linear_call_primitive()
    if linear_call_p is None:
        return False
    if linear_call_p in getattr(batching, "fancy_primitive_batchers", {}):
        return True

    def batch_linear_call(vals, dims, *, callee, transpose_thunk, num_callee_consts, num_res):
        """``vmap`` of ``linear_call``: vmap both the function and its transpose.  Linear
        arguments are broadcast to the batch (so the transpose's batched outputs match)."""
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

    batching.primitive_batchers[linear_call_p] = batch_linear_call
    return True


def _derivative_levels(x) -> int:
    """How many differentiations (JVP or linearisation traces) ``x`` is traced by."""
    levels = 0
    while isinstance(x, jax.core.Tracer):
        levels += type(x).__name__ in _HIGHER_ORDER_TRACERS
        x = getattr(x, "primal", getattr(x, "val", None))
    return levels


def refuse_second_order(*trees):
    """The error of :func:`_refuse_second_order` for arguments of a whole run, checked
    before the run is compiled (inside a ``jit`` the nesting is no longer visible)."""
    if any(_derivative_levels(x) > 1 for x in jax.tree_util.tree_leaves(trees)):
        _raise_second_order()


def _refuse_second_order(primals):
    if any(type(x).__name__ in _HIGHER_ORDER_TRACERS for x in jax.tree_util.tree_leaves(primals)):
        _raise_second_order()


def _raise_second_order():
    raise NotImplementedError(
        "second derivatives (e.g. jax.hessian, jvp of grad) through sphjax's custom "
        "adjoint of the pair sums are not available; build the case with "
        "Model(pair_adjoint=False), e.g. "
        "case.replace(model=case.model.replace(pair_adjoint=False))"
    )


def custom_adjoint(fun: Callable, adjoint: Callable, n_linear: int) -> Callable:
    """``fun(*linear, *static_arrays)`` with reverse mode given by ``adjoint``.

    Args:
      fun: the function; its first ``n_linear`` arguments are differentiable (floating
        point), the rest (e.g. integer neighbour indices) are not.
      adjoint: ``adjoint(args, cotangent, active) -> tuple`` of cotangents of the first
        ``n_linear`` arguments, ``args`` being all arguments of ``fun`` and ``active``
        a tuple of ``n_linear`` booleans, False for an argument whose tangent is a
        symbolic zero (not differentiated): its cotangent is not used and may be
        ``None``, so the adjoint can skip computing it.
      n_linear: number of differentiable leading arguments.
    Returns:
      ``fun`` with the adjoint attached, or ``fun`` itself where the JAX version does not
      support the hook (see the module docstring).
    """
    if not hook_installed():
        return fun

    @jax.custom_jvp
    def wrapped(*args):
        return fun(*args)

    def _jvp(primals, tangents):
        _refuse_second_order(primals)
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
            bars = adjoint(args, cotangent, tuple(active))
            return tuple(b for b, a in zip(bars, active, strict=True) if a)

        linear = tuple(t for t, a in zip(tangents[:n_linear], active, strict=True) if a)
        out_tangent = linear_call(tangent_map, transpose, primals, linear)
        return fun(*primals), out_tangent

    wrapped.defjvp(_jvp, symbolic_zeros=True)
    return wrapped
