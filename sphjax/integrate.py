"""Time integration: a kick-drift-kick step as a ``lax.scan``, and ``simulate``.

Kick-drift-kick (velocity Verlet), one right-hand-side evaluation per step:

    v_{n+1/2} = v_n + dt/2 a_n
    x_{n+1}   = x_n + dt v_{n+1/2}
    rho_{n+1} = rho_n + dt Drho(x_{n+1}, v_{n+1/2})          (continuity, eq. 11)
    a_{n+1}   = a(x_{n+1}, v_{n+1/2}, rho_{n+1})
    v_{n+1}   = v_{n+1/2} + dt/2 a_{n+1}

Density lives at whole steps and velocity at half steps, the staggered leapfrog that is
stable for the acoustic waves of weakly compressible SPH up to the usual Courant limit.
For forces that depend on positions only (elastic solids, inviscid fluids with summation
density) this is the symplectic Störmer-Verlet scheme.  The rates of the last evaluation
are kept in the State, so they are not recomputed.

``simulate`` runs a Case.  With concrete inputs it runs in compiled chunks: after each
chunk it checks for neighbour-list overflow (re-allocating and repeating the chunk) and
for an unstable run (NaN, a particle leaving the domain), and hands finished frames to
``on_frames`` (the HDF5 writer).  Under ``jax.grad``, ``jit`` or ``vmap`` it is a single
``lax.scan`` whose steps are rematerialised in reverse mode (and, with
``checkpoint_every``, chunks of steps too), with the same checks raised from inside the
computation.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import operator
import warnings
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from jax.ad_checkpoint import checkpoint_name

from sphjax.case import Case
from sphjax.neighbors import NeighborSearch, capacity, reference_neighbors
from sphjax.rhs import Neighbors, evaluate, has_kind
from sphjax.space import wrap_fn
from sphjax.state import Kind, Model, Params, State
from sphjax.timestep import check_time_step


class SimulationError(RuntimeError):
    """A run went unstable: NaN or a particle left the domain."""

    def __init__(self, message, step=None, particle=None, time=None):
        super().__init__(message)
        self.step, self.particle, self.time = step, particle, time


class NeighborOverflowError(RuntimeError):
    """The neighbour list ran out of room where it cannot be re-allocated."""


@dataclasses.dataclass(frozen=True)
class Trajectory:
    """Saved frames: ``states`` is a State whose arrays have a leading time axis."""

    states: State
    times: jax.Array

    def __len__(self) -> int:
        return int(self.times.shape[0])

    def frame(self, i: int) -> State:
        return jax.tree_util.tree_map(lambda x: x[i], self.states)

    @property
    def final(self) -> State:
        return self.frame(-1)


jax.tree_util.register_dataclass(Trajectory, data_fields=["states", "times"], meta_fields=[])


# ---------------------------------------------------------------------------- neighbours


def _search(model: Model) -> NeighborSearch:
    return _search_for(model, bool(jax.config.jax_enable_x64))


@functools.lru_cache(maxsize=64)
def _search_for(model: Model, x64: bool) -> NeighborSearch:
    return NeighborSearch(model, x64=x64)


def build_neighbors(state: State, model: Model, extra_capacity: int = 0) -> Neighbors:
    """Allocate neighbour data for concrete ``state`` (outside ``jit``)."""
    fluid = solid_members = solid_idx = None
    if has_kind(model, Kind.FLUID):
        fluid = _search(model).allocate(state.position, extra_capacity)
    if has_kind(model, Kind.SOLID):
        kind = np.asarray(state.kind)
        members = np.flatnonzero((kind == Kind.SOLID) | (kind == Kind.CLAMPED))
        solid_idx = jnp.asarray(reference_neighbors(state.reference_position, members, model))
        solid_members = jnp.asarray(members, dtype=jnp.int32)
    return Neighbors(fluid=fluid, solid_members=solid_members, solid_idx=solid_idx)


_NEIGHBOR_IDX = "sphjax_neighbor_idx"
_KEEP_NEIGHBOR_IDX = jax.checkpoint_policies.save_only_these_names(_NEIGHBOR_IDX)


def _update_neighbors(position, neighbors: Neighbors, model: Model, rebuild=False) -> Neighbors:
    if neighbors.fluid is None:
        return neighbors
    search = _search(model)
    fluid = (search.rebuild if rebuild else search.update)(position, neighbors.fluid)
    # named so that rematerialisation keeps the indices instead of repeating the search
    fluid = fluid.set(idx=checkpoint_name(fluid.idx, _NEIGHBOR_IDX))
    return dataclasses.replace(neighbors, fluid=fluid)


def _overflowed(neighbors: Neighbors):
    if neighbors.fluid is None:
        return jnp.asarray(False)
    return jnp.asarray(neighbors.fluid.did_buffer_overflow)


# ---------------------------------------------------------------------------- one step


def kick_drift(state: State, dt, model: Model) -> State:
    """First half of a step: half kick with the stored rates, then a full drift.

    Returns the State at ``t + dt`` with half-step velocities; its rates
    are still those of ``t`` (the caller evaluates them at the new positions).
    """
    kind = state.kind
    free = ((kind == Kind.FLUID) | (kind == Kind.SOLID))[:, None]
    half = 0.5 * dt
    velocity = jnp.where(free, state.velocity + half * state.acceleration, state.velocity)
    # walls move with their prescribed velocity; with the transport-velocity formulation
    # fluid particles are advected with v~ = v_{n+1/2} + dt/2 a_b (Adami et al. 2013)
    position = state.position + dt * (velocity + half * state.shift_acceleration)
    time = state.time + dt
    if model.clamped_motion is not None:
        clamped = (kind == Kind.CLAMPED)[:, None]
        target = model.clamped_motion(time, state.reference_position)
        velocity = jnp.where(clamped, (target - state.position) / dt, velocity)
        position = jnp.where(clamped, target, position)
    else:
        position = jnp.where((kind == Kind.CLAMPED)[:, None], state.position, position)
    position = wrap_fn(model.domain)(position)
    return state.replace(position=position, velocity=velocity, time=time)


def closing_kick(state: State, dt) -> State:
    """Second half of a step: half kick with the freshly evaluated accelerations."""
    free = ((state.kind == Kind.FLUID) | (state.kind == Kind.SOLID))[:, None]
    velocity = jnp.where(free, state.velocity + 0.5 * dt * state.acceleration, state.velocity)
    return state.replace(velocity=velocity)


def kick_drift_kick(state: State, neighbors: Neighbors, dt, model: Model, params: Params):
    """Advance one step of size ``dt``; returns ``(state, neighbors)``.

    :func:`kick_drift`, a right-hand-side evaluation at the new positions that also
    advances the continuity density by ``dt`` (``evaluate(..., density_step=dt)``), then
    :func:`closing_kick` (both shared with the diffrax solver ``sphjax.KickDriftKick``).
    """
    state = kick_drift(state, dt, model)
    neighbors = _update_neighbors(state.position, neighbors, model)
    state = evaluate(state, neighbors, model, params, density_step=dt)
    return closing_kick(state, dt), neighbors


def unhealthy(state: State, model: Model):
    """``[N]`` True where a particle is NaN/inf or outside the domain on a closed axis."""
    finite = jnp.all(jnp.isfinite(state.position), -1) & jnp.all(jnp.isfinite(state.velocity), -1)
    lower = jnp.asarray(model.domain.lower, state.position.dtype)
    upper = jnp.asarray(model.domain.upper, state.position.dtype)
    closed = ~jnp.asarray(model.domain.periodic)
    outside = jnp.any(closed & ((state.position < lower) | (state.position > upper)), -1)
    return ~finite | outside


def _step_with_checks(carry, dt, model, params):
    state, neighbors, failure, step = carry
    state, neighbors = kick_drift_kick(state, neighbors, dt, model, params)
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
    replayed once more (memory flat, one more forward pass).  Outside differentiation
    ``jax.checkpoint`` costs nothing.
    """

    def body(c, _):
        return step_fn(c), None

    if checkpoint_every is None or n_steps <= 1:
        return jax.lax.scan(jax.checkpoint(body), carry, None, length=n_steps)[0]
    # a step's replay keeps its neighbour indices (recorded by the chunk replay) rather
    # than repeating the cell-list search
    body = jax.checkpoint(body, policy=_KEEP_NEIGHBOR_IDX)
    chunk_len = min(checkpoint_every, n_steps)
    n_chunks, rest = divmod(n_steps, chunk_len)

    @jax.checkpoint
    def chunk(c, _):
        return jax.lax.scan(body, c, None, length=chunk_len)[0], None

    carry = jax.lax.scan(chunk, carry, None, length=n_chunks)[0]
    if rest:
        carry = jax.lax.scan(body, carry, None, length=rest)[0]
    return carry


def _run_frames(carry, dt, params, *, model, save_every, n_frames, checkpoint_every):
    """``n_frames`` frames of ``save_every`` steps from ``carry = (state, neighbors,
    failure, step)``; returns the last carry and the frames' States."""
    step_fn = functools.partial(_step_with_checks, dt=dt, model=model, params=params)

    def frame(carry, _):
        carry = _run_steps(carry, save_every, checkpoint_every, step_fn)
        return carry, carry[0]

    # No checkpoint around a frame: its chunks already store only their first carry, and
    # one more level would replay the whole frame once more in reverse mode.
    return jax.lax.scan(frame, carry, None, length=n_frames)


_run_chunk = jax.jit(
    _run_frames, static_argnames=("model", "save_every", "n_frames", "checkpoint_every")
)


# ---------------------------------------------------------------------------- simulate


def _is_traced(*trees) -> bool:
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(trees))


def _stack(frames: list[State]) -> State:
    return jax.tree_util.tree_map(lambda *xs: jnp.concatenate(xs, axis=0), *frames)


def _expand(state: State) -> State:
    return jax.tree_util.tree_map(lambda x: x[None], state)


def _raise_failure(failure, dt):
    step, particle = (int(x) for x in np.asarray(failure))
    if step >= 0:
        raise SimulationError(
            f"simulation went unstable at step {step} (t = {step * float(dt):.6g}): particle "
            f"{particle} has a non-finite position/velocity or left the domain",
            step=step,
            particle=particle,
            time=step * float(dt),
        )


def _raise_overflow(overflow):
    if bool(overflow):
        raise NeighborOverflowError(
            "the neighbour list overflowed inside a traced (jit/grad/vmap) simulation, where it "
            "cannot be re-allocated; raise Model.neighbor_capacity (e.g. "
            "case.replace(model=case.model.replace(neighbor_capacity=2.0)))"
        )


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
) -> Trajectory:
    """Run ``case`` and return its Trajectory (the initial frame first).

    Args:
      case: from ``sphjax.cases``.
      params: differentiable parameters (default ``case.params``).
      n_steps: number of steps; or give ``t_end`` (default ``case.t_end``).
      save_every: steps between saved frames (default: only the last frame);
        ``n_steps`` must be a multiple of it.
      dt: time step (default ``case.dt``); rejected above the stability limit.
      state: initial state (default ``case.state_for(params)``, i.e. ``case.state`` unless
        the parameters differ from ``case.params`` and the case derives its state from them).
      checkpoint_every: in reverse mode every step is rematerialised (only its input
        carry is stored, about ``N * (4 d + 6 + K)`` numbers); with ``checkpoint_every``
        the steps are also grouped in chunks of this many and only each chunk's first
        carry is stored, so memory does not grow with every step, for one more forward
        pass.  ``None``: store every step's carry (faster, memory linear in ``n_steps``).
      on_frames: ``f(states, times)`` called with each finished block of frames (concrete
        runs only); used to append to HDF5 as the run goes.
      progress: ``f(n)`` called with the number of steps just completed.
    Returns:
      :class:`Trajectory` with ``n_steps // save_every + 1`` frames.
    """
    params = case.params if params is None else params
    state = case.state_for(params) if state is None else state
    model = case.model
    dt = case.dt if dt is None else dt
    if n_steps is None:
        t_end = case.t_end if t_end is None else t_end
        if not t_end > 0:
            raise ValueError(f"t_end must be positive, got {t_end}")
        n_steps = max(1, int(math.ceil(t_end / float(dt) - 1e-9)))
    if not isinstance(n_steps, int | np.integer) or n_steps < 1:
        raise ValueError(f"n_steps must be a positive integer, got {n_steps!r}")
    n_steps = int(n_steps)
    save_every = n_steps if save_every is None else int(save_every)
    if save_every < 1 or n_steps % save_every:
        raise ValueError(f"save_every={save_every} must be a positive divisor of n_steps={n_steps}")
    if checkpoint_every is not None and int(checkpoint_every) < 1:
        raise ValueError(f"checkpoint_every must be a positive integer, got {checkpoint_every}")
    n_frames = n_steps // save_every
    traced = _is_traced(params, state, dt)
    if not traced:
        _check_finite(state)
        check_time_step(float(dt), state, model, params)
        _check_inside(state, model)
    dt = jnp.asarray(dt, state.position.dtype)

    neighbor_state = state if not _is_traced(state) else case.state
    # Allocation needs concrete values; inside an outer ``jit`` the jax-md set-up would
    # otherwise be staged out and fail on a traced box size.
    with jax.ensure_compile_time_eval():
        neighbors = build_neighbors(neighbor_state, model)
    if traced:
        run = functools.partial(_simulate_traced, checkpoint_every=checkpoint_every)
    else:
        run = functools.partial(
            _simulate_in_chunks,
            on_frames=on_frames,
            progress=progress,
            steps_per_chunk=steps_per_chunk,
        )
    states = run(state, neighbors, dt, params, model, save_every=save_every, n_frames=n_frames)
    times = jnp.arange(n_frames + 1) * (save_every * dt)
    return Trajectory(states=states, times=times)


def _initial_carry(state, neighbors):
    """``(state, neighbors, failure, step)``: no failure recorded (-1, -1), step 0."""
    return state, neighbors, -jnp.ones(2, jnp.int32), jnp.zeros((), jnp.int32)


def _simulate_traced(
    state, neighbors, dt, params, model, *, save_every, n_frames, checkpoint_every
):
    """One ``lax.scan`` (under grad/jit/vmap); overflow and instability are raised from
    inside the computation.  Returns the frames, the initial one first."""
    neighbors = _update_neighbors(state.position, neighbors, model, rebuild=True)
    state = evaluate(state, neighbors, model, params)
    carry, frames = _run_frames(
        _initial_carry(state, neighbors),
        dt,
        params,
        model=model,
        save_every=save_every,
        n_frames=n_frames,
        checkpoint_every=checkpoint_every,
    )
    jax.debug.callback(_raise_overflow, _overflowed(carry[1]))
    jax.debug.callback(_raise_failure, carry[2], dt)
    return _stack([_expand(state), frames])


def _simulate_in_chunks(
    state,
    neighbors,
    dt,
    params,
    model,
    *,
    save_every,
    n_frames,
    on_frames,
    progress,
    steps_per_chunk,
):
    """Compiled chunks of at most ``steps_per_chunk`` steps with concrete checks between
    them: a neighbour overflow re-allocates and repeats the chunk; an unstable run hands
    the frames before the failure to ``on_frames`` and raises.  Returns the frames."""
    state = jax.jit(evaluate, static_argnames="model")(state, neighbors, model, params)
    bad = ~np.all(np.isfinite(np.asarray(state.acceleration)), axis=-1)
    if bad.any():
        particle = int(np.argmax(bad))
        raise SimulationError(
            f"the initial state has a non-finite acceleration at particle {particle} "
            "(step 0); check the initial density, mass and spacing of the case",
            step=0,
            particle=particle,
            time=0.0,
        )
    all_frames = [_expand(state)]
    if on_frames is not None:
        on_frames(all_frames[0], jnp.zeros(1))
    frames_per_chunk = max(1, steps_per_chunk // save_every)
    carry = _initial_carry(state, neighbors)
    done = 0
    extra = 0  # neighbour slots added beyond the allocation's own estimate
    while done < n_frames:
        k = min(frames_per_chunk, n_frames - done)
        for _attempt in range(10):
            new_carry, frames = _run_chunk(
                carry,
                dt,
                params,
                model=model,
                save_every=save_every,
                n_frames=k,
                checkpoint_every=None,
            )
            if not bool(_overflowed(new_carry[1])):
                break
            state, neighbors, _, step = carry
            old = capacity(neighbors.fluid)
            # grow on every retry: the chunk's start positions may need less room than
            # the positions where it overflowed
            extra = max(extra + old // 2, 1)
            neighbors = build_neighbors(state, model, extra_capacity=extra)
            carry = (state, neighbors, *carry[2:])
            warnings.warn(
                f"neighbour list overflowed near step {int(step)}; re-allocated "
                f"{old} -> {capacity(neighbors.fluid)} slots and repeated the chunk",
                stacklevel=3,
            )
        else:
            raise NeighborOverflowError(
                "neighbour list kept overflowing; raise Model.neighbor_capacity"
            )
        carry = new_carry
        frame_times = (done + 1 + jnp.arange(k)) * (save_every * dt)
        fail_step = int(carry[2][0])
        if fail_step >= 0:
            good = max(0, (fail_step - 1) // save_every - done)
            kept = jax.tree_util.tree_map(operator.itemgetter(slice(good)), frames)
            if on_frames is not None and good:
                on_frames(kept, frame_times[:good])
            _raise_failure(carry[2], dt)
        if on_frames is not None:
            on_frames(frames, frame_times)
        all_frames.append(frames)
        done += k
        if progress is not None:
            progress(k * save_every)
    return _stack(all_frames)


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
