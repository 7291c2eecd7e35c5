"""sphjax: differentiable Smoothed Particle Hydrodynamics in JAX.

Weakly compressible fluids and total-Lagrangian elastic solids as pure functions, so that
``jax.jit``, ``jax.vmap`` and ``jax.grad`` pass through whole simulations.

    import sphjax
    case = sphjax.cases.taylor_green(n=50)
    traj = sphjax.simulate(case, n_steps=1000, save_every=100)
"""

# ruff: noqa: E402  (XLA flags must be set before the other imports)
from sphjax._xla import apply_default_flags

apply_default_flags()  # before any JAX backend exists; see sphjax/_xla.py

from sphjax import cases, io, kernels
from sphjax._solver import KickDriftKick
from sphjax.calibrate import CalibrationResult, calibrate
from sphjax.case import Case
from sphjax.diffrax_solver import diffeqsolve_case
from sphjax.integrate import (
    NeighborOverflowError,
    SimulationError,
    Trajectory,
    kick_drift_kick,
    simulate,
)
from sphjax.io import TrajectoryWriter, read_trajectory
from sphjax.rhs import Neighbors, evaluate
from sphjax.state import Domain, Kind, Model, Params, State, make_params, make_state
from sphjax.timestep import stable_time_step

__version__ = "0.1.0"

__all__ = [
    "CalibrationResult",
    "KickDriftKick",
    "calibrate",
    "diffeqsolve_case",
    "Case",
    "Domain",
    "Kind",
    "Model",
    "NeighborOverflowError",
    "Neighbors",
    "Params",
    "SimulationError",
    "State",
    "Trajectory",
    "TrajectoryWriter",
    "cases",
    "evaluate",
    "io",
    "kernels",
    "kick_drift_kick",
    "make_params",
    "make_state",
    "read_trajectory",
    "simulate",
    "stable_time_step",
    "__version__",
]
