"""Calibrate Young's modulus and Poisson's ratio from an oscillating plate's tip motion.

Identical-twin experiment with the cantilever of Gray, Monaghan & Swift (2001): the
"observations" are the transverse tip displacement series of a run at the true E and nu
with 1 % Gaussian noise (of the signal's RMS).  The calibration starts at E/2 and
nu = 0.3 and fits log E and logit(2 nu) (nu stays in (0, 0.5)) through the whole
simulation with L-BFGS directions and a capped step (an optax chain).

The plate is set in motion with ``v_y = V_f c0 f(x / L)``, ``c0 = sqrt(K / rho)``, as in the
case definition, so the initial velocity depends on E and nu too.  That makes both
identifiable: the frequency fixes ``E / (1 - nu^2)`` and the amplitude
``V_f c0 / omega`` (independent of E) fixes nu.

    python examples/calibrate_youngs_modulus.py     # ~10 s (48 particles, 100 iterations at most)
"""

from __future__ import annotations

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import optax  # noqa: E402

import sphjax  # noqa: E402
from sphjax.calibration import calibrate  # noqa: E402
from sphjax.observables import tip_displacement  # noqa: E402

# --- parameters -------------------------------------------------------------------
N = 2  # particles across the thickness
TRUE_E, TRUE_NU = 2.0e6, 0.3975  # Gray et al. (2001)
START_E, START_NU = 0.5 * TRUE_E, 0.3
NOISE = 0.01  # Gaussian noise, fraction of the RMS tip displacement
SAVE_EVERY = 10  # one observation every 10 steps (dt = 5.2e-5 s)
# Continuation over observation windows: a short window first (0.41 periods; from E/2 a
# long window would be off by most of a cycle and the fit could lock onto the wrong
# one), then the full window, which pins the frequency down (1.2 periods).
# (Shorter windows, 1000 then 2000 steps, leave E 2.5 % off: too little of a period.)
WINDOWS = (2000, 6000)
MAX_ITERATIONS = 100  # in total, over all windows
SEED = 0
# Quasi-Newton (L-BFGS) directions with every step capped at 0.1 in the optimised
# coordinates (log E, logit(2 nu)): a full L-BFGS line search may try nu -> 0.5, where
# the bulk modulus and the sound speed blow up and the fixed time step becomes unstable.
OPTIMIZER = optax.chain(optax.scale_by_lbfgs(), optax.clip_by_global_norm(0.1), optax.scale(-1.0))
PLOT = "calibrate_youngs_modulus.png"


def sound_speed(params):
    """``c0 = sqrt(K / rho)``, ``K = E / (3 (1 - 2 nu))`` (as the case defines it)."""
    bulk = params.young_modulus / (3.0 * (1.0 - 2.0 * params.poisson_ratio))
    return jnp.sqrt(bulk / params.solid_density)


def make_observables(case, n_steps, save_every=SAVE_EVERY):
    def observables(params):
        scale = sound_speed(params) / sound_speed(case.params)
        state = case.state.replace(velocity=case.state.velocity * scale)
        traj = sphjax.simulate(
            case,
            params,
            n_steps=n_steps,
            save_every=save_every,
            state=state,
            checkpoint_every=save_every,
        )
        return tip_displacement(traj, case)[1:, 1]  # transverse, frames after t = 0

    return observables


def run(
    n=N,
    windows=WINDOWS,
    save_every=SAVE_EVERY,
    noise=NOISE,
    max_iterations=MAX_ITERATIONS,
    seed=SEED,
    verbose=True,
):
    """Returns ``(result, (E_true, nu_true), observed, clean)``; ``result.history`` and
    ``result.iterations`` cover all windows."""
    case = sphjax.cases.oscillating_plate(n=n, young_modulus=TRUE_E, poisson_ratio=TRUE_NU)
    clean = jax.jit(make_observables(case, windows[-1], save_every))(case.params)
    rms = jnp.sqrt(jnp.mean(clean**2))
    observed = clean + noise * rms * jax.random.normal(jax.random.PRNGKey(seed), clean.shape)
    start = {"young_modulus": START_E, "poisson_ratio": START_NU}
    history, iterations, result = None, 0, None
    for n_steps in windows:
        if verbose:
            print(f"--- window: {n_steps} steps ({n_steps // save_every} observations)")
        result = calibrate(
            make_observables(case, n_steps, save_every),
            observed[: n_steps // save_every],
            case.params,
            start,
            OPTIMIZER,
            max_iterations - iterations,
            transform={"young_modulus": "log", "poisson_ratio": (0.0, 0.5)},
            step_tolerance=1e-7,
            verbose=verbose,
        )
        start = result.values
        iterations += result.iterations
        if history is None:
            history = result.history
        else:
            for key, values in result.history.items():
                history[key] = (
                    history[key][:-1] + values if key in start else (history[key] + values)
                )
    result.history, result.iterations = history, iterations
    return result, (TRUE_E, TRUE_NU), observed, clean


def plot(result, truth, path):
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.5))
    axes[0].semilogy(result.history["loss"], "o-")
    axes[0].set(xlabel="iteration", ylabel="relative misfit", title="loss")
    for ax, name, true in zip(axes[1:], ("young_modulus", "poisson_ratio"), truth, strict=True):
        ax.plot(result.history[name], "o-", label="estimate")
        ax.axhline(true, color="k", ls="--", label="truth")
        ax.set(xlabel="iteration", title=name)
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    result, (E, nu), _, _ = run()
    err_E = result.values["young_modulus"] / E - 1.0
    err_nu = result.values["poisson_ratio"] / nu - 1.0
    print(
        f"recovered E = {result.values['young_modulus']:.6g} Pa (truth {E:.6g}), "
        f"error {100 * err_E:+.3f} %"
    )
    print(
        f"recovered nu = {result.values['poisson_ratio']:.6g} (truth {nu}), "
        f"error {100 * err_nu:+.3f} %  after {result.iterations} iterations"
    )
    plot(result, (E, nu), PLOT)
    print(f"plot saved to {PLOT}")
