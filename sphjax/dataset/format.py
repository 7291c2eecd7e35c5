"""The LagrangeBench dataset layout: particle types, statistics, metadata and its checks.

A dataset folder holds ``metadata.json`` and ``train.h5``, ``valid.h5``, ``test.h5``.
Each HDF5 file has one group per trajectory (``00000``, ``00001``, ...) with
``position`` (float32, ``[T, N, d]``) and ``particle_type`` (int32, ``[N]``; -1 padding,
0 fluid, 1 wall, 2 moving wall, 3 rigid or elastic body).  The statistics
``vel_mean``/``vel_std``/``acc_mean``/``acc_std`` are per dimension over the fluid
particles of the training split, of per-frame finite differences of positions (not
divided by time), with the minimum image on periodic axes.

:func:`check_metadata` is what the loader (:func:`sphjax.surrogate.data.load`) and the
metrics rely on: the frame time, box, dimension and periodic axes of a dataset.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from sphjax.core.case import Case
from sphjax.core.space import minimum_image
from sphjax.core.state import Kind
from sphjax.physics.fluid.density import ContinuityDensity
from sphjax.physics.fluid.system import FluidSystem
from sphjax.physics.solid.system import SolidSystem

FORMAT_VERSION = 2

# LagrangeBench particle types
PAD, FLUID, WALL, MOVING_WALL, BODY = -1, 0, 1, 2, 3


def particle_types(case: Case) -> np.ndarray:
    """LagrangeBench particle types of ``case`` (fluid 0, wall 1, moving wall 2, body 3)."""
    kind = np.asarray(case.state.kind)
    out = np.full(kind.shape, FLUID, np.int32)
    out[kind == Kind.WALL] = WALL
    out[kind == Kind.SOLID] = BODY
    solid = case.model.system(SolidSystem)
    moving = solid is not None and solid.clamped_motion is not None
    out[kind == Kind.CLAMPED] = MOVING_WALL if moving else WALL
    return out


def frame_differences(position, bounds, periodic):
    """Per-frame velocities and accelerations ``[T-1, N, d]``, ``[T-2, N, d]``.

    Finite differences of positions (not divided by time) with the minimum image on
    periodic axes; ``bounds`` is ``[[lo, hi]] * d``.
    """
    x = np.asarray(position, np.float64)
    size = np.diff(np.asarray(bounds, np.float64), axis=1)[:, 0]
    periodic = np.asarray(periodic, bool)
    vel = x[1:] - x[:-1]
    vel = minimum_image(vel, size, periodic)
    return vel, vel[1:] - vel[:-1]


def statistics(positions, types, bounds, periodic) -> dict:
    """``vel_mean``, ``vel_std``, ``acc_mean``, ``acc_std`` per dimension, fluid only."""
    vels, accs = [], []
    for x, t in zip(positions, types, strict=True):
        fluid = np.asarray(t) == FLUID
        vel, acc = frame_differences(np.asarray(x)[:, fluid], bounds, periodic)
        vels.append(vel.reshape(-1, vel.shape[-1]))
        accs.append(acc.reshape(-1, acc.shape[-1]))
    vel, acc = np.concatenate(vels), np.concatenate(accs)
    return dict(
        vel_mean=vel.mean(0).tolist(),
        vel_std=vel.std(0).tolist(),
        acc_mean=acc.mean(0).tolist(),
        acc_std=acc.std(0).tolist(),
    )


_NO_FLUID = SimpleNamespace(
    sound_speed=math.nan,
    reference_density=math.nan,
    kinematic_viscosity=math.nan,
    artificial_alpha=math.nan,
    background_pressure=math.nan,
)


def metadata(case: Case, plan: dict, bounds, periodic, types, stats) -> dict:
    """The LagrangeBench metadata keys plus the sphjax settings."""
    params, model = case.params, case.model
    fluid = model.system(FluidSystem)
    # a case without a fluid (an elastic solid) has no fluid parameters: NaN for those keys
    values = params.fluid if params.fluid is not None else _NO_FLUID
    dx = float(case.info.get("dx", model.smoothing_length))
    frames = plan["steps"] // plan["write_every"] + 1
    gravity = np.asarray(params.gravity)
    sound = float(values.sound_speed)
    rho0 = float(values.reference_density)
    return dict(
        case=case.name,
        solver="sphjax WCSPH, kick-drift-kick",
        dim=model.dim,
        dx=dx,
        dt=plan["dt"],
        write_every=plan["write_every"],
        t_end=plan["dt"] * plan["steps"],
        sequence_length_train=frames,
        sequence_length_test=frames,
        num_trajs_train=plan["counts"]["train"],
        num_trajs_valid=plan["counts"]["valid"],
        num_trajs_test=plan["counts"]["test"],
        num_particles_max=int(len(types)),
        periodic_boundary_conditions=periodic,
        bounds=bounds,
        default_connectivity_radius=1.45 * dx,
        **stats,
        viscosity=float(values.kinematic_viscosity),
        artificial_alpha=float(values.artificial_alpha),
        g_ext_magnitude=float(np.linalg.norm(gravity)),
        p_bg_factor=float(values.background_pressure) / (rho0 * sound**2),
        density_evolution=fluid is not None and isinstance(fluid.density, ContinuityDensity),
        reference_density=rho0,
        sound_speed=sound,
        smoothing_length=float(model.smoothing_length),
        kernel=type(model.kernel).__name__,
        gamma=float(getattr(getattr(fluid, "equation_of_state", None), "gamma", 1.0)),
        varied_params=plan["vary"],
        perturbation=plan["perturbation"],
        seed=plan["seed"],
        case_kwargs=plan["case_kwargs"],
        steps=plan["steps"],
        particle_type_names={
            "-1": "pad",
            "0": "fluid",
            "1": "wall",
            "2": "moving wall",
            "3": "body",
        },
        format_version=FORMAT_VERSION,
    )


# ---------------------------------------------------------------------------- checks

REQUIRED = (
    "dim",
    "dt",
    "write_every",
    "bounds",
    "periodic_boundary_conditions",
    "default_connectivity_radius",
    "vel_mean",
    "vel_std",
    "acc_mean",
    "acc_std",
)


def _positive(value) -> bool:
    try:
        return math.isfinite(float(value)) and float(value) > 0
    except (TypeError, ValueError):
        return False


def check_metadata(meta: dict, where: str = "metadata.json") -> None:
    """Raise ``ValueError`` (one line naming the key) unless ``meta`` describes a usable
    dataset: ``dim`` 2 or 3, ``bounds`` ``[[lo, hi]] * dim`` with ``lo < hi``,
    ``periodic_boundary_conditions`` one bool per axis, positive ``dt``, integer
    ``write_every >= 1``, positive connectivity radius and finite statistics per axis."""
    missing = [k for k in REQUIRED if k not in meta]
    if missing:
        raise ValueError(f"{where}: missing key(s) {', '.join(missing)}")
    dim = meta["dim"]
    if dim not in (2, 3):
        raise ValueError(f"{where}: dim must be 2 or 3, got {dim!r}")
    try:
        bounds = np.asarray(meta["bounds"], np.float64)
    except (TypeError, ValueError):
        bounds = np.zeros(0)
    if bounds.shape != (dim, 2) or not np.all(np.isfinite(bounds)):
        raise ValueError(
            f"{where}: bounds must be [[lo, hi]] for each of {dim} axes, got {meta['bounds']!r}"
        )
    if not np.all(bounds[:, 1] > bounds[:, 0]):
        raise ValueError(f"{where}: bounds need lo < hi on every axis, got {meta['bounds']!r}")
    periodic = meta["periodic_boundary_conditions"]
    if not (
        isinstance(periodic, list | tuple)
        and len(periodic) == dim
        and all(isinstance(p, bool) for p in periodic)
    ):
        raise ValueError(
            f"{where}: periodic_boundary_conditions must be {dim} booleans, got {periodic!r}"
        )
    if not _positive(meta["dt"]):
        raise ValueError(f"{where}: dt must be a positive number, got {meta['dt']!r}")
    every = meta["write_every"]
    if isinstance(every, bool) or not isinstance(every, int) or every < 1:
        raise ValueError(f"{where}: write_every must be an integer >= 1, got {every!r}")
    if not _positive(meta["default_connectivity_radius"]):
        raise ValueError(
            f"{where}: default_connectivity_radius must be positive, "
            f"got {meta['default_connectivity_radius']!r}"
        )
    for key in ("vel_mean", "vel_std", "acc_mean", "acc_std"):
        value = np.asarray(meta[key], np.float64) if isinstance(meta[key], list) else None
        if value is None or value.shape != (dim,) or not np.all(np.isfinite(value)):
            raise ValueError(f"{where}: {key} must be {dim} finite numbers, got {meta[key]!r}")


def frame_time(meta: dict) -> float:
    """Physical time between stored frames, ``dt * write_every``."""
    return float(meta["dt"]) * int(meta["write_every"])


def check_same_geometry(expected: dict, got: dict, what: str) -> None:
    """Raise ``ValueError`` unless ``got`` has the dimension, box, periodic axes and frame
    time of ``expected`` (``what`` names the data being checked)."""
    if int(got["dim"]) != int(expected["dim"]):
        raise ValueError(f"{what}: dim {got['dim']} differs from the model's {expected['dim']}")
    if list(map(bool, got["periodic_boundary_conditions"])) != list(
        map(bool, expected["periodic_boundary_conditions"])
    ):
        raise ValueError(
            f"{what}: periodic axes {got['periodic_boundary_conditions']} differ from the "
            f"model's {expected['periodic_boundary_conditions']}"
        )
    if not np.allclose(
        np.asarray(got["bounds"], np.float64),
        np.asarray(expected["bounds"], np.float64),
        rtol=1e-6,
        atol=1e-9,
    ):
        raise ValueError(
            f"{what}: bounds {got['bounds']} differ from the model's {expected['bounds']}"
        )
    t_got, t_exp = frame_time(got), frame_time(expected)
    if not math.isclose(t_got, t_exp, rel_tol=1e-6):
        raise ValueError(
            f"{what}: frame time dt*write_every = {t_got:.6g} differs from the model's "
            f"{t_exp:.6g}; evaluate on data written with the model's dt and write_every"
        )
