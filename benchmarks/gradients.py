"""Cost of gradients through a whole simulation: time and peak memory.

For a Taylor-Green vortex of ``n_side**2`` particles (float32 by default) this measures

* ``time(grad) / time(forward)`` (wall-clock, and per CPU-second of the process) for
  ``loss = kinetic energy after n_steps`` w.r.t. the viscosity, both ``jax.jit``-compiled,
  compile time excluded (best of ``--repeat``);
* peak resident memory (``ru_maxrss``) of a fresh subprocess per configuration, with and
  without ``checkpoint_every``, and XLA's temporary memory of the compiled derivative
  (``memory_analysis().temp_size_in_bytes``: what the program holds at its peak, the
  stored carries included, without the compiler's own memory);
* with ``--forward-mode``, the same derivative in forward mode (``jax.jacfwd``: one
  tangent through the scan, nothing stored), the cheaper route for a few parameters;
* with ``--autodiff-steps``, reverse mode with JAX's own transpose of the pair sums
  (``Model.pair_adjoint=False``) instead of their custom adjoint
  (:mod:`sphjax.physics.pairs`), for comparison;
* with ``--case dam_break``, the dam break (walls, continuity density, Monaghan viscosity,
  delta-SPH; ``n`` particles across the column), derivative w.r.t. ``artificial_alpha``;
  with ``--case oscillating_plate`` (the elastic solid, eqs. 14-19, ``n`` particles along
  the plate's length) and ``--case hydrostatic_fsi_plate`` (fluid, walls and an elastic
  plate, coupled; ``n`` particles through the plate), w.r.t. ``young_modulus``.

Each configuration runs in its own subprocess, so the peak RSS belongs to it alone.

    python benchmarks/gradients.py --n-side 100 --steps 1000 4000 --checkpoint 50 0 \
        --forward-mode --autodiff-steps 1000
    python benchmarks/gradients.py --one 100 1000 50     # a single configuration (internal)

``--checkpoint 0`` means ``checkpoint_every=None``: every step's input carry is kept, so
memory grows with the number of steps (about 16 GB at 4000 steps of 10k particles);
``--steps-no-checkpoint`` runs it at other step counts.
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

#: case -> (factory, the Params field differentiated)
CASES = {
    "taylor_green": ("taylor_green", "kinematic_viscosity"),
    "dam_break": ("dam_break", "artificial_alpha"),
    "oscillating_plate": ("oscillating_plate", "young_modulus"),
    "hydrostatic_fsi_plate": ("hydrostatic_fsi_plate", "young_modulus"),
}


def run_one(
    n_side: int,
    n_steps: int,
    checkpoint: int,
    repeat: int,
    x64: bool,
    mode: str = "reverse",
    case_name: str = "taylor_green",
) -> dict:
    """One configuration in this process: forward, then the gradient (``mode``)."""
    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", x64)
    import sphjax

    factory, field = CASES[case_name]
    # the coupled plate unsplit (one plate step a step), as the figures in the docs
    extra = dict(substeps=1) if factory == "hydrostatic_fsi_plate" else {}
    case = sphjax.cases.get(factory, n=n_side, **extra)
    if mode == "autodiff":
        # reverse mode with JAX's own adjoint of the fluid rates instead of the hand one
        case = case.replace(model=case.model.replace(pair_adjoint=False))
    checkpoint_every = checkpoint or None

    def loss(value):
        params = case.params.replace(**{field: value})
        final = sphjax.simulate(
            case, params, n_steps=n_steps, checkpoint_every=checkpoint_every
        ).final
        return 0.5 * jnp.sum(final.mass[:, None] * final.velocity**2)

    nu = jnp.asarray(getattr(case.params, field))
    derivative = jax.jacfwd(loss) if mode == "forward" else jax.grad(loss)
    out = dict(
        case=case_name,
        particles=case.n_particles,
        n_steps=n_steps,
        checkpoint_every=checkpoint,
        mode=mode,
    )
    for name, fn in (("forward", loss), ("grad", derivative)):
        t0 = time.perf_counter()
        compiled = jax.jit(fn).lower(nu).compile()
        out[f"{name}_compile_s"] = time.perf_counter() - t0
        # XLA's buffer assignment: the temporaries the compiled program holds at its peak
        # (what reverse mode stores included; compilation's own memory is not in it)
        stats = compiled.memory_analysis()
        if stats is not None:
            out[f"{name}_temp_mb"] = stats.temp_size_in_bytes / 2**20
        best, best_cpu = math.inf, math.inf
        for _ in range(repeat):
            t0, c0 = time.perf_counter(), time.process_time()
            value = jax.block_until_ready(compiled(nu))
            best = min(best, time.perf_counter() - t0)
            best_cpu = min(best_cpu, time.process_time() - c0)
        out[f"{name}_s"] = best
        out[f"{name}_cpu_s"] = best_cpu  # CPU seconds of this process: robust to load
        out[f"{name}_value"] = float(value)
    out["ratio"] = out["grad_s"] / out["forward_s"]
    out["ratio_cpu"] = out["grad_cpu_s"] / out["forward_cpu_s"]
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return out


def _configurations(args):
    """``(mode, n_steps, checkpoint)`` in run order."""
    for checkpoint in args.checkpoint:
        steps = args.steps
        if checkpoint == 0 and args.steps_no_checkpoint is not None:
            steps = args.steps_no_checkpoint
        for n_steps in steps:
            yield "reverse", n_steps, checkpoint
    if args.forward_mode:
        for n_steps in args.steps:
            yield "forward", n_steps, 0
    for n_steps in args.autodiff_steps or ():
        yield "autodiff", n_steps, next((c for c in args.checkpoint if c), 0)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", choices=tuple(CASES), default="taylor_green")
    parser.add_argument(
        "--n-side", type=int, default=100, help="the case's n (Taylor-Green: per side)"
    )
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
        help="checkpoint_every values for reverse mode; 0 = no checkpointing",
    )
    parser.add_argument(
        "--forward-mode",
        action="store_true",
        help="also time the derivative in forward mode (jax.jacfwd) at each of --steps",
    )
    parser.add_argument(
        "--autodiff-steps",
        type=int,
        nargs="+",
        default=None,
        help="also time reverse mode with autodiff's adjoint of the fluid rates "
        "(Model.pair_adjoint=False) at these step counts, with the first non-zero --checkpoint",
    )
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--x64", action="store_true", help="float64 instead of float32")
    parser.add_argument("--json", default=None, help="append results to this JSON-lines file")
    parser.add_argument("--one", type=int, nargs=3, metavar=("N_SIDE", "STEPS", "CKPT"))
    parser.add_argument("--mode", choices=("reverse", "forward", "autodiff"), default="reverse")
    args = parser.parse_args(argv)

    if args.one:
        result = run_one(
            *args.one, repeat=args.repeat, x64=args.x64, mode=args.mode, case_name=args.case
        )
        print(json.dumps(result), flush=True)
        return

    header = (
        f"{'case':>12} {'steps':>6} {'mode':>8} {'ckpt':>5} {'particles':>9} {'fwd s':>8} "
        f"{'grad s':>8} {'grad/fwd':>8} {'per CPU-s':>9} {'peak RSS MB':>11} {'temp MB':>8}"
    )
    print(header, flush=True)
    for mode, n_steps, checkpoint in _configurations(args):
        cmd = [sys.executable, __file__, "--one", str(args.n_side), str(n_steps), str(checkpoint)]
        cmd += ["--repeat", str(args.repeat), "--mode", mode, "--case", args.case]
        cmd += ["--x64"] if args.x64 else []
        proc = subprocess.run(cmd, capture_output=True, text=True, env=os.environ.copy())
        label = f"{args.case:>12} {n_steps:>6} {mode:>8} {checkpoint or '-':>5}"
        if proc.returncode != 0:
            tail = proc.stderr.strip().splitlines()[-1:] or ["?"]
            print(f"{label}  failed (exit {proc.returncode}): {tail[0]}", flush=True)
            continue
        r = json.loads(proc.stdout.strip().splitlines()[-1])
        print(
            f"{label} {r['particles']:>9} {r['forward_s']:>8.2f} {r['grad_s']:>8.2f} "
            f"{r['ratio']:>8.2f} {r['ratio_cpu']:>9.2f} {r['peak_rss_mb']:>11.0f} "
            f"{r.get('grad_temp_mb', float('nan')):>8.1f}",
            flush=True,
        )
        if args.json:
            with open(args.json, "a") as f:
                f.write(json.dumps(r) + "\n")


if __name__ == "__main__":
    main()
