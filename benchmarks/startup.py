"""Time to the first step: the README's quick start, cold (no compilation cache), for
source trees side by side.

    python benchmarks/startup.py --trees /path/to/base /path/to/new --rounds 3

Each round runs, for every tree in turn, a fresh process
``sphjax run taylor_green --n 20 --t-end 0.05`` with ``SPHJAX_CACHE_DIR=off`` and
``JAX_LOG_COMPILES=1``, and prints its wall time, its CPU time (user + system of the
child) and the number of programs it compiled; then the median per tree and the ratios to
the first tree.  A benchmark reports; it asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

COMMAND = ["run", "taylor_green", "--n", "20", "--t-end", "0.05", "--quiet"]


def one_run(tree: Path, out: Path) -> tuple[float, float, int]:
    env = dict(os.environ, SPHJAX_CACHE_DIR="off", JAX_LOG_COMPILES="1", PYTHONPATH=str(tree))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "sphjax.cli", *COMMAND, "--overwrite", "--out", str(out)],
        env=env,
        capture_output=True,
        text=True,
        cwd=tree,
    )
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"{tree}: exit {done.returncode}\n{done.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, done.stderr.count("Compiling ")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trees", nargs="+", type=Path, default=[Path.cwd()])
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)
    results = {tree: [] for tree in args.trees}
    with tempfile.TemporaryDirectory() as folder:
        for r in range(args.rounds):
            for tree in args.trees:
                wall, cpu, programs = one_run(tree.resolve(), Path(folder) / "tg.h5")
                results[tree].append((wall, cpu, programs))
                print(f"round {r} {tree}: {wall:.2f} s wall, {cpu:.2f} CPU-s, {programs} programs")
    print(f"load average {os.getloadavg()[0]:.2f}")
    print(f"{'tree':<40} {'wall s':>8} {'CPU s':>8} {'programs':>9} {'x wall':>7} {'x CPU':>7}")
    base = None
    for tree, rows in results.items():
        wall = statistics.median(w for w, _, _ in rows)
        cpu = statistics.median(c for _, c, _ in rows)
        programs = statistics.median(p for _, _, p in rows)
        base = base or (wall, cpu)
        print(
            f"{str(tree):<40} {wall:8.2f} {cpu:8.2f} {programs:9.0f} "
            f"{base[0] / wall:7.2f} {base[1] / cpu:7.2f}"
        )


if __name__ == "__main__":
    main()
