"""Cell order (sphjax.core.ordering): a run with the particles sorted along a Morton curve
equals the run in the user's order, in its outputs (trajectory, frames handed to
``on_frames``) and in its gradients (float64)."""

import jax
import jax.numpy as jnp
import numpy as np

import sphjax
from sphjax.core import ordering
from sphjax.physics.rhs import system_blocks


def test_cell_order_is_a_permutation_within_each_system_block():
    case = sphjax.cases.dam_break(n=8)
    blocks = system_blocks(case.state.kind, case.model)
    perm = ordering.cell_order(case.state.position, blocks, case.model.cutoff)
    assert not np.array_equal(perm, np.arange(perm.size))  # the case is not in cell order
    for start, stop in blocks:
        assert sorted(perm[start:stop]) == list(range(start, stop))
    assert np.array_equal(perm[ordering.inverse(perm)], np.arange(perm.size))


def test_reordered_run_equals_the_run_in_user_order():
    """Dam break (fluid, walls, continuity density, delta-SPH), 20 steps: every saved
    frame's fields agree to 1e-10 (summation order only), in the user's order."""
    case = sphjax.cases.dam_break(n=8)
    seen = {True: [], False: []}
    traj = {
        flag: sphjax.simulate(
            case,
            n_steps=20,
            save_every=10,
            cell_order=flag,
            on_frames=lambda s, t, flag=flag: seen[flag].append(np.asarray(s.position)),
        )
        for flag in (True, False)
    }
    for name in ("position", "velocity", "density", "pressure", "kind", "mass"):
        a = np.asarray(getattr(traj[True].states, name))
        b = np.asarray(getattr(traj[False].states, name))
        scale = max(1.0, float(np.abs(b).max()))
        assert np.abs(a - b).max() <= 1e-10 * scale, name
    moved = np.abs(np.asarray(traj[False].states.position[-1] - case.state.position)).max()
    assert moved > 1e-6  # the comparison is not of two unchanged states
    assert len(seen[True]) == len(seen[False]) > 1
    for a, b in zip(seen[True], seen[False], strict=True):
        assert np.abs(a - b).max() <= 1e-10


def test_gradient_through_a_reordered_run_is_unchanged():
    """Oscillating plate (solid: reference neighbours and L0 in the sorted order) given in
    a shuffled order: d(sum_a w_a y_a after 20 steps)/dE, reverse mode with checkpoints,
    equals the run in the given order (``w_a`` tells the particles apart)."""
    case = sphjax.cases.oscillating_plate(n=2)
    (start, stop), *_ = system_blocks(case.state.kind, case.model)
    shuffle = np.arange(case.n_particles)
    shuffle[start:stop] = start + np.random.default_rng(0).permutation(stop - start)
    state = ordering.permute(case.state, shuffle)
    weight = jnp.linspace(1.0, 2.0, case.n_particles)

    def loss(E, flag):
        params = case.params.replace(young_modulus=E)
        traj = sphjax.simulate(
            case, params, state=state, n_steps=20, checkpoint_every=5, cell_order=flag
        )
        return jnp.sum(weight * traj.final.position[:, 1])

    E0 = jnp.asarray(case.params.young_modulus)
    grads = [jax.grad(loss)(E0, flag) for flag in (True, False)]
    assert abs(float(grads[1])) > 0
    assert abs(float(grads[0] - grads[1])) <= 1e-10 * abs(float(grads[1]))
