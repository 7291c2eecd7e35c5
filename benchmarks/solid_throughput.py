"""Solid throughput: solid particle-steps per second for the oscillating plate (float32).

    python benchmarks/solid_throughput.py [--n 32] [--steps 200] [--repeat 3]

``n`` particles across the plate thickness gives about ``10 n^2`` solid particles
(``n = 32``: 10240 solid particles).  The timed call is ``sphjax.simulate`` of
``--steps`` kick-drift-kick steps (what a user runs: compiled chunks, reference neighbours
built per call); the first call compiles.  Reported: the best wall-clock rate and the rate
per CPU-second of this process (less sensitive to other jobs on a shared machine).  A
benchmark reports; it asserts nothing.
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

import sphjax


def run(n: int, steps: int, repeat: int, penalty: bool = False) -> dict:
    case = sphjax.cases.oscillating_plate(n=n, penalty_alpha=0.1 if penalty else None)

    def once():
        traj = sphjax.simulate(case, n_steps=steps, save_every=steps)
        return jax.block_until_ready(traj.states.position)

    t0 = time.perf_counter()
    once()
    first = time.perf_counter() - t0
    wall, cpu = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = once()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    assert bool(np.all(np.isfinite(np.asarray(out))))
    return dict(case=case, first=first, wall=wall, cpu=cpu)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=32, help="particles across the thickness")
    parser.add_argument("--steps", type=int, default=200, help="steps per timed run")
    parser.add_argument("--repeat", type=int, default=3, help="timed runs (best is kept)")
    parser.add_argument("--penalty", action="store_true", help="switch the penalty force on")
    args = parser.parse_args(argv)
    out = run(args.n, args.steps, args.repeat, args.penalty)
    case, wall, cpu = out["case"], out["wall"], out["cpu"]
    n_solid = case.info["n_solid"]
    best, best_cpu = min(wall), min(cpu)
    print(
        f"oscillating_plate n={args.n}: {case.n_particles} particles ({n_solid} solid, "
        f"{case.info['n_clamped']} clamped), {case.state.position.dtype}, "
        f"penalty {'on' if args.penalty else 'off'}"
    )
    print(
        f"device {jax.devices()[0].platform}; compile + {args.steps} steps "
        f"{out['first']:.2f} s; timed wall {np.round(wall, 3).tolist()} s, "
        f"cpu {np.round(cpu, 3).tolist()} s"
    )
    print(
        f"{n_solid * args.steps / best:.3e} solid particle-steps per second (wall, "
        f"{best / args.steps * 1e3:.2f} ms per step); "
        f"{n_solid * args.steps / best_cpu:.3e} per CPU-second"
    )


if __name__ == "__main__":
    main()
