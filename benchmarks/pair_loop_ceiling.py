"""How far a fused pair loop on this CPU is from the XLA step: the Taylor-Green step of
``benchmarks/throughput.py`` written as plain C loops over a cell list
(``benchmarks/pair_loop_ceiling.c``: the same kernel, support, summation density, linear
equation of state, Morris viscosity and kick-drift-kick, float32), timed beside
``sphjax.simulate`` on the same size in the same run.

    python benchmarks/pair_loop_ceiling.py --n 200 --steps 100
    python benchmarks/pair_loop_ceiling.py --n 40 --steps 10 --no-sphjax   # seconds

Rows: the C loop visiting every pair from both sides (as the XLA step does, OpenMP over
particles, 1 and 2 threads), and visiting each pair once and adding its terms to both
particles (one thread: the scatter to the other particle is what XLA's CPU backend does
slowly); the cell-blocked loop (each pair once; each cell against the contiguous runs of
particles of its half shell of cells, one vectorised loop over each run, no neighbour
list; cells of the support or of half of it; threads over stripes of cells, 1 and 2;
and four particles a at a time against each run); and
sphjax's step (Verlet list, skin 0.25 of the support, padded to the list's
width).  Figures: wall and CPU milliseconds per step, particle-steps per CPU-second, and
each row's CPU time over sphjax's.  The C loop is a ceiling to measure against, not a part
of sphjax: it starts from the lattice (sphjax's case from its relaxed disordered start,
the same number of neighbours), has no health checks, and is not differentiable.  Needs a
C compiler with OpenMP (``--cc``, default ``gcc``); without one it says so in one line.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


# the C loop's modes (its fourth argument)
MODES = {"both": 0, "once": 1, "cells": 2, "cells_by_4": 3}


def compile_loop(cc: str, directory: str) -> str:
    """Build ``pair_loop_ceiling.c`` with ``cc -O3 -march=native -fopenmp`` and, as
    ``sphjax.native`` builds its loops, without errno or trapping maths (so that the
    cell-blocked loops vectorise); the binary's path."""
    binary = os.path.join(directory, "pair_loop_ceiling")
    flags = ["-O3", "-march=native", "-fno-math-errno", "-fno-trapping-math", "-fopenmp"]
    subprocess.run(
        [cc, *flags, "-o", binary, str(HERE / "pair_loop_ceiling.c"), "-lm"],
        check=True,
        capture_output=True,
        text=True,
    )
    return binary


def run_loop(binary: str, n: int, steps: int, threads: int, mode: str, split: int = 1) -> dict:
    """One run of the C loop, ``mode`` one of ``MODES`` (every pair from both sides, each
    pair once, cell-blocked), ``split`` cells per support length: its printed ``key=value``
    figures."""
    env = dict(os.environ, OMP_NUM_THREADS=str(threads), OMP_WAIT_POLICY="passive")
    out = subprocess.run(
        [binary, str(n), str(steps), str(split), str(MODES[mode])],
        check=True,
        capture_output=True,
        text=True,
        env=env,
    ).stdout.split()
    return {k: float(v) for k, v in (item.split("=") for item in out)}


def run_sphjax_step(n: int, steps: int, repeats: int) -> dict:
    """sphjax's step on the same Taylor-Green (``throughput.run_sphjax``), per step."""
    sys.path.insert(0, str(HERE))
    from throughput import run_sphjax

    row = run_sphjax(n, steps, repeats)
    best = min(range(repeats), key=lambda i: row["cpu_seconds"][i])
    return dict(
        wall_ms_per_step=1e3 * row["seconds"][best] / steps,
        cpu_ms_per_step=1e3 * row["cpu_seconds"][best] / steps,
    )


def parse(argv, description: str, compiler: str, default: str, what: str):
    """The arguments both pair-loop benchmarks take (``--n --steps --repeats``, the
    compiler flag ``compiler`` with its ``default``, ``--no-sphjax``), refused in one line
    where they cannot run."""
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--n", type=int, default=200, help="particles per side (n x n)")
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--repeats", type=int, default=3, help="runs of each row; the best is kept")
    p.add_argument(f"--{compiler}", default=default, help=f"the {what} compiler")
    p.add_argument("--no-sphjax", action="store_true", help="time the pair loop alone")
    args = p.parse_args(argv)
    if args.n < 12:
        p.error(f"--n {args.n}: give at least 12 particles per side (three cells of the support)")
    if args.steps < 1 or args.repeats < 1:
        p.error("--steps and --repeats: give positive numbers")
    if shutil.which(getattr(args, compiler)) is None:
        p.error(
            f"--{compiler} {getattr(args, compiler)}: no such compiler on PATH (install "
            f"{default}, or name another)"
        )
    return args


def report(rows: list[dict], args) -> None:
    """Print the rows (wall and CPU ms per step, particle-steps per CPU-second, CPU time
    over the last row's, sphjax's, where it was timed) under the run's conditions."""
    particles = args.n * args.n
    reference = None if args.no_sphjax else rows[-1]["cpu_ms_per_step"]
    print(
        f"Taylor-Green {particles} particles, {args.steps} steps, best of {args.repeats}, "
        f"float32, load average {os.getloadavg()[0]:.2f}, {time.strftime('%Y-%m-%d %H:%M')}"
    )
    print(
        f"{'row':50s} {'wall ms':>8s} {'CPU ms':>8s} {'M p-steps/CPU-s':>16s} {'CPU / sphjax':>13s}"
    )
    for row in rows:
        rate = particles / (1e3 * row["cpu_ms_per_step"])
        ratio = "" if reference is None else f"{row['cpu_ms_per_step'] / reference:13.2f}"
        print(
            f"{row['label']:50s} {row['wall_ms_per_step']:8.2f} {row['cpu_ms_per_step']:8.2f} "
            f"{rate:16.2f} {ratio}"
        )


def main(argv=None) -> list[dict]:
    args = parse(argv, __doc__.split("\n\n")[0], "cc", "gcc", "C (with OpenMP)")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        binary = compile_loop(args.cc, tmp)
        for label, threads, mode, split in (
            ("C, every pair from both sides, 1 thread", 1, "both", 1),
            ("C, every pair from both sides, 2 threads", 2, "both", 1),
            ("C, each pair once, 1 thread", 1, "once", 1),
            ("C, cell-blocked, cells of the support, 1 thread", 1, "cells", 1),
            ("C, cell-blocked, cells of the support, 2 threads", 2, "cells", 1),
            ("C, cell-blocked, cells of support / 2, 1 thread", 1, "cells", 2),
            ("C, cell-blocked, cells of support / 2, 2 threads", 2, "cells", 2),
            ("C, cell-blocked, 4 particles a at once, 1 thread", 1, "cells_by_4", 1),
        ):
            runs = [
                run_loop(binary, args.n, args.steps, threads, mode, split)
                for _ in range(args.repeats)
            ]
            best = min(runs, key=lambda r: r["cpu_ms_per_step"])
            rows.append(dict(best, label=label))
    if not args.no_sphjax:
        rows.append(dict(run_sphjax_step(args.n, args.steps, args.repeats), label="sphjax step"))
    report(rows, args)
    print(
        f"neighbours inside the support per particle {rows[0]['neighbours_inside']:.1f}; "
        "distances evaluated per particle in the density sum: "
        + ", ".join(f"{row['candidates']:.1f}" for row in rows if "candidates" in row)
        + " (the C rows in order; the cell-blocked rows count whole vectors)"
    )
    return rows


if __name__ == "__main__":
    main()
