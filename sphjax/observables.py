"""Observables: what is measured on a trajectory, apart from the set-ups that produce it.

* :func:`surge_front` — the dam-break surge front ``Z`` (Martin & Moyce 1952);
* :func:`probe_pressure` — the pressure the fluid exerts at a probe point (a wall sensor);
* :func:`poiseuille_centreline_speed` — the channel's centre-line speed;
* :func:`channel_profile`, :func:`channel_mass_flux` — the velocity profile and the
  mass flux across a channel with an inflow and an outflow (against
  :func:`poiseuille_profile` and :func:`channel_startup_profile`);
* :func:`centreline_profiles` — a lid-driven cavity's centreline velocities at Ghia, Ghia
  & Shin's (1982) points;
* :func:`tip_displacement` — the displacement of a solid's tip probe (plate, Turek-Hron);
* :func:`oscillation_stats` — mean, amplitude and period of a signal;
* :func:`energy_budget` — kinetic, gravitational, fluid internal (Tait) and elastic strain
  energies of a coupled run (:func:`kinetic_energy`, :func:`gravitational_energy`,
  :func:`tait_internal_energy`, :func:`strain_energy`);
* :func:`momentum_budget` — total momentum of the moving particles against the impulse of
  the forces on them.

Each reads the probes the case put in ``case.info``.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from sphjax.core import kernels
from sphjax.core.case import Case
from sphjax.core.space import displacement_fn
from sphjax.core.state import Kind
from sphjax.physics.fluid.eos import TaitEOS
from sphjax.physics.fluid.system import FluidSystem
from sphjax.physics.solid.correction import (
    corrected_kernel_gradient,
    correction_matrix,
    correction_moment,
)
from sphjax.physics.solid.deformation import deformation_term
from sphjax.physics.solid.material import (
    green_lagrange_strain,
    lame_constants,
    st_venant_kirchhoff_energy,
)


def poiseuille_centreline_speed(state, case: Case) -> float:
    """Centreline speed ``u(L/2)`` of a Poiseuille state.

    With an even number of rows the centreline lies between the rows at ``L/2 -+ dx/2``;
    their mean speed is corrected by the curvature of the parabola,
    ``F / (2 nu) (dx / 2)^2``.
    """
    info = case.info
    L, dx = info["width"], info["dx"]
    fluid = np.asarray(state.kind) == Kind.FLUID
    y = np.asarray(state.position)[fluid, 1]
    u = np.asarray(state.velocity)[fluid, 0]
    near = np.abs(y - L / 2) < 0.6 * dx
    curvature = info["body_force"] / (2 * info["viscosity"]) * (dx / 2) ** 2
    return float(np.mean(u[near])) + curvature


def poiseuille_profile(y, height, mean_velocity):
    """Plane Poiseuille flow of mean speed ``U``: ``u(y) = 4 u_max y (H - y) / H^2``,
    ``u_max = 1.5 U`` (``y`` from the lower wall)."""
    y = np.asarray(y, float)
    return 6.0 * mean_velocity * y * (height - y) / height**2


def channel_startup_profile(y, t, height, mean_velocity, viscosity, terms: int = 40):
    """Plane Poiseuille flow started from a plug at a constant flow rate: ``u(y, t)``
    for ``u(y, 0) = U``, no slip at ``y = 0, H`` and ``int u dy = U H`` held by the
    pressure gradient.  With ``eta = y - H/2``, ``u = u_P(y) + sum_j a_j phi_j(eta)
    exp(-nu k_j^2 t)``, ``phi_j = cos(k_j eta) - cos(k_j H / 2)`` (no net flow, so the
    pressure gradient takes the constant part), ``tan(k_j H / 2) = k_j H / 2``, and
    ``a_j`` the projections of ``U - u_P`` on the ``phi_j`` (orthogonal: the operator is
    symmetric on the functions of zero mean).  ``u_P``: :func:`poiseuille_profile`."""
    from scipy.optimize import brentq

    H, U, nu = float(height), float(mean_velocity), float(viscosity)
    y = np.asarray(y, float)
    grid = (np.arange(4000) + 0.5) / 4000 * H  # midpoint quadrature of the projections
    initial = U - poiseuille_profile(grid, H, U)
    u = poiseuille_profile(y, H, U)
    for j in range(terms):
        # the root of tan(z) = z in (j pi + pi/2 ... (j + 1) pi + pi/2), z = k H / 2
        z = brentq(lambda z: np.sin(z) - z * np.cos(z), (j + 1) * np.pi, (j + 1.5) * np.pi - 1e-9)
        k = 2.0 * z / H

        def phi(yy, k=k):
            return np.cos(k * (yy - H / 2)) - np.cos(k * H / 2)

        a = np.sum(initial * phi(grid)) / np.sum(phi(grid) ** 2)
        u = u + a * phi(y) * np.exp(-nu * k**2 * np.asarray(t, float))
    return u


def _slab(states, x0, x1):
    """Positions and velocities of the fluid particles of ``states`` (one State or a
    Trajectory's, frames stacked) with ``x0 <= x < x1``, each frame's in one array."""
    kind = np.asarray(states.kind).reshape(-1)
    x = np.asarray(states.position).reshape(-1, 2)
    v = np.asarray(states.velocity).reshape(-1, 2)
    keep = (kind == Kind.FLUID) & (x[:, 0] >= x0) & (x[:, 0] < x1)
    return x[keep], v[keep]


def channel_profile(states, case: Case, x0: float, x1: float):
    """``(y, u)``: the mean speed along the channel of the fluid particles between ``x0``
    and ``x1``, per lattice row (bins of ``dx`` across the channel), averaged over the
    frames of ``states`` (a State or a Trajectory's ``states``); ``y`` the bins' centres."""
    H, dx = case.info["height"], case.info["dx"]
    x, v = _slab(states, x0, x1)
    rows = int(round(H / dx))
    index = np.clip(np.floor(x[:, 1] / dx).astype(int), 0, rows - 1)
    count = np.bincount(index, minlength=rows)
    total = np.bincount(index, weights=v[:, 0], minlength=rows)
    y = (np.arange(rows) + 0.5) * dx
    return y, total / np.maximum(count, 1)


def channel_mass_flux(states, case: Case, x0: float, x1: float) -> float:
    """The mass flux across the channel (per unit depth) at the slab ``[x0, x1)``:
    ``sum_a m_a u_a / (x1 - x0)`` over its fluid particles, ``= int rho u dy`` on
    average, averaged over the frames of ``states``."""
    frames = max(1, int(np.prod(np.asarray(states.time).shape)))
    kind = np.asarray(states.kind).reshape(-1)
    x = np.asarray(states.position).reshape(-1, 2)
    m = np.asarray(states.mass).reshape(-1)
    u = np.asarray(states.velocity).reshape(-1, 2)[:, 0]
    keep = (kind == Kind.FLUID) & (x[:, 0] >= x0) & (x[:, 0] < x1)
    return float(np.sum(m[keep] * u[keep]) / (x1 - x0) / frames)


def surge_front(states, case: Case):
    """Surge front ``Z / L`` of a dam break: the rightmost fluid particle plus ``dx / 2``.

    ``states`` may carry a leading time axis.
    """
    x = states.position[..., 0]
    fluid = states.kind == Kind.FLUID
    front = jnp.max(jnp.where(fluid, x, -jnp.inf), axis=-1) + 0.5 * case.info["dx"]
    return front / case.info["column_width"]


def probe_pressure(states, case: Case, point):
    """Fluid pressure at a probe ``point`` (a pressure sensor on a wall), the kernel
    (Shepard) average over the fluid particles within one support of it:

        p(x) = sum_f p_f W(x - x_f) V_f / sum_f W(x - x_f) V_f,     V_f = m_f / rho_f,

    with the case's kernel and smoothing length; 0 where no fluid particle is within the
    support (the sensor is dry).  Wall particles are left out: their pressure is itself
    extrapolated from the fluid.  A probe on a wall's face sees fluid on one side only,
    which the normalisation accounts for.

    Args:
      states: a State (or a Trajectory's ``states``), with or without a leading time axis.
      point: ``[d]`` probe position, e.g. ``(case.info["tank_length"], 0.16)`` on the
        right wall of a dam break (:func:`sphjax.cases.dam_break_wall_sensors`).
    Returns:
      the pressure, ``[T]`` or a scalar; differentiable (jax.numpy).
    """
    states = getattr(states, "states", states)
    model = case.model
    point = jnp.asarray(point, states.position.dtype)
    r = jnp.linalg.norm(states.position - point, axis=-1)
    fluid = states.kind == Kind.FLUID
    weight = kernels.W(model.kernel, r, model.smoothing_length, model.dim)
    weight = jnp.where(fluid & (r < model.cutoff), weight * states.mass / states.density, 0.0)
    total = jnp.sum(weight, axis=-1)
    wet = total > 0
    average = jnp.sum(weight * states.pressure, axis=-1) / jnp.where(wet, total, 1.0)
    return jnp.where(wet, average, 0.0)


#: Ghia, Ghia & Shin (1982), Table I: the heights ``y / L`` of their u-velocity samples on
#: the vertical centreline (the walls, y = 0 and 1, left out)
GHIA_Y = (
    0.9766, 0.9688, 0.9609, 0.9531, 0.8516, 0.7344, 0.6172, 0.5000,
    0.4531, 0.2813, 0.1719, 0.1016, 0.0703, 0.0625, 0.0547,
)  # fmt: skip
#: Ghia, Ghia & Shin (1982), Table II: the abscissae ``x / L`` of their v-velocity samples
#: on the horizontal centreline (the walls, x = 0 and 1, left out)
GHIA_X = (
    0.9688, 0.9609, 0.9531, 0.9453, 0.9063, 0.8594, 0.8047, 0.5000,
    0.2344, 0.2266, 0.1563, 0.0938, 0.0781, 0.0703, 0.0625,
)  # fmt: skip


def _kernel_velocity(states, case: Case, points):
    """Shepard-normalised kernel average of the fluid velocity at ``points`` (``[P, d]``):
    ``v(x) = sum_f v_f W(x - x_f) V_f / sum_f W(x - x_f) V_f``, ``V_f = m_f / rho_f``;
    ``[..., P, d]``, 0 where no fluid particle lies within the support."""
    model = case.model
    position = states.position[..., None, :, :]  # [..., 1, N, d]
    r = jnp.linalg.norm(position - points[:, None, :], axis=-1)  # [..., P, N]
    fluid = (states.kind == Kind.FLUID)[..., None, :]
    volume = (states.mass / states.density)[..., None, :]
    weight = kernels.W(model.kernel, r, model.smoothing_length, model.dim)
    weight = jnp.where(fluid & (r < model.cutoff), weight * volume, 0.0)
    total = jnp.sum(weight, axis=-1)
    wet = total > 0
    summed = jnp.einsum("...pn,...nd->...pd", weight, states.velocity)
    return jnp.where(wet[..., None], summed / jnp.where(wet, total, 1.0)[..., None], 0.0)


def centreline_profiles(trajectory, case: Case, y=None, x=None):
    """Centreline velocities of a lid-driven cavity, as Ghia, Ghia & Shin (1982) tabulate
    them: ``u(y)`` on the vertical centreline ``x = L/2`` (their Table I) and ``v(x)`` on
    the horizontal one ``y = L/2`` (Table II), in units of the lid speed ``U``.

    Each is the kernel (Shepard) average of the fluid velocity (as in
    :func:`probe_pressure`) with the case's kernel and smoothing length.

    Args:
      trajectory: a :class:`sphjax.Trajectory` or a State, with or without a leading time
        axis.
      case: the :func:`sphjax.cases.lid_driven_cavity` it was run from.
      y, x: sample positions in units of ``L`` (default Ghia's interior points,
        :data:`GHIA_Y` and :data:`GHIA_X`).
    Returns:
      ``(u, v)``: ``[..., len(y)]`` and ``[..., len(x)]`` over ``U``; differentiable.
    """
    states = getattr(trajectory, "states", trajectory)
    L, U = case.info["length"], case.info["lid_speed"]
    dtype = states.position.dtype
    y = jnp.asarray(GHIA_Y if y is None else y, dtype) * L
    x = jnp.asarray(GHIA_X if x is None else x, dtype) * L
    vertical = jnp.stack([jnp.full_like(y, 0.5 * L), y], axis=-1)
    horizontal = jnp.stack([x, jnp.full_like(x, 0.5 * L)], axis=-1)
    u = _kernel_velocity(states, case, vertical)[..., 0] / U
    v = _kernel_velocity(states, case, horizontal)[..., 1] / U
    return u, v


def tip_displacement(trajectory, case: Case):
    """Tip displacement ``x - X`` of ``case.info["tip_indices"]`` (averaged), ``[T, d]``.

    Args:
      trajectory: a :class:`sphjax.Trajectory`, a State (with or without a leading time
        axis) or a ``[T, N, d]`` / ``[N, d]`` position array.
      case: the Case the trajectory was run from.
    Returns:
      ``[T, d]`` displacement of the probe; differentiable (jax.numpy).
    """
    states = getattr(trajectory, "states", trajectory)
    position = getattr(states, "position", states)
    position = jnp.asarray(position)
    idx = jnp.asarray(case.info["tip_indices"])
    anchor = case.state.reference_position[idx]
    if position.ndim == 2:
        position = position[None]
    return jnp.mean(position[:, idx, :] - anchor, axis=-2)


def oscillation_stats(times, signal) -> dict:
    """Mean, amplitude, period and frequency of an oscillating signal (numpy).

    ``mean = (max + min) / 2`` and ``amplitude = (max - min) / 2`` over the whole signal
    (the convention of the Turek-Hron tables); the period is the mean spacing of
    successive crossings of the mean level in the same direction (linear interpolation),
    ``nan`` with fewer than two crossings in one direction.
    """
    t = np.asarray(times, float)
    s = np.asarray(signal, float)
    top, bottom = s.max(), s.min()
    mean = 0.5 * (top + bottom)
    d = s - mean
    spacings = []
    for rising in (True, False):
        sel = (d[:-1] < 0) & (d[1:] >= 0) if rising else (d[:-1] > 0) & (d[1:] <= 0)
        k = np.flatnonzero(sel)
        tc = t[k] - d[k] * (t[k + 1] - t[k]) / (d[k + 1] - d[k])
        spacings.extend(np.diff(tc))
    period = float(np.mean(spacings)) if spacings else float("nan")
    return dict(
        mean=float(mean),
        amplitude=float(0.5 * (top - bottom)),
        period=period,
        frequency=1.0 / period if spacings else float("nan"),
    )


def _states(trajectory):
    return getattr(trajectory, "states", trajectory)


def _of_kinds(states, kinds):
    kind = states.kind
    return jnp.any(jnp.stack([kind == k for k in kinds]), axis=0)


#: the particles that move: fluid and (free) solid
MOVING = (Kind.FLUID, Kind.SOLID)


def kinetic_energy(trajectory, kinds=MOVING):
    """Kinetic energy ``K = sum_a m_a |v_a|^2 / 2`` over the particles of ``kinds``,
    ``[T]`` (or a scalar for one State); jax.numpy."""
    s = _states(trajectory)
    speed2 = jnp.sum(s.velocity**2, axis=-1)
    return 0.5 * jnp.sum(jnp.where(_of_kinds(s, kinds), s.mass * speed2, 0.0), axis=-1)


def gravitational_energy(trajectory, case: Case, kinds=MOVING):
    """Gravitational potential energy ``V = -sum_a m_a g . x_a`` (zero at the origin) over
    the particles of ``kinds``, ``[T]``; its decrease is the work of gravity."""
    s = _states(trajectory)
    g = jnp.asarray(case.params.gravity, s.position.dtype)
    height = -jnp.sum(s.position * g, axis=-1)
    return jnp.sum(jnp.where(_of_kinds(s, kinds), s.mass * height, 0.0), axis=-1)


def tait_internal_energy(trajectory, case: Case):
    """Internal (compression) energy of a weakly compressible fluid with the Tait equation
    of state (formulation eq. 12, ``p = B ((rho / rho0)^gamma - 1)``, ``B = rho0 c0^2 /
    gamma``), ``U_f = sum_f m_f e(rho_f)`` with ``de = p / rho^2 drho``:

        e(rho) = B (rho^(gamma-1) - rho0^(gamma-1)) / ((gamma - 1) rho0^gamma)
                 + B (1 / rho - 1 / rho0),

    zero at ``rho0``.  With continuity density (eq. 11) and the symmetric pressure term
    (eq. 10) the fluid's pressure work on itself is exchanged with this energy exactly
    (Monaghan 2005, section 5); ``[T]``."""
    s = _states(trajectory)
    fluid = case.params.fluid
    eos = case.model.system(FluidSystem).equation_of_state
    if not isinstance(eos, TaitEOS):
        raise ValueError(
            f"tait_internal_energy needs a fluid with TaitEOS, got {type(eos).__name__}; "
            "build the case with the Tait equation of state or leave the internal energy out"
        )
    gamma = eos.gamma
    rho0, c0 = fluid.reference_density, fluid.sound_speed
    B = rho0 * c0**2 / gamma
    rho = jnp.where(s.kind == Kind.FLUID, s.density, rho0)
    e = B * (rho ** (gamma - 1) - rho0 ** (gamma - 1)) / ((gamma - 1) * rho0**gamma) + B * (
        1.0 / rho - 1.0 / rho0
    )
    return jnp.sum(jnp.where(s.kind == Kind.FLUID, s.mass * e, 0.0), axis=-1)


def strain_energy(trajectory, case: Case):
    """Elastic strain energy of the TLSPH solid, ``U_s = sum_a V0_a psi(E(F_a))`` over its
    free and clamped particles, with the St Venant-Kirchhoff energy density
    (:func:`~sphjax.physics.solid.material.st_venant_kirchhoff_energy`, eqs. 17-19), ``F_a``
    from eq. 16 with the correction matrix of eq. 15 on the reference configuration, over
    all pairs of the solid within the kernel support (minimum image on periodic axes; dense
    pairs: the solid is small).  The solid's momentum equation (eq. 14) is the variational
    discretisation of this energy: its elastic forces are ``-dU_s / dx_a``.  ``[T]`` (or a
    scalar for one State)."""
    s = _states(trajectory)
    model = case.model
    displacement = displacement_fn(model.domain)
    solid = np.flatnonzero(np.asarray(case.state.kind) >= Kind.SOLID)
    X = jnp.asarray(case.state.reference_position)[solid]
    V = jnp.asarray(case.state.volume)[solid]
    dX = displacement(X[:, None, :], X[None, :, :])
    R = jnp.linalg.norm(dX, axis=-1)
    near = (R < model.cutoff) & (R > 0)
    grad = kernels.grad_W(model.kernel, dX, jnp.where(near, R, 1.0), model.smoothing_length,
                          model.dim)  # fmt: skip
    reference = _DensePairs(dr=dX, grad_w=jnp.where(near[..., None], grad, 0.0))
    moment = jnp.sum(correction_moment(reference, V[None, :]), axis=1)  # eq. 15
    corrected = corrected_kernel_gradient(correction_matrix(moment)[:, None], reference.grad_w)
    lam, mu = lame_constants(case.params.solid.young_modulus, case.params.solid.poisson_ratio)

    def energy(x):
        dx = displacement(x[:, None, :], x[None, :, :])
        F = jnp.sum(deformation_term(dx, corrected, V[None, :]), axis=1)  # eq. 16
        return jnp.sum(V * st_venant_kirchhoff_energy(green_lagrange_strain(F), lam, mu))

    x = jnp.asarray(s.position)[..., solid, :]
    if x.ndim == 2:
        return energy(x)
    return jax.jit(jax.vmap(energy))(x)


@dataclasses.dataclass(frozen=True)
class _DensePairs:
    """All pairs of a small particle set, as :func:`correction_moment` reads them."""

    dr: jax.Array
    grad_w: jax.Array


def energy_budget(trajectory, case: Case) -> dict:
    """Energies of a fluid-structure run, each ``[T]`` (numpy): ``fluid_kinetic``,
    ``fluid_potential`` (gravity), ``fluid_internal`` (:func:`tait_internal_energy`),
    ``solid_kinetic``, ``solid_potential``, ``solid_strain`` (:func:`strain_energy`), and
    ``total``, their sum.  Walls and clamped particles do not move, so in the continuum
    they do no work and ``total`` is conserved but for the scheme's dissipation
    (artificial viscosity, no-slip walls, delta-SPH's density diffusion); gravity's work
    is in the potentials."""
    out = dict(
        fluid_kinetic=kinetic_energy(trajectory, (Kind.FLUID,)),
        fluid_potential=gravitational_energy(trajectory, case, (Kind.FLUID,)),
        fluid_internal=tait_internal_energy(trajectory, case),
        solid_kinetic=kinetic_energy(trajectory, (Kind.SOLID,)),
        solid_potential=gravitational_energy(trajectory, case, (Kind.SOLID,)),
        solid_strain=strain_energy(trajectory, case),
    )
    out = {k: np.asarray(v, float) for k, v in out.items()}
    out["total"] = sum(out.values())
    return out


def momentum_budget(trajectory, case: Case) -> dict:
    """Total linear momentum ``P = sum_a m_a v_a`` of the moving (fluid and free solid)
    particles, ``[T, d]``, against the impulse ``J(t) = int_0^t sum_a m_a (a_a - g) dt``
    of the forces on them apart from gravity (trapezoidal rule over the saved frames;
    ``a_a`` the acceleration the state holds).  Fluid-solid pair forces cancel in the sum
    (equal and opposite), so ``J`` is the impulse of the walls and the clamp; along a
    direction without gravity ``P(t) - P(0) = J(t)``, up to the quadrature error of the
    frames' spacing (the kick-drift-kick step itself applies ``(a_n + a_{n+1}) dt / 2``).
    Returns numpy ``time``, ``momentum``, ``impulse`` and ``wall_force`` (``[T, d]``)."""
    s = _states(trajectory)
    moving = np.asarray(_of_kinds(s, MOVING))
    m = np.asarray(s.mass)
    v = np.asarray(s.velocity)
    a = np.asarray(s.acceleration) - np.asarray(case.params.gravity)
    weight = np.where(moving, m, 0.0)[..., None]
    momentum = np.sum(weight * v, axis=-2)
    force = np.sum(weight * a, axis=-2)
    t = np.asarray(s.time, float)
    steps = np.diff(t)[:, None] * 0.5 * (force[1:] + force[:-1])
    impulse = np.concatenate([np.zeros_like(force[:1]), np.cumsum(steps, axis=0)])
    return dict(time=t, momentum=momentum, impulse=impulse, wall_force=force)
