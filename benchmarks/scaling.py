"""Cost curves: particle-steps per second and peak memory per particle against size.

    python benchmarks/scaling.py --dim 2 --sizes 10000 40000 160000 640000 1000000
    python benchmarks/scaling.py --dim 3 --sizes 10000 40000 160000 --mode reverse
    python benchmarks/scaling.py --plot results.json --out docs/scaling.png

The case is the periodic Taylor-Green vortex (2D, ``[0, 1]^2``) or ABC flow (3D,
``[0, 1)^3``) on the unrelaxed lattice (``disorder = 0``, no packing, so that building a
million particles is quick), float32, quintic spline, ``h = dx``, summation density (2D)
and the case's defaults otherwise.  Each size runs in its own subprocess, one after the
other, so that its peak resident memory (``ru_maxrss``) is its own:

* ``forward``: ``sphjax.simulate`` of ``--steps`` steps (compiled chunks), after an untimed
  warm-up call;
* ``reverse``: ``jax.grad`` of the kinetic energy after ``--steps`` steps w.r.t. the
  viscosity, ``checkpoint_every = --checkpoint`` (memory flat in the number of steps),
  compiled, after an untimed warm-up call.

Reported per size: particle-steps per second (wall-clock and per CPU-second), the
neighbour-list width, and the peak memory above the interpreter's own at start, per
particle.  A size that runs out of memory or time is reported as such.  A benchmark
reports; it asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import time
from pathlib import Path


def make_case(dim: int, n_particles: int):
    import sphjax

    if dim == 2:
        n = int(round(math.sqrt(n_particles)))
        case = sphjax.cases.taylor_green(
            n=n,
            kernel="quintic_spline",
            h_factor=1.0,
            density="summation",
            transport_velocity=False,
            disorder=0.0,
            relax_iterations=0,
        )
        # the benchmark's acoustic step, or the viscous limit where that is smaller (1M)
        return case, min(0.25 / n / 11.0, float(case.dt))
    n = int(round(n_particles ** (1.0 / 3.0)))
    case = sphjax.cases.abc_flow_3d(
        n=n, h_factor=1.0, transport_velocity=False, disorder=0.0, relax_iterations=0
    )
    return case, case.dt


def run_one(dim: int, n_particles: int, steps: int, mode: str, checkpoint: int) -> dict:
    """One size in this process."""
    base_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    import jax
    import jax.numpy as jnp

    import sphjax

    t0 = time.perf_counter()
    case, dt = make_case(dim, n_particles)
    build_s = time.perf_counter() - t0
    base_rss = max(base_rss, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
    n = case.n_particles

    if mode == "forward":

        def once():
            traj = sphjax.simulate(case, n_steps=steps, save_every=steps, dt=dt)
            return jax.block_until_ready(traj.states.position)

    else:

        def loss(nu):
            params = case.params.replace(kinematic_viscosity=nu)
            final = sphjax.simulate(
                case, params, n_steps=steps, dt=dt, checkpoint_every=checkpoint
            ).final
            return 0.5 * jnp.sum(final.mass * jnp.sum(final.velocity**2, axis=-1))

        grad = jax.jit(jax.grad(loss))
        nu0 = jnp.asarray(case.params.kinematic_viscosity)

        def once():
            return jax.block_until_ready(grad(nu0))

    t0 = time.perf_counter()
    once()
    warmup_s = time.perf_counter() - t0
    t0, c0 = time.perf_counter(), time.process_time()
    once()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux
    return dict(
        dim=dim,
        mode=mode,
        particles=n,
        steps=steps,
        wall_s=wall,
        cpu_s=cpu,
        rate=n * steps / wall,
        rate_cpu=n * steps / cpu,
        build_s=build_s,
        warmup_s=warmup_s,
        peak_mib=peak / 1024,
        bytes_per_particle=(peak - base_rss) * 1024 / n,
    )


def run_sizes(args) -> list[dict]:
    results = []
    for size in args.sizes:
        cmd = [sys.executable, __file__, "--one", str(args.dim), str(size), str(args.steps)]
        cmd += ["--mode", args.mode, "--checkpoint", str(args.checkpoint)]
        env = {**os.environ, "JAX_PLATFORMS": os.environ.get("JAX_PLATFORMS", "cpu")}
        try:
            out = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=args.timeout)
        except subprocess.TimeoutExpired:
            print(f"{args.dim}D {size}: over {args.timeout} s, stopped", flush=True)
            results.append(dict(dim=args.dim, mode=args.mode, particles=size, failed="timeout"))
            continue
        line = [x for x in out.stdout.splitlines() if x.startswith("RESULT ")]
        if not line:
            why = "out of memory" if out.returncode in (-9, 137) else out.stderr[-400:]
            print(f"{args.dim}D {size}: failed ({why})", flush=True)
            results.append(dict(dim=args.dim, mode=args.mode, particles=size, failed=why))
            continue
        res = json.loads(line[0][7:])
        results.append(res)
        print(
            f"{res['dim']}D {res['mode']:7s} {res['particles']:>9d} particles: "
            f"{res['rate']:.3e} particle-steps/s ({res['rate_cpu']:.3e} per CPU-s), "
            f"peak {res['peak_mib']:.0f} MiB, {res['bytes_per_particle']:.0f} B/particle; "
            f"build {res['build_s']:.1f} s, warm-up {res['warmup_s']:.1f} s",
            flush=True,
        )
    return results


def plot(results: list[dict], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    groups = {}
    for r in results:
        if "failed" not in r:
            groups.setdefault((r["dim"], r["mode"]), []).append(r)
    for (dim, mode), rs in sorted(groups.items()):
        rs = sorted(rs, key=lambda r: r["particles"])
        n = [r["particles"] for r in rs]
        label = f"{dim}D {mode}"
        (line,) = ax1.plot(n, [r["rate"] for r in rs], "o-", label=f"{label}, wall")
        ax1.plot(
            n,
            [r["rate_cpu"] for r in rs],
            "s--",
            color=line.get_color(),
            alpha=0.6,
            label=f"{label}, per CPU-s",
        )
        ax2.plot(n, [r["bytes_per_particle"] / 1024 for r in rs], "o-", label=label)
    for ax in (ax1, ax2):
        ax.set_xscale("log")
        ax.set_xlabel("particles")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    ax1.set_yscale("log")
    ax1.set_ylabel("particle-steps per second")
    ax2.set_ylabel("peak memory per particle (KiB)")
    fig.suptitle("sphjax on a 2-core CPU, float32 (benchmarks/scaling.py)")
    fig.tight_layout()
    fig.savefig(out, dpi=110)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dim", type=int, default=2, choices=(2, 3))
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000, 40_000, 160_000])
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--mode", default="forward", choices=("forward", "reverse"))
    parser.add_argument("--checkpoint", type=int, default=10, help="checkpoint_every (reverse)")
    parser.add_argument("--timeout", type=float, default=1800.0, help="seconds per size")
    parser.add_argument("--json", type=Path, help="append the results to this JSON list")
    parser.add_argument("--plot", type=Path, help="plot the results of this JSON file")
    parser.add_argument("--out", type=Path, default=Path("scaling.png"))
    parser.add_argument("--one", nargs=3, type=int, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.one:
        res = run_one(*args.one, mode=args.mode, checkpoint=args.checkpoint)
        print("RESULT " + json.dumps(res), flush=True)
        return
    if args.plot:
        plot(json.loads(args.plot.read_text()), args.out)
        return
    results = run_sizes(args)
    if args.json:
        old = json.loads(args.json.read_text()) if args.json.exists() else []
        args.json.write_text(json.dumps(old + results, indent=1))


if __name__ == "__main__":
    main()
