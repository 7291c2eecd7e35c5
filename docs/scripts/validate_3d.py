"""Run the three-dimensional validation cases; results go to docs/figures/validation_3d.json.

    python docs/scripts/validate_3d.py abc --n 12 16 20
    python docs/scripts/validate_3d.py abc --n 16 --lattice        # the unrelaxed lattice start
    python docs/scripts/validate_3d.py tank --n 8 12
    python docs/scripts/validate_3d.py duct --n 8 12 16
    python docs/scripts/validate_3d.py dam --n 8                # --t-end in T = t sqrt(2g/L)
    python docs/scripts/validate_3d.py cantilever --n 4 6 8
    python docs/scripts/validate_3d.py spheric --n 8 --t-end 1.5   # SPHERIC benchmark 2
    python docs/scripts/validate_3d.py fsi --n 2 3 --x64   # plate under water, 3D against 2D
    python docs/scripts/validate_3d.py figures        # docs/img/*_3d.png from the JSON file

Each run is stored in the JSON file under its own key (re-running replaces it) and printed
as a Markdown table row; docs/validation_3d.md holds the tables.  Float32, as a user runs
(``--x64``: float64).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import time

import jax
import numpy as np

import sphjax
from sphjax import Kind
from sphjax.cases import (
    abc_velocity,
    duct_velocity,
    oscillation_stats,
    surge_front,
    tip_displacement,
    water_height,
)
from sphjax.observables import probe_pressure

DOCS = pathlib.Path(__file__).resolve().parents[1]
# Martin & Moyce (1952), Table 2 (height 2L), (T, Z/L): the reference of record.
MARTIN_MOYCE = np.array(
    [
        (0.41, 1.11),
        (0.84, 1.22),
        (1.19, 1.44),
        (1.43, 1.67),
        (1.63, 1.89),
        (1.83, 2.11),
        (1.98, 2.33),
        (2.20, 2.56),
        (2.32, 2.78),
        (2.51, 3.00),
    ]
)
RESULTS = DOCS / "figures" / "validation_3d.json"


def _store(key, record):
    data = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    data[key] = record
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(data, indent=1, sort_keys=True))


def abc(n, reynolds, t_end, lattice, frames=10):
    t0 = time.perf_counter()
    kw = dict(disorder=0.0, relax_iterations=0) if lattice else {}
    case = sphjax.cases.abc_flow_3d(n=n, reynolds=reynolds, **kw)
    start = time.perf_counter() - t0
    n_steps = frames * int(np.ceil(t_end / case.dt / frames))
    t0 = time.perf_counter()
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=n_steps // frames, dt=t_end / n_steps)
    wall = time.perf_counter() - t0
    t = np.asarray(traj.times)
    v = np.asarray(traj.states.velocity)
    m = np.asarray(traj.states.mass)
    ke = 0.5 * np.sum(m * np.sum(v**2, -1), -1)
    exact = abc_velocity(np.asarray(traj.states.position), t[:, None], case)
    error = np.sqrt(np.mean(np.sum((v - exact) ** 2, -1), -1) / np.mean(np.sum(exact**2, -1), -1))
    ke_exact = np.exp(2 * case.info["decay_rate"] * t)
    record = dict(
        n=n,
        reynolds=reynolds,
        start="lattice" if lattice else "relaxed",
        particles=case.n_particles,
        steps=n_steps,
        times=t.tolist(),
        ke_ratio=(ke / ke[0]).tolist(),
        ke_exact=ke_exact.tolist(),
        velocity_error=error.tolist(),
        start_s=start,
        wall_s=wall,
    )
    _store(f"abc_n{n}_re{reynolds:g}_{record['start']}", record)
    print(
        f"| {n} | {reynolds:g} | {record['start']} | {ke[-1] / ke[0]:.4f} ({ke_exact[-1]:.4f}) "
        f"| {ke[-1] / ke[0] / ke_exact[-1] - 1:+.2%} | {np.max(np.diff(ke)) / ke[0]:+.2%} "
        f"| {error[1]:.2%} | {error.max():.2%} | {start:.0f} | {wall:.0f} |"
    )


def cantilever(n, t_end, save_every=20):
    t0 = time.perf_counter()
    case = sphjax.cases.cantilever_3d(n=n)
    n_steps = save_every * int(np.ceil(t_end / case.dt / save_every))
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=save_every)
    wall = time.perf_counter() - t0
    u = np.asarray(tip_displacement(traj, case))
    stats = oscillation_stats(np.asarray(traj.times), u[:, 1])
    info = case.info
    record = dict(
        n=n,
        particles=case.n_particles,
        steps=n_steps,
        times=np.asarray(traj.times).tolist(),
        tip_y=u[:, 1].tolist(),
        tip_z_max=float(np.abs(u[:, 2]).max()),
        period=stats["period"],
        amplitude=stats["amplitude"],
        mean=stats["mean"],
        reference_period=info["period"],
        reference_amplitude=info["tip_amplitude"],
        wall_s=wall,
    )
    _store(f"cantilever_n{n}", record)
    print(
        f"| {n} | {case.n_particles} | {n_steps} | {wall:.0f} | {stats['period']:.4f} | "
        f"{stats['period'] / info['period'] - 1:+.1%} | {stats['amplitude']:.3e} | "
        f"{stats['amplitude'] / info['tip_amplitude'] - 1:+.1%} |"
    )


def tank(n, width, t_end, frames=10):
    t0 = time.perf_counter()
    case = sphjax.cases.hydrostatic_tank_3d(n=n, width=width)
    n_steps = frames * int(np.ceil(t_end / case.dt / frames))
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=n_steps // frames)
    wall = time.perf_counter() - t0
    info = case.info
    g, H = info["gravity"], info["height"]
    fluid = np.asarray(case.state.kind) == Kind.FLUID
    x = np.asarray(traj.states.position)[:, fluid]
    p = np.asarray(traj.states.pressure)[:, fluid]
    bottom = [float(np.polyfit(x[i, :, 2], p[i], 1)[1]) for i in range(len(traj.times))]
    speed = np.linalg.norm(np.asarray(traj.states.velocity)[:, fluid], axis=-1).max(axis=-1)
    inside = bool(
        np.all(x[..., 2] > 0)
        & np.all((x[..., :2] > 0) & (x[..., :2] < [info["width"], info["depth"]]))
    )
    record = dict(
        n=n,
        width=info["width"],
        particles=case.n_particles,
        fluid=int(fluid.sum()),
        steps=n_steps,
        times=np.asarray(traj.times).tolist(),
        bottom_pressure=bottom,
        reference=1000.0 * g * H,
        max_speed=(speed / np.sqrt(g * H)).tolist(),
        inside=inside,
        wall_s=wall,
    )
    _store(f"tank_n{n}_w{width:g}", record)
    print(
        f"| {n} | {info['width']:g} x {info['depth']:g} | {int(fluid.sum())} | {n_steps} | "
        f"{bottom[-1] / (1000.0 * g * H) - 1:+.2%} | {speed[-1] / np.sqrt(g * H):.2e} | "
        f"{inside} | {wall:.0f} |"
    )


def duct(n, t_end, frames=10):
    t0 = time.perf_counter()
    case = sphjax.cases.duct_poiseuille_3d(n=n)
    n_steps = frames * int(np.ceil(t_end / case.dt / frames))
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=n_steps // frames, dt=t_end / n_steps)
    wall = time.perf_counter() - t0
    info = case.info
    a, b, dx = 0.5 * info["width"], 0.5 * info["height"], info["dx"]
    fluid = np.asarray(case.state.kind) == Kind.FLUID
    centre, exact, profile = [], [], []
    for i in range(1, len(traj.times)):
        t = float(traj.times[i])
        x = np.asarray(traj.states.position[i])[fluid]
        u = np.asarray(traj.states.velocity[i])[fluid, 0]
        y, z = x[:, 1] - a, x[:, 2] - b
        ue = duct_velocity(y, z, a, b, info["viscosity"], info["body_force"], t=t)
        near = (np.abs(y) < 0.6 * dx) & (np.abs(z) < 0.6 * dx)
        centre.append(float(u[near].mean()))
        exact.append(float(ue[near].mean()))
        profile.append(float(np.sqrt(np.mean((u - ue) ** 2)) / info["centre_speed"]))
    record = dict(
        n=n,
        particles=case.n_particles,
        steps=n_steps,
        times=np.asarray(traj.times)[1:].tolist(),
        centre=centre,
        centre_exact=exact,
        profile_error=profile,
        wall_s=wall,
    )
    _store(f"duct_n{n}", record)
    errors = np.array(centre) / np.array(exact) - 1
    middle = errors[len(errors) // 2]
    print(
        f"| {n} | {case.n_particles} | {n_steps} | {errors[0]:+.2%} | {middle:+.2%} "
        f"| {errors[-1]:+.2%} | {profile[-1]:.2%} | {wall:.0f} |"
    )


def dam(n, t_scaled, wall_slip="no_slip", dim=3):
    t0 = time.perf_counter()
    factory = sphjax.cases.dam_break_3d if dim == 3 else sphjax.cases.dam_break
    case = factory(n=n, wall_slip=wall_slip)
    scale = case.info["time_scale"]
    save_every = max(1, int(0.05 * scale / case.dt))
    n_steps = save_every * int(np.ceil(t_scaled * scale / case.dt / save_every))
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=save_every)
    wall = time.perf_counter() - t0
    T = np.asarray(traj.times) / scale
    Z = np.asarray(surge_front(traj.states, case))
    reached = MARTIN_MOYCE[MARTIN_MOYCE[:, 0] <= T[-1]]
    measured = np.interp(reached[:, 0], T, Z)
    record = dict(
        n=n,
        particles=case.n_particles,
        steps=n_steps,
        T=T.tolist(),
        front=Z.tolist(),
        martin_moyce=reached.tolist(),
        measured=measured.tolist(),
        wall_slip=wall_slip,
        dim=dim,
        wall_s=wall,
    )
    _store(f"dam_n{n}_{wall_slip}_{dim}d", record)
    for (t_ref, z_ref), z in zip(reached, measured, strict=True):
        print(f"| {dim}D {wall_slip} | {n} | {t_ref} | {z_ref} | {z:.3f} | {z / z_ref - 1:+.1%} |")
    print(f"wall {wall:.0f} s, {case.n_particles} particles, {n_steps} steps")


def spheric(n, t_end, wall_slip="no_slip", every=0.01):
    """SPHERIC benchmark 2: the four water heights and the eight box pressures, every
    ``every`` seconds, against the MARIN measurements (docs/data/spheric_test2_heights.csv)."""
    t0 = time.perf_counter()
    case = sphjax.cases.spheric_dam_break_3d(n=n, wall_slip=wall_slip)
    save_every = max(1, int(round(every / case.dt)))
    n_steps = save_every * int(np.ceil(t_end / case.dt / save_every))
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=save_every)
    wall = time.perf_counter() - t0
    info = case.info
    heights = {
        g: np.asarray(water_height(traj.states, case, xy)).tolist()
        for g, xy in info["gauges"].items()
    }
    pressures = {
        p: np.asarray(probe_pressure(traj.states, case, xyz)).tolist()
        for p, xyz in info["sensors"].items()
    }
    fluid = np.asarray(traj.states.kind[-1]) == Kind.FLUID
    record = dict(
        n=n,
        dx=info["dx"],
        particles=case.n_particles,
        fluid_particles=int(fluid.sum()),
        steps=n_steps,
        dt=case.dt,
        t=np.asarray(traj.times).tolist(),
        heights=heights,
        pressures=pressures,
        finite=bool(np.all(np.isfinite(np.asarray(traj.states.position)))),
        wall_slip=wall_slip,
        wall_s=wall,
    )
    _store(f"spheric_n{n}" + ("" if wall_slip == "no_slip" else f"_{wall_slip}"), record)
    print(f"wall {wall:.0f} s, {case.n_particles} particles, {n_steps} steps")
    _spheric_table(record)


def _spheric_experiment():
    """The MARIN water heights: columns t, H1, H2, H3, H4 (m)."""
    return np.loadtxt(DOCS / "data" / "spheric_test2_heights.csv", delimiter=",", comments="#")


def _spheric_table(record, gauges=("H2", "H3", "H4")):
    """Per gauge: the mean absolute difference to the experiment over the run, relative
    to the measured range, and the arrival time (first reading above 0.02 m)."""
    exp = _spheric_experiment()
    t = np.asarray(record["t"])
    exp = exp[exp[:, 0] <= t[-1] + 1e-9]
    rows = {}
    for g in gauges:
        col = int(g[1])
        sim = np.interp(exp[:, 0], t, record["heights"][g])
        mae = float(np.mean(np.abs(sim - exp[:, col])))
        arrival = lambda times, h: float(times[np.argmax(np.asarray(h) > 0.02)])  # noqa: E731
        rows[g] = dict(
            mae=mae,
            mae_rel=mae / float(np.ptp(exp[:, col])),
            arrival=arrival(t, record["heights"][g]) if g != "H4" else None,
            arrival_exp=arrival(exp[:, 0], exp[:, col]) if g != "H4" else None,
        )
        print(
            f"| {record['n']} | {g} | {mae:.4f} | {rows[g]['mae_rel']:.1%} "
            f"| {rows[g]['arrival']} | {rows[g]['arrival_exp']} |"
        )
    return rows


#: the small hydrostatic plate of tests/test_fsi.py (0.4 m, 0.05 m thick, rho_s = 800,
#: under 0.2 m of water)
SMALL_PLATE = dict(length=0.4, depth=0.2, solid_density=800.0)


def fsi(n, periods, length=None, depth=None):
    """The hydrostatic plate in 3D (extruded, periodic span) and in 2D, same arguments,
    split integration ``"auto"``: static mid-span deflection ``(max + min) / 2`` over the
    second half of ``periods`` dry periods, against each other and Euler-Bernoulli."""
    kw = dict(SMALL_PLATE, n=n, substeps="auto")
    if length is not None:
        kw["length"] = length
    if depth is not None:
        kw["depth"] = depth
    record = dict(kw, x64=bool(jax.config.jax_enable_x64))
    for name in ("hydrostatic_fsi_plate", "hydrostatic_fsi_plate_3d"):
        t0 = time.perf_counter()
        case = sphjax.cases.get(name, **kw)
        n_steps = int(round(periods * case.info["dry_period"] / case.dt))
        traj = sphjax.simulate(case, n_steps=n_steps, save_every=max(1, n_steps // 200))
        w = np.asarray(sphjax.cases.midspan_deflection(traj, case))
        late = w[len(w) // 2 :]
        record[f"{case.model.dim}d"] = dict(
            particles=case.n_particles,
            substeps=case.info["substeps"],
            steps=n_steps,
            static=float(0.5 * (late.max() + late.min())),
            mean=float(late.mean()),
            reference=case.info["reference_deflection"],
            wall_s=time.perf_counter() - t0,
            times=np.asarray(traj.times).tolist(),
            deflection=w.tolist(),
        )
    _store(f"fsi_plate_n{n}_L{kw['length']:g}_H{kw['depth']:g}", record)
    a, b = record["2d"], record["3d"]
    print(
        f"| {n} | {kw['length']:g} / {kw['depth']:g} | {a['particles']} / {b['particles']} | "
        f"{a['substeps']} / {b['substeps']} | {b['steps']} | {a['static']:.4e} | "
        f"{b['static']:.4e} | {b['static'] / a['static']:.3f} | "
        f"{a['static'] / a['reference']:.3f} / {b['static'] / b['reference']:.3f} | "
        f"{a['wall_s']:.0f} / {b['wall_s']:.0f} |"
    )


def figures():
    """The figures of docs/validation_3d.md, from the stored runs (no simulation)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = json.loads(RESULTS.read_text())
    img = DOCS / "img"

    def save(fig, name):
        fig.tight_layout()
        fig.savefig(img / name, dpi=110)
        plt.close(fig)
        print(f"wrote docs/img/{name}")

    fig, (ax, ax_err) = plt.subplots(1, 2, figsize=(9, 3.8))
    first = True
    for n in (10, 12, 16, 20):
        r = data.get(f"abc_n{n}_re50_relaxed")
        if r is None:
            continue
        if first:
            ax.plot(r["times"], r["ke_exact"], "k-", lw=2, label="exact, exp(-2 nu k^2 t)")
            first = False
        ke, exact = np.asarray(r["ke_ratio"]), np.asarray(r["ke_exact"])
        ax.plot(r["times"], ke, "o--", ms=3, label=f"sphjax, {n}^3")
        ax_err.plot(r["times"], 100 * (ke / exact - 1), "o-", ms=3, label=f"{n}^3")
    ax.set(xlabel="t", ylabel="KE / KE(0)", title="ABC flow, Re = 50 (relaxed start)")
    ax.legend()
    ax_err.set(xlabel="t", ylabel="KE error (%)", title="against the exact decay")
    ax_err.axhline(0.0, color="k", lw=0.8)
    ax_err.legend()
    save(fig, "abc_3d_ke.png")

    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    for n in (8, 12, 16):
        r = data.get(f"duct_n{n}")
        if r is None:
            continue
        (line,) = ax.plot(
            r["times"], np.asarray(r["centre"]) * 1e6, "o--", ms=3, label=f"sphjax, {n} across"
        )
        ax.plot(
            r["times"],
            np.asarray(r["centre_exact"]) * 1e6,
            "-",
            color=line.get_color(),
            lw=1,
            label=f"series at the same particles ({n})",
        )
    ax.set(xlabel="t (s)", ylabel="speed near the axis (um/s)", title="Square duct, start-up")
    ax.legend()
    save(fig, "duct_3d_centre.png")

    fig, ax = plt.subplots(figsize=(6.5, 3.8))
    for n in (4, 6, 8):
        r = data.get(f"cantilever_n{n}")
        if r is None:
            continue
        ax.plot(r["times"], np.asarray(r["tip_y"]) * 1e3, lw=1, label=f"sphjax, {n} x {n} section")
    if r is not None:
        t = np.linspace(0.0, max(r["times"]), 400)
        omega = 2 * np.pi / r["reference_period"]
        ax.plot(
            t, r["reference_amplitude"] * np.sin(omega * t) * 1e3, "k--", label="Euler-Bernoulli"
        )
    ax.set(xlabel="t (s)", ylabel="tip u_y (mm)", title="Cantilever, square section")
    ax.legend(fontsize=8)
    save(fig, "cantilever_3d_tip.png")

    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    ax.plot(MARTIN_MOYCE[:, 0], MARTIN_MOYCE[:, 1], "ks", label="Martin & Moyce (1952)")
    for key, label in (
        ("dam_n8_no_slip_3d", "3D, no-slip"),
        ("dam_n8_free_slip_3d", "3D, free-slip"),
        ("dam_n8_no_slip_2d", "2D, no-slip"),
    ):
        r = data.get(key)
        if r is not None:
            ax.plot(r["T"], r["front"], label=f"sphjax {label}, n = 8")
    ax.set(xlabel="T = t sqrt(2g/L)", ylabel="Z / L", title="Dam break, surge front", xlim=(0, 2.7))
    ax.legend(fontsize=8)
    save(fig, "dam_break_3d_front.png")

    spheric_runs = sorted(k for k in data if k.startswith("spheric_n"))
    if spheric_runs:
        exp = _spheric_experiment()
        fig, axes = plt.subplots(2, 2, figsize=(9, 6), sharex=True)
        for ax, g in zip(axes.ravel(), ("H1", "H2", "H3", "H4"), strict=True):
            ax.plot(exp[:, 0], exp[:, int(g[1])], "ko", ms=3, label="experiment (MARIN)")
            for key in spheric_runs:
                r = data[key]
                slip = r.get("wall_slip", "no_slip").replace("_", "-")
                ax.plot(r["t"], r["heights"][g], label=f"sphjax, dx = {r['dx']:.3g} m, {slip}")
            ax.set(title=g, ylabel="water height (m)")
        for ax in axes[1]:
            ax.set_xlabel("t (s)")
        axes[0, 0].legend(fontsize=8)
        save(fig, "spheric_3d_heights.png")


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "case",
        choices=["abc", "tank", "duct", "dam", "cantilever", "spheric", "fsi", "figures"],
    )
    p.add_argument("--n", type=int, nargs="*", default=None)
    p.add_argument("--reynolds", type=float, default=50.0)
    p.add_argument("--t-end", type=float, default=None)
    p.add_argument("--lattice", action="store_true")
    p.add_argument("--width", type=float, default=1.0)
    p.add_argument("--wall-slip", default="no_slip", choices=["no_slip", "free_slip"])
    p.add_argument("--length", type=float, default=None, help="fsi: the plate's length")
    p.add_argument("--depth", type=float, default=None, help="fsi: the water's depth")
    p.add_argument("--periods", type=float, default=8.0, help="fsi: dry periods")
    p.add_argument(
        "--x64", action="store_true", help="float64 (the plate's deflection is 1e-6 of its size)"
    )
    p.add_argument("--dim", type=int, default=3, choices=[2, 3], help="dam: 2 for the 2D case")
    args = p.parse_args()
    if args.x64:
        jax.config.update("jax_enable_x64", True)
    if args.case == "abc":
        for n in args.n or [12, 16]:
            abc(n, args.reynolds, args.t_end or 0.5, args.lattice)
    elif args.case == "tank":
        for n in args.n or [8, 12]:
            tank(n, args.width, args.t_end or 1.0)
    elif args.case == "dam":
        for n in args.n or [8]:
            dam(n, args.t_end or 2.6, args.wall_slip, args.dim)
    elif args.case == "duct":
        for n in args.n or [8, 12]:
            duct(n, args.t_end or 0.5)
    elif args.case == "cantilever":
        for n in args.n or [4, 6, 8]:
            cantilever(n, args.t_end or 0.55)
    elif args.case == "spheric":
        for n in args.n or [8]:
            spheric(n, args.t_end or 1.5, args.wall_slip)
    elif args.case == "fsi":
        for n in args.n or [2, 3]:
            fsi(n, args.periods, args.length, args.depth)
    elif args.case == "figures":
        figures()


if __name__ == "__main__":
    main()
