"""Ensembles of SPH trajectories in the LagrangeBench dataset layout.

A dataset folder holds ``metadata.json`` and ``train.h5``, ``valid.h5``, ``test.h5``
(the layout of LagrangeBench, Toshev et al. 2023; see ``docs/surrogates.md``).  Each HDF5
file has one group per trajectory (``00000``, ``00001``, ...) with ``position`` (float32,
``[T, N, d]``) and ``particle_type`` (int32, ``[N]``; -1 padding, 0 fluid, 1 wall, 2 moving
wall, 3 rigid or elastic body).  The statistics ``vel_mean``/``vel_std``/``acc_mean``/
``acc_std`` are per dimension over the fluid particles of the training split, of per-frame
finite differences of positions (not divided by time), with the minimum image on periodic
axes.

Each trajectory starts from the case's initial state with a seeded random change
(:class:`Perturbation`: a scaled velocity field plus a random divergence-free Fourier
field) and with the Params named in ``vary`` drawn uniformly from their ranges.  A batch
of trajectories runs as one compiled ``jax.vmap`` of :func:`sphjax.simulate`; with more
than one JAX device the batch is sharded over all of them (``jax.sharding``).

Generation is resumable: finished trajectories go to ``DIR/.partial/`` one file each, an
``INCOMPLETE`` marker holds the plan, and only when every trajectory is done are the HDF5
files and ``metadata.json`` written and the marker removed.  An interrupted folder is
never mistaken for a dataset: it has no ``metadata.json``, and :func:`generate_dataset`
with ``resume=True`` (``sphjax dataset --resume``) continues it.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shutil
from collections.abc import Mapping
from pathlib import Path

import h5py
import jax
import jax.numpy as jnp
import numpy as np

from sphjax.core.case import Case
from sphjax.core.params import Params
from sphjax.core.space import minimum_image
from sphjax.core.state import Kind, State
from sphjax.integration.simulate import simulate
from sphjax.integration.timestep import check_time_step, stable_time_step

SPLITS = ("train", "valid", "test")
MARKER = "INCOMPLETE"
PARTIAL = ".partial"
FORMAT_VERSION = 1

# LagrangeBench particle types
PAD, FLUID, WALL, MOVING_WALL, BODY = -1, 0, 1, 2, 3


@dataclasses.dataclass(frozen=True)
class Perturbation:
    """Seeded random change of a case's initial velocities (fluid particles only).

    ``v = s v_case + v_random`` with ``s`` uniform in ``amplitude`` and ``v_random`` a
    divergence-free 2D field from a random stream function ``psi`` built of Fourier modes
    with wavenumbers up to ``modes`` (periodic axes: ``cos(2 pi k x / L + phase)``;
    closed axes: ``sin(pi k x / L)``, so no flow crosses the walls), scaled so its
    largest speed is ``fourier`` times the largest speed of the case (or 1 if at rest).

    Attributes:
      amplitude: ``(lo, hi)`` range of the scale ``s`` of the case velocity field.
      fourier: relative size of the random field (0 switches it off).
      modes: largest wavenumber of the random field.
    """

    amplitude: tuple[float, float] = (1.0, 1.0)
    fourier: float = 0.0
    modes: int = 2

    def __post_init__(self):
        lo, hi = self.amplitude
        if not 0 <= lo <= hi:
            raise ValueError(f"Perturbation.amplitude must satisfy 0 <= lo <= hi, got {lo, hi}")
        if self.fourier < 0:
            raise ValueError(f"Perturbation.fourier must be >= 0, got {self.fourier}")
        if self.modes < 1:
            raise ValueError(f"Perturbation.modes must be >= 1, got {self.modes}")


def _rng(seed: int, split: str, index: int) -> np.random.Generator:
    """Per-trajectory generator: a trajectory does not depend on its batch."""
    return np.random.default_rng([int(seed), SPLITS.index(split), int(index)])


def random_velocity_field(position, domain, rng, modes: int = 2) -> np.ndarray:
    """Divergence-free 2D velocity ``(d psi/dy, -d psi/dx)`` at ``position``, max speed 1."""
    x = np.asarray(position, np.float64)
    if x.shape[1] != 2:
        raise ValueError("the random Fourier velocity field is 2D only; use fourier=0 in 3D")
    lower, size = np.asarray(domain.lower), np.asarray(domain.size)
    s = (x - lower) / size  # in [0, 1) per axis
    u = np.zeros_like(x)
    axes_k = [range(0, modes + 1) if p else range(1, modes + 1) for p in domain.periodic]
    for kx in axes_k[0]:
        for ky in axes_k[1]:
            if kx == 0 and ky == 0:
                continue
            amp = rng.normal() / (kx * kx + ky * ky)
            f, df = [], []
            for axis, k in enumerate((kx, ky)):
                if domain.periodic[axis]:
                    phase = rng.uniform(0, 2 * np.pi)
                    arg = 2 * np.pi * k * s[:, axis] + phase
                    f.append(np.cos(arg))
                    df.append(-2 * np.pi * k / size[axis] * np.sin(arg))
                else:
                    arg = np.pi * k * s[:, axis]
                    f.append(np.sin(arg))
                    df.append(np.pi * k / size[axis] * np.cos(arg))
            u[:, 0] += amp * f[0] * df[1]
            u[:, 1] -= amp * df[0] * f[1]
    peak = np.linalg.norm(u, axis=1).max()
    return u / peak if peak > 0 else u


def perturb_state(case: Case, perturbation: Perturbation, rng: np.random.Generator) -> State:
    """The case's initial state with velocities changed by ``perturbation`` (see there)."""
    state = case.state
    velocity = np.asarray(state.velocity, np.float64)
    fluid = np.asarray(state.kind) == Kind.FLUID
    scale = rng.uniform(*perturbation.amplitude)
    new = velocity.copy()
    new[fluid] = scale * velocity[fluid]
    if perturbation.fourier > 0:
        speed = np.linalg.norm(velocity[fluid], axis=1).max(initial=0.0)
        speed = speed if speed > 0 else 1.0
        field = random_velocity_field(
            np.asarray(state.position), case.model.domain, rng, perturbation.modes
        )
        new[fluid] += perturbation.fourier * speed * field[fluid]
    return state.replace(velocity=jnp.asarray(new, state.velocity.dtype))


def sample_params(
    params: Params, vary: Mapping[str, tuple[float, float]], rng: np.random.Generator
) -> Params:
    """``params`` with each field named in ``vary`` drawn uniformly from ``(lo, hi)``."""
    changes = {}
    for name in sorted(vary):
        lo, hi = vary[name]
        changes[name] = jnp.asarray(rng.uniform(lo, hi), getattr(params, name).dtype)
    return params.replace(**changes)


def check_vary(params: Params, vary: Mapping[str, tuple[float, float]]) -> dict:
    """Validate ``vary``: scalar Params fields with ``lo <= hi``."""
    names = [f.name for f in dataclasses.fields(params)]
    scalar = [n for n in names if np.ndim(getattr(params, n)) == 0]
    out = {}
    for name, rng in vary.items():
        if name not in scalar:
            raise ValueError(
                f"vary: {name!r} is not a scalar Params field; choose from {', '.join(scalar)}"
            )
        lo, hi = (float(v) for v in rng)
        if not lo <= hi:
            raise ValueError(f"vary: {name}={lo}:{hi} needs lo <= hi")
        out[name] = (lo, hi)
    return out


def particle_types(case: Case) -> np.ndarray:
    """LagrangeBench particle types of ``case`` (fluid 0, wall 1, moving wall 2, body 3)."""
    kind = np.asarray(case.state.kind)
    out = np.full(kind.shape, FLUID, np.int32)
    out[kind == Kind.WALL] = WALL
    out[kind == Kind.SOLID] = BODY
    out[kind == Kind.CLAMPED] = MOVING_WALL if case.model.clamped_motion is not None else WALL
    return out


# ---------------------------------------------------------------------------- statistics


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


# ---------------------------------------------------------------------------- running


class _Runner:
    """One compiled, vmapped, sharded simulation of a batch of (state, params)."""

    def __init__(self, case: Case, dt: float, steps: int, write_every: int, devices=None):
        self.devices = list(jax.devices() if devices is None else devices)
        self.case, self.dt, self.steps, self.write_every = case, dt, steps, write_every
        self._compile()

    def _compile(self):
        case, dt, steps, every = self.case, self.dt, self.steps, self.write_every

        def one(state, params):
            # simulate allocates its neighbour list from the concrete case.state; evaluate
            # that eagerly while the traced (state, params) computation is staged
            with jax.ensure_compile_time_eval():
                traj = simulate(case, params, n_steps=steps, save_every=every, dt=dt, state=state)
            return traj.states.position

        self._fn = jax.jit(jax.vmap(one))
        if len(self.devices) > 1:
            mesh = jax.sharding.Mesh(np.array(self.devices), ("batch",))
            self._sharding = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("batch"))
        else:
            self._sharding = None

    def __call__(self, states: list[State], params: list[Params], size: int) -> np.ndarray:
        """Positions ``[B, T, N, d]``; the batch is padded to ``size`` (one compilation)."""
        n = len(states)
        pad = max(size, n) - n
        states = states + [states[-1]] * pad
        params = params + [params[-1]] * pad
        batch_states = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *states)
        batch_params = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *params)
        if self._sharding is not None:
            batch_states = jax.device_put(batch_states, self._sharding)
            batch_params = jax.device_put(batch_params, self._sharding)
        for _attempt in range(5):
            try:
                out = self._fn(batch_states, batch_params)
                out = np.asarray(jax.block_until_ready(out))
                break
            except Exception as error:  # raised from a callback inside the compiled run
                if "neighbour list overflowed" not in str(error):
                    raise
                model = self.case.model
                self.case = self.case.replace(
                    model=model.replace(neighbor_capacity=1.5 * model.neighbor_capacity)
                )
                self._compile()
        else:
            raise RuntimeError("neighbour list kept overflowing; raise Model.neighbor_capacity")
        return out[:n]


_RUNNERS: dict = {}


def _runner(case: Case, dt, steps, write_every, devices) -> _Runner:
    """A cached runner: the same set-up and run length compile once per process."""
    x = np.asarray(case.state.position)
    key = (case.model, x.shape, x.tobytes(), float(dt), steps, write_every, tuple(devices))
    if key not in _RUNNERS:
        _RUNNERS.clear()  # keep one: a runner holds a compiled simulation
        _RUNNERS[key] = _Runner(case, dt, steps, write_every, devices)
    return _RUNNERS[key]


# ---------------------------------------------------------------------------- generation


def _plan(case, counts, steps, write_every, vary, perturbation, seed, dt, case_kwargs):
    return dict(
        format_version=FORMAT_VERSION,
        case=case.name,
        case_kwargs=case_kwargs,
        counts=dict(zip(SPLITS, counts, strict=True)),
        steps=steps,
        write_every=write_every,
        vary={k: list(v) for k, v in vary.items()},
        perturbation=dataclasses.asdict(perturbation),
        seed=seed,
        dt=dt,
        n_particles=case.n_particles,
    )


def _json_roundtrip(obj):
    return json.loads(json.dumps(obj))


def generate_dataset(
    case: Case,
    out,
    *,
    n_train: int,
    n_valid: int,
    n_test: int,
    steps: int,
    write_every: int,
    vary: Mapping[str, tuple[float, float]] | None = None,
    perturbation: Perturbation | None = None,
    seed: int = 0,
    dt: float | None = None,
    batch_size: int | None = None,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool = True,
    devices=None,
    case_kwargs: dict | None = None,
    stop_after: int | None = None,
) -> Path:
    """Simulate an ensemble of ``case`` and write it to ``out`` in the LagrangeBench layout.

    Args:
      case: the base set-up (``sphjax.cases.<name>(...)``).
      out: dataset folder (created).
      n_train, n_valid, n_test: trajectories per split.
      steps: solver steps per trajectory; a multiple of ``write_every``.  Each trajectory
        has ``steps // write_every + 1`` frames.
      write_every: solver steps between frames.
      vary: ``{Params field: (lo, hi)}`` drawn uniformly per trajectory.
      perturbation: the random initial condition (default: 20 % random Fourier field,
        velocity scale in ``[0.75, 1.25]``).
      seed: base seed; trajectory ``i`` of a split uses ``(seed, split, i)``.
      dt: solver step (default: the smallest stable step over all trajectories).
      batch_size: trajectories per compiled call (default 4 per device).
      resume: continue an interrupted folder (its ``INCOMPLETE`` plan must match).
      overwrite: replace whatever ``out`` holds.
      progress: show a tqdm bar over trajectories.
      devices: JAX devices to shard over (default: all).
      case_kwargs: recorded in the metadata (how ``case`` was built).
      stop_after: stop after this many batches, leaving the folder incomplete (tests).
    Returns:
      the dataset folder, or the incomplete folder if stopped early.
    """
    from tqdm.auto import tqdm

    counts = [int(n_train), int(n_valid), int(n_test)]
    for name, n in zip(("n_train", "n_valid", "n_test"), counts, strict=True):
        if n < 0:
            raise ValueError(f"{name} must be >= 0, got {n}")
    if counts[0] < 1:
        raise ValueError("n_train must be >= 1 (the statistics come from the training split)")
    if write_every < 1 or steps < 2 * write_every or steps % write_every:
        raise ValueError(
            f"steps={steps} must be a multiple of write_every={write_every} and give at least "
            "3 frames (steps >= 2 * write_every)"
        )
    vary = check_vary(case.params, dict(vary or {}))
    perturbation = Perturbation((0.75, 1.25), 0.2) if perturbation is None else perturbation
    out = Path(out)
    marker, partial = out / MARKER, out / PARTIAL

    # the whole ensemble's initial conditions, deterministic per trajectory
    jobs = []
    for split, n in zip(SPLITS, counts, strict=True):
        for i in range(n):
            rng = _rng(seed, split, i)
            state = perturb_state(case, perturbation, rng)
            params = sample_params(case.params, vary, rng)
            jobs.append((split, i, state, params))
    if dt is None:
        dt = min(stable_time_step(s, case.model, p) for _, _, s, p in jobs)
    dt = float(dt)
    for split, i, s, p in jobs:
        try:
            check_time_step(dt, s, case.model, p)
        except ValueError as error:
            raise ValueError(f"trajectory {split}/{i}: {error}") from None
    plan = _json_roundtrip(
        _plan(case, counts, steps, write_every, vary, perturbation, seed, dt, case_kwargs or {})
    )

    # the folder
    if out.exists() and any(out.iterdir()):
        if overwrite:
            shutil.rmtree(out)
        elif marker.exists() and resume:
            old = json.loads(marker.read_text())
            if old != plan:
                raise ValueError(
                    f"{out} holds an incomplete dataset made with other settings; resume it "
                    "with the same arguments, or pass overwrite=True (--overwrite)"
                )
        elif marker.exists():
            raise FileExistsError(
                f"{out} holds an incomplete dataset; pass resume=True (--resume) to continue it "
                "or overwrite=True (--overwrite) to start afresh"
            )
        else:
            raise FileExistsError(f"{out} is not empty; choose another folder or overwrite")
    try:
        partial.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise OSError(f"cannot write the dataset folder {out}: {error}") from None
    if not marker.exists():
        marker.write_text(json.dumps(plan, indent=1))

    def part_file(split, i):
        return partial / f"{split}_{i:05d}.npy"

    todo = [job for job in jobs if not part_file(job[0], job[1]).exists()]
    devices = list(jax.devices() if devices is None else devices)
    batch_size = 4 * len(devices) if batch_size is None else int(batch_size)
    batch_size = min(batch_size, max(1, len(todo)))
    batch_size = len(devices) * math.ceil(batch_size / len(devices))
    runner = _runner(case, dt, steps, write_every, devices) if todo else None
    bar = tqdm(
        total=len(jobs),
        initial=len(jobs) - len(todo),
        desc="trajectories",
        unit="traj",
        disable=not progress,
    )
    try:
        for b, start in enumerate(range(0, len(todo), batch_size)):
            if stop_after is not None and b >= stop_after:
                return out
            batch = todo[start : start + batch_size]
            positions = runner([j[2] for j in batch], [j[3] for j in batch], batch_size)
            for (split, i, _, _), x in zip(batch, positions, strict=True):
                _check_finite(x, split, i)
                tmp = partial / f"tmp_{split}_{i:05d}.npy"
                np.save(tmp, x.astype(np.float32))
                os.replace(tmp, part_file(split, i))
            bar.update(len(batch))
    finally:
        bar.close()

    _assemble(out, case, plan, jobs, part_file)
    return out


def _check_finite(x, split, i):
    if not np.all(np.isfinite(x)):
        frame = int(np.argmax(~np.all(np.isfinite(x), axis=(1, 2))))
        raise RuntimeError(
            f"trajectory {split}/{i} went unstable (non-finite positions from frame {frame}); "
            "shorten --steps, reduce the perturbation or choose a smaller dt"
        )


def _assemble(out: Path, case: Case, plan: dict, jobs, part_file) -> None:
    """Write the HDF5 splits and metadata.json from the partial files; remove the marker."""
    types = particle_types(case)
    domain = case.model.domain
    bounds = [[float(lo), float(hi)] for lo, hi in zip(domain.lower, domain.upper, strict=True)]
    periodic = [bool(p) for p in domain.periodic]
    params_of = {(s, i): p for s, i, _, p in jobs}
    for split in SPLITS:
        tmp = out / f".{split}.h5.tmp"
        with h5py.File(tmp, "w") as f:
            for i in range(plan["counts"][split]):
                g = f.create_group(f"{i:05d}")
                g.create_dataset("position", data=np.load(part_file(split, i)))
                g.create_dataset("particle_type", data=types)
                for name in plan["vary"]:
                    g.attrs[name] = float(getattr(params_of[(split, i)], name))
        os.replace(tmp, out / f"{split}.h5")
    train = [np.load(part_file("train", i)) for i in range(plan["counts"]["train"])]
    stats = statistics(train, [types] * len(train), bounds, periodic)
    meta = metadata(case, plan, bounds, periodic, types, stats)
    (out / "metadata.json").write_text(json.dumps(meta, indent=2))
    shutil.rmtree(out / PARTIAL)
    (out / MARKER).unlink()


def metadata(case: Case, plan: dict, bounds, periodic, types, stats) -> dict:
    """The LagrangeBench metadata keys plus the sphjax settings."""
    params, model = case.params, case.model
    dx = float(case.info.get("dx", model.smoothing_length))
    frames = plan["steps"] // plan["write_every"] + 1
    gravity = np.asarray(params.gravity)
    sound = float(params.sound_speed)
    rho0 = float(params.reference_density)
    meta = dict(
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
        viscosity=float(params.kinematic_viscosity),
        artificial_alpha=float(params.artificial_alpha),
        g_ext_magnitude=float(np.linalg.norm(gravity)),
        p_bg_factor=float(params.background_pressure) / (rho0 * sound**2),
        density_evolution=model.density == "continuity",
        reference_density=rho0,
        sound_speed=sound,
        smoothing_length=float(model.smoothing_length),
        kernel=type(model.kernel).__name__,
        gamma=float(model.gamma),
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
    return meta
