"""Three-dimensional throughput: sphjax's ABC flow against JAX-SPH's 3D Taylor-Green.

Prints particle-steps per second (wall clock and per CPU-second) at ``n^3`` particles in
a periodic cube (default ``n = 32``; ``--sizes 32 64`` adds 262k particles), float32:

* **sphjax** — :func:`sphjax.cases.abc_flow_3d` set up as JAX-SPH's case is: quintic
  spline with ``h = dx`` (support ``3h``), summation density, no transport velocity,
  the lattice start (no packing), ``dt = 0.25 h / (c0 + |u|max)``;
* **JAX-SPH 0.1.0** — its own 3D Taylor-Green set-up (``[0, 2 pi)^3``,
  ``u = sin x cos y cos z``, ``v = -cos x sin y cos z``, ``w = 0``), driven by
  ``benchmarks/peers/jaxsph_tgv.py --dim 3`` in its own venv, standard SPH, ``QSK``
  with ``h = dx``, ``dt = 0.25 h / (c0 + U)``.

Same particle count, kernel, support and ``h / dx`` (so the same ~113 neighbours per
particle), one right-hand side per step in both; the step's displacement is the same
fraction of ``dx`` (``|u|max dt = dx / 44``), so the neighbour-list rebuild rate is
comparable.  Timing as in ``benchmarks/throughput.py``: an untimed warm-up (compilation,
neighbour-list allocation), then ``--repeats`` runs of ``--steps`` steps.

    python benchmarks/throughput_3d.py                       # 32^3, sphjax and JAX-SPH
    python benchmarks/throughput_3d.py --sizes 32 64 --steps 10
    python benchmarks/throughput_3d.py --pair-loops xla native   # both of sphjax's loops

``--pair-loops`` picks sphjax's pair sums (``Model.pair_loop``: ``xla``, the default, and/or
``native``, the compiled loops; each a row of its own).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from throughput import (  # noqa: E402
    PEERS,
    USER_XLA_FLAGS,
    peer_available,
    peer_python,
    rate,
    summarise,
    timed_runs,
)


def run_sphjax(n: int, steps: int, repeats: int, pair_loop: str = "xla") -> dict:
    """Time ``sphjax.simulate`` on the ABC flow with ``n^3`` particles (in-process), its
    pair sums by ``pair_loop``."""
    import dataclasses

    import jax

    import sphjax
    from sphjax.cases.fluid3d import ABC_MAX_SPEED

    case = sphjax.cases.abc_flow_3d(
        n=n, kernel="quintic_spline", h_factor=1.0, transport_velocity=False, relax_iterations=0
    )
    case = case.replace(model=dataclasses.replace(case.model, pair_loop=pair_loop))
    speed = ABC_MAX_SPEED * case.info["speed"]
    dt = 0.25 * case.model.smoothing_length / (float(case.params.sound_speed) + speed)

    def run():
        traj = sphjax.simulate(case, n_steps=steps, save_every=steps, dt=dt)
        jax.block_until_ready(traj.states.position)

    warmup, seconds, cpu_seconds = timed_runs(run, repeats)
    return dict(
        code="sphjax" if pair_loop == "xla" else f"sphjax-{pair_loop}",
        n_particles=case.n_particles,
        steps=steps,
        seconds=seconds,
        cpu_seconds=cpu_seconds,
        warmup_s=warmup,
        rhs_per_step=1,
        note=f"jax {jax.__version__}, {case.state.position.dtype}, ABC flow, "
        f"skin {case.model.neighbor_skin} x support",
    )


def run_jaxsph(python: str, n: int, steps: int, repeats: int) -> dict:
    dt = 0.25 * (2.0 * math.pi / n) / (10.0 + 1.0)
    cmd = [python, str(PEERS["jax-sph"]["script"]), "--dim", "3", "--n", str(n)]
    cmd += ["--steps", str(steps), "--repeats", str(repeats), "--dt", repr(dt)]
    cmd += ["--warmup-steps", "2"]
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    env.pop("XLA_FLAGS", None)
    if USER_XLA_FLAGS is not None:
        env["XLA_FLAGS"] = USER_XLA_FLAGS
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if proc.returncode or not lines:
        tail = "\n".join((proc.stderr or proc.stdout).strip().splitlines()[-15:])
        raise RuntimeError(f"jax-sph failed (exit {proc.returncode}):\n{tail}")
    return json.loads(lines[-1])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[32], help="n (n^3 particles)")
    parser.add_argument("--steps", type=int, default=20, help="time steps per timed run")
    parser.add_argument("--repeats", type=int, default=2, help="timed runs per code")
    parser.add_argument("--peers", default="jax-sph", help="'jax-sph' or 'none'")
    parser.add_argument("--jaxsph-python", help="python of the JAX-SPH venv")
    parser.add_argument("--json", type=Path, help="also write all raw results here")
    parser.add_argument(
        "--pair-loops",
        nargs="+",
        default=["xla"],
        choices=["xla", "native"],
        help="sphjax's pair sums (Model.pair_loop), a row each",
    )
    args = parser.parse_args(argv)
    for n in args.sizes:
        if n < 8:
            parser.error(f"--sizes: n={n} is too small; use n >= 8")

    python = None
    if args.peers != "none":
        if args.peers != "jax-sph":
            parser.error(f"--peers: unknown peer {args.peers!r}; choose jax-sph or none")
        python = peer_python("jax-sph", args.jaxsph_python)
        ok, why = peer_available("jax-sph", python)
        if not ok:
            print(f"skipping jax-sph: {why} (see docs/performance.md)", flush=True)
            python = None
    print(f"{os.cpu_count()} CPUs; {args.steps} steps per run, {args.repeats} runs", flush=True)
    raw, rows = [], []
    for n in args.sizes:
        row = {}
        jobs = [
            (
                "sphjax" if loop == "xla" else f"sphjax-{loop}",
                lambda n=n, loop=loop: run_sphjax(n, args.steps, args.repeats, loop),
            )
            for loop in args.pair_loops
        ]
        if python:
            jobs.append(("jax-sph", lambda n=n: run_jaxsph(python, n, args.steps, args.repeats)))
        for name, job in jobs:
            try:
                result = job()
            except Exception as err:  # a failing peer must not lose the others
                print(f"{name} n={n}: {err}", flush=True)
                continue
            raw.append(dict(result, n=n))
            row[name] = summarise([result])
            wall = ", ".join(f"{rate(result, s) / 1e6:.4f}" for s in result["seconds"])
            cpu = ", ".join(f"{rate(result, s) / 1e6:.4f}" for s in result["cpu_seconds"])
            print(
                f"  {name:13s} {result['n_particles']:7d} particles: {wall} M particle-steps/s; "
                f"per CPU-s {cpu} (warm-up {result['warmup_s']:.1f} s)",
                flush=True,
            )
        rows.append(row)
    print()
    print("M particle-steps/s (median of the timed runs): wall clock, per CPU-second;")
    print("ratio sphjax / JAX-SPH of the wall-clock rates (of the CPU rates in brackets)")
    for row in rows:
        for name, s in row.items():
            ratio = ""
            if name.startswith("sphjax") and "jax-sph" in row:
                peer = row["jax-sph"]
                ratio = f"{s['median'] / peer['median']:.2f}x ({s['cpu'] / peer['cpu']:.2f}x)"
            print(
                f"{name:13s} {s['n_particles']:8d} {s['median'] / 1e6:9.4f} {s['cpu'] / 1e6:9.4f}"
                f"  {ratio:>15s}   {s['note']}"
            )
    if args.json:
        args.json.write_text(json.dumps(raw, indent=1))


if __name__ == "__main__":
    main()
