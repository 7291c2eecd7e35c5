"""Wall pressure of the dam break against De Courcy et al. (2024): one resolution per call.

    python docs/scripts/validate_impact.py --n 40     # H/dx = 20: run, append to the jsonl
    python docs/scripts/validate_impact.py --table    # the table and the figure from it
    python docs/scripts/validate_impact.py --table --filter 0.05

The dam break of Zhou et al. (1999) and Buchner (2002) as TrixiParticles.jl sets it up
(`sphjax.cases.dam_break_impact`: column 1.2 x 0.6 m, tank 5.366 H long, free-slip walls,
Monaghan alpha = 0.02, c0 = 20 sqrt(g H)), observed by `sphjax.observables.probe_pressure`
at the centres of the four wall sensors of De Courcy et al. (2024, incompressible
delta-SPH at H/dx = 400; `docs/data/decourcy_2024_dam_break_wall_pressure.csv`;
`sphjax.cases.dam_break_wall_sensors`).  Both series, the simulation's
and the reference's, get the same filter: linear interpolation onto a grid of 0.0025 in
t sqrt(g/H) and a centred running mean over ``FILTER`` (``--filter``).  Compared: the
first peak (the largest filtered value in ``PEAK_WINDOW``) and its time, and the plateau
(the mean over ``PLATEAU``).  Each run appends one line to
``docs/data/dam_break_impact_sensors.jsonl`` (resolution, particles, steps, wall and CPU
seconds, load average, the series); a resolution already there with the same precision
is skipped unless ``--force``, so an interrupted sweep resumes where it stopped.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import time

import numpy as np

from sphjax.cases import DAM_BREAK_WALL_SENSORS

DOCS = pathlib.Path(__file__).resolve().parents[1]
REFERENCE = DOCS / "data" / "decourcy_2024_dam_break_wall_pressure.csv"
RESULTS = DOCS / "data" / "dam_break_impact_sensors.jsonl"
FIGURE = DOCS / "figures" / "dam_break_impact_sensors.png"
H, G = 0.6, 9.81
SENSORS = DAM_BREAK_WALL_SENSORS  # De Courcy et al.'s P1-P4: name -> height (m)
FRAME = 0.005  # frame spacing, t sqrt(g/H)
T_END = 3.6
FILTER = 0.1  # running-mean width, t sqrt(g/H) (as the impact figure of validate_fluid.py)
PEAK_WINDOW = (2.3, 3.0)
PLATEAU = (2.8, 3.5)


def reference() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """De Courcy et al.'s series per sensor: (t sqrt(g/H), p / rho0 g H)."""
    rows = np.genfromtxt(REFERENCE, delimiter=",", comments="#", skip_header=8, dtype=None,
                         encoding="ascii")  # fmt: skip
    return {
        name: (
            np.array([r[2] for r in rows if r[0] == name]),
            np.array([r[3] for r in rows if r[0] == name]),
        )
        for name in SENSORS
    }


def filtered(t, p, width=FILTER):
    """``p(t)`` on the common grid, running mean over ``width`` (the same for both)."""
    grid = np.arange(2.2, T_END + 1e-9, 0.0025)
    values = np.interp(grid, t, p)
    width = int(round(width / 0.0025)) | 1
    padded = np.pad(values, width // 2, mode="edge")
    return grid, np.convolve(padded, np.ones(width) / width, mode="valid")


def metrics(t, p, width=FILTER) -> dict:
    """First peak (value, time) of the filtered series and the plateau mean."""
    grid, f = filtered(t, p, width)
    window = (grid >= PEAK_WINDOW[0]) & (grid <= PEAK_WINDOW[1])
    k = int(np.argmax(np.where(window, f, -np.inf)))
    plateau = (grid >= PLATEAU[0]) & (grid <= PLATEAU[1])
    return dict(peak=float(f[k]), peak_time=float(grid[k]), plateau=float(np.mean(f[plateau])))


def run(n: int, float64: bool) -> dict:
    import jax

    jax.config.update("jax_enable_x64", float64)
    import sphjax
    from sphjax.observables import probe_pressure

    case = sphjax.cases.dam_break_impact(n=n)
    scale = np.sqrt(H / G)
    save_every = max(1, int(round(FRAME * scale / case.dt)))
    n_steps = save_every * int(np.ceil(T_END * scale / case.dt / save_every))
    load = os.getloadavg()[0]
    t0, c0 = time.perf_counter(), time.process_time()
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=save_every)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    T = np.asarray(traj.times) / scale
    pressure = {
        name: np.asarray(probe_pressure(traj.states, case, point)) / (1000.0 * G * H)
        for name, point in sphjax.cases.dam_break_wall_sensors(case, SENSORS).items()
    }
    return dict(
        n=n,
        H_dx=n // 2,
        float64=float64,
        particles=case.n_particles,
        steps=n_steps,
        dt=case.dt,
        wall_s=round(wall, 1),
        cpu_s=round(cpu, 1),
        load=round(load, 2),
        t=[round(float(x), 5) for x in T],
        p={name: [round(float(x), 5) for x in v] for name, v in pressure.items()},
    )


def load_runs() -> list[dict]:
    if not RESULTS.exists():
        return []
    return [json.loads(line) for line in RESULTS.read_text().splitlines() if line.strip()]


def table(runs: list[dict], width=FILTER) -> list[str]:
    """The comparison, one row per sensor and resolution, in markdown."""
    ref = {name: metrics(*series, width) for name, series in reference().items()}
    lines = [
        "| sensor (y) | run | first peak (time) | peak error | time error | plateau "
        "| plateau error |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, y in SENSORS.items():
        r = ref[name]
        lines.append(
            f"| {name} ({y:.3f} m) | De Courcy H/400 | {r['peak']:.3f} ({r['peak_time']:.3f}) "
            f"| | | {r['plateau']:.3f} | |"
        )
        for run_ in sorted(runs, key=lambda r: (r["float64"], r["n"])):
            m = metrics(np.array(run_["t"]), np.array(run_["p"][name]), width)
            precision = "float64" if run_["float64"] else "float32"
            lines.append(
                f"| | sphjax H/{run_['H_dx']} ({precision}) | {m['peak']:.3f} "
                f"({m['peak_time']:.3f}) | {m['peak'] / r['peak'] - 1:+.1%} "
                f"| {m['peak_time'] - r['peak_time']:+.3f} | {m['plateau']:.3f} "
                f"| {m['plateau'] / r['plateau'] - 1:+.1%} |"
            )
    return lines


def figure(runs: list[dict], width=FILTER) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(9, 6), sharex=True)
    for ax, (name, (t_ref, p_ref)) in zip(axes.flat, reference().items(), strict=True):
        ax.plot(
            *filtered(t_ref, p_ref, width), "k-", lw=1.5, label="De Courcy et al. (2024), H/400"
        )
        for run_ in sorted(runs, key=lambda r: (r["float64"], r["n"])):
            label = f"sphjax H/{run_['H_dx']}" + (", float64" if run_["float64"] else "")
            series = filtered(np.array(run_["t"]), np.array(run_["p"][name]), width)
            ax.plot(*series, lw=1, label=label)
        ax.set_title(f"{name}, y = {SENSORS[name]:.3f} m", fontsize=9)
        ax.set_xlim(2.2, T_END)
        ax.set_ylabel(f"p / rho0 g H, mean over {width}")
    for ax in axes[1]:
        ax.set_xlabel("t sqrt(g/H)")
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(FIGURE, dpi=120)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, help="fluid particles across the column (2 H/dx)")
    parser.add_argument("--float64", action="store_true")
    parser.add_argument("--force", action="store_true", help="rerun a resolution already saved")
    parser.add_argument("--table", action="store_true", help="print the table, draw the figure")
    parser.add_argument(
        "--filter", type=float, default=FILTER, help="running-mean width in t sqrt(g/H)"
    )
    args = parser.parse_args(argv)
    if args.n is None and not args.table:
        parser.error("give --n N (a run) or --table")
    if args.n is not None:
        done = [r for r in load_runs() if r["n"] == args.n and r["float64"] == args.float64]
        if done and not args.force:
            print(f"n = {args.n} already in {RESULTS.name} (--force reruns it)")
        else:
            row = run(args.n, args.float64)
            with RESULTS.open("a") as f:
                f.write(json.dumps(row) + "\n")
            print({k: v for k, v in row.items() if k not in ("t", "p")})
    if args.table:
        runs = load_runs()
        print("\n".join(table(runs, args.filter)))
        figure(runs, args.filter)


if __name__ == "__main__":
    main()
