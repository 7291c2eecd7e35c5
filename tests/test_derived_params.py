"""Quantities derived from Params follow them (issue 14, point 4).

``simulate(case, params)`` starts from ``case.state_for(params)``: changing a parameter
through ``params.replace`` gives the same run as building the case with that value.
Fast (about 15 s in all on one core, compile included).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sphjax
from sphjax.cases import plate_reference, plate_sound_speed


def _same_run(case_a, params_a, case_b, n_steps):
    dt = min(case_a.dt, case_b.dt)
    run_a = sphjax.simulate(case_a, params_a, n_steps=n_steps, save_every=n_steps, dt=dt)
    run_b = sphjax.simulate(case_b, n_steps=n_steps, save_every=n_steps, dt=dt)
    for name in ("position", "velocity", "density"):
        a = np.asarray(getattr(run_a.final, name))
        b = np.asarray(getattr(run_b.final, name))
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-12, err_msg=name)
    return run_a, run_b


def test_plate_initial_velocity_follows_young_modulus():
    built = sphjax.cases.oscillating_plate(n=3, young_modulus=3.0e6)
    case = sphjax.cases.oscillating_plate(n=3, young_modulus=2.0e6)
    params = case.params.replace(young_modulus=3.0e6)
    state = case.state_for(params)
    np.testing.assert_allclose(state.velocity, built.state.velocity, rtol=1e-6)
    # the velocity scales with c0 = sqrt(E / (3 (1 - 2 nu)) / rho), i.e. sqrt(E)
    v_old = np.abs(np.asarray(case.state.velocity[:, 1])).max()
    assert np.abs(np.asarray(state.velocity[:, 1])).max() == pytest.approx(
        v_old * np.sqrt(1.5), rel=1e-6
    )
    run_a, _ = _same_run(case, params, built, 40)
    unchanged = sphjax.simulate(case, n_steps=40, save_every=40, dt=built.dt)
    assert not np.allclose(run_a.final.velocity, unchanged.final.velocity, rtol=1e-3)
    reference = plate_reference(case, params)
    for key in ("sound_speed", "omega", "period", "tip_amplitude"):
        assert float(reference[key]) == pytest.approx(built.info[key], rel=1e-6), key


def test_plate_initial_velocity_gradient_sees_young_modulus():
    case = sphjax.cases.oscillating_plate(n=3)

    def tip_speed(E):
        return jnp.max(case.state_for(case.params.replace(young_modulus=E)).velocity[:, 1])

    E = case.params.young_modulus
    grad = jax.grad(tip_speed)(E)
    # v ~ sqrt(E): dv/dE = v / (2 E)
    assert float(grad) == pytest.approx(float(tip_speed(E)) / (2 * float(E)), rel=1e-5)
    assert float(plate_sound_speed(case.params)) == pytest.approx(case.info["sound_speed"])


def test_dam_break_initial_density_follows_sound_speed_and_gravity():
    built = sphjax.cases.dam_break(n=4, sound_speed_factor=30.0, gravity=5.0)
    case = sphjax.cases.dam_break(n=4, sound_speed_factor=20.0, gravity=5.0)
    params = case.params.replace(sound_speed=built.params.sound_speed)
    state = case.state_for(params)
    np.testing.assert_allclose(state.density, built.state.density, rtol=1e-6)
    assert not np.allclose(state.density, case.state.density, rtol=1e-7)
    _same_run(case, params, built, 30)


def test_state_for_defaults_and_replace():
    case = sphjax.cases.hydrostatic_tank(n=4)
    assert case.state_for() is case.state
    assert case.state_for(case.params) is case.state
    # a case given another state starts from that state whatever the parameters
    other = case.replace(state=case.state.replace(velocity=case.state.velocity + 1.0))
    assert other.initial_state is None
    assert other.state_for(case.params.replace(sound_speed=50.0)) is other.state
