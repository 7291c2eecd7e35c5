"""Learned surrogates: a graph network simulator trained on SPH datasets.

    from sphjax.surrogate import data, LearnedSimulator, train, rollout_metrics
    train_set = data.load("datasets/tg", "train")
    sim = LearnedSimulator(train_set.metadata)
    model = sim.init_model(jax.random.PRNGKey(0))
    result = train(sim, model, train_set, n_steps=1000)

Modules: :mod:`~sphjax.surrogate.data` (dataset folders and training windows),
:mod:`~sphjax.surrogate.graph` (radius graphs), :mod:`~sphjax.surrogate.gns` (the
network), :mod:`~sphjax.surrogate.simulator` (features, rollouts, loss, metrics),
:mod:`~sphjax.surrogate.train` (the optax training loop).
"""

from sphjax.surrogate import data
from sphjax.surrogate.gns import GNS
from sphjax.surrogate.simulator import (
    LearnedSimulator,
    SimulatorConfig,
    kinetic_energy,
    rollout_metrics,
)
from sphjax.surrogate.train import TrainResult, train

__all__ = [
    "GNS",
    "LearnedSimulator",
    "SimulatorConfig",
    "TrainResult",
    "data",
    "kinetic_energy",
    "rollout_metrics",
    "train",
]
