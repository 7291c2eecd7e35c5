"""One stepper, two implementations: what advances a simulation with neighbour lists.

A stepper is a hashable object built for one Model with

    init((state, neighbors), params) -> (state, neighbors)   the rates of the first state
    step((state, neighbors), dt, params) -> (state, neighbors)   one step of size dt

:class:`KickDriftKickStepper` is the plain kick-drift-kick step
(:func:`sphjax.integration.step.kick_drift_kick`, one right-hand-side evaluation on lists
updated at the drifted positions); :class:`~sphjax.integration.split.SplitStepper` sub-cycles
an elastic solid inside each step (r-RESPA).  :func:`stepper_for` picks one from the Model;
:func:`sphjax.simulate` drives it (``lax.scan``, compiled chunks), and the diffrax solver
:class:`sphjax.KickDriftKick` runs the same step through diffrax's term.
"""

from __future__ import annotations

import dataclasses

from sphjax.integration import step as kdk
from sphjax.neighbors import update_neighbors
from sphjax.physics.rhs import evaluate


@dataclasses.dataclass(frozen=True)
class KickDriftKickStepper:
    """Kick-drift-kick (velocity Verlet) with neighbour lists, for ``model``."""

    model: object

    def init(self, carry, params):
        """The first state with its rates evaluated (``neighbors`` current)."""
        state, neighbors = carry
        return evaluate(state, neighbors, self.model, params), neighbors

    def step(self, carry, dt, params):
        """One step of size ``dt``: the lists follow the drifted positions (a Verlet
        skin), then the one evaluation of the step."""
        state, neighbors = carry
        model, updated = self.model, []

        def rates(drifted, density_step):
            updated.append(update_neighbors(drifted.position, neighbors))
            return evaluate(drifted, updated[0], model, params, density_step=density_step)

        return kdk.kick_drift_kick(state, dt, model, rates), updated[0]


def stepper_for(model) -> KickDriftKickStepper:
    """The stepper ``model`` asks for: split integration where a solid has
    ``substeps > 1`` (:class:`~sphjax.integration.split.SplitStepper`), else plain."""
    from sphjax.integration import split

    return split.SplitStepper(model) if split.split_active(model) else KickDriftKickStepper(model)
