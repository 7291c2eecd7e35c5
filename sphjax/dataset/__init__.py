"""Ensembles of SPH trajectories in the LagrangeBench dataset layout.

    from sphjax.dataset import Perturbation, generate_dataset
    generate_dataset(sphjax.cases.taylor_green(n=32), "tg32", n_train=32, n_valid=4,
                     n_test=4, steps=150, write_every=5, case_kwargs={"n": 32})

Modules: :mod:`~sphjax.dataset.perturb` (per-trajectory initial conditions from
``seed``), :mod:`~sphjax.dataset.runner` (batches as one compiled, vmapped, sharded
simulation), :mod:`~sphjax.dataset.format` (particle types, statistics, metadata and
its checks), :mod:`~sphjax.dataset.generate` (the resumable generation); the ``sphjax dataset``
command is in :mod:`sphjax.cli`.
"""

from sphjax.dataset.format import (
    BODY,
    FLUID,
    FORMAT_VERSION,
    MOVING_WALL,
    PAD,
    WALL,
    check_metadata,
    check_same_geometry,
    frame_differences,
    frame_time,
    metadata,
    particle_types,
    statistics,
)
from sphjax.dataset.generate import (
    MARKER,
    PARTIAL,
    RESEED_SPEED_MARGIN,
    ensemble_time_step,
    generate_dataset,
)
from sphjax.dataset.perturb import (
    SPLITS,
    Perturbation,
    check_vary,
    initial_conditions,
    perturb_state,
    random_velocity_field,
    redraws_case_seed,
    reseeded_case,
    sample_params,
    speed_bound,
    trajectory_rng,
)

__all__ = [
    "BODY",
    "FLUID",
    "FORMAT_VERSION",
    "MARKER",
    "MOVING_WALL",
    "PAD",
    "PARTIAL",
    "RESEED_SPEED_MARGIN",
    "SPLITS",
    "WALL",
    "Perturbation",
    "check_metadata",
    "check_same_geometry",
    "check_vary",
    "ensemble_time_step",
    "frame_differences",
    "frame_time",
    "generate_dataset",
    "initial_conditions",
    "metadata",
    "particle_types",
    "perturb_state",
    "random_velocity_field",
    "redraws_case_seed",
    "reseeded_case",
    "sample_params",
    "speed_bound",
    "statistics",
    "trajectory_rng",
]
