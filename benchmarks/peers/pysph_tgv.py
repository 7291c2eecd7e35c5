"""Time PySPH 1.0b2 on the 2D Taylor-Green vortex (run with the PySPH venv's python).

Runs PySPH's own bundled example ``pysph.examples.taylor_green`` (what
``pysph run taylor_green`` starts) through its Python API with
``--openmp --nx N --max-steps ... --disable-output``: its default scheme (TVF, Adami et
al. 2013) with the quintic spline, ``h = dx``, ``c0 = 10 U``, ``nu = 0.01`` and
``dt = 0.25 h / (c0 + U)``, i.e. the same resolution, kernel support and time step as the
sphjax run.  Its integrator (``PECIntegrator``) evaluates the forces twice per step; we
count time steps, not force evaluations.  ``OMP_NUM_THREADS`` sets the threads.

Time stamps are taken after every step by a post-step callback, so the set-up, code
generation and compilation are excluded: the first 20 steps are warm-up, then
``--repeats`` blocks of ``--steps`` steps are timed.  Prints one JSON line.
"""

import argparse
import json
import os
import sys
import tempfile
import time

WARMUP_STEPS = 20


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--n", type=int, required=True, help="particles per side")
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--dt", type=float, required=True, help="expected time step (checked)")
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    os.environ["OMP_NUM_THREADS"] = str(args.threads)

    from pysph.examples.taylor_green import TaylorGreen

    stamps = []

    class TimedTaylorGreen(TaylorGreen):
        def post_step(self, solver):
            stamps.append((time.perf_counter(), time.process_time()))

    total = WARMUP_STEPS + args.repeats * args.steps
    with tempfile.TemporaryDirectory() as out:
        app = TimedTaylorGreen(fname="tg_bench", output_dir=out)
        argv = [
            "--openmp",
            "--nx",
            str(args.n),
            "--max-steps",
            str(total),
            "--disable-output",
            "--pfreq",
            str(10 * total),
            "-q",
            "-d",
            out,
        ]
        t0 = time.perf_counter()
        real_stdout = sys.stdout
        sys.stdout = sys.stderr  # PySPH talks; keep stdout for the JSON line
        try:
            app.run(argv)
        finally:
            sys.stdout = real_stdout
        fluid = [pa for pa in app.particles if pa.name == "fluid"][0]
        n_particles = fluid.get_number_of_particles(real=True)  # periodic ghosts excluded
        dt = app.solver.dt
    if abs(dt - args.dt) > 1e-6 * args.dt:
        raise SystemExit(f"PySPH chose dt = {dt}, expected {args.dt}")
    marks = [stamps[WARMUP_STEPS - 1 + k * args.steps] for k in range(args.repeats + 1)]
    seconds = [b[0] - a[0] for a, b in zip(marks[:-1], marks[1:], strict=True)]
    cpu_seconds = [b[1] - a[1] for a, b in zip(marks[:-1], marks[1:], strict=True)]
    import pysph

    print(
        json.dumps(
            dict(
                code="pysph",
                n_particles=int(n_particles),
                steps=args.steps,
                seconds=seconds,
                cpu_seconds=cpu_seconds,
                warmup_s=stamps[WARMUP_STEPS - 1][0] - t0,
                rhs_per_step=2,
                dt=dt,
                note=f"pysph {pysph.__version__}, float64, OpenMP {args.threads} threads, "
                "TVF scheme, PEC integrator (2 force evaluations per step)",
            )
        )
    )


if __name__ == "__main__":
    main()
