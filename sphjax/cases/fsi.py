"""Fluid-structure interaction cases: elastic (TLSPH) solids in weakly compressible fluids.

* :func:`hydrostatic_fsi_plate` — a water column resting on an elastic plate clamped at
  both ends (Fourey et al. 2017; O'Connor & Rogers 2021): its static mid-span deflection
  against Euler-Bernoulli theory (:func:`plate_deflection_reference`).
* :func:`hydrostatic_fsi_plate_3d` — the same plate extruded across a tank, periodic along
  its span (plane strain in 3D): its deflection against the plane case's.
* :func:`elastic_gate_dam_break` — a water column held by a rubber gate clamped at its top
  (Antoci, Gallati & Sibilla 2007).
* :func:`dam_break_elastic_obstacle` — a dam break hitting an elastic plate fixed to the
  floor (Walhorn et al. 2005; Zhan et al. 2019).

Each returns a :class:`sphjax.Case` whose model is ``(FluidSystem, WallSystem,
SolidSystem)``: the solid's particles are moving boundary particles for the fluid and the
fluid's pair forces act back on them (:mod:`sphjax.physics.fsi`).
"""

from __future__ import annotations

import dataclasses
import math

import jax.numpy as jnp
import numpy as np

from sphjax.cases._geometry import check_positive, check_resolution, lattice, wall_layers
from sphjax.cases._systems import finish_case, fluid_system, wall_system
from sphjax.core.case import Case
from sphjax.core.kernels import as_kernel
from sphjax.core.model import Domain, Model
from sphjax.core.params import make_params
from sphjax.core.state import Kind, make_state
from sphjax.integration.timestep import split_substeps, stable_time_step
from sphjax.physics.fluid.eos import tait_density
from sphjax.physics.solid.boundary import SolidBoundary
from sphjax.physics.solid.penalty import PenaltyForce
from sphjax.physics.solid.system import SolidSystem

GAMMA = 7.0


def plate_deflection_reference(
    length, thickness, depth, young_modulus, poisson_ratio, solid_density, fluid_density, gravity
):
    """Euler-Bernoulli mid-span deflection of a plate clamped at both ends under its own
    weight and a water column: ``w = -q L^4 / (384 D)``, ``D = E t^3 / (12 (1 - nu^2))``
    (plane strain), ``q = g (rho_f H + rho_s t)`` (Fourey et al. 2017).  Works with
    jax.numpy arguments (differentiable in ``young_modulus``)."""
    D = young_modulus * thickness**3 / (12.0 * (1.0 - poisson_ratio**2))
    q = gravity * (fluid_density * depth + solid_density * thickness)
    return -q * length**4 / (384.0 * D)


def midspan_deflection(trajectory, case: Case):
    """Vertical displacement of the plate at mid-span (along the last axis: ``y - Y`` in
    2D, ``z - Z`` in 3D), ``[T]`` (or a scalar for one State): the mean over the particles
    of the column(s) nearest ``x = L / 2`` (``case.info["midspan_indices"]``), across the
    whole thickness (and in 3D the whole span); jax.numpy."""
    states = getattr(trajectory, "states", trajectory)
    position = jnp.asarray(getattr(states, "position", states))
    idx = jnp.asarray(case.info["midspan_indices"])
    anchor = case.state.reference_position[idx, -1]
    return jnp.mean(position[..., idx, -1] - anchor, axis=-1)


def _rows(x0, y0, nx, ny, dx):
    """Lattice points ``(x0 + (i + 1/2) dx, y0 + (j + 1/2) dx)``, ``0 <= i < nx, 0 <= j < ny``."""
    return lattice([x0, y0], [x0 + nx * dx, y0 + ny * dx], dx)


def _fsi_model(kernel, h, domain, fluid_kw, wall_slip, penalty, no_slip_solid, gradient_correction):
    return Model(
        dim=len(domain.lower),
        smoothing_length=h,
        kernel=kernel,
        domain=domain,
        systems=(
            fluid_system(**fluid_kw),
            wall_system(wall_slip),
            SolidSystem(
                penalty=PenaltyForce() if penalty else None,
                boundary=SolidBoundary(no_slip=no_slip_solid),
                gradient_correction=gradient_correction,
            ),
        ),
    )


def _column_indices(x, kind, x_probe, y_probe=None, dx=1.0):
    """Free solid particles of the lattice column nearest ``x_probe`` (both columns when
    ``x_probe`` falls between two), or of that column those nearest ``y_probe``."""
    solid = np.flatnonzero(kind == Kind.SOLID)
    dist = np.abs(x[solid, 0] - x_probe)
    column = solid[dist < dist.min() + 1e-6 * dx]
    if y_probe is None:
        return column
    dist = np.abs(x[column, 1] - y_probe)
    return column[dist < dist.min() + 1e-6 * dx]


def _fluid_solid_state(fluid, walls, solid, clamped, dx, depth_of, solid_weights=None):
    """``initial_state(params)``: hydrostatic fluid density ``rho(rho0 g (H - y))``
    (eq. 12 inverted; gravity along the last axis), masses ``rho dx^d``, the solid at its
    reference density.  ``solid_weights``: the volumes (and masses) of the solid and
    clamped particles over ``dx^d`` (default 1)."""
    x = np.concatenate([fluid, walls, solid, clamped])
    cell = dx ** x.shape[1]
    if solid_weights is not None:
        n_fluid_walls = len(fluid) + len(walls)
        cell = cell * np.concatenate([np.ones(n_fluid_walls), solid_weights])
    kind = np.concatenate(
        [
            np.full(len(fluid), Kind.FLUID),
            np.full(len(walls), Kind.WALL),
            np.full(len(solid), Kind.SOLID),
            np.full(len(clamped), Kind.CLAMPED),
        ]
    ).astype(np.int32)
    is_fluid = jnp.asarray(kind == Kind.FLUID)
    is_solid = jnp.asarray(kind >= Kind.SOLID)
    depth = jnp.asarray(np.where(kind == Kind.FLUID, depth_of(x), 0.0))

    def initial_state(p):
        rho0 = p.reference_density
        pressure = rho0 * (-p.gravity[-1]) * depth
        rho_f = tait_density(pressure, rho0, p.sound_speed, GAMMA)
        rho = jnp.where(is_solid, p.solid_density, jnp.where(is_fluid, rho_f, rho0))
        mass = jnp.where(is_solid, p.solid_density, rho0) * cell
        return make_state(x, 0.0, rho, mass, kind, volume=cell)

    return x, kind, initial_state


#: the fluid of every coupled case: continuity density (eq. 11), Tait (eq. 12), Monaghan's
#: artificial viscosity and Molteni & Colagrossi's delta-SPH
WEAKLY_COMPRESSIBLE = dict(
    density="continuity", gamma=GAMMA, artificial_viscosity=True, density_diffusion="molteni"
)


def _coupled_params(g, rho_f, c0, artificial_alpha, E, poisson_ratio, rho_s, dim=2):
    """Params of a coupled case: gravity along minus the last axis (-y in 2D, -z in 3D),
    the fluid's and the solid's groups."""
    return make_params(
        dim,
        gravity=(0.0,) * (dim - 1) + (-g,),
        reference_density=rho_f,
        sound_speed=c0,
        artificial_alpha=artificial_alpha,
        young_modulus=E,
        poisson_ratio=poisson_ratio,
        solid_density=rho_s,
    )


def _check_substeps(substeps):
    if substeps == "auto" or (isinstance(substeps, int) and substeps >= 1):
        return substeps
    raise ValueError(
        f"substeps must be a positive integer or 'auto' (split integration), got {substeps!r}"
    )


#: with ``substeps="auto"``, at least this many steps per period of the solid's first mode
STEPS_PER_PERIOD = 20


def _finish(name, model, params, initial_state, t_end, info, cfl, substeps=1, period=None):
    """The Case with its stable step.  ``substeps`` (split integration,
    ``SolidSystem.substeps``): ``"auto"`` is the whole number of the solid's stable steps
    in the fluid's, or in ``period / STEPS_PER_PERIOD`` if that is shorter: the fluid's
    force on the solid is sampled once a step, so a step must resolve the solid's motion
    (a plate sampled a few times a period oscillates about the wrong deflection)."""
    state = initial_state(params)
    if substeps == "auto":
        max_dt = None if period is None else period / STEPS_PER_PERIOD
        substeps = split_substeps(state, model, params, solid_cfl=cfl, max_dt=max_dt)
    solid = model.system(SolidSystem).replace(substeps=_check_substeps(substeps))
    model = model.replace(systems=model.systems[:-1] + (solid,))
    info = {**info, "substeps": substeps}
    dt = stable_time_step(state, model, params, solid_cfl=cfl)
    return finish_case(name, state, model, params, t_end, info, dt, initial_state)


@dataclasses.dataclass(frozen=True)
class _PlateSetUp:
    """The plane (x, vertical) geometry of the hydrostatic plate and its derived numbers."""

    n: int
    dx: float
    length: float
    thickness: float
    depth: float
    young_modulus: float
    poisson_ratio: float
    solid_density: float
    fluid_density: float
    gravity: float
    sound_speed: float
    kernel: object
    h: float
    layers: int
    n_clamp: int
    tank_height: float
    points: tuple  # (fluid, walls, plate, clamped) [N, 2] lattices
    placement: str = "cell"
    face_weight: float = 1.0

    @property
    def body_thickness(self) -> float:
        """The thickness the plate's rows of particles fill, ``dx`` per row and
        ``face_weight dx`` per face row with surface placement: ``t`` with cell placement
        and with surface placement's half-volume face rows."""
        if self.placement == "cell":
            return self.n * self.dx
        return (self.n - 2 + 2 * self.face_weight) * self.dx

    def volume_weights(self, plate_and_clamped) -> np.ndarray:
        """Each plate or clamped particle's volume over ``dx^d``: ``face_weight`` on the
        face rows with surface placement (trapezoidal rule through the thickness), else 1."""
        v = plate_and_clamped[:, -1]
        if self.placement == "cell":
            return np.ones(len(v))
        on_face = (np.abs(v) < 1e-6 * self.dx) | (np.abs(v + self.thickness) < 1e-6 * self.dx)
        return np.where(on_face, self.face_weight, 1.0)

    @property
    def particle_density(self) -> float:
        """The plate particles' density: ``rho_s t`` over the thickness their rows fill
        (:attr:`body_thickness`), so that their mass per unit length is the plate's,
        ``rho_s t`` (``rho_s`` with cell placement)."""
        return self.solid_density * self.thickness / self.body_thickness

    @property
    def margin(self) -> float:
        return (self.n_clamp + 2) * self.dx

    @property
    def domain_2d(self) -> Domain:
        m, t, L, H = self.margin, self.thickness, self.length, self.depth
        return Domain((-m, -t - m), (L + m, self.tank_height + H + m), (False,) * 2)

    @property
    def dry_omega(self) -> float:
        """First bending mode of the dry plate clamped at both ends: ``omega = 22.373 /
        L^2 sqrt(D / (rho_s t))``, ``D = E t^3 / (12 (1 - nu^2))``."""
        E, t, nu = self.young_modulus, self.thickness, self.poisson_ratio
        D = E * t**3 / (12.0 * (1.0 - nu**2))
        return 22.373 / self.length**2 * math.sqrt(D / (self.solid_density * t))


def _plate_set_up(
    n, length, thickness, depth, E, poisson_ratio, rho_s, rho_f, gravity, c_factor, kernel, h_f,
    placement="cell", face_weight=1.0, clamp_end_columns=True,
) -> _PlateSetUp:  # fmt: skip
    """The arguments of :func:`hydrostatic_fsi_plate` checked, rounded to whole particle
    spacings, and the plane lattices of fluid, side walls, plate and clamps."""
    if placement not in ("cell", "surface"):
        raise ValueError(f"placement must be 'cell' or 'surface', got {placement!r}")
    surface = placement == "surface"
    face_weight = check_positive("face_weight", face_weight)
    if not surface and (face_weight != 1.0 or not clamp_end_columns):
        raise ValueError(
            "face_weight and clamp_end_columns apply to placement='surface' only; "
            "leave them at 1.0 and True or pass placement='surface'"
        )
    n = check_resolution("n", n, 3 if surface else 2)
    L = check_positive("length", length)
    t = check_positive("thickness", thickness)
    H = check_positive("depth", depth)
    E = check_positive("young_modulus", E)
    rho_s = check_positive("solid_density", rho_s)
    rho_f = check_positive("fluid_density", rho_f)
    g = check_positive("gravity", gravity)
    dx = t / (n - 1) if surface else t / n
    nx = int(round(L / dx))
    L = nx * dx
    ny = int(round(H / dx))
    H = ny * dx
    kernel = as_kernel(kernel)
    if h_f is None:
        h_f = 2**0.5 if surface else 1.2
    h = check_positive("h_factor", h_f) * dx
    cutoff = kernel.support * h
    layers = wall_layers(cutoff, dx)
    n_clamp = 2 * layers
    tank_height = H + max(0.1 * H, 2 * cutoff)
    n_wall = int(math.ceil(tank_height / dx))
    # with surface placement the plate's top row lies on its face y = 0, one spacing below
    # the fluid's first row: fluid and walls are the cell-centred ones lifted by dx / 2
    lift = 0.5 * dx if surface else 0.0
    fluid = _rows(0.0, lift, nx, ny, dx)
    walls = np.concatenate(
        [_rows(-layers * dx, lift, layers, n_wall, dx), _rows(L, lift, layers, n_wall, dx)]
    )
    if surface:
        # rows on both faces and columns on both ends, spacing t / (n - 1)
        columns = np.arange(-n_clamp, nx + n_clamp + 1) * dx
        gx, gy = np.meshgrid(columns, -t + np.arange(n) * dx, indexing="ij")
        sites = np.stack([gx.ravel(), gy.ravel()], axis=-1)
        edge = 0.5 * dx if clamp_end_columns else -0.5 * dx
        free = (sites[:, 0] > edge) & (sites[:, 0] < L - edge)
        plate, clamped = sites[free], sites[~free]
    else:
        plate = _rows(0.0, -t, nx, n, dx)
        clamped = np.concatenate(
            [_rows(-n_clamp * dx, -t, n_clamp, n, dx), _rows(L, -t, n_clamp, n, dx)]
        )
    c0 = c_factor * math.sqrt(g * H)
    return _PlateSetUp(
        n, dx, L, t, H, E, float(poisson_ratio), rho_s, rho_f, g, c0, kernel, h, layers,
        n_clamp, tank_height, (fluid, walls, plate, clamped), placement, face_weight,
    )  # fmt: skip


def _plate_case(
    name, s: _PlateSetUp, points, domain, artificial_alpha, cfl, t_end, substeps,
    gradient_correction="first_order", **extra,
):  # fmt: skip
    """The hydrostatic plate's Case from its set-up ``s`` and its particles ``points``
    (fluid, walls, plate, clamped; plane or extruded) in ``domain``."""
    fluid, walls, plate, clamped = points
    dim = fluid.shape[1]
    # depth below the free surface: the fluid's top row lies dx / 2 under it
    surface_level = s.depth + (0.5 * s.dx if s.placement == "surface" else 0.0)

    def depth_of(x):
        return surface_level - x[:, -1]

    weights = s.volume_weights(np.concatenate([plate, clamped]))
    x, kind, initial_state = _fluid_solid_state(
        fluid, walls, plate, clamped, s.dx, depth_of, weights
    )
    params = _coupled_params(
        s.gravity, s.fluid_density, s.sound_speed, artificial_alpha, s.young_modulus,
        s.poisson_ratio, s.particle_density, dim,
    )  # fmt: skip
    model = _fsi_model(
        s.kernel, s.h, domain, WEAKLY_COMPRESSIBLE, "no_slip", False, True, gradient_correction
    )
    omega = s.dry_omega
    period = 2.0 * math.pi / omega
    if t_end is None:
        t_end = 20 * 2.0 * math.pi / omega
    reference = plate_deflection_reference(
        s.length, s.thickness, s.depth, s.young_modulus, s.poisson_ratio, s.solid_density,
        s.fluid_density, s.gravity,
    )  # fmt: skip
    info = dict(
        n=s.n,
        dx=s.dx,
        length=s.length,
        thickness=s.thickness,
        depth=s.depth,
        gravity=s.gravity,
        placement=s.placement,
        solid_density=s.solid_density,
        body_thickness=s.body_thickness,
        reference_deflection=float(reference),
        dry_period=period,
        midspan_indices=tuple(int(i) for i in _column_indices(x, kind, 0.5 * s.length, dx=s.dx)),
        n_fluid=len(fluid),
        n_solid=len(plate),
        n_clamped=len(clamped),
        **extra,
    )
    args = (model, params, initial_state, t_end, info, cfl, substeps, period)
    return _finish(name, *args)


def hydrostatic_fsi_plate(
    n: int = 4,
    length: float = 1.0,
    thickness: float = 0.05,
    depth: float = 2.0,
    young_modulus: float = 67.5e9,
    poisson_ratio: float = 0.3,
    solid_density: float = 2700.0,
    fluid_density: float = 1000.0,
    gravity: float = 9.81,
    sound_speed_factor: float = 10.0,
    artificial_alpha: float = 0.1,
    kernel="wendland_c2",
    h_factor: float | None = None,
    cfl: float = 0.5,
    t_end: float | None = None,
    substeps: int | str = "auto",
    placement: str = "cell",
    *,
    face_weight: float = 1.0,
    clamp_end_columns: bool = True,
    gradient_correction: str = "first_order",
) -> Case:
    """A water column of depth ``H`` resting on an elastic plate clamped at both ends
    (Fourey et al. 2017; O'Connor & Rogers 2021), plane strain.

    The plate ``[0, L] x [-t, 0]`` (``n`` particles through its thickness, ``dx = t / n``)
    continues beyond both ends as clamped particles (two kernel supports); the fluid
    ``[0, L] x [0, H]`` sits on it between two no-slip side walls, from the hydrostatic
    density.  Fluid: continuity density with delta-SPH, Tait (``gamma = 7``),
    ``c0 = sound_speed_factor sqrt(g H)``, artificial viscosity ``alpha``.  The plate
    starts flat and unloaded, oscillates about its static deflection, and its mid-span
    deflection (:func:`midspan_deflection`), averaged over the second half of the run, is
    compared with ``w = -q L^4 / (384 D)`` (:func:`plate_deflection_reference`;
    ``info["reference_deflection"]``), -7.05e-5 m with the defaults.

    Args:
      n: particles through the plate thickness (``dx = t / n`` with the default cell
        placement, ``t / (n - 1)`` with ``placement="surface"``).
      kernel, h_factor: kernel name and ``h = h_factor dx`` for fluid and solid
        (``None``: 1.2 with cell placement, ``sqrt(2)`` with surface placement).
      cfl: solid Courant number of the time step (the solid's sound speed sets it).
      t_end: default ``20`` periods of the plate's first dry bending mode.
      substeps: split integration (``SolidSystem.substeps``): the plate takes this many
        steps of its own per step, the step ``substeps`` times the solid's stable one (up
        to the fluid's); ``"auto"`` (the default): as many as fit in the fluid's stable
        step and in 1/20 of the dry first-mode period (63 with the defaults: 878 steps
        instead of 55,338; the static deflection moves by 0.1-2 %,
        docs/validation_fsi.md); ``1``: the unsplit step.
      placement: ``"cell"`` (the default: particles at the centres of square cells that
        tile the plate, the clamped cells beyond its ends) or ``"surface"`` (``n`` rows
        with the outer ones on the faces ``y = -t`` and ``y = 0`` and columns on
        ``x = 0, ..., L``, as TrixiParticles.jl builds it; the columns on the ends and
        beyond are clamped; fluid and walls lifted by ``dx / 2``, the fluid's first row one
        spacing above the top face; the particles' density ``rho_s t / (t + dx)``, so that
        the plate's mass per unit length is ``rho_s t``).  Cell placement errs soft in
        bending, surface placement stiff, by about as much at 12 spacings through the
        thickness (+11 % and -12 %; docs/validation_fsi.md).
      face_weight: with ``placement="surface"``, the volume (and mass) of a face-row
        particle over ``dx^d``: 1 (TrixiParticles' set-up); 0.5 is the trapezoidal rule
        through the thickness.  For measurements (docs/scripts/validate_fsi.py).
      clamp_end_columns: with ``placement="surface"``, clamp the columns on ``x = 0`` and
        ``x = L`` too; ``False`` leaves them free, the clamp starting one spacing beyond
        each end.  For measurements.
      gradient_correction: the plate's ``SolidSystem.gradient_correction``
        (``"second_order"`` needs ``n >= 3``); the time step and ``"auto"``'s substeps
        are computed for it (the second order's stable step is about half,
        ``SECOND_ORDER_STEP_FACTOR``).
    """
    plate = _plate_set_up(
        n, length, thickness, depth, young_modulus, poisson_ratio, solid_density,
        fluid_density, gravity, sound_speed_factor, kernel, h_factor, placement,
        face_weight, clamp_end_columns,
    )  # fmt: skip
    return _plate_case("hydrostatic_fsi_plate", plate, plate.points, plate.domain_2d,
                       artificial_alpha, cfl, t_end, substeps, gradient_correction)  # fmt: skip


def _extrude(points, dx, n_span):
    """Plane points ``(x, v)`` extruded along y: ``(x, (j + 1/2) dx, v)``, ``0 <= j < n_span``."""
    y = (np.arange(n_span) + 0.5) * dx
    plane = np.repeat(points, n_span, axis=0)
    return np.stack([plane[:, 0], np.tile(y, len(points)), plane[:, 1]], axis=1)


def hydrostatic_fsi_plate_3d(
    n: int = 2,
    span: float | None = None,
    length: float = 1.0,
    thickness: float = 0.05,
    depth: float = 2.0,
    young_modulus: float = 67.5e9,
    poisson_ratio: float = 0.3,
    solid_density: float = 2700.0,
    fluid_density: float = 1000.0,
    gravity: float = 9.81,
    sound_speed_factor: float = 10.0,
    artificial_alpha: float = 0.1,
    kernel="wendland_c2",
    h_factor: float | None = None,
    cfl: float = 0.5,
    t_end: float | None = None,
    substeps: int | str = "auto",
    placement: str = "cell",
) -> Case:
    """A water column resting on an elastic plate clamped at both ends, in 3D: the
    hydrostatic plate extruded across a tank, periodic along its span.

    :func:`hydrostatic_fsi_plate` in three dimensions.

    The plate ``[0, L] x [0, W) x [-t, 0]`` (x along the plate, y across it, z up;
    gravity along ``-z``), clamped particles beyond both ends, the fluid ``[0, L] x [0, W)
    x [0, H]`` between two no-slip side walls at ``x = 0`` and ``x = L``: the particles of
    the plane case, in its (x, z) plane, repeated at every spacing along y, with the same
    fluid, solid and coupling (St Venant-Kirchhoff in 3D).  Periodic along y, the plate
    is uniform across its span and cannot strain along it: it is a plane-strain plate,
    and the plane case's reference ``w = -q L^4 / (384 D)``, ``D = E t^3 / (12 (1 -
    nu^2))`` (:func:`plate_deflection_reference`; ``info["reference_deflection"]``)
    applies, as does the plane run of the same arguments.  The mid-span deflection
    (:func:`midspan_deflection`) is the mean over the particles nearest ``x = L / 2``
    through the thickness and across the span.

    Args:
      n: particles through the plate thickness (``dx = t / n``); the default 2 gives
        about 23 000 particles.
      span: the periodic extent ``W`` along y, rounded to whole spacings; at least (and
        by default) ``2.5`` kernel supports, the least the periodic neighbour search
        allows (6 spacings with the default kernel).
      substeps: split integration, as in :func:`hydrostatic_fsi_plate`; by default
        ``"auto"`` (unsplit, the plate's step would set the fluid's: 60 times more
        evaluations of the whole model).

    The other arguments (``placement`` among them) are :func:`hydrostatic_fsi_plate`'s.
    """
    s = _plate_set_up(
        n, length, thickness, depth, young_modulus, poisson_ratio, solid_density,
        fluid_density, gravity, sound_speed_factor, kernel, h_factor, placement,
    )  # fmt: skip
    dx = s.dx
    least = max(4, math.ceil(2.5 * s.kernel.support * s.h / dx - 1e-9))
    if span is None:
        n_span = least
    else:
        n_span = int(round(check_positive("span", span) / dx))
        if n_span < least:
            raise ValueError(
                f"span must be at least {least * dx:.6g} ({least} particle spacings, 2.5 "
                f"kernel supports) for the periodic neighbour search, got {span!r}"
            )
    W = n_span * dx
    points = tuple(_extrude(p, dx, n_span) for p in s.points)
    m, t, L, H = s.margin, s.thickness, s.length, s.depth
    domain = Domain((-m, 0.0, -t - m), (L + m, W, s.tank_height + H + m), (False, True, False))
    return _plate_case(
        "hydrostatic_fsi_plate_3d", s, points, domain, artificial_alpha, cfl, t_end,
        substeps, span=W, n_span=n_span,
    )  # fmt: skip


def elastic_gate_dam_break(
    n: int = 2,
    column_width: float = 0.1,
    column_height: float = 0.14,
    gate_length: float = 0.079,
    gate_thickness: float = 0.005,
    young_modulus: float = 12.0e6,
    poisson_ratio: float = 0.4,
    solid_density: float = 1100.0,
    fluid_density: float = 1000.0,
    gravity: float = 9.81,
    sound_speed_factor: float = 20.0,
    artificial_alpha: float = 0.1,
    outflow_length: float = 0.4,
    kernel="wendland_c2",
    h_factor: float = 1.5,
    cfl: float = 0.5,
    t_end: float = 0.4,
    substeps: int | str = "auto",
    gradient_correction: str = "first_order",
) -> Case:
    """Dam break through an elastic gate (Antoci, Gallati & Sibilla 2007), plane strain.

    Water ``[0, 0.1] x [0, 0.14]`` held on the right by a rubber gate ``0.005`` thick and
    ``0.079`` long, clamped at its top (clamped particles over two kernel supports above
    ``y = 0.079``, a rigid wall above them), its free end at the floor; the floor runs on
    ``outflow_length`` to the right of the gate, where the water escapes as the gate
    bends.  The water that passes under the gate runs along it at about 1 m/s; its front
    is 0.2 m past the gate at t = 0.247 s and 0.29 m past it at t = 0.4 s (0.34 m in plane
    stress, below), so the default 0.4 m keeps it on the floor to ``t_end`` at 2 and 3
    particles through the gate; a finer gate opens further sooner (at 4 through the front
    leaves a 0.4 m floor at t = 0.364 s: give it ``outflow_length=0.6``).  On a floor
    shorter than the front's run it falls off the end and leaves the domain, which stops
    the run (:class:`sphjax.SimulationError`).  Gate: ``E = 12 MPa``, ``nu = 0.4``,
    ``rho_s = 1100`` (the values vary across the literature: E 7.8-12 MPa, nu 0.4-0.47);
    in plane strain it bends with ``E / (1 - nu^2)``, in plane stress with ``E``
    (``young_modulus, poisson_ratio =``
    :func:`sphjax.physics.solid.material.plane_stress_equivalent` ``(E, nu)``; the two
    against the experiment: docs/validation_fsi.md).  Fluid: continuity density with
    delta-SPH, Tait, ``c0 = sound_speed_factor sqrt(g H)``.  The free end's displacement
    (``info["tip_indices"]``, :func:`sphjax.cases.tip_displacement`) peaks at 0.046 m
    horizontally and 0.017 m vertically at t = 0.16 s in the experiment.

    Args:
      n: particles across the gate thickness (``dx = thickness / n``).
      outflow_length: the floor's length past the gate (see above).
      substeps: split integration, as in :func:`hydrostatic_fsi_plate`; ``"auto"`` (the
        default) takes 3 gate steps a step at n = 2 and 4: 3,523 steps to t = 0.12 s
        instead of 10,569, the tip within 0.3 mm (0.8 %) of the unsplit run's, 15 % less
        CPU time (the gate is a small part of a step).
      gradient_correction: the gate's ``SolidSystem.gradient_correction``, as in
        :func:`hydrostatic_fsi_plate` (``"second_order"``: ``n >= 3``; with ``"auto"`` it
        takes about twice the gate steps per step, 7 at n = 3, at about the same step).
    """
    n = check_resolution("n", n, 2)
    W = check_positive("column_width", column_width)
    Hc = check_positive("column_height", column_height)
    Lg = check_positive("gate_length", gate_length)
    tg = check_positive("gate_thickness", gate_thickness)
    E = check_positive("young_modulus", young_modulus)
    rho_s = check_positive("solid_density", solid_density)
    rho_f = check_positive("fluid_density", fluid_density)
    g = check_positive("gravity", gravity)
    out = check_positive("outflow_length", outflow_length)
    dx = tg / n
    nx, ny = int(round(W / dx)), int(round(Hc / dx))
    W, Hc = nx * dx, ny * dx
    n_gate = int(round(Lg / dx))
    Lg = n_gate * dx
    kernel = as_kernel(kernel)
    h = h_factor * dx
    layers = wall_layers(kernel.support * h, dx)
    n_clamp = 2 * layers
    tank_height = Hc + 2 * layers * dx
    n_out = int(round(out / dx))
    fluid = _rows(0.0, 0.0, nx, ny, dx)
    gate = _rows(W, 0.0, n, n_gate, dx)
    clamped = _rows(W, Lg, n, n_clamp, dx)
    top = Lg + n_clamp * dx
    n_top = int(math.ceil((tank_height - top) / dx))
    walls = np.concatenate(
        [
            _rows(-layers * dx, -layers * dx, layers, ny + 3 * layers, dx),  # left
            _rows(0.0, -layers * dx, nx + n + n_out, layers, dx),  # floor
            _rows(W, top, max(n, layers), max(n_top, 1), dx),  # above the clamp
        ]
    )
    x, kind, initial_state = _fluid_solid_state(
        fluid, walls, gate, clamped, dx, lambda x: Hc - x[:, 1]
    )
    c0 = sound_speed_factor * math.sqrt(g * Hc)
    params = _coupled_params(g, rho_f, c0, artificial_alpha, E, poisson_ratio, rho_s)
    margin = (layers + 2) * dx
    domain = Domain(
        (-margin, -margin), (W + (n + n_out) * dx + margin, tank_height + margin), (False,) * 2
    )
    model = _fsi_model(
        kernel, h, domain, WEAKLY_COMPRESSIBLE, "no_slip", False, True, gradient_correction
    )
    gate_mask = kind == Kind.SOLID
    bottom = np.flatnonzero(gate_mask & (x[:, 1] < dx))
    centre = W + 0.5 * tg
    dist = np.abs(x[bottom, 0] - centre)
    tips = bottom[dist < dist.min() + 1e-6 * dx]
    info = dict(
        n=n,
        dx=dx,
        column_width=W,
        column_height=Hc,
        gate_length=Lg,
        gate_thickness=tg,
        tip_index=int(tips[0]),
        tip_indices=tuple(int(i) for i in tips),
        n_fluid=len(fluid),
        n_solid=len(gate),
        n_clamped=len(clamped),
        experiment_peak_ux=0.04,
    )
    return _finish(
        "elastic_gate_dam_break", model, params, initial_state, t_end, info, cfl, substeps
    )


def dam_break_elastic_obstacle(
    n: int = 3,
    column_width: float = 0.146,
    plate_length: float = 0.08,
    plate_thickness: float = 0.012,
    young_modulus: float = 1.0e6,
    poisson_ratio: float = 0.0,
    solid_density: float = 2500.0,
    fluid_density: float = 1000.0,
    gravity: float = 9.81,
    sound_speed_factor: float = 20.0,
    artificial_alpha: float = 0.1,
    kernel="wendland_c2",
    h_factor: float = 1.5,
    cfl: float = 0.5,
    t_end: float = 1.0,
    substeps: int | str = "auto",
    gradient_correction: str = "first_order",
) -> Case:
    """A dam break hitting an elastic plate fixed to the floor (Zhan et al. 2019, section
    6.5; TrixiParticles' ``dam_break_plate_2d``), plane strain.

    Water ``L x 2L`` (``L = 0.146``) at the left of a tank ``4L`` long; an elastic plate
    ``0.012`` thick and ``0.08`` high standing on the floor at ``x = 2L``, clamped below
    the floor (clamped particles in place of the floor's wall particles under it).
    ``E = 1 MPa``, ``nu = 0``, ``rho_s = 2500``.  The plate's top (``info["tip_indices"]``,
    :func:`sphjax.cases.tip_displacement`) is the probe; its energy and momentum budgets
    are :func:`sphjax.observables.energy_budget` and
    :func:`sphjax.observables.momentum_budget` (docs/validation_fsi.md).

    Args:
      n: particles across the plate thickness (``dx = thickness / n``).
      substeps: split integration, as in :func:`hydrostatic_fsi_plate`; ``"auto"`` (the
        default) is 1 here, the soft plate's stable step being about the fluid's.
      gradient_correction: the plate's ``SolidSystem.gradient_correction``, as in
        :func:`hydrostatic_fsi_plate` (``"second_order"``: ``n >= 3``; its half stable
        step is still above the fluid's at n = 3, so the step does not change).
    """
    n = check_resolution("n", n, 2)
    L = check_positive("column_width", column_width)
    Lp = check_positive("plate_length", plate_length)
    tp = check_positive("plate_thickness", plate_thickness)
    E = check_positive("young_modulus", young_modulus)
    rho_s = check_positive("solid_density", solid_density)
    rho_f = check_positive("fluid_density", fluid_density)
    g = check_positive("gravity", gravity)
    dx = tp / n
    nx, ny = int(round(L / dx)), int(round(2.0 * L / dx))
    L = nx * dx
    H = ny * dx
    n_tank = int(round(4.0 * L / dx))
    n_plate = int(round(Lp / dx))
    i_plate = int(round(2.0 * L / dx))
    kernel = as_kernel(kernel)
    h = h_factor * dx
    layers = wall_layers(kernel.support * h, dx)
    tank_height = 1.25 * H
    n_wall = int(math.ceil(tank_height / dx))
    fluid = _rows(0.0, 0.0, nx, ny, dx)
    floor = _rows(0.0, -layers * dx, n_tank, layers, dx)
    under = (floor[:, 0] > i_plate * dx) & (floor[:, 0] < (i_plate + n) * dx)
    walls = np.concatenate(
        [
            _rows(-layers * dx, -layers * dx, layers, n_wall + layers, dx),
            floor[~under],
            _rows(n_tank * dx, -layers * dx, layers, n_wall + layers, dx),
        ]
    )
    plate = _rows(i_plate * dx, 0.0, n, n_plate, dx)
    clamped = floor[under]
    x, kind, initial_state = _fluid_solid_state(
        fluid, walls, plate, clamped, dx, lambda x: H - x[:, 1]
    )
    c0 = sound_speed_factor * math.sqrt(g * H)
    params = _coupled_params(g, rho_f, c0, artificial_alpha, E, poisson_ratio, rho_s)
    margin = (layers + 2) * dx
    domain = Domain((-margin, -margin), (n_tank * dx + margin, 2.0 * tank_height), (False,) * 2)
    model = _fsi_model(
        kernel, h, domain, WEAKLY_COMPRESSIBLE, "no_slip", False, True, gradient_correction
    )
    solid = np.flatnonzero(kind == Kind.SOLID)
    top = solid[x[solid, 1] > x[solid, 1].max() - 0.5 * dx]
    centre = (i_plate + 0.5 * n) * dx
    dist = np.abs(x[top, 0] - centre)
    tips = top[dist < dist.min() + 1e-6 * dx]
    info = dict(
        n=n,
        dx=dx,
        column_width=L,
        column_height=H,
        tank_length=n_tank * dx,
        plate_length=n_plate * dx,
        plate_thickness=tp,
        tip_index=int(tips[0]),
        tip_indices=tuple(int(i) for i in tips),
        n_fluid=len(fluid),
        n_solid=len(plate),
        n_clamped=len(clamped),
    )
    return _finish(
        "dam_break_elastic_obstacle", model, params, initial_state, t_end, info, cfl, substeps
    )


__all__ = [
    "dam_break_elastic_obstacle",
    "elastic_gate_dam_break",
    "hydrostatic_fsi_plate",
    "hydrostatic_fsi_plate_3d",
    "midspan_deflection",
    "plate_deflection_reference",
]
