"""Three-dimensional cases against exact and published references (issue 12).

CI sizes (6^3 to 10^3 fluid particles, a few hundred steps).  Reference numbers:

* ABC flow (Arnold 1965, Childress 1970; Dombre et al. 1986): with ``A = B = C = U``,
  ``u(x, t) = u(x, 0) exp(-nu k^2 t)`` solves the incompressible Navier-Stokes
  equations, so ``KE(t) / KE0 = exp(-2 nu k^2 t)``.
* Hydrostatic column: ``p = rho0 g (H - z)``, bottom pressure ``rho0 g H``.

docs/validation_3d.md has the larger resolutions and the convergence tables.
"""

from __future__ import annotations

import numpy as np
import pytest

import sphjax
from sphjax.cases import abc_pressure, abc_velocity


def _rms(a):
    return float(np.sqrt(np.mean(np.square(a))))


@pytest.mark.slow
def test_abc_flow_kinetic_energy_and_velocity_field():
    """ABC flow, Re = 50, 10^3 particles, to t = 0.3 (about 30 s).

    Tolerances: KE/KE0 within 2 % of exp(-2 nu k^2 t) at every saved frame (the
    Taylor-Green test allows 5 % at t = 0.5 with 50^2 particles; measured here -0.9 % at
    t = 0.3); KE never rises between frames; the velocity field within 2 % rms of the
    exact one at the first frame (t = 0.03; measured 0.9 %) and within 12 % up to t = 0.3
    (measured 10.9 %: the particle noise of the relaxed start at 10 particles per
    wavelength; 8 % at n = 12 and 6 % at n = 16 by t = 0.5, docs/validation_3d.md).
    The pressure at the first step is the exact one (within 3 % rms)."""
    case = sphjax.cases.abc_flow_3d(n=10)
    assert case.model.dim == 3 and case.n_particles == 1000
    info = case.info
    k, nu = info["wavenumber"], info["viscosity"]
    assert nu == pytest.approx(1.0 / 50.0) and k == pytest.approx(2 * np.pi)

    one = sphjax.simulate(case, n_steps=1)
    x, p = np.asarray(one.final.position), np.asarray(one.final.pressure)
    p_exact = abc_pressure(x, float(one.times[-1]), case)
    assert _rms(p - p_exact) < 0.03 * _rms(p_exact)

    frames, t_end = 10, 0.3
    n_steps = frames * int(np.ceil(t_end / case.dt / frames))
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=n_steps // frames, dt=t_end / n_steps)
    t = np.asarray(traj.times)
    assert t[-1] == pytest.approx(t_end)
    v = np.asarray(traj.states.velocity)
    m = np.asarray(traj.states.mass)
    ke = 0.5 * np.sum(m * np.sum(v**2, -1), -1)
    exact = np.exp(-2 * nu * k**2 * t)
    np.testing.assert_allclose(ke / ke[0], exact, rtol=0.02)
    assert np.all(np.diff(ke) < 0)
    u_exact = abc_velocity(np.asarray(traj.states.position), t[:, None], case)
    error = np.sqrt(
        np.mean(np.sum((v - u_exact) ** 2, -1), -1) / np.mean(np.sum(u_exact**2, -1), -1)
    )
    assert error[1] < 0.02, error
    assert error.max() < 0.12, error


@pytest.mark.slow
def test_hydrostatic_tank_3d_holds_still():
    """p = rho0 g (H - z): bottom pressure within 3 % of rho0 g H at every frame after the
    first acoustic transit (the 2D test's tolerance; measured +1.5 to +2.4 %, as the 2D
    tank's +1.9 %), no particle through the floor or a side wall, the largest speed on
    the last two frames below 1 % of sqrt(g H) (measured 0.23 %) and falling (below half
    its largest value over the run).  H = 1 m, 8 particles over the depth, a 0.5 x 0.5 m
    tank (128 fluid particles, 1140 wall particles), 0.6 s (about 25 s)."""
    case = sphjax.cases.hydrostatic_tank_3d(n=8, width=0.5)
    info = case.info
    g, H, W, D = info["gravity"], info["height"], info["width"], info["depth"]
    assert case.model.dim == 3 and (W, D) == (0.5, 0.5)
    assert np.asarray(case.params.gravity) == pytest.approx([0.0, 0.0, -g])
    frames = 8
    n_steps = frames * int(np.ceil(0.6 / case.dt / frames))
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=n_steps // frames)
    fluid = np.asarray(case.state.kind) == sphjax.Kind.FLUID
    x = np.asarray(traj.states.position)[:, fluid]
    p = np.asarray(traj.states.pressure)[:, fluid]
    assert np.all(x[..., 2] > 0)
    assert np.all((x[..., 0] > 0) & (x[..., 0] < W) & (x[..., 1] > 0) & (x[..., 1] < D))
    for i in range(2, frames + 1):
        # bottom pressure: least-squares line p(z) through the fluid, evaluated at z = 0
        slope, bottom = np.polyfit(x[i, :, 2], p[i], 1)
        assert bottom == pytest.approx(1000.0 * g * H, rel=0.03), (i, bottom)
    speed = np.linalg.norm(np.asarray(traj.states.velocity)[:, fluid], axis=-1).max(axis=-1)
    assert speed[-2:].max() < 0.01 * np.sqrt(g * H)
    assert speed[-1] < 0.5 * speed.max()
