"""The pair loop outside XLA, called from a compiled JAX step: the Taylor-Green right-hand
side of ``benchmarks/pair_loop_ceiling.c`` (each pair once, one thread) as an XLA FFI
handler (``benchmarks/pair_loop_ffi.cc``), inside a jitted ``lax.scan`` of kick-drift-kick
steps, timed beside ``sphjax.simulate`` on the same Taylor-Green in the same run.

    python benchmarks/pair_loop_ffi.py --n 200 --steps 100
    python benchmarks/pair_loop_ffi.py --n 40 --steps 10 --no-sphjax   # seconds

What it measures is whether the ceiling survives the trip through XLA (the call, the
copies into cell order and back, the scan around it): wall and CPU milliseconds per step
and the CPU time over sphjax's.  Not part of sphjax: no gradients, the periodic unit
square only.  Needs a C++ compiler (``--cxx``, default ``g++``) and the FFI headers that
jaxlib ships (``jax.ffi.include_dir()``); without a compiler it says so in one line.
"""

from __future__ import annotations

import argparse
import ctypes
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
TARGET = "sphjax_benchmark_taylor_green_rhs"


def build(cxx: str, directory: str) -> str:
    """Compile ``pair_loop_ffi.cc`` into a shared library; its path."""
    import jax

    library = os.path.join(directory, "libpair_loop_ffi.so")
    command = [cxx, "-O3", "-march=native", "-std=c++17", "-shared", "-fPIC", "-w"]
    command += ["-I", jax.ffi.include_dir(), "-o", library, str(HERE / "pair_loop_ffi.cc")]
    subprocess.run(command, check=True, capture_output=True, text=True)
    return library


def register(library: str) -> None:
    """Register the handler with XLA's CPU backend (once per process)."""
    import jax

    handler = ctypes.cdll.LoadLibrary(library).SphjaxTaylorGreenRhs
    jax.ffi.register_ffi_target(TARGET, jax.ffi.pycapsule(handler), platform="cpu")


def simulate_ffi(case, n_steps: int, dt: float):
    """``n_steps`` kick-drift-kick steps of ``case`` (sphjax's Taylor-Green from
    ``benchmarks/throughput.py``) with the FFI right-hand side; the final position and
    velocity.  The first acceleration is the right-hand side at the start, as in sphjax."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    params = case.params.fluid
    h = float(case.model.smoothing_length)
    mass = float(np.asarray(case.state.mass)[0])
    attributes = dict(
        h=np.float32(h),
        mass=np.float32(mass),
        sound_speed=np.float32(params.sound_speed),
        reference_density=np.float32(params.reference_density),
        kinematic_viscosity=np.float32(params.kinematic_viscosity),
    )
    x0 = jnp.asarray(case.state.position, jnp.float32)
    v0 = jnp.asarray(case.state.velocity, jnp.float32)
    shapes = (
        jax.ShapeDtypeStruct(x0.shape, jnp.float32),
        jax.ShapeDtypeStruct(x0.shape[:1], jnp.float32),
    )

    def rhs(x, v):
        return jax.ffi.ffi_call(TARGET, shapes)(x, v, **attributes)

    @jax.jit
    def run(x, v):
        def kick_drift_kick(carry, _):
            x, v, a = carry
            v = v + 0.5 * dt * a  # half-step velocity
            x = jnp.mod(x + dt * v, 1.0)
            a, _ = rhs(x, v)
            return (x, v + 0.5 * dt * a, a), None

        (x, v, _), _ = jax.lax.scan(kick_drift_kick, (x, v, rhs(x, v)[0]), None, length=n_steps)
        return x, v

    return run, x0, v0


def main(argv=None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--n", type=int, default=200, help="particles per side (n x n)")
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--repeats", type=int, default=3, help="timed runs of each row; the best")
    p.add_argument("--cxx", default="g++", help="C++ compiler")
    p.add_argument("--no-sphjax", action="store_true", help="time the FFI step alone")
    args = p.parse_args(argv)
    if args.n < 12:
        p.error(f"--n {args.n}: give at least 12 particles per side (three cells of the support)")
    if args.steps < 1 or args.repeats < 1:
        p.error("--steps and --repeats: give positive numbers")
    if shutil.which(args.cxx) is None:
        p.error(f"--cxx {args.cxx}: no such compiler on PATH (install g++, or name another)")
    import jax

    import sphjax

    sys.path.insert(0, str(HERE))
    from throughput import run_sphjax, time_step

    with tempfile.TemporaryDirectory() as tmp:
        register(build(args.cxx, tmp))
    case = sphjax.cases.taylor_green(
        n=args.n,
        kernel="quintic_spline",
        h_factor=1.0,
        density="summation",
        transport_velocity=False,
    )
    run, x0, v0 = simulate_ffi(case, args.steps, time_step(args.n))
    jax.block_until_ready(run(x0, v0))  # compile
    walls, cpus = [], []
    for _ in range(args.repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        jax.block_until_ready(run(x0, v0))
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    best = min(range(args.repeats), key=lambda i: cpus[i])
    rows = [
        dict(
            label="FFI pair loop in a jitted scan",
            wall_ms_per_step=1e3 * walls[best] / args.steps,
            cpu_ms_per_step=1e3 * cpus[best] / args.steps,
        )
    ]
    if not args.no_sphjax:
        row = run_sphjax(args.n, args.steps, args.repeats)
        i = min(range(args.repeats), key=lambda i: row["cpu_seconds"][i])
        rows.append(
            dict(
                label="sphjax step",
                wall_ms_per_step=1e3 * row["seconds"][i] / args.steps,
                cpu_ms_per_step=1e3 * row["cpu_seconds"][i] / args.steps,
            )
        )
    particles = args.n * args.n
    print(
        f"Taylor-Green {particles} particles, {args.steps} steps, best of {args.repeats}, "
        f"float32, load average {os.getloadavg()[0]:.2f}, {time.strftime('%Y-%m-%d %H:%M')}"
    )
    print(
        f"{'row':32s} {'wall ms':>8s} {'CPU ms':>8s} {'M p-steps/CPU-s':>16s} {'CPU / sphjax':>13s}"
    )
    reference = rows[-1]["cpu_ms_per_step"] if not args.no_sphjax else None
    for row in rows:
        rate = particles / (1e3 * row["cpu_ms_per_step"])
        ratio = "" if reference is None else f"{row['cpu_ms_per_step'] / reference:13.2f}"
        print(
            f"{row['label']:32s} {row['wall_ms_per_step']:8.2f} {row['cpu_ms_per_step']:8.2f} "
            f"{rate:16.2f} {ratio}"
        )
    return rows


if __name__ == "__main__":
    main()
