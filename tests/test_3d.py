"""Three-dimensional cases against exact and published references (issue 12).

CI sizes (6^3 to 10^3 fluid particles, a few hundred steps).  Reference numbers:

* ABC flow (Arnold 1965, Childress 1970; Dombre et al. 1986): with ``A = B = C = U``,
  ``u(x, t) = u(x, 0) exp(-nu k^2 t)`` solves the incompressible Navier-Stokes
  equations, so ``KE(t) / KE0 = exp(-2 nu k^2 t)``.
* Hydrostatic column: ``p = rho0 g (H - z)``, bottom pressure ``rho0 g H``.
* Duct flow (White, *Viscous Fluid Flow*): the steady profile is White's series; its
  centre speed in a square duct of half-side ``a`` is ``0.2947 F a^2 / nu`` (White's
  table for b / a = 1), and for ``b -> infinity`` it is the plane ``F (a^2 - y^2) / (2 nu)``.
* Square-section cantilever: Euler-Bernoulli ``omega = (kL)^2 sqrt(E I / (rho A L^4))``,
  ``kL = 1.8751``, ``I = H^4 / 12`` (no plane-strain factor): with Gray, Monaghan &
  Swift's (2001) plate numbers (L = 0.2 m, H = 0.02 m, E = 2e6 Pa, nu = 0.3975,
  rho = 1000 kg/m^3) the period is 0.2541 s / sqrt(1 - nu^2) = 0.2769 s and the tip
  amplitude V_f c0 / omega = 2.51e-3 m for V_f = 0.001.

docs/validation_3d.md has the larger resolutions and the convergence tables.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sphjax
from sphjax.cases import (
    abc_pressure,
    abc_velocity,
    duct_velocity,
    oscillation_stats,
    tip_displacement,
)

PLATE_PERIOD_2D = 0.2541  # s, Gray, Monaghan & Swift (2001), plane strain
PLATE_POISSON = 0.3975


def _rms(a):
    return float(np.sqrt(np.mean(np.square(a))))


@pytest.mark.parametrize(
    "name, n, kwargs",
    [
        ("abc_flow_3d", 8, dict(relax_iterations=20)),
        ("hydrostatic_tank_3d", 4, {}),
        ("cantilever_3d", 4, {}),
        ("duct_poiseuille_3d", 4, {}),
        ("dam_break_3d", 4, {}),
        ("spheric_dam_break_3d", 4, {}),
        ("hydrostatic_fsi_plate_3d", 4, dict(length=0.2, depth=0.05, substeps=1)),
    ],
)
def test_3d_cases_are_registered_and_three_dimensional(name, n, kwargs):
    case = sphjax.cases.get(name, n=n, **kwargs)
    assert name in sphjax.cases.CASES and case.name == name
    assert case.model.dim == 3 and case.model.domain.dim == 3
    assert case.state.position.shape == (case.n_particles, 3)
    assert case.params.gravity.shape == (3,)
    assert case.info["n"] == n
    assert sphjax.cases.get(name, dx=case.info["dx"], **kwargs).info["n"] == n


def test_abc_flow_needs_the_kernel_support_under_half_the_box():
    with pytest.raises(ValueError, match=r"^n must be an integer >= 8"):
        sphjax.cases.abc_flow_3d(n=7)
    with pytest.raises(ValueError, match=r"dx=0.2 is too coarse.*use dx <= 0.125"):
        sphjax.cases.get("abc_flow_3d", dx=0.2, relax_iterations=20)


@pytest.mark.slow
def test_abc_flow_kinetic_energy_and_velocity_field():
    """ABC flow, Re = 50, 10^3 particles, to t = 0.3 (about 25 s of CPU time).

    Tolerances: KE/KE0 within 2 % of exp(-2 nu k^2 t) at every saved frame (the
    Taylor-Green test allows 5 % at t = 0.5 with 50^2 particles; measured here -0.9 % at
    t = 0.3); KE never rises between frames; the velocity field within 2 % rms of the
    exact one at the first frame (t = 0.03; measured 0.9 %) and within 12 % up to t = 0.3
    (measured 10.9 %: the particle noise of the relaxed start at 10 particles per
    wavelength; 8 % at n = 12 and 6 % at n = 16 by t = 0.5, docs/validation_3d.md).
    The pressure of the start (the right-hand side's first evaluation) is the exact one
    (within 3 % rms)."""
    case = sphjax.cases.abc_flow_3d(n=10)
    assert case.model.dim == 3 and case.n_particles == 1000
    info = case.info
    k, nu = info["wavenumber"], info["viscosity"]
    assert nu == pytest.approx(1.0 / 50.0) and k == pytest.approx(2 * np.pi)

    neighbors = sphjax.build_neighbors(case.state, case.model)
    rates = jax.jit(sphjax.evaluate, static_argnums=2)(
        case.state, neighbors, case.model, case.params
    )
    x, p = np.asarray(case.state.position), np.asarray(rates.pressure)
    p_exact = abc_pressure(x, 0.0, case)
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
    first acoustic transit (the 2D test's tolerance; measured +0.9 to +2.4 %, as the 2D
    tank's +1.9 %), no particle through the floor or a side wall, the largest speed on
    the last two frames below 1 % of sqrt(g H) (measured 0.24 %) and falling (below half
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


def test_duct_reference_series():
    """White's series against its limits and the start-up series at long times (100
    terms: truncation error below 1e-6 of the peak)."""
    a, nu, F = 0.5e-3, 1e-6, 2e-4
    assert duct_velocity(0.0, 0.0, a, a, nu, F) == pytest.approx(0.2947 * F * a**2 / nu, rel=1e-3)
    y = np.linspace(-a, a, 9)
    plane = F * (a**2 - y**2) / (2 * nu)
    np.testing.assert_allclose(
        duct_velocity(y, 0.0, a, 100 * a, nu, F), plane, atol=1e-6 * plane.max()
    )
    z = np.linspace(-0.6 * a, 0.6 * a, 5)[:, None]
    steady = duct_velocity(y, z, a, 0.6 * a, nu, F)
    late = duct_velocity(y, z, a, 0.6 * a, nu, F, t=100.0)
    np.testing.assert_allclose(late, steady, atol=1e-6 * steady.max())
    assert np.all(duct_velocity(y, z, a, 0.6 * a, nu, F, t=0.0) == 0.0)


@pytest.mark.slow
def test_duct_poiseuille_startup_and_white_profile():
    """Square duct 10 x 10 particles across (800 fluid, 1248 wall particles), 0.5 s
    (400 steps, about 25 s).  Tolerances of the 2D Poiseuille test: the centre speed
    within 5 % of the start-up series at t = 0.1, 0.2, 0.3 s (measured +1.0 to +2.8 %)
    and within 3 % of White's steady value at t = 0.5 s (steady to 1e-4; measured
    +2.8 %, +1.0 % in 2D at 20 across; docs/validation_3d.md has 8 to 16 across); the
    whole profile within 3 % rms of the centre speed (measured 2.5 %); no cross-flow."""
    case = sphjax.cases.duct_poiseuille_3d(n=10)
    info = case.info
    a, b, dx, nu, F = info["width"] / 2, info["height"] / 2, info["dx"], 1e-6, 2e-4
    assert (info["viscosity"], info["body_force"]) == (nu, F)
    frames, t_end = 5, 0.5
    n_steps = frames * int(np.ceil(t_end / case.dt / frames))
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=n_steps // frames, dt=t_end / n_steps)
    times = np.asarray(traj.times)
    np.testing.assert_allclose(times, [0.0, 0.1, 0.2, 0.3, 0.4, 0.5], atol=1e-12)
    fluid = np.asarray(case.state.kind) == sphjax.Kind.FLUID
    for i, t in enumerate(times):
        if i == 0:
            continue
        x = np.asarray(traj.states.position[i])[fluid]
        v = np.asarray(traj.states.velocity[i])[fluid]
        y, z = x[:, 1] - a, x[:, 2] - b
        near = (np.abs(y) < 0.6 * dx) & (np.abs(z) < 0.6 * dx)
        assert near.sum() == 4 * info["length"] / dx
        steady = t == times[-1]
        exact = duct_velocity(y, z, a, b, nu, F, t=None if steady else t)
        centre = v[near, 0].mean()
        assert centre == pytest.approx(exact[near].mean(), rel=0.03 if steady else 0.05), t
        assert np.abs(v[:, 1:]).max() < 1e-3 * info["centre_speed"]
    assert _rms(v[:, 0] - exact) < 0.03 * info["centre_speed"]


# (case, arguments): particles, dt, sum of positions, sum of densities, as built before
# the tank cases shared one assembly (sphjax/cases/fluid.py::_water_tank)
TANK_CASES_BEFORE = [
    ("hydrostatic_tank", dict(n=6), 114, 0.0019954714587537, 90.50000024586916, 114176.5349121),
    (
        "dam_break",
        dict(n=4, column_width=1.2, column_height=0.6, tank_length_factor=2.6833),
        89,
        0.0023185282968048297,
        140.40000158548355,
        89009.95361328125,
    ),
    ("hydrostatic_tank_3d", dict(n=4), 784, 0.00299320718813055, 966.0, 784313.8955078125),
    ("dam_break_3d", dict(n=4), 2708, 0.0005796320742012074, 2986.0499945878983, 2708159.208984),
]


@pytest.mark.parametrize("name, kwargs, particles, dt, x_sum, rho_sum", TANK_CASES_BEFORE)
def test_tank_cases_build_as_before(name, kwargs, particles, dt, x_sum, rho_sum):
    """The 2D and 3D tank and dam-break cases build the same particles, time step and
    hydrostatic densities as before their assembly was shared (checked leaf by leaf when
    it was; these sums pin it to float32 rounding: they were taken in float32)."""
    case = sphjax.cases.get(name, **kwargs)
    assert case.n_particles == particles
    assert case.dt == pytest.approx(dt, rel=1e-6)
    assert float(np.sum(np.asarray(case.state.position, np.float64))) == pytest.approx(
        x_sum, rel=1e-6
    )
    assert float(np.sum(np.asarray(case.state.density, np.float64))) == pytest.approx(
        rho_sum, rel=1e-6
    )


@pytest.mark.parametrize(
    "name, particles, dt, x_sum, speed_sum",
    [
        ("cantilever_3d", 720, 5.255538152511226e-05, 62.99999976158142, 14.28712528932374),
        ("oscillating_plate", 180, 2.5751412548408248e-05, 15.749999940395355, 3.571781322330935),
    ],
)
def test_beam_cases_build_as_before(name, particles, dt, x_sum, speed_sum):
    """The 2D plate and the 3D cantilever build the same particles, time step and initial
    first-mode velocity as before they shared their argument checks, mode velocity and
    Params (sphjax/cases/solid.py; checked leaf by leaf then, pinned here)."""
    case = sphjax.cases.get(name, n=4)
    assert case.n_particles == particles
    assert case.dt == pytest.approx(dt, rel=1e-6)
    x = np.asarray(case.state.position, np.float64)
    v = np.asarray(case.state.velocity, np.float64)
    assert float(np.sum(x)) == pytest.approx(x_sum, rel=1e-6)
    assert float(np.sum(np.abs(v))) == pytest.approx(speed_sum, rel=1e-6)


def test_spheric_dam_break_geometry_and_gauges():
    """SPHERIC benchmark 2 as built (no simulation): the tank, the column across the full
    width against the far wall, the box of wall particles where Kleefsman et al. (2005)
    put it, no fluid inside it, and the gauges reading the initial state: 0.55 m in the
    reservoir (H4), dry elsewhere."""
    from sphjax.cases import spheric_dam_break_3d, water_height
    from sphjax.observables import probe_pressure

    n = 6
    case = spheric_dam_break_3d(n=n)
    info, dx = case.info, 0.55 / n
    x, kind = np.asarray(case.state.position), np.asarray(case.state.kind)
    fluid = x[kind == sphjax.Kind.FLUID]
    L, W, H = info["tank"]
    assert abs(L - 3.22) <= dx / 2 and abs(W - 1.0) <= dx / 2 and abs(H - 1.0) <= dx / 2
    assert len(fluid) == round(1.228 / dx) * round(1.0 / dx) * n
    assert fluid[:, 0].max() < L and fluid[:, 0].min() > L - 1.228 - dx / 2
    assert fluid[:, 2].max() < 0.55 and fluid[:, 1].min() < dx and fluid[:, 1].max() > W - dx
    # the box 0.161 x 0.403 x 0.161 m, faces at x = 0.6635 and 0.8245, centred across
    lo, hi = np.array([0.6635, 0.2985, 0.0]), np.array([0.8245, 0.7015, 0.161])
    inside = np.all((x > lo) & (x < hi), axis=1)
    centres = [np.arange(0.5, 60) * dx for _ in range(3)]
    expected = np.prod([np.sum((c > a) & (c < b)) for c, a, b in zip(centres, lo, hi, strict=True)])
    assert inside.sum() == info["box_particles"] == expected > 0
    assert np.all(kind[inside] == sphjax.Kind.WALL)
    heights = {g: float(water_height(case.state, case, xy)) for g, xy in info["gauges"].items()}
    assert heights["H4"] == pytest.approx(0.55, rel=0.01)
    assert heights["H1"] == heights["H2"] == heights["H3"] == 0.0
    sensors = info["sensors"]
    assert float(probe_pressure(case.state, case, sensors["P1"])) == 0.0


@pytest.mark.slow
def test_spheric_dam_break_runs_and_reaches_the_gauges():
    """A smoke test of SPHERIC benchmark 2 at 4 particles over the column's height
    (252 fluid and 2 646 wall particles, t = 0.3 s: 270 steps, about 27 s of CPU time,
    mostly compilation): the surge reaches the gauge H3 half a metre ahead of the column,
    the reservoir (H4) drains, no particle leaves the tank or enters the box.  The
    experiment reads H3 = 0.070 m and H4 = 0.486 m at t = 0.3 s (Kleefsman et al. 2005);
    the comparison at 8 particles is in docs/validation_3d.md."""
    from sphjax.cases import spheric_dam_break_3d, water_height

    case = spheric_dam_break_3d(n=4)
    info = case.info
    n_steps = int(round(0.3 / case.dt))
    final = sphjax.simulate(case, n_steps=n_steps).final
    h3 = float(water_height(final, case, info["gauges"]["H3"]))
    h4 = float(water_height(final, case, info["gauges"]["H4"]))
    assert 0.02 < h3 < 0.2 and 0.35 < h4 < 0.53
    fluid = np.asarray(final.kind) == sphjax.Kind.FLUID
    x = np.asarray(final.position)[fluid]
    L, W, _ = info["tank"]
    assert np.all(x[:, 2] > 0) and np.all((x[:, 1] > 0) & (x[:, 1] < W))
    assert np.all((x[:, 0] > 0) & (x[:, 0] < L))
    lo, hi = (np.asarray(c) for c in info["box"])
    assert not np.any(np.all((x > lo) & (x < hi), axis=1))


def _tip_stats(case, t_end):
    save_every = 20
    n_steps = save_every * int(np.ceil(t_end / case.dt / save_every))
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=save_every)
    u = np.asarray(tip_displacement(traj, case))
    return oscillation_stats(np.asarray(traj.times), u[:, 1]), u


@pytest.mark.slow
def test_cantilever_3d_against_euler_bernoulli_and_the_2d_plate():
    """Square-section beam, 4 x 4 particles per section (720 particles, 10 500 steps,
    about 25 s), against Euler-Bernoulli with no plane-strain factor.

    At 4 particles across the SPH beam is too soft in bending, as the 2D plate is at the
    same resolution (the 2D plate converges to within 4 % at 12 across,
    docs/validation_solid.md; the 3D beam in docs/validation_3d.md).  So the test
    compares the 3D errors with the 2D plate's at the same H / dx, run here: period and
    amplitude errors within 2 points of the 2D ones (measured +24.2 / +20.6 % in 3D,
    +25.1 / +21.2 % in 2D), both positive and below 30 %; were the plane-strain factor
    left in (the 2D period in 3D), the period error would differ by 8.6 points.  The beam
    stays in its plane (tip z displacement below 1e-4 of the amplitude) and oscillates
    about 0."""
    case = sphjax.cases.cantilever_3d(n=4)
    info = case.info
    assert case.model.dim == 3 and len(info["tip_indices"]) == 4
    assert info["period"] == pytest.approx(
        PLATE_PERIOD_2D / np.sqrt(1 - PLATE_POISSON**2), rel=2e-3
    )
    assert info["tip_amplitude"] == pytest.approx(2.51e-3, rel=2e-3)
    stats, u = _tip_stats(case, 0.55)
    period_error = stats["period"] / info["period"] - 1
    amplitude_error = stats["amplitude"] / info["tip_amplitude"] - 1

    plate = sphjax.cases.oscillating_plate(n=4, cfl=0.5)
    assert plate.info["period"] == pytest.approx(PLATE_PERIOD_2D, rel=1e-3)
    plate_stats, _ = _tip_stats(plate, 0.55)
    plate_period_error = plate_stats["period"] / plate.info["period"] - 1
    plate_amplitude_error = plate_stats["amplitude"] / plate.info["tip_amplitude"] - 1

    assert 0 < period_error < 0.3 and 0 < amplitude_error < 0.3, stats
    assert abs(period_error - plate_period_error) < 0.02, (stats, plate_stats)
    assert abs(amplitude_error - plate_amplitude_error) < 0.02, (stats, plate_stats)
    assert np.abs(u[:, 2]).max() < 1e-4 * info["tip_amplitude"]
    assert abs(stats["mean"]) < 0.05 * info["tip_amplitude"]


def _gradient_check(loss, x0, step):
    """``(grad, central difference, jvp)`` of ``loss`` at ``x0`` (float64)."""
    grad = float(jax.jit(jax.grad(loss))(x0))
    f = jax.jit(loss)
    fd = float((f(x0 + step) - f(x0 - step)) / (2.0 * step))
    _, tangent = jax.jit(lambda a: jax.jvp(loss, (a,), (jnp.ones_like(a),)))(x0)
    return grad, fd, float(tangent)


@pytest.mark.slow
def test_abc_flow_kinetic_energy_gradient_wrt_viscosity():
    """d(KE after 60 steps)/d(nu), ABC flow 8^3 (512 particles, relaxed start), float64,
    central FD step 1e-5 (nu = 0.02): relative error <= 1e-5 (measured 5.8e-10);
    forward (jvp) vs reverse <= 1e-8 (about 30 s)."""
    case = sphjax.cases.abc_flow_3d(n=8)

    def loss(nu):
        params = case.params.replace(kinematic_viscosity=nu)
        final = sphjax.simulate(case, params, n_steps=60, checkpoint_every=10).final
        return 0.5 * jnp.sum(final.mass[:, None] * final.velocity**2)

    grad, fd, tangent = _gradient_check(loss, case.params.kinematic_viscosity, 1e-5)
    print(f"ABC d KE / d nu: grad {grad:.10g} fd {fd:.10g} rel {abs(grad / fd - 1):.2e}")
    assert grad < 0  # more viscosity, less kinetic energy
    assert abs(grad / fd - 1) <= 1e-5
    assert abs(tangent / grad - 1) <= 1e-8


@pytest.mark.slow
def test_cantilever_3d_tip_gradient_wrt_young_modulus():
    """d(tip u_y after 1000 steps)/dE, cantilever 2 x 2 particles per section (100
    particles, t = 0.1 s), float64, central FD with relative step 1e-5: relative error
    <= 1e-5 (measured 5.7e-7; 5.8e-5 with step 1e-4 and 5.7e-3 with 1e-3, the truncation
    error of the difference, falling as step^2); forward vs reverse <= 1e-8 (about 15 s).
    The initial velocity V_f c0 f(x / L) follows E through c0 (``case.state_for``)."""
    case = sphjax.cases.cantilever_3d(n=2)

    def loss(E):
        params = case.params.replace(young_modulus=E)
        final = sphjax.simulate(case, params, n_steps=1000, checkpoint_every=50).final
        return tip_displacement(final.position, case)[0, 1]

    E0 = case.params.young_modulus
    grad, fd, tangent = _gradient_check(loss, E0, 1e-5 * float(E0))
    print(f"cantilever d u_y / d E: grad {grad:.10g} fd {fd:.10g} rel {abs(grad / fd - 1):.2e}")
    assert grad != 0.0
    assert abs(grad / fd - 1) <= 1e-5
    assert abs(tangent / grad - 1) <= 1e-8


def test_plot_slice_of_a_3d_trajectory(tmp_path, capsys):
    """``sphjax plot --slice z=0``: only the particles within one kernel support of the
    plane are drawn, in x and y; a bad slice gets one line naming --slice (exit 2)."""
    from sphjax.cli import main
    from sphjax.io import read_trajectory
    from sphjax.plot import FramePlot, parse_slice

    case = sphjax.cases.cantilever_3d(n=2)
    path = tmp_path / "beam.h5"
    with sphjax.TrajectoryWriter(path, case) as writer:
        sphjax.simulate(case, n_steps=2, save_every=1, on_frames=writer)
    assert main(["plot", str(path), "--slice", "z=0.005", "--out", str(tmp_path / "s.png")]) == 0
    assert (tmp_path / "s.png").stat().st_size > 0
    assert (
        main(
            [
                "plot",
                str(path),
                "--slice",
                "y=0",
                "--field",
                "kind",
                "--out",
                str(tmp_path / "k.png"),
            ]
        )
        == 0
    )

    trajectory, meta = read_trajectory(path, frames=-1)
    x = np.asarray(trajectory.states.position)[0]
    support = case.model.cutoff
    z = 0.5 * case.info["thickness"] + 0.6 * support  # the upper layer only (z = +dx/2)
    figure = FramePlot(trajectory, meta, "velocity", slice_plane=parse_slice(f"z={z}"))
    drawn = figure.points.get_offsets()
    expected = np.abs(x[:, 2] - z) <= support
    assert 0 < expected.sum() < len(x) and len(drawn) == expected.sum()
    np.testing.assert_allclose(np.sort(drawn[:, 0]), np.sort(x[expected, 0]), rtol=1e-6)
    assert figure.ax.get_ylabel().startswith("y") and "z = " in figure.title.get_text()
    figure.close()
    assert parse_slice("X = 0.25") == (0, 0.25)

    capsys.readouterr()
    for bad, message in [
        ("w=1", "AXIS=VALUE"),
        ("z=", "AXIS=VALUE"),
        ("z=9", "no particle within"),
    ]:
        assert main(["plot", str(path), "--slice", bad, "--out", str(tmp_path / "b.png")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--slice" in err[0] and message in err[0], err
    plate = sphjax.cases.oscillating_plate(n=2)
    flat = tmp_path / "plate.h5"
    with sphjax.TrajectoryWriter(flat, plate) as writer:
        sphjax.simulate(plate, n_steps=1, on_frames=writer)
    assert main(["plot", str(flat), "--slice", "z=0", "--out", str(tmp_path / "p.png")]) == 2
    assert "needs a 3D trajectory" in capsys.readouterr().err


@pytest.mark.slow
def test_cantilever_3d_young_modulus_recovered_by_calibrate():
    """Identical twin: the tip history (100 frames over 2000 steps, 0.21 s) of the 2 x 2
    cantilever at E = 2e6, fitted from E = 1.5e6 by ``sphjax.calibrate`` (forward mode,
    L-BFGS directions with capped steps): E within 1e-4 (measured 2.5e-7 in 6
    iterations; about 15 s).  The initial velocity follows E, as in the case."""
    import optax

    from sphjax.calibration import calibrate

    case = sphjax.cases.cantilever_3d(n=2)

    def observables(params):
        traj = sphjax.simulate(case, params, n_steps=2000, save_every=20, checkpoint_every=20)
        return tip_displacement(traj, case)[1:, 1]

    observed = observables(case.params)
    optimizer = optax.chain(
        optax.scale_by_lbfgs(), optax.clip_by_global_norm(0.1), optax.scale(-1.0)
    )
    result = calibrate(
        observables,
        observed,
        case.params,
        {"young_modulus": 1.5e6},
        optimizer,
        40,
        loss_tolerance=1e-10,
        verbose=False,
    )
    assert abs(result.values["young_modulus"] / 2.0e6 - 1) < 1e-4, result.values
    assert result.iterations <= 20


def test_a_3d_run_with_gravity_is_drawn_from_the_side(tmp_path):
    """Gravity along -z: the default view is the x-z projection with z upwards (the tank
    extends equally in x and y, so y, the second, is the axis looked along); without
    gravity, or in a file that does not record it, the x-y projection."""
    import h5py

    from sphjax.io import read_trajectory, write_trajectory
    from sphjax.plot import FramePlot, projection_axes

    case = sphjax.cases.hydrostatic_tank_3d(n=4)
    assert np.asarray(case.params.gravity).tolist() == [0.0, 0.0, -9.81]
    frames = jax.tree_util.tree_map(lambda a: a[None], case.state)
    trajectory = sphjax.Trajectory(states=frames, times=np.zeros(1))
    x = np.asarray(case.state.position)

    def drawn(path):
        figure = FramePlot(*read_trajectory(path), "kind")
        out = (
            figure.axes,
            figure.ax.get_xlabel()[0] + figure.ax.get_ylabel()[0],
            figure.title.get_text(),
            figure.ax.yaxis_inverted(),
            np.asarray(figure.points.get_offsets()),
        )
        figure.close()
        return out

    side = write_trajectory(tmp_path / "tank.h5", trajectory, case)
    axes, labels, title, inverted, offsets = drawn(side)
    assert axes == (0, 2) and labels == "xz" and "(x-z projection)" in title and not inverted
    np.testing.assert_allclose(offsets, x[:, [0, 2]], rtol=1e-6)

    still = case.params.replace(gravity=np.zeros(3))
    top = write_trajectory(tmp_path / "still.h5", trajectory, case, params=still)
    assert drawn(top)[:2] == ((0, 1), "xy") and "(x-y projection)" in drawn(top)[2]
    with h5py.File(side, "a") as f:  # a file written before gravity was recorded
        del f["params"]
    assert drawn(side)[:2] == ((0, 1), "xy")

    # the view is along the shorter horizontal extent; gravity along +axis turns it upside down
    meta = {"params": case.params.replace(gravity=np.array([0.0, 9.81, 0.0]))}
    assert projection_axes(x * np.array([1.0, 1.0, 3.0]), meta) == (2, 1, True)
    assert projection_axes(x * np.array([3.0, 1.0, 1.0]), meta) == (0, 1, True)
    assert projection_axes(x, {"params": case.params}) == (0, 2, False)
    assert projection_axes(x * np.array([1.0, 2.0, 1.0]), {"params": case.params}) == (1, 2, False)
