"""A channel with an inflow and an outflow (:mod:`sphjax.physics.open_boundary`)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from sphjax._text import show
from sphjax.cases._geometry import check_positive, check_resolution, lattice, wall_layers
from sphjax.cases._systems import finish_case, fluid_system, wall_system
from sphjax.core.case import Case
from sphjax.core.kernels import as_kernel
from sphjax.core.model import Domain, Model
from sphjax.core.params import make_params
from sphjax.core.state import Kind, make_state
from sphjax.physics.open_boundary import PROFILES, Inflow, OpenBoundarySystem, Outflow

#: room beyond the outflow buffer's end, in spacings, for outflow particles waiting to be
#: recycled (:meth:`OpenBoundarySystem.transfer`)
EXIT_ROOM = 8


def channel_flow(
    n: int = 20,
    length: float = 3.0,
    height: float = 1.0,
    inflow_velocity: float = 1.0,
    reynolds: float = 10.0,
    profile: str = "parabolic",
    initial_profile: str | None = None,
    sound_speed_factor: float = 10.0,
    outflow_pressure_factor: float = 0.003,
    buffer_width: float | None = None,
    density: str = "summation",
    kernel="quintic_spline",
    t_end: float | None = None,
) -> Case:
    """2D channel flow between no-slip walls with an inflow and an outflow.

    Fluid enters at ``x = 0`` with the mean speed ``U = inflow_velocity`` (a ``"uniform"``
    or ``"parabolic"`` profile, :class:`~sphjax.physics.open_boundary.Inflow`) and leaves
    at ``x = length``; walls at ``y = 0`` and ``y = H``.  Downstream of the entrance
    length the flow is plane Poiseuille flow, ``u(y) = 4 u_max y (H - y) / H^2`` with
    ``u_max = 1.5 U`` (:func:`sphjax.observables.poiseuille_profile`).  The buffers'
    particles start with the inflow's profile ``u_in(y)``, the fluid's with
    ``initial_profile`` (default the inflow's); ``nu = U H / reynolds``,
    ``c0 = sound_speed_factor * u_max``, ``rho0 = 1000``.  Fluid as the Poiseuille case's:
    quintic spline, ``h = dx``, summation density (or ``density="continuity"``), Tait
    with ``gamma = 1``, Morris viscosity, Adami walls.  The parabolic inflow is the
    validated one (docs/validation_open_boundary.md); a uniform inflow runs, its mass
    flux right, but its profile downstream is 3 % of u_max off at n = 20.

    Args:
      n: particles across the channel (``dx = H / n``).
      length: the channel's length between the planes, in channel heights.
      initial_profile: the fluid's initial velocity profile, ``"uniform"`` (a plug of
        speed ``U``: away from the ends it develops as plane Poiseuille flow started at
        a constant flow rate, :func:`sphjax.observables.channel_startup_profile`) or
        ``"parabolic"``; default ``profile``.
      outflow_pressure_factor: the outflow buffer's pressure, ``factor * rho0 c0^2``;
        the default 0.003 (a fifth of the pressure drop along a channel 2 H long at
        Re = 10) keeps the pressure near the outflow positive; at 0, fluid particles
        next to the walls near the outflow reached the walls' surface.
      buffer_width: each buffer's length (default: the kernel support plus one
        spacing); at least the support.
      t_end: default three flow-through times, ``3 length H / U``.
    """
    n = check_resolution("n", n, 4)
    H = check_positive("height", height)
    U = float(inflow_velocity) if _is_number(inflow_velocity) else math.nan
    if not (U > 0 and math.isfinite(U)):
        raise ValueError(
            f"inflow_velocity must be a positive number (the mean speed along +x at which "
            f"fluid enters at x = 0), got {show(inflow_velocity)}; for a flow towards -x "
            "mirror the set-up"
        )
    Re = check_positive("reynolds", reynolds)
    for name, value in (("profile", profile), ("initial_profile", initial_profile)):
        if value not in PROFILES and not (name == "initial_profile" and value is None):
            raise ValueError(f"{name} must be 'uniform' or 'parabolic', got {value!r}")
    dx = H / n
    kernel = as_kernel(kernel)
    h = dx
    cutoff = kernel.support * h
    L = dx * max(1, round(check_positive("length", length) * H / dx))
    if buffer_width is None:
        buffer_width = cutoff + dx
    W = check_positive("buffer_width", buffer_width)
    W = dx * max(1, round(W / dx))
    if W < cutoff * (1.0 - 1e-9):
        raise ValueError(
            f"buffer_width = {show(buffer_width)} is narrower than the kernel support "
            f"{cutoff:.6g} (rounded to {W:.6g}, a whole number of spacings): give "
            f"buffer_width >= {cutoff:.6g}"
        )
    rho0 = 1000.0
    u_max = 1.5 * U
    nu = U * H / Re
    c0 = check_positive("sound_speed_factor", sound_speed_factor) * u_max
    open_system = OpenBoundarySystem(
        Inflow(plane=0.0, width=W, velocity=U, profile=profile, bottom=0.0, height=H),
        Outflow(plane=L, width=W, pressure=outflow_pressure_factor * rho0 * c0**2),
    )
    open_system.check_support(cutoff)
    layers = wall_layers(cutoff, dx)
    room = EXIT_ROOM * dx
    fluid = lattice([0.0, 0.0], [L, H], dx)
    buffers = np.concatenate([lattice([-W, 0.0], [0.0, H], dx), lattice([L, 0.0], [L + W, H], dx)])
    wall_x = (-W, L + W + room)
    walls = np.concatenate(
        [
            lattice([wall_x[0], -layers * dx], [wall_x[1], 0.0], dx),
            lattice([wall_x[0], H], [wall_x[1], H + layers * dx], dx),
        ]
    )
    x = np.concatenate([fluid, walls, buffers])
    kind = np.concatenate(
        [
            np.full(len(fluid), Kind.FLUID),
            np.full(len(walls), Kind.WALL),
            np.full(len(buffers), Kind.OPEN),
        ]
    )
    start = dataclasses.replace(open_system.inflow, profile=initial_profile or profile)
    u = np.where(kind == Kind.OPEN, open_system.inflow.velocity_at(x[:, 1]), 0.0)
    u = np.where(kind == Kind.FLUID, start.velocity_at(x[:, 1]), u)
    velocity = np.zeros_like(x)
    velocity[:, 0] = u
    params = make_params(2, reference_density=rho0, sound_speed=c0, kinematic_viscosity=nu)
    margin = (layers + 2) * dx
    model = Model(
        dim=2,
        smoothing_length=h,
        kernel=kernel,
        domain=Domain((-W - margin, -margin), (L + W + room + margin, H + margin), (False, False)),
        systems=(
            fluid_system(density=density, gamma=1.0, physical_viscosity=True),
            wall_system("no_slip"),
            open_system,
        ),
    )
    # every particle at the outflow's pressure (eq. 12 inverted), the masses those of the
    # lattice at that density, so that the run starts without a pressure jump at the outflow
    rho_start = rho0 * (1.0 + outflow_pressure_factor)  # Tait, gamma = 1
    state = make_state(x, velocity, rho_start, rho_start * dx**2, kind)
    flow_through = L / U
    info = dict(
        dx=dx,
        n=n,
        height=H,
        length=L,
        inflow_velocity=U,
        peak_velocity=u_max,
        reynolds=Re,
        viscosity=nu,
        profile=profile,
        initial_profile=initial_profile or profile,
        buffer_width=W,
        inflow_plane=0.0,
        outflow_plane=L,
        flow_through_time=flow_through,
        mass_flux=rho_start * U * H,
    )
    t_end = 3.0 * flow_through if t_end is None else t_end
    return finish_case("channel_flow", state, model, params, t_end, info)


def _is_number(value) -> bool:
    try:
        float(value)
    except (TypeError, ValueError):
        return False
    return True
