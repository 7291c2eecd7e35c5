"""Fluid validation cases: Taylor-Green, Poiseuille, hydrostatic tank, dam break (Martin &
Moyce's surge, and Zhou et al.'s and Buchner's impact on a wall with pressure sensors)."""

from __future__ import annotations

import functools
import math
import numbers
from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from sphjax._host import device_array
from sphjax._text import show
from sphjax.cases._geometry import box_walls, check_positive, check_resolution, lattice, wall_layers
from sphjax.cases._packing import periodic_neighbours, relax_periodic, summation_masses
from sphjax.cases._systems import finish_case as _finish
from sphjax.cases._systems import fluid_system, wall_system
from sphjax.core.case import Case
from sphjax.core.kernels import QuinticSpline, WendlandC2, as_kernel
from sphjax.core.model import Domain, Model
from sphjax.core.params import make_params
from sphjax.core.state import Kind, make_state
from sphjax.physics.fluid.eos import tait_density

#: ``Model.pair_block`` of the Taylor-Green case: without walls and with summation density
#: the pair sums' adjoints fuse when they run unblocked (reverse mode 18.5 -> 15.5 CPU-s at
#: 10k particles, 41.9 -> 35.1 at 20k; the dam break, with walls, is slower so: 7.1 -> 10-12)
TAYLOR_GREEN_PAIR_BLOCK = 32768


def _relax_iterations(value) -> int:
    """``relax_iterations`` as an int; a ValueError naming it unless it is a whole number >= 0."""
    try:
        whole = int(value) == value and value >= 0
    except (TypeError, ValueError, OverflowError):
        whole = False
    if not whole:
        raise ValueError(
            f"relax_iterations must be a whole number >= 0 (0: no packing), got {show(value)}"
        )
    return int(value)


def taylor_green(
    n: int = 50,
    reynolds: float = 100.0,
    speed: float = 1.0,
    sound_speed_factor: float = 10.0,
    kernel="quintic_spline",
    h_factor: float = 1.2,
    density: str = "summation",
    reference_pressure_factor: float = 0.0,
    density_diffusion: str | None = None,
    artificial_alpha: float = 0.0,
    transport_velocity: bool = True,
    transport_pressure_factor: float = 1.0,
    gamma: float = 1.0,
    disorder: float = 0.45,
    seed: int = 0,
    relax_iterations: int = 1000,
    t_end: float = 1.0,
) -> Case:
    """2D periodic Taylor-Green vortex on ``[0, 1]^2`` (Taylor & Green 1937).

    ``u = -U cos(2 pi x) sin(2 pi y)``, ``v = U sin(2 pi x) cos(2 pi y)``,
    ``p = -(rho0 U^2 / 4)(cos 4 pi x + cos 4 pi y)``, ``nu = U / Re``, ``c0 = 10 U``.
    Kinetic energy decays as ``exp(-16 pi^2 nu t)``.

    Defaults: quintic spline with ``h = 1.2 dx``, summation density, linear equation of
    state, the transport-velocity formulation (Adami et al. 2013, ``p_b = rho0 c0^2``).

    The start is the relaxed one of Adami et al. (2013): the square lattice displaced by
    up to ``disorder * dx`` (seeded), relaxed for ``relax_iterations`` pseudo-time steps
    under a uniform background pressure (:mod:`sphjax.cases._packing`), then given the
    analytic velocity at the relaxed positions, the density of the analytic pressure
    through the equation of state, and masses for which summation density (eq. 5) equals
    that density at every particle.  So the pressure is the analytic one from step 0 and
    no compression energy is stored.  A perfect lattice (``disorder=0``) is not a good
    start: the vortices shear it, an affinely sheared lattice feels no background-pressure
    force, and its rows collapse into lines after ``t ~ 0.1`` (docs/design.md).
    ``relax_iterations=0`` gives the unrelaxed disordered start with lattice masses
    ``rho0 dx^2`` (the start of earlier versions, with ``disorder=0.3``).

    The initial density and masses follow ``params.sound_speed``,
    ``params.reference_density`` and ``params.reference_pressure``
    (``case.state_for(params)``; ``simulate(case, params)`` uses it), and so does the
    transport-velocity background pressure ``p_b = transport_pressure_factor * rho0 c0^2``
    (:class:`~sphjax.TransportVelocity` evaluates it from Params).  The reference pressure
    ``p0 = reference_pressure_factor * rho0 c0^2`` is computed once, when the case is
    built, and stored as ``Params.reference_pressure``: after ``replace(sound_speed=...)``
    set ``reference_pressure`` too if it should scale with ``c0^2``.

    Args:
      n: particles per side (``dx = 1 / n``).
      reference_pressure_factor: ``p0 = factor * rho0 c0^2`` added to the pressure (at
        build time).
      transport_pressure_factor: the transport-velocity background pressure
        ``p_b = factor * rho0 c0^2``, evaluated from Params in every step.
      disorder: largest random displacement from the lattice, in units of ``dx``.
      seed: seed of that displacement.
      relax_iterations: pseudo-time steps of the packing (0: none).
    """
    n = check_resolution("n", n, 4)
    check_positive("reynolds", reynolds)
    check_positive("speed", speed)
    if not 0.0 <= disorder < 0.5:
        raise ValueError(f"disorder must lie in [0, 0.5) (units of dx), got {disorder}")
    relax_iterations = _relax_iterations(relax_iterations)
    dx = 1.0 / n
    kernel = as_kernel(kernel)
    h = h_factor * dx
    x = lattice([0.0, 0.0], [1.0, 1.0], dx)
    rng = np.random.default_rng(seed)
    x = np.mod(x + disorder * dx * rng.uniform(-1.0, 1.0, x.shape), 1.0)
    relaxed = relax_iterations > 0
    if relaxed:
        x, _ = relax_periodic(x, 1.0, kernel, h, int(relax_iterations))
        neighbours = periodic_neighbours(x, 1.0, kernel.support * h)
    U, nu, rho0 = speed, speed / reynolds, 1.0
    c0 = sound_speed_factor * U
    X, Y = x[:, 0], x[:, 1]
    u = np.stack(
        [
            -U * np.cos(2 * np.pi * X) * np.sin(2 * np.pi * Y),
            U * np.sin(2 * np.pi * X) * np.cos(2 * np.pi * Y),
        ],
        axis=-1,
    )
    pressure_shape = -0.25 * U**2 * (np.cos(4 * np.pi * X) + np.cos(4 * np.pi * Y))
    p0 = reference_pressure_factor * rho0 * c0**2
    gamma = float(gamma)
    params = make_params(
        2,
        reference_density=rho0,
        sound_speed=c0,
        kinematic_viscosity=nu,
        reference_pressure=p0,
        artificial_alpha=artificial_alpha,
    )

    def initial_state(p):
        """Density of the analytic pressure (eq. 12 inverted) and masses from ``p``."""
        # device arrays, not numpy: a jitted function hands an argument it returns
        # unchanged back as it came (the positions, under jax.grad)
        return _taylor_green_state(
            p,
            device_array(x),
            device_array(u),
            device_array(pressure_shape),
            device_array(neighbours) if relaxed else None,
            kernel=kernel,
            h=float(h),
            dx=float(dx),
            gamma=gamma,
        )

    model = Model(
        dim=2,
        smoothing_length=h,
        kernel=kernel,
        domain=Domain((0.0, 0.0), (1.0, 1.0), (True, True)),
        systems=(
            fluid_system(
                density=density,
                gamma=gamma,
                artificial_viscosity=artificial_alpha > 0,
                physical_viscosity=True,
                density_diffusion=density_diffusion,
                transport_velocity=transport_velocity,
                transport_pressure_factor=transport_pressure_factor,
            ),
        ),
        pair_block=TAYLOR_GREEN_PAIR_BLOCK,
    )
    state = initial_state(params)
    info = dict(
        dx=dx,
        n=n,
        speed=U,
        viscosity=nu,
        reynolds=reynolds,
        decay_rate=-8 * np.pi**2 * nu,
        relax_iterations=int(relax_iterations),
    )
    return _finish("taylor_green", state, model, params, t_end, info, initial_state=initial_state)


@functools.partial(jax.jit, static_argnames=("kernel", "h", "dx", "gamma"))
def _taylor_green_state(p, x, u, pressure_shape, neighbours, *, kernel, h, dx, gamma):
    """The Taylor-Green State for Params ``p`` (one compiled program; the geometry comes
    in as arguments): the density of the analytic pressure ``rho0 * pressure_shape``
    (eq. 12 inverted) and, with ``neighbours`` (the relaxed start), the masses for which
    summation density gives it (eq. 5), else ``rho0 dx^2``."""
    rho0_p, p0_p = p.reference_density, p.reference_pressure
    pressure = rho0_p * pressure_shape
    rho = tait_density(pressure + p0_p, rho0_p, p.sound_speed, gamma, p0_p)
    if neighbours is not None:
        mass = summation_masses(x, neighbours, 1.0, kernel, h, rho)
    else:
        mass = rho0_p * dx**2
    return make_state(x, u, rho, mass, Kind.FLUID)


def taylor_green_velocity(position, t, case: Case):
    """Analytic Taylor-Green velocity ``e^{bt} (-U cos 2 pi x sin 2 pi y, U sin 2 pi x
    cos 2 pi y)``, ``b = -8 pi^2 nu``, at ``position`` (``[..., 2]``; numpy or jax)."""
    xp = np if isinstance(position, np.ndarray) else jnp
    U, b = case.info["speed"], case.info["decay_rate"]
    X, Y = position[..., 0], position[..., 1]
    decay = xp.exp(b * xp.asarray(t))[..., None]
    return decay * xp.stack(
        [
            -U * xp.cos(2 * np.pi * X) * xp.sin(2 * np.pi * Y),
            U * xp.sin(2 * np.pi * X) * xp.cos(2 * np.pi * Y),
        ],
        axis=-1,
    )


def poiseuille(
    n: int = 20,
    width: float = 1.0e-3,
    viscosity: float = 1.0e-6,
    body_force: float = 2.0e-4,
    sound_speed_factor: float = 20.0,
    kernel="quintic_spline",
    t_end: float = 1.0,
) -> Case:
    """Body-force-driven channel between plates at ``y = 0`` and ``y = L``, periodic in x.

    Morris, Fox & Zhu (1997); steady ``u(y) = F / (2 nu) y (L - y)``, centreline
    ``F L^2 / (8 nu)``.  No-slip dummy walls (Adami et al. 2012).

    Args:
      n: particles across the channel (``dx = L / n``).
    """
    n = check_resolution("n", n, 4)
    L = check_positive("width", width)
    nu = check_positive("viscosity", viscosity)
    F = check_positive("body_force", body_force)
    dx = L / n
    kernel = as_kernel(kernel)
    h = dx
    layers = wall_layers(kernel.support * h, dx)
    length = max(L, 2.0 * (kernel.support * h) * 1.5)
    length = dx * math.ceil(length / dx)
    fluid = lattice([0.0, 0.0], [length, L], dx)
    walls = np.concatenate(
        [
            lattice([0.0, -layers * dx], [length, 0.0], dx),
            lattice([0.0, L], [length, L + layers * dx], dx),
        ]
    )
    x = np.concatenate([fluid, walls])
    kind = np.concatenate([np.full(len(fluid), Kind.FLUID), np.full(len(walls), Kind.WALL)])
    rho0 = 1000.0
    u_max = F * L**2 / (8 * nu)
    c0 = sound_speed_factor * u_max
    params = make_params(
        2, reference_density=rho0, sound_speed=c0, kinematic_viscosity=nu, gravity=(F, 0.0)
    )
    margin = (layers + 2) * dx
    model = Model(
        dim=2,
        smoothing_length=h,
        kernel=kernel,
        domain=Domain((0.0, -margin), (length, L + margin), (True, False)),
        systems=(
            fluid_system(density="summation", gamma=1.0, physical_viscosity=True),
            wall_system("no_slip"),
        ),
    )
    state = make_state(x, 0.0, rho0, rho0 * dx**2, kind)
    info = dict(
        dx=dx, n=n, width=L, viscosity=nu, body_force=F, centreline_speed=u_max, length=length
    )
    return _finish("poiseuille", state, model, params, t_end, info)


def poiseuille_startup_speed(y, t, width, viscosity, body_force, terms: int = 200):
    """Analytic start-up velocity ``u(y, t)`` of Poiseuille flow (series, Morris et al. 1997)."""
    L, nu, F = width, viscosity, body_force
    u = F / (2 * nu) * y * (L - y)
    for k in range(terms):
        m = 2 * k + 1
        u = u - 4 * F * L**2 / (nu * np.pi**3 * m**3) * np.sin(m * np.pi * y / L) * np.exp(
            -(m**2) * np.pi**2 * nu * t / L**2
        )
    return u


def _tank(
    name,
    fluid,
    tank_upper,
    dx,
    kernel,
    h,
    rho0,
    g,
    c0,
    params_kw,
    fluid_kw,
    wall_slip,
    t_end,
    info,
    fluid_height,
    obstacle=None,
):
    """A tank ``[0, tank_upper]`` (2D or 3D, open at the top, gravity along the last
    axis) of dummy walls around ``fluid``, with the hydrostatic initial density;
    ``obstacle`` (``[M, d]`` positions) adds wall particles inside the tank."""
    dim = fluid.shape[1]
    tank_upper = np.asarray(tank_upper, float)
    layers = wall_layers(kernel.support * h, dx)
    walls = box_walls([0.0] * dim, tank_upper, dx, layers, open_top=True)
    if obstacle is not None:
        walls = np.concatenate([walls, np.asarray(obstacle, float)])
    x = np.concatenate([fluid, walls])
    kind = np.concatenate([np.full(len(fluid), Kind.FLUID), np.full(len(walls), Kind.WALL)])
    # hydrostatic initial density so the column starts near equilibrium (eq. 12 inverted)
    gamma = fluid_kw.get("gamma", 7.0)
    depth = jnp.asarray(np.where(kind == Kind.FLUID, fluid_height - x[:, -1], 0.0))
    gravity = (0.0,) * (dim - 1) + (-g,)
    params = make_params(dim, reference_density=rho0, sound_speed=c0, gravity=gravity, **params_kw)

    def initial_state(p):
        """Density ``rho(p = rho0 g (H - z))`` (``z`` the last axis) and mass ``rho0 dx^d``
        from ``p`` (eq. 12)."""
        rho0_p = p.reference_density
        pressure = rho0_p * (-p.gravity[-1]) * depth
        rho = tait_density(pressure, rho0_p, p.sound_speed, gamma)
        return make_state(x, 0.0, rho, rho0_p * dx**dim, kind)

    margin = (layers + 2) * dx
    upper = tuple(float(u) + margin for u in tank_upper[:-1]) + (
        2.0 * float(tank_upper[-1]) + margin,
    )
    model = Model(
        dim=dim,
        smoothing_length=h,
        kernel=kernel,
        domain=Domain((-margin,) * dim, upper, (False,) * dim),
        systems=(fluid_system(**fluid_kw), wall_system(wall_slip)),
    )
    return _finish(
        name, initial_state(params), model, params, t_end, info, initial_state=initial_state
    )


#: density of water (kg/m^3) in the free-surface cases
WATER_DENSITY = 1000.0


def _water_tank(
    name,
    fluid,
    tank_upper,
    dx,
    gravity,
    depth,
    sound_speed_factor,
    artificial_alpha,
    density_diffusion,
    wall_slip,
    t_end,
    info,
    obstacle=None,
):
    """:func:`_tank` with the free-surface formulation of the tank and dam-break cases:
    Wendland C2 with ``h = 1.5 dx``, water (``rho0 = 1000``), ``c0 = sound_speed_factor
    sqrt(g depth)``, continuity density with ``density_diffusion`` (delta-SPH), Tait
    ``gamma = 7``, artificial viscosity ``artificial_alpha``."""
    return _tank(
        name,
        fluid,
        tank_upper,
        dx,
        WendlandC2(),
        1.5 * dx,
        WATER_DENSITY,
        gravity,
        sound_speed_factor * math.sqrt(gravity * depth),
        dict(artificial_alpha=artificial_alpha),
        dict(
            density="continuity",
            gamma=7.0,
            artificial_viscosity=True,
            density_diffusion=density_diffusion,
        ),
        wall_slip,
        t_end,
        info,
        depth,
        obstacle,
    )


def hydrostatic_tank(
    n: int = 20,
    height: float = 1.0,
    width: float = 1.0,
    gravity: float = 9.81,
    sound_speed_factor: float = 10.0,
    artificial_alpha: float = 0.1,
    density_diffusion: str | None = "molteni",
    t_end: float = 2.0,
) -> Case:
    """A water column of depth ``H`` at rest in a tank: ``p = rho0 g (H - y)``.

    Args:
      n: particles over the depth (``dx = H / n``).
      density_diffusion: ``"molteni"`` (Molteni & Colagrossi 2009 with the hydrostatic
        correction), ``"antuono"`` (Antuono et al. 2010) or ``None``.
    """
    n = check_resolution("n", n, 4)
    H = check_positive("height", height)
    W = check_positive("width", width)
    g = check_positive("gravity", gravity)
    dx = H / n
    W = dx * round(W / dx)
    fluid = lattice([0.0, 0.0], [W, H], dx)
    info = dict(dx=dx, n=n, height=H, width=W, gravity=g, bottom_pressure=WATER_DENSITY * g * H)
    return _water_tank(
        "hydrostatic_tank",
        fluid,
        (W, 1.2 * H),
        dx,
        g,
        H,
        sound_speed_factor,
        artificial_alpha,
        density_diffusion,
        "no_slip",
        t_end,
        info,
    )


def dam_break(
    n: int = 20,
    column_width: float = 0.3,
    column_height: float | None = None,
    tank_length_factor: float = 5.0,
    gravity: float = 9.81,
    sound_speed_factor: float = 20.0,
    artificial_alpha: float = 0.1,
    density_diffusion: str | None = "molteni",
    wall_slip: str = "no_slip",
    t_end: float | None = None,
) -> Case:
    """Martin & Moyce (1952) dam break: a column ``L`` wide and ``2L`` high at the left
    of a tank ``tank_length_factor * L`` long; ``c0 = 20 sqrt(g H)``.

    The surge front ``Z`` (from the left wall) is reported as ``Z / L`` against
    ``T = t sqrt(2 g / L)``; see :func:`surge_front`.  Defaults: no-slip walls and
    ``alpha = 0.1`` (the experiment had wall friction; free-slip walls with ``alpha = 0.02``
    run 12-17 % ahead of it at ``T = 2-2.3``, see docs/validation.md).

    The other common set-up, with pressure sensors on the right wall (Zhou et al. 1999,
    Buchner 2002, Colagrossi & Landrini 2003), is :func:`dam_break_impact`; its sensors'
    positions are :func:`dam_break_wall_sensors`.

    Args:
      n: particles across the column width (``dx = L / n``).
      column_height: ``H`` (default ``2 L``, Martin & Moyce's column).
    """
    n = check_resolution("n", n, 4)
    L = check_positive("column_width", column_width)
    g = check_positive("gravity", gravity)
    dx = L / n
    if column_height is None:
        H = 2.0 * L
    else:
        H = dx * max(1, round(check_positive("column_height", column_height) / dx))
    tank_length = dx * round(tank_length_factor * L / dx)
    fluid = lattice([0.0, 0.0], [L, H], dx)
    if t_end is None:
        t_end = 3.0 / math.sqrt(2 * g / L)
    info = dict(
        dx=dx,
        n=n,
        column_width=L,
        column_height=H,
        tank_length=tank_length,
        gravity=g,
        time_scale=1.0 / math.sqrt(2 * g / L),
    )
    return _water_tank(
        "dam_break",
        fluid,
        (tank_length, 1.25 * max(H, L)),
        dx,
        g,
        H,
        sound_speed_factor,
        artificial_alpha,
        density_diffusion,
        wall_slip,
        t_end,
        info,
    )


#: pressure sensors on the right wall of that dam break: name -> the sensor's centre
#: height (m), De Courcy et al. (2024), "Incompressible delta-SPH via artificial
#: compressibility", CMAME 420, 116700; their P4 is at the height of Buchner's (2002) P1
DAM_BREAK_WALL_SENSORS = {"P1": 0.006, "P2": 0.030, "P3": 0.060, "P4": 0.160}


def dam_break_impact(
    n: int = 30,
    sound_speed_factor: float = 20.0,
    density_diffusion: str | None = "molteni",
    t_end: float | None = None,
) -> Case:
    """The dam break against a wall with pressure sensors: Zhou et al. (1999), Buchner
    (2002), Colagrossi & Landrini (2003), De Courcy et al. (2024).

    A column ``2H`` wide and ``H = 0.6 m`` high at the left of a tank ``5.366 H`` long
    (3.22 m); free-slip walls and Monaghan ``alpha = 0.02``, as the reference SPH runs of
    this case use (TrixiParticles.jl, De Courcy et al.).  It
    is :func:`dam_break` with those arguments (its name is ``"dam_break"``); the surge
    hits the right wall at ``t sqrt(g / H) = 2.49`` (Buchner's sensor P1).  The sensors'
    positions are :func:`dam_break_wall_sensors`; read the wall pressure there with
    :func:`sphjax.observables.probe_pressure`.

    Args:
      n: particles across the column width ``2H`` (``dx = 2H / n``; ``H / dx = n / 2``).
      sound_speed_factor: ``c0 = sound_speed_factor sqrt(g H)``.
      density_diffusion: as :func:`dam_break`'s.
      t_end: as :func:`dam_break`'s (default ``3 sqrt(H / g)``).
    """
    sound_speed_factor = check_positive("sound_speed_factor", sound_speed_factor)
    H = 0.6
    return dam_break(
        n=n,
        column_width=2 * H,
        column_height=H,
        tank_length_factor=5.366 / 2,  # 5.366 H over the column's width 2 H
        wall_slip="free_slip",
        artificial_alpha=0.02,
        density_diffusion=density_diffusion,
        sound_speed_factor=sound_speed_factor,
        t_end=t_end,
    )


def dam_break_wall_sensors(case: Case, heights: Mapping | None = None) -> dict:
    """Positions of pressure sensors on the right wall's face of a 2D dam break
    (:func:`dam_break_impact`, :func:`dam_break`): ``(case.info["tank_length"], y)``.

    Args:
      case: the dam break.
      heights: sensor name -> height (m) above the floor; default
        :data:`DAM_BREAK_WALL_SENSORS`, De Courcy et al.'s (2024) P1-P4 at 0.006, 0.030,
        0.060 and 0.160 m (P4 at Buchner's 2002 P1).
    Returns:
      ``{name: (x, y)}``, the points to give :func:`sphjax.observables.probe_pressure`.
    """
    info = getattr(case, "info", None)
    dim = getattr(getattr(case, "model", None), "dim", None)
    if not isinstance(info, Mapping) or "tank_length" not in info or dim != 2:
        raise ValueError(
            "case must be a 2D dam break (sphjax.cases.dam_break_impact or dam_break), got "
            + show(getattr(case, "name", case))
        )
    if heights is None:
        heights = DAM_BREAK_WALL_SENSORS
    if not isinstance(heights, Mapping) or not all(
        isinstance(y, numbers.Real) and not isinstance(y, bool) and 0 <= y < math.inf
        for y in heights.values()
    ):
        raise ValueError(
            "heights must map sensor names to heights on the wall in metres (>= 0), "
            f"e.g. {DAM_BREAK_WALL_SENSORS}, got {show(heights)}"
        )
    wall = info["tank_length"]
    return {name: (wall, y) for name, y in heights.items()}


__all__ = [
    "taylor_green",
    "taylor_green_velocity",
    "poiseuille",
    "hydrostatic_tank",
    "dam_break",
    "dam_break_impact",
    "dam_break_wall_sensors",
    "DAM_BREAK_WALL_SENSORS",
    "QuinticSpline",
]
