"""The lid-driven cavity against Ghia, Ghia & Shin (1982): one resolution per invocation.

    python docs/scripts/validate_cavity.py --n 30            # run, append to the jsonl
    python docs/scripts/validate_cavity.py --n 30 --re 1000 --t-end 30
    python docs/scripts/validate_cavity.py --plot            # figure from the jsonl

Each run appends one line to docs/data/cavity.jsonl (resolution, particles, steps, wall
time, load average, the RMS differences from Ghia's Tables I and II over the lid speed,
the change of the profiles per unit time at the end, and the profiles themselves); a
resolution already there for the same Reynolds number, end time and options is skipped
unless ``--force``, so an interrupted sweep resumes where it stopped.  The profiles are
time-averaged over the last ``--average`` time units (frames every 0.1 L/U): a WCSPH
snapshot carries acoustic noise of a few per cent of U.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import time

import numpy as np

import sphjax
from sphjax.cases import centreline_profiles, lid_driven_cavity

DOCS = pathlib.Path(__file__).resolve().parents[1]
RESULTS = DOCS / "data" / "cavity.jsonl"
FIGURE = DOCS / "figures" / "cavity_centrelines.png"


def ghia(reynolds):
    """Ghia et al.'s interior points and values at ``reynolds`` (100 or 1000)."""
    column = {100: 1, 1000: 2}[int(reynolds)]
    u = np.loadtxt(DOCS / "data" / "ghia_1982_u_vertical_centreline.csv", delimiter=",",
                   skiprows=7)[1:-1]  # fmt: skip
    v = np.loadtxt(DOCS / "data" / "ghia_1982_v_horizontal_centreline.csv", delimiter=",",
                   skiprows=7)[1:-1]  # fmt: skip
    return u[:, 0], u[:, column], v[:, 0], v[:, column]


def rms(a, b):
    return float(np.sqrt(np.mean((np.asarray(a) - np.asarray(b)) ** 2)))


def run(n, reynolds, t_end, average, options):
    case = lid_driven_cavity(n=n, reynolds=reynolds, t_end=t_end, **options)
    every = max(1, int(round(0.1 / case.dt)))
    load = os.getloadavg()[0]
    start = time.perf_counter()
    traj = sphjax.simulate(case, t_end=t_end, save_every=every)
    u, v = (np.asarray(a) for a in centreline_profiles(traj, case))
    wall = time.perf_counter() - start
    t = np.asarray(traj.times)
    y, u_ref, x, v_ref = ghia(reynolds)
    last = t >= t[-1] - average - 1e-9
    u_avg, v_avg = u[last].mean(0), v[last].mean(0)
    before = (t >= t[-1] - 2 * average - 1e-9) & (t < t[-1] - average - 1e-9)
    change = max(np.abs(u_avg - u[before].mean(0)).max(), np.abs(v_avg - v[before].mean(0)).max())
    return dict(
        n=n,
        reynolds=reynolds,
        t_end=t_end,
        average=average,
        options=options,
        particles=int(case.state.position.shape[0]),
        dx=case.info["dx"],
        dt=float(case.dt),
        steps=int(round(t_end / case.dt)),
        wall_s=round(wall, 1),
        load_average=round(load, 2),
        rms_u=rms(u_avg, u_ref),
        rms_v=rms(v_avg, v_ref),
        rms_u_last_frame=rms(u[-1], u_ref),
        rms_v_last_frame=rms(v[-1], v_ref),
        change_per_unit_time=float(change / average),
        y=y.tolist(),
        u=u_avg.tolist(),
        x=x.tolist(),
        v=v_avg.tolist(),
    )


def records():
    if not RESULTS.exists():
        return []
    return [json.loads(line) for line in RESULTS.read_text().splitlines() if line.strip()]


def plot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in records() if r["reynolds"] == 100 and not r["options"]]
    y, u_ref, x, v_ref = ghia(100)
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4.5))
    a.plot(u_ref, y, "ks", label="Ghia et al. (1982)")
    b.plot(x, v_ref, "ks", label="Ghia et al. (1982)")
    for r in sorted(rows, key=lambda r: r["n"]):
        label = f"SPH n = {r['n']}"
        order = np.argsort(r["y"])
        a.plot(np.asarray(r["u"])[order], np.asarray(r["y"])[order], "-o", ms=3, label=label)
        order = np.argsort(r["x"])
        b.plot(np.asarray(r["x"])[order], np.asarray(r["v"])[order], "-o", ms=3, label=label)
    a.set(xlabel="u / U", ylabel="y / L", title="u on x = L/2 (Re 100)")
    b.set(xlabel="x / L", ylabel="v / U", title="v on y = L/2 (Re 100)")
    a.legend(fontsize=8)
    fig.tight_layout()
    FIGURE.parent.mkdir(exist_ok=True)
    fig.savefig(FIGURE, dpi=110)
    print(f"wrote {FIGURE}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, help="particles per side")
    parser.add_argument("--re", type=float, default=100.0)
    parser.add_argument("--t-end", type=float, default=10.0)
    parser.add_argument("--average", type=float, default=2.0, help="time units averaged")
    parser.add_argument("--no-transport-velocity", action="store_true")
    parser.add_argument("--force", action="store_true", help="rerun a resolution done")
    parser.add_argument("--plot", action="store_true")
    args = parser.parse_args()
    if args.plot:
        plot()
        return
    if args.n is None:
        parser.error("give --n (or --plot)")
    options = {"transport_velocity": False} if args.no_transport_velocity else {}
    key = (args.n, args.re, args.t_end, args.average, options)
    done = [(r["n"], r["reynolds"], r["t_end"], r["average"], r["options"]) for r in records()]
    if key in done and not args.force:
        print(f"n = {args.n} already in {RESULTS.name}; --force to rerun")
        return
    record = run(args.n, args.re, args.t_end, args.average, options)
    with RESULTS.open("a") as f:
        f.write(json.dumps(record) + "\n")
    print({k: v for k, v in record.items() if k not in ("y", "u", "x", "v")})


if __name__ == "__main__":
    main()
