"""Set-up data handed to JAX without compiling anything.

Outside ``jit`` every jax.numpy operation is a program of its own, compiled the first time
it meets a shape and dtype: ``jnp.asarray`` of a numpy array or a Python number too (the
``stage`` operation), ``jnp.zeros``, ``x * 2.0``.  Each costs 10-80 ms of XLA time, and a
run's set-up met some forty of them, more than its first evaluation took to compile.  Set-up
data that is never traced (geometry, lattices, capacities, frame times) is computed in numpy
and handed over with one transfer, :func:`device_array` (``jax.device_put`` compiles
nothing); what ``jax.grad`` must see stays in jax.numpy, inside one jitted program.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np


def is_traced(*trees) -> bool:
    """Whether a leaf of ``trees`` is a Tracer (set-up under ``jax.grad``, ``jit``, ...)."""
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(trees))


def inside_trace() -> bool:
    """Whether the caller runs inside a ``jit`` trace (a new array would be traced)."""
    return isinstance(jax.device_put(np.int32(0)), jax.core.Tracer)


def outside_traces():
    """A context in which JAX computes as it does outside every trace, even inside an
    outer ``jit`` or ``jax.grad``: operations on concrete arrays run now and jitted
    functions run compiled (set-up that needs concrete values: a neighbour allocation).

    Unlike ``jax.ensure_compile_time_eval()`` it does not fold constants into programs
    traced meanwhile: lowered there, a neighbour rebuild computed its shape-only arrays
    (cell indices, ``arange(N)``) eagerly and captured them as constants of the program,
    and so did the traced run behind it (a ``[N, K]`` list and positions; 2.9 GB at one
    million particles).  Operations on a Tracer of an enclosing trace are not allowed
    inside it."""
    return jax.core.eval_context()


def concrete_call(*trees) -> bool:
    """Whether a function called with ``trees`` runs on concrete arrays outside any trace:
    then a public pure function (``evaluate``, ``kick_drift_kick``) runs as one compiled
    program rather than operation by operation."""
    return not is_traced(*trees) and not inside_trace()


def device_array(value, dtype=None) -> jax.Array:
    """``jnp.asarray(value, dtype)`` without compiling: a concrete ``value`` goes through
    numpy and one transfer; a traced one (or a list holding a Tracer) to ``jnp.asarray``.
    ``dtype`` follows JAX's precision (float64 is float32 unless ``jax_enable_x64``)."""
    if is_traced(value):
        return jnp.asarray(value, dtype)
    if dtype is not None:
        dtype = jax.dtypes.canonicalize_dtype(dtype)
    if isinstance(value, jax.Array) and (dtype is None or value.dtype == dtype):
        return value
    return jax.device_put(np.asarray(value, dtype))
