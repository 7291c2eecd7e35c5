"""Open boundaries (issue 34): a channel with an inflow and an outflow.

``sphjax.cases.channel_flow``: fluid enters at ``x = 0`` through an inflow buffer with a
prescribed velocity profile and leaves at ``x = L`` through an outflow buffer; the buffers'
particles are recycled at fixed capacity (:mod:`sphjax.physics.open_boundary`).  Checked
here: the steady plane Poiseuille profile downstream, the mass flux along the channel
against the inflow's, a run of three flow-through times that stays stable, the gradient
of a run with respect to the viscosity against finite differences, the trade of places
at fixed capacity, and the errors for bad input.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _room import with_room

import sphjax
from sphjax.cases import channel_flow
from sphjax.core.state import Kind
from sphjax.observables import (
    channel_mass_flux,
    channel_profile,
    channel_startup_profile,
    poiseuille_profile,
)
from sphjax.physics.open_boundary import Inflow, OpenBoundarySystem, Outflow, recycle

#: flow-through times of the validation run
FLOW_THROUGHS = 3.0
#: time between frames of the validation run, in H / U
SAMPLE = 0.0371


@pytest.fixture(scope="module")
def channel():
    """A channel 2 H long, 10 particles across, parabolic inflow at Re = 10, run for three
    flow-through times (6 H / U, about 4,000 steps), a frame every 24 steps (0.036 H / U,
    a time in which no lattice row moves a whole number of spacings: frames in step with
    the rows would sample the slabs stroboscopically)."""
    case = channel_flow(n=10, length=2.0, profile="parabolic")
    save_every = max(1, round(SAMPLE / case.dt))
    # room for the rows that fill against the buffers: one compilation, not two
    trajectory = sphjax.simulate(
        with_room(case),
        t_end=FLOW_THROUGHS * case.info["flow_through_time"],
        save_every=save_every,
    )
    return case, trajectory


def _late(trajectory):
    """The frames of the last flow-through time (the flow steady)."""
    start = int(len(trajectory) * (FLOW_THROUGHS - 1.0) / FLOW_THROUGHS)
    return jax.tree_util.tree_map(lambda a: a[start:], trajectory.states)


def _inflow_flux(case):
    """The mass flux the inflow buffer carries in: its lattice rows, ``m / dx`` per unit
    length each, at the prescribed speeds (the midpoint rule of ``rho int u dy``)."""
    dx, H = case.info["dx"], case.info["height"]
    y = (np.arange(case.info["n"]) + 0.5) * dx
    u = poiseuille_profile(y, H, case.info["inflow_velocity"])
    mass = float(np.asarray(case.state.mass)[np.asarray(case.state.kind) == Kind.OPEN][0])
    return mass / dx * float(np.sum(u))


@pytest.mark.slow
def test_the_steady_profile_downstream_is_plane_poiseuille(channel):
    """Over the last flow-through time, the mean speed per lattice row between 0.6 L and
    0.9 L is ``4 u_max y (H - y) / H^2`` within 2 % of ``u_max`` (the largest error of the
    10 rows; measured 1.2 %)."""
    case, trajectory = channel
    L, H, U = case.info["length"], case.info["height"], case.info["inflow_velocity"]
    y, u = channel_profile(_late(trajectory), case, 0.6 * L, 0.9 * L)
    exact = poiseuille_profile(y, H, U)
    error = np.max(np.abs(u - exact)) / case.info["peak_velocity"]
    assert error < 0.02, f"profile error {error:.4f} of u_max"


@pytest.mark.slow
def test_the_mass_flux_in_equals_the_mass_flux_out(channel):
    """The mass flux across the channel, averaged over the last flow-through time, near
    the inflow (0.1 L), half-way and near the outflow (0.9 L) equals the inflow's within
    1 % (measured within 0.3 %).  Each is a slab estimate (``sum m u / width`` over a slab
    2 dx wide) from about 55 frames, whose sampling scatter is a few tenths of a percent;
    recycling itself conserves mass exactly (one particle out of the outflow for each
    into the inflow)."""
    case, trajectory = channel
    L, dx = case.info["length"], case.info["dx"]
    late = _late(trajectory)
    inflow = _inflow_flux(case)
    fluxes = [channel_mass_flux(late, case, x - dx, x + dx) for x in (0.1 * L, 0.5 * L, 0.9 * L)]
    assert np.allclose(np.asarray(fluxes) / inflow, 1.0, atol=0.01), fluxes


@pytest.mark.slow
def test_three_flow_through_times_stay_stable(channel):
    """No particle is lost (each system keeps its count, every fluid particle stays between
    the walls and inside the channel or its buffers), nothing is NaN, and the fluid's
    density stays within 3 % of rho0 (the steady pressure drop is 1.2 % of rho0 c0^2)."""
    case, trajectory = channel
    states = trajectory.states
    kind = np.asarray(states.kind)
    assert (kind == np.asarray(case.state.kind)[None]).all()
    x = np.asarray(states.position)
    assert np.isfinite(x).all() and np.isfinite(np.asarray(states.velocity)).all()
    fluid = kind == Kind.FLUID
    H, L, dx = case.info["height"], case.info["length"], case.info["dx"]
    y = x[..., 1][fluid]
    assert y.min() > 0.0 and y.max() < H
    along = x[..., 0][fluid]
    assert along.min() >= 0.0 and along.max() < L + case.info["buffer_width"]
    rho = np.asarray(states.density)[fluid] / float(case.params.reference_density)
    assert np.abs(rho - 1.0).max() < 0.03
    # the fluid near each plane is fluid that came in (no gap opens at the inflow)
    last = x[-1][fluid[-1]][:, 0]
    assert last.min() < 0.5 * dx and last.max() > L - dx
    assert float(trajectory.times[-1]) >= FLOW_THROUGHS * case.info["flow_through_time"] - 1e-9


@pytest.mark.slow
def test_the_flow_started_from_a_plug_develops_as_the_series_solution():
    """The fluid starts as a plug of speed U (the inflow parabolic): between 0.4 and 0.8 L
    the profile follows plane Poiseuille flow started at a constant flow rate
    (:func:`channel_startup_profile`; its slowest mode decays in 0.12 H / U) within 2 %
    of u_max (the largest error over the 20 rows, in one frame) at t = 0.1, 0.2 and 0.3
    H / U.  A weakly compressible fluid holds the flow rate through pressure waves, so
    the comparison needs a sound speed well above the viscous one (``c0 = 40 u_max``:
    the channel's acoustic time 0.025 H / U) and a resolution of the wall layers (at
    n = 10 the error is 5 % at t = 0.1)."""
    case = channel_flow(
        n=20, length=1.5, profile="parabolic", initial_profile="uniform", sound_speed_factor=40.0
    )
    L, H, U, nu = (case.info[k] for k in ("length", "height", "inflow_velocity", "viscosity"))
    # room for the rows that fill as the flow starts: one compilation
    trajectory = sphjax.simulate(with_room(case), t_end=0.3, save_every=round(0.1 / case.dt))
    errors = []
    for k in range(1, len(trajectory)):
        t = float(trajectory.times[k])
        y, u = channel_profile(trajectory.frame(k), case, 0.4 * L, 0.8 * L)
        exact = channel_startup_profile(y, t, H, U, nu)
        errors.append(np.max(np.abs(u - exact)) / case.info["peak_velocity"])
    assert len(errors) == 3 and max(errors) < 0.02, errors


def test_the_trade_keeps_every_block_and_moves_the_inflow_row_back():
    """:func:`recycle` by hand: one inflow particle past ``x_in``, one fluid particle past
    ``x_out`` (and one upstream of it), one outflow particle past the buffer's end."""
    inflow = Inflow(plane=0.0, width=1.0, velocity=1.0)
    outflow = Outflow(plane=5.0, width=1.0)
    x = np.array([[2.0, 0.5], [5.2, 0.5], [-0.5, 0.3], [0.1, 0.7], [5.5, 0.4], [6.3, 0.6]])
    kind = [Kind.FLUID, Kind.FLUID, Kind.OPEN, Kind.OPEN, Kind.OPEN, Kind.OPEN]
    velocity = np.arange(12.0).reshape(6, 2)
    state = sphjax.make_state(x, velocity, 1000.0, 1.0, kind)
    out = recycle(state, inflow, outflow)
    assert (np.asarray(out.kind) == np.asarray(state.kind)).all()
    position, v = np.asarray(out.position), np.asarray(out.velocity)
    np.testing.assert_allclose(position[1], [0.1, 0.7])  # a new fluid particle at x_in
    np.testing.assert_allclose(v[1], velocity[3])
    np.testing.assert_allclose(position[3], [-0.9, 0.7])  # the inflow row goes on
    np.testing.assert_allclose(position[5], [5.2, 0.5])  # the fluid particle, now outflow
    np.testing.assert_allclose(v[5], [velocity[1, 0], 0.0])  # its speed along the channel
    np.testing.assert_allclose(position[[0, 2, 4]], x[[0, 2, 4]])
    # nothing to trade without an outflow particle past the end: all wait
    waiting = recycle(state.replace(position=state.position.at[5, 0].set(5.9)), inflow, outflow)
    np.testing.assert_allclose(np.asarray(waiting.position)[:5], x[:5])


def test_the_gradient_wrt_viscosity_matches_finite_differences():
    """``jax.grad`` of the fluid's momentum after 60 steps (past the first trades at the
    planes) with respect to the kinematic viscosity, against central differences."""
    case = channel_flow(n=4, length=1.0, profile="parabolic")  # float64 (tests/conftest.py)
    n_steps = 60

    def momentum(nu):
        params = case.params.replace(kinematic_viscosity=nu)
        final = sphjax.simulate(case, params, n_steps=n_steps).final
        fluid = final.kind == Kind.FLUID
        return jnp.sum(jnp.where(fluid, final.mass * final.velocity[:, 0], 0.0))

    final = sphjax.simulate(case, n_steps=n_steps).final
    fluid = np.asarray(final.kind) == Kind.FLUID
    assert np.asarray(final.position)[fluid, 0].min() < 0.5 * case.info["dx"]  # traded
    nu = float(case.params.kinematic_viscosity)
    grad = float(jax.jit(jax.grad(momentum))(nu))
    step = 1e-4 * nu
    fd = (float(momentum(nu + step)) - float(momentum(nu - step))) / (2 * step)
    assert grad < 0  # more viscous: the no-slip walls slow the fluid more
    assert grad == pytest.approx(fd, rel=1e-5)


def test_bad_input_gets_one_line_naming_the_argument():
    with pytest.raises(ValueError, match=r"^inflow_velocity must be a positive number") as err:
        channel_flow(n=4, inflow_velocity=-1.0)
    assert "\n" not in str(err.value)
    with pytest.raises(ValueError, match=r"^buffer_width = .* narrower than the kernel support"):
        channel_flow(n=4, buffer_width=0.3)
    with pytest.raises(ValueError, match=r"^Inflow.velocity must be a positive number"):
        Inflow(plane=0.0, width=1.0, velocity=-2.0)
    with pytest.raises(ValueError, match=r"^Inflow.profile must be 'uniform' or 'parabolic'"):
        Inflow(plane=0.0, width=1.0, velocity=1.0, profile="plug")
    with pytest.raises(ValueError, match=r"^Outflow.plane .* downstream of Inflow.plane"):
        OpenBoundarySystem(Inflow(0.0, 1.0, 1.0), Outflow(plane=-1.0, width=1.0))
    with pytest.raises(ValueError, match=r"^Outflow.width = .* narrower than the kernel"):
        OpenBoundarySystem(Inflow(0.0, 1.0, 1.0), Outflow(2.0, 0.5)).check_support(0.75)


def test_the_diffrax_route_refuses_open_boundaries():
    with pytest.raises(ValueError, match=r"^OpenBoundarySystem: .* run in sphjax.simulate only"):
        sphjax.diffeqsolve_case(channel_flow(n=4), t1=0.01)


def test_parameters_the_channel_does_not_read_are_refused():
    case = channel_flow(n=4)
    with pytest.raises(sphjax.UnusedParameterError, match=r"^artificial_alpha is not used"):
        case.params.replace(artificial_alpha=0.1)
    assert "kinematic_viscosity" in case.params.used


def test_channel_flow_runs_from_the_command_line(tmp_path):
    """``sphjax run channel_flow``: a short run at the coarsest resolution, read back."""
    from sphjax.cli import main

    out = tmp_path / "channel.h5"
    argv = ["run", "channel_flow", "--n", "4", "--t-end", "0.02", "--quiet", "--out", str(out)]
    assert main(argv) == 0
    trajectory, meta = sphjax.read_trajectory(out)
    assert meta["complete"] and meta["case"] == "channel_flow"
    kind = np.asarray(trajectory.states.kind)
    assert (kind == Kind.OPEN).any() and np.isfinite(np.asarray(trajectory.states.position)).all()
