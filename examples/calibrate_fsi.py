"""Recover a plate's Young's modulus from its deflection under a water column, through the
coupled fluid-structure simulation.

Identical-twin experiment with a small ``hydrostatic_fsi_plate`` (0.3 m plate 0.05 m thick,
2 particles through it, 0.1 m of water): the "observations" are the mid-span deflection
series of a run at the true E with 1 % Gaussian noise (of the signal's RMS).  The
calibration starts at E/2 and fits log E through the whole coupled run (forward mode, one
tangent) with L-BFGS directions and steps capped at 0.1 in log E.

    python examples/calibrate_fsi.py     # about a minute (150 particles, 30 iterations at most)
"""

from __future__ import annotations

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import optax  # noqa: E402

import sphjax  # noqa: E402
from sphjax.calibration import calibrate  # noqa: E402
from sphjax.cases.fsi import hydrostatic_fsi_plate, midspan_deflection  # noqa: E402

# --- parameters -------------------------------------------------------------------
N = 2  # particles through the plate thickness
LENGTH, DEPTH = 0.3, 0.1  # plate length and water depth (m)
TRUE_E = 67.5e9  # Young's modulus of the twin run (Pa)
START_E = 0.5 * TRUE_E
NOISE = 0.01  # Gaussian noise, fraction of the RMS deflection
N_STEPS, SAVE_EVERY = 150, 5  # the first sag under the load; one observation every 5 steps
MAX_ITERATIONS = 30
SEED = 0
OPTIMIZER = optax.chain(optax.scale_by_lbfgs(), optax.clip_by_global_norm(0.1), optax.scale(-1.0))


def make_observables(case, n_steps=N_STEPS, save_every=SAVE_EVERY):
    def observables(params):
        traj = sphjax.simulate(
            case, params, n_steps=n_steps, save_every=save_every, checkpoint_every=save_every
        )
        return midspan_deflection(traj, case)[1:]

    return observables


def observe(case, n_steps=N_STEPS, save_every=SAVE_EVERY, noise=NOISE, seed=SEED):
    """``(observables, observed)``: the model's mid-span deflection series as a function of
    the parameters, and the twin run's series at ``case.params`` with Gaussian noise of
    ``noise`` times its RMS."""
    observables = make_observables(case, n_steps, save_every)
    clean = np.asarray(jax.jit(observables)(case.params))
    rms = np.sqrt(np.mean(clean**2))
    observed = clean + noise * rms * np.random.default_rng(seed).standard_normal(clean.shape)
    return observables, observed


def run(n=N, max_iterations=MAX_ITERATIONS, seed=SEED, verbose=True, n_steps=N_STEPS):
    case = hydrostatic_fsi_plate(n=n, length=LENGTH, depth=DEPTH, young_modulus=TRUE_E, substeps=1)
    observables, observed = observe(case, n_steps=n_steps, seed=seed)
    result = calibrate(
        observables,
        observed,
        case.params,
        {"young_modulus": START_E},
        OPTIMIZER,
        n_iterations=max_iterations,
        step_tolerance=1e-5,
        verbose=verbose,
    )
    return case, result


if __name__ == "__main__":
    case, result = run()
    E = result.values["young_modulus"]
    print(
        f"E = {E:.5g} Pa (true {TRUE_E:.5g}, error {E / TRUE_E - 1:+.2%}), "
        f"{result.iterations} iterations"
    )
