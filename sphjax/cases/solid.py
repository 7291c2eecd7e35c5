"""Elastic-solid validation cases, total-Lagrangian SPH.

* :func:`oscillating_plate` — Gray, Monaghan & Swift (2001) cantilever plate, clamped over
  an extra length, released with the first bending mode as velocity profile.
* :func:`turek_hron_csm` — the Turek & Hron (2006) CSM beam behind a rigid cylinder under
  gravity (CSM3: from rest, undamped; CSM1 and CSM2: its static equilibrium for two
  Young's moduli, found with :func:`relax_to_rest`).

Both return a :class:`sphjax.Case` whose ``info`` holds ``tip_index`` (the probe particle,
on the beam's centre line at its free end), ``tip_indices`` (the one or two particles the
probe averages: two when the centre line falls between particle rows) and the reference
numbers.  :func:`tip_displacement` turns a trajectory into the tip displacement ``[T, d]``;
:func:`oscillation_stats` extracts mean, amplitude and period from a signal.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from sphjax._text import show
from sphjax.cases._geometry import check_positive, check_resolution
from sphjax.cases._systems import finish_case
from sphjax.core.case import Case
from sphjax.core.kernels import as_kernel
from sphjax.core.model import Domain, Model
from sphjax.core.params import make_params
from sphjax.core.state import Kind, make_state
from sphjax.integration.simulate import simulate
from sphjax.integration.timestep import stable_time_step
from sphjax.physics.solid.penalty import PenaltyForce
from sphjax.physics.solid.system import SolidSystem

# Gray, Monaghan & Swift (2001) first bending mode: k L = 1.87510.
PLATE_KL = 1.8751040687


def plate_mode_shape(s, kL: float = PLATE_KL):
    """Cantilever mode shape ``f(s)``, ``s = x / L``, normalised so that ``f(1) = 1``.

    ``f(s) = [M (cos kLs - cosh kLs) - N (sin kLs - sinh kLs)] / Q`` with
    ``M = sin kL + sinh kL``, ``N = cos kL + cosh kL``,
    ``Q = 2 (cos kL sinh kL - sin kL cosh kL)`` (Gray, Monaghan & Swift 2001).
    """
    s = np.asarray(s, float)
    M = math.sin(kL) + math.sinh(kL)
    N = math.cos(kL) + math.cosh(kL)
    Q = 2.0 * (math.cos(kL) * math.sinh(kL) - math.sin(kL) * math.cosh(kL))
    a = kL * s
    return (M * (np.cos(a) - np.cosh(a)) - N * (np.sin(a) - np.sinh(a))) / Q


def plate_angular_frequency(
    length, thickness, young_modulus, density, poisson_ratio, kL: float = PLATE_KL
) -> float:
    """Linear-theory ``omega`` of the plate: ``omega^2 = E H^2 k^4 / (12 rho (1 - nu^2))``."""
    k = kL / length
    return math.sqrt(
        young_modulus * thickness**2 * k**4 / (12.0 * density * (1.0 - poisson_ratio**2))
    )


def _strip(x0, y0, nx, ny, dx, i_start=0):
    """Lattice points ``(x0 + (i + 1/2) dx, y0 + (j + 1/2) dx)``, ``i_start <= i < nx``."""
    i = np.arange(i_start, nx)
    j = np.arange(ny)
    gx, gy = np.meshgrid(x0 + (i + 0.5) * dx, y0 + (j + 0.5) * dx, indexing="ij")
    return np.stack([gx.ravel(), gy.ravel()], axis=-1)


def _tip_indices(x, kind, centre_line, dx):
    """Particles of the free end's cross-section closest to the centre line, which runs
    along x through ``centre_line`` (``y`` in 2D, ``(y, z)`` in 3D)."""
    solid = np.flatnonzero(kind == Kind.SOLID)
    x_max = x[solid, 0].max()
    column = solid[np.abs(x[solid, 0] - x_max) < 1e-6 * dx]
    dist = np.linalg.norm(x[column, 1:] - np.atleast_1d(centre_line), axis=-1)
    return column[dist < dist.min() + 1e-6 * dx]


def _solid_model(kernel, h, domain, penalty):
    return Model(
        dim=domain.dim,
        smoothing_length=h,
        kernel=kernel,
        domain=domain,
        systems=(SolidSystem(penalty=PenaltyForce() if penalty else None),),
    )


def plate_sound_speed(params):
    """``c0 = sqrt(K / rho)`` with ``K = E / (3 (1 - 2 nu))`` from ``params`` (jax.numpy).

    The three-dimensional bulk modulus of Gray, Monaghan & Swift (2001), which sets the
    plate's initial velocity ``V_f c0 f(x / L)``.
    """
    E, nu = params.young_modulus, params.poisson_ratio
    return jnp.sqrt(E / (3.0 * (1.0 - 2.0 * nu)) / params.solid_density)


def plate_reference(case: Case, params=None) -> dict:
    """Linear-theory reference of an oscillating-plate case for ``params`` (jax.numpy).

    ``case.info`` holds these numbers for the parameters the case was built with; this
    recomputes them for others (default ``case.params``): ``sound_speed`` (see
    :func:`plate_sound_speed`), ``omega`` (:func:`plate_angular_frequency`), ``period``
    and ``tip_amplitude = V_f c0 / omega``.
    """
    p = case.params if params is None else params
    info = case.info
    k = PLATE_KL / info["length"]
    E, nu, rho = p.young_modulus, p.poisson_ratio, p.solid_density
    omega = jnp.sqrt(E * info["thickness"] ** 2 * k**4 / (12.0 * rho * (1.0 - nu**2)))
    c0 = plate_sound_speed(p)
    return dict(
        sound_speed=c0,
        omega=omega,
        period=2.0 * jnp.pi / omega,
        tip_amplitude=info["amplitude"] * c0 / omega,
    )


def _finish(name, x, velocity, kind, dx, rho, model, params, t_end, info, cfl, velocity_fn=None):
    """The Case; ``velocity_fn(params)``, if given, is the initial velocity for ``params``.

    The state's density and mass follow ``params.solid_density`` too, so
    ``case.state_for(params)`` is the state this factory builds with those parameters.
    """
    volume = dx ** x.shape[1]

    def initial_state(p):
        v = velocity if velocity_fn is None else velocity_fn(p)
        density = jnp.asarray(p.solid_density)
        return make_state(x, v, density, density * volume, kind, volume=volume)

    state = initial_state(params)
    dt = stable_time_step(state, model, params, solid_cfl=cfl)
    tips = _tip_indices(x, kind, info["centre_line"], dx)
    info = dict(
        info,
        dx=dx,
        tip_index=int(tips[0]),
        tip_indices=tuple(int(i) for i in tips),
        n_solid=int(np.sum(kind == Kind.SOLID)),
        n_clamped=int(np.sum(kind == Kind.CLAMPED)),
    )
    return finish_case(name, state, model, params, t_end, info, dt, initial_state)


def _beam_arguments(n, length, thickness, young_modulus, density, amplitude, clamp_length):
    """The checked arguments of a clamped beam (plate or cantilever): ``n``, ``L``, ``H``,
    ``E``, ``rho``, ``dx = H / n``, particles along the beam and along the clamp."""
    n = check_resolution("n", n, 2)
    L = check_positive("length", length)
    H = check_positive("thickness", thickness)
    E = check_positive("young_modulus", young_modulus)
    rho = check_positive("density", density)
    if not amplitude >= 0:
        raise ValueError(f"amplitude (V_f) must be >= 0, got {amplitude}")
    if not clamp_length >= 0:
        raise ValueError(f"clamp_length must be >= 0, got {clamp_length}")
    dx = H / n
    return n, L, H, E, rho, dx, int(round(L / dx)), int(round(clamp_length / dx))


def _first_mode_velocity(x, kind, amplitude, length):
    """``params -> v``: ``v_y(x) = V_f c0 f(x / L)`` on the beam (:func:`plate_mode_shape`,
    ``c0`` of the parameters), 0 on the clamp."""
    solid = kind == Kind.SOLID
    profile = np.zeros_like(x)
    profile[solid, 1] = amplitude * plate_mode_shape(x[solid, 0] / length)

    def velocity_fn(p):
        return plate_sound_speed(p) * jnp.asarray(profile)

    return velocity_fn


def _beam_params(dim, E, poisson_ratio, rho, penalty_alpha):
    """The elastic Params of a beam (no fluid, no gravity)."""
    return make_params(
        dim,
        young_modulus=E,
        poisson_ratio=poisson_ratio,
        solid_density=rho,
        penalty_alpha=0.0 if penalty_alpha is None else penalty_alpha,
    )


def oscillating_plate(
    n: int = 12,
    amplitude: float = 0.001,
    length: float = 0.2,
    thickness: float = 0.02,
    clamp_length: float = 0.06,
    young_modulus: float = 2.0e6,
    poisson_ratio: float = 0.3975,
    density: float = 1000.0,
    kernel="wendland_c2",
    h_factor: float = 1.2,
    penalty_alpha: float | None = None,
    cfl: float = 0.3,
    t_end: float = 0.6,
) -> Case:
    """Oscillating cantilever plate (Gray, Monaghan & Swift 2001), plane strain.

    The plate ``[0, L] x [-H/2, H/2]`` continues into ``[-clamp_length, 0]`` as clamped
    particles (fixed); of these only the ones within two kernel supports of the plate are
    kept (the others cannot act on it), so ``clamp_length`` beyond that changes nothing.
    Initial transverse velocity ``v_y(x) = V_f c0 f(x / L)`` with the mode shape
    :func:`plate_mode_shape`; ``c0 = sqrt(K / rho)`` with the three-dimensional bulk
    modulus ``K = E / (3 (1 - 2 nu))`` as in Gray et al., which gives the reference tip
    amplitude ``V_f c0 / omega = 2.31e-3 m`` for ``V_f = 0.001``.  Linear theory: period
    ``2 pi / omega = 0.2541 s`` (:func:`plate_angular_frequency`).

    The initial velocity follows the parameters: ``simulate(case, params)`` with another
    ``young_modulus`` (or ``poisson_ratio``, ``solid_density``) starts from
    ``case.state_for(params)``, the velocity ``V_f c0 f`` of those parameters.  The
    reference numbers in ``case.info`` are for the parameters given here;
    :func:`plate_reference` recomputes them for others.

    Args:
      n: particles across the thickness (``dx = H / n``).
      amplitude: ``V_f``.
      kernel, h_factor: kernel name and ``h = h_factor dx`` (Wendland C2, ``1.2 dx``: the
        setting validated in docs/validation_solid.md).
      penalty_alpha: ``None`` (no penalty force) or Ganzenmüller's ``alpha``.
      cfl: solid Courant number of the time step.
    """
    n, L, H, E, rho, dx, nx, n_clamp = _beam_arguments(
        n, length, thickness, young_modulus, density, amplitude, clamp_length
    )
    x = _strip(0.0, -0.5 * H, nx, n, dx, i_start=-n_clamp)
    kind = np.where(x[:, 0] > 0.0, Kind.SOLID, Kind.CLAMPED).astype(np.int32)
    kernel = as_kernel(kernel)
    h = h_factor * dx
    # clamped particles further than two kernel supports from the plate cannot act on it
    keep = x[:, 0] > -2.0 * kernel.support * h
    x, kind = x[keep], kind[keep]
    # v_y = V_f c0 f(x / L) on the plate, 0 on the clamp; c0 follows the parameters
    velocity_fn = _first_mode_velocity(x, kind, amplitude, L)
    omega = plate_angular_frequency(L, H, E, rho, poisson_ratio)
    params = _beam_params(2, E, poisson_ratio, rho, penalty_alpha)
    margin = L
    domain = Domain((-clamp_length - margin, -margin), (L + margin, margin), (False, False))
    model = _solid_model(kernel, h, domain, penalty_alpha is not None)
    c0 = float(plate_sound_speed(params))
    info = dict(
        n=n,
        length=L,
        thickness=H,
        clamp_length=n_clamp * dx,
        amplitude=amplitude,
        sound_speed=c0,
        omega=omega,
        period=2.0 * math.pi / omega,
        tip_amplitude=amplitude * c0 / omega,
        centre_line=0.0,
    )
    return _finish(
        "oscillating_plate", x, 0.0, kind, dx, rho, model, params, t_end, info, cfl, velocity_fn
    )


# Turek & Hron (2006) CSM3 reference: tip u_y = -63.607 +- 65.160 mm,
# u_x = -14.305 +- 14.305 mm, 1.0995 Hz.
TUREK_HRON_CSM3 = dict(
    uy_mean=-63.607e-3,
    uy_amplitude=65.160e-3,
    ux_mean=-14.305e-3,
    ux_amplitude=14.305e-3,
    frequency=1.0995,
)


# Turek & Hron (2006) CSM1 and CSM2, steady tip displacements (m): the static equilibrium
# under gravity with E = 1.4e6 and 5.6e6 Pa (rho = 1000, nu = 0.4, g = 2 m/s^2).
TUREK_HRON_STEADY = {
    1.4e6: dict(name="CSM1", ux=-7.187e-3, uy=-66.10e-3),
    5.6e6: dict(name="CSM2", ux=-0.469e-3, uy=-16.97e-3),
}


def relax_to_rest(case: Case, params=None, *, t_end: float, damping_rate: float, segments: int):
    """Static equilibrium of a solid case by damped dynamics (dynamic relaxation).

    Runs ``case`` to ``t_end`` in ``segments`` equal runs of :func:`sphjax.simulate`,
    multiplying the velocities by ``exp(-damping_rate * t_segment)`` after each: a
    velocity damping ``-c v`` with ``c = damping_rate`` applied in discrete steps.  The
    damping only acts on velocities, so an equilibrium of the undamped equations is one of
    the damped ones.  For Turek-Hron, ``c = 1.4 * 2 pi 1.0995 Hz * sqrt(E / 1.4e6)`` settles
    the tip to about 0.1 % in 1.2 s (CSM1) and 0.9 s (CSM2) (docs/validation_solid.md).

    Returns:
      ``(times, states)``: the end time of each segment and its final State (stacked).
    """
    check_positive("t_end", t_end)
    if not (isinstance(damping_rate, int | float) and damping_rate >= 0):
        raise ValueError(f"damping_rate must be a number >= 0 (1/s), got {show(damping_rate)}")
    if not (isinstance(segments, int) and segments >= 1):
        raise ValueError(f"segments must be a whole number >= 1, got {show(segments)}")
    params = case.params if params is None else params
    state = case.state_for(params)
    n_steps = max(1, int(round(t_end / case.dt / segments)))
    factor = math.exp(-damping_rate * n_steps * case.dt)
    times, finals = [], []
    for k in range(segments):
        final = simulate(case, params, state=state, n_steps=n_steps).final
        state = final.replace(velocity=final.velocity * factor)
        times.append((k + 1) * n_steps * case.dt)
        finals.append(final)
    stacked = jax.tree_util.tree_map(lambda *leaves: jnp.stack(leaves), *finals)
    return np.asarray(times), stacked


def turek_hron_csm(
    n: int = 13,
    young_modulus: float = 1.4e6,
    poisson_ratio: float = 0.4,
    density: float = 1000.0,
    gravity: float = 2.0,
    kernel="wendland_c2",
    h_factor: float | None = None,
    penalty_alpha: float | None = None,
    cfl: float = 0.3,
    t_end: float = 2.0,
    clamp: str = "cylinder",
    fill_root: bool = True,
    placement: str = "surface",
    embedded_root: bool = True,
) -> Case:
    """Turek-Hron CSM beam (CSM3 with the defaults): elastic beam behind a rigid cylinder.

    Cylinder centre ``(0.2, 0.2)``, radius 0.05; beam ``0.35 x 0.02`` from ``x = 0.25`` to
    the tip point A ``(0.6, 0.2)``; ``rho = 1000``, ``nu = 0.4``, gravity 2 m/s^2 down,
    St Venant-Kirchhoff in plane strain, from rest and undamped.

    The rigid cylinder is modelled by clamped particles on the beam's own lattice,
    continued to the left of ``x = 0.25`` at the lattice sites inside the circle (only
    those within two kernel supports of the beam, the rest cannot influence it).  So the
    beam's root sits against the cylinder's curved surface as in the benchmark, and the
    clamped particles share the beam's regular spacing.

    CSM1 and CSM2 are the static equilibria for ``young_modulus=1.4e6`` and ``5.6e6``
    (``case.info["reference_steady"]`` holds their tip displacements): run
    :func:`relax_to_rest`.

    The default set-up is the one of the reference SPH codes (TrixiParticles.jl,
    DualSPHysics): particle rows on the beam's faces (``placement="surface"``),
    ``h = sqrt(2) dx`` and the beam continued into the cylinder up to its centre
    (``embedded_root=True``).  It meets the CSM3 targets (mean 2 %, amplitude 3 %,
    frequency 1.5 %) at 17 particles across.  The set-up of earlier versions, particles at
    cell centres with the beam clamped at the cylinder's surface, is
    ``placement="cell", embedded_root=False`` (``h = 1.2 dx``); it stays about 5 % too
    soft at 16 across (docs/validation_solid.md explains why).

    Args:
      n: particles across the beam thickness 0.02 (``dx = 0.02 / (n - 1)`` with the
        default surface placement, ``0.02 / n`` with ``placement="cell"``).
      young_modulus: 1.4e6 (CSM1, CSM3) or 5.6e6 (CSM2).
      kernel, h_factor: kernel name and ``h = h_factor dx`` (Wendland C2; ``h_factor``
        ``None`` gives ``sqrt(2)`` with ``placement="surface"``, ``1.2`` with ``"cell"``).
      penalty_alpha: ``None`` (no penalty force) or Ganzenmüller's ``alpha``.
      cfl: solid Courant number of the time step (0.5 gives the same tip curve).
      clamp: ``"cylinder"`` (clamped lattice sites inside the cylinder, the default) or
        ``"strip"`` (the beam continued to the left of ``x = 0.25`` as clamped particles,
        like the plate's clamp; for comparison).
      fill_root: with ``clamp="cylinder"``, make the lattice sites of the beam's band
        between the cylinder's surface and ``x = 0.25`` free beam particles (default).
        ``False`` leaves them out (the set-up of earlier versions), which notches the
        root's outer fibres at some resolutions (one site per edge at 12 particles
        across, two at 16) and adds 2.6 % and 6 % of the CSM3 mean deflection there
        (docs/validation_solid.md).
      placement: ``"surface"`` (``n`` rows with the outer ones *on* the beam's faces and a
        column on the tip, spacing ``H / (n - 1)``, as TrixiParticles.jl and DualSPHysics
        set the benchmark up; the default; use an odd ``n`` so a row lies on the centre
        line) or ``"cell"`` (particles at the centres of ``n x n_x`` square cells that tile
        the beam, spacing ``H / n``; the set-up of earlier versions).
      embedded_root: with ``clamp="cylinder"``, also make the beam's band inside the
        cylinder's right half free particles (the beam runs on into the cylinder up to its
        centre, held by the clamped particles above and below it), as TrixiParticles.jl
        does (the default); ``False`` clamps the beam at the cylinder's surface.
    """
    if placement not in ("cell", "surface"):
        raise ValueError(f"placement must be 'cell' or 'surface', got {placement!r}")
    n = check_resolution("n", n, 2 if placement == "cell" else 3)
    E = check_positive("young_modulus", young_modulus)
    rho = check_positive("density", density)
    if not gravity >= 0:
        raise ValueError(f"gravity must be >= 0 (it points down), got {gravity}")
    centre, radius = np.array([0.2, 0.2]), 0.05
    x_root, thickness, length = 0.25, 0.02, 0.35
    y_low = 0.2 - 0.5 * thickness
    surface = placement == "surface"
    dx = thickness / (n - 1) if surface else thickness / n
    nx = int(round(length / dx)) + (1 if surface else 0)
    offset = 0.0 if surface else 0.5  # lattice sites at (i + offset) dx from the root
    kernel = as_kernel(kernel)
    if h_factor is None:
        h_factor = 2**0.5 if surface else 1.2
    h = check_positive("h_factor", h_factor) * dx
    cutoff = kernel.support * h
    n_back = int(math.ceil(2.0 * radius / dx)) + 1
    n_up = int(math.ceil((radius + 2.0 * cutoff) / dx))
    i = np.arange(-n_back, 0)
    j = np.arange(-n_up, n + n_up)
    gx, gy = np.meshgrid(x_root + (i + offset) * dx, y_low + (j + offset) * dx, indexing="ij")
    cyl = np.stack([gx.ravel(), gy.ravel()], axis=-1)
    # lattice sites in the beam's band (its faces included with surface placement)
    in_band = (cyl[:, 1] > y_low - 0.25 * dx) & (cyl[:, 1] < y_low + thickness + 0.25 * dx)
    if clamp == "cylinder":
        inside = np.linalg.norm(cyl - centre, axis=-1) <= radius
    elif clamp == "strip":
        inside = in_band
    else:
        raise ValueError(f"clamp must be 'cylinder' or 'strip', got {clamp!r}")
    # distance to the free beam, the rectangle [x_start, x_root + L] x [y_low, y_low + H]
    # (an embedded root starts at the cylinder's centre)
    x_start = centre[0] if embedded_root and clamp == "cylinder" else x_root
    gap_y = np.maximum(0.0, np.maximum(y_low - cyl[:, 1], cyl[:, 1] - (y_low + thickness)))
    gap_x = np.maximum(0.0, x_start - cyl[:, 0])
    near = np.hypot(gap_x, gap_y) < 2.0 * cutoff
    clamped = cyl[inside & near]
    beam = _strip(x_root + (offset - 0.5) * dx, y_low + (offset - 0.5) * dx, nx, n, dx)
    if clamp == "cylinder" and fill_root:
        # The cylinder's surface lies left of x = 0.25 at the beam's edges (x = 0.24899 at
        # y = 0.19 and 0.21): lattice sites of the beam's band outside the circle are beam
        # material.  Left out, they would leave a notch at the root's outer fibres, where
        # the bending stress is largest, whenever a site falls between the arc and 0.25.
        band = in_band & (cyl[:, 0] > centre[0])
        free = band & ~inside
        if embedded_root:
            free = free | (band & inside & (cyl[:, 0] >= centre[0] - 1e-9))
        beam = np.concatenate([cyl[free], beam])
        clamped = cyl[inside & near & ~free]
    x = np.concatenate([beam, clamped])
    kind = np.concatenate([np.full(len(beam), Kind.SOLID), np.full(len(clamped), Kind.CLAMPED)])
    kind = kind.astype(np.int32)
    params = make_params(
        2,
        young_modulus=E,
        poisson_ratio=poisson_ratio,
        solid_density=rho,
        gravity=(0.0, -gravity),
        penalty_alpha=0.0 if penalty_alpha is None else penalty_alpha,
    )
    domain = Domain((0.0, -0.2), (1.0, 0.61), (False, False))
    model = _solid_model(kernel, h, domain, penalty_alpha is not None)
    info = dict(
        n=n,
        spacings=n - 1 if surface else n,  # dx = 0.02 / spacings
        young_modulus=E,
        cylinder_centre=(0.2, 0.2),
        cylinder_radius=radius,
        tip_point=(0.6, 0.2),
        centre_line=0.2,
        reference=dict(TUREK_HRON_CSM3),
        reference_steady=dict(TUREK_HRON_STEADY[E]) if E in TUREK_HRON_STEADY else None,
    )
    return _finish("turek_hron_csm", x, 0.0, kind, dx, rho, model, params, t_end, info, cfl)
