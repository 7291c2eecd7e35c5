"""Run the fluid validation cases and write docs/validation_fluid.md with plots.

    python docs/scripts/validate_fluid.py [--quick]

Compares with the reference numbers of VALIDATION.md (copied below): Taylor-Green kinetic
energy decay, Poiseuille start-up, hydrostatic tank, Martin & Moyce dam break.
"""

from __future__ import annotations

import argparse
import pathlib
import time

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import sphjax  # noqa: E402
from sphjax import Kind  # noqa: E402
from sphjax.cases import poiseuille_centreline_speed, poiseuille_startup_speed, surge_front  # noqa: E402

DOCS = pathlib.Path(__file__).resolve().parents[1]
MARTIN_MOYCE = np.array(
    [
        (0.0, 1.0),
        (0.381, 1.111),
        (0.769, 1.252),
        (1.153, 1.505),
        (1.537, 1.892),
        (1.935, 2.241),
        (2.323, 2.615),
        (2.719, 3.003),
        (3.096, 3.624),
    ]
)


def run(case, t_end, frames=100):
    n_steps = int(round(t_end / case.dt))
    save_every = max(1, n_steps // frames)
    n_steps -= n_steps % save_every
    t0 = time.perf_counter()
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=save_every)
    return traj, time.perf_counter() - t0


def taylor_green(n, rows):
    case = sphjax.cases.taylor_green(n=n)
    traj, wall = run(case, 1.0)
    mass = np.asarray(traj.states.mass)
    ke = 0.5 * np.sum(mass * np.sum(np.asarray(traj.states.velocity) ** 2, -1), -1)
    t = np.asarray(traj.times)
    exact = np.exp(-16 * np.pi**2 * case.info["viscosity"] * t)
    for t_ref in (0.5, 1.0):
        i = int(np.argmin(abs(t - t_ref)))
        err = ke[i] / ke[0] / exact[i] - 1
        rows.append(
            (
                "taylor_green",
                f"n={n}",
                f"KE/KE0 at t={t[i]:.3f}",
                f"{exact[i]:.4f}",
                f"{ke[i] / ke[0]:.4f}",
                f"{err:+.2%}",
            )
        )
    plt.figure(figsize=(5, 3.5))
    plt.semilogy(t, ke / ke[0], label=f"sphjax n={n}")
    plt.semilogy(t, exact, "k--", label="exp(-16 pi^2 nu t)")
    plt.xlabel("t"), plt.ylabel("KE / KE0"), plt.legend(), plt.tight_layout()
    plt.savefig(DOCS / "img" / "taylor_green_ke.png", dpi=120)
    plt.close()
    return wall


def poiseuille(n, rows):
    case = sphjax.cases.poiseuille(n=n)
    info = case.info
    L, nu, F = info["width"], info["viscosity"], info["body_force"]
    traj, wall = run(case, 1.0, frames=200)
    t = np.asarray(traj.times)
    fluid = np.asarray(case.state.kind) == Kind.FLUID
    plt.figure(figsize=(5, 3.5))
    for t_ref in (0.0225, 0.1125, 0.225, 1.0):
        i = int(np.argmin(abs(t - t_ref)))
        y = np.asarray(traj.states.position[i])[fluid, 1]
        u = np.asarray(traj.states.velocity[i])[fluid, 0]
        u_c = poiseuille_centreline_speed(traj.frame(i), case)
        ref = poiseuille_startup_speed(L / 2, t[i], L, nu, F)
        rows.append(
            (
                "poiseuille",
                f"n={n}",
                f"u(L/2) at t={t[i]:.4f}",
                f"{ref:.4e}",
                f"{u_c:.4e}",
                f"{u_c / ref - 1:+.2%}",
            )
        )
        yy = np.linspace(0, L, 100)
        plt.plot(poiseuille_startup_speed(yy, t[i], L, nu, F), yy, "k-", lw=0.8)
        plt.plot(u, y, ".", ms=2, label=f"t={t[i]:.3f}")
    plt.xlabel("u (m/s)"), plt.ylabel("y (m)"), plt.legend(), plt.tight_layout()
    plt.savefig(DOCS / "img" / "poiseuille.png", dpi=120)
    plt.close()
    return wall


def hydrostatic(n, rows):
    case = sphjax.cases.hydrostatic_tank(n=n)
    info = case.info
    traj, wall = run(case, 2.0, frames=20)
    fluid = np.asarray(case.state.kind) == Kind.FLUID
    x = np.asarray(traj.final.position)[fluid]
    p = np.asarray(traj.final.pressure)[fluid]
    v = np.asarray(traj.final.velocity)[fluid]
    g, H = info["gravity"], info["height"]
    _, bottom = np.polyfit(x[:, 1], p, 1)
    ref = 1000 * g * H
    rows.append(
        (
            "hydrostatic_tank",
            f"n={n}",
            "bottom pressure (Pa), t=2 s",
            f"{ref:.1f}",
            f"{bottom:.1f}",
            f"{bottom / ref - 1:+.2%}",
        )
    )
    vmax = np.linalg.norm(v, axis=-1).max() / np.sqrt(g * H)
    rows.append(
        ("hydrostatic_tank", f"n={n}", "max speed / sqrt(gH), t=2 s", "< 0.01", f"{vmax:.2e}", "")
    )
    plt.figure(figsize=(4, 3.5))
    plt.plot(p, x[:, 1], ".", ms=2, label="sphjax")
    yy = np.linspace(0, H, 50)
    plt.plot(1000 * g * (H - yy), yy, "k--", label="rho0 g (H - y)")
    plt.xlabel("p (Pa)"), plt.ylabel("y (m)"), plt.legend(), plt.tight_layout()
    plt.savefig(DOCS / "img" / "hydrostatic.png", dpi=120)
    plt.close()
    return wall


def dam_break(n, rows):
    case = sphjax.cases.dam_break(n=n)
    scale = case.info["time_scale"]
    traj, wall = run(case, 3.0 * scale, frames=120)
    T = np.asarray(traj.times) / scale
    Z = np.asarray(surge_front(traj.states, case))
    for T_ref, Z_ref in MARTIN_MOYCE:
        if 1.0 <= T_ref <= 2.5:
            z = float(np.interp(T_ref, T, Z))
            rows.append(
                (
                    "dam_break",
                    f"n={n}",
                    f"Z/L at T={T_ref}",
                    f"{Z_ref}",
                    f"{z:.3f}",
                    f"{z / Z_ref - 1:+.2%}",
                )
            )
    plt.figure(figsize=(5, 3.5))
    plt.plot(T, Z, label=f"sphjax n={n}")
    plt.plot(MARTIN_MOYCE[:, 0], MARTIN_MOYCE[:, 1], "ko", label="Martin & Moyce (1952)")
    plt.xlabel("T = t sqrt(2g/L)"), plt.ylabel("Z / L"), plt.legend(), plt.tight_layout()
    plt.savefig(DOCS / "img" / "dam_break_front.png", dpi=120)
    plt.close()
    return wall


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="coarser resolutions")
    args = parser.parse_args()
    (DOCS / "img").mkdir(exist_ok=True)
    rows = []
    walls = {}
    walls["taylor_green"] = taylor_green(30 if args.quick else 50, rows)
    walls["poiseuille"] = poiseuille(20, rows)
    walls["hydrostatic_tank"] = hydrostatic(20, rows)
    walls["dam_break"] = dam_break(20 if args.quick else 30, rows)
    lines = [
        "# Fluid validation",
        "",
        "Produced by `python docs/scripts/validate_fluid.py` (float64). References from",
        "VALIDATION.md. Error = measured / reference - 1.",
        "",
        "| case | resolution | quantity | reference | measured | error |",
        "|---|---|---|---|---|---|",
    ]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    lines += ["", "Wall time (s): " + ", ".join(f"{k} {v:.0f}" for k, v in walls.items()), ""]
    lines += [
        f"![{name}](img/{name}.png)"
        for name in ("taylor_green_ke", "poiseuille", "hydrostatic", "dam_break_front")
    ]
    (DOCS / "validation_fluid.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
