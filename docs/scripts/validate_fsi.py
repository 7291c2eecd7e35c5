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

    python docs/scripts/validate_fsi.py --case obstacle --n 2 --t-end 1.0
    python docs/scripts/validate_fsi.py --case gate --n 2 --t-end 0.4

``--case obstacle``: the dam break against an elastic plate (``dam_break_elastic_obstacle``):
the plate top's displacement against the published curves
(``docs/data/elastic_plate_dam_break_tip_displacement.csv``), the energy budget
(:func:`sphjax.observables.energy_budget`) and the momentum budget
(:func:`sphjax.observables.momentum_budget`); figure ``docs/figures/fsi_obstacle.png``,
numbers ``docs/figures/fsi_obstacle.json``.  ``--case gate``: the elastic gate's free end
against Antoci et al.'s experiment (``docs/data/antoci_2007_gate_tip_displacement.csv``);
``docs/figures/fsi_gate.png`` and ``.json``; with ``--plane-stress`` also the gate of the
same E and nu in plane stress; ``--outflow-length`` the floor's length past the gate.
``--case gate --compare RUN.json ...`` runs nothing: it sets stored runs beside the
experiment and the published numerical results
(``docs/data/elastic_gate_published_tip_displacement.csv``; :func:`compare_gate`).
``--gradient-correction second_order`` builds every case with the second-order solid
gradient (its step and ``"auto"`` substeps computed for it) and is recorded in the output.

    python docs/scripts/validate_fsi.py --case gate --dry-only --n 2 3 4 6 --out gate_dry.jsonl

``--case gate --dry-only`` (``obstacle``): the gate (the obstacle's plate) alone under a
uniform sideways load of 100 Pa against Euler-Bernoulli's cantilever
(:func:`cantilever_alone`; default ``--t-end`` 0.3 s for the gate, 1 s for the plate).
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import pathlib
import time

import jax
import numpy as np

import sphjax
from sphjax import observables
from sphjax.cases.fsi import (
    dam_break_elastic_obstacle,
    elastic_gate_dam_break,
    hydrostatic_fsi_plate,
    midspan_deflection,
)
from sphjax.core.state import Kind

ROOT = pathlib.Path(__file__).resolve().parents[2]
DATA = ROOT / "docs" / "data"
FIGURES = ROOT / "docs" / "figures"


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
        float(p.reference_density) * info["depth"] + info["solid_density"] * info["thickness"]
    )
    # the particles' weight per unit length is rho_particles (n dx) g_eff
    g_eff = load / (float(p.solid_density) * info["body_thickness"])
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


def relaxed(case, t_end):
    """Static deflection of ``case`` by dynamic relaxation
    (:func:`sphjax.cases.solid.relax_to_rest`, velocity damping ``2 omega`` of the dry
    first mode, critical for it), over the analytic value: the last two segments' values."""
    from sphjax.cases.solid import relax_to_rest

    omega = 2.0 * np.pi / case.info["dry_period"]
    segments = int(round(10 * t_end / case.info["dry_period"]))
    start = time.perf_counter()
    _, finals = relax_to_rest(case, t_end=t_end, damping_rate=2.0 * omega, segments=segments)
    w = np.asarray(midspan_deflection(finals, case)) / case.info["reference_deflection"]
    return dict(static=float(w[-1]), static_before=float(w[-2]),
                wall_s=round(time.perf_counter() - start, 1))  # fmt: skip


def read_series(path):
    """``{series: (time, value)}`` from a ``series,time,value`` csv with ``#`` comments."""
    rows = [r for r in csv.reader(open(path)) if r and not r[0].startswith("#")][1:]
    out = {}
    for name, t, v in rows:
        out.setdefault(name, ([], []))
        out[name][0].append(float(t))
        out[name][1].append(float(v))
    return {k: (np.array(t), np.array(v)) for k, (t, v) in out.items()}


def curve_error(t, u, t_ref, u_ref):
    """RMS of ``u - u_ref`` at the reference times (``u`` interpolated linearly), over the
    reference times inside the run, divided by ``max |u_ref|``."""
    inside = (t_ref >= t[0]) & (t_ref <= t[-1])
    diff = np.interp(t_ref[inside], t, u) - u_ref[inside]
    return float(np.sqrt(np.mean(diff**2)) / np.max(np.abs(u_ref)))


def peak(t, u):
    i = int(np.argmax(u))
    return float(u[i]), float(t[i])


def coupling_info(case):
    """The solid's gradient correction, its steps per step and the step of ``case``."""
    solid = case.model.system(sphjax.SolidSystem)
    return dict(
        gradient_correction=solid.gradient_correction,
        substeps=solid.substeps,
        float64=bool(jax.config.jax_enable_x64),
    )


def run_coupled(case, t_end, frames):
    n_steps = int(round(t_end / case.dt))
    save_every = max(1, n_steps // frames)
    start, cpu = time.perf_counter(), time.process_time()
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=save_every)
    jax.block_until_ready(traj.states.position)
    cost = dict(
        steps=n_steps,
        dt=case.dt,
        particles=case.n_particles,
        wall_s=round(time.perf_counter() - start, 1),
        cpu_s=round(time.process_time() - cpu, 1),
    )
    return traj, cost


def obstacle(n, t_end, frames, gradient_correction="first_order"):
    """The dam break against the elastic plate: tip curve, energy and momentum budgets;
    the plate's ``SolidSystem.gradient_correction`` is ``gradient_correction`` (the
    case's step computed for it)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    jax.config.update("jax_enable_x64", True)
    case = dam_break_elastic_obstacle(n=n, gradient_correction=gradient_correction)
    traj, cost = run_coupled(case, t_end, frames)
    t = np.asarray(traj.states.time)
    tip = np.asarray(observables.tip_displacement(traj, case))
    energy = observables.energy_budget(traj, case)
    budget = observables.momentum_budget(traj, case)
    finite = bool(np.all(np.isfinite(np.asarray(traj.states.position))))
    released = energy["fluid_potential"][0] - energy["fluid_potential"].min()
    refs = read_series(DATA / "elastic_plate_dam_break_tip_displacement.csv")
    peak_u, peak_t = peak(t, tip[:, 0])
    row = dict(case="dam_break_elastic_obstacle", n=n, dx=case.info["dx"], t_end=t_end, **cost)
    row.update(coupling_info(case))
    row.update(
        finite=finite,
        tip_peak_ux=peak_u,
        tip_peak_time=peak_t,
        tip_ux_end=float(tip[-1, 0]),
        references={
            k: dict(
                peak_ux=peak(*v)[0],
                peak_time=peak(*v)[1],
                curve_error=curve_error(t, tip[:, 0], *v),
            )
            for k, v in refs.items()
        },
        energy_initial=float(energy["total"][0]),
        potential_released_max=float(released),
        energy_change_max=float(np.max(energy["total"] - energy["total"][0])),
        energy_change_end=float(energy["total"][-1] - energy["total"][0]),
        strain_energy_max=float(energy["solid_strain"].max()),
        fluid_kinetic_max=float(energy["fluid_kinetic"].max()),
        momentum_x_change_max=float(
            np.max(np.abs(budget["momentum"][:, 0] - budget["momentum"][0, 0]))
        ),
        momentum_x_minus_impulse_max=float(
            np.max(
                np.abs(
                    budget["momentum"][:, 0] - budget["momentum"][0, 0] - budget["impulse"][:, 0]
                )
            )
        ),
        series=dict(
            time=t[:: max(1, len(t) // 100)].tolist(),
            tip_ux=tip[:: max(1, len(t) // 100), 0].tolist(),
        ),
    )
    fig, ax = plt.subplots(1, 3, figsize=(15, 4))
    for k, (tr, ur) in refs.items():
        ax[0].plot(tr, 1e3 * ur, "--", lw=1, label=k)
    order = "" if gradient_correction == "first_order" else f", {gradient_correction}"
    ax[0].plot(t, 1e3 * tip[:, 0], "k", lw=2, label=f"sphjax, n = {n}{order}")
    ax[0].set(xlabel="t (s)", ylabel="tip ux (mm)", title="plate top, horizontal")
    ax[0].legend(fontsize=7)
    E0 = energy["total"][0]
    for k in (
        "fluid_kinetic",
        "fluid_potential",
        "fluid_internal",
        "solid_kinetic",
        "solid_strain",
    ):
        ax[1].plot(t, energy[k] - energy[k][0], label=k)
    ax[1].plot(t, energy["total"] - E0, "k", lw=2, label="total")
    ax[1].set(xlabel="t (s)", ylabel="E(t) - E(0) (J/m)", title="energy budget")
    ax[1].legend(fontsize=7)
    ax[2].plot(
        t, budget["momentum"][:, 0] - budget["momentum"][0, 0], "k", lw=2, label="P_x(t) - P_x(0)"
    )
    ax[2].plot(t, budget["impulse"][:, 0], "r--", label="impulse of walls and clamp")
    ax[2].set(xlabel="t (s)", ylabel="kg m/s per m", title="horizontal momentum")
    ax[2].legend(fontsize=7)
    fig.tight_layout()
    name = "fsi_obstacle" if n == 2 else f"fsi_obstacle_n{n}"
    if gradient_correction != "first_order":
        name += f"_{gradient_correction}"
    fig.savefig(FIGURES / f"{name}.png", dpi=110)
    return row


def gate_run(case, t_end, frames, exp):
    """Run the gate ``case``; its tip series and peaks against the experiment ``exp``."""
    traj, cost = run_coupled(case, t_end, frames)
    t = np.asarray(traj.states.time)
    tip = np.asarray(observables.tip_displacement(traj, case))
    row = dict(case="elastic_gate_dam_break", n=case.info["n"], dx=case.info["dx"], **cost)
    row["t_end"] = t_end
    row.update(coupling_info(case))
    row["young_modulus"] = float(case.params.young_modulus)
    row["poisson_ratio"] = float(case.params.poisson_ratio)
    row["finite"] = bool(np.all(np.isfinite(tip)))
    fluid = np.asarray(traj.states.kind[0]) == Kind.FLUID
    row["front_x_end"] = float(np.asarray(traj.states.position)[-1, fluid, 0].max())
    for j, key in enumerate(("ux", "uy")):
        te, ue = exp[key]
        pk, pt = peak(t, tip[:, j])
        pke, pte = peak(te, ue)
        row[key] = dict(
            peak=pk,
            peak_time=pt,
            experiment_peak=pke,
            experiment_peak_time=pte,
            peak_error=(pk - pke) / pke,
            curve_error=curve_error(t, tip[:, j], te, ue),
            at=[[tt, float(np.interp(tt, t, tip[:, j]))] for tt in (0.04, 0.08, 0.16, 0.25, 0.35)],
        )
    row["series"] = dict(
        time=t[:: max(1, len(t) // 100)].tolist(),
        tip=tip[:: max(1, len(t) // 100)].tolist(),
    )
    return row, t, tip


def cantilever_alone(case, length, thickness, pressure=100.0, t_end=0.3, cfl=0.5):
    """The solid of ``case`` (the gate or the obstacle's plate, clamped at one end) alone,
    no fluid, no walls, under a uniform sideways load ``pressure`` (its weight turned
    horizontal, ``g = pressure / (rho_s t)``), undamped from rest for ``t_end``: the free
    end's (``info["tip_indices"]``) mean and ``(max + min) / 2`` over the run against
    Euler-Bernoulli's plane-strain cantilever ``q L^4 / (8 D)``; ``cfl``: the solid
    Courant number of its step."""
    kind = np.asarray(case.state.kind)
    keep = kind >= Kind.SOLID

    def take(a):
        return a[keep] if getattr(a, "ndim", 0) >= 1 and a.shape[0] == len(kind) else a

    state = jax.tree_util.tree_map(take, case.state)
    p, t = case.params, thickness
    params = sphjax.make_params(
        2,
        gravity=(pressure / (float(p.solid_density) * t), 0.0),
        young_modulus=p.young_modulus,
        poisson_ratio=p.poisson_ratio,
        solid_density=p.solid_density,
    )
    model = case.model.replace(systems=(case.model.system(sphjax.SolidSystem),))
    shift = int((~keep).sum())
    tips = tuple(int(i) - shift for i in case.info["tip_indices"])
    info = dict(case.info, tip_indices=tips, tip_index=tips[0])
    dt = sphjax.stable_time_step(state, model, params, solid_cfl=cfl)
    dry = sphjax.Case("cantilever", state, model, params, dt, t_end, info)
    E, nu, L = float(p.young_modulus), float(p.poisson_ratio), length
    reference = pressure * L**4 / (8.0 * E * t**3 / (12.0 * (1.0 - nu**2)))
    steps = int(round(t_end / dt))
    traj = sphjax.simulate(dry, n_steps=steps, save_every=max(1, steps // 600))
    ux = np.asarray(observables.tip_displacement(traj, dry))[:, 0]
    solid = case.model.system(sphjax.SolidSystem)
    return dict(
        case=f"{case.name}, solid alone",
        n=case.info["n"],
        gradient_correction=solid.gradient_correction,
        pressure=pressure,
        t_end=t_end,
        particles=dry.n_particles,
        steps=steps,
        reference=reference,
        mean=float(ux.mean() / reference),
        mid_range=float(0.5 * (ux.max() + ux.min()) / reference),
    )


STYLES = ("b", "r--")


def gate(
    n, t_end, frames, substeps, plane_stress=False, gradient_correction="first_order", **extra
):
    """The elastic gate's free end against Antoci et al.'s experiment; with
    ``plane_stress`` also the gate of the same E and nu in plane stress
    (:func:`sphjax.physics.solid.material.plane_stress_equivalent`); the gate's
    ``SolidSystem.gradient_correction`` is ``gradient_correction``; ``extra``: further
    arguments of :func:`elastic_gate_dam_break` (``outflow_length``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sphjax.physics.solid.material import plane_stress_equivalent

    exp = read_series(DATA / "antoci_2007_gate_tip_displacement.csv")
    case = elastic_gate_dam_break(
        n=n, substeps=substeps, gradient_correction=gradient_correction, **extra
    )
    runs = {"plane strain": gate_run(case, t_end, frames, exp)}
    if plane_stress:
        E, nu = (float(case.params.young_modulus), float(case.params.poisson_ratio))
        E, nu = plane_stress_equivalent(E, nu)
        sheet = elastic_gate_dam_break(
            n=n,
            substeps=substeps,
            young_modulus=E,
            poisson_ratio=nu,
            gradient_correction=gradient_correction,
            **extra,
        )
        runs["plane stress"] = gate_run(sheet, t_end, frames, exp)
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for j, key in enumerate(("ux", "uy")):
        te, ue = exp[key]
        ax[j].plot(te, 1e3 * ue, "ko", label="Antoci et al. 2007 (experiment)")
        for (label, (_, t, tip)), style in zip(runs.items(), STYLES[: len(runs)], strict=True):
            order = "" if gradient_correction == "first_order" else f", {gradient_correction}"
            ax[j].plot(t, 1e3 * tip[:, j], style, label=f"sphjax, n = {n}, {label}{order}")
        ax[j].set(xlabel="t (s)", ylabel=f"{key} (mm)", title=f"gate free end, {key}")
        ax[j].legend(fontsize=8)
    fig.tight_layout()
    suffix = "" if gradient_correction == "first_order" else f"_n{n}_{gradient_correction}"
    if suffix and substeps != "auto":
        suffix += f"_k{substeps}"
    fig.savefig(FIGURES / f"fsi_gate{suffix}.png", dpi=110)
    row = runs["plane strain"][0]
    if plane_stress:
        row["plane_stress"] = runs["plane stress"][0]
    return row


PUBLISHED_GATE = {
    "khayyer2018_isph_sph": "Khayyer et al. 2018 (ISPH-SPH)",
    "ng2020_sph_vcpm": "Ng et al. 2020 (SPH-VCPM)",
    "yang2012_sph_fem": "Yang et al. 2012 (SPH-FEM)",
}


def gate_runs(paths):
    """``{label: (t, tip)}`` of the gate runs stored by ``--case gate --out`` (times
    ``[T]``, free-end displacements ``[T, 2]``; a run with ``--plane-stress`` holds both
    gates), labelled by resolution, plane strain or stress, and gradient."""
    runs = {}
    for path in paths:
        row = json.load(open(path))
        parts = [("plane strain", row)]
        if "plane_stress" in row:
            parts.append(("plane stress", row["plane_stress"]))
        for kind, part in parts:
            order = part.get("gradient_correction") or "first_order"
            label = f"n = {part['n']}, {kind}, {order.replace('_', ' ')}"
            series = part["series"]
            runs[label] = (np.asarray(series["time"]), np.asarray(series["tip"]))
    return runs


def compare_gate(paths, t_max=0.36):
    """The stored gate runs ``paths`` against the experiment and the published numerical
    results (``docs/data/elastic_gate_published_tip_displacement.csv``): each curve's
    peak and its time, and the RMS difference of the run from each curve over
    ``0 <= t <= t_max`` (at the curve's times, over the curve's peak); prints a table per
    displacement component and writes ``docs/figures/fsi_gate_published.png``.  Runs no
    simulation."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    exp = read_series(DATA / "antoci_2007_gate_tip_displacement.csv")
    published = read_series(DATA / "elastic_gate_published_tip_displacement.csv")
    runs = gate_runs(paths)
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    out = {}
    for j, key in enumerate(("ux", "uy")):
        refs = {"Antoci et al. 2007 (experiment)": exp[key]}
        refs.update({label: published[f"{name}_{key}"] for name, label in PUBLISHED_GATE.items()})
        names = list(refs)
        print(f"\n{key}: peak (mm) at t (s); RMS difference / reference peak, 0-{t_max} s")
        print("| curve | peak | at t | " + " | ".join(names) + " |")
        for label, (t, u) in list(refs.items()) + [
            (k, (t, tip[:, j])) for k, (t, tip) in runs.items()
        ]:
            pk, pt = peak(t, u)
            cells = []
            for ref in names:
                tr, ur = refs[ref]
                keep = tr <= t_max
                cells.append(f"{curve_error(t, u, tr[keep], ur[keep]):.1%}")
            print(f"| {label} | {1e3 * pk:.1f} | {pt:.3f} | " + " | ".join(cells) + " |")
            out[f"{key}: {label}"] = dict(
                peak=pk, peak_time=pt, rms=dict(zip(names, cells, strict=True))
            )
        te, ue = exp[key]
        ax[j].plot(te, 1e3 * ue, "ko", label="Antoci et al. 2007 (experiment)")
        for (name, label), style in zip(PUBLISHED_GATE.items(), ("g:", "m:", "c:"), strict=True):
            tr, ur = published[f"{name}_{key}"]
            ax[j].plot(tr, 1e3 * ur, style, lw=1.5, label=label)
        styles = itertools.cycle(("b", "r--", "k-.", "y"))
        for (label, (t, tip)), style in zip(runs.items(), styles, strict=False):
            ax[j].plot(t, 1e3 * tip[:, j], style, label=f"sphjax {label}")
        ax[j].set(xlabel="t (s)", ylabel=f"{key} (mm)", title=f"gate free end, {key}")
        ax[j].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(FIGURES / "fsi_gate_published.png", dpi=110)
    return out


# the flags each mode of main() reads (besides --case and --out); a flag given to a mode
# that does not read it would do nothing, and is refused
COMMON = {"gradient_correction", "t_end", "n"}
READS = {
    "compare": {"compare"},
    "dry cantilever": COMMON | {"dry_only"},
    "obstacle": COMMON | {"frames"},
    "gate": COMMON | {"frames", "substeps", "plane_stress", "outflow_length"},
    "plate": {
        "gradient_correction", "n", "depth", "periods", "dry_only", "relax", "no_dry",
        "substeps", "placement", "h_factor", "length", "thickness", "young_modulus",
        "float64", "face_weight", "free_end_columns",
    },
}  # fmt: skip


def refuse_unread_flags(parser, args):
    """Stop, in one line, on a flag that the chosen mode would not read (its value left at
    the default is fine), or on a combination in which a flag does nothing."""
    if args.compare:
        mode = "compare"
    elif args.case in ("gate", "obstacle") and args.dry_only:
        mode = "dry cantilever"
    else:
        mode = args.case
    given = {k for k, v in vars(args).items() if v != parser.get_default(k)} - {"case", "out"}
    refused = [(k, "does not read it: leave it out") for k in sorted(given - READS[mode])]
    if mode == "plate" and args.placement != "surface":
        surface_only = "is read with --placement surface only"
        refused += [(k, surface_only) for k in ("face_weight", "free_end_columns") if k in given]
    if mode == "plate" and args.no_dry:
        refused += [
            (k, "acts on the dry run, which --no-dry leaves out") for k in ("relax",) if k in given
        ]
        if args.dry_only:
            refused.append(("dry_only", "and --no-dry together leave nothing to run"))
    if mode in ("obstacle", "gate") and args.n is not None and len(args.n) > 1:
        refused.append(("n", "runs one resolution: give a single --n"))
    if mode == "plate" and args.dry_only and "substeps" in given:
        refused.append(("substeps", "runs no coupled run with --dry-only: leave it out"))
    if mode == "gate" and len(args.substeps) > 1:
        refused.append(("substeps", "runs one coupled run: give a single --substeps"))
    if refused:
        name, reason = refused[0]
        where = f"--case {args.case}" + {
            "compare": " --compare",
            "dry cantilever": " --dry-only",
        }.get(mode, "")
        parser.error(f"--{name.replace('_', '-')}: {where} {reason}")


def build_parser():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--case", choices=("plate", "obstacle", "gate"), default="plate")
    p.add_argument("--t-end", type=float, default=None)
    p.add_argument("--frames", type=int, default=400)
    p.add_argument(
        "--n",
        type=int,
        nargs="+",
        default=None,
        help="particles through the solid (plate and dry runs: default 2 3 4; coupled "
        "gate and obstacle: one, default 2)",
    )
    p.add_argument("--depth", type=float, default=0.5)
    p.add_argument("--periods", type=float, default=8.0)
    p.add_argument("--dry-only", action="store_true")
    p.add_argument(
        "--relax", action="store_true", help="the dry plate's static value by relaxation"
    )
    p.add_argument("--no-dry", action="store_true")
    p.add_argument("--substeps", nargs="+", default=["1"])
    p.add_argument("--placement", choices=("cell", "surface"), default="cell")
    p.add_argument("--h-factor", type=float, default=None)
    p.add_argument("--length", type=float, default=1.0)
    p.add_argument("--thickness", type=float, default=0.05)
    p.add_argument("--young-modulus", type=float, default=67.5e9)
    p.add_argument("--float64", action="store_true")
    p.add_argument(
        "--gradient-correction",
        choices=("first_order", "second_order"),
        default="first_order",
        help="the solid's reference kernel gradient (SolidSystem.gradient_correction), "
        "every case; its time step and 'auto' substeps computed for it",
    )
    p.add_argument(
        "--face-weight",
        type=float,
        default=1.0,
        help="surface placement: volume of a face-row particle over dx^2",
    )
    p.add_argument(
        "--free-end-columns",
        action="store_true",
        help="surface placement: leave the columns on x = 0 and x = L free",
    )
    p.add_argument(
        "--plane-stress",
        action="store_true",
        help="gate: also run the gate of the same E, nu in plane stress",
    )
    p.add_argument(
        "--outflow-length",
        type=float,
        default=None,
        help="gate: the floor's length past the gate (the case's default 0.4 m)",
    )
    p.add_argument(
        "--compare",
        nargs="+",
        default=None,
        metavar="RUN_JSON",
        help="gate: compare stored runs (--out files) with the experiment and the published "
        "numerical results; runs no simulation",
    )
    p.add_argument("--out", default=None)
    return p


def main(argv=None):
    p = build_parser()
    args = p.parse_args(argv)
    if args.compare and args.case != "gate":
        p.error("--compare: give it with --case gate")
    refuse_unread_flags(p, args)
    if args.n is None:
        args.n = [2] if args.case in ("gate", "obstacle") and not args.dry_only else [2, 3, 4]
    if args.compare:
        missing = [path for path in args.compare if not pathlib.Path(path).is_file()]
        if missing:
            p.error(f"--compare: no such file {missing[0]} (give runs written by --out)")
        compare_gate(args.compare)
        return
    if args.case in ("gate", "obstacle") and args.dry_only:
        for n in args.n:
            kw = dict(n=n, substeps=1, gradient_correction=args.gradient_correction)
            if args.case == "gate":
                case = elastic_gate_dam_break(**kw)
                size = (case.info["gate_length"], case.info["gate_thickness"])
            else:
                case = dam_break_elastic_obstacle(**kw)
                size = (case.info["plate_length"], case.info["plate_thickness"])
            t_end = args.t_end or (0.3 if args.case == "gate" else 1.0)
            # the plate's nu = 0: its P-wave modulus E is twice the bulk modulus the
            # solid's stable step takes (E / 2 in 2D), so half that Courant number
            cfl = 0.5 if args.case == "gate" else 0.25
            row = cantilever_alone(case, *size, t_end=t_end, cfl=cfl)
            print(json.dumps(row), flush=True)
            if args.out:
                with open(args.out, "a") as f:
                    f.write(json.dumps(row) + "\n")
        return
    if args.case in ("obstacle", "gate"):
        n = args.n[0]
        if args.case == "obstacle":
            row = obstacle(n, args.t_end or 1.0, args.frames, args.gradient_correction)
        else:
            k = args.substeps[0]
            k = k if k == "auto" else int(k)
            extra = {} if args.outflow_length is None else dict(outflow_length=args.outflow_length)
            row = gate(
                n,
                args.t_end or 0.4,
                args.frames,
                k,
                args.plane_stress,
                args.gradient_correction,
                **extra,
            )
            row.update(extra)
        out = pathlib.Path(args.out or FIGURES / f"fsi_{args.case}.json")
        out.write_text(json.dumps(row, indent=1) + "\n")
        print(json.dumps({k: v for k, v in row.items() if k != "series"}, indent=1))
        return
    if args.out is None:
        p.error("--out is required with --case plate")
    if args.float64:
        jax.config.update("jax_enable_x64", True)
    plate = dict(
        depth=args.depth,
        placement=args.placement,
        h_factor=args.h_factor,
        length=args.length,
        thickness=args.thickness,
        young_modulus=args.young_modulus,
    )
    if args.placement == "surface":
        plate.update(face_weight=args.face_weight, clamp_end_columns=not args.free_end_columns)
    for n in args.n:
        plate["gradient_correction"] = args.gradient_correction
        case = hydrostatic_fsi_plate(n=n, **plate)
        t_end = args.periods * case.info["dry_period"]
        row = dict(n=n, depth=case.info["depth"], dx=case.info["dx"], t_end=t_end)
        row.update({k: v for k, v in plate.items() if k not in ("depth", "gradient_correction")})
        row.update(float64=args.float64, end_columns_clamped=not args.free_end_columns)
        row["face_weight"] = args.face_weight
        row["gradient_correction"] = args.gradient_correction
        row["h"] = float(case.model.smoothing_length)
        row["reference_deflection"] = case.info["reference_deflection"]
        if not args.no_dry:
            if args.relax:  # the static value by relaxation only
                row["dry"] = dict(relaxed=relaxed(dry_case(case), t_end))
            else:
                row["dry"] = measure(dry_case(case), t_end)
        for substeps in [] if args.dry_only else args.substeps:
            k = substeps if substeps == "auto" else int(substeps)
            split = hydrostatic_fsi_plate(n=n, **plate, substeps=k)
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
