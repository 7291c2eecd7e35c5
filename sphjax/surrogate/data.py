"""Read LagrangeBench-format datasets (ours or LagrangeBench's) into training windows.

A dataset folder holds ``metadata.json`` and ``{train,valid,test}.h5`` with one group per
trajectory (``position`` ``[T, N, d]``, ``particle_type`` ``[N]``), see
:mod:`sphjax.dataset`.  A training window is a position history of ``H + 1`` frames and
the next frame as target.  Velocities and accelerations are per-frame finite differences
of positions (not divided by time), with the minimum image on periodic axes, the same
conventions as the ``vel_*``/``acc_*`` statistics in the metadata.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import h5py
import jax.numpy as jnp
import numpy as np

from sphjax.core.space import minimum_image
from sphjax.dataset.format import check_metadata

PAD, FLUID = -1, 0


@dataclasses.dataclass(frozen=True)
class Trajectories:
    """One split of a dataset.

    Attributes:
      metadata: the folder's ``metadata.json``.
      positions: ``[n_traj, T, N, d]`` float32 (padded particles sit at the lower bound).
      particle_type: ``[n_traj, N]`` int32 (-1 padding, 0 fluid, 1 wall, ...).
    """

    metadata: dict
    positions: np.ndarray
    particle_type: np.ndarray

    @property
    def bounds(self) -> np.ndarray:
        return np.asarray(self.metadata["bounds"], np.float64)

    @property
    def periodic(self) -> tuple[bool, ...]:
        return tuple(bool(p) for p in self.metadata["periodic_boundary_conditions"])

    @property
    def frame_dt(self) -> float:
        """Physical time between frames, ``dt * write_every``."""
        return float(self.metadata["dt"]) * float(self.metadata["write_every"])

    def __len__(self) -> int:
        return int(self.positions.shape[0])


def read_metadata(folder) -> dict:
    """``metadata.json`` of a complete dataset folder (clear errors otherwise)."""
    folder = Path(folder)
    if (folder / "INCOMPLETE").exists():
        raise ValueError(
            f"{folder} is an incomplete dataset (an interrupted run); finish it with "
            "`sphjax dataset ... --resume` before loading it"
        )
    path = folder / "metadata.json"
    if not path.exists():
        raise FileNotFoundError(f"{path} not found: {folder} is not a dataset folder")
    try:
        meta = json.loads(path.read_text())
    except json.JSONDecodeError as error:
        raise ValueError(f"{path} is not valid JSON ({error})") from None
    check_metadata(meta, str(path))
    return meta


def load(folder, split: str = "train", max_trajectories: int | None = None) -> Trajectories:
    """Read ``split`` (``"train"``, ``"valid"`` or ``"test"``) of the dataset in ``folder``."""
    folder = Path(folder)
    meta = read_metadata(folder)
    path = folder / f"{split}.h5"
    if not path.exists():
        raise FileNotFoundError(f"{path} not found; splits are train, valid and test")
    xs, ts = [], []
    dim = int(meta["dim"])
    with h5py.File(path, "r") as f:
        names = sorted(f.keys())[:max_trajectories]
        for name in names:
            x = np.asarray(f[name]["position"], np.float32)
            t = np.asarray(f[name]["particle_type"], np.int32)
            where = f"{path}, trajectory {name}"
            if x.ndim != 3 or x.shape[-1] != dim:
                raise ValueError(
                    f"{where}: position has shape {x.shape}, expected (frames, particles, {dim}) "
                    f"for dim={dim} in metadata.json"
                )
            if t.shape != (x.shape[1],):
                raise ValueError(
                    f"{where}: particle_type has shape {t.shape}, expected ({x.shape[1]},)"
                )
            if not np.all(np.isfinite(x)):
                raise ValueError(f"{where}: position holds non-finite values")
            _check_inside(x, meta, where)
            xs.append(x)
            ts.append(t)
    if not xs:
        raise ValueError(f"{path} holds no trajectories")
    lengths = sorted({x.shape[0] for x in xs})
    if len(lengths) > 1:
        raise ValueError(
            f"{path}: trajectories have different lengths {lengths}; a split must have one "
            "sequence length"
        )
    n_max = max(x.shape[1] for x in xs)
    n_frames = lengths[0]
    lower = np.asarray(meta["bounds"], np.float32)[:, 0]
    positions = np.empty((len(xs), n_frames, n_max, xs[0].shape[-1]), np.float32)
    types = np.full((len(xs), n_max), PAD, np.int32)
    positions[...] = lower
    for k, (x, t) in enumerate(zip(xs, ts, strict=True)):
        positions[k, :, : x.shape[1]] = x[:n_frames]
        types[k, : t.shape[0]] = t
    return Trajectories(metadata=meta, positions=positions, particle_type=types)


def _check_inside(x, meta, where) -> None:
    """Positions on periodic axes lie in ``[lo, hi]`` (a box that does not fit the data
    would be scored with wrong minimum images)."""
    bounds = np.asarray(meta["bounds"], np.float64)
    size = bounds[:, 1] - bounds[:, 0]
    for axis, periodic in enumerate(meta["periodic_boundary_conditions"]):
        if not periodic:
            continue
        lo, hi = x[..., axis].min(), x[..., axis].max()
        tol = 1e-5 * size[axis]
        if lo < bounds[axis, 0] - tol or hi > bounds[axis, 1] + tol:
            raise ValueError(
                f"{where}: positions on periodic axis {axis} span [{lo:.6g}, {hi:.6g}], outside "
                f"the bounds {bounds[axis].tolist()} of metadata.json"
            )


def displacement(a, b, bounds, periodic):
    """``a - b`` with the minimum image on periodic axes (numpy or jax arrays)."""
    xp = jnp if isinstance(a, jnp.ndarray) or isinstance(b, jnp.ndarray) else np
    size = xp.asarray(np.diff(np.asarray(bounds), axis=1)[:, 0], dtype=a.dtype)
    d = a - b
    if not any(periodic):
        return d
    return minimum_image(d, size, periodic)


def wrap(x, bounds, periodic):
    """Map positions back into the box on periodic axes."""
    xp = jnp if isinstance(x, jnp.ndarray) else np
    bounds = np.asarray(bounds)
    lo = xp.asarray(bounds[:, 0], dtype=x.dtype)
    size = xp.asarray(bounds[:, 1] - bounds[:, 0], dtype=x.dtype)
    return xp.where(xp.asarray(periodic), lo + xp.mod(x - lo, size), x)


def frame_velocities(positions, bounds, periodic):
    """``[..., T-1, N, d]`` per-frame velocities of ``[..., T, N, d]`` positions."""
    return displacement(positions[..., 1:, :, :], positions[..., :-1, :, :], bounds, periodic)


def window_index(data: Trajectories, history: int, horizon: int = 1) -> np.ndarray:
    """All windows ``(trajectory, start)``: frames ``start .. start + history`` as input and
    ``horizon`` following frames as targets.  ``[W, 2]`` int."""
    n_traj, n_frames = data.positions.shape[:2]
    starts = np.arange(0, n_frames - history - horizon)
    if starts.size == 0:
        raise ValueError(
            f"trajectories of {n_frames} frames are too short for history={history} and "
            f"horizon={horizon}"
        )
    return np.stack(np.meshgrid(np.arange(n_traj), starts, indexing="ij"), -1).reshape(-1, 2)


def windows(data: Trajectories, index: np.ndarray, history: int, unroll: int = 0):
    """Gather windows: ``(positions [B, H+1+unroll, N, d], target [B, N, d], types [B, N])``.

    ``unroll > 0`` (push-forward training) adds the ``unroll`` frames the model will
    predict itself before the target; they serve the non-fluid particles (walls follow
    the ground truth)."""
    index = np.asarray(index)
    traj, start = index[:, 0], index[:, 1]
    frames = start[:, None] + np.arange(history + 2 + unroll)[None, :]
    seq = data.positions[traj[:, None], frames]
    return seq[:, :-1], seq[:, -1], data.particle_type[traj]


@dataclasses.dataclass(frozen=True)
class Normalization:
    """Per-dimension statistics of per-frame velocities and accelerations (metadata)."""

    vel_mean: np.ndarray
    vel_std: np.ndarray
    acc_mean: np.ndarray
    acc_std: np.ndarray

    @classmethod
    def from_metadata(cls, meta: dict, noise_std: float = 0.0) -> Normalization:
        """With ``noise_std`` added in quadrature to the standard deviations (as in GNS)."""
        f = lambda k: np.asarray(meta[k], np.float32)  # noqa: E731
        return cls(
            vel_mean=f("vel_mean"),
            vel_std=np.sqrt(f("vel_std") ** 2 + noise_std**2).astype(np.float32),
            acc_mean=f("acc_mean"),
            acc_std=np.sqrt(f("acc_std") ** 2 + noise_std**2).astype(np.float32),
        )
