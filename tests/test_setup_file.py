"""Set-up files (``sphjax run FILE.toml``): the TOML dam break is the built-in dam break bit
for bit, the example files run, every primitive can be used, bad files exit 2 with one line
naming the key.  About 30 s of CPU (three small compilations); 65 s wall on two cores
at load 10."""

from __future__ import annotations

import math
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh

import sphjax
from sphjax import geometry
from sphjax.cases.setup_file import SetupError, from_toml
from sphjax.cli import main
from sphjax.io import read_trajectory

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _dam_break_toml(n: int) -> str:
    """The built-in dam break at resolution n as a set-up file, every number as the case
    computes it (repr round-trips a float exactly)."""
    L, g = 0.3, 9.81
    dx, H = L / n, 2.0 * L
    tank_length = dx * round(5.0 * L / dx)
    margin = (3 + 2) * dx
    return f"""
name = "dam_break_toml"
dim = 2
dx = {dx!r}
kernel = "wendland_c2"
h_factor = 1.5
gravity = [0.0, {-g!r}]

[time]
t_end = 0.5

[domain]
lower = [{-margin!r}, {-margin!r}]
upper = [{tank_length + margin!r}, {2.0 * 1.25 * H + margin!r}]

[fluid]
density = 1000.0
sound_speed = {20.0 * math.sqrt(g * H)!r}
equation_of_state = "tait"
gamma = 7.0
density_model = "continuity"
artificial_viscosity = 0.1
density_diffusion = 0.1
hydrostatic = true

[[fluid.shapes]]
shape = "rectangle"
lower = [0.0, 0.0]
upper = [{L!r}, {H!r}]

[walls]
slip = "no_slip"

[[walls.shapes]]
shape = "rectangle"
lower = [0.0, 0.0]
upper = [{tank_length!r}, {1.25 * H!r}]
open_top = true
"""


def test_toml_dam_break_is_the_built_in_one(tmp_path):
    n = 8
    path = tmp_path / "dam.toml"
    path.write_text(_dam_break_toml(n))
    ours, theirs = from_toml(path), sphjax.cases.get("dam_break", n=n)
    for field in ("position", "velocity", "density", "mass", "kind", "volume"):
        a, b = np.asarray(getattr(ours.state, field)), np.asarray(getattr(theirs.state, field))
        assert a.shape == b.shape and np.array_equal(a, b), field
    assert ours.model == theirs.model  # systems, kernel, h, domain
    for (name, a), (_, b) in zip(ours.params.items(), theirs.params.items(), strict=True):
        assert np.array_equal(np.asarray(a), np.asarray(b)), name
    assert ours.dt == theirs.dt  # so the runs are the same, bit for bit
    # examples/dam_break.toml is the default dam break too (it leaves the domain default)
    example, default = from_toml(EXAMPLES / "dam_break.toml"), sphjax.cases.get("dam_break")
    assert np.array_equal(np.asarray(example.state.position), np.asarray(default.state.position))
    assert np.array_equal(np.asarray(example.state.density), np.asarray(default.state.density))
    assert example.model.systems == default.model.systems and example.dt == default.dt
    assert example.params.sound_speed == default.params.sound_speed
    # the initial state follows the parameters as the built-in one's does
    params = theirs.params.replace(sound_speed=80.0)
    assert np.array_equal(
        np.asarray(ours.state_for(params).density), np.asarray(theirs.state_for(params).density)
    )


def test_example_lid_driven_cavity_is_the_built_in_one():
    """examples/lid_driven_cavity.toml (a moving-wall lid listed before the box) builds
    the built-in cavity at n = 20: the same particles (in another order), velocities
    (the lid's rows at U, corners included), model, parameters and step."""
    ours = from_toml(EXAMPLES / "lid_driven_cavity.toml")
    theirs = sphjax.cases.lid_driven_cavity(n=20)

    def sorted_fields(case):
        s = case.state
        x = np.asarray(s.position)
        order = np.lexsort((x[:, 1], x[:, 0], np.asarray(s.kind)))
        fields = ("position", "velocity", "density", "mass", "kind")
        return {f: np.asarray(getattr(s, f))[order] for f in fields}

    a, b = sorted_fields(ours), sorted_fields(theirs)
    for field in a:
        assert a[field].shape == b[field].shape and np.allclose(a[field], b[field]), field
    assert np.sum(a["velocity"][:, 0] == 1.0) == len(theirs.info["lid_indices"])
    assert ours.model == theirs.model
    for (name, x), (_, y) in zip(ours.params.items(), theirs.params.items(), strict=True):
        assert np.array_equal(np.asarray(x), np.asarray(y)), name
    assert ours.dt == theirs.dt


def test_example_cantilever_falls_freely_at_first(tmp_path):
    # early on (t << the bending period, ~0.9 s) the free end falls as g t^2 / 2
    out = tmp_path / "beam.h5"
    argv = ["run", str(EXAMPLES / "cantilever.toml"), "--dx", "0.005", "--t-end", "0.01"]
    assert main([*argv, "--quiet", "--out", str(out)]) == 0
    trajectory, meta = read_trajectory(out)
    assert meta["case"] == "cantilever"
    kind = np.asarray(trajectory.states.kind[0])
    x0, x1 = (np.asarray(trajectory.states.position[i]) for i in (0, -1))
    t = float(trajectory.times[-1])
    assert np.array_equal(x0[kind == sphjax.Kind.CLAMPED], x1[kind == sphjax.Kind.CLAMPED])
    tip = (kind == sphjax.Kind.SOLID) & (x0[:, 0] > x0[:, 0].max() - 1e-9)
    fall = x1[tip, 1].mean() - x0[tip, 1].mean()
    assert fall == pytest.approx(-0.5 * 2.0 * t**2, rel=0.05)
    assert np.allclose(trajectory.times, [0.0, 0.01])  # the file's save_dt = 0.01


def _plate_toml(case) -> str:
    """The built-in hydrostatic_fsi_plate ``case`` (cell placement) as a set-up file: a
    tank whose floor is the plate, side walls filled with wall particles standing on the
    clamps, every number as the case computes it."""
    i, p, d = case.info, case.params, case.model.domain
    dx, L, t, H = i["dx"], i["length"], i["thickness"], i["depth"]
    cutoff = case.model.kernel.support * case.model.smoothing_length
    layers = math.ceil(cutoff / dx - 1e-9)
    wall_top = math.ceil((H + max(0.1 * H, 2 * cutoff)) / dx) * dx
    return f"""
dim = 2
dx = {dx!r}
h_factor = {case.model.smoothing_length / dx!r}
gravity = [0.0, {float(p.gravity[1])!r}]
[time]
t_end = 1.0
dt = {case.dt!r}
[domain]
lower = [{d.lower[0]!r}, {d.lower[1]!r}]
upper = [{d.upper[0]!r}, {d.upper[1]!r}]
[fluid]
density = {float(p.reference_density)!r}
sound_speed = {float(p.sound_speed)!r}
artificial_viscosity = {float(p.artificial_alpha)!r}
density_diffusion = {float(p.density_diffusion)!r}
hydrostatic = true
[[fluid.shapes]]
shape = "rectangle"
lower = [0.0, 0.0]
upper = [{L!r}, {H!r}]
[walls]
[[walls.shapes]]
shape = "rectangle"
lower = [{-layers * dx!r}, 0.0]
upper = [0.0, {wall_top!r}]
side = "fill"
[[walls.shapes]]
shape = "rectangle"
lower = [{L!r}, 0.0]
upper = [{L + layers * dx!r}, {wall_top!r}]
side = "fill"
[solid]
density = {float(p.solid_density)!r}
young_modulus = {float(p.young_modulus)!r}
poisson_ratio = {float(p.poisson_ratio)!r}
substeps = {i["substeps"]}
[[solid.shapes]]
shape = "rectangle"
lower = [0.0, {-t!r}]
upper = [{L!r}, 0.0]
[[solid.clamps]]
shape = "rectangle"
lower = [{-2 * layers * dx!r}, {-t!r}]
upper = [0.0, 0.0]
[[solid.clamps]]
shape = "rectangle"
lower = [{L!r}, {-t!r}]
upper = [{L + 2 * layers * dx!r}, 0.0]
"""


@pytest.mark.parametrize("n", [2, 3])
def test_toml_fsi_plate_is_the_built_in_one(tmp_path, n):
    """A fluid, walls and an elastic solid in one file make the coupled case: the file of
    the built-in hydrostatic plate (split integration, 5 plate steps a step) builds it
    particle for particle, with the same model (the solid a no-slip moving boundary for
    the fluid), parameters and step, so the runs are the same bit for bit."""
    theirs = sphjax.cases.get("hydrostatic_fsi_plate", n=n, length=0.3, depth=0.1, substeps=5)
    ours = from_toml(_write(tmp_path, "plate.toml", _plate_toml(theirs)))
    for field in ("position", "velocity", "density", "mass", "kind", "volume"):
        a, b = np.asarray(getattr(ours.state, field)), np.asarray(getattr(theirs.state, field))
        assert a.shape == b.shape and np.array_equal(a, b), field
    assert ours.model == theirs.model
    assert ours.model.system(sphjax.SolidSystem).substeps == 5
    for (name, a), (_, b) in zip(ours.params.items(), theirs.params.items(), strict=True):
        assert np.array_equal(np.asarray(a), np.asarray(b)), name
    assert ours.dt == theirs.dt
    # the initial state follows the parameters as the built-in one's does
    params = theirs.params.replace(sound_speed=5.0, solid_density=900.0)
    for field in ("density", "mass"):
        a = np.asarray(getattr(ours.state_for(params), field))
        assert np.array_equal(a, np.asarray(getattr(theirs.state_for(params), field))), field


def _floating_body_toml(case) -> str:
    """The built-in floating body ``case`` as a set-up file (its numbers as it computed
    them): water around a rigid body in an open tank, the body cut out of the water."""
    i = case.info
    dx, W, D = i["dx"], i["tank_width"], i["water_depth"]
    x0 = float(np.min(np.asarray(case.state.position)[list(i["body_indices"]), 0])) - dx / 2
    y0, w, hb = i["initial_bottom"], i["body_width"], i["body_height"]
    tank_height = max(1.5 * D, y0 + 2 * hb)
    lower, upper = case.model.domain.lower, case.model.domain.upper
    return f"""
name = "floating_body_toml"
dim = 2
dx = {dx!r}
gravity = [0.0, -9.81]
[time]
t_end = 2.0
[domain]
lower = [{lower[0]!r}, {lower[1]!r}]
upper = [{upper[0]!r}, {upper[1]!r}]
[fluid]
density = 1000.0
sound_speed = {float(case.params.sound_speed)!r}
artificial_viscosity = 0.1
density_diffusion = 0.1
hydrostatic = true
[[fluid.shapes]]
shape = "rectangle"
lower = [0.0, 0.0]
upper = [{W!r}, {D!r}]
[walls]
[[walls.shapes]]
shape = "rectangle"
lower = [0.0, 0.0]
upper = [{W!r}, {tank_height!r}]
open_top = true
[rigid]
density = {float(case.params.solid_density)!r}
[[rigid.shapes]]
shape = "rectangle"
lower = [{x0!r}, {y0!r}]
upper = [{x0 + w!r}, {y0 + hb!r}]
"""


def test_toml_floating_body_is_the_built_in_one(tmp_path):
    """A fluid, walls and a ``[rigid]`` body make the built-in floating body particle for
    particle, with the same model (the body a no-slip moving boundary), parameters and
    step; the initial state follows the body's density as the built-in one's does."""
    theirs = sphjax.cases.floating_body(n=4)
    ours = from_toml(_write(tmp_path, "body.toml", _floating_body_toml(theirs)))
    for field in ("position", "velocity", "density", "mass", "kind", "volume"):
        a, b = np.asarray(getattr(ours.state, field)), np.asarray(getattr(theirs.state, field))
        assert a.shape == b.shape and np.array_equal(a, b), field
    assert ours.model == theirs.model
    assert ours.info["n_rigid"] == len(theirs.info["body_indices"])
    for (name, a), (_, b) in zip(ours.params.items(), theirs.params.items(), strict=True):
        assert np.array_equal(np.asarray(a), np.asarray(b)), name
    assert ours.params.unused == theirs.params.unused
    assert ours.dt == theirs.dt
    params = theirs.params.replace(solid_density=700.0)
    for field in ("density", "mass"):
        a = np.asarray(getattr(ours.state_for(params), field))
        assert np.array_equal(a, np.asarray(getattr(theirs.state_for(params), field))), field


def test_example_floating_body_is_the_default_floating_body():
    example, default = from_toml(EXAMPLES / "floating_body.toml"), sphjax.cases.floating_body()
    a, b = np.asarray(example.state.position), np.asarray(default.state.position)
    assert a.shape == b.shape
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
    assert np.array_equal(np.asarray(example.state.kind), np.asarray(default.state.kind))
    assert example.model.systems == default.model.systems
    assert float(example.params.solid_density) == float(default.params.solid_density)


def test_example_fsi_plate_sags_under_the_column():
    """examples/fsi_plate.toml (0.5 m plate, 0.02 m thick, under 0.3 m of water) at dx =
    0.01: split integration by default, with as many plate steps a step as the plate's
    stable step fits in the fluid's (t = 0: c0 = 17.2 m/s, c_s = sqrt(E / (2 (1 - 2 nu))
    / rho_s)); the plate's mid-span sags, no faster than free of elastic forces under its
    weight and the column's, ``g (1 + rho_f H / (rho_s t))``; the clamps stay put."""
    case = from_toml(EXAMPLES / "fsi_plate.toml", dx=0.01)
    h = 1.2 * 0.01
    c_s = math.sqrt(1.0e8 / (2 * (1 - 2 * 0.3)) / 1200.0)
    dt_fluid, dt_solid = 0.25 * h / 17.2, 0.3 * h / c_s
    assert case.info["substeps"] == int(dt_fluid / dt_solid) == 15
    assert case.dt == pytest.approx(min(dt_fluid, 15 * dt_solid), rel=1e-6)
    assert (case.info["n_fluid"], case.info["n_solid"], case.info["n_clamped"]) == (1500, 100, 12)
    solid = case.model.system(sphjax.SolidSystem)
    assert solid.boundary.no_slip and solid.substeps == 15
    trajectory = sphjax.simulate(case, n_steps=30, save_every=30)
    kind = np.asarray(case.state.kind)
    x0, x1 = (np.asarray(trajectory.states.position[i]) for i in (0, -1))
    mid = (kind == sphjax.Kind.SOLID) & (np.abs(x0[:, 0] - 0.25) < 0.0051)
    sag = float(np.mean(x1[mid, 1] - x0[mid, 1]))
    t = float(trajectory.times[-1])
    loaded_fall = -0.5 * 9.81 * (1.0 + 1000.0 * 0.3 / (1200.0 * 0.02)) * t**2
    assert loaded_fall < sag < -1e-4, (sag, loaded_fall)
    clamped = kind == sphjax.Kind.CLAMPED
    assert np.array_equal(x0[clamped], x1[clamped])


def test_the_files_time_step_and_saving_are_used(tmp_path):
    text = _edit("t_end = 0.1", "t_end = 0.1\ndt = 1e-4\nsave_every = 2", SOLID)
    path = _write(tmp_path, "s.toml", text)
    out = tmp_path / "s.h5"
    assert main(["run", str(path), "--t-end", "0.0005", "--quiet", "--out", str(out)]) == 0
    trajectory, meta = read_trajectory(out)
    assert meta["dt"] == 1e-4 and meta["n_steps"] == 5 and meta["save_every"] == 2
    assert np.allclose(trajectory.times, np.array([0, 2, 4, 5]) * 1e-4)


def _write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_every_2d_primitive_in_the_drop_example():
    # examples/drop_in_pool.toml (built, not run): a pool with a circular obstacle (walls
    # inside its surface), a polygon ramp (filled wall), a drop above it, a closed tank
    path = EXAMPLES / "drop_in_pool.toml"
    case = from_toml(path)
    dx = 0.02
    pool = geometry.fill(geometry.rectangle([0, 0], [1, 0.4]), dx).position
    obstacle, ramp = (
        geometry.circle([0.3, 0.2], 0.08),
        geometry.Polygon([[0.7, 0.0], [1.0, 0.0], [1.0, 0.15]]),
    )
    kept = pool[~obstacle.contains(pool) & ~ramp.contains(pool)]
    drop = geometry.fill(geometry.circle([0.5, 0.7], 0.1), dx).position
    assert case.info["n_fluid"] == len(kept) + len(drop)
    walls = [
        geometry.wall_layers(geometry.rectangle([0, 0], [1, 1]), dx, 3).position,
        geometry.wall_layers(obstacle, dx, 3, side="inside").position,
        geometry.fill(ramp, dx).position,
    ]
    sites = np.round(np.concatenate(walls) / dx - 0.5)
    assert case.info["n_wall"] == len(np.unique(sites, axis=0))
    kind = np.asarray(case.state.kind)
    v = np.asarray(case.state.velocity)
    assert np.sum(v[:, 1] == -1.0) == len(drop) and np.all(v[kind == sphjax.Kind.WALL] == 0)
    # hydrostatic: the pool's bottom row is denser than its surface, the drop starts at rest
    rho, y = np.asarray(case.state.density), np.asarray(case.state.position)[:, 1]
    fluid = kind == sphjax.Kind.FLUID
    assert rho[fluid & (y < dx)].min() > rho[fluid & (y > 0.4 - dx) & (y < 0.4)].max() > 1000.0
    bottom = 1000.0 * 9.81 * (0.4 - dx / 2)  # p at the lowest row, Tait inverted
    expected = 1000.0 * (bottom / (1000.0 * 30.0**2 / 7.0) + 1.0) ** (1 / 7)
    assert rho[fluid & (y < dx)].max() == pytest.approx(expected, rel=1e-6)


def test_stl_and_3d_primitives_in_a_file(tmp_path):
    trimesh.creation.icosphere(subdivisions=2, radius=0.1).export(tmp_path / "ball.stl")
    path = _write(
        tmp_path,
        "drop.toml",
        """
dim = 3
dx = 0.025
gravity = [0.0, 0.0, -9.81]
[time]
t_end = 0.1
[fluid]
density = 1000.0
sound_speed = 20.0
[[fluid.shapes]]
shape = "stl"
file = "ball.stl"
scale = 2.0
translate = [0.25, 0.25, 0.3]
[[fluid.shapes]]
shape = "box"
lower = [0.0, 0.0, 0.0]
upper = [0.5, 0.5, 0.05]
[walls]
[[walls.shapes]]
shape = "box"
lower = [0.0, 0.0, 0.0]
upper = [0.5, 0.5, 0.6]
open_top = true
[[walls.shapes]]
shape = "cylinder"
base = [0.1, 0.1, 0.0]
axis = [0.0, 0.0, 1.0]
radius = 0.04
length = 0.05
side = "fill"
""",
    )
    case = from_toml(path)
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.1)
    ball.apply_scale(2.0)
    ball.apply_translation([0.25, 0.25, 0.3])
    n_ball = len(geometry.fill(geometry.Mesh(ball), 0.025))
    pool = geometry.fill(geometry.box([0, 0, 0], [0.5, 0.5, 0.05]), 0.025).position
    post = geometry.Cylinder([0.1, 0.1, 0.0], [0, 0, 1], 0.04, 0.05)
    assert case.info["n_fluid"] == n_ball + int(np.sum(~post.contains(pool)))
    assert n_ball * 0.025**3 == pytest.approx(ball.volume, rel=0.1)
    assert case.model.dim == 3 and case.state.position.shape == (case.n_particles, 3)


# ---------------------------------------------------------------------------- bad input

BASE = """
dim = 2
dx = 0.05
gravity = [0.0, -9.81]

[time]
t_end = 0.01

[fluid]
density = 1000.0
sound_speed = 20.0

[[fluid.shapes]]
shape = "rectangle"
lower = [0.0, 0.0]
upper = [0.3, 0.3]

[walls]

[[walls.shapes]]
shape = "rectangle"
lower = [0.0, 0.0]
upper = [1.0, 0.5]
open_top = true
"""

SOLID = """
dim = 2
dx = 0.01
[time]
t_end = 0.1
[solid]
density = 1000.0
young_modulus = 1e6
poisson_ratio = 0.3
[[solid.shapes]]
shape = "rectangle"
lower = [0.0, 0.0]
upper = [0.2, 0.02]
"""

RIGID = """
[rigid]
density = 500.0
[[rigid.shapes]]
shape = "rectangle"
lower = [0.1, 0.2]
upper = [0.2, 0.3]
"""


def test_the_base_files_are_valid(tmp_path):
    assert from_toml(_write(tmp_path, "a.toml", BASE)).info["n_fluid"] == 36
    assert from_toml(_write(tmp_path, "b.toml", SOLID)).info["n_solid"] == 40
    body = from_toml(_write(tmp_path, "c.toml", BASE + RIGID))
    assert body.info["n_rigid"] == 4 and body.info["n_fluid"] == 36 - 4  # cut out
    assert body.model.systems[-1].wall_contact is None
    with pytest.raises(sphjax.UnusedParameterError, match=r"^contact_frequency is not used"):
        body.params.replace(contact_frequency=800.0)


def test_a_rigid_contact_table_gives_the_body_wall_contact(tmp_path):
    """``[rigid.contact]`` is ``RigidSystem(wall_contact=WallContact(distance=...))`` and
    the contact's Params (``frequency``, ``damping_ratio``, ``friction``: 1 and 0.5 by
    default), and with it the body and the walls get neighbour lists; without it the
    contact's Params are refused."""
    from sphjax.physics.rhs import neighbor_pairs

    text = BASE + RIGID + "[rigid.contact]\nfrequency = 800.0\nfriction = 0.2\n"
    body = from_toml(_write(tmp_path, "contact.toml", text))
    # the static distance on the model, the spring, dashpot and friction as Params
    assert body.model.systems[-1].wall_contact == sphjax.WallContact(distance=1.5)
    assert float(body.params.contact_frequency) == 800.0
    assert float(body.params.contact_damping_ratio) == 1.0
    assert float(body.params.contact_friction) == 0.2
    assert {"contact_frequency", "contact_damping_ratio", "contact_friction"} <= set(
        body.params.used
    )
    types = [type(s).__name__ for s in body.model.systems]
    pairs = {(types[i], types[j]) for i, j in neighbor_pairs(body.model)}
    assert ("RigidSystem", "WallSystem") in pairs
    assert body.dt <= sphjax.WallContact.time_step_limit(body.params)
    assert isinstance(body.model.systems[-1], sphjax.RigidSystem)


def _edit(old, new, base=BASE):
    assert old in base, old
    return base.replace(old, new, 1)


BAD_FILES = [
    (_edit("dx = 0.05", "dxx = 0.05"), "dxx: unknown key; did you mean 'dx'?"),
    (_edit("dx = 0.05", ""), "dx: missing; add it (the particle spacing in m)"),
    (_edit("dx = 0.05", "dx = -1"), "dx: must be a positive number, got -1"),
    (_edit("dx = 0.05", 'dx = "fine"'), "dx: must be a number, got 'fine'"),
    (_edit("dim = 2", "dim = 4"), "dim: must be 2 or 3, got 4"),
    (_edit("[0.0, -9.81]", "[0.0, -9.81, 0.0]"), "gravity: must be 2 numbers (one per axis)"),
    (_edit("[time]\nt_end = 0.01", ""), "time: missing; add a [time] section with t_end"),
    (_edit("t_end = 0.01", 't_end = "1"'), "time.t_end: must be a number, got '1'"),
    (_edit("t_end = 0.01", "t_end = 0.01\ndt = 1e-5\ncfl = 0.2"), "time.cfl: give either"),
    (_edit("t_end = 0.01", "t_end = 0.01\ndt = 1.0"), "time.dt: 1 exceeds the stability limit"),
    (
        _edit("t_end = 0.01", "t_end = 0.01\nsave_every = 2\nsave_dt = 0.001"),
        "time.save_dt: give either time.save_every or time.save_dt",
    ),
    (
        _edit("sound_speed", "sound_sped"),
        "fluid.sound_sped: unknown key; did you mean 'sound_speed'",
    ),
    (_edit("sound_speed = 20.0", ""), "fluid.sound_speed: missing; add it (about 10x the largest"),
    (_edit("sound_speed = 20.0", "sound_speed = 0"), "fluid.sound_speed: must be a positive"),
    (
        _edit("density = 1000.0", 'density = 1000.0\ndensity_model = "sum"'),
        "fluid.density_model: unknown value 'sum'; choose one of continuity, summation",
    ),
    (
        _edit("density = 1000.0", 'density = 1000.0\nequation_of_state = "linear"\ngamma = 7'),
        "fluid.gamma: applies to the Tait equation of state only",
    ),
    (
        _edit("density = 1000.0", "density = 1000.0\nhydrostatic = 1"),
        "fluid.hydrostatic: must be true or false",
    ),
    (
        _edit('shape = "rectangle"', 'shape = "rectangel"'),
        "fluid.shapes[0].shape: unknown value 'rectangel'; did you mean 'rectangle'?",
    ),
    (
        _edit('shape = "rectangle"', 'shape = "box"'),
        "fluid.shapes[0].shape: a box is 3D but dim = 2; use 'rectangle'",
    ),
    (
        _edit("upper = [0.3, 0.3]", "upper = [0.3, -0.3]"),
        "fluid.shapes[0].upper: [1] = -0.3 must exceed",
    ),
    (_edit("upper = [0.3, 0.3]", "upper = [0.3]"), "fluid.shapes[0].upper: must be 2 numbers"),
    (
        _edit("upper = [0.3, 0.3]", "uper = [0.3, 0.3]"),
        "fluid.shapes[0].uper: unknown key; did you mean 'upper'?",
    ),
    (_edit("upper = [0.3, 0.3]", ""), "fluid.shapes[0].upper: missing; add it"),
    (
        _edit("upper = [0.3, 0.3]", "upper = [0.3, 0.3]\nradius = 1"),
        "fluid.shapes[0].radius: unknown key; the keys here are velocity, shape, lower, upper",
    ),
    (
        _edit(
            'shape = "rectangle"\nlower = [0.0, 0.0]\nupper = [0.3, 0.3]',
            'shape = "circle"\ncentre = [0.2, 0.2]\nradius = -0.1',
        ),
        "fluid.shapes[0].radius: must be a positive number, got -0.1",
    ),
    (
        _edit(
            'shape = "rectangle"\nlower = [0.0, 0.0]\nupper = [0.3, 0.3]',
            'shape = "polygon"\nvertices = [[0, 0], [0.3, 0.3], [0.3, 0], [0, 0.3]]',
        ),
        "fluid.shapes[0].vertices: do not form a simple polygon: edge 0",
    ),
    (
        _edit(
            'shape = "rectangle"\nlower = [0.0, 0.0]\nupper = [0.3, 0.3]',
            'shape = "stl"\nfile = "x.stl"',
        ),
        "fluid.shapes[0].shape: a stl is 3D but dim = 2",
    ),
    (
        _edit("upper = [0.3, 0.3]", "upper = [1.3, 0.3]"),
        "fluid.shapes[0]: 18 of its particles lie in the walls; keep the fluid inside",
    ),
    (
        _edit("[walls]\n", "[walls]\nslip = 'slip'\n"),
        "walls.slip: unknown value 'slip'; did you mean",
    ),
    (
        _edit("open_top = true", 'side = "outsde"'),
        "walls.shapes[0].side: unknown value 'outsde'; did you mean 'outside'?",
    ),
    (
        _edit("open_top = true", 'open_top = true\nside = "inside"'),
        "walls.shapes[0].open_top: applies to side = 'outside' walls, not 'inside'",
    ),
    (_edit("[walls]\n", "[walls]\nlayers = 0\n"), "walls.layers: must be a positive number, got 0"),
    (
        BASE + "[domain]\nlower = [0.0, 0.0]\nupper = [1.0, 1.0]\n",
        "domain: 138 particles lie outside it (e.g. at -0.125, -0.125); enlarge",
    ),
    (
        BASE + _edit("[0.0, 0.0]", "[-0.2, -0.1]", SOLID.split("[time]")[1].split("\n", 2)[2]),
        "solid.shapes: 14 of their particles lie in the walls (e.g. at -0.125, -0.075); a "
        "solid and the walls may touch but not overlap",
    ),
    (
        _edit("poisson_ratio = 0.3", "poisson_ratio = 0.3\nsubsteps = 4", SOLID),
        "solid.substeps: concerns a solid in a fluid only (fluid-structure coupling); remove "
        "it or add a [fluid] section",
    ),
    (
        _edit("poisson_ratio = 0.3", 'poisson_ratio = 0.3\nslip = "free_slip"', SOLID),
        "solid.slip: concerns a solid in a fluid only",
    ),
    (
        BASE + _edit("0.3\n", '0.3\nsubsteps = "fast"\n', SOLID.split("t_end = 0.1\n")[1]),
        "solid.substeps: must be a whole number >= 1 or \"auto\", got 'fast'",
    ),
    (
        BASE + _edit("0.3\n", "0.3\nsubsteps = 2.5\n", SOLID.split("t_end = 0.1\n")[1]),
        "solid.substeps: must be a whole number, got 2.5",
    ),
    (
        BASE + _edit("0.3\n", '0.3\nslip = "slippy"\n', SOLID.split("t_end = 0.1\n")[1]),
        "solid.slip: unknown value 'slippy'; did you mean 'no_slip'?",
    ),
    (
        BASE + _edit("density = 500.0", 'density = 500.0\nslip = "sticky"', RIGID),
        "rigid.slip: unknown value 'sticky'; choose one of no_slip, free_slip",
    ),
    (BASE + _edit("density = 500.0", "", RIGID), "rigid.density: missing; add it"),
    (
        _edit(
            "[walls]\n",
            '[walls]\nslip = "free_slip"\n',
            _edit("open_top", "velocity = [1.0, 0.0]\nopen_top"),
        ),
        "walls.shapes[0].velocity: acts through the no-slip condition only; remove it or "
        "set walls.slip = 'no_slip'",
    ),
    (
        BASE + RIGID + "[rigid.contact]\ndamping_ratio = 1.0\n",
        "rigid.contact.frequency: missing; add it (omega in rad/s)",
    ),
    (
        BASE + RIGID + "[rigid.contact]\nfrequency = 800.0\ndistance = 0.5\n",
        "rigid.contact.distance: must be >= 1 (particle spacings), got 0.5",
    ),
    (
        BASE + RIGID + "[rigid.contact]\nfrequency = 800.0\nfrictoin = 0.1\n",
        "rigid.contact.frictoin: unknown key; did you mean 'friction'?",
    ),
    (
        BASE + _edit("[0.1, 0.2]", "[0.1, -0.1]", RIGID),
        "rigid.shapes: 4 of their particles lie in the walls (e.g. at 0.125, -0.075)",
    ),
    (
        SOLID + RIGID,
        "rigid: a file has a [solid] or a [rigid] section, not both (both are set by "
        "Params.solid_density); remove one of them",
    ),
    (
        SOLID.split("[solid]")[0]
        + _edit("density = 500.0", 'density = 500.0\nslip = "no_slip"', RIGID),
        "rigid.slip: concerns a body in a fluid only; remove it or add a [fluid] section",
    ),
    (
        _edit("dim = 2", "dim = 3", SOLID.split("[solid]")[0]) + RIGID,
        "rigid: rigid bodies are 2D (RigidSystem) but dim = 3; use dim = 2",
    ),
    (_edit("[fluid]", "[fluids]"), "fluids: unknown key; did you mean 'fluid'?"),
    (
        BASE.split("[fluid]")[0] + "[walls]\n" + BASE.split("[walls]")[1],
        "walls: walls act on a fluid only",
    ),
    (
        BASE.split("[fluid]")[0],
        "the file describes no body; add a [fluid], a [solid] or a [rigid] section",
    ),
    (
        _edit("poisson_ratio = 0.3", "poisson_ratio = 0.7", SOLID),
        "solid.poisson_ratio: must lie in (-1, 0.5), got 0.7",
    ),
    (_edit("young_modulus = 1e6\n", "", SOLID), "solid.young_modulus: missing; add it (E in Pa)"),
    (
        _edit(
            "density = 1000.0",
            'density = 1000.0\ndensity_model = "summation"\ndensity_diffusion = 0.1',
        ),
        "fluid.density_diffusion: applies to density_model = 'continuity' only",
    ),  # fmt: skip
    (_edit("dx = 0.05", "dx = 0.05\ngravity 0"), "not valid TOML: Expected '=' after a key"),
    ("fluid = 3\n" + BASE.split("[fluid]")[0], "fluid: must be a table (a [fluid] section)"),
]


@pytest.mark.parametrize(("text", "message"), BAD_FILES, ids=[m[:40] for _, m in BAD_FILES])
def test_bad_file_exits_2_with_one_line(text, message, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("bad.toml").write_text(text)
    assert main(["run", "bad.toml", "--quiet", "--out", "x.h5"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sphjax run: error: bad.toml: ")
    assert message in err, err
    assert len(err.strip().splitlines()) == 1, err
    assert "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]  # nothing written


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["nothere.toml"], "CASE: 'nothere.toml' does not exist; give the path of a set-up"),
        (["EX", "--n", "10"], "--n: applies to the named cases; for a set-up file set dx"),
        (["EX", "--case-arg", "n=3"], "--case-arg: applies to the named cases"),
        (["EX", "--dx", "2"], "fluid.shapes: hold no particle at dx = 2; use a smaller dx"),
    ],
)
def test_bad_run_arguments_with_a_file(argv, message, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("ok.toml").write_text(BASE)
    argv = ["ok.toml" if a == "EX" else a for a in argv]
    assert main(["run", *argv, "--quiet", "--out", "x.h5"]) == 2
    err = capsys.readouterr().err
    assert message in err, err
    assert len(err.strip().splitlines()) == 1, err


def test_a_key_given_chooses_its_term_and_the_others_are_refused(tmp_path):
    """Parameters act or are refused: a term's key in the file (0 included) puts the term
    in the model, so the value set acts and ``replace`` and ``jax.grad`` reach it; a term
    whose key is absent is not in the model, and its parameter is refused."""
    base = from_toml(_write(tmp_path, "a.toml", BASE))
    fluid = base.model.systems[0]
    assert fluid.viscosity == () and fluid.density_diffusion is None
    unused = dict(base.params.unused)
    for field in ("artificial_alpha", "artificial_beta", "kinematic_viscosity",
                  "density_diffusion", "transport_pressure"):  # fmt: skip
        assert field in unused
    with pytest.raises(sphjax.UnusedParameterError, match=r"^kinematic_viscosity is not used"):
        base.params.replace(kinematic_viscosity=1e-3)
    given = _edit(
        "sound_speed = 20.0",
        "sound_speed = 20.0\nkinematic_viscosity = 0.0\nartificial_beta = 0.0\n"
        "density_diffusion = 0.0",
    )
    case = from_toml(_write(tmp_path, "b.toml", given))
    fluid = case.model.systems[0]
    assert fluid.physical_viscosity and fluid.artificial_viscosity
    assert isinstance(fluid.density_diffusion, sphjax.MolteniColagrossi)
    assert dict(case.params.unused).keys() == {"transport_pressure"}
    assert float(case.params.replace(kinematic_viscosity=1e-3).kinematic_viscosity) == 1e-3
    assert float(case.params.density_diffusion) == 0.0
    # in the solid: penalty_alpha absent, no penalty force, refused; given, it acts
    solid = from_toml(_write(tmp_path, "s.toml", SOLID))
    with pytest.raises(sphjax.UnusedParameterError, match=r"^penalty_alpha is not used"):
        solid.params.replace(penalty_alpha=0.1)
    penalised = from_toml(_write(tmp_path, "p.toml", _edit("poisson_ratio = 0.3",
                          "poisson_ratio = 0.3\npenalty_alpha = 0.0", SOLID)))  # fmt: skip
    # only a rigid body's wall-contact fields are left over, refused by an elastic solid
    contact = {"contact_frequency", "contact_damping_ratio", "contact_friction"}
    assert dict(penalised.params.unused).keys() == contact


def test_errors_name_the_key_in_python(tmp_path):
    path = _write(tmp_path, "s.toml", _edit("sound_speed = 20.0", "sound_speed = -1"))
    with pytest.raises(SetupError, match=r"^fluid.sound_speed: must be a positive") as err:
        from_toml(path)
    assert err.value.key == "fluid.sound_speed"
    with pytest.raises(SetupError, match="^dx: must be a positive number"):
        from_toml(_write(tmp_path, "ok.toml", BASE), dx=0.0)


def test_example_dam_break_runs_as_the_docs_show(tmp_path, monkeypatch, capsys):
    # the Python blocks of docs/setups.md: examples/dam_break.toml at dx = 0.05, 10 steps
    shutil.copytree(EXAMPLES, tmp_path / "examples")
    monkeypatch.chdir(tmp_path)
    page = EXAMPLES.parent / "docs" / "setups.md"
    blocks = re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.S)
    assert len(blocks) == 2
    names = {"__name__": "docs"}
    for block in blocks:
        exec(compile(block, "setups.md", "exec"), names)
    assert capsys.readouterr().out.split() == ["270", "3", "800", "0.000225"]
    case, trajectory = names["case"], names["trajectory"]
    assert case.name == "dam_break_toml" and case.info["n_fluid"] == 6 * 12  # 0.3 x 0.6 m
    positions = np.asarray(trajectory.states.position)
    assert np.all(np.isfinite(positions)) and not np.array_equal(positions[0], positions[-1])
