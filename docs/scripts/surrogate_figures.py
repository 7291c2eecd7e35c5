"""Regenerate every number, plot and the shipped weights of docs/surrogates.md.

    python docs/scripts/surrogate_figures.py --work runs/figures --write-docs --write-model
    python docs/scripts/surrogate_figures.py --work /tmp/fig --small        # minutes

The budget is a number of optimiser steps per model (``--train-steps``, default
:data:`TRAIN_STEPS`), not wall-clock time, so a rerun trains the same models on any
machine; ``--seconds`` caps the wall-clock time in addition.  ``--stages`` runs a part
(``gns``: steps 1-3 and 5, the same as ``dataset train metrics``; ``sil``: step 4), and
``--models`` the networks trained (the metrics score every network trained in ``--work``).
The pieces resume: the dataset, each trained network (``WORK/models/NAME.eqx``, its
training record beside it) and each network's metrics (``WORK/metrics/NAME.json``, removed
when the network is trained again) are kept in ``--work`` and not redone, so the run can
be made piece by piece, e.g. ``--stages dataset``, ``--stages train --models gns``,
``--stages train --models gns_pushforward``, ``--stages metrics``.

1. the Taylor-Green dataset with exactly the command printed in docs/surrogates.md
   (:data:`DATASET_COMMAND`; the tests check the two agree), trajectories long enough for
   100-step rollouts;
2. a graph network simulator trained one-step and one trained with push-forward, the same
   budget each;
3. rollout metrics over 100 steps on the test split (LagrangeBench's and ours) for both
   and the constant-velocity baseline -> ``docs/figures/tg_metrics.json``; plots
   ``tg_rollout.png`` and ``tg_rollout_mse.png``;
4. solver in the loop (``docs/scripts/solver_in_the_loop.py``) -> ``sil_tg.json`` and
   ``sil_tg.png``;
5. with ``--write-model``: the one-step model to ``docs/models/tg32_gns.eqx``.

Writes into ``docs/`` only with ``--write-docs`` (otherwise into ``--work``).
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from pathlib import Path

import jax
import numpy as np

HERE = Path(__file__).resolve().parent
DOCS = HERE.parent

# The command printed in docs/surrogates.md ("Reproduce"); DIR is replaced by the folder.
DATASET_COMMAND = (
    "sphjax dataset taylor_green --out DIR --case-arg n=32 --n-train 32 --n-valid 4 "
    "--n-test 4 --steps 600 --write-every 5 --vary kinematic_viscosity=0.0075:0.015 "
    "--amplitude 0.7:1.1 --fourier 0.2 --seed 1 --batch-size 8"
)
# the same ensemble at a size that runs in a minute (the tests and --small)
SMALL_OVERRIDES = {
    "--case-arg": "n=12",
    "--n-train": "2",
    "--n-valid": "1",
    "--n-test": "1",
    "--steps": "130",
}
ROLLOUT, SMALL_ROLLOUT = 100, 14
HISTORY = 5
# optimiser steps per model (one-step and push-forward) for the published figures; the
# push-forward step costs more than the one-step one (at 1024 particles, latent 32, three
# message-passing steps on the shared 2-core machine: 0.13 s and 0.18 s with the other heavy
# jobs held back, 0.5 s and 1.0 s under heavy load)
TRAIN_STEPS = 600


def dataset_argv(folder, small: bool = False) -> list[str]:
    """``DATASET_COMMAND`` as an argv list for :func:`sphjax.cli.main` (without the
    leading ``sphjax``), optionally at the small size."""
    argv = shlex.split(DATASET_COMMAND)[1:]
    argv[argv.index("DIR")] = str(folder)
    if small:
        for flag, value in SMALL_OVERRIDES.items():
            argv[argv.index(flag) + 1] = value
    return argv


def make_dataset(folder: Path, small: bool) -> None:
    from sphjax.cli import main

    if (folder / "metadata.json").exists():
        return
    argv = dataset_argv(folder, small) + (["--resume"] if (folder / "INCOMPLETE").exists() else [])
    if main(argv) != 0:
        raise SystemExit(f"dataset command failed: sphjax {shlex.join(argv)}")


#: the networks: name -> (push-forward unrolls, their weights)
MODELS = {"gns": ((0,), None), "gns_pushforward": ((0, 1, 3), (6, 2, 1))}


def make_simulator(train_set, small: bool):
    from sphjax.surrogate import LearnedSimulator, SimulatorConfig

    config = SimulatorConfig(
        history=HISTORY,
        latent=16 if small else 32,
        hidden=16 if small else 32,
        message_steps=2 if small else 3,
    )
    return LearnedSimulator(train_set.metadata, config)


def train_models(sim, train_set, valid_set, names, n_steps: int, seconds, small: bool, cache):
    """Train the networks ``names`` (:data:`MODELS`), each saved to ``cache/NAME.eqx`` with
    its record (steps, seconds, validation curve) in ``cache/NAME.train.json``; one found
    there is not trained again."""
    from sphjax.surrogate import train

    cache.mkdir(parents=True, exist_ok=True)
    for name in names:
        record = cache / f"{name}.train.json"
        if record.exists():
            print(f"{name}: trained before ({record})")
            continue
        pushforward, weights = MODELS[name]
        result = train(
            sim,
            sim.init_model(jax.random.PRNGKey(1)),
            train_set,
            valid_set,
            n_steps=n_steps,
            seconds=seconds,
            batch_size=2,
            lr=1e-3,
            lr_final=1e-5,
            seed=1,
            eval_every=max(1, n_steps // 6),
            eval_rollout=20 if not small else 8,
            pushforward=pushforward,
            pushforward_weights=weights,
        )
        sim.save(result.model, cache / f"{name}.eqx", overwrite=True)
        (cache.parent / "metrics" / f"{name}.json").unlink(missing_ok=True)  # stale scores
        info = dict(
            steps=result.steps,
            seconds=result.seconds,
            valid=result.valid,
            budget=dict(train_steps=n_steps, seconds=seconds),
            command=shlex.join(["python", "docs/scripts/surrogate_figures.py", *sys.argv[1:]]),
        )
        record.write_text(json.dumps(info, indent=1))
        print(f"{name}: {result.steps} steps in {result.seconds:.0f} s", flush=True)


def load_models(cache, names) -> dict:
    """The trained networks ``names`` found in ``cache``: name -> (model, record)."""
    from sphjax.surrogate import LearnedSimulator

    out = {}
    for name in names:
        record = cache / f"{name}.train.json"
        if record.exists():
            _, model = LearnedSimulator.load(cache / f"{name}.eqx")
            out[name] = (model, json.loads(record.read_text()))
    return out


def plot_mse(metrics: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    for name, m in metrics.items():
        curve = np.asarray(m["lb_mse_curve"])
        ax.semilogy(np.arange(1, len(curve) + 1), curve, label=name)
    ax.set_xlabel("rollout step")
    ax.set_ylabel("position MSE per step (LagrangeBench)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_rollout(sim, model, test, path: Path, n_steps: int) -> None:
    import jax.numpy as jnp
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    h = sim.config.history
    types = jnp.asarray(test.particle_type[0])
    x0 = jnp.asarray(test.positions[0, : h + 1])
    truth = test.positions[0, h + 1 : h + 1 + n_steps]
    frames, _ = sim.compiled_rollout(n_steps)(
        model, x0, types, jnp.asarray(truth), sim.allocate(x0[-1])
    )
    frames = np.asarray(frames)
    shows = sorted({0, n_steps // 2, n_steps - 1})
    fig, axes = plt.subplots(2, len(shows), figsize=(3.2 * len(shows), 6.4), squeeze=False)
    for col, k in enumerate(shows):
        for row, (x, title) in enumerate([(truth[k], "SPH"), (frames[k], "GNS")]):
            ax = axes[row, col]
            ax.scatter(x[:, 0], x[:, 1], s=3, c=np.arange(len(x)), cmap="twilight")
            ax.set_title(f"{title}, rollout step {k + 1}")
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_sil(results: dict, path: Path) -> None:
    """The error curves on the test condition and, beside them, each network's training
    loss (mean over 10 iterations) when the results carry it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    trained = [n for n in ("solver + correction", "pure GNS") if f"{n} training" in results]
    fig, axes = plt.subplots(1, 2 if trained else 1, figsize=(10 if trained else 5.5, 3.6))
    ax = axes[0] if trained else axes
    for name in ("coarse solver", "solver + correction", "pure GNS"):
        if name in results:
            curve = np.asarray(results[name]["curve"])
            ax.plot(np.arange(len(curve)), curve, label=name)
    ax.set_yscale("log")
    ax.set_xlabel("coarse step")
    ax.set_ylabel("relative probe-velocity error")
    ax.legend()
    if trained:
        for name in trained:
            losses = np.asarray(results[f"{name} training"]["losses"])
            k = len(losses) // 10 * 10
            if k:
                mean = losses[:k].reshape(-1, 10).mean(1)
                axes[1].plot(10 * np.arange(1, len(mean) + 1), mean, label=name)
        axes[1].set_yscale("log")
        axes[1].set_xlabel("training iteration")
        axes[1].set_ylabel("training loss (mean of 10)")
        axes[1].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--work", type=Path, required=True, help="folder for the dataset and runs")
    p.add_argument(
        "--train-steps", type=int, default=TRAIN_STEPS, help="optimiser steps per GNS model"
    )
    p.add_argument("--seconds", type=float, default=None, help="also cap each GNS training")
    p.add_argument("--sil-seconds", type=float, default=900.0, help="solver-in-the-loop budget")
    p.add_argument(
        "--stages",
        nargs="+",
        default=["gns", "sil"],
        choices=["gns", "dataset", "train", "metrics", "sil"],
        help="parts to run (gns = dataset train metrics)",
    )
    p.add_argument(
        "--models",
        nargs="+",
        default=list(MODELS),
        choices=list(MODELS),
        help="networks to train (the metrics score every one trained in --work)",
    )
    p.add_argument("--small", action="store_true", help="a run of minutes (checks the script)")
    p.add_argument("--write-docs", action="store_true", help="write into docs/figures")
    p.add_argument("--write-model", action="store_true", help="write docs/models/tg32_gns.eqx")
    args = p.parse_args(argv)
    if args.train_steps < 1:
        p.error(f"--train-steps must be a positive number of steps, got {args.train_steps}")
    if args.small:
        args.train_steps, args.sil_seconds = 20, 10.0

    work = args.work
    work.mkdir(parents=True, exist_ok=True)
    figures = DOCS / "figures" if args.write_docs else work / "figures"
    figures.mkdir(parents=True, exist_ok=True)
    out = {}
    if "gns" in args.stages:
        args.stages = [*args.stages, "dataset", "train", "metrics"]
    if {"dataset", "train", "metrics"} & set(args.stages):
        out["gns"] = gns_stage(args, work, figures)
    if "sil" in args.stages:
        sys.path.insert(0, str(HERE))
        import solver_in_the_loop

        sil_argv = ["--out", str(figures / "sil_tg.json"), "--seconds", str(args.sil_seconds)]
        sil = solver_in_the_loop.main(sil_argv + (["--small"] if args.small else []))
        plot_sil(sil, figures / "sil_tg.png")
        out["sil"] = sil
    print(f"wrote {figures}")
    return out


def gns_stage(args, work: Path, figures: Path) -> dict:
    """Steps 1-3 and 5 (the parts in ``args.stages``): dataset, trained GNS, rollout
    metrics, plots, weights."""
    from sphjax.surrogate import data, rollout_metrics

    folder = work / ("tg12" if args.small else "tg32")
    timing = work / "dataset_seconds.json"
    if "dataset" in args.stages:
        t0 = time.perf_counter()
        made = not (folder / "metadata.json").exists()
        make_dataset(folder, args.small)
        if made:
            timing.write_text(json.dumps(time.perf_counter() - t0))
        print(f"dataset: {time.perf_counter() - t0:.0f} s", flush=True)
    if not {"train", "metrics"} & set(args.stages):
        return {}
    train_set, valid_set, test_set = (data.load(folder, s) for s in ("train", "valid", "test"))
    sim = make_simulator(train_set, args.small)
    cache = work / "models"
    if "train" in args.stages:
        train_models(
            sim,
            train_set,
            valid_set,
            args.models,
            args.train_steps,
            args.seconds,
            args.small,
            cache,
        )
    if "metrics" not in args.stages:
        return {}
    runs = load_models(cache, MODELS)  # every network trained in this --work
    if "gns" not in runs:
        raise SystemExit(f"no trained gns in {cache}: run --stages train first")
    n_steps = SMALL_ROLLOUT if args.small else ROLLOUT
    scores = work / "metrics"
    scores.mkdir(parents=True, exist_ok=True)
    metrics, metrics_seconds = {}, {}
    for name, model in [*((n, m) for n, (m, _) in runs.items()), ("constant velocity", None)]:
        path = scores / f"{name.replace(' ', '_')}.json"
        if not path.exists():
            t0 = time.perf_counter()
            m = rollout_metrics(sim, model, test_set, n_steps=n_steps)
            seconds = time.perf_counter() - t0
            path.write_text(json.dumps(dict(metrics=m, seconds=seconds), default=_plain))
            print(f"metrics of {name}: {seconds:.0f} s", flush=True)
        saved = json.loads(path.read_text())
        metrics[name], metrics_seconds[name] = saved["metrics"], saved["seconds"]
    first = next(iter(runs.values()))[1]
    out = dict(
        metrics=metrics,
        dataset=dict(
            command=shlex.join(["sphjax", *dataset_argv(folder, args.small)]),
            seconds=json.loads(timing.read_text()) if timing.exists() else None,
            metadata=train_set.metadata,
        ),
        budget=first["budget"],
        training={
            n: dict(steps=r["steps"], seconds=r["seconds"], valid=r["valid"], command=r["command"])
            for n, (_, r) in runs.items()
        },
        metrics_seconds=metrics_seconds,
        config=dict(sim.config.__dict__),
        command=shlex.join(["python", "docs/scripts/surrogate_figures.py", *sys.argv[1:]]),
    )
    (figures / "tg_metrics.json").write_text(json.dumps(out, indent=1, default=_plain))
    plot_mse(metrics, figures / "tg_rollout_mse.png")
    plot_rollout(sim, runs["gns"][0], test_set, figures / "tg_rollout.png", n_steps)
    if args.write_model:
        sim.save(runs["gns"][0], DOCS / "models" / "tg32_gns.eqx", overwrite=True)
    base = metrics["constant velocity"]
    print("| metric | " + " | ".join(metrics) + " | GNS / const. velocity |")
    print("|---|" + "---:|" * (len(metrics) + 1))
    keys = [k for k in metrics["gns"] if not k.endswith("curve") and not k.startswith("n_")]
    for key in keys:
        row = " | ".join(f"{m[key]:.3e}" for m in metrics.values())
        print(f"| {key} | {row} | {metrics['gns'][key] / base[key]:.2f} |")
    return out


def _plain(value):
    """JSON for numpy and JAX numbers and arrays."""
    array = np.asarray(value)
    return array.item() if array.ndim == 0 else array.tolist()


if __name__ == "__main__":
    main()
