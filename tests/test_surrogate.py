"""The learned surrogate: loader, windows, GNS training and rollouts (sphjax.surrogate)."""

from __future__ import annotations

import json

import h5py
import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest
from _tiny_dataset import KWARGS, shared

from sphjax.surrogate import LearnedSimulator, SimulatorConfig, data, rollout_metrics
from sphjax.surrogate.train import make_train_step, train

HISTORY = 3
SMALL = SimulatorConfig(history=HISTORY, latent=16, hidden=16, message_steps=2)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return shared(tmp_path_factory)


def test_loader_and_windows(dataset):
    train_set = data.load(dataset, "train")
    frames = KWARGS["steps"] // KWARGS["write_every"] + 1
    assert train_set.positions.shape == (3, frames, 64, 2)
    assert train_set.particle_type.shape == (3, 64)
    index = data.window_index(train_set, HISTORY)
    assert len(index) == 3 * (frames - HISTORY - 1)
    x, y, t = data.windows(train_set, index[[0, -1]], HISTORY)
    assert x.shape == (2, HISTORY + 1, 64, 2) and y.shape == (2, 64, 2) and t.shape == (2, 64)
    k, s = index[-1]
    np.testing.assert_array_equal(x[1], train_set.positions[k, s : s + HISTORY + 1])
    np.testing.assert_array_equal(y[1], train_set.positions[k, s + HISTORY + 1])
    # finite differences use the minimum image: no jumps across the periodic box
    v = data.frame_velocities(train_set.positions, train_set.bounds, train_set.periodic)
    assert np.abs(v).max() < 0.1


def test_loader_reads_lagrangebench_layout_with_padding(tmp_path):
    meta = dict(
        dim=2,
        dt=0.001,
        write_every=10,
        bounds=[[0.0, 1.0], [0.0, 2.0]],
        periodic_boundary_conditions=[False, False],
        default_connectivity_radius=0.1,
        vel_mean=[0, 0],
        vel_std=[1e-3, 1e-3],
        acc_mean=[0, 0],
        acc_std=[1e-4, 1e-4],
    )
    (tmp_path / "metadata.json").write_text(json.dumps(meta))
    rng = np.random.default_rng(0)
    with h5py.File(tmp_path / "valid.h5", "w") as f:
        for name, n in [("00000", 5), ("00001", 7)]:
            g = f.create_group(name)
            g["position"] = rng.uniform(0.2, 0.8, (6, n, 2)).astype(np.float32)
            g["particle_type"] = np.r_[np.zeros(n - 2), np.ones(2)].astype(np.int64)
    ds = data.load(tmp_path, "valid")
    assert ds.positions.shape == (2, 6, 7, 2) and ds.frame_dt == pytest.approx(0.01)
    assert list(ds.particle_type[0]) == [0, 0, 0, 1, 1, -1, -1]


def test_a_few_training_steps_lower_the_loss(dataset):
    train_set = data.load(dataset, "train")
    sim = LearnedSimulator(train_set.metadata, SMALL)
    model = sim.init_model(jax.random.PRNGKey(0))
    step = make_train_step(sim, optax.adam(3e-3))
    opt_state = optax.adam(3e-3).init(model)
    x, y, t = data.windows(train_set, data.window_index(train_set, HISTORY)[:2], HISTORY)
    neighbors = sim.allocate(x[0, -1])
    key = jax.random.PRNGKey(1)
    losses = []
    for _ in range(25):
        model, opt_state, loss, over = step(model, opt_state, x, y, t, key, neighbors)
        assert not bool(over)
        losses.append(float(loss))
    assert np.isfinite(losses).all()
    assert np.mean(losses[-3:]) < 0.5 * losses[0]


def test_trained_rollout_shapes_finite_and_sensible(dataset, tmp_path):
    train_set, test_set = data.load(dataset, "train"), data.load(dataset, "test")
    sim = LearnedSimulator(train_set.metadata, SMALL)
    result = train(
        sim,
        sim.init_model(jax.random.PRNGKey(0)),
        train_set,
        n_steps=40,
        batch_size=2,
        lr=3e-3,
        log=lambda s: None,
    )
    assert result.steps == 40 and np.isfinite(result.losses).all()
    model = result.model
    x0 = jnp.asarray(test_set.positions[0, : HISTORY + 1])
    types = jnp.asarray(test_set.particle_type[0])
    n_steps = test_set.positions.shape[1] - HISTORY - 1
    frames, over = sim.rollout(model, x0, types, n_steps, sim.allocate(x0[-1]))
    assert frames.shape == (n_steps, 64, 2) and not bool(over)
    assert bool(jnp.all(jnp.isfinite(frames)))
    assert bool(jnp.all((frames >= 0) & (frames < 1)))
    truth = test_set.positions[0, HISTORY + 1 :]
    err = np.mean(
        np.sum(
            data.displacement(np.asarray(frames), truth, test_set.bounds, test_set.periodic) ** 2,
            -1,
        )
    )
    frozen = np.mean(
        np.sum(
            data.displacement(np.asarray(x0[-1])[None], truth, test_set.bounds, test_set.periodic)
            ** 2,
            -1,
        )
    )
    assert err < 0.25 * frozen  # far better than particles standing still
    metrics = rollout_metrics(sim, model, test_set, n_steps=4, stride=2)
    baseline = rollout_metrics(sim, None, test_set, n_steps=4, stride=2)
    for m in (metrics, baseline):
        assert {"mse_sumdim_at_1", "mse_sumdim_mean", "ke_mse_specific"} <= set(m)
        assert {"lb_ekin_mse", "lb_sinkhorn", "lb_mse_curve"} <= set(m)
        assert all(np.isfinite(v) for v in m["mse_sumdim_curve"])
        # all-fluid data: LagrangeBench's per-step MSE is ours / dim (mean, not sum, over axes)
        np.testing.assert_allclose(
            m["lb_mse_curve"], np.asarray(m["mse_sumdim_curve"]) / 2, rtol=1e-5
        )
        assert m["n_rollouts"] == len(test_set) and m["lb_sinkhorn"] >= 0
    # saved weights give the same rollout
    sim.save(model, tmp_path / "gns.eqx")
    with pytest.raises(FileExistsError, match=r"^path: '.*gns\.eqx' exists; pass overwrite=True"):
        sim.save(model, tmp_path / "gns.eqx")  # one overwrite rule, as every writer
    sim.save(model, tmp_path / "gns.eqx", overwrite=True)
    sim2, model2 = LearnedSimulator.load(tmp_path / "gns.eqx")
    frames2, _ = sim2.rollout(model2, x0, types, n_steps, sim2.allocate(x0[-1]))
    np.testing.assert_allclose(np.asarray(frames2), np.asarray(frames), atol=1e-6)


def test_push_forward_training_steps_lower_the_loss(dataset):
    """Two-step push-forward: the model first rolls out two steps by itself (no gradient);
    a few Adam steps lower the loss of the third (one compilation, ~20 s)."""
    train_set = data.load(dataset, "train")
    sim = LearnedSimulator(train_set.metadata, SMALL)
    model = sim.init_model(jax.random.PRNGKey(0))
    optimizer = optax.adam(3e-3)
    step = make_train_step(sim, optimizer, unroll=2)
    opt_state = optimizer.init(model)
    index = data.window_index(train_set, HISTORY, horizon=3)
    x, y, t = data.windows(train_set, index[:2], HISTORY, unroll=2)
    assert x.shape == (2, HISTORY + 3, 64, 2)
    np.testing.assert_array_equal(y[0], train_set.positions[index[0, 0], index[0, 1] + HISTORY + 3])
    neighbors = sim.allocate(x[0, -1])
    key = jax.random.PRNGKey(1)
    losses = []
    for _ in range(25):
        model, opt_state, loss, over = step(model, opt_state, x, y, t, key, neighbors)
        assert not bool(over)
        losses.append(float(loss))
    assert np.isfinite(losses).all()
    assert np.mean(losses[-3:]) < 0.5 * losses[0]


def test_train_draws_push_forward_lengths_and_checks_them(dataset):
    train_set = data.load(dataset, "train")
    sim = LearnedSimulator(train_set.metadata, SMALL)
    model = sim.init_model(jax.random.PRNGKey(0))
    with pytest.raises(ValueError, match="pushforward_weights"):
        train(sim, model, train_set, n_steps=1, pushforward=(0, 1), pushforward_weights=(1,))
    with pytest.raises(ValueError, match="pushforward must"):
        train(sim, model, train_set, n_steps=1, pushforward=(-1,))
