"""Where one time step's time goes: isolated pieces of the step, each compiled and timed.

    python benchmarks/profile_step.py --case taylor_green --n 200     # 40k particles
    python benchmarks/profile_step.py --case dam_break --n 80
    python benchmarks/profile_step.py --case oscillating_plate --n 32

For one case (float32; ``--pair-loop native``: with the compiled loops of
``Model.pair_loop``) this times, as separately compiled functions on the case's state
(best of ``--repeat``, wall-clock and CPU seconds of this process):

* ``step``: one kick-drift-kick step with its neighbour update, averaged over a
  ``lax.scan`` of ``--steps`` steps (the unit of ``sphjax.simulate``);
* ``rebuild``: one forced neighbour rebuild (jax-md's cell list, with ``--pair-loop
  native`` the compiled one of ``sphjax.native``, and the split into lists per pair of
  systems), and how many of the ``--steps`` steps rebuilt (Verlet skin);
* ``evaluate``, ``update stage`` and ``interaction stage`` of the right-hand side, each
  averaged over a ``lax.scan`` of ``--steps`` evaluations whose positions (stresses)
  change from one to the next, so that XLA cannot hoist them out of the loop;
* ``gathers``: reading the neighbours' fields of every pair list (``x, v, m, rho``,
  and ``p``), summed over the neighbours so that nothing else is computed;
* ``geometry``: the gathers of ``x`` plus the pair geometry (``r_ab``, ``W``, ``grad W``)
  of every list;
* the rest of the step (``step`` minus the right-hand side and the amortised rebuilds)
  is the integrator and the per-step neighbour check.

The neighbours are those ``sphjax.simulate`` runs with: a solid's reference quantities
(its stored pair geometry and ``L0``, eq. 15) computed once (``with_reference``), not in
every timed piece.  A benchmark reports; it asserts nothing.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import jax
import jax.numpy as jnp

import sphjax
from sphjax.integration.simulate import kick_drift_kick
from sphjax.neighbors import update_neighbors
from sphjax.physics import rhs
from sphjax.physics.pairs import Geometry
from sphjax.physics.rhs import build_neighbors, with_reference

#: the update stage's fields that the interaction stage reads (pressure, which follows the
#: density; the walls' extrapolated velocity; the solid's stress)
UPDATED = ("p", "v_viscous", "PL0")


def make_case(name: str, n: int, pair_loop: str = "xla"):
    if name == "taylor_green":
        case = sphjax.cases.taylor_green(
            n=n,
            kernel="quintic_spline",
            h_factor=1.0,
            density="summation",
            transport_velocity=False,
        )
        dt = 0.25 / n / 11.0
    else:
        case = getattr(sphjax.cases, name)(n=n)
        dt = case.dt
    return case.replace(model=dataclasses.replace(case.model, pair_loop=pair_loop)), dt


def timed(fn, *args, repeat=3):
    jax.block_until_ready(fn(*args))
    wall, cpu = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        jax.block_until_ready(fn(*args))
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return min(wall), min(cpu)


def profile(name: str, n: int, steps: int, repeat: int, pair_loop: str = "xla") -> dict:
    case, dt = make_case(name, n, pair_loop)
    model, params = case.model, case.params
    neighbors = build_neighbors(case.state, model, compact_rows=True)
    # as simulate: a solid's reference quantities once per run
    neighbors = jax.jit(with_reference, static_argnames="model")(case.state, neighbors, model)
    state = jax.jit(rhs.evaluate, static_argnames="model")(case.state, neighbors, model, params)
    geometry = Geometry.of(model)

    @jax.jit
    def run(state, neighbors):
        def body(carry, _):
            s, nb, count = carry
            s2, nb2 = kick_drift_kick(s, nb, dt, model, params)
            if nb.search is not None:
                moved = jnp.any(nb2.search.reference_position != nb.search.reference_position)
                count = count + moved
            return (s2, nb2, count), None

        return jax.lax.scan(body, (state, neighbors, jnp.int32(0)), None, length=steps)[0]

    rebuilds = int(run(state, neighbors)[2])
    out = {"particles": case.n_particles, "steps": steps, "rebuilds": rebuilds}
    w, c = timed(run, state, neighbors, repeat=repeat)
    out["step"] = (w / steps, c / steps)

    @jax.jit
    def rebuild(position, neighbors):
        return update_neighbors(position, neighbors, rebuild=True)

    out["rebuild"] = timed(rebuild, state.position, neighbors, repeat=repeat)

    def scanned(piece, moving):
        """``piece`` ``steps`` times in a ``lax.scan``, its input ``moving`` nudged by its
        output each time (so each evaluation is done), per evaluation."""

        @jax.jit
        def run(moving, *rest):
            def body(m, _):
                out = piece(m, *rest)
                nudge = sum(jnp.sum(leaf) for leaf in jax.tree_util.tree_leaves(out))
                return m + 1e-12 * nudge, None

            return jax.lax.scan(body, moving, None, length=steps)[0]

        return run

    def evaluate(x, state, neighbors):
        out = rhs.evaluate(state.replace(position=x), neighbors, model, params, density_step=dt)
        return out.acceleration, out.density_rate

    def update_views(x, state, neighbors):
        return rhs.update_stage(state.replace(position=x), neighbors, model, params, dt)

    def update(x, state, neighbors):
        # what the interaction stage reads of it
        views = update_views(x, state, neighbors)
        return [v[k] for v in views for k in UPDATED if k in v]

    run = scanned(evaluate, state.position)
    w, c = timed(run, state.position, state, neighbors, repeat=repeat)
    out["evaluate"] = (w / steps, c / steps)
    run = scanned(update, state.position)
    w, c = timed(run, state.position, state, neighbors, repeat=repeat)
    out["update stage"] = (w / steps, c / steps)
    views = jax.jit(update_views)(state.position, state, neighbors)

    def interact(scale, views, neighbors):
        # every float field of the update stage scaled by (1 + scale): none is constant
        views = jax.tree_util.tree_map(
            lambda q: q * (1 + scale) if jnp.issubdtype(q.dtype, jnp.floating) else q, views
        )
        ctx = rhs.Context(params, geometry, model.pair_adjoint, model.pair_block)
        return rhs.interaction_stage(views, neighbors, model, ctx)

    run = scanned(interact, jnp.zeros((), state.position.dtype))
    w, c = timed(run, jnp.zeros((), state.position.dtype), views, neighbors, repeat=repeat)
    out["interaction stage"] = (w / steps, c / steps)

    def lists(views):
        for (i, j), pl in neighbors.pairs.items():
            rows = (
                views[i]
                if pl.members is None
                else jax.tree_util.tree_map(
                    lambda q, m=pl.members, n=pl.n_rows: q[jnp.minimum(m, n - 1)], views[i]
                )
            )
            yield rows, views[j], pl

    @jax.jit
    def gathers(views):
        total = 0.0
        for _rows, cols, pl in lists(views):
            j = jnp.minimum(pl.idx, pl.n_cols - 1)
            for key in ("x", "v", "m", "rho", "p"):
                if key in cols:
                    total = total + jnp.sum(cols[key][j], axis=1).sum()
        return total

    out["gathers"] = timed(gathers, views, repeat=repeat)

    @jax.jit
    def pair_geometry(views):
        total = 0.0
        for rows, cols, pl in lists(views):
            valid = pl.idx < pl.n_cols
            xb = cols["x"][jnp.where(valid, pl.idx, 0)]
            pair = geometry.pairs(rows["x"][:, None], xb, valid)
            total = total + jnp.sum(pair.w) + jnp.sum(pair.grad_w)
        return total

    out["geometry"] = timed(pair_geometry, views, repeat=repeat)
    slots = {f"{i}{j}": pl.idx.shape for (i, j), pl in neighbors.pairs.items()}
    out["lists"] = slots
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", default="taylor_green")
    parser.add_argument("--n", type=int, default=200)
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument(
        "--pair-loop", choices=("xla", "native"), default="xla", help="Model.pair_loop"
    )
    args = parser.parse_args(argv)
    out = profile(args.case, args.n, args.steps, args.repeat, args.pair_loop)
    print(
        f"{args.case} n={args.n}: {out['particles']} particles, lists {out['lists']}, "
        f"{out['rebuilds']} rebuilds in {out['steps']} steps"
    )
    print(f"{'piece':<20} {'wall ms':>9} {'cpu ms':>9}")
    for key in ("step", "rebuild", "evaluate", "update stage", "interaction stage"):
        w, c = out[key]
        print(f"{key:<20} {w * 1e3:9.2f} {c * 1e3:9.2f}")
    for key in ("gathers", "geometry"):
        w, c = out[key]
        print(f"  {key:<18} {w * 1e3:9.2f} {c * 1e3:9.2f}")
    frac = out["rebuilds"] / out["steps"]
    w = out["step"][0] - out["evaluate"][0] - frac * out["rebuild"][0]
    c = out["step"][1] - out["evaluate"][1] - frac * out["rebuild"][1]
    print(f"{'integrator + check':<20} {w * 1e3:9.2f} {c * 1e3:9.2f}")


if __name__ == "__main__":
    main()
