"""Contact between a rigid body and the walls: a spring-dashpot force between particles.

A body's particle ``a`` and a wall particle ``b`` closer than the contact distance
``d_c = distance * dx_a`` (``dx_a = V_a^(1/d)``, the body's particle spacing) push
apart along ``n_ab = (x_a - x_b) / r_ab`` with the normal force

    F_ab = max(k_a delta_ab - c_a v_n, 0),   delta_ab = d_c - r_ab,
    v_n = (v_a - v_b) . n_ab,   k_a = m_a omega^2,   c_a = 2 zeta sqrt(m_a k_a),

a linear spring of overlap ``delta_ab`` and a dashpot on the normal relative velocity
(Kelvin-Voigt; Cundall & Strack 1979), clamped at zero so that it never pulls the body
onto the wall; and a tangential dashpot on the sliding velocity
``v_t = v_a - v_b - v_n n_ab``, capped by Coulomb friction:

    f_ab = F_ab n_ab - min(c_a |v_t|, mu F_ab) v_t / |v_t|.

This is TrixiParticles.jl's rigid-body boundary contact (``RigidBoundaryContactModel``:
a body particle and a wall particle within ``contact_distance``;
``normal_contact_force_components`` with ``normal_stiffness`` and ``normal_damping``;
``tangential_contact_force`` with ``tangential_damping`` and no tangential spring, capped
at the friction coefficient times the normal force), with the stiffness per unit mass
of the body's particle, ``omega^2``, and both dashpots a fraction ``zeta`` of the
critical damping ``2 sqrt(m_a k_a)`` of that spring (as TrixiParticles'
``LinearContactModel``).  The friction matters even on a level floor: a particle
resting on the lattice of wall particles sits on a bump of the pair forces, and without
it the body drifts off sideways.

On a lattice the walls' first row of particles lies half a spacing behind the wall's
surface and the body's half a spacing inside its face, so a face at a gap ``g`` from the
wall has its particles ``dx + g`` from the wall's: with ``distance = 1.5`` the contact
acts within half a spacing of the surfaces touching, and a body at rest on a floor under
a load ``F`` per particle column stays ``0.5 dx - F / k`` above it.

``omega``, ``zeta`` and ``mu`` are differentiable Params fields (``contact_frequency``,
``contact_damping_ratio``, ``contact_friction`` of :class:`~sphjax.SolidParams`); the
contact distance ``distance`` is static, on :class:`WallContact` (it decides which pairs
touch).

The forces ``f_ab`` enter the body's resultant force and torque with the fluid's
(:func:`sphjax.physics.rigid.system.rigid_acceleration`); the walls do not move.

References:
  P. A. Cundall, O. D. L. Strack, "A discrete numerical model for granular assemblies",
  Geotechnique 29 (1979) 47-65.
  TrixiParticles.jl, ``src/schemes/structure/rigid_body/boundary_contact_models.jl`` and
  ``contact_forces.jl``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from sphjax.core.space import dot, scale

_MOVED = {
    "frequency": "contact_frequency",
    "damping_ratio": "contact_damping_ratio",
    "friction": "contact_friction",
}


@dataclasses.dataclass(frozen=True, init=False)
class WallContact:
    """Contact of a rigid body with the walls (module docstring): a spring-dashpot force
    between its particles and the wall particles within ``distance`` particle spacings.

    The spring's frequency ``omega``, the dashpots' damping ratio ``zeta`` and the
    friction coefficient ``mu`` are differentiable :class:`~sphjax.Params` fields,
    ``contact_frequency``, ``contact_damping_ratio`` and ``contact_friction`` (the case
    sets them: ``make_params(..., contact_frequency=800.0)``, ``params.replace(...)``), so
    ``jax.grad`` sees them; a model whose body has no wall contact refuses them
    (:class:`~sphjax.UnusedParameterError`).

    The contact distance stays static, here: it decides which body-wall pairs exist (the
    pairs the force acts on, and that the model forms body-wall neighbour lists at all),
    a structural choice like the smoothing length, checked once against the neighbour
    lists' reach; the force also jumps where a pair crosses it (an approaching particle's
    dashpot), so it has no useful derivative.

    Attributes:
      distance: the contact distance in the body's particle spacings (> 1: the force
        starts before the surfaces touch; it must stay within the kernel's support, where
        the neighbour lists reach).  Keyword only.
    """

    distance: float = 1.5

    parameters = ("contact_frequency", "contact_damping_ratio", "contact_friction")

    def __init__(self, *args, distance: float = 1.5, **moved):
        unknown = sorted(set(moved) - set(_MOVED))
        if unknown:
            raise TypeError(
                f"WallContact got an unexpected keyword {unknown[0]!r}: it takes only "
                "distance= (the contact distance in particle spacings)"
            )
        if args or moved:
            names = [_MOVED[name] for name in moved] or ["contact_frequency"]
            raise ValueError(
                f"WallContact takes only distance= (the contact distance in spacings); its "
                f"spring and friction are Params fields ({', '.join(names)}): set them with "
                f"make_params(..., {names[0]}=...) or params.replace({names[0]}=...)"
            )
        number = (
            float(distance)
            if isinstance(distance, int | float) and not isinstance(distance, bool)
            else None
        )
        if number is None or not math.isfinite(number) or not number > 1.0:
            raise ValueError(
                f"WallContact.distance must be a number > 1, got {distance!r}; "
                "e.g. WallContact(distance=1.5)"
            )
        object.__setattr__(self, "distance", number)

    @staticmethod
    def time_step_limit(params) -> float:
        """``0.2 / omega`` (``params.contact_frequency``, concrete): about 30 steps a
        period of one particle's spring (a body's own contact frequency, ``omega`` over
        the square root of its particles per column, is lower)."""
        return 0.2 / float(params.contact_frequency)

    def acceleration(self, body: dict, wall: dict, pairs, ctx) -> jax.Array:
        """``sum_b f_ab / m_a`` of each body particle ``a`` over the wall particles ``b``
        (``body``: ``x, v, V``; ``wall``: ``x, v``), with the contact's Params
        (``ctx.params``)."""
        solid = ctx.params.solid
        shared = ContactParameters(
            solid.contact_frequency, solid.contact_damping_ratio, solid.contact_friction
        )
        summand = functools.partial(contact_summand, distance=self.distance)
        rows = {"x": body["x"], "v": body["v"], "V": body["V"]}
        cols = {"x": wall["x"], "v": wall["v"]}
        return ctx.pair_sum(summand, rows, cols, pairs, shared)["a"]


class ContactParameters(NamedTuple):
    """The contact's Params every pair sees (``pair_sum``'s ``shared``), by name."""

    frequency: object
    damping_ratio: object
    friction: object


def contact_summand(pair, a, b, shared: ContactParameters, *, distance):
    """``f_ab / m_a`` (module docstring): ``max(omega^2 delta_ab - 2 zeta omega v_n, 0)``
    along ``n_ab``, less the tangential dashpot ``2 zeta omega v_t`` capped at ``mu`` times
    that; zero beyond the contact distance, for padding and at ``r = 0``."""
    frequency, damping_ratio, friction = shared
    dim = pair.dr.shape[-1]
    reach = distance * a["V"] ** (1.0 / dim)
    touching = pair.mask & (pair.r > 0.0) & (pair.r < reach)
    r = jnp.where(touching, pair.r, 1.0)  # the double-where: no 1/0 in the derivative
    normal = scale(1.0 / r, pair.dr)
    relative_velocity = a["v"] - b["v"]
    normal_velocity = dot(relative_velocity, normal)
    damping = 2.0 * damping_ratio * frequency
    push = frequency**2 * (reach - r) - damping * normal_velocity
    normal_force = jnp.where(touching, jnp.maximum(push, 0.0), 0.0)
    sliding = relative_velocity - scale(normal_velocity, normal)
    speed_squared = dot(sliding, sliding)
    moving = touching & (speed_squared > 0.0)
    speed = jnp.sqrt(jnp.where(moving, speed_squared, 1.0))
    # c |v_t| capped at mu F_n, as a coefficient of v_t
    drag = jnp.where(moving, jnp.minimum(damping, friction * normal_force / speed), 0.0)
    return {"a": scale(normal_force, normal) - scale(drag, sliding)}
