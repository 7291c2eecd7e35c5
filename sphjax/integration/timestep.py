"""Stable time steps: the smallest of every system's limits (``time_step_limits``).

Fluid: ``dt = min(CFL h / (c0 + |v|max), 0.125 h^2 / nu, 0.25 sqrt(h / |g|))``, CFL 0.25.
Solid (TLSPH): ``dt = CFL h / (c_s + |v|max)``, ``c_s = sqrt(K / rho0)``,
``K = E / (d (1 - 2 nu))``, CFL 0.3; ``substeps`` times that with split integration
(``SolidSystem.substeps``: the solid takes that many steps of its own per step).

``MAX_*_CFL`` are the largest Courant numbers :func:`sphjax.simulate` accepts; a larger
time step is rejected before the run starts.
"""

from __future__ import annotations

import math

import numpy as np

from sphjax.core.state import State
from sphjax.physics.solid.system import SolidSystem

FLUID_CFL = 0.25
SOLID_CFL = 0.3
MAX_FLUID_CFL = 0.5
MAX_SOLID_CFL = 0.6


def stable_time_step(
    state: State, model, params, fluid_cfl=FLUID_CFL, solid_cfl=SOLID_CFL
) -> float:
    """The largest stable step for the kinds in ``model`` (concrete values, outside jit)."""
    kinds = np.asarray(state.kind)
    speed = np.linalg.norm(np.asarray(state.velocity), axis=-1)
    cfl = {"fluid": fluid_cfl, "solid": solid_cfl}
    limits = []
    for system in model.systems:
        moving = np.isin(kinds, [int(k) for k in system.free_kinds])
        v_max = float(speed[moving].max(initial=0.0))
        limits += system.time_step_limits(v_max, params, model, cfl[system.params_group])
    if not limits:
        raise ValueError("the model has no fluid or solid particles to set a time step")
    return min(limits)


def split_substeps(
    state: State, model, params, fluid_cfl=FLUID_CFL, solid_cfl=SOLID_CFL, max_dt=None
) -> int:
    """Split integration's ``"auto"`` (``SolidSystem.substeps``): the whole number of the
    solid's stable steps in the fluid's stable step, or in ``max_dt`` if that is shorter
    (e.g. a fraction of the solid's first period, so that the fluid's force on it, sampled
    once a step, follows its motion); at least 1."""
    unsplit = model.replace(
        systems=tuple(
            s.replace(substeps=1) if isinstance(s, SolidSystem) else s for s in model.systems
        )
    )
    dt_solid = stable_time_step(state, unsplit, params, fluid_cfl, solid_cfl)
    fluid_only = model.replace(
        systems=tuple(s for s in model.systems if not isinstance(s, SolidSystem))
    )
    dt = stable_time_step(state, fluid_only, params, fluid_cfl, solid_cfl)
    if max_dt is not None:
        dt = min(dt, max_dt)
    return max(1, int(dt / dt_solid))


def check_time_step(dt: float, state: State, model, params) -> None:
    """Raise a ValueError naming ``dt`` if it exceeds the stability limit."""
    if not dt > 0 or not math.isfinite(dt):
        raise ValueError(f"dt must be a positive number, got {dt}")
    limit = stable_time_step(state, model, params, MAX_FLUID_CFL, MAX_SOLID_CFL)
    if dt > limit * (1.0 + 1e-9):
        recommended = stable_time_step(state, model, params)
        raise ValueError(
            f"dt={dt:.4g} exceeds the stability limit {limit:.4g} of this case "
            f"(acoustic CFL {MAX_FLUID_CFL} fluid / {MAX_SOLID_CFL} solid, viscous and "
            f"body-force limits); pass dt <= {limit:.4g}, e.g. the recommended {recommended:.4g}"
        )
