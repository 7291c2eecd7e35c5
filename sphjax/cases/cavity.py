"""The lid-driven square cavity (Ghia, Ghia & Shin 1982; in SPH Adami, Hu & Adams 2013)."""

from __future__ import annotations

import numpy as np

from sphjax.cases._geometry import box_walls, check_positive, check_resolution, lattice, wall_layers
from sphjax.cases._systems import finish_case as _finish
from sphjax.cases._systems import fluid_system, wall_system
from sphjax.core.case import Case
from sphjax.core.kernels import as_kernel
from sphjax.core.model import Domain, Model
from sphjax.core.params import make_params
from sphjax.core.state import Kind, make_state


def lid_driven_cavity(
    n: int = 40,
    reynolds: float = 100.0,
    lid_speed: float = 1.0,
    length: float = 1.0,
    sound_speed_factor: float = 10.0,
    kernel="quintic_spline",
    h_factor: float = 1.0,
    transport_velocity: bool = True,
    t_end: float = 10.0,
) -> Case:
    """A square cavity ``[0, L]^2`` of fluid at rest whose lid (``y = L``) slides at ``U``.

    Ghia, Ghia & Shin (1982) give the steady centreline velocities (Tables I and II, see
    :func:`sphjax.observables.centreline_profiles`); the SPH set-up is that of Adami, Hu &
    Adams (2013): ``nu = U L / Re`` through the physical (Morris) viscosity, ``rho0 = 1``,
    ``c0 = sound_speed_factor * U`` (10 U), the linear equation of state (``gamma = 1``),
    summation density, the quintic spline with ``h = h_factor dx`` and the
    transport-velocity formulation with ``p_b = rho0 c0^2``.  The walls are no-slip Adami
    dummy particles, as many layers as the kernel support; the lid is the wall particles
    above ``y = L`` (corners included), which stay where they are and carry the velocity
    ``(U, 0)`` that the no-slip viscous terms see (a conveyor belt: walls never drift, see
    :class:`sphjax.WallSystem`).  The fluid starts on the square lattice at rest.

    ``t_end = 10 L / U`` by default: at Re 100 the centreline profiles have settled by
    then (docs/validation_fluid.md gives the measured change per unit time).

    Args:
      n: particles per side of the cavity (``dx = L / n``).
      reynolds: ``Re = U L / nu``.
      lid_speed: ``U``.
      length: the side ``L``.
      transport_velocity: advect with the transport velocity (Adami et al. 2013).
    """
    n = check_resolution("n", n, 4)
    reynolds = check_positive("reynolds", reynolds)
    U = check_positive("lid_speed", lid_speed)
    L = check_positive("length", length)
    check_positive("t_end", t_end)
    dx = L / n
    kernel = as_kernel(kernel)
    h = check_positive("h_factor", h_factor) * dx
    layers = wall_layers(kernel.support * h, dx)
    fluid = lattice([0.0, 0.0], [L, L], dx)
    walls = box_walls([0.0, 0.0], [L, L], dx, layers)
    x = np.concatenate([fluid, walls])
    kind = np.concatenate([np.full(len(fluid), Kind.FLUID), np.full(len(walls), Kind.WALL)])
    lid = (kind == Kind.WALL) & (x[:, 1] > L)
    velocity = np.zeros_like(x)
    velocity[lid, 0] = U
    rho0, nu, c0 = 1.0, U * L / reynolds, sound_speed_factor * U
    params = make_params(2, reference_density=rho0, sound_speed=c0, kinematic_viscosity=nu)
    margin = (layers + 2) * dx
    model = Model(
        dim=2,
        smoothing_length=h,
        kernel=kernel,
        domain=Domain((-margin, -margin), (L + margin, L + margin), (False, False)),
        systems=(
            fluid_system(
                density="summation",
                gamma=1.0,
                physical_viscosity=True,
                transport_velocity=transport_velocity,
            ),
            wall_system("no_slip"),
        ),
    )

    def initial_state(p):
        """At rest at ``rho0`` from ``p``, masses ``rho0 dx^2``; the lid at ``U``."""
        rho = p.reference_density
        return make_state(x, velocity, rho, rho * dx**2, kind)

    info = dict(
        dx=dx,
        n=n,
        length=L,
        lid_speed=U,
        reynolds=reynolds,
        viscosity=nu,
        lid_indices=np.flatnonzero(lid),
    )
    return _finish(
        "lid_driven_cavity",
        initial_state(params),
        model,
        params,
        t_end,
        info,
        initial_state=initial_state,
    )


__all__ = ["lid_driven_cavity"]
