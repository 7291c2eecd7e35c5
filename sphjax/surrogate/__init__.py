"""Learned surrogates: a graph network simulator trained on SPH datasets.

    from sphjax.surrogate import data, LearnedSimulator, train, rollout_metrics
    train_set = data.load("datasets/tg", "train")
    sim = LearnedSimulator(train_set.metadata)
    model = sim.init_model(jax.random.PRNGKey(0))
    result = train(sim, model, train_set, n_steps=1000)

Modules: :mod:`~sphjax.surrogate.data` (dataset folders and training windows),
:mod:`~sphjax.surrogate.graph` (radius graphs through :class:`sphjax.neighbors.NeighborSearch`),
:mod:`~sphjax.surrogate.gns` (the network), :mod:`~sphjax.surrogate.simulator` (features,
rollouts, loss), :mod:`~sphjax.surrogate.metrics` (LagrangeBench's metrics beside ours),
:mod:`~sphjax.surrogate.train` (the optax training loop, one-step or push-forward),
:mod:`~sphjax.surrogate.solver_in_the_loop` (a learned correction of a coarse sphjax
simulation, trained through the differentiable solver).
"""

from sphjax.surrogate import data, metrics
from sphjax.surrogate.gns import GNS
from sphjax.surrogate.metrics import kinetic_energy, rollout_metrics
from sphjax.surrogate.simulator import LearnedSimulator, SimulatorConfig
from sphjax.surrogate.train import TrainResult, train

__all__ = [
    "GNS",
    "LearnedSimulator",
    "SimulatorConfig",
    "TrainResult",
    "data",
    "kinetic_energy",
    "metrics",
    "rollout_metrics",
    "train",
]
