"""One stepper: ``stepper_for(model)`` with ``init`` and ``step`` is what ``simulate``
drives; a loop over ``step`` reproduces ``simulate``."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import sphjax
from sphjax import cases
from sphjax.integration.split import SplitStepper
from sphjax.integration.stepper import KickDriftKickStepper, stepper_for
from sphjax.physics.rhs import build_neighbors


@pytest.mark.parametrize(
    "make",
    [
        lambda: cases.dam_break(n=8),
        lambda: cases.hydrostatic_fsi_plate(n=2, substeps=4),
    ],
    ids=["dam_break", "fsi_plate_split"],
)
def test_a_loop_over_the_stepper_is_simulate(make):
    case = make()
    stepper = stepper_for(case.model)
    split = any(getattr(s, "substeps", 1) > 1 for s in case.model.systems)
    assert type(stepper) is (SplitStepper if split else KickDriftKickStepper)
    n_steps = 6
    trajectory = sphjax.simulate(case, n_steps=n_steps, save_every=1, cell_order=False)

    neighbors = sphjax.physics.rhs.with_reference(
        case.state, build_neighbors(case.state, case.model), case.model
    )
    carry = stepper.init((case.state, neighbors), case.params)
    step = jax.jit(lambda c: stepper.step(c, case.dt, case.params))
    np.testing.assert_allclose(carry[0].acceleration, trajectory.states.acceleration[0], atol=1e-4)
    for k in range(1, n_steps + 1):
        carry = step(carry)
        np.testing.assert_allclose(
            carry[0].position, trajectory.states.position[k], rtol=1e-6, atol=1e-7
        )
        np.testing.assert_allclose(
            carry[0].velocity, trajectory.states.velocity[k], rtol=1e-5, atol=1e-6
        )


def test_a_traced_overflow_is_recognised_through_jaxs_wrapping():
    """Inside ``jit`` the lists cannot be re-allocated: the run raises, and whoever catches
    it (the dataset runner re-allocates) recognises the overflow by one rule."""
    from sphjax.neighbors import NeighborOverflowError, is_neighbor_overflow

    case = cases.dam_break(n=8)

    def run(squeeze):
        # a traced run sizes its lists from case.state; this state is twice as dense
        state = case.state.replace(position=squeeze * case.state.position)
        return sphjax.simulate(case, state=state, n_steps=3).states.position[-1, 0, 0]

    with pytest.raises(Exception) as caught:
        jax.block_until_ready(jax.jit(run)(0.7))
    assert is_neighbor_overflow(caught.value)
    assert not is_neighbor_overflow(ValueError("dt must be a positive number"))
    assert is_neighbor_overflow(NeighborOverflowError("any words"))
