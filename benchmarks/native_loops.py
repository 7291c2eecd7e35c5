"""``Model.pair_loop="native"`` against ``"xla"``: the same runs, alternating, in one run.

    python benchmarks/native_loops.py --cases tg40k dam --steps 200 --rounds 2
    python benchmarks/native_loops.py --cases tg10k --steps 20 --rounds 1   # a minute

Each measurement is a fresh subprocess (``sphjax.simulate`` of ``--steps`` steps after an
untimed warm-up call, best of ``--repeats`` calls); the two pair loops alternate within
every round (``--rounds``), so a change of load hits both.  Cases: ``tg10k``/``tg40k``
(2D Taylor-Green as in ``throughput.py``: quintic spline, ``h = dx``, summation density,
Morris viscosity, float32), ``dam`` (dam break ``n = 80``, 15k particles, the case's
defaults: continuity density with Molteni & Colagrossi's diffusion, Monaghan viscosity,
no-slip walls), ``abc32`` (3D ABC flow at 32^3 without transport velocity), ``plate``
(the oscillating plate ``n = 32`` of ``solid_throughput.py``, 10k solid particles,
Wendland C2), ``plate_penalty`` (the same with Ganzenmüller's penalty force, alpha
0.1).  Prints, per case, the best wall-clock and CPU milliseconds per step of each loop
and the ratios (xla / native: above 1 means the native loops are faster), and the load
average before and after.  ``--baseline DIR`` also runs ``pair_loop="native"`` with the
sphjax of another checkout (e.g. a git worktree of an earlier commit), alternating with
the others, and adds its figures and the ratio baseline / native; ``--native-only`` leaves
out the XLA runs (the 3D case's take minutes), so that only the two checkouts' native
loops are compared.  A benchmark reports; it asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

CHILD = r"""
import dataclasses, json, sys, time
import jax
import sphjax
name, loop, steps, repeats = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
if name.startswith("tg"):
    n = {"tg10k": 100, "tg40k": 200}[name]
    case = sphjax.cases.taylor_green(n=n, kernel="quintic_spline", h_factor=1.0,
                                     density="summation", transport_velocity=False)
    dt = 0.25 / n / 11.0
elif name == "dam":
    case = sphjax.cases.dam_break(n=80)
    dt = case.dt
elif name.startswith("plate"):
    penalty = 0.1 if name == "plate_penalty" else None
    case = sphjax.cases.oscillating_plate(n=32, penalty_alpha=penalty)
    dt = case.dt
else:
    case = sphjax.cases.abc_flow_3d(n=32, transport_velocity=False, relax_iterations=50)
    dt = case.dt
case = case.replace(model=dataclasses.replace(case.model, pair_loop=loop))
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
                                  cpu=min(cpu) / steps, source=sphjax.__file__)))
"""

CASES = ("tg10k", "tg40k", "dam", "abc32", "plate", "plate_penalty")
LOOPS = ("xla", "native")


def measure(case: str, loop: str, steps: int, repeats: int, checkout: str | None = None) -> dict:
    """One measurement in a fresh process; ``checkout``: import sphjax from there (run in
    that folder: ``python -c`` puts the working directory first on the path)."""
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    if checkout is not None:
        env["PYTHONPATH"] = os.pathsep.join([checkout, env.get("PYTHONPATH", "")])
    out = subprocess.run(
        [sys.executable, "-c", CHILD, case, loop.split("@")[0], str(steps), str(repeats)],
        env=env,
        cwd=checkout,
        capture_output=True,
        text=True,
    )
    lines = [line for line in out.stdout.splitlines() if line.startswith("RESULT ")]
    if out.returncode or not lines:
        raise SystemExit(f"{case} with pair_loop={loop!r} failed: {out.stderr.strip()[-400:]}")
    row = json.loads(lines[-1][len("RESULT ") :])
    if checkout is not None and not row["source"].startswith(checkout):
        raise SystemExit(f"--baseline: the run imported {row['source']}, not {checkout}'s")
    return row


def load() -> str:
    with open("/proc/loadavg") as f:
        return " ".join(f.read().split()[:3])


def _against_xla(cases, best) -> None:
    """The table of each case's two pair loops (best of the rounds)."""
    print(
        "\n| case | particles | xla wall (CPU) ms | native wall (CPU) ms | wall ratio | CPU ratio |"
    )
    print("|---|---:|---:|---:|---:|---:|")
    for case in cases:
        x, n = best[(case, "xla")], best[(case, "native")]
        print(
            f"| {case} | {x['n']} | {1e3 * x['wall']:.2f} ({1e3 * x['cpu']:.2f}) | "
            f"{1e3 * n['wall']:.2f} ({1e3 * n['cpu']:.2f}) | {x['wall'] / n['wall']:.2f} | "
            f"{x['cpu'] / n['cpu']:.2f} |"
        )


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", nargs="+", default=["tg40k", "dam"], choices=CASES)
    p.add_argument("--steps", type=int, default=200)
    p.add_argument("--repeats", type=int, default=2, help="timed calls per measurement")
    p.add_argument("--rounds", type=int, default=2, help="alternating rounds")
    p.add_argument(
        "--baseline",
        metavar="DIR",
        help="also time pair_loop='native' with the sphjax of this checkout",
    )
    p.add_argument(
        "--native-only",
        action="store_true",
        help="with --baseline: leave out the XLA runs, compare the two native loops",
    )
    args = p.parse_args(argv)
    if args.native_only and args.baseline is None:
        p.error("--native-only compares with --baseline DIR: give both")
    if args.steps < 1 or args.repeats < 1 or args.rounds < 1:
        p.error("--steps, --repeats and --rounds: give positive numbers")
    baseline = None if args.baseline is None else os.path.abspath(args.baseline)
    loops = LOOPS[args.native_only :] + (() if baseline is None else ("native@baseline",))
    print(f"load average before: {load()}", flush=True)
    best: dict = {}
    for _ in range(args.rounds):
        for case in args.cases:
            for loop in loops:
                checkout = baseline if loop.endswith("@baseline") else None
                row = measure(case, loop, args.steps, args.repeats, checkout)
                key = (case, loop)
                if key not in best or row["cpu"] < best[key]["cpu"]:
                    best[key] = row
                print(
                    f"  {case:6s} {loop:15s} {1e3 * row['wall']:8.2f} wall ms/step "
                    f"{1e3 * row['cpu']:8.2f} CPU ms/step",
                    flush=True,
                )
    print(f"load average after: {load()}")
    if not args.native_only:
        _against_xla(args.cases, best)
    if baseline is not None:
        print(f"\nbaseline: pair_loop='native' with the sphjax of {baseline}")
        print("\n| case | baseline wall (CPU) ms | native wall (CPU) ms | wall ratio | CPU ratio |")
        print("|---|---:|---:|---:|---:|")
        for case in args.cases:
            b, n = best[(case, "native@baseline")], best[(case, "native")]
            print(
                f"| {case} | {1e3 * b['wall']:.2f} ({1e3 * b['cpu']:.2f}) | "
                f"{1e3 * n['wall']:.2f} ({1e3 * n['cpu']:.2f}) | {b['wall'] / n['wall']:.2f} | "
                f"{b['cpu'] / n['cpu']:.2f} |"
            )
    return {f"{c}/{loop}": row for (c, loop), row in best.items()}


if __name__ == "__main__":
    main()
