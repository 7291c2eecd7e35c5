"""Produce the numbers and plots of docs/validation_solid.md.

    python docs/scripts/validate_solid.py [--plate-n 6 8 12] [--csm-n 9 13 17] [--t-csm 2.1]
        [--csm-placement surface|cell]

* Oscillating plate (Gray, Monaghan & Swift 2001), V_f = 0.001: period and tip amplitude
  at three resolutions against linear theory (T = 0.2541 s, A = 2.31e-3 m).
* Turek-Hron CSM3 (``turek_hron_csm``'s default set-up: particles on the faces,
  h = sqrt(2) dx, root embedded in the cylinder; ``--csm-placement cell`` gives the
  cell-centred set-up of earlier versions, clamped at the cylinder's surface, h = 1.2 dx):
  tip displacement at three resolutions against the finite-element
  reference curve of Turek & Hron (2006), the benchmark's published CSM3 tip
  displacement (``docs/data/turek_hron_csm3_tip_displacement.csv``), and the table
  values (u_y = -63.607 +- 65.160 mm, 1.0995 Hz).

Writes ``docs/figures/solid_plate.png``, ``docs/figures/solid_csm3.png`` and
``docs/figures/validation_solid.json``; prints Markdown tables.  Float32, as a user runs.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import sphjax  # noqa: E402
from sphjax.cases import oscillation_stats, tip_displacement  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
FIGURES = ROOT / "docs" / "figures"
REFERENCE = ROOT / "docs" / "data" / "turek_hron_csm3_tip_displacement.csv"
PLATE_PERIOD, PLATE_AMPLITUDE = 0.2541, 2.31e-3
CSM3 = dict(mean=-63.607e-3, amplitude=65.160e-3, frequency=1.0995)


def run(case, t_end, save_every):
    n_steps = save_every * int(np.ceil(t_end / case.dt / save_every))
    t0 = time.perf_counter()
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=save_every)
    seconds = time.perf_counter() - t0
    return np.asarray(traj.times), np.asarray(tip_displacement(traj, case)), n_steps, seconds


def plate(resolutions, t_end, h_factor, cfl):
    rows, curves = [], []
    for n in resolutions:
        case = sphjax.cases.oscillating_plate(n=n, amplitude=0.001, h_factor=h_factor, cfl=cfl)
        t, u, steps, seconds = run(case, t_end, 20)
        s = oscillation_stats(t, u[:, 1])
        row = dict(
            n=n,
            dx=case.info["dx"],
            particles=case.n_particles,
            steps=steps,
            seconds=seconds,
            period=s["period"],
            amplitude=s["amplitude"],
            period_error=s["period"] / PLATE_PERIOD - 1,
            amplitude_error=s["amplitude"] / PLATE_AMPLITUDE - 1,
        )
        print("plate", row, flush=True)
        rows.append(row)
        curves.append((n, t, u[:, 1]))
    fig, ax = plt.subplots(figsize=(7, 4))
    omega = 2 * np.pi / PLATE_PERIOD
    tt = np.linspace(0, t_end, 500)
    ax.plot(tt, 1e3 * PLATE_AMPLITUDE * np.sin(omega * tt), "k--", label="linear theory")
    for n, t, uy in curves:
        ax.plot(t, 1e3 * uy, label=f"SPH, H/dx = {n}")
    ax.set(xlabel="t (s)", ylabel="tip u_y (mm)", title="Oscillating plate, V_f = 0.001")
    ax.legend()
    fig.tight_layout()
    fig.savefig(FIGURES / "solid_plate.png", dpi=120)
    return rows


def csm3(resolutions, t_end, placement, cfl, reference):
    ref = np.loadtxt(reference, delimiter=",", skiprows=1) if reference.exists() else None
    rows, curves = [], []
    if ref is not None:
        sel = ref[:, 0] <= t_end
        s = oscillation_stats(ref[sel, 0], ref[sel, 2])
        print("reference curve over the same window", s)
    for n in resolutions:
        case = sphjax.cases.turek_hron_csm(
            n=n, placement=placement, embedded_root=placement == "surface", cfl=cfl
        )
        t, u, steps, seconds = run(case, t_end, 50)
        s = oscillation_stats(t, u[:, 1])
        sx = oscillation_stats(t, u[:, 0])
        row = dict(
            n=n,
            dx=case.info["dx"],
            particles=case.n_particles,
            steps=steps,
            seconds=seconds,
            uy_mean=s["mean"],
            uy_amplitude=s["amplitude"],
            frequency=s["frequency"],
            ux_mean=sx["mean"],
            ux_amplitude=sx["amplitude"],
            mean_error=s["mean"] / CSM3["mean"] - 1,
            amplitude_error=s["amplitude"] / CSM3["amplitude"] - 1,
            frequency_error=s["frequency"] / CSM3["frequency"] - 1,
        )
        if ref is not None:
            uy_ref = np.interp(t, ref[:, 0], ref[:, 2])
            row["uy_rms_difference"] = float(np.sqrt(np.mean((u[:, 1] - uy_ref) ** 2)))
        print("csm3", row, flush=True)
        rows.append(row)
        curves.append((n, t, u))
    fig, axes = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    if ref is not None:
        sel = ref[:, 0] <= t_end
        axes[0].plot(ref[sel, 0], 1e3 * ref[sel, 2], "k--", label="Turek & Hron (FEM)")
        axes[1].plot(ref[sel, 0], 1e3 * ref[sel, 1], "k--", label="Turek & Hron (FEM)")
    for n, t, u in curves:
        axes[0].plot(t, 1e3 * u[:, 1], label=f"SPH, {n} particles across")
        axes[1].plot(t, 1e3 * u[:, 0], label=f"SPH, {n} particles across")
    axes[0].set(ylabel="tip u_y (mm)", title="Turek-Hron CSM3")
    axes[1].set(xlabel="t (s)", ylabel="tip u_x (mm)")
    axes[0].legend()
    fig.tight_layout()
    fig.savefig(FIGURES / "solid_csm3.png", dpi=120)
    return rows


def table(rows, columns):
    head = "| " + " | ".join(columns) + " |\n|" + "---|" * len(columns)
    lines = []
    for r in rows:
        cells = []
        for c in columns:
            v = r[c]
            cells.append(
                f"{100 * v:+.2f} %"
                if c.endswith("error")
                else (f"{v:.4g}" if isinstance(v, float) else str(v))
            )
        lines.append("| " + " | ".join(cells) + " |")
    return head + "\n" + "\n".join(lines)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--plate-n", type=int, nargs="*", default=[6, 8, 12])
    p.add_argument("--csm-n", type=int, nargs="*", default=[9, 13, 17])
    p.add_argument("--t-plate", type=float, default=0.42)
    p.add_argument("--t-csm", type=float, default=2.1)
    p.add_argument("--h-factor", type=float, default=1.2, help="plate's h / dx")
    p.add_argument("--csm-placement", choices=["surface", "cell"], default="surface")
    p.add_argument("--cfl", type=float, default=0.5)
    p.add_argument("--reference", type=Path, default=REFERENCE)
    args = p.parse_args(argv)
    FIGURES.mkdir(parents=True, exist_ok=True)
    out = FIGURES / "validation_solid.json"
    results = json.loads(out.read_text()) if out.exists() else {}
    if args.plate_n:
        results["plate"] = plate(args.plate_n, args.t_plate, args.h_factor, args.cfl)
        print(
            table(
                results["plate"],
                [
                    "n",
                    "particles",
                    "steps",
                    "seconds",
                    "period",
                    "period_error",
                    "amplitude",
                    "amplitude_error",
                ],
            )
        )
    if args.csm_n:
        results["csm3"] = csm3(args.csm_n, args.t_csm, args.csm_placement, args.cfl, args.reference)
        print(
            table(
                results["csm3"],
                [
                    "n",
                    "particles",
                    "steps",
                    "seconds",
                    "uy_mean",
                    "mean_error",
                    "uy_amplitude",
                    "amplitude_error",
                    "frequency",
                    "frequency_error",
                ],
            )
        )
    out.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
