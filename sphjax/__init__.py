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

# The public names are imported on first use (PEP 562), so ``import sphjax`` and the
# ``sphjax`` command's --help do not pay for importing JAX.
_NAMES = {
    "KickDriftKick": "sphjax._solver",
    "CalibrationResult": "sphjax.calibrate",
    "calibrate": "sphjax.calibrate",
    "Case": "sphjax.case",
    "diffeqsolve_case": "sphjax.diffrax_solver",
    "NeighborOverflowError": "sphjax.integrate",
    "SimulationError": "sphjax.integrate",
    "Trajectory": "sphjax.integrate",
    "kick_drift_kick": "sphjax.integrate",
    "simulate": "sphjax.integrate",
    "TrajectoryWriter": "sphjax.io",
    "read_trajectory": "sphjax.io",
    "Neighbors": "sphjax.rhs",
    "evaluate": "sphjax.rhs",
    "Domain": "sphjax.state",
    "Kind": "sphjax.state",
    "Model": "sphjax.state",
    "Params": "sphjax.state",
    "State": "sphjax.state",
    "make_params": "sphjax.state",
    "make_state": "sphjax.state",
    "stable_time_step": "sphjax.timestep",
}


def __getattr__(name):
    import importlib

    if name.startswith("__"):
        raise AttributeError(f"module 'sphjax' has no attribute {name!r}")
    if name in _NAMES:
        value = getattr(importlib.import_module(_NAMES[name]), name)
        globals()[name] = value
        return value
    try:  # a submodule, e.g. sphjax.cases or sphjax.integrate
        return importlib.import_module(f"sphjax.{name}")
    except ModuleNotFoundError as err:
        if err.name != f"sphjax.{name}":
            raise
    raise AttributeError(f"module 'sphjax' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))


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
