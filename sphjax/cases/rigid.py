"""Set-ups with a rigid body (:class:`~sphjax.physics.rigid.system.RigidSystem`)."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from sphjax.cases._geometry import box_walls, check_positive, check_resolution, lattice, wall_layers
from sphjax.cases._systems import finish_case, fluid_system, wall_system
from sphjax.core.case import Case
from sphjax.core.kernels import WendlandC2
from sphjax.core.model import Domain, Model
from sphjax.core.params import make_params
from sphjax.core.state import Kind, make_state
from sphjax.physics.fluid.eos import tait_density
from sphjax.physics.rigid.system import RigidSystem
from sphjax.physics.solid.boundary import SolidBoundary

WATER_DENSITY = 1000.0
GAMMA = 7.0


def floating_body(
    n: int = 10,
    body_width: float = 0.2,
    body_height: float = 0.1,
    density_ratio: float = 0.5,
    initial_draught: float = 0.4,
    water_depth: float = 0.3,
    tank_width: float = 1.0,
    gravity: float = 9.81,
    sound_speed_factor: float = 20.0,
    artificial_alpha: float = 0.1,
    t_end: float = 2.0,
) -> Case:
    """A rectangular rigid body floating on water at rest in a tank (2D).

    The body (``body_width x body_height``, density ``density_ratio`` times the water's,
    ``Params.solid_density``) starts level at the centre of a tank ``tank_width`` wide,
    its bottom ``initial_draught * body_height`` below the still water surface at
    ``water_depth``, the water hydrostatic around it.  By Archimedes it floats at the
    draught ``d = density_ratio * body_height`` below the surface, which has risen by
    ``body_width (d - d_0) / tank_width`` as the body sank (the water's volume kept):
    ``info["equilibrium_bottom"]`` is the height of its bottom there.  The body heaves
    about it.  Fluid as the dam break's (Wendland C2, ``h = 1.5 dx``, continuity density
    with delta-SPH, Tait, ``c0 = sound_speed_factor sqrt(g depth)``), no-slip walls, the
    body a no-slip moving boundary.

    Args:
      n: particles across the body's height (``dx = body_height / n``).
      initial_draught: the body's initial draught over its height.
    """
    n = check_resolution("n", n, 4)
    w = check_positive("body_width", body_width)
    hb = check_positive("body_height", body_height)
    ratio = check_positive("density_ratio", density_ratio)
    if not ratio < 1.0:
        raise ValueError(f"density_ratio must be below 1 for the body to float, got {ratio}")
    if not 0.0 < initial_draught < 1.0:
        raise ValueError(
            f"initial_draught must lie in (0, 1) (of the height), got {initial_draught}"
        )
    D = check_positive("water_depth", water_depth)
    W = check_positive("tank_width", tank_width)
    g = check_positive("gravity", gravity)
    dx = hb / n
    nx_body = max(1, round(w / dx))
    w = nx_body * dx
    W = dx * round(W / dx)
    rows, rows_under = round(D / dx), max(1, round(initial_draught * hb / dx))
    D, d0 = dx * rows, dx * rows_under
    x0 = dx * round((W - w) / (2 * dx))  # the body's left face, on the lattice
    y0 = dx * (rows - rows_under)  # its bottom, on the lattice
    water = lattice([0.0, 0.0], [W, D], dx)
    inside = (
        (water[:, 0] > x0) & (water[:, 0] < x0 + w) & (water[:, 1] > y0) & (water[:, 1] < y0 + hb)
    )
    fluid = water[~inside]
    body = lattice([x0, y0], [x0 + w, y0 + hb], dx)
    kernel, h = WendlandC2(), 1.5 * dx
    layers = wall_layers(kernel.support * h, dx)
    tank_height = max(1.5 * D, y0 + 2 * hb)
    walls = box_walls([0.0, 0.0], [W, tank_height], dx, layers, open_top=True)
    x = np.concatenate([fluid, walls, body])
    kind = np.concatenate(
        [
            np.full(len(fluid), Kind.FLUID),
            np.full(len(walls), Kind.WALL),
            np.full(len(body), Kind.RIGID),
        ]
    ).astype(np.int32)
    is_fluid, is_body = jnp.asarray(kind == Kind.FLUID), jnp.asarray(kind == Kind.RIGID)
    depth = jnp.asarray(np.where(kind == Kind.FLUID, D - x[:, 1], 0.0))
    c0 = sound_speed_factor * math.sqrt(g * D)
    params = make_params(
        2,
        gravity=(0.0, -g),
        reference_density=WATER_DENSITY,
        sound_speed=c0,
        artificial_alpha=artificial_alpha,
        solid_density=ratio * WATER_DENSITY,
    )
    cell = dx * dx

    def initial_state(p):
        """Hydrostatic water (eq. 12 inverted), masses ``rho0 dx^2``; the body's particles
        at its density ``p.solid_density``."""
        rho0 = p.reference_density
        rho_f = tait_density(rho0 * (-p.gravity[-1]) * depth, rho0, p.sound_speed, GAMMA)
        rho = jnp.where(is_body, p.solid_density, jnp.where(is_fluid, rho_f, rho0))
        mass = jnp.where(is_body, p.solid_density, rho0) * cell
        return make_state(x, 0.0, rho, mass, kind, volume=cell)

    margin = (layers + 2) * dx
    domain = Domain((-margin, -margin), (W + margin, 2.0 * tank_height + margin), (False, False))
    model = Model(
        dim=2,
        smoothing_length=h,
        kernel=kernel,
        domain=domain,
        systems=(
            fluid_system(
                density="continuity",
                gamma=GAMMA,
                artificial_viscosity=True,
                density_diffusion="molteni",
            ),
            wall_system("no_slip"),
            RigidSystem(SolidBoundary(no_slip=True)),
        ),
    )
    draught = ratio * hb
    info = dict(
        n=n,
        dx=dx,
        body_width=w,
        body_height=hb,
        water_depth=D,
        tank_width=W,
        initial_bottom=y0,
        equilibrium_draught=draught,
        equilibrium_bottom=D + w * (draught - d0) / W - draught,
        body_indices=tuple(int(i) for i in np.flatnonzero(kind == Kind.RIGID)),
        heave_period=2 * math.pi * math.sqrt(draught / g),
    )
    return finish_case(
        "floating_body",
        initial_state(params),
        model,
        params,
        t_end,
        info,
        initial_state=initial_state,
    )


def body_bottom(states, case: Case):
    """The height of the body's bottom face: its centre of mass (of the particles, all of
    one mass) less half its height; ``[T]`` for a trajectory's states."""
    position = jnp.asarray(getattr(states, "position", states))
    idx = jnp.asarray(case.info["body_indices"])
    return jnp.mean(position[..., idx, 1], axis=-1) - 0.5 * case.info["body_height"]
