"""Solid throughput: solid particle-steps per second for the oscillating plate (float32).

    python benchmarks/solid_throughput.py [--n 32] [--steps 200] [--repeat 3]

``n`` particles across the plate thickness gives about ``10 n^2`` solid particles
(``n = 32``: 10240 solid particles).  The timed function is the compiled ``lax.scan`` of
``--steps`` kick-drift-kick steps (reference neighbours built once, outside the timing);
the first call compiles.  Reported: the best wall-clock rate and the rate per CPU-second
of this process (less sensitive to other jobs on a shared machine).  A benchmark reports;
it asserts nothing.
"""

from __future__ import annotations

import argparse
import functools
import time

import jax
import numpy as np

import sphjax
from sphjax.integration.simulate import build_neighbors, kick_drift_kick


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=32, help="particles across the thickness")
    parser.add_argument("--steps", type=int, default=200, help="steps per timed run")
    parser.add_argument("--repeat", type=int, default=3, help="timed runs (best is kept)")
    parser.add_argument("--penalty", action="store_true", help="switch the penalty force on")
    args = parser.parse_args(argv)

    case = sphjax.cases.oscillating_plate(n=args.n, penalty_alpha=0.1 if args.penalty else None)
    model, params, dt = case.model, case.params, case.dt
    neighbors = build_neighbors(case.state, model)
    state = sphjax.evaluate(case.state, neighbors, model, params)

    @functools.partial(jax.jit, static_argnums=1)
    def run(state, n_steps):
        def body(carry, _):
            return kick_drift_kick(carry, neighbors, dt, model, params)[0], None

        return jax.lax.scan(body, state, None, length=n_steps)[0]

    t0 = time.perf_counter()
    jax.block_until_ready(run(state, args.steps))
    first = time.perf_counter() - t0
    wall, cpu = [], []
    for _ in range(args.repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = jax.block_until_ready(run(state, args.steps))
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    assert bool(np.all(np.isfinite(np.asarray(out.position))))
    n_solid = case.info["n_solid"]
    best, best_cpu = min(wall), min(cpu)
    print(
        f"oscillating_plate n={args.n}: {case.n_particles} particles ({n_solid} solid, "
        f"{case.info['n_clamped']} clamped), {case.state.position.dtype}, "
        f"{neighbors.solid_idx.shape[1]} reference-neighbour slots, "
        f"penalty {'on' if args.penalty else 'off'}"
    )
    print(
        f"device {jax.devices()[0].platform}; compile + {args.steps} steps {first:.2f} s; "
        f"timed wall {np.round(wall, 3).tolist()} s, cpu {np.round(cpu, 3).tolist()} s"
    )
    print(
        f"{n_solid * args.steps / best:.3e} solid particle-steps per second (wall, "
        f"{best / args.steps * 1e3:.2f} ms per step); "
        f"{n_solid * args.steps / best_cpu:.3e} per CPU-second"
    )


if __name__ == "__main__":
    main()
