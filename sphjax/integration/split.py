"""Split integration: an elastic solid sub-cycled inside each step of a coupled run.

A stiff solid's stable step ``CFL h / c_s`` is often a hundred times below the fluid's
``CFL h / c0`` (an aluminium plate: ``c_s ~ 5.6 km/s`` against ``c0 ~ 22 m/s``).  With
``SolidSystem(substeps=k)`` a step ``dt`` of :func:`sphjax.simulate` splits the solid's
acceleration into a fast part, its elastic forces and gravity (eq. 14 without ``f^PF``,
re-evaluated on the solid's own reference-configuration neighbours only), and a slow part,
the fluid's forces on it (``solid_fluid``, :mod:`sphjax.physics.fsi`), and integrates the
two with the impulse multiple-time-step scheme (r-RESPA; Tuckerman, Berne & Martyna 1992,
J. Chem. Phys. 97, 1990):

    v_s += dt/2 a_slow(t_n)                                  (coupling half kick)
    k times: kick-drift-kick of the solid alone with a_fast, step dt / k
    fluid: half kick, drift by dt; one evaluation of every system at t_n+1
    fluid: half kick;  v_s += dt/2 a_slow(t_n+1),  a_slow = a(t_n+1) - a_fast(x_s(t_n+1))

The fluid takes its ordinary kick-drift-kick step around the same evaluation, which sees
the solid where its inner steps took it.  Each fluid-solid pair force is applied to both
of its particles with the same weights (``dt/2`` at either end of the step), so linear
momentum is conserved to round-off as without splitting, and with ``k = 1`` the scheme is
the unsplit kick-drift-kick.  The fluid's force on the solid is sampled once per fluid
step, as the fluid's own pressure is; between samples the solid's elastic response is
resolved with its own stable step.

Cost of a step: one evaluation of every system plus ``k + 1`` of the solid alone, in
place of ``k`` evaluations of everything at the solid's step.  The inner steps are a
``lax.scan``, differentiable in forward and reverse mode; in reverse mode the step is
rematerialised as a whole (with ``simulate``'s step checkpoint) and its transpose keeps the
inner steps' per-particle residuals, ``k`` solid states' worth: checkpointing each inner
step as well made the gradient 2x slower (a third replay of the inner steps) for no
measurable memory (the 3,838-particle plate, 126 inner steps: 37.2 MB of temporary
buffers with it, 38.1 MB without).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from sphjax.core.state import Kind, State
from sphjax.integration import step as kdk
from sphjax.integration.stepper import KickDriftKickStepper
from sphjax.neighbors import reference_pairs, update_neighbors
from sphjax.physics.interactions import INTERACTIONS
from sphjax.physics.rhs import Context, evaluate
from sphjax.physics.solid.system import SolidSystem, update_solid

_PER_PARTICLE = (
    "position",
    "velocity",
    "density",
    "mass",
    "kind",
    "reference_position",
    "volume",
    "acceleration",
    "density_rate",
    "pressure",
    "shift_acceleration",
)


def split_active(model) -> bool:
    """Whether ``model`` asks for split integration (a solid with ``substeps > 1``)."""
    solid = model.system(SolidSystem)
    return solid is not None and solid.substeps > 1


def _block(state: State, s: slice) -> State:
    """The particles ``s`` of ``state`` as a State of their own."""
    return state.replace(**{name: getattr(state, name)[s] for name in _PER_PARTICLE})


def fast_acceleration(solid: State, system: SolidSystem, pairs, ctx, reference=None):
    """``a_fast``: the solid's elastic acceleration (eq. 14 without the fluid's force) plus
    gravity, zero on clamped particles; ``solid`` holds the solid's block only.
    ``reference``: the solid's reference quantities (``L0``), or ``None`` (computed
    here)."""
    view = update_solid(system, system.view(solid, slice(None)), pairs, ctx, reference)
    elastic = INTERACTIONS[(SolidSystem, SolidSystem)](system, view, system, view, pairs, ctx)
    return system.body_acceleration(view, elastic["a"], ctx.params)


@dataclasses.dataclass(frozen=True)
class SplitStepper(KickDriftKickStepper):
    """Kick-drift-kick with the solid of ``model`` sub-cycled ``substeps`` times inside
    each step (module docstring); ``init`` is the plain stepper's."""

    def step(self, carry, dt, params):
        state, neighbors = carry
        return split_step(state, neighbors, dt, self.model, params)


def split_step(state: State, neighbors, dt, model, params):
    """One split step of size ``dt`` (module docstring); returns ``(state, neighbors)``."""
    i = next(k for k, s in enumerate(model.systems) if isinstance(s, SolidSystem))
    system = model.systems[i]
    s = slice(*neighbors.blocks[i])
    # the solid's list with its reference geometry, and its L0: computed once per run
    pairs = reference_pairs(neighbors)[(i, i)]
    reference = (neighbors.reference or {}).get(i)
    ctx = Context.of(model, params)

    def with_fast(solid):
        return solid.replace(acceleration=fast_acceleration(solid, system, pairs, ctx, reference))

    def coupling_kick(solid, slow):
        free = (solid.kind == Kind.SOLID)[:, None]
        return solid.replace(
            velocity=jnp.where(free, solid.velocity + 0.5 * dt * slow, solid.velocity)
        )

    solid = _block(state, s)
    inner = with_fast(solid)
    inner = coupling_kick(inner, solid.acceleration - inner.acceleration)
    h = dt / system.substeps

    def substep(solid, _):
        return kdk.closing_kick(with_fast(kdk.kick_drift(solid, h, model)), h, model), None

    inner = jax.lax.scan(substep, inner, None, length=system.substeps)[0]

    drifted = kdk.kick_drift(state, dt, model)
    drifted = drifted.replace(
        position=drifted.position.at[s].set(inner.position),
        velocity=drifted.velocity.at[s].set(inner.velocity),
    )
    neighbors = update_neighbors(drifted.position, neighbors)
    out = evaluate(drifted, neighbors, model, params, density_step=dt)
    out = kdk.closing_kick(out, dt, model)
    solid = coupling_kick(inner, out.acceleration[s] - inner.acceleration)
    return out.replace(velocity=out.velocity.at[s].set(solid.velocity)), neighbors
