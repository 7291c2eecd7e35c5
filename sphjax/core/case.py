"""A Case bundles what a run starts from: initial State, static Model, Params, time step."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

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
      params: differentiable :class:`Params`.
      dt: a stable time step for ``params`` (CFL and viscous/body-force limits).
      t_end: default end time.
      info: case-specific numbers (resolution, geometry, reference values, probes).
      initial_state: ``None``, or ``f(params) -> State`` for a case whose initial state
        depends on its parameters (computed with ``jax.numpy``, so gradients see it).
    """

    name: str
    state: State
    model: Model
    params: Params
    dt: float
    t_end: float
    info: dict[str, Any] = dataclasses.field(default_factory=dict)
    initial_state: Callable[[Params], State] | None = None

    @property
    def n_particles(self) -> int:
        return self.state.n_particles

    def state_for(self, params: Params) -> State:
        """The initial State for ``params`` (``state`` unless it depends on them)."""
        if self.initial_state is None or params is self.params:
            return self.state
        return self.initial_state(params)

    def replace(self, **changes) -> Case:
        return dataclasses.replace(self, **changes)
