"""Time JAX-SPH 0.1.0 on the Taylor-Green vortex (run with the JAX-SPH venv's python).

``--dim 2``: the periodic unit square; ``--dim 3``: JAX-SPH's own 3D Taylor-Green set-up,
the periodic cube ``[0, 2 pi)^3`` with ``u = sin x cos y cos z``,
``v = -cos x sin y cos z``, ``w = 0`` (``nu = 0.02``).

JAX-SPH's wheel ships no case files, so this script defines the Taylor-Green set-up as a
``jax_sph.case_setup.SimulationSetup`` and then does what ``jax_sph.simulate.simulate``
does: a ``WCSPH`` solver (standard SPH, ``tvf = 0``, density summation, quintic spline
with ``h = dx``), a Sparse jax-md neighbour list from ``jax_sph.partition`` with
``r_cutoff`` = kernel support (3h, no skin: rebuilt every step), ``si_euler`` as the
integrator (one right-hand side per step), jitted, stepped from a Python loop that checks
``did_buffer_overflow`` after every step exactly as ``simulate`` does (minus file output).

Prints one JSON line: particles, steps, seconds of each timed run, warm-up seconds.
"""

import argparse
import json
import time

import jax

jax.config.update("jax_enable_x64", False)  # float32, as the sphjax run

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from jax_sph import partition  # noqa: E402
from jax_sph.case_setup import SimulationSetup  # noqa: E402
from jax_sph.defaults import set_defaults  # noqa: E402
from jax_sph.integrator import si_euler  # noqa: E402
from jax_sph.jax_md.partition import Sparse  # noqa: E402
from jax_sph.solver import WCSPH  # noqa: E402
from jax_sph.utils import Tag  # noqa: E402


class TaylorGreen(SimulationSetup):
    """Periodic unit square, ``u = -cos(2 pi x) sin(2 pi y)``, ``v = sin(2 pi x) cos(2 pi y)``;
    in 3D the periodic cube of side ``2 pi`` (JAX-SPH's 3D set-up)."""

    def _box_size2D(self, n_walls):
        return np.array([1.0, 1.0])

    def _box_size3D(self, n_walls):
        return 2.0 * np.pi * np.ones(3)

    def _init_walls_2d(self):
        pass

    def _init_walls_3d(self):
        pass

    def _init_velocity2D(self, r):
        x, y = r
        return jnp.array(
            [
                -jnp.cos(2.0 * jnp.pi * x) * jnp.sin(2.0 * jnp.pi * y),
                jnp.sin(2.0 * jnp.pi * x) * jnp.cos(2.0 * jnp.pi * y),
            ]
        )

    def _init_velocity3D(self, r):
        x, y, z = r
        return jnp.array(
            [
                jnp.sin(x) * jnp.cos(y) * jnp.cos(z),
                -jnp.cos(x) * jnp.sin(y) * jnp.cos(z),
                jnp.zeros_like(x),
            ]
        )

    def _external_acceleration_fn(self, r):
        return jnp.zeros_like(r)

    def _boundary_conditions_fn(self, state):
        return state


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--n", type=int, required=True, help="particles per side")
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--dt", type=float, required=True)
    parser.add_argument("--threads", type=int, default=2, help="unused (XLA uses all cores)")
    parser.add_argument("--dim", type=int, default=2, choices=[2, 3])
    parser.add_argument(
        "--warmup-steps", type=int, default=20, help="untimed steps after compiling"
    )
    args = parser.parse_args()

    cfg = set_defaults()
    cfg.config = "tgv.yaml"
    cfg.case.source = "tgv.py"
    cfg.case.dim = args.dim
    cfg.case.dx = (1.0 if args.dim == 2 else 2.0 * np.pi) / args.n
    cfg.case.viscosity = 0.01 if args.dim == 2 else 0.02
    cfg.case.u_ref = 1.0
    cfg.case.c_ref_factor = 10.0
    cfg.solver.name = "SPH"
    cfg.solver.tvf = 0.0
    cfg.solver.dt = args.dt
    cfg.solver.t_end = 1.0
    cfg.kernel.name = "QSK"
    cfg.dtype = "float32"

    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()):
        (cfg, box_size, state, g_ext_fn, bc_fn, nw_fn, eos_fn, _key, displacement_fn, shift_fn) = (
            TaylorGreen(cfg).initialize()
        )
    solver = WCSPH(
        displacement_fn,
        eos_fn,
        g_ext_fn,
        cfg.case.dx,
        cfg.case.dim,
        cfg.solver.dt,
        cfg.case.c_ref,
        cfg.solver.eta_limiter,
        cfg.solver.name,
        cfg.kernel.name,
        cfg.solver.is_bc_trick,
        cfg.solver.density_evolution,
        cfg.solver.artificial_alpha,
        cfg.solver.free_slip,
        cfg.solver.density_renormalize,
        cfg.solver.heat_conduction,
    )
    forward = solver.forward_wrapper()
    neighbor_fn = partition.neighbor_list(
        displacement_fn,
        box_size,
        r_cutoff=solver._kernel_fn.cutoff,
        backend=cfg.nl.backend,
        capacity_multiplier=1.25,
        mask_self=False,
        format=Sparse,
        num_particles_max=state["r"].shape[0],
        num_partitions=cfg.nl.num_partitions,
        pbc=np.array(cfg.case.pbc),
    )
    num_particles = (state["tag"] != Tag.PAD_VALUE).sum()
    neighbors = neighbor_fn.allocate(state["r"], num_particles=num_particles)
    advance = jax.jit(si_euler(cfg.solver.tvf, forward, shift_fn, bc_fn, nw_fn))
    dt = cfg.solver.dt

    def run(state, neighbors, steps):
        # the loop of jax_sph.simulate.simulate, without writing files
        for _ in range(steps):
            state_, neighbors_ = advance(dt, state, neighbors)
            if neighbors_.did_buffer_overflow:
                neighbors = neighbor_fn.allocate(state["r"], num_particles=num_particles)
                state, neighbors = advance(dt, state, neighbors)
            else:
                state, neighbors = state_, neighbors_
        state["v"].block_until_ready()
        return state, neighbors

    t0 = time.perf_counter()
    state, neighbors = advance(0.0, state, neighbors)  # compile, initial accelerations
    state, neighbors = run(state, neighbors, args.warmup_steps)
    warmup = time.perf_counter() - t0
    seconds, cpu_seconds = [], []
    for _ in range(args.repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        state, neighbors = run(state, neighbors, args.steps)
        seconds.append(time.perf_counter() - t0)
        cpu_seconds.append(time.process_time() - c0)
    finite = bool(jnp.all(jnp.isfinite(state["u"])))
    print(
        json.dumps(
            dict(
                code="jax-sph",
                n_particles=int(state["r"].shape[0]),
                steps=args.steps,
                seconds=seconds,
                cpu_seconds=cpu_seconds,
                warmup_s=warmup,
                rhs_per_step=1,
                finite=finite,
                dtype=str(state["r"].dtype),
                note=f"jax-sph 0.1.0 (jax {jax.__version__}), {state['r'].dtype}, Sparse list, "
                "no skin, si_euler",
            )
        )
    )


if __name__ == "__main__":
    main()
