"""Cost of gradients through a whole simulation: time and peak memory.

For a Taylor-Green vortex of ``n_side**2`` particles (float32 by default) this measures

* ``time(grad) / time(forward)`` for ``loss = kinetic energy after n_steps`` w.r.t.
  the viscosity, both ``jax.jit``-compiled, compile time excluded (best of ``--repeat``);
* peak resident memory (``ru_maxrss``) of a fresh subprocess per configuration, with and
  without ``checkpoint_every``.

Each configuration runs in its own subprocess, so the peak RSS belongs to it alone.

    python benchmarks/gradients.py --n-side 100 --steps 1000 4000 --checkpoint 0 50
    python benchmarks/gradients.py --one 100 1000 50     # a single configuration (internal)

``--checkpoint 0`` means no rematerialisation (every step's residuals are stored); at
10k particles that needs tens of GB for a thousand steps, so run it at fewer steps
(``--steps-no-checkpoint``).
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


def run_one(n_side: int, n_steps: int, checkpoint: int, repeat: int, x64: bool) -> dict:
    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", x64)
    import sphjax

    case = sphjax.cases.taylor_green(n=n_side)
    checkpoint_every = checkpoint or None

    def loss(nu):
        params = case.params.replace(kinematic_viscosity=nu)
        final = sphjax.simulate(
            case, params, n_steps=n_steps, checkpoint_every=checkpoint_every
        ).final
        return 0.5 * jnp.sum(final.mass[:, None] * final.velocity**2)

    nu = jnp.asarray(case.params.kinematic_viscosity)
    forward = jax.jit(loss)
    gradient = jax.jit(jax.grad(loss))
    out = dict(particles=case.n_particles, n_steps=n_steps, checkpoint_every=checkpoint)
    for name, fn in (("forward", forward), ("grad", gradient)):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(nu))
        out[f"{name}_first_s"] = time.perf_counter() - t0
        best = math.inf
        for _ in range(repeat):
            t0 = time.perf_counter()
            value = jax.block_until_ready(fn(nu))
            best = min(best, time.perf_counter() - t0)
        out[f"{name}_s"] = best
        out[f"{name}_value"] = float(value)
    out["ratio"] = out["grad_s"] / out["forward_s"]
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-side", type=int, default=100, help="particles per side")
    parser.add_argument("--steps", type=int, nargs="+", default=[1000, 4000])
    parser.add_argument(
        "--steps-no-checkpoint",
        type=int,
        nargs="+",
        default=None,
        help="step counts for checkpoint 0 (default: --steps)",
    )
    parser.add_argument(
        "--checkpoint",
        type=int,
        nargs="+",
        default=[0, 50],
        help="checkpoint_every values; 0 = no checkpointing",
    )
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--x64", action="store_true", help="float64 instead of float32")
    parser.add_argument("--json", default=None, help="append results to this JSON-lines file")
    parser.add_argument("--one", type=int, nargs=3, metavar=("N_SIDE", "STEPS", "CKPT"))
    args = parser.parse_args(argv)

    if args.one:
        print(json.dumps(run_one(*args.one, repeat=args.repeat, x64=args.x64)), flush=True)
        return

    header = (
        f"{'particles':>9} {'steps':>6} {'ckpt':>5} {'fwd s':>8} {'grad s':>8} "
        f"{'grad/fwd':>8} {'peak RSS MB':>11}"
    )
    print(header, flush=True)
    for checkpoint in args.checkpoint:
        steps = args.steps
        if checkpoint == 0 and args.steps_no_checkpoint is not None:
            steps = args.steps_no_checkpoint
        for n_steps in steps:
            cmd = [
                sys.executable,
                __file__,
                "--one",
                str(args.n_side),
                str(n_steps),
                str(checkpoint),
                "--repeat",
                str(args.repeat),
            ]
            if args.x64:
                cmd.append("--x64")
            proc = subprocess.run(cmd, capture_output=True, text=True, env=os.environ.copy())
            if proc.returncode != 0:
                tail = proc.stderr.strip().splitlines()[-1:] or ["?"]
                print(
                    f"{args.n_side**2:>9} {n_steps:>6} {checkpoint:>5}  failed "
                    f"(exit {proc.returncode}): {tail[0]}",
                    flush=True,
                )
                continue
            r = json.loads(proc.stdout.strip().splitlines()[-1])
            print(
                f"{r['particles']:>9} {n_steps:>6} {checkpoint:>5} {r['forward_s']:>8.2f} "
                f"{r['grad_s']:>8.2f} {r['ratio']:>8.2f} {r['peak_rss_mb']:>11.0f}",
                flush=True,
            )
            if args.json:
                with open(args.json, "a") as f:
                    f.write(json.dumps(r) + "\n")


if __name__ == "__main__":
    main()
