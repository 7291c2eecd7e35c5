"""A channel with an inflow and an outflow against plane Poiseuille flow.

    python docs/scripts/validate_open_boundary.py --profile parabolic --n 10 --length 2 \
        --flow-throughs 3                    # the test's run (float64)
    python docs/scripts/validate_open_boundary.py --profile uniform --n 20 --length 3

`sphjax.cases.channel_flow`: fluid enters at x = 0 with the mean speed U (a uniform or a
parabolic profile) and leaves at x = L.  Over the last flow-through time it prints the
mean speed per lattice row in three slabs against ``u(y) = 4 u_max y (H - y) / H^2``
(the largest error over u_max and the L2 relative error), the mass flux across five
slabs over the inflow's, the fluid's density range and how close it came to the walls.
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

import sphjax
from sphjax.cases import channel_flow
from sphjax.core.state import Kind
from sphjax.observables import channel_mass_flux, channel_profile, poiseuille_profile


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profile", default="parabolic", choices=("parabolic", "uniform"))
    parser.add_argument("--n", type=int, default=10)
    parser.add_argument("--length", type=float, default=2.0)
    parser.add_argument("--flow-throughs", type=float, default=3.0)
    parser.add_argument("--float32", action="store_true")
    args = parser.parse_args()
    jax.config.update("jax_enable_x64", not args.float32)
    case = channel_flow(n=args.n, length=args.length, profile=args.profile)
    t_end = args.flow_throughs * case.info["flow_through_time"]
    start = time.perf_counter()
    # frames 0.0371 H / U apart: no lattice row moves a whole number of spacings between
    # them (frames in step with the rows would sample the slabs stroboscopically)
    save_every = max(1, round(0.0371 / case.dt))
    trajectory = sphjax.simulate(case, t_end=t_end, save_every=save_every)
    wall = time.perf_counter() - start
    info = case.info
    L, H, U, dx, n = info["length"], info["height"], info["inflow_velocity"], info["dx"], info["n"]
    print(
        f"{args.profile} n={n} L={L / H:g} H: {case.n_particles} particles, "
        f"{round(t_end / case.dt)} steps, {wall:.0f} s"
    )
    states = trajectory.states
    fluid = np.asarray(states.kind) == Kind.FLUID
    rho = np.asarray(states.density)[fluid] / float(case.params.reference_density)
    y = np.asarray(states.position)[..., 1][fluid]
    print(
        f"fluid density {rho.min():.4f} .. {rho.max():.4f} rho0; closest to a wall "
        f"{min(y.min(), H - y.max()) / dx:.3f} dx"
    )
    first = int(len(trajectory) * (1.0 - 1.0 / args.flow_throughs))
    late = jax.tree_util.tree_map(lambda a: a[first:], states)
    for a, b in ((0.1, 0.3), (0.3, 0.6), (0.6, 0.9)):
        rows, u = channel_profile(late, case, a * L, b * L)
        exact = poiseuille_profile(rows, H, U)
        worst = np.max(np.abs(u - exact)) / info["peak_velocity"]
        l2 = np.linalg.norm(u - exact) / np.linalg.norm(exact)
        print(f"profile {a:.1f}-{b:.1f} L: max error {worst:.4f} u_max, L2 {l2:.4f}")
    rows = (np.arange(n) + 0.5) * dx
    u_in = poiseuille_profile(rows, H, U) if args.profile == "parabolic" else np.full(n, U)
    mass = float(np.asarray(case.state.mass)[np.asarray(case.state.kind) == Kind.OPEN][0])
    inflow = mass / dx * float(np.sum(u_in))
    fluxes = [
        channel_mass_flux(late, case, x - dx, x + dx) / inflow
        for x in (0.1 * L, 0.3 * L, 0.5 * L, 0.7 * L, 0.9 * L)
    ]
    print("mass flux / inflow at 0.1 .. 0.9 L:", " ".join(f"{f:.4f}" for f in fluxes))


if __name__ == "__main__":
    main()
