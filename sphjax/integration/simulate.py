"""``simulate``: a Case run by the kick-drift-kick step in a ``lax.scan``.

With concrete inputs it runs in compiled chunks, each a ``lax.while_loop`` over steps that
stops early at the first step whose neighbour lists overflowed (that step is not taken;
the lists are re-allocated and the run goes on from the step before) or that went unstable
(NaN, a particle leaving the domain: the run stops there); finished frames go to
``on_frames`` (the HDF5 writer).  Under ``jax.grad``, ``jit`` or ``vmap`` it is a single
``lax.scan`` whose steps are rematerialised in reverse mode (and, with
``checkpoint_every``, chunks of steps too), with the same checks raised from inside the
computation.

Frames are saved every ``save_every`` steps and at the last step.
"""

from __future__ import annotations

import contextlib
import functools
import math
import operator
import types
import warnings
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from sphjax._host import concrete_call, device_array, inside_trace, outside_traces
from sphjax._linear_call import refuse_second_order
from sphjax._text import show
from sphjax.core import ordering
from sphjax.core.case import Case
from sphjax.core.model import Model
from sphjax.core.params import Params
from sphjax.core.state import State, Trajectory
from sphjax.integration.stepper import stepper_for
from sphjax.integration.timestep import check_time_step
from sphjax.neighbors import (
    NEIGHBOR_IDX,
    ListSizes,
    NeighborOverflowError,
    NeighborOverflowWarning,
    Neighbors,
    grown,
    list_sizes,
    needed_sizes,
    overflow_message,
    overflowed,
    update_neighbors,
    widest,
)
from sphjax.physics.rhs import (
    UPDATE_FIELDS,
    build_neighbors,
    check_params,
    check_system_params,
    system_blocks,
    with_reference,
)


class SimulationError(RuntimeError):
    """A run went unstable: NaN or a particle left the domain."""

    def __init__(self, message, step=None, particle=None, time=None):
        super().__init__(message)
        self.step, self.particle, self.time = step, particle, time


#: the most chunk carries (``checkpoint_every``) one level of reverse mode stores; runs
#: (and frames) with more chunks are checkpointed in groups of chunks (frames) too
#: (:func:`_nested_scan`)
MAX_STORED_CHUNKS = 16

_KEEP_UPDATE = jax.checkpoint_policies.save_only_these_names(UPDATE_FIELDS)
_KEEP_NEIGHBOR_IDX = jax.checkpoint_policies.save_only_these_names(NEIGHBOR_IDX, UPDATE_FIELDS)


# ---------------------------------------------------------------------------- one step


def kick_drift_kick(state: State, neighbors: Neighbors, dt, model: Model, params: Params):
    """Advance one step of size ``dt`` with neighbour lists; returns ``(state, neighbors)``.

    The step of :func:`sphjax.integration.stepper.stepper_for` ``(model)``: kick-drift-kick
    with the right-hand side evaluated on neighbour lists updated at the drifted positions;
    a solid with ``substeps > 1`` is sub-cycled inside the step
    (:mod:`sphjax.integration.split`).  Called with concrete arrays outside any trace, the
    step runs as one compiled program (kept per model and shapes), so that a loop of steps
    written in Python does not run each step operation by operation.
    """
    if concrete_call(state, neighbors, dt, params):
        return _step_compiled(state, neighbors, dt, params, model=model)
    return stepper_for(model).step((state, neighbors), dt, params)


@functools.partial(jax.jit, static_argnames="model")
def _step_compiled(state, neighbors, dt, params, *, model):
    return stepper_for(model).step((state, neighbors), dt, params)


def unhealthy(state: State, model: Model):
    """``[N]`` True where a particle is NaN/inf or outside the domain on a closed axis."""
    finite = jnp.all(jnp.isfinite(state.position), -1) & jnp.all(jnp.isfinite(state.velocity), -1)
    lower = jnp.asarray(model.domain.lower, state.position.dtype)
    upper = jnp.asarray(model.domain.upper, state.position.dtype)
    closed = ~jnp.asarray(model.domain.periodic)
    outside = jnp.any(closed & ((state.position < lower) | (state.position > upper)), -1)
    return ~finite | outside


def _split_fixed(neighbors: Neighbors):
    """``(fixed, rest)``: the part of ``neighbors`` that no step changes (the solids'
    reference quantities and their reference-configuration lists), or ``None``, and the
    rest."""
    keys = [k for k in neighbors.pairs if k[0] == k[1] and not neighbors.plan.current[k[0]]]
    if neighbors.reference is None and not keys:
        return None, neighbors
    fixed = (neighbors.reference, {k: neighbors.pairs[k] for k in keys})
    pairs = {k: v for k, v in neighbors.pairs.items() if k not in keys}
    return fixed, neighbors.replace(reference=None, pairs=pairs)


def _join_fixed(neighbors: Neighbors, fixed) -> Neighbors:
    """:func:`_split_fixed` undone."""
    reference, pairs = fixed
    return neighbors.replace(reference=reference, pairs={**neighbors.pairs, **pairs})


def _step_with_checks(carry, dt, model, params, fixed=None):
    """One step and its health check.  ``fixed``: the part of the neighbours that no step
    changes (:func:`_split_fixed`) when the carry goes without it: a scan then closes over
    it instead of carrying it, so reverse mode keeps it once, not once per stored carry."""
    state, neighbors, failure, step = carry
    if fixed is not None:
        neighbors = _join_fixed(neighbors, fixed)
    state, neighbors = kick_drift_kick(state, neighbors, dt, model, params)
    if fixed is not None:
        neighbors = _split_fixed(neighbors)[1]
    step = step + 1
    bad = unhealthy(state, model)
    record = (failure[0] < 0) & jnp.any(bad)
    failure = jnp.where(record, jnp.stack([step, jnp.argmax(bad).astype(step.dtype)]), failure)
    return state, neighbors, failure, step


def _run_steps(carry, n_steps: int, checkpoint_every: int | None, step_fn):
    """``n_steps`` steps, each rematerialised in reverse mode; with ``checkpoint_every``
    also in chunks of that many steps.

    Reverse mode keeps only a step's input carry and recomputes its internals when it is
    transposed: storing every pair quantity of every step instead would take about 100 x
    the memory and, being memory-bound on the CPU, twice the time.  Without
    ``checkpoint_every`` the input carry of every step is kept (memory grows with the
    number of steps); with it, only the first carry of each chunk is kept, and a chunk is
    replayed once more (one more forward pass); past :data:`MAX_STORED_CHUNKS` chunks,
    groups of chunks are checkpointed too (:func:`_nested_scan`: memory flat, a second
    extra forward pass).  Outside differentiation ``jax.checkpoint`` costs nothing.
    """

    def body(c, _):
        return step_fn(c), None

    if checkpoint_every is None or n_steps <= 1:
        body = jax.checkpoint(body, policy=_KEEP_UPDATE, prevent_cse=False)
        return jax.lax.scan(body, carry, None, length=n_steps)[0]
    # a step's replay keeps its neighbour indices (recorded by the chunk replay) rather
    # than repeating the cell-list search
    body = jax.checkpoint(body, policy=_KEEP_NEIGHBOR_IDX, prevent_cse=False)
    chunk_len = min(checkpoint_every, n_steps)
    n_chunks, rest = divmod(n_steps, chunk_len)

    @functools.partial(jax.checkpoint, prevent_cse=False)
    def chunk(c, _):
        return jax.lax.scan(body, c, None, length=chunk_len)[0], None

    carry = _nested_scan(chunk, carry, n_chunks)[0]
    if rest:
        carry = jax.lax.scan(body, carry, None, length=rest)[0]
    return carry


def _nested_scan(f, carry, length: int, stored: int = 1):
    """``jax.lax.scan(f, carry, None, length=length)`` for an ``f`` whose reverse mode
    stores ``stored`` carries (a checkpointed chunk: its input carry), with nested
    checkpointing when the scan would store more than :data:`MAX_STORED_CHUNKS`.

    Then the iterations are grouped: a scan over groups of about ``sqrt(length *
    stored) / stored`` iterations (at most the bound's worth of groups, and one more for
    the rest), each group checkpointed, so reverse mode stores one carry per group plus
    those of the one group it replays: about ``2 sqrt(length * stored)`` carries rather
    than ``length * stored`` (13 rather than 40 for 2,000 steps in chunks of 50), for one
    more forward replay of each step.  A group that would still store too many is nested
    again, so each level stores at most about the bound's worth.  Returns ``(carry,
    ys)``, ``ys`` stacked over all ``length`` iterations as ``lax.scan`` stacks them.
    """
    if length * stored <= MAX_STORED_CHUNKS:
        return jax.lax.scan(f, carry, None, length=length)
    size = max(
        math.ceil(math.sqrt(length * stored) / stored), math.ceil(length / MAX_STORED_CHUNKS)
    )
    n_groups, rest = divmod(length, size)

    def group(c, _, n=size):
        return _nested_scan(f, c, n, stored)

    carry, ys = jax.lax.scan(jax.checkpoint(group, prevent_cse=False), carry, None, n_groups)
    ys = jax.tree_util.tree_map(lambda y: y.reshape(-1, *y.shape[2:]), ys)
    if rest:
        carry, more = jax.checkpoint(functools.partial(group, n=rest), prevent_cse=False)(
            carry, None
        )
        ys = jax.tree_util.tree_map(lambda y, z: jnp.concatenate([y, z]), ys, more)
    return carry, ys


def _stored_per_run(n_steps: int, checkpoint_every: int) -> int:
    """How many carries reverse mode stores for :func:`_run_steps` with
    ``checkpoint_every`` (the chunks' first carries, nested past the bound, and one per
    step left over)."""
    chunk_len = min(checkpoint_every, n_steps)
    n_chunks, rest = divmod(n_steps, chunk_len)
    return min(n_chunks, MAX_STORED_CHUNKS) + rest


def _run_frames(carry, dt, params, *, model, save_every, n_frames, checkpoint_every, fixed=None):
    """``n_frames`` frames of ``save_every`` steps from ``carry = (state, neighbors,
    failure, step)``; returns the last carry and the frames' States.  ``fixed``: see
    :func:`_step_with_checks`."""
    step_fn = functools.partial(_step_with_checks, dt=dt, model=model, params=params, fixed=fixed)

    def frame(carry, _):
        carry = _run_steps(carry, save_every, checkpoint_every, step_fn)
        return carry, carry[0]

    if checkpoint_every is None:
        return jax.lax.scan(frame, carry, None, length=n_frames)
    # Frames are checkpointed (in groups) only when their chunks together would store
    # more than the bound: a frame's chunks already store only their first carry, and
    # one more level replays the frames once more in reverse mode.
    stored = _stored_per_run(save_every, int(checkpoint_every))
    return _nested_scan(frame, carry, n_frames, stored)


_with_reference = jax.jit(with_reference, static_argnames="model")


def _run_until_stopped(carry, frames, dt, params, start, stop, *, model, save_every):
    """Steps from ``carry = (state, neighbors, failure, step)`` until step ``stop``, the
    first unstable step, or the first step whose neighbour lists overflowed, saving the
    state after every step ``start + k save_every`` in ``frames[k - 1]``.

    An overflowing step is not taken: the state, failure and step are those before it, and
    the overflowed lists are returned for their counts (what a re-allocation needs).
    Returns ``(carry, frames)``."""

    def running(loop):
        (_, neighbors, failure, step), _ = loop
        return (step < stop) & (failure[0] < 0) & ~overflowed(neighbors).astype(bool)

    def one_step(loop):
        carry, frames = loop
        stepped = _step_with_checks(carry, dt, model, params)
        lost = overflowed(stepped[1]).astype(bool)
        state, _, failure, step = jax.tree_util.tree_map(
            lambda old, new: jnp.where(lost, old, new),
            (carry[0], None, carry[2], carry[3]),
            (stepped[0], None, stepped[2], stepped[3]),
        )
        slot, phase = jnp.divmod(step - start, save_every)
        saved = (phase == 0) & (slot > 0) & ~lost
        slot = jnp.clip(slot - 1, 0, frames.position.shape[0] - 1)

        def save(frames):
            return jax.tree_util.tree_map(
                lambda buffer, x: jax.lax.dynamic_update_index_in_dim(buffer, x, slot, 0),
                frames,
                state,
            )

        # (a frame written only in the steps that save one: selecting the old slot or the
        # state in every step would read and write the whole state each step)
        frames = jax.lax.cond(saved, save, lambda frames: frames, frames)
        return (state, stepped[1], failure, step), frames

    return jax.lax.while_loop(running, one_step, (carry, frames))


def _run_chunk_checked(carry, frames, dt, params, start, stop, first, save_every, *, model):
    """:func:`_run_until_stopped`, after the run's first evaluation if ``first`` (the
    stepper's ``init``: the rates of the initial state; in the chunk's program rather than
    a program of its own, which would cost a small run's start-up about 0.3 s to compile).
    Returns ``(carry, frames, initial, overflow)``: ``initial`` is the state the steps
    started from, ``overflow`` whether the last carry's lists overflowed."""
    state = jax.lax.cond(
        first,
        lambda s: stepper_for(model).init((s, carry[1]), params)[0],
        lambda s: s,
        carry[0],
    )
    carry, frames = _run_until_stopped(
        (state, *carry[1:]), frames, dt, params, start, stop, model=model, save_every=save_every
    )
    return carry, frames, state, overflowed(carry[1]).astype(bool)


# ``save_every`` and ``stop`` are arguments, not constants, and a run hands every chunk a
# frame buffer of one size: a run compiles one chunk program whatever its number of steps,
# its last (shorter) chunk and its remainder steps (a last frame after fewer steps)
_run_chunk = jax.jit(_run_chunk_checked, static_argnames=("model",), donate_argnums=(1,))


# ---------------------------------------------------------------------------- simulate


def _concrete(traced: bool):
    """:func:`~sphjax._host.outside_traces` inside a trace (``traced`` inputs or an outer
    ``jit``), where the set-up must stay concrete; outside one a no-op."""
    inside = traced or inside_trace()
    return outside_traces() if inside else contextlib.nullcontext()


def _is_traced(*trees) -> bool:
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(trees))


def _on_host(*trees) -> bool:
    """Whether ``trees`` hold concrete arrays in host memory (the CPU backend): then the
    drivers' bookkeeping (stacking frames, frame times) runs in numpy, compiling nothing."""
    return jax.default_backend() == "cpu" and not _is_traced(*trees)


def _stack(frames: list[State]) -> State:
    if _on_host(frames):
        return jax.tree_util.tree_map(
            lambda *xs: jax.device_put(np.concatenate([np.asarray(x) for x in xs])), *frames
        )
    return jax.tree_util.tree_map(lambda *xs: jnp.concatenate(xs, axis=0), *frames)


def _first(frames: State, n: int) -> State:
    """The first ``n`` frames (in numpy on the host: no program compiled for the slice)."""
    if _on_host(frames):
        return jax.tree_util.tree_map(lambda x: jax.device_put(np.asarray(x)[:n]), frames)
    return jax.tree_util.tree_map(lambda x: x[:n], frames)


def _expand(state: State) -> State:
    if _on_host(state):
        return jax.tree_util.tree_map(lambda x: jax.device_put(np.asarray(x)[None]), state)
    return jax.tree_util.tree_map(lambda x: x[None], state)


def _times(steps, dt):
    """``steps * dt`` in the precision of ``dt`` (numpy for a concrete ``dt``)."""
    if _is_traced(dt):
        return jnp.asarray(steps, dt.dtype) * dt
    dt = np.asarray(dt)
    return jax.device_put(np.asarray(steps, dt.dtype) * dt)


def _failure_reason(state: State, model: Model, row: int) -> str:
    """What :func:`unhealthy` found at particle ``row`` of the failing ``state``: a
    non-finite value, or the side of the domain it left, with its position and velocity."""
    x = np.asarray(state.position[row], np.float64)
    v = np.asarray(state.velocity[row], np.float64)
    where = f"at x = {np.round(x, 6).tolist()} with v = {np.round(v, 4).tolist()}"
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(v))):
        return f"has a non-finite position/velocity ({where})"
    sides = []
    for axis, (lo, hi, periodic) in enumerate(
        zip(model.domain.lower, model.domain.upper, model.domain.periodic, strict=True)
    ):
        if not periodic and x[axis] < lo:
            sides.append(f"below the lower bound {lo:.6g} on axis {axis}")
        if not periodic and x[axis] > hi:
            sides.append(f"above the upper bound {hi:.6g} on axis {axis}")
    hint = "a particle that flows out of a case's geometry: lengthen it or enlarge its Domain"
    return f"left the domain {where}, {' and '.join(sides)} ({hint})"


#: the error a traced run's check raised last, so that a run executed when ``simulate``
#: is called (under ``jax.grad`` with no ``jit`` around it) raises that error rather than
#: the runtime's wrapper around it (the checks run on the runtime's callback thread)
_raised = types.SimpleNamespace(error=None)

# How a traced run reports a neighbour overflow or an unstable step: "raise" (a host
# callback raises NeighborOverflowError / SimulationError from inside the program) or
# "nan" (its frames' floating-point fields come back NaN; see failures_as_nan).
_traced_failures = types.SimpleNamespace(mode="raise")


@contextlib.contextmanager
def failures_as_nan():
    """Inside this block a traced run (under ``jit``/``grad``/``vmap``) that overflows its
    neighbour lists or goes unstable returns NaN in every floating-point field of its
    frames instead of raising from a host callback; runs traced elsewhere still raise.

    JAX never writes a program that holds a host callback to its persistent compilation
    cache, so with the callbacks every gradient of a simulation is compiled anew in every
    process; a program traced inside this block has none and is cached like any other.
    The price is the message: a NaN says that the run failed, not where.  Read it from the
    same run outside the block (:func:`sphjax.calibrate` does: a non-finite loss is
    re-run concretely, which raises the SimulationError or NeighborOverflowError that
    names the step and particle).  A function traced inside the block keeps its NaN
    reporting when a ``jit`` cache later calls it outside."""
    previous, _traced_failures.mode = _traced_failures.mode, "nan"
    try:
        yield
    finally:
        _traced_failures.mode = previous


def _nan_where(failed, frames: State) -> State:
    """``frames`` with every floating-point field NaN where ``failed``, and so every
    derivative of them (a product with NaN, not a ``where``, whose derivative would be 0);
    exact where not (a product with 1)."""

    def poison(x):
        if not jnp.issubdtype(x.dtype, jnp.inexact):
            return x
        return x * jnp.where(failed, jnp.asarray(jnp.nan, x.dtype), jnp.asarray(1, x.dtype))

    return jax.tree_util.tree_map(poison, frames)


def _raising_what_the_run_raised(run, *args):
    """``run(*args)`` (the compiled traced run); if it executes now and one of its checks
    raises, raise that SimulationError or NeighborOverflowError itself."""
    *args, segments = args
    _raised.error = None
    try:
        return run(*args, segments=segments)
    except jax.errors.JaxRuntimeError:
        error, _raised.error = _raised.error, None
        if error is None:
            raise
        raise error from None


def _raise_failure(failure, dt, order=None, state=None, model=None):
    """Raise the SimulationError of a recorded ``failure = (step, particle)``; with the
    failing ``state`` and ``model`` (concrete runs) it says what went wrong and where,
    and its time is the state's own (right after a resumed run's start too)."""
    step, row = (int(x) for x in np.asarray(failure))
    particle = row if order is None else int(order[row])
    if step >= 0:
        time = step * float(dt) if state is None else float(state.time)
        if state is None:
            reason = "has a non-finite position/velocity or left the domain"
        else:
            reason = _failure_reason(state, model, row)
        _raised.error = SimulationError(
            f"simulation went unstable at step {step} (t = {time:.6g}): particle "
            f"{particle} {reason}",
            step=step,
            particle=particle,
            time=time,
        )
        raise _raised.error


def _raise_overflow(overflow):
    if bool(overflow):
        _raised.error = NeighborOverflowError(
            overflow_message("inside a traced (jit/grad/vmap) simulation")
        )
        raise _raised.error


def simulate(
    case: Case,
    params: Params | None = None,
    *,
    n_steps: int | None = None,
    t_end: float | None = None,
    save_every: int | None = None,
    dt: float | None = None,
    state: State | None = None,
    checkpoint_every: int | None = None,
    on_frames: Callable[[State, jax.Array], None] | None = None,
    progress: Callable[[int], None] | None = None,
    steps_per_chunk: int = 2000,
    cell_order: bool = True,
) -> Trajectory:
    """Run ``case`` and return its Trajectory (the initial frame first).

    Args:
      case: from ``sphjax.cases``.
      params: differentiable parameters (default ``case.params``).
      n_steps: number of steps; or give ``t_end`` (default ``case.t_end``), not both.
      save_every: steps between saved frames (default: only the last frame); when it
        does not divide ``n_steps`` the last frame is at ``n_steps`` (see
        ``Trajectory.times``).
      dt: time step (default ``case.dt``); rejected above the stability limit.
      state: initial state (default ``case.state_for(params)``: the case's initial state,
        recomputed from ``params`` where it depends on them).
      checkpoint_every: in reverse mode every step is rematerialised (only its input
        carry is stored, about ``N * (4 d + 6 + K)`` numbers); with ``checkpoint_every``
        the steps are also grouped in chunks of this many and only each chunk's first
        carry is stored, so memory does not grow with every step, for one more forward
        pass.  Past ``MAX_STORED_CHUNKS`` (16) chunks the chunks are checkpointed in
        groups too (nested checkpointing), so the stored carries stay few (13 for 40
        chunks) at any ``n_steps``, for a second extra forward pass.  ``None``: store
        every step's carry (faster, memory linear in ``n_steps``).
      on_frames: ``f(states, times)`` called with each finished block of frames (concrete
        runs only); used to append to HDF5 as the run goes.
      progress: ``f(n)`` called with the number of steps just completed.
      cell_order: run with each system's particles in a space-filling order of their
        cells (:mod:`sphjax.core.ordering`), so that neighbours are near in memory;
        the Trajectory, ``on_frames`` and error messages keep the particles in the
        order of ``state`` (results equal to round-off).  ``False``: run in that order.
    Returns:
      :class:`Trajectory` with ``ceil(n_steps / save_every) + 1`` frames.
    """
    params = case.params if params is None else params
    model = case.model
    check_params(model, params)
    state = case.state_for(params) if state is None else state
    dt = case.dt if dt is None else dt
    if n_steps is not None and t_end is not None:
        raise ValueError(
            f"give n_steps or t_end, not both (got n_steps={show(n_steps)} and "
            f"t_end={show(t_end)}); t_end = n_steps * dt"
        )
    if n_steps is None:
        t_end = case.t_end if t_end is None else t_end
        if not t_end > 0:
            raise ValueError(f"t_end must be a positive number, got {show(t_end)}")
        n_steps = max(1, int(math.ceil(t_end / float(dt) - 1e-9)))
    if not isinstance(n_steps, int | np.integer) or n_steps < 1:
        raise ValueError(f"n_steps must be a positive integer, got {show(n_steps)}")
    n_steps = int(n_steps)
    save_every = n_steps if save_every is None else save_every
    if not isinstance(save_every, int | np.integer) or save_every < 1:
        raise ValueError(f"save_every must be a positive integer, got {show(save_every)}")
    save_every = int(min(save_every, n_steps))
    if checkpoint_every is not None and int(checkpoint_every) < 1:
        raise ValueError(f"checkpoint_every must be a positive integer, got {checkpoint_every}")
    n_frames, rest = divmod(n_steps, save_every)
    segments = ((save_every, n_frames),) + (((rest, 1),) if rest else ())
    traced = _is_traced(params, state, dt)
    if not traced:
        _check_finite(state)
        check_system_params(model, params)
        check_time_step(float(dt), state, model, params)
        _check_inside(state, model)
    dt = device_array(dt, state.position.dtype)

    neighbor_state = state if not _is_traced(state) else case.state
    order = None
    if cell_order:
        blocks = system_blocks(np.asarray(neighbor_state.kind), model)
        perm = ordering.cell_order(np.asarray(neighbor_state.position), blocks, model.cutoff)
        if not np.array_equal(perm, np.arange(perm.shape[0])):
            order = perm
    if order is not None:
        back = ordering.inverse(order)
        state = ordering.permute(state, order)
        with _concrete(traced):  # concrete even inside an outer jit
            neighbor_state = ordering.permute(neighbor_state, order)
        if on_frames is not None:
            on_frames = functools.partial(_in_user_order, on_frames, back)
    # Allocation needs concrete values; inside an outer ``jit`` the jax-md set-up would
    # otherwise be staged out and fail on a traced box size.
    with _concrete(traced):
        neighbors = build_neighbors(
            neighbor_state,
            model,
            compact_rows=not traced,
            margin=None if traced else model.neighbor_margin,
        )
    # the solids' reference quantities (L0), once per run, from the (maybe traced) state
    if not all(system.current_configuration for system in model.systems):
        neighbors = _with_reference(state, neighbors, model)
        if not traced:
            _check_reference(neighbors, model, order)
    if traced:
        if model.pair_adjoint:
            refuse_second_order(params, state, dt)
        run = functools.partial(
            _simulate_compiled,
            checkpoint_every=checkpoint_every,
            order=order,
            max_stored=MAX_STORED_CHUNKS,
            failures=_traced_failures.mode,
        )
    else:
        run = functools.partial(
            _simulate_in_chunks,
            on_frames=on_frames,
            progress=progress,
            steps_per_chunk=steps_per_chunk,
            order=order,
        )
    if traced:
        if inside_trace():
            neighbors = _rebuilt_as_zeros(neighbors)
        states = _raising_what_the_run_raised(run, state, neighbors, dt, params, model, segments)
    else:
        states = run(state, neighbors, dt, params, model, segments=segments)
    if order is not None:
        states = ordering.permute(states, back, axis=1)
    steps = np.concatenate(
        [[0], np.arange(1, n_frames + 1) * save_every, [n_steps] if rest else []]
    )
    return Trajectory(states=states, times=_times(steps, dt))


def _in_user_order(on_frames, back, states, times):
    """``on_frames`` with the frames' particles in the user's order."""
    return on_frames(ordering.permute(states, back, axis=1), times)


def _initial_carry(state, neighbors):
    """``(state, neighbors, failure, step)``: no failure recorded (-1, -1), step 0."""
    return state, neighbors, np.full(2, -1, np.int32), np.zeros((), np.int32)


@functools.partial(
    jax.jit, static_argnames=("model", "segments", "checkpoint_every", "max_stored", "failures")
)
def _simulate_compiled(
    state,
    neighbors,
    dt,
    params,
    model,
    *,
    segments,
    checkpoint_every,
    order,
    max_stored,
    failures="raise",
):
    """:func:`_simulate_traced` as one program.  Under an outer transformation without a
    ``jit`` (``jax.grad(loss)(p)``) the run would otherwise be differentiated and executed
    operation by operation, about twice as slow (under an outer ``jit`` it is not used).
    ``order`` (an array, or ``None``) maps the run's particles to the user's for error
    messages; ``max_stored`` is :data:`MAX_STORED_CHUNKS` when called, read by the trace,
    a part of the cache key; ``failures``: ``"raise"`` or ``"nan"`` (:func:`failures_as_nan`)."""
    del max_stored
    return _simulate_traced(
        state,
        neighbors,
        dt,
        params,
        model,
        segments=segments,
        checkpoint_every=checkpoint_every,
        order=order,
        failures=failures,
    )


def _rebuilt_as_zeros(neighbors: Neighbors) -> Neighbors:
    """``neighbors`` with the arrays that the traced run's forced rebuild overwrites (the
    searched list and its reference positions, the lists split from it, their support
    level and its origin) replaced by zeros made in the enclosing trace.  Inside an outer
    ``jit`` the allocation's concrete lists would otherwise be constants of its program
    (``[N, K]`` integers: 7 MB at 40,000 particles, hundreds of MB at a million).  Zero
    reference positions make jax-md's rebuild see every particle as moved."""
    if neighbors.search is None:
        return neighbors
    fixed, rest = _split_fixed(neighbors)

    def zeros(tree):
        return jax.tree_util.tree_map(jnp.zeros_like, tree)

    search = rest.search
    rest = rest.replace(
        search=search.set(
            idx=zeros(search.idx), reference_position=zeros(search.reference_position)
        ),
        pairs=zeros(rest.pairs),
        skin=zeros(rest.skin),
        support_origin=zeros(rest.support_origin),
    )
    return rest if fixed is None else _join_fixed(rest, fixed)


def _simulate_traced(
    state, neighbors, dt, params, model, *, segments, checkpoint_every, order, failures="raise"
):
    """One ``lax.scan`` per segment of equal frames (under grad/jit/vmap); overflow and
    instability are raised from inside the computation.  Returns the frames, the initial
    one first.

    The run starts behind an optimisation barrier: where the initial state is a constant
    of an enclosing program (a loss that closes over the case), XLA would otherwise
    evaluate the first neighbour rebuild and evaluation while compiling (constant
    folding: a sort of every particle, seconds at 40,000 particles)."""
    state, neighbors = jax.lax.optimization_barrier((state, neighbors))
    neighbors = update_neighbors(state.position, neighbors, rebuild=True)
    state, neighbors = stepper_for(model).init((state, neighbors), params)
    # what no step changes (a solid's reference list and quantities) stays out of the
    # scans' carry: reverse mode then keeps it once, not once per step or chunk
    fixed, neighbors = _split_fixed(neighbors)
    carry, all_frames = _initial_carry(state, neighbors), [_expand(state)]
    for save_every, n_frames in segments:
        carry, frames = _run_frames(
            carry,
            dt,
            params,
            model=model,
            save_every=save_every,
            n_frames=n_frames,
            checkpoint_every=checkpoint_every,
            fixed=fixed,
        )
        all_frames.append(frames)
    if failures == "nan":
        return _nan_where(overflowed(carry[1]) | (carry[2][0] >= 0), _stack(all_frames))
    jax.debug.callback(_raise_overflow, overflowed(carry[1]))
    jax.debug.callback(_raise_failure, carry[2], dt, order)
    return _stack(all_frames)


def _simulate_in_chunks(
    state,
    neighbors,
    dt,
    params,
    model,
    *,
    segments,
    on_frames,
    progress,
    steps_per_chunk,
    order,
):
    """Compiled chunks of at most ``steps_per_chunk`` steps with concrete checks between
    them: a neighbour overflow re-allocates and repeats the chunk; an unstable run hands
    the frames before the failure to ``on_frames`` and raises.  Returns the frames."""
    carry = _initial_carry(state, neighbors)
    all_frames = []
    extra = [0]  # neighbour slots added beyond the allocation's own estimate
    base = 0  # steps before the current segment

    def frames_per_chunk(save_every):
        return max(1, steps_per_chunk // save_every)

    # the frame buffer of every chunk: the longest chunk's (one program for the run)
    buffer = max(min(frames_per_chunk(every), n) for every, n in segments)
    for save_every, n_frames in segments:
        done = 0
        while done < n_frames:
            k = min(frames_per_chunk(save_every), n_frames - done)
            start = base + done * save_every
            carry, frames, initial = _run_chunk_growing(
                carry, dt, params, model, save_every, k, start, extra, not all_frames, buffer
            )
            if not all_frames:  # the first chunk: the initial state, its rates evaluated
                _check_initial_rates(initial, order)
                all_frames.append(_expand(initial))
                if on_frames is not None:
                    on_frames(all_frames[0], _times([0], dt))
            end_steps = start + (1 + np.arange(k)) * save_every
            frame_times = _times(end_steps, dt)
            fail_step = int(np.asarray(carry[2])[0])
            if fail_step >= 0:
                good = int(np.sum(end_steps < fail_step))
                kept = jax.tree_util.tree_map(operator.itemgetter(slice(good)), frames)
                if on_frames is not None and good:
                    on_frames(kept, frame_times[:good])
                _raise_failure(carry[2], dt, order, carry[0], model)
            if on_frames is not None:
                on_frames(frames, frame_times)
            all_frames.append(frames)
            done += k
            if progress is not None:
                progress(k * save_every)
        base += n_frames * save_every
    return _stack(all_frames)


def _check_initial_rates(state, order):
    """A SimulationError if the initial ``state`` has a non-finite acceleration."""
    bad = ~np.all(np.isfinite(np.asarray(state.acceleration)), axis=-1)
    if bad.any():
        particle = int(np.argmax(bad))
        particle = particle if order is None else int(order[particle])
        raise SimulationError(
            f"the initial state has a non-finite acceleration at particle {particle} "
            "(step 0); check the initial density, mass and spacing of the case",
            step=0,
            particle=particle,
            time=0.0,
        )


def _run_chunk_growing(
    carry, dt, params, model, save_every, n_frames, start, extra, first, buffer=None
):
    """``n_frames`` frames of ``save_every`` steps from step ``start``; at a neighbour-list
    overflow, re-allocate and go on from the step before it.  ``buffer``: the frames are
    written into a buffer of this many (at least ``n_frames``; the chunks of a run share
    one size, so one compiled program), of which the first ``n_frames`` are returned.

    The split lists are re-allocated from the most neighbours (and rows with neighbours)
    they met (``Neighbors.counts``, the overflowing step's included; a dam break's fluid
    spreading along the floor meets ever more wall particles).  An overflow of the search
    itself, which jax-md does not count, raises ``extra``, kept for later chunks.  With
    ``first``, the chunk begins with the run's first evaluation.  Returns the last carry,
    the frames (those after an unstable step are not filled) and, with ``first``, the
    initial state with its rates (else ``None``)."""
    zeros = np.zeros if _on_host(carry[0]) else jnp.zeros
    size = n_frames if buffer is None else max(buffer, n_frames)
    frames = jax.tree_util.tree_map(
        lambda x: jax.device_put(zeros((size, *x.shape), x.dtype)), carry[0]
    )
    stop = start + n_frames * save_every
    stuck = 0  # re-allocations at the same step
    initial = None
    every = np.int32(save_every)
    while True:
        before = int(carry[3])
        carry, frames, started, lost_any = _run_chunk(
            carry, frames, dt, params, start, stop, np.bool_(first), every, model=model
        )
        if first:  # the state after the first evaluation; a repeat starts from its carry
            initial, first = started, False
        state, lost, _, step = carry
        if not bool(lost_any):
            if size > n_frames:
                frames = _first(frames, n_frames)
            return carry, frames, initial
        stuck = stuck + 1 if int(step) == before else 0
        if stuck >= 10:
            raise NeighborOverflowError(
                f"neighbour list kept overflowing at step {int(step) + 1}; raise "
                "Model.neighbor_capacity"
            )
        old = list_sizes(lost)
        if bool(lost.search.did_buffer_overflow):
            extra[0] = max(extra[0] + old.search // 2, 2)
        neighbors = build_neighbors(
            state,
            model,
            extra_capacity=extra[0],
            compact_rows=True,
            margin=model.neighbor_margin,
            at_least=widest(old, grown(old, needed_sizes(lost, extra[0], model.neighbor_margin))),
        )
        neighbors = neighbors.replace(reference=lost.reference)
        carry = (state, neighbors, *carry[2:])
        warnings.warn(
            f"neighbour list overflowed at step {int(step) + 1}; re-allocated "
            f"({_growth(old, list_sizes(neighbors), model)}) and went on from step {int(step)}",
            NeighborOverflowWarning,
            stacklevel=4,
        )


def _growth(old: ListSizes, new: ListSizes, model) -> str:
    """What a re-allocation changed, in words."""

    def name(i, j):
        systems = (model.systems[i], model.systems[j])
        return "-".join(type(x).__name__.removesuffix("System").lower() for x in systems)

    changes = [f"search {old.search} -> {new.search} slots per particle"]
    changes += [
        f"{name(*key)} {old.widths.get(key, 0)} -> {width} slots"
        for key, width in new.widths.items()
        if width != old.widths.get(key, 0)
    ]
    changes += [
        f"{name(*key)} {old.members.get(key, 0)} -> {rows} rows"
        for key, rows in new.members.items()
        if rows != old.members.get(key, 0)
    ]
    return ", ".join(changes)


def _check_finite(state: State) -> None:
    """Reject an initial state with NaN/inf in its positions, velocities, densities or masses."""
    for name in ("position", "velocity", "density", "mass"):
        x = np.asarray(getattr(state, name))
        bad = ~np.isfinite(x.reshape(x.shape[0], -1)).all(axis=-1)
        if bad.any():
            i = int(np.argmax(bad))
            raise ValueError(
                f"state.{name}: particle {i} has a non-finite value {x[i].tolist()}; "
                f"every initial {name} must be a finite number"
            )


def _check_reference(neighbors, model: Model, order) -> None:
    """Reject a run whose solids' reference quantities (``L0``, eq. 15, or the
    second-order gradient's ``G``) are not finite: their moment matrix is singular, as
    the second-order gradient's is with fewer than three particles through a solid."""
    for i, fields in (neighbors.reference or {}).items():
        for name, value in fields.items():
            if name == "geometry":
                continue
            x = np.asarray(value)
            bad = ~np.isfinite(x.reshape(x.shape[0], -1)).all(axis=-1)
            if not bad.any():
                continue
            row = neighbors.blocks[i][0] + int(np.argmax(bad))
            particle = row if order is None else int(order[row])
            system = model.systems[i]
            hint = (
                "gradient_correction='second_order' needs at least three particles through "
                "the solid in every direction; use 'first_order' or a finer resolution"
                if getattr(system, "gradient_correction", None) == "second_order"
                else "check the solid's reference positions and volumes"
            )
            raise ValueError(
                f"{type(system).__name__}: the reference-configuration matrix of particle "
                f"{particle} is singular ({int(bad.sum())} particles in all): {hint}"
            )


def _check_inside(state: State, model: Model) -> None:
    """Reject initial particles outside the domain (periodic axes included)."""
    x = np.asarray(state.position)
    lower, upper = np.asarray(model.domain.lower), np.asarray(model.domain.upper)
    outside = np.any((x < lower) | (x > upper), axis=-1)
    periodic_out = np.any(np.asarray(model.domain.periodic) & ((x < lower) | (x >= upper)), -1)
    bad = outside | periodic_out
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(
            f"state.position: particle {i} at {x[i].tolist()} lies outside the domain "
            f"[{model.domain.lower}, {model.domain.upper}) (periodic axes "
            f"{model.domain.periodic}); move it inside or enlarge Model.domain"
        )
