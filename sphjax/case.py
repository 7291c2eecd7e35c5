"""A Case bundles what a run starts from: initial State, static Model, Params, time step."""

from __future__ import annotations

import dataclasses
from typing import Any

from sphjax.state import Model, Params, State


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
    """

    name: str
    state: State
    model: Model
    params: Params
    dt: float
    t_end: float
    info: dict[str, Any] = dataclasses.field(default_factory=dict)

    @property
    def n_particles(self) -> int:
        return self.state.n_particles

    def replace(self, **changes) -> Case:
        return dataclasses.replace(self, **changes)
