"""A Case bundles what a run starts from: initial State, static Model, Params, time step."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any

from sphjax._text import show
from sphjax.core.model import Model
from sphjax.core.params import Params
from sphjax.core.state import State


@dataclasses.dataclass(frozen=True)
class Case:
    """A ready-to-run set-up returned by ``sphjax.cases.<name>(...)``.

    Attributes:
      name: case name.
      state: initial :class:`State`.
      model: static :class:`Model`.
      params: differentiable :class:`Params`, carrying the fields ``model`` does not read
        as :attr:`Params.unused`: ``case.params.replace(...)`` refuses to set them.
      dt: a stable time step for ``params`` (CFL and viscous/body-force limits).
      t_end: default end time.
      info: case-specific numbers (resolution, geometry, reference values, probes), for
        the parameters the case was built with.
      initial_state: ``f(params) -> State`` for cases whose initial state depends on
        parameters (the plate's initial velocity on the Young's modulus through its sound
        speed, an initial density on ``sound_speed`` through the equation of state), or
        ``None`` when it does not.  Written with ``jax.numpy``, so ``jax.grad`` with respect
        to ``params`` sees the dependence.  Use :meth:`state_for`.
    """

    name: str
    state: State
    model: Model
    params: Params
    dt: float
    t_end: float
    info: dict[str, Any] = dataclasses.field(default_factory=dict)
    initial_state: Callable[[Params], State] | None = None

    def __post_init__(self):
        try:
            t_end = float(self.t_end)
        except (TypeError, ValueError):
            t_end = math.nan
        if not (t_end > 0 and math.isfinite(t_end)):
            raise ValueError(
                f"t_end must be a positive number (the end time in s), got {show(self.t_end)}"
            )
        # parameters act or are refused: the fields the model does not read are refused
        object.__setattr__(self, "params", self.params.for_model(self.model))

    @property
    def n_particles(self) -> int:
        return self.state.n_particles

    def state_for(self, params: Params | None = None) -> State:
        """The initial State for ``params`` (default ``self.params``).

        ``case.state_for(case.params)`` equals ``case.state``; for other parameters it is
        the state the case factory would have built with them (see ``initial_state``).
        """
        if self.initial_state is None or params is None or params is self.params:
            return self.state
        return self.initial_state(params)

    def replace(self, **changes) -> Case:
        """A copy with ``changes``; a new ``state`` drops ``initial_state`` unless given."""
        if "state" in changes:
            changes.setdefault("initial_state", None)
        return dataclasses.replace(self, **changes)
