"""Run the fluid validation cases and write docs/validation_fluid.md with plots.

    python docs/scripts/validate_fluid.py [--quick]

    python docs/scripts/validate_fluid.py --cases dam_break   # rerun one case

Compares with the reference numbers copied below: Taylor-Green kinetic energy decay and
velocity field (Re = 50 to 1000, a convergence table), Poiseuille start-up, hydrostatic
tank, dam break against Martin & Moyce (1952) and Koshizuka & Oka (1996).
"""

from __future__ import annotations

import argparse
import json
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
        (2.65, 3.22),
        (2.83, 3.44),
        (2.98, 3.67),
        (3.11, 3.89),
        (3.33, 4.11),
    ]
)
# Koshizuka & Oka (1996), their own experiment, (T, Z/L).
KOSHIZUKA_OKA = np.array(
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
# Buchner (2002), PhD thesis TU Delft, pressure sensor P1 (right wall, y = 0.16 m) of the
# dam break of Zhou et al. (1999) (column 1.2 x 0.6 m, tank 3.22 m), as digitised in
# TrixiParticles.jl (validation/dam_break_2d/exp_pressure_sensor_P1.csv):
# (t sqrt(g/H), p / (rho0 g H)), first impact and plateau.
BUCHNER_P1 = np.array(
    [
        (2.42553, -0.01511),
        (2.47263, 0.07666),
        (2.49148, 0.15352),
        (2.55271, 0.26544),
        (2.61552, 0.37138),
        (2.65007, 0.56241),
        (2.68932, 0.66239),
        (2.77411, 0.68698),
        (2.83535, 0.67203),
        (2.90287, 0.66081),
        (2.96097, 0.64586),
        (3.02221, 0.64285),
        (3.13212, 0.57862),
        (3.23105, 0.54574),
        (3.36765, 0.54121),
        (3.51996, 0.54487),
        (3.67856, 0.54108),
        (3.90467, 0.54396),
    ]
)
TG_REYNOLDS = (50, 100, 400, 1000)
# Measured at n = 100 (float32, 10 000 particles, 3 680 steps) by an earlier version of
# taylor_green_run that kept only these numbers; the text below the table refers to them.
TG_NOTES = [
    "",
    "n = 100 (float32, the same start and parameters; an earlier run that kept only these",
    "numbers):",
    "",
    "| Re | n | KE error at t=1 | KE rise | velocity error t=0.05 | max velocity error |",
    "|---|---|---|---|---|---|",
    "| 50 | 100 | +0.28% | -0.73% | 0.62% | 2.36% (below 2 % up to t = 0.7) |",
    "| 100 | 100 | -1.30% | -1.68% | 0.71% | 2.06% (below 2 % up to t = 0.9) |",
    "| 400 | 100 | -2.33% | -1.38% | 0.88% | 2.67% |",
    "| 1000 | 100 | -2.49% | -0.77% | 0.97% | 3.61% |",
    "",
    "float32 and float64 give the same KE error to 0.01 % (Re = 1000 at n = 25: -18.90 %",
    "both; Re = 50 at n = 50: -1.46 % and -1.47 %).",
    "",
    "**Kinetic energy.** The KE error at t = 1 converges with n at every Re (at Re = 50 not",
    "monotonically, below); the hardest case is Re = 1000: -18.9, -6.6, -2.5, -1.9 % at",
    "n = 25, 50, 100, 128 (order about 1.5 between 25 and 100; a Richardson fit of n = 25,",
    "50, 100 gives an order of 1.6 and a limit of -0.4 %, which predicted -1.8 % at",
    "n = 128).  **At n = 128 (16 384 particles, 4 700 steps) KE at t = 1 is within 2 % of",
    "the analytic decay for Re = 50 to 1000** (measured at each Re: +0.70 %, -0.81 %,",
    "-1.78 %, -1.92 % at Re = 50, 100, 400, 1000).  At Re = 100 the error falls steadily",
    "(-10.48, -3.61, -1.30, -0.81 % at n = 25, 50, 100, 128); at Re = 50 it changes sign",
    "between n = 50 and 100 and its size grows again from n = 100 to 128 (-5.46, -1.46,",
    "+0.28, +0.70 %): not monotone, but within 1 %.  n = 150 would leave a margin at",
    "Re = 1000 (about -1.6 % by the same fit).  The kinetic energy falls between every pair",
    "of frames in every run (KE rise < 0).",
    "",
    "**Velocity field.** The field is within 1 % (rms) of the analytic one at the first",
    "saved frame (t = 0.05) in every run, and KE never rises.  Between t = 0.05 and 0.15 the",
    "error grows to 2.6 % (n = 128, Re = 1000) or 3.7 % (n = 50, Re = 50) and then stays",
    "about level: the vortices' shear rearranges the particles (the start is a relaxed",
    "glass, not a lattice) and the velocity picks up particle-scale noise.  The error is",
    "almost all in the shape of the field, not its amplitude: at n = 128, Re = 1000, the",
    "best-fit amplitude is 1.0 % low at t = 1 (the KE error) while the shape error is",
    "2.6 %, total 2.8 %.  So the velocity field stays within 2 % only to t ~ 0.1 at",
    "n = 128, Re = 1000; at Re = 400 and n = 128 it is 1.7-2.1 % from t = 0.15 on (largest",
    "2.10 %, at t = 1).  At Re = 50 and 100 and n = 128 it stays within 2 % over the whole",
    "run: 1.46 % and 1.58 % at t = 0.15, down to 1.21 % and 1.26 % at t = 0.35, then rising",
    "to its largest at t = 1, 1.82 % and 1.64 % (shape error 1.78 % and 1.59 %).  Its",
    "largest value falls with order 1.0-1.3 in n at Re = 1000",
    "(8.7, 3.6, 2.8 % at n = 50, 100, 128): within 2 % over the whole run would take n ~ 180",
    "(extrapolated, not run; a run costs about 428 (180/128)^3 = 1 200 CPU s).",
    "",
    "The shape error is noise at the particle scale: averaged over cells of 4 x 4 particle",
    "spacings it falls to a third (n = 50, Re = 1000, t = 0.5: 7.1 % per particle, 2.4 %",
    "over 4 dx cells, 1.4 % over 8 dx cells, against 1.8 % and 0.9 % for independent",
    "particle noise), so a smaller coherent part remains at the scale of a few spacings.",
    "The physical options of the case do not lower it (measured separately, n = 50,",
    "Re = 1000, to t = 0.5, the same metrics): shape error 7.1 % with the default",
    "background pressure p_b = rho0 c0^2, 7.6 % with `transport_pressure_factor=2`, 7.5 %",
    "with 0.5, 7.2 % with a three times longer packing (`relax_iterations=3000`, which",
    "lowers the first-frame error from 1.0 to 0.7 %).  The background pressure does move",
    "the KE error (t = 0.5: -2.9 % default, -1.0 % at twice p_b, -4.7 % at half), not the",
    "noise; of what was tried, only resolution lowers the noise.",
    "",
    "At Re = 50 the relative error also grows late because the",
    "field itself decays (to 0.21 of its amplitude by t = 1): at n = 50 the noise's",
    "absolute rms falls from 0.029 U at t = 0.15 to 0.0097 U at t = 1 while the relative",
    "error rises from 3.0 % (t = 0.5) to 4.7 %.",
    "",
    "**Cost.** The start (the packing: 1000 pseudo-time steps of the background-pressure",
    "relaxation, at the run's particle count) costs 30-48 CPU s at n = 128, 28 at n = 100",
    "and 11 at n = 50 (one thread asked for, float32), 11-12 % of the n = 128 run: 248-428",
    "CPU s to t = 1 for the same 4 700 steps (0.05-0.09 s a step).  The Re = 50 and 100",
    "runs (start 31 and 30, run 248 and 259 CPU s) were measured in a later session than",
    "the Re = 400 and 1000 ones (46 and 48, 419 and 428), which took 2.5-3.6 times their CPU",
    "time in wall time; the particles and steps are the same, so the spread is most likely",
    "the load on the shared machine (not measured).  CPU time is the process's: in the",
    "Re = 100 run it exceeded the wall time (259 CPU s in 172 s), so the process did not",
    "run on one thread only.  A run costs about particles x steps, i.e. n^3 (the steps grow",
    "with n through dt = 0.25 h / (c0 + U)).",
]


def run(case, t_end, frames=100):
    n_steps = int(round(t_end / case.dt))
    save_every = max(1, n_steps // frames)
    n_steps -= n_steps % save_every
    t0 = time.perf_counter()
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=save_every)
    return traj, time.perf_counter() - t0


def taylor_green_run(n, reynolds, t_end=1.0, frames=20):
    """One run: KE error at t_end, largest KE rise between frames, velocity rms error.

    The velocity error at each frame is split into the amplitude of the field (the
    least-squares factor ``a`` with ``v ~ a v_exact``) and the rest (``v - a v_exact``, the
    error of the field's shape, mostly particle noise)."""
    from sphjax.cases import taylor_green_velocity

    t0, c0 = time.perf_counter(), time.process_time()
    case = sphjax.cases.taylor_green(n=n, reynolds=reynolds)
    start, start_cpu = time.perf_counter() - t0, time.process_time() - c0
    n_steps = frames * int(np.ceil(t_end / case.dt / frames))
    t0, c0 = time.perf_counter(), time.process_time()
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=n_steps // frames, dt=t_end / n_steps)
    mass = np.asarray(traj.states.mass)
    v = np.asarray(traj.states.velocity)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    ke = 0.5 * np.sum(mass * np.sum(v**2, -1), -1)
    t = np.asarray(traj.times)
    exact = np.exp(-16 * np.pi**2 * case.info["viscosity"] * t)
    v_exact = taylor_green_velocity(np.asarray(traj.states.position), t[:, None], case)
    norm = np.sqrt(np.mean(np.sum(v_exact**2, -1), -1))
    error = np.sqrt(np.mean(np.sum((v - v_exact) ** 2, -1), -1)) / norm
    amplitude = np.sum(v * v_exact, (-1, -2)) / np.sum(v_exact**2, (-1, -2))
    shape = v - amplitude[:, None, None] * v_exact
    shape_error = np.sqrt(np.mean(np.sum(shape**2, -1), -1)) / norm
    above = np.nonzero(error[1:] > 0.02)[0]
    return dict(
        n=n,
        reynolds=reynolds,
        precision="float64" if jax.config.jax_enable_x64 else "float32",
        t=t.tolist(),
        ke=(ke / ke[0]).tolist(),
        exact=exact.tolist(),
        ke_error=float(ke[-1] / ke[0] / exact[-1] - 1),
        ke_rise=float(np.max(np.diff(ke)) / ke[0]),
        velocity_error=error.tolist(),
        amplitude=amplitude.tolist(),
        shape_error=shape_error.tolist(),
        velocity_error_first=float(error[1]),
        velocity_error_max=float(np.max(error[1:])),
        velocity_error_end=float(error[-1]),
        first_above_2pc=float(t[above[0] + 1]) if len(above) else None,
        start_seconds=start,
        start_cpu_seconds=start_cpu,
        seconds=wall,
        cpu_seconds=cpu,
        steps=n_steps,
    )


def taylor_green(resolutions, rows, reynolds=TG_REYNOLDS, results=()):
    """Run every (Re, n) pair and merge them into ``results`` (runs stored earlier, keyed by
    Re, n and precision); the rows cover all of them."""
    fresh = [taylor_green_run(n, re) for re in reynolds for n in resolutions]
    key = lambda r: (r["reynolds"], r["n"], r.get("precision", "float64"))  # noqa: E731
    merged = {key(r): r for r in results}
    merged.update({key(r): r for r in fresh})
    results = [merged[k] for k in sorted(merged)]
    for r in results:
        rows.append(
            (
                "taylor_green",
                f"n={r['n']}, Re={r['reynolds']}" + (", float32" if key(r)[2] == "float32" else ""),
                "KE/KE0 at t=1",
                f"{r['exact'][-1]:.4f}",
                f"{r['ke'][-1]:.4f}",
                f"{r['ke_error']:+.2%}",
            )
        )
    return sum(r["seconds"] + r["start_seconds"] for r in fresh), results


def taylor_green_plot(results):
    """KE / KE0 against t, the largest n of each Re, with the analytic decay."""
    plt.figure(figsize=(5, 3.5))
    for re in sorted({r["reynolds"] for r in results}):
        r = max((r for r in results if r["reynolds"] == re), key=lambda r: r["n"])
        plt.semilogy(r["t"], r["ke"], label=f"Re={r['reynolds']} n={r['n']}")
        plt.semilogy(r["t"], r["exact"], "k--", lw=0.8)
    plt.xlabel("t"), plt.ylabel("KE / KE0"), plt.legend(), plt.tight_layout()
    plt.savefig(DOCS / "img" / "taylor_green_ke.png", dpi=120)
    plt.close()


def taylor_green_table(results):
    lines = [
        "",
        "## Taylor–Green convergence",
        "",
        "Default case (relaxed start, summation density, transport velocity, quintic spline,",
        "h = 1.2 dx, c0 = 10 U), 20 frames to t = 1.  KE rise: the largest increase of KE",
        "between saved frames over KE0 (negative: KE fell between every pair of frames).",
        "Velocity error: rms of v - v_exact over the rms of v_exact, at the first saved",
        "frame (t = 0.05), at t = 1 and the largest over all frames; > 2 % from: the first",
        "frame at which it exceeds 2 % (- if none).  Shape error at t = 1: the rms of",
        "v - a v_exact over the rms of v_exact, a the best-fit amplitude (what remains of",
        "the velocity error once the amplitude, i.e. the KE error, is taken out).  Start:",
        "seconds to build the case (the packing); run: seconds of the simulation; CPU",
        "seconds on one thread for the rows with a shape error (float32 rows:",
        "`python docs/scripts/validate_fluid.py --float32`), wall seconds for the others.",
        "",
        "| Re | n | KE/KE0 at t=1 (exact) | KE error | KE rise | velocity error t=0.05 "
        "| at t=1 | max | > 2 % from | shape error t=1 | start (s) | run (s) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        n = f"{r['n']}" + (" (float32)" if r.get("precision") == "float32" else "")
        above = r.get("first_above_2pc")
        lines.append(
            f"| {r['reynolds']} | {n} | {r['ke'][-1]:.4f} ({r['exact'][-1]:.4f}) | "
            f"{r['ke_error']:+.2%} | {r['ke_rise']:+.2%} | {r['velocity_error_first']:.2%} | "
            + (f"{r['velocity_error_end']:.2%} | " if "velocity_error_end" in r else "| ")
            + f"{r['velocity_error_max']:.2%} | "
            + ("- | " if above is None else f"{above:.2f} | ")
            + (f"{r['shape_error'][-1]:.2%} | " if "shape_error" in r else "| ")
            + f"{r.get('start_cpu_seconds', r['start_seconds']):.0f} | "
            f"{r.get('cpu_seconds', r['seconds']):.0f} |"
        )
    lines += TG_NOTES
    return lines


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


def arrival_lead(T, Z, table):
    """For each reference point (T_ref, Z_ref): T_ref minus the time at which the
    simulated front first reaches Z_ref (positive: the simulation is ahead)."""
    leads = []
    for T_ref, Z_ref in table:
        if Z_ref <= Z[0]:
            continue
        k = int(np.argmax(Z >= Z_ref))
        if Z[k] < Z_ref:
            break
        T_hit = T[k - 1] + (Z_ref - Z[k - 1]) * (T[k] - T[k - 1]) / (Z[k] - Z[k - 1])
        leads.append((T_ref, Z_ref, T_ref - T_hit))
    return leads


def dam_break(n, rows, density_diffusion="molteni"):
    case = sphjax.cases.dam_break(n=n, density_diffusion=density_diffusion)
    name = "dam_break" if density_diffusion == "molteni" else f"dam_break ({density_diffusion})"
    scale = case.info["time_scale"]
    traj, wall = run(case, 3.0 * scale, frames=120)
    T = np.asarray(traj.times) / scale
    Z = np.asarray(surge_front(traj.states, case))
    for label, table in (("Martin & Moyce", MARTIN_MOYCE), ("Koshizuka & Oka", KOSHIZUKA_OKA)):
        for T_ref, Z_ref in table:
            if 0.4 <= T_ref <= 3.0:
                z = float(np.interp(T_ref, T, Z))
                rows.append(
                    (
                        name,
                        f"n={n}",
                        f"Z/L at T={T_ref} ({label})",
                        f"{Z_ref}",
                        f"{z:.3f}",
                        f"{z / Z_ref - 1:+.2%}",
                    )
                )
        for T_ref, Z_ref, lead in arrival_lead(T, Z, table):
            if T_ref <= 3.0:
                rows.append(
                    (
                        name,
                        f"n={n}",
                        f"lead in T reaching Z/L={Z_ref} ({label})",
                        f"T={T_ref}",
                        f"{lead:+.3f}",
                        "",
                    )
                )
    np.savetxt(
        DOCS / "figures" / f"dam_break_front_{density_diffusion}_n{n}.csv",
        np.stack([T, Z], -1),
        delimiter=",",
        header="T,Z/L",
        comments="",
    )
    plt.figure(figsize=(5, 3.5))
    for other in ("molteni", "antuono"):
        path = DOCS / "figures" / f"dam_break_front_{other}_n{n}.csv"
        if path.exists():
            data = np.loadtxt(path, delimiter=",", skiprows=1)
            label = {"molteni": "Molteni & Colagrossi", "antuono": "Antuono et al."}[other]
            plt.plot(data[:, 0], data[:, 1], label=f"sphjax n={n}, {label}")
    plt.plot(MARTIN_MOYCE[:, 0], MARTIN_MOYCE[:, 1], "ko", label="Martin & Moyce (1952), Table 2")
    plt.plot(
        KOSHIZUKA_OKA[:, 0], KOSHIZUKA_OKA[:, 1], "bs", mfc="none", label="Koshizuka & Oka (1996)"
    )
    plt.xlabel("T = t sqrt(2g/L)"), plt.ylabel("Z / L"), plt.legend(), plt.tight_layout()
    plt.savefig(DOCS / "img" / "dam_break_front.png", dpi=120)
    plt.close()
    return wall


#: heights (m) on the right wall at which the impact's pressure profile is measured
IMPACT_HEIGHTS = (0.06, 0.08, 0.10, 0.12, 0.14, 0.16, 0.18, 0.20)
IMPACT_PROFILE = {f"y = {y:.2f} m": y for y in IMPACT_HEIGHTS}
#: Buchner's (2002) sensor P1: De Courcy et al.'s (2024) P4, y = 0.16 m
BUCHNER_P1_SENSOR = "P4"
#: the section where the flow arriving at the wall is measured: this far before it (m)
IMPACT_SECTION = 0.5


def running_mean(t, p, width=0.1):
    """Centred running mean of ``p(t)`` over ``width`` in t sqrt(g/H) (the filter applied
    to the simulation and to the experiment alike)."""
    return np.array([np.mean(p[np.abs(t - tk) <= width / 2]) for tk in t])


def impact_diagnostics(traj, case, T, window):
    """What the wall sees after the impact, averaged over the frames in ``window``: the
    probe at ``IMPACT_HEIGHTS`` on the right wall; the first layer of wall particles'
    pressure summed over the height (the force on the wall per unit width, / rho0 g H^2);
    and the flow arriving ``IMPACT_SECTION`` before the wall (depth: the highest fluid
    particle in a slice dx wide plus dx / 2; mean speed; momentum flux
    ``sum m u^2 / dx``, / rho0 g H^2) against Ritter's shallow-water solution of the dam
    break on a dry bed, ``h = (2 c - xi / t)^2 / (9 g)``, ``u = 2 (xi / t + c) / 3``,
    ``c = sqrt(g H)``, ``xi`` the section's distance from the column's initial face."""
    info = case.info
    g, H, dx, wall = info["gravity"], info["column_height"], info["dx"], info["tank_length"]
    scale = 1000.0 * g * H
    states = traj.states
    profile = [
        float(np.mean(np.asarray(sphjax.cases.probe_pressure(states, case, point))[window])) / scale
        for point in sphjax.cases.dam_break_wall_sensors(case, IMPACT_PROFILE).values()
    ]
    section = wall - IMPACT_SECTION
    force, depth, speed, flux = [], [], [], []
    frames = zip(
        np.asarray(states.position)[window],
        np.asarray(states.velocity)[window],
        np.asarray(states.pressure)[window],
        np.asarray(states.kind)[window],
        strict=True,
    )
    for xk, vk, pk, kind in frames:
        first_layer = (kind == Kind.WALL) & (np.abs(xk[:, 0] - wall - dx / 2) < 0.1 * dx)
        force.append(np.sum(pk[first_layer & (xk[:, 1] > 0)]) * dx)
        inside = (kind == Kind.FLUID) & (np.abs(xk[:, 0] - section) < dx / 2)
        depth.append(xk[inside, 1].max() + dx / 2)
        speed.append(vk[inside, 0].mean())
        flux.append(1000.0 * dx * np.sum(vk[inside, 0] ** 2))  # m u^2 / dx, m = rho0 dx^2
    t = T[window] * np.sqrt(H / g)
    c, xi = np.sqrt(g * H), section - info["column_width"]
    ritter_h = (2 * c - xi / t) ** 2 / (9 * g)
    ritter_u = 2 * (xi / t + c) / 3
    return dict(
        profile=profile,
        force=float(np.mean(force) / (scale * H)),
        depth=float(np.mean(depth)),
        speed=float(np.mean(speed)),
        flux=float(np.mean(flux) / (scale * H)),
        ritter_depth=float(np.mean(ritter_h)),
        ritter_speed=float(np.mean(ritter_u)),
        ritter_flux=float(np.mean(1000.0 * ritter_u**2 * ritter_h) / (scale * H)),
    )


def dam_break_impact(runs, rows, t_end=3.6):
    """Pressure on the right wall (sensor P1, y = 0.16 m) of the Zhou/Buchner dam break:
    arrival of the first impact, peak, and the mean over t sqrt(g/H) in [2.8, 3.5]; the
    mean pressure profile on the wall and the flow arriving at it
    (:func:`impact_diagnostics`).  ``runs``: ``(n, density diffusion, sound speed
    factor)``.  Returns the wall time and the diagnostics per run."""
    H, g = 0.6, 9.81
    scale = np.sqrt(H / g)
    wall = 0.0
    diagnostics = []
    fig, (ax, ax_profile) = plt.subplots(1, 2, figsize=(9, 3.5), width_ratios=(3, 2))
    window_ref = np.linspace(2.8, 3.5, 701)
    mean_ref = float(np.mean(np.interp(window_ref, BUCHNER_P1[:, 0], BUCHNER_P1[:, 1])))
    for n, diffusion, c_factor in runs:
        case = sphjax.cases.dam_break_impact(
            n=n, density_diffusion=diffusion, sound_speed_factor=c_factor
        )
        traj, seconds = run(case, t_end * scale, frames=int(t_end / 0.01))
        wall += seconds
        T = np.asarray(traj.times) / scale
        sensor = sphjax.cases.dam_break_wall_sensors(case)[BUCHNER_P1_SENSOR]
        p = np.asarray(sphjax.cases.probe_pressure(traj.states, case, sensor)) / (1000.0 * g * H)
        label = f"H/dx={n // 2}, {diffusion}" + ("" if c_factor == 20 else f", c0={c_factor:g}")
        arrival = float(T[np.argmax(p > 0.15)])
        window = (T >= 2.8) & (T <= 3.5)
        k = int(np.argmax(p))
        rows.append(
            (
                "dam_break_impact",
                label,
                "P1 arrival (p > 0.15)",
                "2.49",
                f"{arrival:.3f}",
                f"{arrival - 2.49:+.3f}",
            )
        )
        rows.append(
            (
                "dam_break_impact",
                label,
                "P1 mean over T in [2.8, 3.5]",
                f"{mean_ref:.3f}",
                f"{np.mean(p[window]):.3f}",
                f"{np.mean(p[window]) / mean_ref - 1:+.1%}",
            )
        )
        rows.append(
            (
                "dam_break_impact",
                label,
                "P1 rms fluctuation over [2.8, 3.5]",
                "",
                f"{np.std(p[window]):.3f}",
                "",
            )
        )
        rows.append(
            (
                "dam_break_impact",
                label,
                "P1 largest value (time)",
                "0.687 (2.77)",
                f"{p[k]:.2f} ({T[k]:.2f})",
                "",
            )
        )
        diagnostics.append(
            dict(label=label, **impact_diagnostics(traj, case, T, window), wall=seconds)
        )
        (line,) = ax.plot(T, running_mean(T, p), lw=1.0, label=f"sphjax {label}")
        ax_profile.plot(
            diagnostics[-1]["profile"], IMPACT_HEIGHTS, "o-", ms=3, color=line.get_color()
        )
    t_ref = np.linspace(BUCHNER_P1[0, 0], BUCHNER_P1[-1, 0], 300)
    p_ref = np.interp(t_ref, BUCHNER_P1[:, 0], BUCHNER_P1[:, 1])
    ax.plot(t_ref, running_mean(t_ref, p_ref), "k-", lw=1.5, label="Buchner (2002), P1")
    ax.plot(BUCHNER_P1[:, 0], BUCHNER_P1[:, 1], "ko", ms=3)
    ax.set_xlim(2.2, t_end), ax.set_ylim(-0.5, 1.5)
    ax.set_xlabel("t sqrt(g/H)"), ax.set_ylabel("p / (rho0 g H), running mean over 0.1")
    ax.legend(fontsize=7)
    ax_profile.plot([mean_ref], [0.16], "ks", label="Buchner P1")
    ax_profile.set_xlabel("mean p / (rho0 g H), t sqrt(g/H) in [2.8, 3.5]")
    ax_profile.set_ylabel("height on the wall (m)"), ax_profile.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(DOCS / "img" / "dam_break_impact.png", dpi=120)
    plt.close(fig)
    return wall, diagnostics


#: the findings of the dam-break impact's diagnostics (numbers from the tables the script
#: writes, and from the measurements named in the text)
IMPACT_NOTES = [
    "",
    "**The probe and the pressure field are right where the answer is known.** In a tank",
    "at rest (`hydrostatic_tank(height=0.6, width=0.6)`, after 1 s) the probe on the side",
    "wall reads rho0 g (H - y) at y = 0.1 to 0.45 m within 0.015 rho0 g H (10 particles",
    "over the depth) and 0.019 (20): the water's surface settles about dx / 2 high, the",
    "gradient is exact (`tests/test_dam_break_impact.py`).  After the impact three",
    "readings at P1 agree (measured separately at H/dx = 20 and 30): the probe 0.17-0.20,",
    "the wall particles' extrapolated pressure at y = 0.16 m 0.21 and 0.19, the",
    "fluid particles within 1.5 dx of the wall and dx of the sensor's height 0.09 and",
    "0.17.  The field is low there, not its sampling.",
    "",
    "**The load is there, lower down.** The wall's mean pressure is about rho0 g H at",
    "y = 0.06 m in every run, 0.56-0.65 at 0.10 m, 0.40-0.46 at 0.12 m and 0.15-0.20 at",
    "the sensor: P1 sits on the flank of a profile that falls by about 0.05 rho0 g H per",
    "centimetre.  The profile is the same at H/dx = 20 and 30, with either density",
    "diffusion and with twice the sound speed; a wider kernel (h = 2 and 2.5 dx instead",
    "of 1.5 dx, H/dx = 20, measured separately) gives 0.21 and 0.22 at P1.  None of these",
    "is the cause.  The force on the wall, 0.24-0.31 rho0 g H^2, is what the arriving",
    "layer brings: its momentum flux is 0.21-0.22 rho0 g H^2 (Ritter: 0.23), and a layer",
    "turned upwards by the wall pushes on it with that flux plus its hydrostatic force",
    "(0.01); the rest is water accumulating at the wall.  So the total load agrees with",
    "the flow that reaches the wall; it acts within about 0.15 m (twice the layer's",
    "depth) of the floor.  For the experiment's 0.59 at 0.16 m the same load would have",
    "to be spread over a taller region, i.e. a deeper arriving flow.",
    "",
    "**The arriving layer is thin.** 0.5 m before the wall it is 0.074 m deep (2.5",
    "particles at H/dx = 20, 3.7 at 30) and runs at 3.1 m/s: 23 % shallower and 5 %",
    "faster than Ritter's ideal shallow-water flow, the same at both resolutions.  The",
    "simulation is 2D, its floor is free-slip and it releases the column instantly; a",
    "floor's friction and a gate's opening time make a dam-break flow deeper and",
    "slower.  Open: whether the layer deepens beyond H/dx = 30 (not run; between 20",
    "and 30 the profile did not change above y = 0.12 m), and what the experiment's layer",
    "depth was (no height record is digitised with the pressure).  Adami, Hu & Adams",
    "(2012) moved their probe below the sensor for this comparison, citing Greco's",
    "report of uncertainties in the measurement, and SPHinXsys's dam break observes the",
    "wall at y = 0.2 H (0.12 m here); at that height sphjax reads 0.40-0.46, 23-32 %",
    "below Buchner's P1.",
]

#: the comparison with TrixiParticles.jl and De Courcy et al. (2024): numbers measured
#: separately (runs at H/dx = 15 and 20 sampled several ways; the references' files)
IMPACT_ANCHOR = [
    "",
    "## Dam-break impact: TrixiParticles.jl and De Courcy et al. as the anchor",
    "",
    "TrixiParticles.jl (WCSPH like sphjax: Wendland C2, Adami walls with pressure",
    "extrapolation, 4 wall layers, Monaghan alpha = 0.02, delta-SPH, c0 = 20 sqrt(g H), the",
    "same 1.2 x 0.6 m column in a tank 5.366 H long) validated this case against Buchner's",
    "P1 until October 2025 (repository `trixi-framework/TrixiParticles.jl`,",
    "`validation/dam_break_2d/`, the state before PR #934).  Its P1: the mean of 10 Shepard",
    "interpolations of the fluid's pressure on a line from y = 0.160 down to 0.151 m, dx / 2",
    "inside the wall, with twice the smoothing length (h = 1.75 dx), negative pressures",
    "clipped to 0 and dry points counted as 0.  Its own stored results of that P1",
    "(`validation_reference_wcsph_0015.json`, `_00075`, `_0001875`: H/dx = 40, 80, 320)",
    "average 0.253, 0.209 and 0.213 rho0 g H over t sqrt(g/H) in [2.8, 3.5] against",
    "Buchner's 0.590: the same gap as sphjax's 0.19.  PR #934 removed Buchner's data and now",
    "compares with the incompressible delta-SPH of De Courcy et al. (2024, CMAME 420,",
    "116700; H/dx = 400) at four wall sensors 8.4 mm long centred at y = 0.006, 0.030, 0.060",
    "and 0.160 m (`decourcy_pressure_sensor_P1..P4.csv`).  Means over [2.8, 3.5]",
    "(p / rho0 g H; sphjax: `probe_pressure` at the sensor's centre on the wall's face,",
    "runs of this section at H/dx = 15 and 20, float64):",
    "",
    "| sensor (y) | De Courcy H/400 | TrixiParticles H/40, 80, 400 | sphjax H/15 | sphjax H/20 |",
    "|---|---|---|---|---|",
    "| P1 (0.006 m) | 1.260 | 1.097, 1.172, 1.211 | 1.29 | 1.49 |",
    "| P2 (0.030 m) | 1.160 | 1.016, 1.107, 1.135 | 1.20 | 1.34 |",
    "| P3 (0.060 m) | 0.970 | 0.866, 0.937, 0.965 | 0.93 | 0.99 |",
    "| P4 (0.160 m, Buchner's P1) | 0.185 | 0.218, 0.180, 0.191 | 0.20 | 0.19 |",
    "",
    "At y = 0.06 and 0.16 m sphjax is within 8 % of De Courcy's H/400 result (a test:",
    "`tests/test_dam_break_impact.py`, H/dx = 15, 10 %); nearer the floor (0.006 and",
    "0.030 m) it reads 3-4 % high at H/dx = 15 and 15-18 % at 20.  **Two independent SPH",
    "codes at up to 20 times sphjax's resolution read 0.18-0.22 at y = 0.16 m, as sphjax",
    "does: the factor of three against Buchner's P1 is not a",
    "defect of sphjax's set-up, boundary, kernel or sound speed.**  It lies between SPH and",
    "the curve digitised as P1 at 0.16 m.  The curves that TrixiParticles' README",
    "attributes to Marrone et al. (2011), delta-SPH at H/dx = 40, 80 and 320",
    "(`sim_pressure_sensor_P1.csv`), do match Buchner (0.625-0.639); their probe's height",
    "is not given with them.  Other codes compare Buchner's P1 lower on the wall: PySPH's",
    "`dam_break_2d_buchner` and SPHinXsys's dam break at y = 0.2 H (0.12 m), Adami et al.",
    "(2012) and the earlier TrixiParticles set-up with the probe's top at the sensor's",
    "centre.",
    "",
    "How P1 depends on where and how it is sampled (sphjax, H/dx = 20, Molteni diffusion,",
    "free slip; the same run for every row; arrival: first time above 0.15; peak: the largest",
    "running mean over 0.1 in t sqrt(g/H) in [2.4, 3.0]); Buchner: 0.590, arrival 2.49, peak",
    "0.68 at 2.77:",
    "",
    "| sampling | plateau | arrival | peak (time) |",
    "|---|---|---|---|",
    "| probe at y = 0.16 m (the case's P1) | 0.188 | 2.53 | 0.25 (2.64) |",
    "| TrixiParticles' old P1 (line 0.151-0.160 m, 2 h, clipped) | 0.356 | 2.38 | 1.60 (2.48) |",
    "| probe at y = 0.12 m (0.2 H: PySPH, SPHinXsys) | 0.422 | 2.48 | 0.52 (2.82) |",
    "| probe averaged over y = 0.07-0.16 m (Adami's shifted sensor) | 0.483 | 2.44 | 0.62 (2.47) |",
    "| the same line, dx / 2 inside, 2 h, negatives clipped | 0.584 | 2.33 | 1.51 (2.48) |",
    "| probe at y = 0.096 m (0.16 H) | 0.593 | 2.46 | 1.10 (2.47) |",
    "",
    "The wall's mean pressure equals Buchner's 0.59 at y = 0.097 m (0.16 H); a sensor at",
    "0.16 H instead of 0.16 m would explain the plateau, but the thesis (not available here)",
    "would have to say so.  Where the plateau matches, the impact does not: the simulation's",
    "pressure spikes at the arrival (t sqrt(g/H) = 2.45-2.5) and dips, the experiment's rises",
    "over 0.25 to its peak at 2.77, so no sampling meets the peak (30 %) and its time (0.1)",
    "together with the plateau (10 %).  The target is not met against the experiment; against",
    "De Courcy et al.'s four sensors it is met at H/dx = 60 and 80 (the last section).",
]


def impact_section(diagnostics):
    """The page's section on the dam-break impact's diagnostics (:func:`impact_diagnostics`)."""
    heights = " | ".join(f"{y:.2f}" for y in IMPACT_HEIGHTS)
    lines = [
        "",
        "## Dam-break impact: where the load acts",
        "",
        "Why P1 reads a third of the experiment's plateau, measured on the runs above",
        "(`python docs/scripts/validate_fluid.py --cases dam_break_impact`).  All values",
        "are means over t sqrt(g/H) in [2.8, 3.5].",
        "",
        "Mean pressure on the right wall (the probe, p / rho0 g H) against the height y (m);",
        "Buchner's P1 is 0.593 at y = 0.16:",
        "",
        f"| run | {heights} |",
        "|---" * (len(IMPACT_HEIGHTS) + 1) + "|",
    ]
    for d in diagnostics:
        lines.append(f"| {d['label']} | " + " | ".join(f"{p:.2f}" for p in d["profile"]) + " |")
    lines += [
        "",
        f"The flow arriving {IMPACT_SECTION} m before the wall (depth: the highest particle",
        "plus dx / 2; u: mean horizontal speed; rho u^2 h: momentum flux, / rho0 g H^2)",
        "against Ritter's shallow-water solution of a dam break on a dry bed, and the force",
        "on the wall (the first layer of wall particles' pressure summed over the height,",
        "/ rho0 g H^2):",
        "",
        "| run | depth (m) | Ritter | u (m/s) | Ritter | rho u^2 h | Ritter | wall force |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for d in diagnostics:
        lines.append(
            f"| {d['label']} | {d['depth']:.3f} | {d['ritter_depth']:.3f} | {d['speed']:.2f} | "
            f"{d['ritter_speed']:.2f} | {d['flux']:.3f} | {d['ritter_flux']:.3f} | "
            f"{d['force']:.3f} |"
        )
    return lines + IMPACT_NOTES + IMPACT_ANCHOR


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="coarser resolutions")
    parser.add_argument(
        "--tg-n", type=int, nargs="+", default=None, help="Taylor-Green resolutions (25 50 100)"
    )
    parser.add_argument(
        "--tg-re",
        type=float,
        nargs="+",
        default=None,
        help="Taylor-Green Reynolds numbers (50 100 400 1000); the runs are added to the "
        "stored ones (same Re, n and precision: replaced)",
    )
    parser.add_argument(
        "--float32",
        action="store_true",
        help="run in float32 (the Taylor-Green KE error is the same to 0.01 %%)",
    )
    parser.add_argument(
        "--cases",
        nargs="*",
        default=[
            "taylor_green",
            "poiseuille",
            "hydrostatic_tank",
            "dam_break",
            "dam_break_antuono",
        ],
        help="cases to rerun (default: all but dam_break_impact; --cases with no names: "
        "only rewrite the page); the others keep their rows from "
        "docs/figures/validation_fluid.json",
    )
    args = parser.parse_args()
    if args.float32:
        jax.config.update("jax_enable_x64", False)
    (DOCS / "img").mkdir(exist_ok=True)
    store = DOCS / "figures" / "validation_fluid.json"
    saved = json.loads(store.read_text()) if store.exists() else {}
    tg_n = args.tg_n or ([25, 50] if args.quick else [25, 50, 100])
    for name in args.cases:
        rows = []
        if name == "taylor_green":
            reynolds = [int(r) if r == int(r) else r for r in args.tg_re or TG_REYNOLDS]
            stored = saved.get("taylor_green_results", [])
            wall, results = taylor_green(tg_n, rows, reynolds, stored)
            saved["taylor_green_results"] = results
        elif name == "poiseuille":
            wall = poiseuille(20, rows)
        elif name == "hydrostatic_tank":
            wall = hydrostatic(20, rows)
        elif name == "dam_break":
            wall = dam_break(20 if args.quick else 30, rows)
        elif name == "dam_break_impact":
            runs = (
                [(30, "molteni", 20)]
                if args.quick
                else [
                    (40, "molteni", 20),
                    (40, "antuono", 20),
                    (40, "molteni", 40),
                    (60, "molteni", 20),
                ]
            )
            wall, saved["dam_break_impact_diagnostics"] = dam_break_impact(runs, rows)
        elif name == "dam_break_antuono":
            wall = dam_break(20 if args.quick else 30, rows, "antuono")
        else:
            raise SystemExit(f"--cases: unknown case {name!r}")
        saved[name] = dict(rows=rows, wall=wall)
    store.write_text(json.dumps(saved, indent=1))
    lines = [
        "# Fluid validation",
        "",
        "Produced by `python docs/scripts/validate_fluid.py` (float64). Error = measured /",
        "reference - 1.  Dam break: Martin & Moyce (1952), Table 2, is the reference of",
        "record; Koshizuka & Oka (1996) is their own later experiment (the table often",
        "plotted as Martin & Moyce's); the two differ by up to 7 %.",
        "",
        "`dam_break (antuono)` is the same run with Antuono et al.'s (2010, 2012) density",
        'diffusion (`density_diffusion="antuono"`, renormalised density gradient) instead of',
        "Molteni & Colagrossi's with the hydrostatic correction: the surge front is the same to",
        "0.1 % of Z and the early-time lead against Martin & Moyce (about 0.17 in T at",
        "Z/L = 1.44) is unchanged, so the lead does not come from the density diffusion.",
        "Weakly compressible SPH commonly runs ahead of this experiment early on; Martin &",
        "Moyce removed a gate (the simulation releases the column instantly) and had wall",
        "friction.",
        "",
        "`dam_break_impact`: the dam break of Zhou et al. (1999) and Buchner (2002) (column",
        "1.2 m wide and H = 0.6 m high, tank 5.366 H long; `sphjax.cases.dam_break_impact(n)`,",
        "`dam_break(column_width=1.2, column_height=0.6, tank_length_factor=2.683,",
        'wall_slip="free_slip", artificial_alpha=0.02)`), pressure on the right wall at',
        'sensor P1 (y = 0.16 m, `dam_break_wall_sensors(case)["P4"]`) from',
        "`sphjax.cases.probe_pressure` (kernel average of the fluid's pressure at the wall's",
        "face), in units of rho0 g H against t sqrt(g/H).  Reference: Buchner's measurement",
        "of P1 (PhD thesis, TU Delft 2002), as digitised in TrixiParticles.jl.  Filter: the",
        "plateau is the mean over t sqrt(g/H) in [2.8, 3.5], of the simulation's frames and",
        "of the experiment's curve alike; the figure shows both through a running mean over",
        "0.1.  The impact arrives on time; the plateau at P1 is about a third of the",
        "measured one.  Not met: the plateau within 20 % (`tests/test_dam_break_impact.py`",
        "records it as a strict xfail); why is measured below, under *Dam-break impact:",
        "where the load acts*.",
        "",
        "| case | resolution | quantity | reference | measured | error |",
        "|---|---|---|---|---|---|",
    ]
    walls = {}
    for name in (
        "taylor_green",
        "poiseuille",
        "hydrostatic_tank",
        "dam_break",
        "dam_break_antuono",
        "dam_break_impact",
    ):
        if name in saved:
            lines += ["| " + " | ".join(r) + " |" for r in saved[name]["rows"]]
            walls[name] = saved[name]["wall"]
    lines += ["", "Wall time (s): " + ", ".join(f"{k} {v:.0f}" for k, v in walls.items())]
    if "taylor_green_results" in saved:
        taylor_green_plot(saved["taylor_green_results"])
        lines += taylor_green_table(saved["taylor_green_results"])
    lines += [""]
    lines += [
        f"![{name}](img/{name}.png)"
        for name in (
            "taylor_green_ke",
            "poiseuille",
            "hydrostatic",
            "dam_break_front",
            "dam_break_impact",
        )
    ]
    if "dam_break_impact_diagnostics" in saved:
        lines += impact_section(saved["dam_break_impact_diagnostics"])
    page = DOCS / "validation_fluid.md"
    # the lid-driven cavity's section comes from docs/scripts/validate_cavity.py: kept
    cavity = "\n## Lid-driven cavity"
    kept = page.read_text() if page.exists() else ""
    kept = kept[kept.index(cavity) :] if cavity in kept else ""
    page.write_text("\n".join(lines) + "\n" + kept)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
