"""sphjax: differentiable Smoothed Particle Hydrodynamics in JAX.

Weakly compressible fluids and total-Lagrangian elastic solids as pure functions, so that
``jax.jit``, ``jax.vmap`` and ``jax.grad`` pass through whole simulations.

    import sphjax
    case = sphjax.cases.taylor_green(n=50)
    traj = sphjax.simulate(case, n_steps=1000, save_every=100)

Layers, each importing only those below it: ``sphjax.core`` (State, Params, Model,
kernels, space, neighbour search), ``sphjax.physics`` (systems, per-pair terms,
interactions, the right-hand side), ``sphjax.integration`` (the kick-drift-kick step, the
``lax.scan`` driver, diffrax), ``sphjax.cases``, ``sphjax.io``, and the applications
(command line, calibration, datasets, surrogates).  See docs/architecture.md.
"""

# ruff: noqa: E402  (XLA flags must be set before the other imports)
from sphjax._xla import apply_default_flags

apply_default_flags()  # before any JAX backend exists; see sphjax/_xla.py

# The public names are imported on first use (PEP 562), so ``import sphjax`` and the
# ``sphjax`` command's --help do not pay for importing JAX.
_NAMES = {
    "CalibrationResult": "sphjax.calibration",
    "calibrate": "sphjax.calibration",
    "Case": "sphjax.core.case",
    "Domain": "sphjax.core.model",
    "Model": "sphjax.core.model",
    "FluidParams": "sphjax.core.params",
    "Params": "sphjax.core.params",
    "SolidParams": "sphjax.core.params",
    "UnusedParameterError": "sphjax.core.params",
    "make_params": "sphjax.core.params",
    "Kind": "sphjax.core.state",
    "State": "sphjax.core.state",
    "Trajectory": "sphjax.core.state",
    "make_state": "sphjax.core.state",
    "KickDriftKick": "sphjax.integration._kdk",
    "diffeqsolve_case": "sphjax.integration.diffrax",
    "NeighborOverflowError": "sphjax.neighbors",
    "SimulationError": "sphjax.integration.simulate",
    "kick_drift_kick": "sphjax.integration.simulate",
    "simulate": "sphjax.integration.simulate",
    "stable_time_step": "sphjax.integration.timestep",
    "TrajectoryWriter": "sphjax.io",
    "read_trajectory": "sphjax.io",
    "WallSystem": "sphjax.physics.boundary.system",
    "AdamiBoundary": "sphjax.physics.boundary.wall",
    "ContinuityDensity": "sphjax.physics.fluid.density",
    "SummationDensity": "sphjax.physics.fluid.density",
    "MolteniColagrossi": "sphjax.physics.fluid.density_diffusion",
    "Antuono": "sphjax.physics.fluid.density_diffusion",
    "LinearEOS": "sphjax.physics.fluid.eos",
    "TaitEOS": "sphjax.physics.fluid.eos",
    "TransportVelocity": "sphjax.physics.fluid.momentum",
    "FluidSystem": "sphjax.physics.fluid.system",
    "ArtificialViscosity": "sphjax.physics.fluid.viscosity",
    "MorrisViscosity": "sphjax.physics.fluid.viscosity",
    "Neighbors": "sphjax.neighbors",
    "build_neighbors": "sphjax.physics.rhs",
    "evaluate": "sphjax.physics.rhs",
    "StVenantKirchhoff": "sphjax.physics.solid.material",
    "PenaltyForce": "sphjax.physics.solid.penalty",
    "SolidSystem": "sphjax.physics.solid.system",
    "SolidBoundary": "sphjax.physics.solid.boundary",
    "RigidSystem": "sphjax.physics.rigid.system",
    "WallContact": "sphjax.physics.rigid.contact",
    "OpenBoundarySystem": "sphjax.physics.open_boundary",
    "Inflow": "sphjax.physics.open_boundary",
    "Outflow": "sphjax.physics.open_boundary",
}
_MODULES = {"kernels": "sphjax.core.kernels"}


def __getattr__(name):
    import importlib

    if name.startswith("__"):
        raise AttributeError(f"module 'sphjax' has no attribute {name!r}")
    if name in _NAMES:
        value = getattr(importlib.import_module(_NAMES[name]), name)
        globals()[name] = value
        return value
    try:  # a submodule, e.g. sphjax.cases or sphjax.io
        return importlib.import_module(_MODULES.get(name, f"sphjax.{name}"))
    except ModuleNotFoundError as err:
        if err.name != _MODULES.get(name, f"sphjax.{name}"):
            raise
    raise AttributeError(f"module 'sphjax' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))


__version__ = "0.2.0"

__all__ = [
    "__version__",
    "AdamiBoundary",
    "ArtificialViscosity",
    "build_neighbors",
    "calibrate",
    "CalibrationResult",
    "Case",
    "cases",
    "ContinuityDensity",
    "diffeqsolve_case",
    "Domain",
    "evaluate",
    "FluidParams",
    "FluidSystem",
    "io",
    "kernels",
    "kick_drift_kick",
    "KickDriftKick",
    "Kind",
    "LinearEOS",
    "make_params",
    "make_state",
    "Model",
    "MolteniColagrossi",
    "Antuono",
    "MorrisViscosity",
    "NeighborOverflowError",
    "Inflow",
    "OpenBoundarySystem",
    "Outflow",
    "Neighbors",
    "Params",
    "PenaltyForce",
    "read_trajectory",
    "RigidSystem",
    "simulate",
    "SimulationError",
    "SolidParams",
    "SolidSystem",
    "SolidBoundary",
    "stable_time_step",
    "State",
    "StVenantKirchhoff",
    "SummationDensity",
    "TaitEOS",
    "Trajectory",
    "TrajectoryWriter",
    "TransportVelocity",
    "UnusedParameterError",
    "WallContact",
    "WallSystem",
]
