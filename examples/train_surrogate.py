"""Train a graph-network surrogate on an SPH Taylor-Green ensemble and evaluate rollouts.

1. make (or read) a LagrangeBench-format dataset of 2D Taylor-Green trajectories with random
   initial velocity fields and viscosities (``sphjax.dataset``);
2. train a GNS (``sphjax.surrogate``) for a wall-clock budget;
3. roll it out on the test split against the SPH ground truth: LagrangeBench's MSE5/10/20,
   kinetic-energy error and Sinkhorn distance (and the original sphjax metrics in the
   JSON), beside the constant-velocity baseline;
4. save the weights, the metrics (JSON) and a plot of a rollout beside the ground truth.

    python examples/train_surrogate.py --out runs/tg --seconds 1800
    SPHJAX_SMALL=1 python examples/train_surrogate.py --out /tmp/tg-small   # seconds
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import jax
import numpy as np

import sphjax
from sphjax.dataset import Perturbation, generate_dataset
from sphjax.surrogate import LearnedSimulator, SimulatorConfig, data, rollout_metrics, train

SMALL = os.environ.get("SPHJAX_SMALL", "0") not in ("", "0")

# ---- dataset: 2D periodic Taylor-Green vortex, random velocity fields and viscosities
PARTICLES_PER_SIDE = 12 if SMALL else 32
N_TRAIN, N_VALID, N_TEST = (2, 1, 1) if SMALL else (32, 4, 4)
WRITE_EVERY = 5  # solver steps per frame
STEPS = 14 * WRITE_EVERY if SMALL else 30 * WRITE_EVERY  # frames = STEPS / WRITE_EVERY + 1
VARY = {"kinematic_viscosity": (0.0075, 0.015)}
PERTURBATION = Perturbation(amplitude=(0.7, 1.1), fourier=0.2, modes=2)
SEED = 1

# ---- surrogate and training
CONFIG = SimulatorConfig(
    history=5,
    latent=16 if SMALL else 32,
    hidden=16 if SMALL else 32,
    message_steps=2 if SMALL else 3,
)
TRAIN_SECONDS = 20.0 if SMALL else 1800.0
BATCH_SIZE = 2
LEARNING_RATE, FINAL_LEARNING_RATE = 1e-3, 1e-5
ROLLOUT_STEPS = 20 if not SMALL else 8
REPORT = (1, 5, 10, 20)


def make_dataset(folder: Path) -> None:
    case = sphjax.cases.taylor_green(n=PARTICLES_PER_SIDE)
    generate_dataset(
        case,
        folder,
        n_train=N_TRAIN,
        n_valid=N_VALID,
        n_test=N_TEST,
        steps=STEPS,
        write_every=WRITE_EVERY,
        vary=VARY,
        perturbation=PERTURBATION,
        seed=SEED,
        resume=(folder / "INCOMPLETE").exists(),
        case_kwargs={"n": PARTICLES_PER_SIDE},
    )


def plot_rollout(sim, model, test, path: Path, n_steps: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import jax.numpy as jnp
    import matplotlib.pyplot as plt

    h = sim.config.history
    types = jnp.asarray(test.particle_type[0])
    x0 = jnp.asarray(test.positions[0, : h + 1])
    truth = test.positions[0, h + 1 : h + 1 + n_steps]
    neighbors = sim.allocate(x0[-1])
    frames, _ = sim.compiled_rollout(n_steps)(model, x0, types, jnp.asarray(truth), neighbors)
    frames = np.asarray(frames)
    shows = sorted({0, n_steps // 2, n_steps - 1})
    fig, axes = plt.subplots(2, len(shows), figsize=(3.2 * len(shows), 6.4), squeeze=False)
    for col, k in enumerate(shows):
        for row, (x, prev, title) in enumerate(
            [
                (truth[k], truth[k - 1] if k else x0[-1], "SPH"),
                (frames[k], frames[k - 1] if k else x0[-1], "GNS"),
            ]
        ):
            v = (
                np.linalg.norm(
                    data.displacement(x, np.asarray(prev), sim.bounds, sim.periodic), axis=-1
                )
                / sim.frame_dt
            )
            ax = axes[row, col]
            ax.scatter(x[:, 0], x[:, 1], c=v, s=4, cmap="viridis", vmin=0, vmax=1.2)
            ax.set_title(f"{title}, rollout step {k + 1}")
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=None, help="dataset folder (made if absent)")
    parser.add_argument("--out", type=Path, default=Path("runs/surrogate"))
    parser.add_argument("--seconds", type=float, default=TRAIN_SECONDS, help="training budget")
    parser.add_argument("--steps", type=int, default=None, help="training steps (optional cap)")
    parser.add_argument(
        "--overwrite", action="store_true", help="replace the weights of an earlier run in --out"
    )
    args = parser.parse_args(argv)
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    folder = args.data or out / "dataset"
    if not (folder / "metadata.json").exists():
        t0 = time.perf_counter()
        make_dataset(folder)
        print(f"dataset written to {folder} in {time.perf_counter() - t0:.0f} s")
    train_set, valid_set, test_set = (data.load(folder, s) for s in ("train", "valid", "test"))
    print(f"train: {train_set.positions.shape} (trajectories, frames, particles, dim)")

    sim = LearnedSimulator(train_set.metadata, CONFIG)
    model = sim.init_model(jax.random.PRNGKey(SEED))
    result = train(
        sim,
        model,
        train_set,
        valid_set,
        n_steps=args.steps,
        seconds=args.seconds,
        batch_size=BATCH_SIZE,
        lr=LEARNING_RATE,
        lr_final=FINAL_LEARNING_RATE,
        seed=SEED,
        eval_every=100 if SMALL else 500,
        eval_rollout=ROLLOUT_STEPS,
    )
    print(f"trained {result.steps} steps in {result.seconds:.0f} s")
    sim.save(result.model, out / "gns.eqx", overwrite=args.overwrite)

    t0 = time.perf_counter()
    surrogate = rollout_metrics(sim, result.model, test_set, ROLLOUT_STEPS, report=REPORT)
    baseline = rollout_metrics(sim, None, test_set, ROLLOUT_STEPS, report=REPORT)
    eval_seconds = time.perf_counter() - t0
    metrics = dict(
        surrogate=surrogate,
        constant_velocity=baseline,
        train_steps=result.steps,
        train_seconds=result.seconds,
        eval_seconds=eval_seconds,
        final_loss=float(np.mean(result.losses[-50:])) if result.losses else None,
        dataset=dict(
            folder=str(folder),
            train_shape=list(train_set.positions.shape),
            n_valid=len(valid_set),
            n_test=len(test_set),
        ),
        config=dict(sim.config.__dict__),
    )
    (out / "metrics.json").write_text(json.dumps(metrics, indent=1))
    print(f"{'':>10} {'GNS':>10} {'const-vel':>10}   (LagrangeBench's definitions)")
    for key in [k for k in surrogate if k.startswith("lb_mse") and k != "lb_mse_curve"]:
        print(f"{key[3:].upper():>10} {surrogate[key]:10.3e} {baseline[key]:10.3e}")
    for key in ("lb_ekin_mse", "lb_sinkhorn"):
        print(f"{key[3:]:>10} {surrogate[key]:10.3e} {baseline[key]:10.3e}")
    plot_rollout(sim, result.model, test_set, out / "rollout.png", ROLLOUT_STEPS)
    print(f"saved {out / 'gns.eqx'}, {out / 'metrics.json'}, {out / 'rollout.png'}")
    return metrics


if __name__ == "__main__":
    main()
