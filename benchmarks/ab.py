"""Two source trees side by side: the same benchmark, alternating, in one run.

    python benchmarks/ab.py --trees /path/to/main /path/to/branch --cases tg40k dam plate

Each measurement is a fresh subprocess with ``PYTHONPATH`` set to one tree, so ``import
sphjax`` loads that tree's code; the benchmark code itself is this directory's (it uses
the public API only: ``sphjax.cases``, ``sphjax.simulate``).  Trees alternate within
every round (``--rounds``), so a load change on a shared machine hits both.  For each case
and tree it prints the best wall-clock and CPU seconds per step and the ratios
(first tree / each other tree: above 1 means faster than the first).

Cases: ``tg10k``/``tg40k`` (2D Taylor-Green as in ``throughput.py``, float32), ``dam``
(dam break ``n = 80``, 15k particles, the case's defaults), ``plate`` (oscillating plate
``n = 32``, 10k solid particles), ``plate_grad`` (``jax.grad`` of the plate's summed
heights w.r.t. the Young modulus, ``n = 16``, 2.6k particles, ``checkpoint_every=25``).
Timed: ``sphjax.simulate`` of ``--steps`` steps (or its gradient) after an untimed warm-up
call (compilation).  A benchmark reports; it asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent

CHILD = r"""
import json, sys, time
import jax
import sphjax
name, steps, repeats = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
if name.startswith("tg"):
    n = {"tg10k": 100, "tg40k": 200}[name]
    case = sphjax.cases.taylor_green(n=n, kernel="quintic_spline", h_factor=1.0,
                                     density="summation", transport_velocity=False)
    dt = 0.25 / n / 11.0
elif name == "dam":
    case = sphjax.cases.dam_break(n=80)
    dt = case.dt
elif name == "plate":
    case = sphjax.cases.oscillating_plate(n=32)
    dt = case.dt
else:
    dt = None
if name.endswith("_grad"):
    import jax.numpy as jnp
    case = sphjax.cases.oscillating_plate(n=16)
    def loss(E):
        params = case.params.replace(young_modulus=E)
        final = sphjax.simulate(case, params, n_steps=steps, checkpoint_every=25).final
        return jnp.sum(final.position[:, 1])
    grad = jax.jit(jax.grad(loss))
    E0 = jnp.asarray(case.params.young_modulus)
    def run():
        jax.block_until_ready(grad(E0))
else:
    def run():
        traj = sphjax.simulate(case, n_steps=steps, save_every=steps, dt=dt)
        jax.block_until_ready(traj.states.position)
run()
wall, cpu = [], []
for _ in range(repeats):
    t0, c0 = time.perf_counter(), time.process_time()
    run()
    wall.append(time.perf_counter() - t0)
    cpu.append(time.process_time() - c0)
print("RESULT " + json.dumps(dict(n=case.n_particles, wall=min(wall) / steps,
                                  cpu=min(cpu) / steps)))
"""


def measure(tree: str, case: str, steps: int, repeats: int) -> dict:
    env = {**os.environ, "PYTHONPATH": tree, "JAX_PLATFORMS": "cpu"}
    out = subprocess.run(
        [sys.executable, "-c", CHILD, case, str(steps), str(repeats)],
        env=env,
        capture_output=True,
        text=True,
        cwd=tree,
    )
    for line in out.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    raise RuntimeError(f"{case} in {tree} failed:\n{out.stderr[-2000:]}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trees", nargs="+", required=True, help="source trees (first: base)")
    parser.add_argument("--cases", nargs="+", default=["tg40k", "dam", "plate"])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--json", type=Path, help="also write the raw results here")
    args = parser.parse_args(argv)
    results = {}
    for case in args.cases:
        for r in range(args.rounds):
            for tree in args.trees:
                res = measure(tree, case, args.steps, args.repeats)
                results.setdefault(case, {}).setdefault(tree, []).append(res)
                print(
                    f"{case:6s} round {r} {tree}: {res['n']} particles, "
                    f"{res['wall'] * 1e3:.2f} ms/step wall, {res['cpu'] * 1e3:.2f} cpu",
                    flush=True,
                )
    print(f"\n{'case':6s} {'tree':40s} {'wall ms':>8s} {'cpu ms':>8s} {'x wall':>7s} {'x cpu':>7s}")
    for case, by_tree in results.items():
        base = by_tree[args.trees[0]]
        bw, bc = min(x["wall"] for x in base), min(x["cpu"] for x in base)
        for tree, runs in by_tree.items():
            w, c = min(x["wall"] for x in runs), min(x["cpu"] for x in runs)
            print(f"{case:6s} {tree:40s} {w * 1e3:8.2f} {c * 1e3:8.2f} {bw / w:7.2f} {bc / c:7.2f}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
