"""Calibrate the kinematic viscosity from Taylor-Green kinetic-energy decay.

Identical-twin experiment: the "observations" are the kinetic energy KE(t)/KE(0) of a run
at the true viscosity; the calibration starts three times too high and fits log(nu)
through the whole simulation with optax's L-BFGS.  The run stays within the first 40
steps (t ~ 0.09), where the decay follows exp(-16 pi^2 nu t) at this resolution.

    python examples/calibrate_viscosity.py            # n = 10
    SPHJAX_SMALL=1 python examples/calibrate_viscosity.py
"""

from __future__ import annotations

import os

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import optax  # noqa: E402

import sphjax  # noqa: E402
from sphjax.calibration import calibrate  # noqa: E402

# --- parameters -------------------------------------------------------------------
SMALL = os.environ.get("SPHJAX_SMALL", "0") == "1"
N = 8 if SMALL else 10  # particles per side
TRUE_VISCOSITY = 0.01  # Re = 100
START_FACTOR = 3.0  # start three times off
N_STEPS, SAVE_EVERY = 40, 5
MAX_ITERATIONS = 30
PLOT = "calibrate_viscosity.png"


def kinetic_energy(states):
    return 0.5 * jnp.sum(states.mass[..., None] * states.velocity**2, axis=(-1, -2))


def make_observables(case):
    def observables(params):
        traj = sphjax.simulate(
            case, params, n_steps=N_STEPS, save_every=SAVE_EVERY, checkpoint_every=SAVE_EVERY
        )
        ke = kinetic_energy(traj.states)
        return ke / ke[0]

    return observables


def run(n=N, start_factor=START_FACTOR, max_iterations=MAX_ITERATIONS, verbose=True):
    """Returns ``(result, true_viscosity)``."""
    case = sphjax.cases.taylor_green(n=n, reynolds=1.0 / TRUE_VISCOSITY)
    observables = make_observables(case)
    observed = jax.jit(observables)(case.params)
    result = calibrate(
        observables,
        observed,
        case.params,
        {"kinematic_viscosity": start_factor * TRUE_VISCOSITY},
        optax.lbfgs(),
        max_iterations,
        step_tolerance=1e-6,
        verbose=verbose,
    )
    return result, TRUE_VISCOSITY


def plot(result, truth, path):
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.5))
    ax1.semilogy(result.history["loss"], "o-")
    ax1.set(xlabel="iteration", ylabel="relative misfit", title="loss")
    ax2.plot(result.history["kinematic_viscosity"], "o-", label="estimate")
    ax2.axhline(truth, color="k", ls="--", label="truth")
    ax2.set(xlabel="iteration", ylabel="nu", title="kinematic viscosity")
    ax2.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    result, truth = run()
    error = result.values["kinematic_viscosity"] / truth - 1.0
    print(
        f"recovered nu = {result.values['kinematic_viscosity']:.6g} (truth {truth}), "
        f"error {100 * error:+.3f} % after {result.iterations} iterations"
    )
    plot(result, truth, PLOT)
    print(f"plot saved to {PLOT}")
