"""sphjax: differentiable Smoothed Particle Hydrodynamics in JAX.

Weakly compressible fluids and total-Lagrangian elastic solids as pure functions, so that
``jax.jit``, ``jax.vmap`` and ``jax.grad`` pass through whole simulations.

    import sphjax
    case = sphjax.cases.taylor_green(n=50)
    traj = sphjax.simulate(case, n_steps=1000, save_every=100)

Layers, each importing only those below it: ``sphjax.core`` (State, Params, Model,
kernels, space, neighbour search), ``sphjax.physics`` (systems, per-pair terms,
interactions, the right-hand side), ``sphjax.integration`` (the kick-drift-kick step, the
``lax.scan`` driver, diffrax), ``sphjax.cases`` and ``sphjax.observables``, ``sphjax.io``,
and the applications (command line, calibration, datasets, surrogates).
"""

# ruff: noqa: E402  (XLA flags must be set before the other imports)
from sphjax._xla import apply_default_flags

apply_default_flags()  # before any JAX backend exists; see sphjax/_xla.py

from sphjax import cases, io
from sphjax.calibrate import CalibrationResult, calibrate
from sphjax.core import kernels
from sphjax.core.case import Case
from sphjax.core.model import Domain, Model
from sphjax.core.params import FluidParams, Params, SolidParams, make_params
from sphjax.core.state import Kind, State, Trajectory, make_state
from sphjax.integration._kdk import KickDriftKick
from sphjax.integration.diffrax import diffeqsolve_case
from sphjax.integration.simulate import (
    NeighborOverflowError,
    SimulationError,
    kick_drift_kick,
    simulate,
)
from sphjax.integration.timestep import stable_time_step
from sphjax.io import TrajectoryWriter, read_trajectory
from sphjax.physics.boundary.system import WallSystem
from sphjax.physics.boundary.wall import AdamiBoundary
from sphjax.physics.fluid.density import ContinuityDensity, SummationDensity
from sphjax.physics.fluid.density_diffusion import MolteniColagrossi
from sphjax.physics.fluid.eos import LinearEOS, TaitEOS
from sphjax.physics.fluid.momentum import TransportVelocity
from sphjax.physics.fluid.system import FluidSystem
from sphjax.physics.fluid.viscosity import ArtificialViscosity, MorrisViscosity
from sphjax.physics.rhs import Neighbors, build_neighbors, evaluate
from sphjax.physics.solid.material import StVenantKirchhoff
from sphjax.physics.solid.penalty import PenaltyForce
from sphjax.physics.solid.system import SolidSystem

__version__ = "0.2.0"

__all__ = [
    "AdamiBoundary",
    "ArtificialViscosity",
    "CalibrationResult",
    "Case",
    "ContinuityDensity",
    "Domain",
    "FluidParams",
    "FluidSystem",
    "KickDriftKick",
    "Kind",
    "LinearEOS",
    "Model",
    "MolteniColagrossi",
    "MorrisViscosity",
    "NeighborOverflowError",
    "Neighbors",
    "Params",
    "PenaltyForce",
    "SimulationError",
    "SolidParams",
    "SolidSystem",
    "State",
    "StVenantKirchhoff",
    "SummationDensity",
    "TaitEOS",
    "Trajectory",
    "TrajectoryWriter",
    "TransportVelocity",
    "WallSystem",
    "__version__",
    "build_neighbors",
    "calibrate",
    "cases",
    "diffeqsolve_case",
    "evaluate",
    "io",
    "kernels",
    "kick_drift_kick",
    "make_params",
    "make_state",
    "read_trajectory",
    "simulate",
    "stable_time_step",
]
