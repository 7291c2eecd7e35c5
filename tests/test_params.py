"""Params: grouped by system, addressed by name, and physically invalid values rejected
with the field named (issue: bad input gets one clear line)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sphjax

BAD = [
    ("kinematic_viscosity", -0.01, "non-negative"),
    ("artificial_alpha", -1.0, "non-negative"),
    ("sound_speed", 0.0, "positive"),
    ("sound_speed", -3.0, "positive"),
    ("reference_density", 0.0, "positive"),
    ("density_diffusion", -0.1, "non-negative"),
    ("transport_pressure", -1.0, "non-negative"),
    ("young_modulus", 0.0, "positive"),
    ("solid_density", -1.0, "positive"),
    ("poisson_ratio", 0.7, "(-1, 0.5)"),
    ("poisson_ratio", 0.5, "(-1, 0.5)"),
    ("poisson_ratio", -1.0, "(-1, 0.5)"),
    ("kinematic_viscosity", math.nan, "non-negative"),
    ("young_modulus", math.inf, "positive"),
    ("kinematic_viscosity", "abc", "non-negative"),
    ("background_pressure", math.nan, "finite"),
]


@pytest.mark.parametrize(("field", "value", "what"), BAD)
def test_invalid_values_are_rejected_with_the_field_named(field, value, what):
    params = sphjax.make_params(2)  # both groups
    with pytest.raises(ValueError, match=rf"Params\.{field} must be .*{what}".replace("(", r"\(")
                       .replace(")", r"\)")):  # fmt: skip
        params.replace(**{field: value})
    with pytest.raises(ValueError, match=rf"Params\.{field}"):
        sphjax.make_params(2, **{field: value})


def test_valid_values_pass_and_land_in_their_group():
    params = sphjax.make_params(2, kinematic_viscosity=0.02, young_modulus=2e6)
    new = params.replace(kinematic_viscosity=0.0, poisson_ratio=-0.5, gravity=(0.0, -9.81))
    assert float(new.fluid.kinematic_viscosity) == 0.0
    assert float(new.solid.poisson_ratio) == -0.5
    np.testing.assert_allclose(new.gravity, [0.0, -9.81])
    assert float(new.young_modulus) == 2e6  # read by name through its group


def test_groups_follow_the_fields_given_and_unknown_fields_are_named():
    fluid_only = sphjax.make_params(2, sound_speed=20.0)
    assert fluid_only.solid is None and fluid_only.fluid is not None
    with pytest.raises(ValueError, match="young_modulus belongs to the solid parameters"):
        fluid_only.replace(young_modulus=1e6)
    with pytest.raises(ValueError, match="no field 'viscosity'; valid fields: gravity"):
        fluid_only.replace(viscosity=0.1)
    with pytest.raises(ValueError, match="unknown field"):
        sphjax.make_params(2, viscosity=0.1)
    with pytest.raises(ValueError, match=r"Params.gravity must have shape \(2,\)"):
        fluid_only.replace(gravity=(0.0, 0.0, -9.81))


def test_traced_values_are_not_checked_and_gradients_keep_the_groups():
    case = sphjax.cases.taylor_green(n=6, relax_iterations=0)

    def loss(params):
        return jnp.sum(sphjax.simulate(case, params, n_steps=3).final.velocity ** 2)

    grad = jax.grad(loss)(case.params)
    assert isinstance(grad, sphjax.Params) and grad.solid is None
    assert np.isfinite(float(grad.kinematic_viscosity))
    # inside a trace replace() cannot see the value; it is taken as given
    jax.jit(lambda nu: case.params.replace(kinematic_viscosity=nu).fluid.kinematic_viscosity)(-1.0)


def test_a_case_without_the_params_group_it_needs_is_refused_by_name():
    case = sphjax.cases.taylor_green(n=6, relax_iterations=0)
    solid_only = sphjax.make_params(2, young_modulus=1e6)
    with pytest.raises(ValueError, match="FluidSystem but Params has no fluid parameters"):
        sphjax.simulate(case, solid_only, n_steps=1)
