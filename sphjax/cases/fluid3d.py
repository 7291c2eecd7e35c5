"""Three-dimensional fluid cases: ABC flow, hydrostatic tank, duct flow, dam break.

* :func:`abc_flow_3d` — the decaying Arnold-Beltrami-Childress flow in a periodic cube,
  an exact Navier-Stokes solution;
* :func:`hydrostatic_tank_3d` — a water column at rest in a box, ``p = rho0 g (H - z)``;
* :func:`dam_break_3d` — the Martin & Moyce (1952) dam break with the column across the
  whole width of a box tank;
* :func:`spheric_dam_break_3d` — SPHERIC benchmark 2 (Kleefsman et al. 2005): a dam break
  onto a box obstacle, with the experiment's water-height gauges (:func:`water_height`);
* :func:`duct_poiseuille_3d` — body-force-driven flow in a square or rectangular duct with
  four no-slip walls, periodic along the flow (White's series, :func:`duct_velocity`).

The physics is the two-dimensional cases' (the systems are dimension-generic); only the
geometry differs.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from sphjax.cases._geometry import check_positive, check_resolution, lattice, wall_layers
from sphjax.cases._packing import periodic_neighbours, relax_periodic, summation_masses
from sphjax.cases._systems import fluid_system, wall_system
from sphjax.cases.fluid import WATER_DENSITY, _finish, _relax_iterations, _water_tank
from sphjax.core import kernels
from sphjax.core.case import Case
from sphjax.core.kernels import as_kernel
from sphjax.core.model import Domain, Model
from sphjax.core.params import make_params
from sphjax.core.state import Kind, make_state
from sphjax.physics.fluid.eos import tait_density

#: largest speed of the ABC field with A = B = C = U: sqrt(6) U (at sin = cos = 1/sqrt 2)
ABC_MAX_SPEED = math.sqrt(6.0)


def _abc_field(position, t, U, k, b):
    xp = np if isinstance(position, np.ndarray) else jnp
    X, Y, Z = (position[..., i] for i in range(3))
    decay = xp.exp(b * xp.asarray(t))[..., None]
    components = [
        xp.sin(k * Z) + xp.cos(k * Y),
        xp.sin(k * X) + xp.cos(k * Z),
        xp.sin(k * Y) + xp.cos(k * X),
    ]
    return decay * U * xp.stack(components, axis=-1)


def _abc_pressure_shape(position, k):
    xp = np if isinstance(position, np.ndarray) else jnp
    X, Y, Z = (position[..., i] for i in range(3))
    return (
        xp.sin(k * Z) * xp.cos(k * Y)
        + xp.sin(k * X) * xp.cos(k * Z)
        + xp.sin(k * Y) * xp.cos(k * X)
    )


def abc_velocity(position, t, case: Case):
    """Exact ABC velocity ``e^{-nu k^2 t} (A sin kz + C cos ky, B sin kx + A cos kz,
    C sin ky + B cos kx)``, ``A = B = C = U``, ``k = 2 pi / L``, at ``position``
    (``[..., 3]``; numpy or jax)."""
    info = case.info
    return _abc_field(position, t, info["speed"], info["wavenumber"], info["decay_rate"])


def abc_pressure(position, t, case: Case):
    """Exact ABC pressure ``p = -rho0 |u|^2 / 2`` less its mean ``3 rho0 U^2 / 2``:
    ``-rho0 U^2 e^{-2 nu k^2 t} (sin kz cos ky + sin kx cos kz + sin ky cos kx)``."""
    xp = np if isinstance(position, np.ndarray) else jnp
    info = case.info
    decay = xp.exp(2 * info["decay_rate"] * xp.asarray(t))
    shape = _abc_pressure_shape(position, info["wavenumber"])
    return -info["reference_density"] * info["speed"] ** 2 * decay * shape


def abc_flow_3d(
    n: int = 16,
    reynolds: float = 50.0,
    speed: float = 1.0,
    length: float = 1.0,
    sound_speed_factor: float = 10.0,
    kernel="quintic_spline",
    h_factor: float = 1.2,
    transport_velocity: bool = True,
    disorder: float = 0.45,
    seed: int = 0,
    relax_iterations: int = 400,
    t_end: float = 1.0,
) -> Case:
    """Decaying Arnold-Beltrami-Childress flow in the periodic cube ``[0, L)^3``.

    ``u = (A sin kz + C cos ky, B sin kx + A cos kz, C sin ky + B cos kx)`` with
    ``A = B = C = U`` and ``k = 2 pi / L`` is a Beltrami field (``curl u = k u``), so the
    advective term is a pure gradient and ``u(x, t) = u(x, 0) exp(-nu k^2 t)``,
    ``p = -rho0 |u|^2 / 2`` (times ``exp(-2 nu k^2 t)``) solve the incompressible
    Navier-Stokes equations exactly (Arnold 1965; Childress 1970; Dombre et al. 1986):
    ``KE(t) = KE0 exp(-2 nu k^2 t)``.  ``nu = U L / Re``; ``c0 = 10 |u|max``,
    ``|u|max = sqrt(6) U``.

    The formulation and the start are the Taylor-Green vortex's
    (:func:`sphjax.cases.taylor_green`): quintic spline with ``h = 1.2 dx``, summation
    density, linear equation of state, transport velocity; the cubic lattice displaced by
    up to ``disorder * dx``, relaxed under a uniform background pressure for
    ``relax_iterations`` pseudo-time steps, then the exact velocity, the density of the
    exact pressure and masses for which summation density reproduces it.

    Args:
      n: particles per side (``dx = L / n``); at least 8 with the default kernel, so
        that the kernel support stays under half the box.
      reynolds: ``Re = U L / nu`` (the flow is unstable at large Re: keep it 10-100).
      relax_iterations: pseudo-time steps of the packing (0: no packing, lattice masses).
    """
    kernel = as_kernel(kernel)
    check_positive("h_factor", h_factor)
    # the kernel support must stay under half the box (one periodic image per pair)
    n = check_resolution("n", n, math.floor(2 * kernel.support * h_factor) + 1)
    check_positive("reynolds", reynolds)
    U = check_positive("speed", speed)
    L = check_positive("length", length)
    if not 0.0 <= disorder < 0.5:
        raise ValueError(f"disorder must lie in [0, 0.5) (units of dx), got {disorder}")
    relax_iterations = _relax_iterations(relax_iterations)
    dx = L / n
    h = h_factor * dx
    x = lattice([0.0] * 3, [L] * 3, dx)
    rng = np.random.default_rng(seed)
    x = np.mod(x + disorder * dx * rng.uniform(-1.0, 1.0, x.shape), L)
    relaxed = relax_iterations > 0
    if relaxed:
        x, _ = relax_periodic(x, L, kernel, h, relax_iterations)
        neighbours = periodic_neighbours(x, L, kernel.support * h)
    nu, rho0, k = U * L / reynolds, 1.0, 2.0 * np.pi / L
    c0 = sound_speed_factor * ABC_MAX_SPEED * U
    info = dict(
        dx=dx,
        n=n,
        length=L,
        speed=U,
        wavenumber=k,
        viscosity=nu,
        reynolds=reynolds,
        reference_density=rho0,
        decay_rate=-nu * k**2,
        relax_iterations=relax_iterations,
    )
    velocity = _abc_field(x, 0.0, U, k, 0.0)
    pressure_shape = -(U**2) * _abc_pressure_shape(x, k)
    params = make_params(
        3,
        reference_density=rho0,
        sound_speed=c0,
        kinematic_viscosity=nu,
    )

    def initial_state(p):
        """Density of the exact pressure (eq. 12 inverted) and masses from ``p``."""
        rho0_p = p.reference_density
        rho = tait_density(
            rho0_p * jnp.asarray(pressure_shape) + p.reference_pressure,
            rho0_p,
            p.sound_speed,
            1.0,
            p.reference_pressure,
        )
        if relaxed:
            mass = summation_masses(x, neighbours, L, kernel, h, rho)
        else:
            mass = rho0_p * dx**3
        return make_state(x, velocity, rho, mass, Kind.FLUID)

    model = Model(
        dim=3,
        smoothing_length=h,
        kernel=kernel,
        domain=Domain((0.0,) * 3, (L,) * 3, (True,) * 3),
        systems=(
            fluid_system(
                density="summation",
                gamma=1.0,
                physical_viscosity=True,
                transport_velocity=transport_velocity,
            ),
        ),
    )
    state = initial_state(params)
    return _finish("abc_flow_3d", state, model, params, t_end, info, initial_state=initial_state)


abc_flow_3d.min_n = 8  # the smallest resolution (sphjax.cases._resolution)


def hydrostatic_tank_3d(
    n: int = 10,
    height: float = 1.0,
    width: float = 1.0,
    depth: float | None = None,
    gravity: float = 9.81,
    sound_speed_factor: float = 10.0,
    artificial_alpha: float = 0.1,
    t_end: float = 1.0,
) -> Case:
    """A water column at rest in a 3D tank: ``p = rho0 g (H - z)``.

    The column is ``H`` deep and fills a box ``width x depth``.

    The two-dimensional :func:`sphjax.cases.hydrostatic_tank` extruded: Wendland C2 with
    ``h = 1.5 dx``, continuity density with delta-SPH (Molteni & Colagrossi 2009), Tait
    ``gamma = 7``, artificial viscosity ``alpha``, ``c0 = 10 sqrt(g H)``, no-slip dummy
    walls (Adami et al. 2012) on the floor and the four sides, gravity along ``-z``, the
    hydrostatic density from the first step.

    Args:
      n: particles over the depth of water (``dx = H / n``).
      width, depth: the tank's extent along x and y (``depth`` defaults to ``width``),
        rounded to whole particle spacings.
    """
    n = check_resolution("n", n, 4)
    H = check_positive("height", height)
    W = check_positive("width", width)
    D = W if depth is None else check_positive("depth", depth)
    g = check_positive("gravity", gravity)
    dx = H / n
    W, D = dx * max(1, round(W / dx)), dx * max(1, round(D / dx))
    fluid = lattice([0.0, 0.0, 0.0], [W, D, H], dx)
    info = dict(
        dx=dx, n=n, height=H, width=W, depth=D, gravity=g, bottom_pressure=WATER_DENSITY * g * H
    )
    return _water_tank(
        "hydrostatic_tank_3d",
        fluid,
        (W, D, 1.2 * H),
        dx,
        g,
        H,
        sound_speed_factor,
        artificial_alpha,
        "molteni",
        "no_slip",
        t_end,
        info,
    )


def dam_break_3d(
    n: int = 8,
    column_width: float = 0.3,
    tank_length_factor: float = 5.0,
    tank_width: float | None = None,
    gravity: float = 9.81,
    sound_speed_factor: float = 20.0,
    artificial_alpha: float = 0.1,
    density_diffusion: str | None = "molteni",
    wall_slip: str = "no_slip",
    t_end: float | None = None,
) -> Case:
    """Martin & Moyce (1952) dam break in a 3D box tank, the column across its whole width.

    The two-dimensional :func:`sphjax.cases.dam_break` extruded along y: a column ``L``
    long and ``2L`` high against the wall ``x = 0`` of a tank ``tank_length_factor * L``
    long and ``tank_width`` wide (default ``L``), walls on the floor and the four sides;
    Wendland C2 with ``h = 1.5 dx``, continuity density with delta-SPH, Tait ``gamma = 7``,
    artificial viscosity, ``c0 = 20 sqrt(g H)``.  The surge front
    (:func:`sphjax.cases.surge_front`) is compared with the same tables as in 2D, against
    ``T = t sqrt(2 g / L)``.

    Args:
      n: particles along the column's length ``L`` (``dx = L / n``).
      tank_width: the tank's (and the column's) extent along y, rounded to whole spacings.
    """
    n = check_resolution("n", n, 4)
    L = check_positive("column_width", column_width)
    g = check_positive("gravity", gravity)
    dx = L / n
    Wy = L if tank_width is None else check_positive("tank_width", tank_width)
    Wy = dx * max(1, round(Wy / dx))
    H = 2.0 * L
    tank_length = dx * round(tank_length_factor * L / dx)
    fluid = lattice([0.0, 0.0, 0.0], [L, Wy, H], dx)
    if t_end is None:
        t_end = 3.0 / math.sqrt(2 * g / L)
    info = dict(
        dx=dx,
        n=n,
        column_width=L,
        column_height=H,
        tank_length=tank_length,
        tank_width=Wy,
        gravity=g,
        time_scale=1.0 / math.sqrt(2 * g / L),
    )
    return _water_tank(
        "dam_break_3d",
        fluid,
        (tank_length, Wy, 1.25 * H),
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


#: SPHERIC benchmark 2 (Kleefsman et al. 2005, J. Comput. Phys. 206, 363-393; SPHERIC
#: test-case 2 description): tank, water column, box obstacle (m), with x from the wall
#: the box faces (the column stands against the opposite wall) and z up.
SPHERIC_TANK = (3.22, 1.0, 1.0)
SPHERIC_COLUMN = (1.228, 0.55)  # length along x, height (across the full width)
SPHERIC_BOX = ((0.6635, 0.2985, 0.0), (0.8245, 0.7015, 0.161))  # 0.161 x 0.403 x 0.161
#: water-height gauges (x, y): H1 behind the box, H2 and H3 between it and the column,
#: H4 in the reservoir
SPHERIC_GAUGES = {
    "H1": (0.496, 0.5),
    "H2": (0.992, 0.5),
    "H3": (1.488, 0.5),
    "H4": (2.638, 0.5),
}
#: pressure sensors: P1-P4 up the box's face towards the column, P5-P8 along its top
SPHERIC_SENSORS = {
    "P1": (0.8245, 0.5, 0.021),
    "P2": (0.8245, 0.5, 0.061),
    "P3": (0.8245, 0.5, 0.101),
    "P4": (0.8245, 0.5, 0.141),
    "P5": (0.8035, 0.5, 0.161),
    "P6": (0.7635, 0.5, 0.161),
    "P7": (0.7235, 0.5, 0.161),
    "P8": (0.6835, 0.5, 0.161),
}


def spheric_dam_break_3d(
    n: int = 10,
    gravity: float = 9.81,
    sound_speed_factor: float = 20.0,
    artificial_alpha: float = 0.1,
    density_diffusion: str | None = "molteni",
    wall_slip: str = "no_slip",
    t_end: float = 6.0,
) -> Case:
    """SPHERIC benchmark 2: a dam break onto a box obstacle (Kleefsman et al. 2005).

    A tank ``3.22 x 1 x 1`` m; a water column ``1.228`` m long and ``0.55`` m high across
    the full width against the wall ``x = 3.22``; a box ``0.161 x 0.403 x 0.161`` m on the
    floor, its faces at ``x = 0.6635`` and ``0.8245``, centred across the width.  The
    experiment (MARIN) measured the water height at four gauges (``info["gauges"]``,
    :func:`water_height`) and the pressure at eight sensors on the box
    (``info["sensors"]``, :func:`sphjax.observables.probe_pressure`).

    The formulation is :func:`dam_break_3d`'s: Wendland C2 with ``h = 1.5 dx``,
    continuity density with delta-SPH, Tait ``gamma = 7``, artificial viscosity,
    ``c0 = 20 sqrt(g H)`` with ``H`` the column height, dummy walls (Adami et al. 2012)
    for the tank and the box.  The box is the lattice points inside it, so its faces
    sit within ``dx / 2`` of the true ones; the tank and column are rounded to whole
    spacings.

    Args:
      n: particles over the column's height (``dx = 0.55 / n``); the box is ``0.161``
        high, about ``0.3 n`` spacings.
    """
    n = check_resolution("n", n, 4)
    g = check_positive("gravity", gravity)
    length, width, height = SPHERIC_TANK
    column_length, column_height = SPHERIC_COLUMN
    dx = column_height / n
    L, W, Ht = (dx * max(1, round(v / dx)) for v in (length, width, height))
    Lc = dx * max(1, round(column_length / dx))
    fluid = lattice([L - Lc, 0.0, 0.0], [L, W, column_height], dx)
    # the box: the tank lattice's points inside it, as wall particles
    lo, hi = (np.asarray(c) for c in SPHERIC_BOX)
    grid = lattice([0.0, 0.0, 0.0], [L, W, hi[2] + dx], dx)
    box = grid[np.all((grid > lo) & (grid < hi), axis=1)]
    info = dict(
        dx=dx,
        n=n,
        tank=(L, W, Ht),
        column_length=Lc,
        column_height=column_height,
        box=(tuple(map(float, lo)), tuple(map(float, hi))),
        box_particles=len(box),
        gravity=g,
        gauges=dict(SPHERIC_GAUGES),
        sensors=dict(SPHERIC_SENSORS),
    )
    return _water_tank(
        "spheric_dam_break_3d",
        fluid,
        (L, W, Ht),
        dx,
        g,
        column_height,
        sound_speed_factor,
        artificial_alpha,
        density_diffusion,
        wall_slip,
        t_end,
        info,
        obstacle=box,
    )


def water_height(states, case: Case, gauge):
    """Depth of water over the floor at ``gauge = (x, y)``: the fluid volume per unit
    floor area there, ``sum_f V_f W2(|(x_f, y_f) - gauge|, h)`` with ``V_f = m_f / rho_f``
    and ``W2`` the case's kernel in two dimensions (its 2D normalisation), so a column
    of depth ``d`` without gaps reads ``d``; spray above the column adds its volume.

    Args:
      states: a State or a Trajectory's ``states``, with or without a leading time axis.
      gauge: the ``(x, y)`` position, e.g. ``case.info["gauges"]["H2"]``.
    Returns:
      the depth, ``[T]`` or a scalar (jax.numpy, differentiable).
    """
    states = getattr(states, "states", states)
    model = case.model
    gauge = jnp.asarray(gauge, states.position.dtype)
    r = jnp.linalg.norm(states.position[..., :2] - gauge, axis=-1)
    weight = kernels.W(model.kernel, r, model.smoothing_length, 2)
    fluid = (states.kind == Kind.FLUID) & (r < model.cutoff)
    return jnp.sum(jnp.where(fluid, weight * states.mass / states.density, 0.0), axis=-1)


def duct_velocity(y, z, half_width, half_height, viscosity, body_force, t=None, terms=100):
    """Velocity ``u(y, z)`` along a duct ``|y| <= a``, ``|z| <= b`` driven by a body force
    ``F`` (numpy; ``y``, ``z`` from the duct's axis).

    Steady (``t=None``), White (*Viscous Fluid Flow*, eq. 3-48):

        u = 16 a^2 F / (nu pi^3) sum_{i = 1, 3, 5, ...} (-1)^((i-1)/2)
            [1 - cosh(i pi z / (2a)) / cosh(i pi b / (2a))] cos(i pi y / (2a)) / i^3.

    Start-up from rest at time ``t``, the double sine series over the modes of the
    duct (``Y = y + a``, ``Z = z + b``, ``W = 2a``, ``D = 2b``):

        u = sum_{m, n odd} 16 F / (pi^2 m n nu lambda_mn) (1 - exp(-nu lambda_mn t))
            sin(m pi Y / W) sin(n pi Z / D),   lambda_mn = pi^2 (m^2 / W^2 + n^2 / D^2).
    """
    a, b, nu, F = half_width, half_height, viscosity, body_force
    y, z = np.asarray(y, float), np.asarray(z, float)
    if t is None:
        u = np.zeros(np.broadcast(y, z).shape)
        for i in range(1, 2 * terms, 2):
            sign = (-1.0) ** ((i - 1) // 2)
            # cosh(i pi z / 2a) / cosh(i pi b / 2a), written to stay finite for large i
            ratio = np.exp(i * np.pi * (np.abs(z) - b) / (2 * a)) * (
                (1 + np.exp(-i * np.pi * np.abs(z) / a)) / (1 + np.exp(-i * np.pi * b / a))
            )
            u += sign * (1 - ratio) * np.cos(i * np.pi * y / (2 * a)) / i**3
        return 16 * a**2 * F / (nu * np.pi**3) * u
    W, D = 2 * a, 2 * b
    m = np.arange(1, 2 * terms, 2)[:, None]
    n = np.arange(1, 2 * terms, 2)[None, :]
    lam = np.pi**2 * (m**2 / W**2 + n**2 / D**2)
    coefficient = 16 * F / (np.pi**2 * m * n * nu * lam) * (1 - np.exp(-nu * lam * t))
    Y, Z = (y + a)[..., None, None], (z + b)[..., None, None]
    modes = np.sin(m * np.pi * Y / W) * np.sin(n * np.pi * Z / D)
    return np.sum(coefficient * modes, axis=(-2, -1))


def duct_poiseuille_3d(
    n: int = 10,
    width: float = 1.0e-3,
    height: float | None = None,
    viscosity: float = 1.0e-6,
    body_force: float = 2.0e-4,
    sound_speed_factor: float = 20.0,
    kernel="quintic_spline",
    t_end: float = 0.5,
) -> Case:
    """Body-force-driven flow in a duct with four no-slip walls (White's series).

    The duct is ``[0, width] x [0, height]`` in (y, z), periodic along the flow (x); the
    fluid starts from rest.

    The three-dimensional :func:`sphjax.cases.poiseuille` (Morris, Fox & Zhu 1997: the
    same fluid, ``nu = 1e-6``, ``F = 2e-4``, quintic spline with ``h = dx``, summation
    density, Morris viscosity, Adami no-slip dummy walls, ``c0 = 20 u_max``).  The steady
    profile is White's series and the start-up the duct's double sine series
    (:func:`duct_velocity`); ``info["centre_speed"]`` is the steady speed on the axis.

    Args:
      n: particles across the width (``dx = width / n``).
      height: the duct's extent along z (default ``width``: a square duct), rounded to
        whole particle spacings.
    """
    n = check_resolution("n", n, 4)
    Wy = check_positive("width", width)
    Dz = Wy if height is None else check_positive("height", height)
    nu = check_positive("viscosity", viscosity)
    F = check_positive("body_force", body_force)
    dx = Wy / n
    Dz = dx * max(1, round(Dz / dx))
    kernel = as_kernel(kernel)
    h = dx
    cutoff = kernel.support * h
    layers = wall_layers(cutoff, dx)
    # periodic length: at least twice the neighbour-search radius (cutoff and skin)
    length = dx * max(4, math.ceil(2.5 * cutoff / dx))
    fluid = lattice([0.0, 0.0, 0.0], [length, Wy, Dz], dx)
    pad = layers * dx
    shell = lattice([0.0, -pad, -pad], [length, Wy + pad, Dz + pad], dx)
    inside = (shell[:, 1] > 0) & (shell[:, 1] < Wy) & (shell[:, 2] > 0) & (shell[:, 2] < Dz)
    walls = shell[~inside]
    x = np.concatenate([fluid, walls])
    kind = np.concatenate([np.full(len(fluid), Kind.FLUID), np.full(len(walls), Kind.WALL)])
    rho0 = 1000.0
    a, b = 0.5 * Wy, 0.5 * Dz
    u_centre = float(duct_velocity(0.0, 0.0, a, b, nu, F))
    c0 = sound_speed_factor * u_centre
    params = make_params(
        3, reference_density=rho0, sound_speed=c0, kinematic_viscosity=nu, gravity=(F, 0.0, 0.0)
    )
    margin = (layers + 2) * dx
    model = Model(
        dim=3,
        smoothing_length=h,
        kernel=kernel,
        domain=Domain(
            (0.0, -margin, -margin), (length, Wy + margin, Dz + margin), (True, False, False)
        ),
        systems=(
            fluid_system(density="summation", gamma=1.0, physical_viscosity=True),
            wall_system("no_slip"),
        ),
    )
    state = make_state(x, 0.0, rho0, rho0 * dx**3, kind)
    info = dict(
        dx=dx,
        n=n,
        width=Wy,
        height=Dz,
        length=length,
        viscosity=nu,
        body_force=F,
        centre_speed=u_centre,
    )
    return _finish("duct_poiseuille_3d", state, model, params, t_end, info)


__all__ = [
    "abc_flow_3d",
    "abc_velocity",
    "abc_pressure",
    "hydrostatic_tank_3d",
    "duct_poiseuille_3d",
    "duct_velocity",
    "dam_break_3d",
    "spheric_dam_break_3d",
    "water_height",
]
