"""Rigid bodies against a reference, one resolution per invocation: a body floating on
water against Archimedes, and a disk settling in a channel against Glowinski et al. (2001)
and Wang, Fan & Luo (2008).

    python docs/scripts/validate_rigid.py --n 6              # run, append to the jsonl
    python docs/scripts/validate_rigid.py --n 10 --density-ratio 0.3
    python docs/scripts/validate_rigid.py --table            # the table from the jsonl
    python docs/scripts/validate_rigid.py --case settling --n 7
    python docs/scripts/validate_rigid.py --case settling --table
    python docs/scripts/validate_rigid.py --case settling --figure

`sphjax.cases.floating_body`: the body starts level with 40 % of its height under water
and heaves about its floating position.  The height of its bottom against time, sampled
every 0.01 s, is fitted with a damped oscillation
``b(t) = b_eq + A exp(-t / tau) cos(omega t + phi)``; the error is ``b_eq`` against
Archimedes' floating position (``case.info["equilibrium_bottom"]``) over the draught.
Each run appends one line to docs/data/floating_body.jsonl (resolution, particles, steps,
wall time, load average, the fit and the error, the sampled heights); a set-up already
there is skipped unless ``--force``, so an interrupted sweep resumes.

`sphjax.cases.settling_disk` (``--case settling``): the disk's velocity, sampled every
0.01 s to 0.6 s (its centre then still about 3 diameters above the floor); its largest
speed, of the running mean over 0.05 s (the acoustic ripple smoothed), gives its largest
Reynolds number on the disk's density, ``Re = rho_s speed d / mu``, against the
reference's, about 17 (``sphjax.cases.rigid.SETTLING_DISK_REYNOLDS``), and the speed
against that of the resolved immersed-boundary run IBLBM_SPEED.  One line per run in
docs/data/settling_disk.jsonl (wall and CPU time, float32 or float64, the sampled
velocity); ``--figure`` draws docs/figures/settling_disk.png from it.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import tempfile
import time

import jax
import jax.numpy as jnp
import numpy as np
from scipy.optimize import curve_fit

import sphjax
from sphjax.cases import body_bottom, body_velocity, floating_body, settling_disk

DOCS = pathlib.Path(__file__).resolve().parents[1]
RESULTS = DOCS / "data" / "floating_body.jsonl"
SETTLING = DOCS / "data" / "settling_disk.jsonl"
#: the mean speed is over t >= SETTLED (s); the running mean that smooths the acoustic
#: ripple (about 0.03 s: a sound wave across the channel) is over SMOOTH samples (0.05 s)
SETTLED = 0.3
SMOOTH = 5
#: the largest settling speed (cm/s) of the same set-up in the immersed-boundary lattice
#: Boltzmann run of github.com/mulgae-life/iblbm-mechanism-resolved (H. Jo, Physics of
#: Fluids 2026), data/single_particle_sedimentation/method_matrix/rho125/
#: df_bgk_verlet_explicit_history/status.json: "Re_standard_peak": 13.93 (``|V| d / nu``,
#: 160 lattice spacings across the disk), i.e. 13.93 * 0.1 / 0.25 cm/s
IBLBM_SPEED = 13.93 * 0.1 / 0.25


def settling_speed(t, vy):
    """``(largest, mean, spread)``: the largest downward speed of the running mean over
    SMOOTH samples (the reference's is its largest), the mean and standard deviation of
    the speed over ``t >= SETTLED``."""
    running = np.convolve(-np.asarray(vy), np.ones(SMOOTH) / SMOOTH, mode="valid")
    late = -np.asarray(vy)[np.asarray(t) >= SETTLED]
    return float(running.max()), float(late.mean()), float(late.std())


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


def _piece_files(n, t_end, piece, c0):
    name = f"settling_disk_n{n}_t{t_end}_p{piece}_c{c0:g}.npz"
    return pathlib.Path(tempfile.gettempdir()) / name, SETTLING.with_name(
        "settling_disk_pieces.jsonl"
    )


def run_settling_piece(case, n, t_end, piece):
    """One piece of ``piece`` seconds of a long run, from the last piece's state (saved in
    the temporary directory); the pieces' sampled velocities accumulate in
    docs/data/settling_disk_pieces.jsonl.  ``None`` until the run has reached ``t_end``,
    then ``(t, v, centre, wall, cpu)`` of the whole run."""
    c0 = float(case.params.sound_speed)
    state_file, pieces = _piece_files(n, t_end, piece, c0)
    key = (n, t_end, piece, c0)
    done = []
    if pieces.exists():
        done = [json.loads(line) for line in pieces.read_text().splitlines()]
        done = [r for r in done if (r["n"], r["t_end"], r["piece"], r.get("c0", 68.0)) == key]
    t0 = done[-1]["t"][-1] if done else 0.0
    state = None
    if done:
        leaves, treedef = jax.tree_util.tree_flatten(case.state)
        saved = np.load(state_file)
        state = jax.tree_util.tree_unflatten(
            treedef, [jnp.asarray(saved[f"leaf{i}"]) for i in range(len(leaves))]
        )
    every = max(1, int(round(0.01 / case.dt)))
    steps = int(round(min(piece, t_end - t0) / case.dt)) // every * every
    start, cpu = time.perf_counter(), time.process_time()
    trajectory = sphjax.simulate(case, n_steps=steps, save_every=every, state=state)
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    last = jax.tree_util.tree_map(lambda a: np.asarray(a[-1]), trajectory.states)
    leaves = jax.tree_util.tree_leaves(last)
    np.savez(state_file, **{f"leaf{i}": leaf for i, leaf in enumerate(leaves)})
    t = t0 + np.asarray(trajectory.times)
    v = np.asarray(body_velocity(trajectory.states, case))
    idx = np.asarray(case.info["body_indices"])
    centre = np.asarray(trajectory.states.position)[:, idx].mean(axis=1)
    row = dict(
        n=n, t_end=t_end, piece=piece, c0=c0, wall_s=wall, cpu_s=cpu, t=t.round(6).tolist(),
        vx=v[:, 0].tolist(), vy=v[:, 1].tolist(), y=centre[:, 1].tolist(),
    )  # fmt: skip
    with pieces.open("a") as out:
        out.write(json.dumps(row) + "\n")
    done.append(row)
    print(f"piece to t = {t[-1]:.3f} s: {wall:.0f} s wall")
    if t[-1] < t_end - 1.5 * every * case.dt:
        return None
    # the pieces joined: each piece's first frame is the last one's last
    t = np.concatenate([done[0]["t"][:1]] + [r["t"][1:] for r in done])
    vx = np.concatenate([done[0]["vx"][:1]] + [r["vx"][1:] for r in done])
    vy = np.concatenate([done[0]["vy"][:1]] + [r["vy"][1:] for r in done])
    y = np.concatenate([done[0]["y"][:1]] + [r["y"][1:] for r in done])
    wall = sum(r["wall_s"] for r in done)
    cpu = sum(r["cpu_s"] for r in done)
    return t, np.stack([vx, vy], -1), np.stack([np.zeros_like(y), y], -1), wall, cpu


def run_settling(n, t_end, piece=None, sound_speed=None):
    case = settling_disk(n=n, t_end=t_end, sound_speed=sound_speed)
    if piece is not None:
        result = run_settling_piece(case, n, t_end, piece)
        if result is None:
            return None
        t, v, centre, wall, cpu = result
    else:
        every = max(1, int(round(0.01 / case.dt)))
        start, cpu = time.perf_counter(), time.process_time()
        trajectory = sphjax.simulate(case, save_every=every)
        wall, cpu = time.perf_counter() - start, time.process_time() - cpu
        t = np.asarray(trajectory.times)
        v = np.asarray(body_velocity(trajectory.states, case))
        idx = np.asarray(case.info["body_indices"])
        centre = np.asarray(trajectory.states.position)[:, idx].mean(axis=1)
    info = case.info
    speed, mean_speed, spread = settling_speed(t, v[:, 1])
    # on the disk's density, rho_s |V| d / mu (as the reference's)
    reynolds = info["density_ratio"] * speed * info["diameter"] / info["kinematic_viscosity"]
    return dict(
        n=n,
        t_end=t_end,
        density_ratio=info["density_ratio"],
        dx=info["dx"],
        dtype=str(jnp.asarray(case.state.position).dtype),
        particles=int(case.state.position.shape[0]),
        body_particles=len(info["body_indices"]),
        body_area_ratio=info["body_area"] / (np.pi * info["diameter"] ** 2 / 4),
        steps=int(round(t_end / case.dt)),
        sound_speed=float(case.params.sound_speed),
        sound_speed_set=sound_speed,
        wall_s=round(wall, 1),
        cpu_s=round(cpu, 1),
        load=os.getloadavg()[0],
        pieces=piece,
        speed=speed,
        mean_speed=mean_speed,
        speed_std=spread,
        reynolds=reynolds,
        reynolds_error=reynolds / info["reference_reynolds"] - 1.0,
        iblbm_error=speed / IBLBM_SPEED - 1.0,
        largest_sideways=float(np.abs(v[:, 0]).max()),
        final_centre_height=float(centre[-1, 1]),
        t=t.round(5).tolist(),
        vy=v[:, 1].round(5).tolist(),
    )


def settling_table():
    rows = [json.loads(line) for line in SETTLING.read_text().splitlines()]
    print(
        "| n | c0 cm/s | dx cm | particles | disk area | steps | wall s | CPU s | "
        "largest speed cm/s | largest Re | against 17 | against IB-LBM | "
        "mean speed, t >= 0.3 s |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in sorted(rows, key=lambda r: (r["n"], r["sound_speed"])):
        print(
            f"| {r['n']} | {r['sound_speed']:.0f} | {r['dx']:.4f} | {r['particles']} | "
            f"{100 * (r['body_area_ratio'] - 1):+.1f} % | {r['steps']} | {r['wall_s']:.0f} | "
            f"{r['cpu_s']:.0f} | {r['speed']:.2f} | {r['reynolds']:.2f} | "
            f"{100 * r['reynolds_error']:+.1f} % | {100 * (r['speed'] / IBLBM_SPEED - 1):+.1f} % | "
            f"{r['mean_speed']:.2f} ± {r['speed_std']:.2f} |"
        )


def settling_figure():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sphjax.cases.rigid import SETTLING_DISK_REYNOLDS

    rows = [json.loads(line) for line in SETTLING.read_text().splitlines()]
    fig, ax = plt.subplots(figsize=(6, 3.6))
    for r in sorted(rows, key=lambda r: r["n"]):
        label = f"n = {r['n']}, c0 = {r['sound_speed']:.0f} cm/s"
        colour = {7: "C0", 10: "C1", 14: "C2"}.get(r["n"], "C3")
        style = ":" if r["sound_speed"] < 100 else "-" if r["sound_speed"] < 200 else "-."
        ax.plot(r["t"], -np.asarray(r["vy"]), style, color=colour, lw=1.2, label=label)
    speed = SETTLING_DISK_REYNOLDS * 0.1 / (1.25 * 0.25)
    ax.axhline(speed, color="k", ls="--", label="Wang et al. 2008, Re ≈ 17")
    ax.axhline(IBLBM_SPEED, color="0.4", ls=":", label="IB-LBM run (Jo 2026)")
    ax.axvspan(SETTLED, max(r["t_end"] for r in rows), color="0.9", zorder=0)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("settling speed (cm/s)")
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    out = DOCS / "figures" / "settling_disk.png"
    fig.savefig(out, dpi=120)
    print(f"wrote {out}")


def settling_main(args):
    if args.table:
        return settling_table()
    if args.figure:
        return settling_figure()
    if SETTLING.exists() and not args.force:
        for line in SETTLING.read_text().splitlines():
            r = json.loads(line)
            key = (r["n"], r["t_end"], r.get("sound_speed_set"))
            if key == (args.n, args.t_end, args.sound_speed):
                print(f"already there: n={args.n}, t_end={args.t_end}")
                return
    row = run_settling(args.n, args.t_end, args.piece, args.sound_speed)
    if row is None:
        print("run again for the next piece")
        return
    SETTLING.parent.mkdir(parents=True, exist_ok=True)
    with SETTLING.open("a") as out:
        out.write(json.dumps(row) + "\n")
    print(
        f"n={row['n']}: speed {row['speed']:.3f} cm/s, Re {row['reynolds']:.2f} "
        f"({100 * row['reynolds_error']:+.1f} %), {row['particles']} particles, "
        f"{row['wall_s']} s wall, {row['cpu_s']} s CPU"
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", choices=("floating", "settling"), default="floating")
    parser.add_argument("--n", type=int, default=6, help="particles across the body's height")
    parser.add_argument("--density-ratio", type=float, default=0.5)
    parser.add_argument("--t-end", type=float, default=None, help="2.5 s; settling: 0.6 s")
    parser.add_argument("--force", action="store_true", help="run again if already there")
    parser.add_argument("--table", action="store_true", help="print the table and stop")
    parser.add_argument("--figure", action="store_true", help="settling: draw the figure")
    parser.add_argument(
        "--piece", type=float, default=None, help="settling: run this many seconds a call"
    )
    parser.add_argument("--sound-speed", type=float, default=None, help="settling: c0")
    args = parser.parse_args()
    if args.case == "settling":
        args.t_end = 0.6 if args.t_end is None else args.t_end
        return settling_main(args)
    args.t_end = 2.5 if args.t_end is None else args.t_end
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
