"""A rigid body (2D): particles that move as one body, pushed by the fluid around it.

The body is a set of particles (kind ``RIGID``) of volumes ``V_i`` and masses
``m_i = rho_b V_i`` (``rho_b``: ``Params.solid_density``, the body's density).  With
``r_i = x_i - X`` its particles' positions about its centre of mass,

    M = sum_i m_i,  X = sum_i m_i x_i / M,  I = sum_i m_i |r_i|^2,
    V = sum_i m_i v_i / M,  omega = sum_i m_i (r_i x v_i) / I,

the forces ``f_i = m_i a_i`` of its interactions (the fluid's pressure and viscous forces,
equal and opposite to the body's on the fluid) and gravity give

    F = sum_i f_i + M g,   tau = sum_i r_i x f_i,   A = F / M,   alpha = tau / I,

and every particle takes the acceleration of that rigid motion,

    a_i = A + alpha e_z x r_i - omega^2 r_i,

which the integrators' kicks and drift apply particle by particle (exact for a
translation; for a rotation the particles' distances change at second order in
``omega dt`` per step).

A fluid sees the body's particles as moving boundary particles, exactly as an elastic
solid's (Adami, Hu & Adams 2012; :mod:`sphjax.physics.fsi`): pressure extrapolated from
the fluid, hydrodynamic mass ``rho0_fluid V_i``, the body's velocity in the no-slip
terms; the interactions are the elastic solid's ``fluid_solid`` and ``solid_fluid``,
registered for this system.  With ``wall_contact``, a spring-dashpot force keeps it off
the walls (:mod:`sphjax.physics.rigid.contact`, the interaction ``rigid_wall``), summed
into ``F`` and ``tau`` with the fluid's.  Not yet: contact between bodies, friction, 3D.

With ``buoyant_gravity = g_b``, the fluid carries no hydrostatic pressure (its
``Params.gravity`` is zero) and the body is given its weight less its buoyancy instead,

    F = sum_i f_i + M g + M (1 - rho0_f / rho_b) g_b,

``rho0_f`` the fluid's reference density (``Params.reference_density``).  For an
incompressible fluid the two are the same problem: the pressure is the hydrostatic
``rho0_f g_b . x`` plus a part that obeys the equations without gravity, and the
hydrostatic part pushes on the body with ``-rho0_f V g_b``, its buoyancy (``V = M /
rho_b``).  A weakly compressible fluid deep in a tall domain is spared the compression
of its hydrostatic pressure, ``rho0 |g| H``, which would otherwise need a sound speed
well above ``sqrt(|g| H)`` (:func:`sphjax.cases.settling_disk`).
"""

from __future__ import annotations

import dataclasses
import math

import jax.numpy as jnp
import numpy as np

from sphjax.core.params import CONTACT_FIELDS, SOLID_DEFAULTS, refusal
from sphjax.core.state import Kind
from sphjax.physics import fsi
from sphjax.physics.fluid.system import FluidSystem
from sphjax.physics.rigid.contact import WallContact
from sphjax.physics.solid.boundary import SolidBoundary
from sphjax.physics.system import block_fields


def _cross(r, v):
    """``r x v`` (its z component) for ``[..., 2]`` vectors."""
    return r[..., 0] * v[..., 1] - r[..., 1] * v[..., 0]


def _perp(r):
    """``e_z x r``."""
    return jnp.stack([-r[..., 1], r[..., 0]], axis=-1)


def rigid_motion(x, v, m):
    """``(X, V, omega, r, I)`` of particles ``x, v`` of masses ``m`` (see the module)."""
    M = jnp.sum(m)
    X = jnp.sum(m[:, None] * x, axis=0) / M
    r = x - X
    I = jnp.sum(m * jnp.sum(r * r, axis=-1))
    V = jnp.sum(m[:, None] * v, axis=0) / M
    omega = jnp.sum(m * _cross(r, v - V)) / I
    return X, V, omega, r, I


def buoyant_weight(buoyant_gravity, fluid_density, body_density):
    """``(1 - rho0_f / rho_b) g_b``: the body's weight less its buoyancy per unit mass in a
    fluid whose hydrostatic pressure is left out (the last term of ``F``, module
    docstring)."""
    return (1.0 - fluid_density / body_density) * buoyant_gravity


def rigid_acceleration(x, v, m, force, gravity):
    """``a_i = A + alpha e_z x r_i - omega^2 r_i`` for the particle forces ``force``
    (``[n, 2]``) and gravity (the body's acceleration without a fluid, ``[2]``): the
    accelerations of the rigid motion the resultant force and torque give the body (module
    docstring)."""
    _, _, omega, r, I = rigid_motion(x, v, m)
    M = jnp.sum(m)
    A = jnp.sum(force, axis=0) / M + gravity
    alpha = jnp.sum(_cross(r, force)) / I
    return A + alpha * _perp(r) - omega**2 * r


@dataclasses.dataclass(frozen=True)
class RigidSystem:
    """A rigid body (kind ``RIGID``, 2D); its density is ``Params.solid_density``, its
    wall contact's spring, dashpots and friction ``Params.contact_frequency``,
    ``contact_damping_ratio`` and ``contact_friction``.

    Attributes:
      boundary: :class:`~sphjax.SolidBoundary`, how a fluid sees the body (no-slip or free
        slip; ``acceleration=True`` uses the body's acceleration in the extrapolated
        pressure).
      wall_contact: :class:`~sphjax.WallContact`, the contact force that keeps the body
        off the walls, or ``None`` (no contact: a body that reaches a wall passes into it;
        the contact's Params fields are then refused).
      buoyant_gravity: ``None``, or the gravity ``g_b`` (a tuple, one entry per axis) of a
        fluid whose hydrostatic pressure is left out (``Params.gravity`` zero): the body
        is given ``(1 - rho0_f / rho_b) g_b``, its weight less its buoyancy per unit
        mass, ``rho0_f`` the fluid's ``Params.reference_density`` and ``rho_b`` the
        body's ``Params.solid_density`` (module docstring).
    """

    boundary: SolidBoundary = SolidBoundary()
    wall_contact: WallContact | None = None
    buoyant_gravity: tuple[float, ...] | None = None

    kinds = (Kind.RIGID,)
    current_configuration = True
    #: after the fluid, whose pressure it extrapolates
    stage = 2
    params_group = "solid"
    free_kinds = (Kind.RIGID,)

    def __post_init__(self):
        if not isinstance(self.boundary, SolidBoundary):
            raise ValueError(
                f"RigidSystem.boundary must be SolidBoundary(...), got {self.boundary!r}"
            )
        if self.wall_contact is not None and not isinstance(self.wall_contact, WallContact):
            raise ValueError(
                "RigidSystem.wall_contact must be WallContact(distance=...) or None, got "
                f"{self.wall_contact!r}"
            )
        if self.buoyant_gravity is not None:
            g = tuple(float(c) for c in self.buoyant_gravity)
            if len(g) != 2 or not all(map(math.isfinite, g)):
                raise ValueError(
                    "RigidSystem.buoyant_gravity must be None or a 2D gravity vector such as "
                    f"(0.0, -9.81), got {self.buoyant_gravity!r}"
                )
            object.__setattr__(self, "buoyant_gravity", g)

    def parameters(self) -> frozenset[str]:
        """``gravity`` and ``solid_density`` (the body's density); with ``wall_contact``,
        the contact's fields (:attr:`WallContact.parameters`); with ``buoyant_gravity``,
        ``reference_density`` (the fluid's, in its buoyancy)."""
        contact = () if self.wall_contact is None else self.wall_contact.parameters
        buoyancy = () if self.buoyant_gravity is None else ("reference_density",)
        return frozenset({"gravity", "solid_density", *contact, *buoyancy})

    def unused_parameters(self) -> dict[str, str]:
        """The elastic solid's fields (a rigid body has none of them) and, without
        ``wall_contact``, the contact's."""
        read = self.parameters()
        return {
            name: refusal(
                name,
                "rigid body",
                "it has no wall contact",
                "give it RigidSystem(wall_contact=WallContact())",
            )
            if name in CONTACT_FIELDS
            else refusal(name, "rigid body", "it does not deform", "use a SolidSystem")
            for name in SOLID_DEFAULTS
            if name not in read
        }

    def replace(self, **changes) -> RigidSystem:
        return dataclasses.replace(self, **changes)

    # the system protocol (sphjax.physics.system)

    def view(self, state, block: slice, density_step=None) -> dict:
        """``x, v, rho``, the volumes ``V`` and ``a``, the acceleration of the last
        evaluation (the extrapolated pressure may read it)."""
        view = block_fields(state, block)
        view.update(V=state.volume[block], a=state.acceleration[block])
        return view

    def boundary_view(self, view: dict, params) -> dict:
        """A fluid sees the body's particles with their hydrodynamic mass."""
        return fsi.fluid_view_of_solid(view, params.fluid)

    def update(self, i: int, views: list, systems: tuple, pairs: dict, ctx, density_step=None):
        """Masses ``rho_b V`` from Params, then the boundary pressure, density and viscous
        velocity from each fluid (:func:`sphjax.physics.fsi.update_solid_boundary`)."""
        view = {**views[i], "m": ctx.params.solid.solid_density * views[i]["V"]}
        for j, fluid in enumerate(systems):
            if (i, j) in pairs and isinstance(fluid, FluidSystem):
                view = fsi.update_solid_boundary(self, view, fluid, views[j], pairs[(i, j)], ctx)
        return view

    def body_acceleration(self, view: dict, acceleration, params):
        """The rigid motion's particle accelerations (module docstring) for the forces
        ``m_i a_i`` of the interactions, gravity and, with ``buoyant_gravity``, the body's
        weight less its buoyancy."""
        m = view["m"]
        force = m[:, None] * acceleration
        gravity = params.gravity
        if self.buoyant_gravity is not None:
            gravity = gravity + buoyant_weight(
                jnp.asarray(self.buoyant_gravity, gravity.dtype),
                params.fluid.reference_density,
                params.solid.solid_density,
            )
        return rigid_acceleration(view["x"], view["v"], m, force, gravity)

    def check_params(self, params) -> None:
        """With ``buoyant_gravity`` the fluid carries no hydrostatic pressure: a non-zero
        ``Params.gravity`` would give the body its buoyancy twice (from the pressure and
        in ``buoyant_weight``), so it is refused."""
        if self.buoyant_gravity is None:
            return
        g = np.asarray(params.gravity, dtype=float)
        if np.any(g != 0.0):
            raise ValueError(
                f"gravity = {tuple(g.tolist())} with RigidSystem(buoyant_gravity="
                f"{self.buoyant_gravity}): the body would feel its buoyancy twice; set "
                "gravity to zero (buoyant_gravity stands for it) or drop buoyant_gravity"
            )

    def held_kinds(self) -> tuple:
        return ()

    def prescribed_motion(self, time, state):
        return None

    def time_step_limits(self, v_max: float, params, model, cfl: float) -> list[float]:
        """The wall contact's (:meth:`WallContact.time_step_limit`); otherwise none of its
        own: the fluid's acoustic limit covers it (``v_max`` enters the fluid's)."""
        if self.wall_contact is None:
            return []
        return [self.wall_contact.time_step_limit(params)]
