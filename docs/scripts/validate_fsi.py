"""Elastic plate under a hydrostatic water column: mid-span deflection against
Euler-Bernoulli theory, and against the same plate without fluid under the same load.

    python docs/scripts/validate_fsi.py --n 2 3 4 --depth 0.5 --out docs/data/fsi_plate.jsonl
    python docs/scripts/validate_fsi.py --n 2 --substeps 1 auto --out docs/data/fsi_split.jsonl

For each resolution ``n`` (particles through the plate thickness) it runs
``hydrostatic_fsi_plate(n, depth)`` for ``--periods`` dry first-mode periods and a "dry"
run: the plate alone (no fluid, no walls) with its weight raised to the total load,
gravity ``g (rho_f H + rho_s t) / (rho_s t)``.  Both report the mean mid-span deflection
over the second half of the run and ``(max + min) / 2`` over it, divided by the analytic
``-q L^4 / (384 D)``.  The ratio of the two runs isolates the coupling (how much of the
column's weight reaches the plate) from the plate's own discretisation error.
``--substeps`` runs the coupled plate once per value (split integration,
``SolidSystem.substeps``; ``auto``: as many solid steps as fit in the fluid's).
"""

from __future__ import annotations

import argparse
import json
import time

import jax
import numpy as np

import sphjax
from sphjax.cases.fsi import hydrostatic_fsi_plate, midspan_deflection
from sphjax.core.state import Kind


def dry_case(case):
    """The plate of ``case`` alone, its gravity raised so its weight is the total load."""
    kind = np.asarray(case.state.kind)
    keep = kind >= Kind.SOLID
    n_all = len(kind)

    def take(a):
        return a[keep] if getattr(a, "ndim", 0) >= 1 and a.shape[0] == n_all else a

    state = jax.tree_util.tree_map(take, case.state)
    info = case.info
    p = case.params
    load = info["gravity"] * (
        float(p.reference_density) * info["depth"] + float(p.solid_density) * info["thickness"]
    )
    g_eff = load / (float(p.solid_density) * info["thickness"])
    params = sphjax.make_params(
        2,
        gravity=(0.0, -g_eff),
        young_modulus=p.young_modulus,
        poisson_ratio=p.poisson_ratio,
        solid_density=p.solid_density,
    )
    model = case.model.replace(systems=(case.model.systems[2],))
    shift = int((~keep).sum())
    midspan = tuple(int(i) - shift for i in info["midspan_indices"])
    dt = sphjax.stable_time_step(state, model, params, solid_cfl=0.5)
    return sphjax.Case(
        "dry_plate", state, model, params, dt, case.t_end, dict(info, midspan_indices=midspan)
    )


def measure(case, t_end):
    n_steps = int(round(t_end / case.dt))
    start = time.perf_counter()
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=max(1, n_steps // 200))
    wall = time.perf_counter() - start
    w = np.asarray(midspan_deflection(traj, case)) / case.info["reference_deflection"]
    late = w[len(w) // 2 :]
    return dict(
        particles=case.n_particles,
        steps=n_steps,
        wall_s=round(wall, 1),
        mean=float(late.mean()),
        mid_range=float(0.5 * (late.max() + late.min())),
        series=[float(v) for v in w[:: max(1, len(w) // 50)]],
    )


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--n", type=int, nargs="+", default=[2, 3, 4])
    p.add_argument("--depth", type=float, default=0.5)
    p.add_argument("--periods", type=float, default=8.0)
    p.add_argument("--dry-only", action="store_true")
    p.add_argument("--no-dry", action="store_true")
    p.add_argument("--substeps", nargs="+", default=["1"])
    p.add_argument("--out", required=True)
    args = p.parse_args(argv)
    for n in args.n:
        case = hydrostatic_fsi_plate(n=n, depth=args.depth)
        t_end = args.periods * case.info["dry_period"]
        row = dict(n=n, depth=case.info["depth"], dx=case.info["dx"], t_end=t_end)
        row["reference_deflection"] = case.info["reference_deflection"]
        if not args.no_dry:
            row["dry"] = measure(dry_case(case), t_end)
        for substeps in [] if args.dry_only else args.substeps:
            k = substeps if substeps == "auto" else int(substeps)
            split = hydrostatic_fsi_plate(n=n, depth=args.depth, substeps=k)
            row["fsi"] = dict(measure(split, t_end), substeps=split.info["substeps"])
            row["fsi"]["dt"] = split.dt
            print(json.dumps(row, default=str)[:400], flush=True)
            with open(args.out, "a") as f:
                f.write(json.dumps(row) + "\n")
        if args.dry_only:
            print(json.dumps(row, default=str)[:400], flush=True)
            with open(args.out, "a") as f:
                f.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
