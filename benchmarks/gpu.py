"""The GPU benchmark: 2D Taylor-Green at 1M and 4M particles, 3D ABC flow at 1M, float32,
forward and one gradient; prints particle-steps per second.

    python benchmarks/gpu.py              # on a GPU machine (about 5-8 minutes)
    python benchmarks/gpu.py --smoke      # tiny sizes, any machine (a check that it runs)

The cases are those of ``benchmarks/scaling.py`` (periodic lattice, no packing, quintic
spline, ``h = dx``).  Per case: ``sphjax.simulate`` of ``--steps`` steps (compiled chunks,
after an untimed warm-up call), then ``jax.grad`` of the kinetic energy after
``--grad-steps`` steps w.r.t. the viscosity (``checkpoint_every``, compiled, after an
untimed warm-up call).  Particle-interactions per second (one pass over the neighbour
list per step: particles x mean neighbours x steps / s) are printed next to
TrixiParticles' published H100 figures for one interaction pass (2.4e9 in 2D, 3.4e8 in 3D)
for orientation; one sphjax step does two passes (density, then momentum).  A benchmark
reports; it asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from scaling import make_case  # noqa: E402

#: (dim, particles) of the full run and of ``--smoke``
FULL = ((2, 1_000_000), (2, 4_000_000), (3, 1_000_000))
SMOKE = ((2, 400), (3, 512))
TRIXI_H100 = {2: 2.4e9, 3: 3.4e8}


def bench(dim: int, n_particles: int, steps: int, grad_steps: int, checkpoint: int) -> dict:
    import jax
    import jax.numpy as jnp
    import numpy as np

    import sphjax
    from sphjax.physics.rhs import build_neighbors

    case, dt = make_case(dim, n_particles)
    n = case.n_particles
    idx = np.asarray(build_neighbors(case.state, case.model).search.idx)
    mean_neighbours = float((idx < n).sum(axis=1).mean())

    def forward():
        traj = sphjax.simulate(case, n_steps=steps, save_every=steps, dt=dt)
        return jax.block_until_ready(traj.states.position)

    def loss(nu):
        params = case.params.replace(kinematic_viscosity=nu)
        final = sphjax.simulate(
            case, params, n_steps=grad_steps, dt=dt, checkpoint_every=checkpoint
        ).final
        return 0.5 * jnp.sum(final.mass * jnp.sum(final.velocity**2, axis=-1))

    grad = jax.jit(jax.grad(loss))
    nu0 = jnp.asarray(case.params.kinematic_viscosity)
    out = dict(dim=dim, particles=n, mean_neighbours=mean_neighbours)
    for name, fn, k in (("forward", forward, steps), ("gradient", lambda: grad(nu0), grad_steps)):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        out[f"{name}_warmup_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        value = jax.block_until_ready(fn())
        seconds = time.perf_counter() - t0
        out[f"{name}_rate"] = n * k / seconds
        if name == "gradient":
            out["gradient"] = float(value)
    out["interactions_per_s"] = out["forward_rate"] * mean_neighbours
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--smoke", action="store_true", help="tiny sizes (any machine)")
    parser.add_argument("--steps", type=int, default=None, help="forward steps")
    parser.add_argument("--grad-steps", type=int, default=None, help="steps of the gradient")
    parser.add_argument("--json", type=Path, help="also write the results here")
    args = parser.parse_args(argv)
    import jax

    sizes = SMOKE if args.smoke else FULL
    steps = args.steps or (5 if args.smoke else 100)
    grad_steps = args.grad_steps or (4 if args.smoke else 20)
    device = jax.devices()[0]
    print(f"device: {device.platform} {getattr(device, 'device_kind', '')}, float32", flush=True)
    results = []
    for dim, n in sizes:
        res = bench(dim, n, steps, grad_steps, checkpoint=max(1, grad_steps // 2))
        results.append(res)
        print(
            f"{dim}D {res['particles']:>9d} particles ({res['mean_neighbours']:.0f} "
            f"neighbours): forward {res['forward_rate']:.3e} particle-steps/s "
            f"({res['interactions_per_s']:.2e} particle-interactions/s per pass-step; "
            f"TrixiParticles H100, one pass: {TRIXI_H100[dim]:.1e}), "
            f"gradient {res['gradient_rate']:.3e} particle-steps/s; warm-up "
            f"{res['forward_warmup_s']:.0f} s + {res['gradient_warmup_s']:.0f} s",
            flush=True,
        )
    if args.json:
        args.json.write_text(json.dumps(dict(device=str(device), results=results), indent=1))


if __name__ == "__main__":
    main()
