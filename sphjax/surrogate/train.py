"""Training loop for the learned simulator: optax, a time or step budget, best-on-valid.

Any optax optimiser can be passed; the default is Adam whose learning rate decays
exponentially from ``lr`` to ``lr_final`` over the budget (steps or wall-clock seconds;
the rate is injected each step with ``optax.inject_hyperparams``).
"""

from __future__ import annotations

import dataclasses
import time

import jax
import jax.numpy as jnp
import numpy as np
import optax

from sphjax.surrogate.data import Trajectories, window_index, windows
from sphjax.surrogate.simulator import LearnedSimulator, rollout_metrics


@dataclasses.dataclass
class TrainResult:
    """Trained model (best on validation if validated), loss history and timings."""

    model: object
    losses: list
    valid: list
    seconds: float
    steps: int


def make_train_step(sim: LearnedSimulator, optimizer):
    """Jitted ``(model, opt_state, positions, target, types, key, neighbors) ->
    (model, opt_state, loss, overflow)``."""

    def loss_fn(model, positions, target, types, key, neighbors):
        return sim.loss(model, positions, target, types, key, neighbors)

    @jax.jit
    def step(model, opt_state, positions, target, types, key, neighbors):
        (loss, over), grads = jax.value_and_grad(loss_fn, has_aux=True)(
            model, positions, target, types, key, neighbors
        )
        updates, opt_state = optimizer.update(grads, opt_state, model)
        return optax.apply_updates(model, updates), opt_state, loss, over

    return step


def train(
    sim: LearnedSimulator,
    model,
    train_data: Trajectories,
    valid_data: Trajectories | None = None,
    *,
    n_steps: int | None = None,
    seconds: float | None = None,
    batch_size: int = 2,
    lr: float = 1e-3,
    lr_final: float = 1e-5,
    optimizer=None,
    seed: int = 0,
    eval_every: int = 200,
    eval_rollout: int = 20,
    log=print,
) -> TrainResult:
    """Train ``model`` on windows of ``train_data`` for ``n_steps`` or ``seconds``.

    With ``valid_data``, every ``eval_every`` steps the mean rollout MSE over
    ``eval_rollout`` steps is measured and the best model kept.  ``seconds`` is wall-clock
    time after the first (compiling) step, validation included.
    """
    if n_steps is None and seconds is None:
        raise ValueError("give n_steps or seconds (the training budget)")
    h = sim.config.history
    index = window_index(train_data, h)
    rng = np.random.default_rng(seed)
    key = jax.random.PRNGKey(seed)
    if optimizer is None:
        optimizer = optax.inject_hyperparams(optax.adam)(learning_rate=lr)
    schedule = hasattr(optimizer.init(model), "hyperparams")
    opt_state = optimizer.init(model)
    step_fn = make_train_step(sim, optimizer)
    neighbors = sim.allocate(train_data.positions[0, h])
    losses, valid = [], []
    best, best_model = np.inf, model
    start = time.perf_counter()
    k = 0
    while True:
        elapsed = time.perf_counter() - start
        frac = k / n_steps if n_steps is not None else elapsed / seconds
        if seconds is not None and n_steps is not None:
            frac = max(k / n_steps, elapsed / seconds)
        if frac >= 1.0:
            break
        if schedule:
            opt_state.hyperparams["learning_rate"] = jnp.asarray(lr * (lr_final / lr) ** frac)
        batch = index[rng.integers(0, len(index), batch_size)]
        x, y, t = windows(train_data, batch, h)
        key, sub = jax.random.split(key)
        new_model, new_state, loss, over = step_fn(model, opt_state, x, y, t, sub, neighbors)
        if bool(over):  # re-allocate with more room and repeat the step
            neighbors = sim.allocate(x[0, -1], 2 + neighbors.idx.shape[-1] // 4)
            log(f"neighbour list overflow: capacity -> {neighbors.idx.shape[-1]}")
            continue
        model, opt_state = new_model, new_state
        losses.append(float(loss))
        k += 1
        if k == 1:  # the budget starts after the first step has compiled
            start = time.perf_counter()
        if valid_data is not None and k % eval_every == 0:
            m = rollout_metrics(sim, model, valid_data, n_steps=eval_rollout)
            valid.append((k, m["mse_mean"]))
            if m["mse_mean"] < best:
                best, best_model = m["mse_mean"], model
            log(
                f"step {k:6d}  t={time.perf_counter() - start:7.1f}s  "
                f"loss {np.mean(losses[-eval_every:]):.4f}  valid rollout mse {m['mse_mean']:.3e}"
            )
        elif k % 50 == 0:
            log(
                f"step {k:6d}  t={time.perf_counter() - start:7.1f}s  "
                f"loss {np.mean(losses[-50:]):.4f}"
            )
    if valid_data is not None:
        m = rollout_metrics(sim, model, valid_data, n_steps=eval_rollout)
        valid.append((k, m["mse_mean"]))
        if m["mse_mean"] < best:
            best_model = model
    else:
        best_model = model
    return TrainResult(best_model, losses, valid, time.perf_counter() - start, k)
