"""Three-dimensional elastic-solid case: a square-section cantilever (total-Lagrangian SPH).

:func:`cantilever_3d` is the oscillating plate of Gray, Monaghan & Swift (2001)
(:func:`sphjax.cases.oscillating_plate`) with a square ``H x H`` section instead of plane
strain: released with the first bending mode as velocity profile, its period and tip
amplitude are compared with Euler-Bernoulli theory, ``omega = (kL)^2 sqrt(E I / (rho A
L^4))``, ``I = H^4 / 12``, ``A = H^2`` (no plane-strain factor ``1 - nu^2``).
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from sphjax.cases._geometry import lattice
from sphjax.cases.solid import (
    PLATE_KL,
    _beam_arguments,
    _beam_params,
    _finish,
    _first_mode_velocity,
    _solid_model,
    plate_sound_speed,
)
from sphjax.core.case import Case
from sphjax.core.kernels import as_kernel
from sphjax.core.model import Domain
from sphjax.core.state import Kind


def beam_angular_frequency(length, thickness, young_modulus, density, kL: float = PLATE_KL):
    """Euler-Bernoulli first mode of a clamped-free beam of square section ``H x H``:
    ``omega = (kL)^2 sqrt(E I / (rho A L^4))`` with ``I = H^4 / 12``, ``A = H^2``, i.e.
    ``omega^2 = E H^2 k^4 / (12 rho)`` (jax.numpy or floats)."""
    k = kL / length
    return jnp.sqrt(young_modulus * thickness**2 * k**4 / (12.0 * density))


def cantilever_reference(case: Case, params=None) -> dict:
    """Euler-Bernoulli reference of a :func:`cantilever_3d` case for ``params`` (default
    ``case.params``; jax.numpy): ``sound_speed``, ``omega``, ``period`` and
    ``tip_amplitude = V_f c0 / omega``."""
    p = case.params if params is None else params
    info = case.info
    omega = beam_angular_frequency(
        info["length"], info["thickness"], p.young_modulus, p.solid_density
    )
    c0 = plate_sound_speed(p)
    return dict(
        sound_speed=c0,
        omega=omega,
        period=2.0 * jnp.pi / omega,
        tip_amplitude=info["amplitude"] * c0 / omega,
    )


def cantilever_3d(
    n: int = 4,
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
    cfl: float = 0.5,
    t_end: float = 0.4,
) -> Case:
    """Square-section cantilever ``[0, L] x [-H/2, H/2]^2``, clamped over ``clamp_length``.

    The three-dimensional counterpart of :func:`sphjax.cases.oscillating_plate` (Gray,
    Monaghan & Swift 2001): the beam continues into ``[-clamp_length, 0]`` as clamped
    particles (those within two kernel supports of the beam), St Venant-Kirchhoff with
    ``E = 2e6``, ``nu = 0.3975``, ``rho = 1000``, and starts with the transverse velocity
    ``v_y(x) = V_f c0 f(x / L)`` (first mode shape :func:`sphjax.cases.plate_mode_shape`,
    ``c0 = sqrt(E / (3 (1 - 2 nu)) / rho)``).  Euler-Bernoulli: ``omega^2 = E H^2 k^4 /
    (12 rho)``, ``kL = 1.8751``: period 0.2768 s and tip amplitude ``V_f c0 / omega =
    2.51e-3 m`` with the defaults (:func:`cantilever_reference`).

    The initial velocity follows the parameters (``case.state_for(params)``), as the
    plate's does.

    Args:
      n: particles across the section's side (``dx = H / n``; ``n^2`` per section).
      amplitude: ``V_f``.
      penalty_alpha: ``None`` (no penalty force) or Ganzenmüller's ``alpha``.
      cfl: solid Courant number of the time step.
    """
    n, L, H, E, rho, dx, nx, n_clamp = _beam_arguments(
        n, length, thickness, young_modulus, density, amplitude, clamp_length
    )
    kernel = as_kernel(kernel)
    h = h_factor * dx
    # clamped particles further than two kernel supports from the beam cannot act on it
    n_clamp = min(n_clamp, int(math.ceil(2.0 * kernel.support * h / dx)))
    x = lattice([-n_clamp * dx, -0.5 * H, -0.5 * H], [nx * dx, 0.5 * H, 0.5 * H], dx)
    kind = np.where(x[:, 0] > 0.0, Kind.SOLID, Kind.CLAMPED).astype(np.int32)
    order = np.argsort(kind, kind="stable")  # the solid's block: solid, then clamped
    x, kind = x[order], kind[order]
    velocity_fn = _first_mode_velocity(x, kind, amplitude, L)
    params = _beam_params(3, E, poisson_ratio, rho, penalty_alpha)
    margin = L
    domain = Domain(
        (-clamp_length - margin, -margin, -margin), (L + margin, margin, margin), (False,) * 3
    )
    model = _solid_model(kernel, h, domain, penalty_alpha is not None)
    omega = float(beam_angular_frequency(L, H, E, rho))
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
        centre_line=(0.0, 0.0),
    )
    return _finish(
        "cantilever_3d", x, 0.0, kind, dx, rho, model, params, t_end, info, cfl, velocity_fn
    )


__all__ = ["cantilever_3d", "cantilever_reference", "beam_angular_frequency"]
