"""Simulate an ensemble of a case and write it in the LagrangeBench layout.

Each trajectory starts from the case's initial state with a seeded random change and
with the Params named in ``vary`` drawn uniformly from their ranges
(:mod:`sphjax.dataset.perturb`), all with one solver step fixed by the case and the
ranges (:func:`ensemble_time_step`), so every ``seed`` gives the same ``dt``; batches run
as one compiled ``jax.vmap`` of :func:`sphjax.simulate` (:mod:`sphjax.dataset.runner`);
the files and metadata follow :mod:`sphjax.dataset.format`.

Generation is resumable: finished trajectories go to ``DIR/.partial/`` one file each, an
``INCOMPLETE`` marker holds the plan, and only when every trajectory is done are the HDF5
files and ``metadata.json`` written and the marker removed.  An interrupted folder is
never mistaken for a dataset: it has no ``metadata.json``, and :func:`generate_dataset`
with ``resume=True`` (CLI ``--resume``) continues it.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import os
import shutil
import time
from collections.abc import Mapping
from pathlib import Path

import h5py
import jax
import numpy as np

from sphjax._compile import CompileTimer
from sphjax.core.case import Case
from sphjax.core.state import Kind
from sphjax.dataset.format import FORMAT_VERSION, metadata, particle_types, statistics
from sphjax.dataset.perturb import (
    SPLITS,
    Perturbation,
    check_vary,
    initial_conditions,
    redraws_case_seed,
    speed_bound,
)
from sphjax.dataset.runner import cached_runner
from sphjax.integration.timestep import check_time_step, stable_time_step

MARKER = "INCOMPLETE"
PARTIAL = ".partial"

#: factor on :func:`~sphjax.dataset.perturb.speed_bound` when every trajectory rebuilds the
#: case with its own ``seed``: the peak speed of a rebuilt start differs from the given
#: case's by a few per cent (Taylor-Green, six seeds: up to 5 % at ``n = 8``, 0.5 % at
#: ``n = 32``).
RESEED_SPEED_MARGIN = 1.1


def ensemble_time_step(
    case: Case,
    perturbation: Perturbation,
    vary: Mapping[str, tuple[float, float]] | None = None,
    case_kwargs: Mapping | None = None,
) -> float:
    """The solver step of an ensemble, fixed by the case and the ranges, not by the draws.

    ``dt = min over the corners of vary of stable_time_step(fastest, model, params)``:
    the stable step (:func:`~sphjax.integration.timestep.stable_time_step`, fluid CFL
    0.25) of the case's initial state with every fluid particle at the speed bound
    ``a_hi U + f U'`` (:func:`~sphjax.dataset.perturb.speed_bound`, no draw can be
    faster), times :data:`RESEED_SPEED_MARGIN` if every trajectory rebuilds the case with
    its own seed, with the Params of each of the ``2^k`` corners of the ``k`` ranges in
    ``vary``.  Every limit (acoustic ``CFL h / (c0 + |v|)``, viscous ``0.125 h^2 / nu``,
    body force ``0.25 sqrt(h / |g|)``: Morris, Fox & Zhu 1997, J. Comput. Phys. 136;
    solid ``CFL h / (c_s + |v|)``, ``c_s = sqrt(E / (d (1 - 2 nu) rho0))``) is monotone in
    each Params field it reads, so the smallest corner bounds every draw from the box.  For
    a fluid that is the worst end of each range:

        dt = min(0.25 h / (c0_hi + V), 0.125 h^2 / nu_hi, 0.25 sqrt(h / |g|))

    with ``V`` the speed bound above.

    Only the given case and the ranges are read, never a draw: the same arguments with any
    ``seed`` give the same step.  :func:`generate_dataset` still checks every trajectory
    against it.
    """
    vary = dict(vary or {})
    bound = speed_bound(case, perturbation)
    if redraws_case_seed(case, perturbation, case_kwargs or {}):
        bound *= RESEED_SPEED_MARGIN
    state = case.state
    fluid = np.asarray(state.kind) == Kind.FLUID
    velocity = np.array(state.velocity, np.float64)
    velocity[fluid] = 0.0
    velocity[fluid, 0] = bound
    fastest = state.replace(velocity=velocity)
    names = sorted(vary)
    steps = []
    for corner in itertools.product(*(vary[name] for name in names)):
        changes = {
            name: np.asarray(value, np.asarray(getattr(case.params, name)).dtype)
            for name, value in zip(names, corner, strict=True)
        }
        steps.append(stable_time_step(fastest, case.model, case.params.replace(**changes)))
    return min(steps)


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
    timings: dict | None = None,
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
        velocity scale in ``[0.75, 1.25]``, the case's own ``seed`` redrawn per
        trajectory).
      seed: base seed; trajectory ``i`` of a split draws everything random from
        ``(seed, split, i)``.
      dt: solver step (default: :func:`ensemble_time_step`, the same for every ``seed``);
        checked against every trajectory either way.
      batch_size: trajectories per compiled call (default 4 per device).
      resume: continue an interrupted folder (its ``INCOMPLETE`` plan must match).
      overwrite: replace whatever ``out`` holds; without it (and without ``resume``) a
        folder that holds files raises :class:`FileExistsError` naming ``out`` and
        ``overwrite=True``, before anything is simulated.
      progress: show a tqdm bar over trajectories.
      devices: JAX devices to shard over (default: all).
      case_kwargs: recorded in the metadata (how ``case`` was built).
      stop_after: stop after this many batches, leaving the folder incomplete (tests).
      timings: a dict filled with ``trajectories`` (simulated in this call), ``seconds``
        (wall clock, compilation included), ``compile_seconds`` (of those, the time spent
        tracing and compiling the batch program, or loading it from JAX's cache) and
        ``per_minute`` (trajectories per minute after compilation: over ``seconds -
        compile_seconds``).
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

    if out.exists() and not out.is_dir():
        raise FileExistsError(f"out: '{out}' is a file; give the name of a folder")
    if out.exists() and any(out.iterdir()) and not overwrite:
        _refuse_to_replace(out, marker, resume)  # before the initial conditions are built

    # the whole ensemble's initial conditions, deterministic per trajectory
    jobs = initial_conditions(case, counts, perturbation, vary, seed, case_kwargs or {})
    if dt is None:
        dt = ensemble_time_step(case, perturbation, vary, case_kwargs)
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
        else:
            _refuse_to_replace(out, marker, resume)
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
    started = time.perf_counter()
    runner = cached_runner(case, dt, steps, write_every, devices) if todo else None
    bar = tqdm(
        total=len(jobs),
        initial=len(jobs) - len(todo),
        desc="trajectories",
        unit="traj",
        disable=not progress,
    )
    with CompileTimer() as timer:
        finished = _run_batches(
            runner, todo, batch_size, stop_after, partial, part_file, bar, _check_finite
        )
    if not finished:
        return out
    if timings is not None:
        seconds = time.perf_counter() - started
        compiling = min(timer.seconds(started), seconds)
        running = seconds - compiling
        timings.update(
            trajectories=len(todo),
            seconds=seconds,
            compile_seconds=compiling,
            per_minute=60.0 * len(todo) / running if running > 0 else float("inf"),
        )

    _assemble(out, case, plan, jobs, part_file)
    return out


def _run_batches(runner, todo, batch_size, stop_after, partial, part_file, bar, check) -> bool:
    """Simulate ``todo`` in batches, each trajectory saved to its part file as it is done;
    False if stopped early by ``stop_after``."""
    try:
        for b, start in enumerate(range(0, len(todo), batch_size)):
            if stop_after is not None and b >= stop_after:
                return False
            batch = todo[start : start + batch_size]
            positions = runner([j[2] for j in batch], [j[3] for j in batch], batch_size)
            for (split, i, _, _), x in zip(batch, positions, strict=True):
                check(x, split, i)
                tmp = partial / f"tmp_{split}_{i:05d}.npy"
                np.save(tmp, x.astype(np.float32))
                os.replace(tmp, part_file(split, i))
            bar.update(len(batch))
    finally:
        bar.close()
    return True


def _refuse_to_replace(out: Path, marker: Path, resume: bool) -> None:
    """Raise FileExistsError for a folder ``out`` that holds files, unless it holds an
    interrupted dataset (``marker``) and ``resume`` is asked for."""
    if marker.exists() and resume:
        return
    if marker.exists():
        raise FileExistsError(
            f"out: '{out}' holds an incomplete dataset; pass resume=True to continue it "
            "or overwrite=True to start afresh"
        )
    raise FileExistsError(
        f"out: '{out}' is not empty; pass overwrite=True to replace what it holds, "
        "or choose another folder"
    )


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
