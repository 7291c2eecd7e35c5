"""Parameters act or are refused (issue 29).

For every case of ``sphjax.cases.CASES``, every Params field is either *used* (the right-hand
side depends on it: its gradient through one evaluation at a perturbed state is non-zero) or
*refused*: ``case.params.replace`` raises :class:`~sphjax.UnusedParameterError`, one line
naming the field, the system and the choice that would read it, for concrete values and for
tracers under ``jax.grad`` alike.  The table below is the one the models give; a test pins it.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sphjax
from sphjax import cases
from sphjax.core.params import FLUID_DEFAULTS, SOLID_DEFAULTS, UnusedParameterError, fields

FLUID_ONLY_VISCOUS = ("artificial_alpha", "artificial_beta", "density_diffusion")
MORRIS_WALLS = ("artificial_alpha", "artificial_beta", "transport_pressure", "density_diffusion")
MONAGHAN_WALLS = ("kinematic_viscosity", "transport_pressure")
# a rigid body's wall contact: no other system reads these
CONTACT = ("contact_frequency", "contact_damping_ratio", "contact_friction")
ELASTIC = ("penalty_alpha", *CONTACT)
FSI = ("kinematic_viscosity", "transport_pressure", *ELASTIC)
# a rigid body in water: no elastic fields (it does not deform); the contact's fields only
# with wall contact
RIGID_CONTACT = (
    "kinematic_viscosity",
    "transport_pressure",
    "young_modulus",
    "poisson_ratio",
    "penalty_alpha",
)
RIGID = (*RIGID_CONTACT, *CONTACT)
# the settling disk: Morris's viscosity and no artificial one, no wall contact
SETTLING = (
    "artificial_alpha",
    "artificial_beta",
    "transport_pressure",
    "young_modulus",
    "poisson_ratio",
    "penalty_alpha",
    *CONTACT,
)

# case -> (smallest resolution that builds, the fields its model does not read)
UNUSED = {
    "taylor_green": (4, FLUID_ONLY_VISCOUS),
    "poiseuille": (4, MORRIS_WALLS),
    "lid_driven_cavity": (4, FLUID_ONLY_VISCOUS),
    "hydrostatic_tank": (4, MONAGHAN_WALLS),
    "dam_break": (4, MONAGHAN_WALLS),
    "oscillating_plate": (2, ELASTIC),
    "turek_hron_csm": (3, ELASTIC),
    "abc_flow_3d": (8, FLUID_ONLY_VISCOUS),
    "hydrostatic_tank_3d": (4, MONAGHAN_WALLS),
    "cantilever_3d": (2, ELASTIC),
    "duct_poiseuille_3d": (4, MORRIS_WALLS),
    "dam_break_3d": (4, MONAGHAN_WALLS),
    "spheric_dam_break_3d": (4, MONAGHAN_WALLS),
    "hydrostatic_fsi_plate": (2, FSI),
    "hydrostatic_fsi_plate_3d": (2, FSI),
    "elastic_gate_dam_break": (2, FSI),
    "dam_break_elastic_obstacle": (2, FSI),
    "floating_body": (4, RIGID),
    "sinking_body": (4, RIGID_CONTACT),
    "settling_disk": (4, SETTLING),
    "channel_flow": (4, MORRIS_WALLS),
}

# the gradient check evaluates the right-hand side; these are the largest at their
# smallest size (2.7k-23k particles: reverse mode through the 3D plate needs more memory than
# a test may take), and their models are those of 2D cases checked here (the same systems
# and choices, in 3D)
LARGE = {
    "dam_break_3d": "dam_break",
    "spheric_dam_break_3d": "dam_break",
    "hydrostatic_fsi_plate_3d": "hydrostatic_fsi_plate",
}


def _case(name):
    return cases.CASES[name](n=UNUSED[name][0])


def _fields_of(params):
    return [name for name, _ in params.items()]


def test_the_table_covers_every_case():
    assert set(UNUSED) == set(cases.CASES)


@pytest.mark.parametrize("name", list(cases.CASES))
def test_unused_fields_are_refused(name):
    """The fields a case's model does not read are exactly those of the table, and
    ``replace`` refuses each with one line naming it; the others are accepted."""
    case = _case(name)
    unused = dict(case.params.unused)
    assert tuple(unused) == UNUSED[name][1]
    assert [n for n, _ in case.params.items(used_only=True)] == [
        n for n in _fields_of(case.params) if n not in unused
    ]
    for field in _fields_of(case.params):
        value = getattr(case.params, field)
        if field in unused:
            with pytest.raises(UnusedParameterError) as err:
                case.params.replace(**{field: value + 0.5})
            message = str(err.value)
            assert "\n" not in message and message.startswith(f"{field} is not used by this ")
            assert message.endswith("to use it")
            with pytest.raises(UnusedParameterError):
                case.params.check_used(field)
        else:
            changed = case.params.replace(**{field: value * 1.01 + 0.01})
            assert changed.unused == case.params.unused


def test_the_refusal_names_the_choice_that_would_read_it():
    dam = cases.dam_break(n=4)
    with pytest.raises(UnusedParameterError, match=r"^kinematic_viscosity is not used by "
                       r"this fluid \(artificial viscosity only\): add MorrisViscosity\(\) "
                       r"to the fluid's viscosity to use it$"):  # fmt: skip
        dam.params.replace(kinematic_viscosity=0.5)
    tg = cases.taylor_green(n=4)
    with pytest.raises(UnusedParameterError, match=r"^artificial_alpha .*\(Morris viscosity "
                       r"only\): add ArtificialViscosity\(\)"):  # fmt: skip
        tg.params.replace(artificial_alpha=0.1)
    with pytest.raises(UnusedParameterError, match=r"^density_diffusion .*ContinuityDensity"):
        tg.params.replace(density_diffusion=0.1)
    plate = cases.oscillating_plate(n=2)
    refusal = (
        r"^penalty_alpha is not used by this solid \(no penalty force\): give the solid "
        r"penalty=PenaltyForce\(\) to use it$"
    )
    with pytest.raises(UnusedParameterError, match=refusal):
        plate.params.replace(penalty_alpha=0.1)
    # the choice that reads it makes it settable
    assert [n for n, _ in cases.oscillating_plate(n=2, penalty_alpha=0.1).params.unused] == [
        *CONTACT
    ]
    # a rigid body's wall contact: refused by the elastic solid, naming the system to use
    with pytest.raises(UnusedParameterError, match=r"^contact_friction is not used by this "
                       r"solid \(an elastic solid has no wall contact\): give a rigid body "
                       r"RigidSystem\(wall_contact=WallContact\(\)\) to use it$"):  # fmt: skip
        plate.params.replace(contact_friction=0.3)
    # UnusedParameterError is a ValueError
    with pytest.raises(ValueError):
        dam.params.replace(sound_speed=20.0, kinematic_viscosity=0.5)


def test_a_tracer_of_an_unused_field_is_refused():
    """Differentiating with respect to a field the model does not read is refused, not a
    silent zero: the tracer goes through ``replace`` too."""
    case = cases.dam_break(n=4)

    def loss(nu):
        params = case.params.replace(kinematic_viscosity=nu)
        return sphjax.simulate(case, params, n_steps=1).final.velocity.sum()

    with pytest.raises(UnusedParameterError, match=r"^kinematic_viscosity is not used"):
        jax.grad(loss)(0.5)


def test_a_new_model_decides_what_is_used():
    """The refused set follows the case's model: ``case.replace(model=...)`` with
    Morris viscosity makes ``kinematic_viscosity`` settable; Params built with
    ``make_params`` (no model) refuse nothing."""
    case = cases.dam_break(n=4)
    fluid = case.model.systems[0]
    viscous = fluid.replace(viscosity=(*fluid.viscosity, sphjax.MorrisViscosity()))
    model = case.model.replace(systems=(viscous, *case.model.systems[1:]))
    moved = case.replace(model=model)
    assert "kinematic_viscosity" not in dict(moved.params.unused)
    assert float(moved.params.replace(kinematic_viscosity=1e-3).kinematic_viscosity) == 1e-3
    assert sphjax.make_params(2).replace(kinematic_viscosity=1.0).unused == ()


def test_a_group_no_system_reads_is_refused():
    """Params with a solid group on a model without a solid: the solid's fields are
    refused, naming the system that would read them."""
    case = cases.taylor_green(n=4)
    both = sphjax.make_params(2, kinematic_viscosity=0.01, young_modulus=1e6)
    case = case.replace(params=both)
    with pytest.raises(UnusedParameterError, match=r"^young_modulus is not used by this model "
                       r"\(it has no solid\): add a SolidSystem\(\) to use it$"):  # fmt: skip
        case.params.replace(young_modulus=2e6)
    assert float(case.params.replace(kinematic_viscosity=0.02).kinematic_viscosity) == 0.02


def _perturbed_state(case):
    """A state at which every term of the right-hand side is active: uneven masses, a
    velocity field with approaching pairs, densities off the rest density, and a
    non-affine deformation of the solids (so the penalty force is not zero), and a rigid
    body with wall contact lowered into contact (its bottom row 1.2 spacings above the
    floor's top row of wall particles), sliding at 2 m/s (so friction caps the contact's
    tangential dashpot)."""
    s = case.state
    # numpy: each jax.numpy operation on the host compiles a program per case's shape
    x = np.asarray(s.position)
    kind = np.asarray(s.kind)
    solid = (kind == sphjax.Kind.SOLID)[:, None]
    scale = case.info.get("dx", 0.01)
    bend = 0.02 * scale * np.sin(3.0 * x[:, ::-1] / scale) * np.cos(2.0 * x / scale)
    x = np.where(solid, x + bend, x)
    velocity = np.asarray(s.velocity) + 0.1 * np.cos(5.0 * x / scale)
    rigid = case.model.system(sphjax.RigidSystem)
    if rigid is not None and rigid.wall_contact is not None:
        body = (kind == sphjax.Kind.RIGID)[:, None]
        lowest = np.min(np.where(body[:, 0], x[:, 1], np.inf))
        lowered = x.copy()
        lowered[:, 1] += 0.7 * scale - lowest
        x = np.where(body, lowered, x)
        sliding = velocity.copy()
        sliding[:, 0] += 2.0
        velocity = np.where(body, sliding, velocity)
    return s.replace(
        position=jnp.asarray(x),
        mass=jnp.asarray(np.asarray(s.mass) * (1.0 + 0.05 * np.sin(7.0 * x[:, 0] / scale))),
        velocity=jnp.asarray(velocity),
        density=jnp.asarray(np.asarray(s.density) * (1.0 + 1e-3 * np.sin(3.0 * x[:, 0] / scale))),
        shift_acceleration=jnp.asarray(np.ones_like(np.asarray(s.shift_acceleration))),
    )


def test_large_cases_have_the_systems_of_a_checked_case():
    for name, like in LARGE.items():
        big, small = _case(name).model, _case(like).model
        assert big.dim == 3 and small.dim == 2
        # the split integration's substeps do not change which parameters are read
        assert big.parameters() == small.parameters()
        assert [type(s) for s in big.systems] == [type(s) for s in small.systems]
        for a, b in zip(big.systems, small.systems, strict=True):
            if isinstance(a, sphjax.SolidSystem):
                a, b = a.replace(substeps=1), b.replace(substeps=1)
            assert a == b


def _set_anyway(params, field, value):
    """``params`` with ``field`` set, bypassing the refusal (to show it is not read)."""
    if field == "gravity":
        return dataclasses.replace(params, gravity=value)
    group = "fluid" if field in FLUID_DEFAULTS else "solid"
    values = dataclasses.replace(getattr(params, group), **{field: value})
    return dataclasses.replace(params, **{group: values})


@pytest.mark.parametrize("name", [n for n in cases.CASES if n not in LARGE])
def test_used_fields_change_the_right_hand_side(name):
    """One right-hand side (with a density step, as the integrator takes it) at a state
    where every term is active: changing a field the model reads changes it, changing a
    field it does not read leaves it bit-identical (so the table is exact both ways)."""
    case = _case(name)
    state = _perturbed_state(case)
    neighbors = sphjax.build_neighbors(state, case.model)

    @jax.jit
    def rates(params):
        out = sphjax.evaluate(state, neighbors, case.model, params, density_step=case.dt)
        return (out.acceleration, out.density_rate, out.pressure, out.shift_acceleration)

    before = rates(case.params)
    unused = dict(case.params.unused)
    for field, value in case.params.items():
        after = rates(_set_anyway(case.params, field, value * 1.25 + 0.5))
        same = all(bool(jnp.array_equal(a, b)) for a, b in zip(before, after, strict=True))
        if field in unused:
            assert same, f"{field} is refused but the right-hand side depends on it"
        else:
            assert not same, f"{field} is accepted but the right-hand side ignores it"


def test_every_field_is_in_the_table_or_used():
    """Every Params field appears: in no case is a field neither used nor refused."""
    assert set(fields()) == {"gravity", *FLUID_DEFAULTS, *SOLID_DEFAULTS}


def test_the_whole_params_gradient_is_zero_for_unused_fields_and_says_which_are_used():
    """``jax.grad`` with respect to the whole Params pytree: the fields the model does not
    read get a gradient of exactly 0, the fields it reads do not; ``Params.used`` names the
    latter, and the gradient (a Params with the same ``unused``) gives them alone with
    ``items(used_only=True)``."""
    case = _case("dam_break")
    state = _perturbed_state(case)
    neighbors = sphjax.build_neighbors(state, case.model)

    def loss(params):
        out = sphjax.evaluate(state, neighbors, case.model, params, density_step=case.dt)
        return jnp.sum(out.acceleration**2) + jnp.sum(out.density_rate**2) * 1e-6

    grads = jax.jit(jax.grad(loss))(case.params)  # one program, not one per operation
    unused = [name for name, _ in case.params.unused]
    assert case.params.used == tuple(n for n in _fields_of(case.params) if n not in unused)
    assert set(unused) == set(MONAGHAN_WALLS) and "kinematic_viscosity" not in case.params.used
    assert grads.unused == case.params.unused and grads.used == case.params.used
    for name, value in grads.items():
        if name in unused:
            assert bool(jnp.all(value == 0.0)), f"{name}: gradient {value}, expected exactly 0"
        else:
            assert bool(jnp.any(value != 0.0)), f"{name} is read but its gradient is 0"
    assert [name for name, _ in grads.items(used_only=True)] == list(case.params.used)
    assert sphjax.make_params(2).used == tuple(_fields_of(sphjax.make_params(2)))
