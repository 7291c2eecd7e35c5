"""One compiled, vmapped (and with several devices, sharded) simulation of a batch.

A batch of trajectories runs as ``jax.jit(jax.vmap(simulate-one))``, padded to a fixed
batch size so it compiles once; with more than one JAX device the batch is placed with
``NamedSharding(Mesh(devices, ("batch",)), P("batch"))``.  A neighbour-list overflow
inside the compiled batch raises ``Model.neighbor_capacity``
(:func:`sphjax.neighbors.capacity.grown_multiplier`) and repeats.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from sphjax.core.case import Case
from sphjax.core.params import Params
from sphjax.core.state import State
from sphjax.integration.simulate import simulate
from sphjax.neighbors import grown_multiplier, is_neighbor_overflow


class Runner:
    """One compiled, vmapped, sharded simulation of a batch of (state, params)."""

    def __init__(self, case: Case, dt: float, steps: int, write_every: int, devices=None):
        self.devices = list(jax.devices() if devices is None else devices)
        self.case, self.dt, self.steps, self.write_every = case, dt, steps, write_every
        self._compile()

    def _compile(self):
        case, dt, steps, every = self.case, self.dt, self.steps, self.write_every

        def one(state, params):
            # simulate allocates its neighbour list from the concrete case.state; evaluate
            # that eagerly while the traced (state, params) computation is staged
            with jax.ensure_compile_time_eval():
                traj = simulate(case, params, n_steps=steps, save_every=every, dt=dt, state=state)
            return traj.states.position

        self._fn = jax.jit(jax.vmap(one))
        if len(self.devices) > 1:
            mesh = jax.sharding.Mesh(np.array(self.devices), ("batch",))
            self._sharding = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("batch"))
        else:
            self._sharding = None

    def __call__(self, states: list[State], params: list[Params], size: int) -> np.ndarray:
        """Positions ``[B, T, N, d]``; the batch is padded to ``size`` (one compilation)."""
        n = len(states)
        pad = max(size, n) - n
        states = states + [states[-1]] * pad
        params = params + [params[-1]] * pad
        batch_states = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *states)
        batch_params = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *params)
        if self._sharding is not None:
            batch_states = jax.device_put(batch_states, self._sharding)
            batch_params = jax.device_put(batch_params, self._sharding)
        for _attempt in range(5):
            try:
                out = self._fn(batch_states, batch_params)
                out = np.asarray(jax.block_until_ready(out))
                break
            except Exception as error:  # raised from a callback inside the compiled run
                if not is_neighbor_overflow(error):
                    raise
                model = self.case.model
                self.case = self.case.replace(
                    model=model.replace(neighbor_capacity=grown_multiplier(model.neighbor_capacity))
                )
                self._compile()
        else:
            raise RuntimeError("neighbour list kept overflowing; raise Model.neighbor_capacity")
        return out[:n]


_RUNNERS: dict = {}


def cached_runner(case: Case, dt, steps, write_every, devices) -> Runner:
    """A cached runner: the same set-up and run length compile once per process."""
    x = np.asarray(case.state.position)
    key = (case.model, x.shape, x.tobytes(), float(dt), steps, write_every, tuple(devices))
    if key not in _RUNNERS:
        _RUNNERS.clear()  # keep one: a runner holds a compiled simulation
        _RUNNERS[key] = Runner(case, dt, steps, write_every, devices)
    return _RUNNERS[key]
