"""Solid throughput: solid particle-steps per second for the oscillating plate (float32).

    python benchmarks/solid_throughput.py [--n 32] [--steps 200] [--repeat 3]

``n`` particles across the plate thickness gives about ``10 n^2`` solid particles
(``n = 32``: about 10k).  The first run compiles; the best of ``--repeat`` timed runs
of ``--steps`` kick-drift-kick steps is reported.  A benchmark reports; it asserts nothing.
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

import sphjax


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=32, help="particles across the thickness")
    parser.add_argument("--steps", type=int, default=200, help="steps per timed run")
    parser.add_argument("--repeat", type=int, default=3, help="timed runs (best is kept)")
    parser.add_argument("--penalty", action="store_true", help="switch the penalty force on")
    args = parser.parse_args(argv)

    case = sphjax.cases.oscillating_plate(n=args.n, penalty_alpha=0.1 if args.penalty else None)
    n_solid = case.info["n_solid"]
    dtype = case.state.position.dtype
    run = lambda: sphjax.simulate(case, n_steps=args.steps).final.position  # noqa: E731
    t0 = time.perf_counter()
    jax.block_until_ready(run())
    first = time.perf_counter() - t0
    times = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        jax.block_until_ready(run())
        times.append(time.perf_counter() - t0)
    best = min(times)
    rate = n_solid * args.steps / best
    print(
        f"oscillating_plate n={args.n}: {case.n_particles} particles "
        f"({n_solid} solid, {case.info['n_clamped']} clamped), {dtype}, "
        f"K={int(sphjax.integrate.build_neighbors(case.state, case.model).solid_idx.shape[1])} "
        f"reference neighbours, penalty={'on' if args.penalty else 'off'}"
    )
    print(
        f"device: {jax.devices()[0].platform}; first run (compile + {args.steps} steps) "
        f"{first:.2f} s; timed runs {np.round(times, 3).tolist()} s"
    )
    print(f"{rate:.3e} solid particle-steps per second ({best / args.steps * 1e3:.3f} ms per step)")


if __name__ == "__main__":
    main()
