"""Throughput of the 2D Taylor-Green vortex: sphjax against JAX-SPH and PySPH.

Prints particle-steps per second (particles x time steps / wall-clock second) for the
periodic 2D Taylor-Green vortex on ``[0, 1]^2`` at ``n x n`` particles (default
``n = 100, 200``: 10k and 40k particles), float32, and, in the same run and on the same
case (``dx = 1/n``, quintic spline with ``h = dx`` and support ``3h``, ``c0 = 10``,
``nu = 0.01``, ``dt = 0.25 h / (c0 + U)``), the two peer codes a user would pick instead:

* **JAX-SPH 0.1.0** (``pip install jax-sph==0.1.0``; needs Python 3.10, its own venv),
  driven through its package API by ``benchmarks/peers/jaxsph_tgv.py``;
* **PySPH 1.0b2** (``pip install pysph==1.0b2``, built from source, OpenMP),
  its bundled ``taylor_green`` example driven through its Python API by
  ``benchmarks/peers/pysph_tgv.py``.

Peers live outside the repository, in their own virtual environments; point the benchmark
at their interpreters with ``--jaxsph-python`` / ``--pysph-python`` or the environment
variables ``SPHJAX_BENCH_JAXSPH_PYTHON`` / ``SPHJAX_BENCH_PYSPH_PYTHON`` (defaults:
``/tmp/venv-jaxsph/bin/python`` and ``/tmp/venv-pysph/bin/python``).  A peer whose
interpreter is missing or cannot import its package is skipped, and the output says so.
See ``docs/performance.md`` for how to create the environments.

Every code is timed the same way: one untimed warm-up run (compilation, neighbour-list
allocation, caches), then ``--repeats`` timed runs of ``--steps`` steps each; compile time
is reported separately.  The machine is shared and timings are noisy, so codes are run one
after another per size and the whole sequence is repeated ``--rounds`` times; the table
gives the median (and best) of all timed runs, and ratios of medians.

    python benchmarks/throughput.py                      # 10k and 40k, all peers
    python benchmarks/throughput.py --sizes 100 --peers none
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
# XLA_FLAGS as the user gave them: importing sphjax adds its own defaults (sphjax/_xla.py),
# which an older jaxlib in a peer's venv would reject.
USER_XLA_FLAGS = os.environ.get("XLA_FLAGS")
PEERS = {
    "jax-sph": dict(
        script=HERE / "peers" / "jaxsph_tgv.py",
        env="SPHJAX_BENCH_JAXSPH_PYTHON",
        default="/tmp/venv-jaxsph/bin/python",
        module="jax_sph",
    ),
    "pysph": dict(
        script=HERE / "peers" / "pysph_tgv.py",
        env="SPHJAX_BENCH_PYSPH_PYTHON",
        default="/tmp/venv-pysph/bin/python",
        module="pysph",
    ),
}


def time_step(n: int) -> float:
    """The common time step: ``0.25 h / (c0 + U)`` with ``h = dx = 1/n``, ``c0 = 10 U``."""
    return 0.25 * (1.0 / n) / (10.0 + 1.0)


# ---------------------------------------------------------------------------- sphjax


def timed_runs(run, repeats: int):
    """``run()`` once untimed (compilation, warm-up), then ``repeats`` times: the warm-up
    seconds and the wall-clock and process-CPU seconds of each timed run."""
    t0 = time.perf_counter()
    run()
    warmup = time.perf_counter() - t0
    seconds, cpu_seconds = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        run()
        seconds.append(time.perf_counter() - t0)
        cpu_seconds.append(time.process_time() - c0)
    return warmup, seconds, cpu_seconds


def run_sphjax(
    n: int, steps: int, repeats: int, skin: float | None = None, pair_loop: str = "xla"
) -> dict:
    """Time ``sphjax.simulate`` on Taylor-Green with ``n x n`` particles (in-process),
    its pair sums in XLA or in the compiled loops (``Model.pair_loop``)."""
    import jax

    import sphjax

    case = sphjax.cases.taylor_green(
        n=n, kernel="quintic_spline", h_factor=1.0, density="summation", transport_velocity=False
    )
    if skin is not None:
        case = case.replace(model=case.model.replace(neighbor_skin=skin))
    case = case.replace(model=case.model.replace(pair_loop=pair_loop))
    dt = time_step(n)

    def run():
        traj = sphjax.simulate(case, n_steps=steps, save_every=steps, dt=dt)
        jax.block_until_ready(traj.states.position)
        return traj

    compile_s, seconds, cpu_seconds = timed_runs(run, repeats)
    return dict(
        code=sphjax_code(pair_loop),
        n_particles=case.n_particles,
        steps=steps,
        seconds=seconds,
        cpu_seconds=cpu_seconds,
        warmup_s=compile_s,
        rhs_per_step=1,
        note=f"jax {jax.__version__}, {case.state.position.dtype}, dense neighbour list, "
        f"skin {case.model.neighbor_skin} x support, XLA_FLAGS={os.environ.get('XLA_FLAGS', '')!r}",
    )


def sphjax_code(pair_loop: str) -> str:
    """The name a sphjax run goes by in the table: ``sphjax`` (XLA's pair sums) or
    ``sphjax-native``."""
    return "sphjax" if pair_loop == "xla" else f"sphjax-{pair_loop}"


# ---------------------------------------------------------------------------- peers


def peer_python(name: str, override: str | None) -> str:
    info = PEERS[name]
    return override or os.environ.get(info["env"]) or info["default"]


def peer_available(name: str, python: str) -> tuple[bool, str]:
    if not Path(python).exists():
        return False, f"interpreter {python} not found"
    probe = subprocess.run(
        [python, "-c", f"import {PEERS[name]['module']}"], capture_output=True, text=True
    )
    if probe.returncode:
        last = (probe.stderr.strip().splitlines() or ["?"])[-1]
        return False, f"{python} cannot import {PEERS[name]['module']}: {last}"
    return True, ""


def run_peer(name: str, python: str, n: int, steps: int, repeats: int, threads: int) -> dict:
    cmd = [
        python,
        str(PEERS[name]["script"]),
        "--n",
        str(n),
        "--steps",
        str(steps),
        "--repeats",
        str(repeats),
        "--dt",
        repr(time_step(n)),
        "--threads",
        str(threads),
    ]
    env = dict(os.environ)
    env["OMP_NUM_THREADS"] = str(threads)
    env.pop("PYTHONPATH", None)
    env.pop("XLA_FLAGS", None)
    if USER_XLA_FLAGS is not None:
        env["XLA_FLAGS"] = USER_XLA_FLAGS
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if proc.returncode or not lines:
        tail = "\n".join((proc.stderr or proc.stdout).strip().splitlines()[-15:])
        raise RuntimeError(f"{name} failed (exit {proc.returncode}):\n{tail}")
    return json.loads(lines[-1])


# ---------------------------------------------------------------------------- report


def rate(result: dict, seconds: float) -> float:
    return result["n_particles"] * result["steps"] / seconds


def summarise(results: list[dict]) -> dict:
    seconds = [s for r in results for s in r["seconds"]]
    cpu = [s for r in results for s in r.get("cpu_seconds", [])]
    first = results[0]
    return dict(
        code=first["code"],
        n_particles=first["n_particles"],
        steps=first["steps"],
        median=rate(first, statistics.median(seconds)),
        best=rate(first, min(seconds)),
        cpu=rate(first, statistics.median(cpu)) if cpu else float("nan"),
        runs=len(seconds),
        warmup_s=statistics.median(r["warmup_s"] for r in results),
        rhs_per_step=first["rhs_per_step"],
        note=first.get("note", ""),
    )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--sizes",
        type=int,
        nargs="+",
        default=[100, 200],
        help="particles per side n (n x n particles); default 100 200",
    )
    parser.add_argument("--steps", type=int, default=200, help="time steps per timed run")
    parser.add_argument("--repeats", type=int, default=2, help="timed runs per round")
    parser.add_argument(
        "--rounds", type=int, default=1, help="times the whole code sequence is repeated per size"
    )
    parser.add_argument(
        "--peers",
        default="jax-sph,pysph",
        help="comma-separated peers to run (jax-sph, pysph) or 'none'",
    )
    parser.add_argument("--jaxsph-python", help="python of the JAX-SPH venv")
    parser.add_argument("--pysph-python", help="python of the PySPH venv")
    parser.add_argument("--pysph-threads", type=int, default=2, help="OpenMP threads")
    parser.add_argument(
        "--skin", type=float, default=None, help="sphjax Model.neighbor_skin (default: the case's)"
    )
    parser.add_argument(
        "--pair-loops",
        nargs="+",
        choices=("xla", "native"),
        default=["xla"],
        help="sphjax's Model.pair_loop values to run (each a row: sphjax, sphjax-native)",
    )
    parser.add_argument("--json", type=Path, help="also write all raw results here")
    args = parser.parse_args(argv)

    import jax

    if jax.config.jax_enable_x64:
        print("note: jax_enable_x64 is set; sphjax runs in float64", file=sys.stderr)

    wanted = [] if args.peers == "none" else [p.strip() for p in args.peers.split(",")]
    peers = {}
    for name in wanted:
        if name not in PEERS:
            parser.error(f"--peers: unknown peer {name!r}; choose from {sorted(PEERS)}")
        python = peer_python(name, getattr(args, name.replace("-", "") + "_python"))
        ok, why = peer_available(name, python)
        if ok:
            peers[name] = python
        else:
            print(f"skipping {name}: {why} (see docs/performance.md)", flush=True)

    print(
        f"{os.cpu_count()} CPUs; {args.steps} steps per run, {args.repeats} runs per "
        f"round, {args.rounds} rounds; compile/warm-up excluded",
        flush=True,
    )
    raw = []
    table = []
    for n in args.sizes:
        per_code: dict[str, list[dict]] = {}
        for _ in range(args.rounds):
            jobs = [(sphjax_code(loop), loop) for loop in args.pair_loops]
            jobs += list(peers.items())
            for name, python in jobs:
                try:
                    if name.startswith("sphjax"):
                        result = run_sphjax(n, args.steps, args.repeats, args.skin, python)
                    else:
                        result = run_peer(
                            name, python, n, args.steps, args.repeats, args.pysph_threads
                        )
                except Exception as err:  # a failing peer must not lose the others
                    print(f"{name} n={n}: {err}", flush=True)
                    continue
                raw.append(dict(result, n=n))
                per_code.setdefault(name, []).append(result)
                speeds = ", ".join(f"{rate(result, s) / 1e6:.3f}" for s in result["seconds"])
                cpu = ", ".join(f"{rate(result, s) / 1e6:.3f}" for s in result["cpu_seconds"])
                print(
                    f"  {name:13s} {result['n_particles']:6d} particles: {speeds} "
                    f"M particle-steps/s; per CPU-s {cpu} (warm-up {result['warmup_s']:.1f} s)",
                    flush=True,
                )
        table.append({name: summarise(rs) for name, rs in per_code.items()})

    print()
    print("M particle-steps/s: wall clock (median, best of all timed runs) and per CPU-second")
    print("(process CPU time, all threads); ratios are sphjax / peer of the wall-clock medians,")
    print("in brackets of the CPU-time rates.")
    header = f"{'code':13s} {'particles':>9s} {'median':>8s} {'best':>8s} {'per-CPU-s':>9s}"
    print(f"{header}  {'vs JAX-SPH':>15s} {'vs PySPH':>15s}")
    for row in table:
        for name, s in row.items():
            ratios = ["", ""]
            if name.startswith("sphjax"):
                for k, peer in enumerate(("jax-sph", "pysph")):
                    if peer in row:
                        wall = s["median"] / row[peer]["median"]
                        cpu = s["cpu"] / row[peer]["cpu"]
                        ratios[k] = f"{wall:.2f}x ({cpu:.2f}x)"
            print(
                f"{name:13s} {s['n_particles']:9d} {s['median'] / 1e6:8.3f} {s['best'] / 1e6:8.3f}"
                f" {s['cpu'] / 1e6:9.3f}  {ratios[0]:>15s} {ratios[1]:>15s}   {s['note']}"
            )
    if args.json:
        args.json.write_text(json.dumps(raw, indent=1))


if __name__ == "__main__":
    main()
