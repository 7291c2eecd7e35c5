"""Set-ups with a rigid body (:class:`~sphjax.physics.rigid.system.RigidSystem`)."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from sphjax.cases._geometry import (
    box_walls,
    check_positive,
    check_resolution,
    lattice,
    wall_layers,
)
from sphjax.cases._systems import finish_case, fluid_system, wall_system
from sphjax.core.case import Case
from sphjax.core.kernels import WendlandC2
from sphjax.core.model import Domain, Model
from sphjax.core.params import make_params
from sphjax.core.state import Kind, make_state
from sphjax.physics.fluid.eos import tait_density
from sphjax.physics.rigid.contact import WallContact
from sphjax.physics.rigid.system import RigidSystem
from sphjax.physics.solid.boundary import SolidBoundary

WATER_DENSITY = 1000.0
GAMMA = 7.0


def _body_in_tank(h, kernel, domain, rigid, **viscosity) -> Model:
    """The Model of a rigid body in a walled tank of water, shared by the cases below:
    continuity density with Molteni's diffusion, Tait (eqs. 11-12), no-slip walls, the
    fluid's viscosity as given (``artificial_viscosity=True`` or
    ``physical_viscosity=True``)."""
    fluid = fluid_system(
        density="continuity", gamma=GAMMA, density_diffusion="molteni", **viscosity
    )
    systems = (fluid, wall_system("no_slip"), rigid)
    return Model(dim=2, smoothing_length=h, kernel=kernel, domain=domain, systems=systems)


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
    hb = check_positive("body_height", body_height)
    ratio = check_positive("density_ratio", density_ratio)
    if not ratio < 1.0:
        raise ValueError(
            f"density_ratio must be below 1 for the body to float, got {ratio}; for a body "
            "that sinks use sphjax.cases.sinking_body"
        )
    if not 0.0 < initial_draught < 1.0:
        raise ValueError(
            f"initial_draught must lie in (0, 1) (of the height), got {initial_draught}"
        )
    dx = hb / n
    D = check_positive("water_depth", water_depth)
    rows, rows_under = round(D / dx), max(1, round(initial_draught * hb / dx))
    tank = _BodyInTank(
        n, body_width, hb, ratio, rows - rows_under, water_depth, tank_width, gravity
    )
    draught = ratio * tank.body_height
    d0 = dx * rows_under
    w, W, D = tank.body_width, tank.tank_width, tank.water_depth
    info = dict(
        equilibrium_draught=draught,
        equilibrium_bottom=D + w * (draught - d0) / W - draught,
        heave_period=2 * math.pi * math.sqrt(draught / tank.gravity),
    )
    return tank.case(
        "floating_body",
        RigidSystem(SolidBoundary(no_slip=True)),
        sound_speed_factor,
        artificial_alpha,
        t_end,
        info,
    )


def sinking_body(
    n: int = 8,
    body_width: float = 0.2,
    body_height: float = 0.1,
    density_ratio: float = 1.5,
    release_height: float = 0.05,
    water_depth: float = 0.3,
    tank_width: float = 1.0,
    gravity: float = 9.81,
    sound_speed_factor: float = 20.0,
    artificial_alpha: float = 0.1,
    contact_frequency: float | None = None,
    contact_damping_ratio: float = 1.0,
    contact_friction: float = 0.5,
    t_end: float = 1.5,
) -> Case:
    """A rectangular rigid body denser than water released in a tank: it sinks and comes
    to rest on the floor (2D).

    The body (``body_width x body_height``, density ``density_ratio`` times the water's,
    ``Params.solid_density``) starts at rest, level, at the centre of the tank, its bottom
    ``release_height`` above the floor, under water ``water_depth`` deep (hydrostatic).
    The fluid and the body are the floating body's (:func:`floating_body`); the body has
    wall contact (:class:`~sphjax.WallContact`, a spring-dashpot force between its
    particles and the wall particles within 1.5 spacings, critically damped), so it comes
    to rest with its bottom less than half a spacing above the floor.  The contact's
    frequency, damping ratio and friction are the Params fields ``contact_frequency``,
    ``contact_damping_ratio`` and ``contact_friction`` (differentiable); the arguments
    below set their values in ``case.params``.

    Args:
      n: particles across the body's height (``dx = body_height / n``).
      release_height: the height of the body's bottom above the floor at the start.
      contact_frequency: the contact's ``omega`` (rad/s); ``None``:
        ``sqrt(100 g body_height) / dx``, which compresses the contact springs under the
        body's weight by about ``dx / 100``.
      contact_damping_ratio: the contact dashpots' fraction ``zeta`` of critical damping.
      contact_friction: the contact's Coulomb coefficient ``mu``.
    """
    n = check_resolution("n", n, 4)
    hb = check_positive("body_height", body_height)
    ratio = check_positive("density_ratio", density_ratio)
    if not ratio > 1.0:
        raise ValueError(
            f"density_ratio must exceed 1 for the body to sink, got {ratio}; for a body "
            "that floats use sphjax.cases.floating_body"
        )
    dx = hb / n
    lift = check_positive("release_height", release_height)
    D = check_positive("water_depth", water_depth)
    rows_up = max(1, round(lift / dx))
    if not rows_up * dx + hb < D:
        raise ValueError(
            f"release_height + body_height = {rows_up * dx + hb:g} must lie below "
            f"water_depth = {D:g} (the body starts under water); lower release_height"
        )
    g = check_positive("gravity", gravity)
    if contact_frequency is None:
        contact_frequency = math.sqrt(100.0 * g * hb) / dx
    contact = WallContact()
    values = dict(
        contact_frequency=check_positive("contact_frequency", contact_frequency),
        contact_damping_ratio=contact_damping_ratio,
        contact_friction=contact_friction,
    )
    tank = _BodyInTank(n, body_width, hb, ratio, rows_up, water_depth, tank_width, gravity)
    return tank.case(
        "sinking_body",
        RigidSystem(SolidBoundary(no_slip=True), wall_contact=contact),
        sound_speed_factor,
        artificial_alpha,
        t_end,
        dict(
            contact_frequency=values["contact_frequency"],
            contact_distance=contact.distance * dx,
        ),
        values,
    )


class _BodyInTank:
    """The geometry of a rectangular body in an open tank of water, on one lattice: the
    body ``bottom_rows`` spacings above the floor, centred; the water cut out where the
    body is."""

    def __init__(self, n, body_width, body_height, ratio, bottom_rows, depth, width, gravity):
        w = check_positive("body_width", body_width)
        D = check_positive("water_depth", depth)
        W = check_positive("tank_width", width)
        self.gravity = check_positive("gravity", gravity)
        self.n, self.ratio, self.body_height = n, ratio, body_height
        self.dx = dx = body_height / n
        self.body_width = w = max(1, round(w / dx)) * dx
        self.tank_width = W = dx * round(W / dx)
        self.water_depth = D = dx * round(D / dx)
        self.x0 = x0 = dx * round((W - w) / (2 * dx))  # the body's left face, on the lattice
        self.y0 = y0 = dx * bottom_rows  # its bottom, on the lattice
        hb = body_height
        water = lattice([0.0, 0.0], [W, D], dx)
        inside = (
            (water[:, 0] > x0)
            & (water[:, 0] < x0 + w)
            & (water[:, 1] > y0)
            & (water[:, 1] < y0 + hb)
        )
        self.fluid = water[~inside]
        self.body = lattice([x0, y0], [x0 + w, y0 + hb], dx)

    def case(
        self, name, rigid, sound_speed_factor, artificial_alpha, t_end, info, values=None
    ) -> Case:
        """The Case: fluid, tank walls and ``rigid`` (a :class:`RigidSystem`); ``values``:
        more Params fields (the wall contact's)."""
        dx, g, D, W = self.dx, self.gravity, self.water_depth, self.tank_width
        hb, fluid, body = self.body_height, self.fluid, self.body
        kernel, h = WendlandC2(), 1.5 * dx
        layers = wall_layers(kernel.support * h, dx)
        tank_height = max(1.5 * D, self.y0 + 2 * hb)
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
            solid_density=self.ratio * WATER_DENSITY,
            **(values or {}),
        )
        cell = dx * dx

        def initial_state(p):
            """Hydrostatic water (eq. 12 inverted), masses ``rho0 dx^2``; the body's
            particles at its density ``p.solid_density``."""
            rho0 = p.reference_density
            rho_f = tait_density(rho0 * (-p.gravity[-1]) * depth, rho0, p.sound_speed, GAMMA)
            rho = jnp.where(is_body, p.solid_density, jnp.where(is_fluid, rho_f, rho0))
            mass = jnp.where(is_body, p.solid_density, rho0) * cell
            return make_state(x, 0.0, rho, mass, kind, volume=cell)

        margin = (layers + 2) * dx
        domain = Domain(
            (-margin, -margin), (W + margin, 2.0 * tank_height + margin), (False, False)
        )
        model = _body_in_tank(h, kernel, domain, rigid, artificial_viscosity=True)
        info = dict(
            n=self.n,
            dx=dx,
            body_width=self.body_width,
            body_height=hb,
            water_depth=D,
            tank_width=W,
            initial_bottom=self.y0,
            body_indices=tuple(int(i) for i in np.flatnonzero(kind == Kind.RIGID)),
            **info,
        )
        return finish_case(
            name, initial_state(params), model, params, t_end, info, initial_state=initial_state
        )


def body_bottom(states, case: Case):
    """The height of the body's bottom face: its centre of mass (of the particles, all of
    one mass) less half its height; ``[T]`` for a trajectory's states."""
    position = jnp.asarray(getattr(states, "position", states))
    idx = jnp.asarray(case.info["body_indices"])
    return jnp.mean(position[..., idx, 1], axis=-1) - 0.5 * case.info["body_height"]


#: The largest Reynolds number of the settling disk, Wang, Fan & Luo (2008), Int. J.
#: Multiphase Flow 34, section 3.1 (the set-up of Glowinski et al. 2001), for rho_s / rho_f
#: = 1.25 and mu = 0.1 g/(cm s): "Re_max ≈ 17", as quoted (two significant figures) in
#: scenarios/sedimentation.py of github.com/mulgae-life/iblbm-mechanism-resolved (H. Jo,
#: Physics of Fluids 2026), whose comparison with it takes the Reynolds number on the
#: disk's density, ``Re = rho_s |V| d / mu`` (its "particle basis",
#: monitor/sedimentation.py)
SETTLING_DISK_REYNOLDS = 17.0


def settling_disk(
    n: int = 10,
    diameter: float = 0.25,
    channel_width: float = 2.0,
    channel_height: float = 6.0,
    release_height: float = 4.0,
    density_ratio: float = 1.25,
    fluid_density: float = 1.0,
    kinematic_viscosity: float = 0.1,
    gravity: float = 980.0,
    sound_speed: float | None = None,
    t_end: float = 0.6,
) -> Case:
    """A circular disk denser than the fluid settling in a closed vertical channel (2D),
    the sedimentation benchmark of Glowinski and co-authors (2001) and Wang, Fan & Luo
    (2008), in CGS units.

    A disk of diameter ``d = 0.25`` cm and density ``density_ratio`` times the fluid's
    (``Params.solid_density``) starts at rest on the centre line of a channel 2 cm wide
    and 6 cm high, its centre ``release_height`` above the floor, in a fluid at rest of
    density 1 g/cm^3 and kinematic viscosity 0.1 cm^2/s, under ``g = 980`` cm/s^2.  It
    accelerates and settles at a nearly constant speed; with the defaults the reference
    gives a largest Reynolds number of about 17 (:data:`SETTLING_DISK_REYNOLDS`), on the
    disk's density, ``Re = rho_s |V| d / mu``: a largest speed
    ``info["reference_speed"] = Re mu / (rho_s d) = 5.44`` cm/s.

    The fluid: Wendland C2, ``h = 1.5 dx``, continuity density with delta-SPH, Tait
    (``gamma = 7``), Morris's laminar viscosity (``Params.kinematic_viscosity``), no
    artificial viscosity; the channel's walls (Adami) and the disk no-slip.  The fluid
    carries no gravity and no hydrostatic pressure: the disk is given its weight less its
    buoyancy, ``(1 - rho_f / rho_s) g`` (``RigidSystem(buoyant_gravity=...)``), which for
    an incompressible fluid is the same problem, so that the sound speed need only exceed
    the flow's speeds (``c0 = sound_speed``, default ``20 Re nu / d = 136`` cm/s, 25 times
    the reference's speed: with half that the disk settled 5-8 % faster,
    docs/validation_rigid.md) and not ``sqrt(g H)``.

    The disk is the particles of the fluid's lattice (``dx = d / n``, the channel's
    centre line on a lattice line) whose centres lie inside the circle, the fluid the
    rest: one lattice, no gaps or overlaps between the disk and the fluid, so that the
    fluid sees a boundary as regular as the walls (concentric rings would fit the circle
    better but leave the fluid next to the disk unevenly spaced).  The disk's centre is
    on a lattice line or half way between two, whichever gives the particles an area
    closer to the circle's; its mass and area are its particles' (``info["body_area"]``
    against ``pi d^2 / 4``: within 1.3 % for ``n`` = 7, 10, 14).

    Args:
      n: particles across the disk's diameter (``dx = diameter / n``; at least 4).
      release_height: the height of the disk's centre above the floor at the start.
      sound_speed: ``c0``; ``None``: ``20 Re nu / d`` (136 cm/s with the defaults).
    """
    n = check_resolution("n", n, 4)
    d = check_positive("diameter", diameter)
    W = check_positive("channel_width", channel_width)
    H = check_positive("channel_height", channel_height)
    y0 = check_positive("release_height", release_height)
    ratio = check_positive("density_ratio", density_ratio)
    if not ratio > 1.0:
        raise ValueError(
            f"density_ratio must exceed 1 for the disk to settle, got {ratio}; for a body "
            "that floats use sphjax.cases.floating_body"
        )
    rho_f = check_positive("fluid_density", fluid_density)
    nu = check_positive("kinematic_viscosity", kinematic_viscosity)
    g = check_positive("gravity", gravity)
    dx = d / n
    W, H = dx * round(W / dx), dx * round(H / dx)
    if not d < W:
        raise ValueError(f"diameter = {d:g} must be below channel_width = {W:g}")
    if not d / 2 < y0 < H - d / 2:
        raise ValueError(
            f"release_height must put the disk inside the channel: between {d / 2:g} and "
            f"{H - d / 2:g}, got {y0:g}"
        )
    # the centre on the centre line, a lattice line; vertically on a lattice line or half
    # way between two, whichever puts the area of the particles inside the circle closer
    # to the circle's (within 1.3 % for n = 7, 10, 14; 3.5 % at worst for n >= 8)
    points = lattice([0.0, 0.0], [W, H], dx)
    x_c = dx * round(W / (2 * dx))
    candidates = []
    for y_c in (dx * round(y0 / dx), dx * (math.floor(y0 / dx) + 0.5)):
        inside = np.linalg.norm(points - np.array([x_c, y_c]), axis=-1) < d / 2
        error = abs(int(inside.sum()) * dx * dx - math.pi * d * d / 4)
        candidates.append((error, y_c, inside))
    _, y_c, inside = min(candidates, key=lambda c: c[0])
    centre = np.array([x_c, y_c])
    fluid, body = points[~inside], points[inside]
    reference_speed = SETTLING_DISK_REYNOLDS * nu / (ratio * d)
    c0 = 20.0 * SETTLING_DISK_REYNOLDS * nu / d if sound_speed is None else sound_speed
    c0 = check_positive("sound_speed", c0)

    kernel, h = WendlandC2(), 1.5 * dx
    layers = wall_layers(kernel.support * h, dx)
    walls = box_walls([0.0, 0.0], [W, H], dx, layers)
    x = np.concatenate([fluid, walls, body])
    kind = np.concatenate(
        [
            np.full(len(fluid), Kind.FLUID),
            np.full(len(walls), Kind.WALL),
            np.full(len(body), Kind.RIGID),
        ]
    ).astype(np.int32)
    is_body = jnp.asarray(kind == Kind.RIGID)
    params = make_params(
        2,
        gravity=(0.0, 0.0),
        reference_density=rho_f,
        sound_speed=c0,
        kinematic_viscosity=nu,
        solid_density=ratio * rho_f,
    )
    cell = dx * dx

    def initial_state(p):
        """The fluid at rest at its reference density (no hydrostatic pressure), masses
        ``rho_f dx^2``; the disk's particles at its density ``p.solid_density``."""
        rho0 = p.reference_density
        rho = jnp.where(is_body, p.solid_density, rho0) * jnp.ones(len(x))
        mass = rho * cell
        return make_state(x, 0.0, rho, mass, kind, volume=cell)

    margin = (layers + 2) * dx
    domain = Domain((-margin, -margin), (W + margin, H + margin), (False, False))
    rigid = RigidSystem(SolidBoundary(no_slip=True), buoyant_gravity=(0.0, -g))
    model = _body_in_tank(h, kernel, domain, rigid, physical_viscosity=True)
    info = dict(
        n=n,
        dx=dx,
        diameter=d,
        channel_width=W,
        channel_height=H,
        initial_centre=tuple(float(c) for c in centre),
        body_area=float(len(body) * cell),
        kinematic_viscosity=nu,
        density_ratio=ratio,
        reference_reynolds=SETTLING_DISK_REYNOLDS,
        reference_speed=reference_speed,
        body_indices=tuple(int(i) for i in np.flatnonzero(kind == Kind.RIGID)),
    )
    return finish_case(
        "settling_disk",
        initial_state(params),
        model,
        params,
        t_end,
        info,
        initial_state=initial_state,
    )


def body_velocity(states, case: Case):
    """The velocity of the body's centre of mass (its particles, all of one mass):
    ``[..., 2]``, ``[T, 2]`` for a trajectory's states."""
    velocity = jnp.asarray(getattr(states, "velocity", states))
    return jnp.mean(velocity[..., jnp.asarray(case.info["body_indices"]), :], axis=-2)
