"""Bad input gets a clear error naming the argument; an unstable run names step and particle
and keeps the frames it had written."""

from __future__ import annotations

import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sphjax
import sphjax.integration.simulate
from sphjax.io import TrajectoryWriter, check_writable, read_trajectory


@pytest.fixture(scope="module")
def tg():
    return sphjax.cases.get("taylor_green", n=8)


# ---------------------------------------------------------------------------- case set-up


def test_unknown_case_lists_the_available_ones():
    with pytest.raises(ValueError, match="unknown case 'nope'") as err:
        sphjax.cases.get("nope")
    for name in sphjax.cases.CASES:
        assert name in str(err.value)


def test_unknown_case_argument_is_named():
    with pytest.raises(ValueError, match="no argument 'resolution'.*accepts n,"):
        sphjax.cases.get("taylor_green", resolution=10)


@pytest.mark.parametrize("name", sorted(sphjax.cases.CASES))
@pytest.mark.parametrize("n", [0, -5, 2.5, "ten"])
def test_bad_resolution(name, n):
    with pytest.raises(ValueError, match=r"^n must be an integer >= \d+"):
        sphjax.cases.get(name, n=n)


@pytest.mark.parametrize("value", ["no", 0, None])
def test_pair_adjoint_must_be_a_bool(tg, value):
    with pytest.raises(ValueError, match="Model.pair_adjoint must be True or False"):
        tg.model.replace(pair_adjoint=value)


@pytest.mark.parametrize("dx", [0.0, -0.1, float("nan"), float("inf")])
def test_non_positive_spacing(dx):
    with pytest.raises(ValueError, match="^dx must be a positive number"):
        sphjax.cases.get("taylor_green", dx=dx)


def test_spacing_too_coarse_says_the_largest_allowed():
    with pytest.raises(ValueError, match=r"dx=0.5 is too coarse.*use dx <= 0.25"):
        sphjax.cases.get("taylor_green", dx=0.5)


def test_spacing_maps_onto_resolution():
    case = sphjax.cases.get("dam_break", dx=0.3 / 6)
    assert case.info["n"] == 6 and case.info["dx"] == pytest.approx(0.05)
    with pytest.raises(ValueError, match="either n or dx"):
        sphjax.cases.get("taylor_green", n=8, dx=0.1)


@pytest.mark.parametrize("t_end", [-1.0, 0.0, float("nan")])
def test_non_positive_end_time(t_end):
    with pytest.raises(ValueError, match="^t_end must be a positive number"):
        sphjax.cases.get("taylor_green", n=8, relax_iterations=0, t_end=t_end)


def test_messages_show_plain_numbers(tg):
    with pytest.raises(ValueError, match=r"got 0\.7$"):
        sphjax.cases.get("oscillating_plate", n=4).params.replace(
            poisson_ratio=jnp.asarray(0.7, jnp.float32)
        )
    with pytest.raises(ValueError, match=r"got 0\.0$"):
        tg.params.replace(sound_speed=np.float64(0.0))


@pytest.mark.parametrize("argument", ["width", "viscosity", "body_force"])
def test_non_positive_physical_argument(argument):
    with pytest.raises(ValueError, match=f"^{argument} must be a positive number"):
        sphjax.cases.get("poiseuille", **{argument: -1.0})


# ---------------------------------------------------------------------------- simulate


def test_time_step_above_stability_limit(tg):
    with pytest.raises(ValueError, match=r"dt=.* exceeds the stability limit .*pass dt <="):
        sphjax.simulate(tg, dt=10 * tg.dt, n_steps=1)


@pytest.mark.parametrize("dt", [0.0, -1e-3, float("nan")])
def test_non_positive_time_step(tg, dt):
    with pytest.raises(ValueError, match="dt must be a positive number"):
        sphjax.simulate(tg, dt=dt, n_steps=1)


def test_bad_step_counts(tg):
    with pytest.raises(ValueError, match="t_end must be a positive number, got -1.0"):
        sphjax.simulate(tg, t_end=-1.0)
    with pytest.raises(ValueError, match="give n_steps or t_end, not both"):
        sphjax.simulate(tg, n_steps=2, t_end=0.1)
    with pytest.raises(ValueError, match="n_steps must be a positive integer"):
        sphjax.simulate(tg, n_steps=0)
    with pytest.raises(ValueError, match="save_every must be a positive integer"):
        sphjax.simulate(tg, n_steps=4, save_every=0)


@pytest.mark.parametrize("shift", [1.0, -0.3])
def test_particle_outside_periodic_box(tg, shift):
    position = np.array(tg.state.position)
    position[5, 0] += shift
    with pytest.raises(ValueError, match=r"state.position: particle 5 .* outside the domain"):
        sphjax.simulate(tg, state=tg.state.replace(position=jnp.asarray(position)), n_steps=1)


@pytest.mark.parametrize("field", ["position", "velocity", "density"])
def test_non_finite_initial_state(tg, field):
    values = np.array(getattr(tg.state, field))
    values[3] = np.nan
    state = tg.state.replace(**{field: jnp.asarray(values)})
    with pytest.raises(ValueError, match=f"state.{field}: particle 3 has a non-finite value"):
        sphjax.simulate(tg, state=state, n_steps=1)


# ---------------------------------------------------------------------------- output path


def test_unwritable_path_is_rejected_before_the_run(tg, tmp_path):
    missing = tmp_path / "no" / "such" / "dir" / "run.h5"
    with pytest.raises(ValueError, match=r"^path: cannot write .* does not exist; create it"):
        TrajectoryWriter(missing, tg)
    with pytest.raises(ValueError, match=r"^--out: .* is a directory"):
        check_writable(tmp_path, "--out")
    with pytest.raises(ValueError, match="output file name is required"):
        check_writable("", "--out")


@pytest.mark.skipif(os.geteuid() == 0, reason="root can write anywhere")
def test_read_only_directory(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        with pytest.raises(ValueError, match="is not writable"):
            check_writable(locked / "run.h5", "--out")
    finally:
        locked.chmod(0o700)


# ---------------------------------------------------------------------------- unstable runs


def test_particle_leaving_a_closed_domain_stops_the_run_and_keeps_frames(tmp_path):
    case = sphjax.cases.get("hydrostatic_tank", n=4)
    kind = np.asarray(case.state.kind)
    particle = int(np.flatnonzero(kind == sphjax.Kind.FLUID)[-1])
    position = np.array(case.state.position)
    velocity = np.zeros_like(position)
    position[particle, 1] = case.model.domain.upper[1] - 2 * case.info["dx"]
    velocity[particle, 1] = 20.0  # leaves through the top in about ten steps
    start = 0.25  # a resumed run: the error gives the simulated time, not the steps' own
    state = case.state.replace(
        position=jnp.asarray(position),
        velocity=jnp.asarray(velocity),
        time=jnp.asarray(start, case.state.time.dtype),
    )
    path = tmp_path / "escape.h5"
    with pytest.raises(sphjax.SimulationError) as err:
        with TrajectoryWriter(path, case) as writer:
            sphjax.simulate(case, state=state, n_steps=40, save_every=2, on_frames=writer)
    error = err.value
    assert error.particle == particle
    assert 2 < error.step < 40
    assert f"step {error.step}" in str(error) and f"particle {particle}" in str(error)
    # what happened and where: the side it left by, its position and velocity
    top = case.model.domain.upper[1]
    assert "left the domain at x = [" in str(error), str(error)
    assert f"above the upper bound {top:.6g} on axis 1" in str(error)
    assert "non-finite" not in str(error)
    assert error.time == pytest.approx(start + error.step * case.dt, rel=1e-4)
    trajectory, meta = read_trajectory(path)
    assert len(trajectory) == 1 + (error.step - 1) // 2  # every frame before the failure
    assert not meta["complete"] and "SimulationError" in meta["error"]
    assert np.all(np.isfinite(np.asarray(trajectory.states.position)))
    assert float(trajectory.states.position[-1, particle, 1]) <= top


def test_an_unstable_run_under_grad_without_jit_raises_the_simulation_error(monkeypatch):
    """``jax.grad(loss)(p)`` with no ``jit`` runs the simulation when ``simulate`` is
    called, compiled: its instability is the SimulationError itself, not the runtime's
    wrapper around the check that raised it, at the step and (in the user's order of the
    particles) the particle of the same run made concretely."""
    case = sphjax.cases.get("dam_break", n=4)

    def loss(alpha):
        params = case.params.replace(artificial_alpha=alpha)
        final = sphjax.simulate(case, params, dt=30 * case.dt, n_steps=40).final
        return final.position.sum()

    with pytest.raises(
        sphjax.SimulationError, match=r"unstable at step \d+ .* particle \d+"
    ) as traced:
        jax.grad(loss)(case.params.artificial_alpha)
    # the same run, concrete (the time step check let through)
    monkeypatch.setattr(sphjax.integration.simulate, "check_time_step", lambda *args: None)
    with pytest.raises(sphjax.SimulationError) as concrete:
        sphjax.simulate(case, dt=30 * case.dt, n_steps=40)
    assert (traced.value.step, traced.value.particle) == (
        concrete.value.step,
        concrete.value.particle,
    )


def test_failures_as_nan_reports_an_unstable_traced_run_without_a_host_callback():
    """Inside ``failures_as_nan()`` the run above returns NaN instead of raising, and its
    program holds no host callback (JAX writes no program with one to the persistent
    compilation cache); outside, the same loss's program has the callbacks."""
    from sphjax.integration.simulate import failures_as_nan

    case = sphjax.cases.get("dam_break", n=4)

    def loss(alpha, dt):
        params = case.params.replace(artificial_alpha=alpha)
        final = sphjax.simulate(case, params, dt=dt, n_steps=40).final
        return final.position.sum()

    alpha = case.params.artificial_alpha
    with failures_as_nan():
        value, grad = jax.jit(jax.value_and_grad(loss))(alpha, 30 * case.dt)
        fine = jax.jit(loss)(alpha, case.dt)
        quiet = jax.jit(jax.value_and_grad(loss)).lower(alpha, case.dt).as_text()
    assert np.isnan(float(value)) and np.isnan(float(grad))
    assert np.isfinite(float(fine))
    loud = jax.jit(jax.value_and_grad(loss)).lower(alpha, case.dt).as_text()
    assert "callback" in loud and "callback" not in quiet


def test_time_step_forced_past_the_check_blows_up(monkeypatch, tmp_path):
    monkeypatch.setattr(sphjax.integration.simulate, "check_time_step", lambda *args: None)
    case = sphjax.cases.get("dam_break", n=4)
    path = tmp_path / "blowup.h5"
    with pytest.raises(sphjax.SimulationError, match=r"unstable at step \d+ .* particle \d+"):
        with TrajectoryWriter(path, case) as writer:
            sphjax.simulate(case, dt=30 * case.dt, n_steps=40, save_every=1, on_frames=writer)
    trajectory, _ = read_trajectory(path)
    assert 1 <= len(trajectory) < 41
