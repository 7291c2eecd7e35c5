"""A rigid body floating on water against Archimedes: one resolution per invocation.

    python docs/scripts/validate_rigid.py --n 6              # run, append to the jsonl
    python docs/scripts/validate_rigid.py --n 10 --density-ratio 0.3
    python docs/scripts/validate_rigid.py --table            # the table from the jsonl

`sphjax.cases.floating_body`: the body starts level with 40 % of its height under water
and heaves about its floating position.  The height of its bottom against time, sampled
every 0.01 s, is fitted with a damped oscillation
``b(t) = b_eq + A exp(-t / tau) cos(omega t + phi)``; the error is ``b_eq`` against
Archimedes' floating position (``case.info["equilibrium_bottom"]``) over the draught.
Each run appends one line to docs/data/floating_body.jsonl (resolution, particles, steps,
wall time, load average, the fit and the error, the sampled heights); a set-up already
there is skipped unless ``--force``, so an interrupted sweep resumes.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import time

import numpy as np
from scipy.optimize import curve_fit

import sphjax
from sphjax.cases import body_bottom, floating_body

DOCS = pathlib.Path(__file__).resolve().parents[1]
RESULTS = DOCS / "data" / "floating_body.jsonl"


def damped(t, bottom, amplitude, decay, omega, phase):
    return bottom + amplitude * np.exp(-t / decay) * np.cos(omega * t + phase)


def fit(t, b, period_guess):
    """``(b_eq, amplitude, decay, period)`` of the damped oscillation through ``b(t)``."""
    guess = [b[-len(b) // 3 :].mean(), b[0] - b.mean(), 1.0, 2 * np.pi / period_guess, 0.0]
    p, _ = curve_fit(damped, t, b, p0=guess, maxfev=20000)
    return p[0], p[1], p[2], 2 * np.pi / p[3], float(np.sqrt(np.mean((damped(t, *p) - b) ** 2)))


def run(n, density_ratio, t_end):
    case = floating_body(n=n, density_ratio=density_ratio, t_end=t_end)
    every = max(1, int(round(0.01 / case.dt)))
    start = time.perf_counter()
    trajectory = sphjax.simulate(case, save_every=every)
    wall = time.perf_counter() - start
    t = np.asarray(trajectory.times)
    b = np.asarray(body_bottom(trajectory.states, case))
    # the heave period with the added mass of about a half cylinder of water
    info = case.info
    bottom, amplitude, decay, period, residual = fit(t, b, 2.0 * info["heave_period"])
    draught = info["equilibrium_draught"]
    return dict(
        n=n,
        density_ratio=density_ratio,
        t_end=t_end,
        particles=int(case.state.position.shape[0]),
        steps=int(round(t_end / case.dt)),
        wall_s=round(wall, 1),
        load=os.getloadavg()[0],
        equilibrium_bottom=info["equilibrium_bottom"],
        fitted_bottom=bottom,
        draught_error=(bottom - info["equilibrium_bottom"]) / draught,
        amplitude=amplitude,
        decay=decay,
        period=period,
        residual=residual,
        t=t.round(5).tolist(),
        bottom=b.round(6).tolist(),
    )


def table():
    rows = [json.loads(line) for line in RESULTS.read_text().splitlines()]
    columns = ("density ratio", "n", "particles", "steps", "wall s", "draught error")
    print("| " + " | ".join((*columns, "period s", "residual mm")) + " |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in sorted(rows, key=lambda r: (r["density_ratio"], r["n"])):
        print(
            f"| {r['density_ratio']} | {r['n']} | {r['particles']} | {r['steps']} | "
            f"{r['wall_s']:.0f} | {100 * r['draught_error']:+.2f} % | {r['period']:.3f} | "
            f"{1000 * r['residual']:.2f} |"
        )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=6, help="particles across the body's height")
    parser.add_argument("--density-ratio", type=float, default=0.5)
    parser.add_argument("--t-end", type=float, default=2.5)
    parser.add_argument("--force", action="store_true", help="run again if already there")
    parser.add_argument("--table", action="store_true", help="print the table and stop")
    args = parser.parse_args()
    if args.table:
        return table()
    key = (args.n, args.density_ratio, args.t_end)
    if RESULTS.exists() and not args.force:
        for line in RESULTS.read_text().splitlines():
            r = json.loads(line)
            if (r["n"], r["density_ratio"], r["t_end"]) == key:
                print(f"already there: n={args.n}, density ratio {args.density_ratio}")
                return
    row = run(args.n, args.density_ratio, args.t_end)
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    with RESULTS.open("a") as out:
        out.write(json.dumps(row) + "\n")
    print(
        f"n={row['n']}: draught error {100 * row['draught_error']:+.2f} %, period "
        f"{row['period']:.3f} s, {row['particles']} particles, {row['wall_s']} s"
    )


if __name__ == "__main__":
    main()
