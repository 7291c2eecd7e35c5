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

import ctypes
import os
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
    sys.path.insert(0, str(HERE))
    from pair_loop_ceiling import parse, report, run_sphjax_step

    args = parse(argv, __doc__.split("\n\n")[0], "cxx", "g++", "C++")
    import jax
    from throughput import time_step

    import sphjax

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
            label="FFI pair loop (each pair once) in a jitted scan",
            wall_ms_per_step=1e3 * walls[best] / args.steps,
            cpu_ms_per_step=1e3 * cpus[best] / args.steps,
        )
    ]
    if not args.no_sphjax:
        rows.append(dict(run_sphjax_step(args.n, args.steps, args.repeats), label="sphjax step"))
    report(rows, args)
    return rows


if __name__ == "__main__":
    main()
