"""Training loop for the learned simulator: optax, a time or step budget, best-on-valid.

Any optax optimiser can be passed; the default is Adam whose learning rate decays
exponentially from ``lr`` to ``lr_final`` over the budget (steps or wall-clock seconds;
the rate is injected each step with ``optax.inject_hyperparams``).

Multi-step (push-forward) training: ``pushforward=(0, 1, 3)`` with weights
``pushforward_weights=(6, 2, 1)`` draws, per training step, how many steps ``u`` the model
first rolls out by itself (without gradient) before the step that is scored
(:meth:`LearnedSimulator.loss`); each ``u`` compiles its own training step once.
"""

from __future__ import annotations

import dataclasses
import time

import jax
import jax.numpy as jnp
import numpy as np
import optax

from sphjax.surrogate.data import Trajectories, window_index, windows
from sphjax.surrogate.metrics import rollout_metrics
from sphjax.surrogate.simulator import LearnedSimulator


@dataclasses.dataclass
class TrainResult:
    """Trained model (best on validation if validated), loss history and timings."""

    model: object
    losses: list
    valid: list
    seconds: float
    steps: int


def make_train_step(sim: LearnedSimulator, optimizer, unroll: int = 0):
    """Jitted ``(model, opt_state, positions, target, types, key, neighbors) ->
    (model, opt_state, loss, overflow)``; ``unroll`` push-forward steps."""

    def loss_fn(model, positions, target, types, key, neighbors):
        return sim.loss(model, positions, target, types, key, neighbors, unroll=unroll)

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
    pushforward=(0,),
    pushforward_weights=None,
    log=print,
) -> TrainResult:
    """Train ``model`` on windows of ``train_data`` for ``n_steps`` or ``seconds``.

    With ``valid_data``, every ``eval_every`` steps LagrangeBench's rollout MSE averaged
    over ``eval_rollout`` steps is measured and the best model kept.  ``seconds`` is
    wall-clock time after the first (compiling) step, validation included.
    ``pushforward``: the push-forward unroll lengths to draw from (``(0,)``: one-step
    training), with ``pushforward_weights`` (default equal).
    """
    if n_steps is None and seconds is None:
        raise ValueError("give n_steps or seconds (the training budget)")
    h = sim.config.history
    unrolls = [int(u) for u in pushforward]
    if not unrolls or min(unrolls) < 0:
        raise ValueError(f"pushforward must list unroll lengths >= 0, got {pushforward!r}")
    weights = (
        np.ones(len(unrolls))
        if pushforward_weights is None
        else np.asarray(pushforward_weights, np.float64)
    )
    if weights.shape != (len(unrolls),) or np.any(weights < 0) or weights.sum() <= 0:
        raise ValueError(
            f"pushforward_weights must give one weight >= 0 per unroll length {unrolls}, "
            f"got {pushforward_weights!r}"
        )
    weights = weights / weights.sum()
    index = window_index(train_data, h, horizon=max(unrolls) + 1)
    rng = np.random.default_rng(seed)
    key = jax.random.PRNGKey(seed)
    if optimizer is None:
        optimizer = optax.inject_hyperparams(optax.adam)(learning_rate=lr)
    schedule = hasattr(optimizer.init(model), "hyperparams")
    opt_state = optimizer.init(model)
    step_fns = {u: make_train_step(sim, optimizer, u) for u in unrolls}
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
        unroll = unrolls[rng.choice(len(unrolls), p=weights)] if len(unrolls) > 1 else unrolls[0]
        x, y, t = windows(train_data, batch, h, unroll)
        key, sub = jax.random.split(key)
        step_fn = step_fns[unroll]
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
            score = _valid_score(sim, model, valid_data, eval_rollout)
            valid.append((k, score))
            if score < best:
                best, best_model = score, model
            log(
                f"step {k:6d}  t={time.perf_counter() - start:7.1f}s  "
                f"loss {np.mean(losses[-eval_every:]):.4f}  valid rollout MSE{eval_rollout} "
                f"{score:.3e}"
            )
        elif k % 50 == 0:
            log(
                f"step {k:6d}  t={time.perf_counter() - start:7.1f}s  "
                f"loss {np.mean(losses[-50:]):.4f}"
            )
    if valid_data is not None:
        score = _valid_score(sim, model, valid_data, eval_rollout)
        valid.append((k, score))
        if score < best:
            best_model = model
    else:
        best_model = model
    return TrainResult(best_model, losses, valid, time.perf_counter() - start, k)


def _valid_score(sim, model, valid_data, n_steps: int) -> float:
    """LagrangeBench's MSE averaged over the first ``n_steps`` rollout steps."""
    m = rollout_metrics(sim, model, valid_data, n_steps=n_steps, sinkhorn=False)
    return float(np.mean(m["lb_mse_curve"]))
