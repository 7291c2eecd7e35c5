"""The wall-impact dam break's set-up and its pressure sensors (fast; the run against the
experiment is tests/test_dam_break_impact.py)."""

from __future__ import annotations

import numpy as np
import pytest

import sphjax
from sphjax import Kind
from sphjax.cases import dam_break_impact, dam_break_wall_sensors, probe_pressure

# De Courcy et al. (2024), "Incompressible delta-SPH via artificial compressibility",
# CMAME 420, 116700: the centres of their wall pressure sensors P1-P4 (m), the heights of
# their digitised curves in TrixiParticles.jl (validation/dam_break_2d/
# decourcy_pressure_sensor_P1.csv to _P4.csv); P4 is Buchner's (2002) sensor P1, 0.16 m.
PUBLISHED_HEIGHTS = {"P1": 0.006, "P2": 0.030, "P3": 0.060, "P4": 0.160}
# Zhou et al. (1999), Buchner (2002): column 1.2 m wide and 0.6 m high, tank 3.22 m long
COLUMN, TANK_LENGTH = (1.2, 0.6), 3.22


def test_the_sensors_are_de_courcy_et_al_s():
    case = dam_break_impact(n=8)
    sensors = dam_break_wall_sensors(case)
    assert sensors == {name: (case.info["tank_length"], y) for name, y in PUBLISHED_HEIGHTS.items()}


def test_the_set_up_is_zhou_and_buchner_s():
    """The column and the tank of the experiment (the tank to within half a spacing), its
    free-slip walls and Monaghan alpha = 0.02; the same case as ``dam_break`` with those
    arguments."""
    case = dam_break_impact(n=8, density_diffusion="antuono", sound_speed_factor=40.0)
    info = case.info
    assert (info["column_width"], info["column_height"]) == pytest.approx(COLUMN)
    assert abs(info["tank_length"] - TANK_LENGTH) <= info["dx"] / 2
    assert float(case.params.artificial_alpha) == pytest.approx(0.02)
    assert case.model.systems[1].boundary.no_slip is False
    explicit = sphjax.cases.dam_break(
        n=8,
        column_width=1.2,
        column_height=0.6,
        tank_length_factor=5.366 / 2,
        wall_slip="free_slip",
        artificial_alpha=0.02,
        density_diffusion="antuono",
        sound_speed_factor=40.0,
    )
    assert case.model == explicit.model and case.info == explicit.info and case.dt == explicit.dt
    np.testing.assert_array_equal(case.state.position, explicit.state.position)
    np.testing.assert_array_equal(case.params.sound_speed, explicit.params.sound_speed)


def test_the_sensors_sit_on_the_right_wall_s_face_and_are_dry_at_rest():
    """Between the fluid's side and the first layer of the right wall's particles (at
    ``tank_length + dx / 2``); the column stands 2 m from it, so no fluid particle is
    within a kernel support of a sensor and each reads 0."""
    case = dam_break_impact(n=8)
    x, kind = np.asarray(case.state.position), np.asarray(case.state.kind)
    wall, dx = case.info["tank_length"], case.info["dx"]
    right = x[(kind == Kind.WALL) & (x[:, 0] > wall), 0]
    assert right.min() == pytest.approx(wall + dx / 2)
    assert x[kind == Kind.FLUID, 0].max() < wall
    for point in dam_break_wall_sensors(case).values():
        assert np.linalg.norm(x[kind == Kind.FLUID] - point, axis=1).min() > case.model.cutoff
        assert float(probe_pressure(case.state, case, point)) == 0.0


def test_other_heights_on_the_same_wall():
    case = sphjax.cases.dam_break(n=4)
    wall = case.info["tank_length"]
    assert dam_break_wall_sensors(case, {"a": 0.1, "b": 0}) == {"a": (wall, 0.1), "b": (wall, 0)}


@pytest.mark.parametrize(
    "case",
    [
        lambda: None,
        lambda: "dam_break",
        lambda: sphjax.cases.hydrostatic_tank(n=4),
        lambda: sphjax.cases.dam_break_3d(n=4),
    ],
    ids=["None", "a name", "hydrostatic_tank", "dam_break_3d"],
)
def test_a_case_that_is_no_2d_dam_break_is_named(case):
    case = case()
    with pytest.raises(ValueError, match="^case must be a 2D dam break") as error:
        dam_break_wall_sensors(case)
    assert "\n" not in str(error.value)


@pytest.mark.parametrize("heights", [[0.1, 0.2], {"P1": -0.1}, {"P1": "low"}, {"P1": np.nan}])
def test_bad_heights_are_named(heights):
    with pytest.raises(ValueError, match="^heights must map sensor names to heights") as error:
        dam_break_wall_sensors(dam_break_impact(n=4), heights)
    assert "\n" not in str(error.value)


@pytest.mark.parametrize(
    "argument, bad",
    [("n", 1), ("n", 2.5), ("sound_speed_factor", -20.0), ("sound_speed_factor", "fast")],
)
def test_bad_set_up_arguments_are_named(argument, bad):
    with pytest.raises(ValueError, match=f"^{argument} must be ") as error:
        dam_break_impact(**{argument: bad})
    assert "\n" not in str(error.value)
