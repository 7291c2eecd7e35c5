"""Ensemble datasets in the LagrangeBench layout (sphjax.dataset)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from _tiny_dataset import KWARGS, N_SIDE, make, shared

METADATA_KEYS = {
    "case",
    "solver",
    "dim",
    "dx",
    "dt",
    "write_every",
    "t_end",
    "sequence_length_train",
    "sequence_length_test",
    "num_trajs_train",
    "num_trajs_test",
    "num_particles_max",
    "periodic_boundary_conditions",
    "bounds",
    "default_connectivity_radius",
    "vel_mean",
    "vel_std",
    "acc_mean",
    "acc_std",
    "viscosity",
    "artificial_alpha",
    "g_ext_magnitude",
    "p_bg_factor",
    "density_evolution",
}


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return shared(tmp_path_factory)


def _read(folder, split):
    with h5py.File(Path(folder) / f"{split}.h5", "r") as f:
        return {k: (f[k]["position"][()], f[k]["particle_type"][()], dict(f[k].attrs)) for k in f}


def test_layout_shapes_dtypes_and_metadata(dataset):
    assert sorted(p.name for p in dataset.iterdir()) == [
        "metadata.json",
        "test.h5",
        "train.h5",
        "valid.h5",
    ]
    meta = json.loads((dataset / "metadata.json").read_text())
    assert METADATA_KEYS <= set(meta)
    frames = KWARGS["steps"] // KWARGS["write_every"] + 1
    n = N_SIDE**2
    assert meta["sequence_length_train"] == frames and meta["num_particles_max"] == n
    assert meta["periodic_boundary_conditions"] == [True, True]
    assert meta["bounds"] == [[0.0, 1.0], [0.0, 1.0]]
    assert meta["default_connectivity_radius"] == pytest.approx(1.45 / N_SIDE)
    assert meta["t_end"] == pytest.approx(meta["dt"] * KWARGS["steps"])
    for split, count in [("train", 3), ("valid", 1), ("test", 1)]:
        groups = _read(dataset, split)
        assert sorted(groups) == [f"{i:05d}" for i in range(count)]
        for x, t, attrs in groups.values():
            assert x.dtype == np.float32 and x.shape == (frames, n, 2)
            assert np.issubdtype(t.dtype, np.integer) and t.shape == (n,)
            assert np.all(t == 0) and np.all(np.isfinite(x))
            assert np.all((x >= 0) & (x < 1))
            assert 0.008 <= attrs["kinematic_viscosity"] <= 0.012
    # trajectories differ from the first frame on: the Taylor-Green disorder is drawn per
    # trajectory from --seed, not shared through the case's own seed
    train = _read(dataset, "train")
    assert not np.allclose(train["00000"][0][1], train["00001"][0][1])
    assert not np.allclose(train["00000"][0][0], train["00001"][0][0])


def test_statistics_recomputed_independently(dataset):
    meta = json.loads((dataset / "metadata.json").read_text())
    vel, acc = [], []
    for x, t, _ in _read(dataset, "train").values():
        x = x[:, t == 0].astype(np.float64)
        v = np.diff(x, axis=0)
        v = (v + 0.5) % 1.0 - 0.5  # minimum image in the unit box
        vel.append(v.reshape(-1, 2))
        acc.append(np.diff(v, axis=0).reshape(-1, 2))
    vel, acc = np.concatenate(vel), np.concatenate(acc)
    np.testing.assert_allclose(meta["vel_mean"], vel.mean(0), atol=1e-9)
    np.testing.assert_allclose(meta["vel_std"], vel.std(0), rtol=1e-6)
    np.testing.assert_allclose(meta["acc_mean"], acc.mean(0), atol=1e-9)
    np.testing.assert_allclose(meta["acc_std"], acc.std(0), rtol=1e-6)
    # per-frame displacements are small compared with the box: no wrap-around jumps left
    assert np.abs(vel).max() < 0.1


def test_interrupted_run_is_marked_and_resumes_to_the_same_data(dataset, tmp_path):
    from sphjax.surrogate import data

    out = tmp_path / "tg"
    make(out, stop_after=1)  # one batch of two trajectories, then "interrupted"
    assert (out / "INCOMPLETE").exists()
    assert not (out / "metadata.json").exists() and not (out / "train.h5").exists()
    with pytest.raises(ValueError, match="incomplete"):
        data.load(out, "train")
    with pytest.raises(FileExistsError, match="resume"):
        make(out)
    make(out, resume=True)
    assert not (out / "INCOMPLETE").exists() and not (out / ".partial").exists()
    for split in ("train", "valid", "test"):
        a, b = _read(dataset, split), _read(out, split)
        for k in a:
            np.testing.assert_array_equal(a[k][0], b[k][0])
    assert json.loads((out / "metadata.json").read_text()) == json.loads(
        (dataset / "metadata.json").read_text()
    )


def test_bad_arguments_are_named():
    import sphjax
    from sphjax.dataset import generate_dataset

    case = sphjax.cases.taylor_green(n=8)
    with pytest.raises(ValueError, match="young_modulusx"):
        generate_dataset(
            case,
            "/nonexistent",
            n_train=1,
            n_valid=0,
            n_test=0,
            steps=4,
            write_every=2,
            vary={"young_modulusx": (1, 2)},
        )
    with pytest.raises(ValueError, match="write_every"):
        generate_dataset(
            case, "/nonexistent", n_train=1, n_valid=0, n_test=0, steps=5, write_every=2
        )
    # a range with an end the field cannot take: named before any draw or time step
    with pytest.raises(ValueError, match=r"vary: sound_speed=0:10: Params.sound_speed must"):
        generate_dataset(
            case,
            "/nonexistent",
            n_train=1,
            n_valid=0,
            n_test=0,
            steps=4,
            write_every=2,
            vary={"sound_speed": (0.0, 10.0)},
        )


def test_an_existing_dataset_folder_is_not_replaced(tmp_path, monkeypatch):
    """``generate_dataset`` into a folder that holds files (or onto a file) raises one
    FileExistsError naming ``out`` and ``overwrite=True`` before any initial condition is
    built, and leaves the folder as it was."""
    import sphjax
    from sphjax.dataset import generate, generate_dataset

    def never(*args, **kwargs):
        raise AssertionError("the refusal must come before the initial conditions")

    monkeypatch.setattr(generate, "initial_conditions", never)
    case = sphjax.cases.taylor_green(n=4)
    sizes = dict(n_train=1, n_valid=0, n_test=0, steps=4, write_every=2)
    folder = tmp_path / "data"
    folder.mkdir()
    (folder / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError) as error:
        generate_dataset(case, folder, **sizes)
    assert str(error.value) == (
        f"out: '{folder}' is not empty; pass overwrite=True to replace what it holds, "
        "or choose another folder"
    )
    assert (folder / "notes.txt").read_text() == "mine"
    (folder / "INCOMPLETE").write_text("{}")
    with pytest.raises(FileExistsError, match=r"^out: .* pass resume=True .* overwrite=True"):
        generate_dataset(case, folder, **sizes)
    with pytest.raises(FileExistsError, match=r"^out: .* is a file"):
        generate_dataset(case, folder / "notes.txt", **sizes)


def test_cli_parses_the_dataset_command():
    from sphjax.cli import _parser as build_parser

    args = build_parser().parse_args(
        [
            "dataset",
            "taylor_green",
            "--out",
            "d",
            "--n-train",
            "4",
            "--n-valid",
            "1",
            "--n-test",
            "1",
            "--steps",
            "20",
            "--write-every",
            "5",
            "--vary",
            "kinematic_viscosity=0.005:0.02",
            "--seed",
            "7",
            "--case-arg",
            "n=16",
            "--resume",
        ]
    )
    assert args.vary == [("kinematic_viscosity", (0.005, 0.02))]
    assert args.case_arg == [("n", 16)] and args.resume and args.seed == 7
    assert args.command == "dataset"


def test_sharded_run_matches_single_device(dataset, tmp_path):
    """Four forced host devices (a fresh process) give the same trajectories."""
    script = Path(__file__).with_name("_tiny_dataset.py")
    import jax

    env = dict(
        os.environ,
        XLA_FLAGS="--xla_force_host_platform_device_count=4",
        JAX_ENABLE_X64=str(bool(jax.config.jax_enable_x64)),  # same precision as this session
    )
    run = subprocess.run(
        [sys.executable, str(script), str(tmp_path / "tg4"), "4"],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    assert "devices 4" in run.stdout
    for split in ("train", "valid", "test"):
        a, b = _read(dataset, split), _read(tmp_path / "tg4", split)
        assert sorted(a) == sorted(b)
        for k in a:
            np.testing.assert_allclose(a[k][0], b[k][0], rtol=0, atol=1e-6)


def test_seed_draws_the_case_disorder_per_trajectory():
    """--seed changes every trajectory's start, the Taylor-Green disorder included; the
    same seed gives the same start whatever the split sizes (no simulation; ~10 s, the
    case is rebuilt per trajectory)."""
    import sphjax
    from sphjax.dataset import Perturbation, initial_conditions

    case = sphjax.cases.taylor_green(n=8)
    p = Perturbation((0.8, 1.2), 0.3, 2)
    a = initial_conditions(case, (3, 1, 0), p, {}, 1, {"n": 8})
    b = initial_conditions(case, (2, 0, 0), p, {}, 1, {"n": 8})
    c = initial_conditions(case, (3, 1, 0), p, {}, 2, {"n": 8})
    x = lambda jobs, k: np.asarray(jobs[k][2].position)  # noqa: E731
    np.testing.assert_array_equal(x(a, 1), x(b, 1))  # trajectory 1 of train, either way
    assert not np.allclose(x(a, 0), x(a, 1))  # a disorder per trajectory
    assert not np.allclose(x(a, 0), x(c, 0))  # another seed, another disorder
    assert not np.allclose(x(a, 0), np.asarray(case.state.position))  # not the case's own
    # the old behaviour (every trajectory on the case's positions) stays available
    same = initial_conditions(case, (2, 0, 0), Perturbation(case_seed=False), {}, 1, {"n": 8})
    np.testing.assert_array_equal(x(same, 0), np.asarray(case.state.position))
    # case_kwargs that do not rebuild the given case are refused, naming the fix
    with pytest.raises(ValueError, match="case_kwargs=.*--case-arg"):
        initial_conditions(case, (1, 0, 0), p, {}, 1, {"n": 9})


def test_every_seed_writes_the_same_dt(tmp_path):
    """The ensemble's step comes from the case and the ranges, not from the draws: the same
    arguments with two seeds write the same ``dt`` (the draws, and so their own stable
    steps, differ)."""
    import sphjax
    from sphjax.dataset import Perturbation, ensemble_time_step, generate_dataset

    case = sphjax.cases.taylor_green(n=8)
    p = Perturbation((0.8, 1.2), 0.3, 2)
    vary = {"kinematic_viscosity": (0.008, 0.012)}

    def written_dt(folder, seed, **given):
        out = generate_dataset(
            case,
            tmp_path / folder,
            n_train=1,
            n_valid=0,
            n_test=0,
            steps=2,
            write_every=1,
            vary=vary,
            perturbation=p,
            seed=seed,
            progress=False,
            case_kwargs={"n": 8},
            **given,
        )
        return json.loads((out / "metadata.json").read_text())["dt"]

    dts = [written_dt(f"seed{seed}", seed) for seed in (1, 2)]
    assert dts[0] == dts[1] == ensemble_time_step(case, p, vary, {"n": 8})
    # an explicit dt still overrides the rule
    assert written_dt("given", 1, dt=0.5 * dts[0]) == 0.5 * dts[0]


@pytest.mark.parametrize("which", ["taylor_green", "taylor_green_same_seed", "dam_break"])
def test_ensemble_time_step_bounds_every_draw(which):
    """The rule's step is at most the stable step of every drawn trajectory (no simulation;
    a Taylor-Green ensemble whose case seed is redrawn, one on the case's own start, and a
    dam break at rest, where the random field sets the speed)."""
    import sphjax
    from sphjax.dataset import Perturbation, ensemble_time_step, initial_conditions
    from sphjax.integration.timestep import stable_time_step

    if which == "dam_break":
        case, kwargs = sphjax.cases.dam_break(n=4), {"n": 4}
        p = Perturbation((1.0, 1.0), 0.5, 2, jitter=0.1)
        vary = {"artificial_alpha": (0.01, 0.1), "sound_speed": (40.0, 60.0)}
    else:
        case, kwargs = sphjax.cases.taylor_green(n=8), {"n": 8}
        p = Perturbation((0.8, 1.2), 0.3, 2, case_seed=which == "taylor_green")
        vary = {"kinematic_viscosity": (0.008, 0.012), "sound_speed": (8.0, 12.0)}
    dt = ensemble_time_step(case, p, vary, kwargs)
    for seed in (0, 1):
        jobs = initial_conditions(case, (6, 1, 1), p, vary, seed, kwargs)
        steps = [stable_time_step(s, case.model, q) for _, _, s, q in jobs]
        assert dt <= min(steps)
    # the corner with the largest sound speed sets it: the rule is not the case's own step
    assert dt < stable_time_step(case.state, case.model, case.params)


def _worst_end_step(case, perturbation, vary, reseed):
    """The fluid's stable step at the worst end of every range, from the formula (Morris,
    Fox & Zhu 1997): ``min(0.25 h / (c0_hi + V), 0.125 h^2 / nu_hi, 0.25 sqrt(h / |g|))``,
    ``V = (a_hi U + f U')`` times 1.1 if the case seed is redrawn; with the limits apart."""
    from sphjax.core.state import Kind

    h = case.model.smoothing_length
    fluid = np.asarray(case.state.kind) == Kind.FLUID
    peak = np.linalg.norm(np.asarray(case.state.velocity, np.float64)[fluid], axis=1).max()
    top = {name: hi for name, (lo, hi) in vary.items()}
    a_hi, f = perturbation.amplitude[1], perturbation.fourier
    speed = (a_hi * peak + f * (peak if peak > 0 else 1.0)) * (1.1 if reseed else 1.0)
    c0 = top.get("sound_speed", float(case.params.sound_speed))
    limits = {"acoustic": 0.25 * h / (c0 + speed)}
    if "kinematic_viscosity" in case.params.used:
        nu = top.get("kinematic_viscosity", float(case.params.kinematic_viscosity))
        limits["viscous"] = 0.125 * h**2 / nu
    g = float(np.linalg.norm(np.asarray(case.params.gravity)))
    if g > 0:
        limits["body force"] = 0.25 * np.sqrt(h / g)
    return limits


@pytest.mark.parametrize("binding", ["acoustic", "viscous", "body force"])
def test_ensemble_time_step_is_the_stable_step_at_the_worst_end(binding):
    """The rule's step equals the stable step at the worst end of the ranges (the largest
    sound speed, the largest viscosity, the fastest start), computed here from the formula,
    for a range that makes each fluid limit the binding one; where the ranges set it
    (acoustic, viscous) it is smaller than the same formula at their low end, so their top
    is what sets it (no simulation, < 1 s)."""
    import sphjax
    from sphjax.dataset import Perturbation, ensemble_time_step

    if binding == "body force":  # dam break at rest (no case seed), c0 + V < sqrt(g h)
        case, kwargs = sphjax.cases.dam_break(n=4), {"n": 4}
        p = Perturbation((1.0, 1.0), 0.1, 2)
        vary = {"sound_speed": (0.4, 0.8)}
        reseed = False
    else:  # Taylor-Green, case seed redrawn per trajectory
        case, kwargs = sphjax.cases.taylor_green(n=8), {"n": 8}
        p = Perturbation((0.7, 1.1), 0.2, 2)
        nu_top = 0.015 if binding == "acoustic" else 2.0
        vary = {"kinematic_viscosity": (0.0075, nu_top), "sound_speed": (8.0, 12.0)}
        reseed = True
    limits = _worst_end_step(case, p, vary, reseed)
    assert min(limits, key=limits.get) == binding, limits  # the set-up tests what it says
    dt = ensemble_time_step(case, p, vary, kwargs)
    # the same numbers in another order of operations: round-off only
    assert dt == pytest.approx(min(limits.values()), rel=1e-12)
    low = {name: (lo, lo) for name, (lo, _) in vary.items()}
    if binding != "body force":
        assert dt < min(_worst_end_step(case, p, low, reseed).values())


def test_dam_break_dataset_walls_and_free_surface(tmp_path):
    """A 2D dam break (walls, free surface): closed box, wall particles of type 1 that do
    not move, the column falling under gravity; the loader reads it (~15 s)."""
    import sphjax
    from sphjax.dataset import Perturbation, generate_dataset
    from sphjax.surrogate import data

    case = sphjax.cases.dam_break(n=4)
    timings = {}
    out = generate_dataset(
        case,
        tmp_path / "dam",
        n_train=2,
        n_valid=0,
        n_test=1,
        steps=40,
        write_every=20,
        perturbation=Perturbation(jitter=0.1),
        seed=5,
        progress=False,
        case_kwargs={"n": 4},
        timings=timings,
    )
    meta = json.loads((out / "metadata.json").read_text())
    domain = case.model.domain
    assert meta["periodic_boundary_conditions"] == [False, False]
    assert meta["bounds"] == [[lo, hi] for lo, hi in zip(domain.lower, domain.upper, strict=True)]
    assert meta["g_ext_magnitude"] == pytest.approx(9.81)
    assert meta["density_evolution"] is True and meta["sequence_length_train"] == 3
    assert timings["trajectories"] == 3 and 0 < timings["compile_seconds"] < timings["seconds"]
    running = timings["seconds"] - timings["compile_seconds"]
    assert timings["per_minute"] == pytest.approx(60.0 * 3 / running)
    train = data.load(out, "train")
    types = train.particle_type[0]
    fluid, wall = types == 0, types == 1
    assert fluid.sum() == 4 * 8 and wall.sum() > 0 and np.all(fluid | wall)
    x = train.positions[0]
    np.testing.assert_array_equal(x[0, wall], x[-1, wall])  # walls stay put
    assert x[-1, fluid, 1].mean() < x[0, fluid, 1].mean()  # the column falls
    # jitter: the two trajectories start from different fluid positions
    assert not np.allclose(train.positions[0, 0, fluid], train.positions[1, 0, fluid])


def test_dataset_command_reports_throughput_and_names_bad_input(tmp_path, capsys):
    from sphjax.cli import main

    argv = ["dataset", "taylor_green", "--out", str(tmp_path / "d"), "--case-arg", "n=8"]
    argv += ["--n-train", "1", "--n-valid", "0", "--n-test", "0", "--steps", "4"]
    argv += ["--write-every", "2", "--no-progress"]
    assert main(argv) == 0
    # the rate leaves compilation out, as `sphjax run` does, and the line says so
    line = capsys.readouterr().out.strip().splitlines()[-1]
    found = re.fullmatch(
        r"wrote .*: 1 trajectories simulated in ([\d.]+) s wall \(([\d.]+) s compiling\), "
        r"([\d.e+]+) trajectories per minute after compilation",
        line,
    )
    assert found, line
    wall, compiling, per_minute = (float(g) for g in found.groups())
    assert 0 < compiling <= wall  # this process has not compiled this batch program before
    assert per_minute > 60.0 / wall  # faster than with compilation counted
    assert main(argv) == 2  # the folder is not empty: one line, no traceback
    err = capsys.readouterr().err
    assert "holds files" in err and "--overwrite" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("periodic", [(True, True, True), (True, False, False)])
def test_random_velocity_field_3d_is_solenoidal_with_no_flow_through_walls(periodic):
    """The 3D random field is the curl of a vector potential: zero divergence (central
    differences, error O(e^2)), no normal flow on the walls of closed axes, largest speed
    1; the same generator draws the same field (numpy only, < 1 s)."""
    from sphjax.core.model import Domain
    from sphjax.dataset import random_velocity_field

    domain = Domain((0.0, 0.0, 0.0), (1.0, 2.0, 0.5), periodic)
    size = np.asarray(domain.size)
    x = np.random.default_rng(0).uniform(0.0, 1.0, (100, 3)) * size
    e = 1e-5
    shifted = [x] + [x + s * e * np.eye(3)[a] for a in range(3) for s in (1, -1)]
    u = random_velocity_field(np.concatenate(shifted), domain, np.random.default_rng(4))
    u = u.reshape(7, len(x), 3)
    div = sum((u[1 + 2 * a][:, a] - u[2 + 2 * a][:, a]) / (2 * e) for a in range(3))
    grad_scale = np.abs(u[1] - u[2]).max() / (2 * e)  # a velocity gradient, for scale
    assert grad_scale > 1.0 and np.abs(div).max() < 1e-6 * grad_scale
    assert np.linalg.norm(u, axis=2).max() == pytest.approx(1.0)
    for axis in range(3):
        if periodic[axis]:
            continue
        for wall in (0.0, size[axis]):
            w = x.copy()
            w[:, axis] = wall
            normal = random_velocity_field(w, domain, np.random.default_rng(4))[:, axis]
            assert np.abs(normal).max() < 1e-12
    again = random_velocity_field(x, domain, np.random.default_rng(4))
    np.testing.assert_array_equal(again, random_velocity_field(x, domain, np.random.default_rng(4)))


def test_abc_flow_3d_dataset_metadata_and_frames(tmp_path, capsys):
    """`sphjax dataset abc_flow_3d`: a 3D LagrangeBench dataset with dim 3, the periodic
    unit cube as bounds, positions [T, N, 3] wrapped into the box, a random start per
    trajectory, statistics per axis and the throughput line (~10 s)."""
    from sphjax.cli import main
    from sphjax.dataset import check_metadata, statistics
    from sphjax.surrogate import data

    out = tmp_path / "abc"
    argv = ["dataset", "abc_flow_3d", "--out", str(out), "--case-arg", "n=8"]
    argv += ["--case-arg", "relax_iterations=0", "--n-train", "2", "--n-valid", "0"]
    argv += ["--n-test", "1", "--steps", "8", "--write-every", "4", "--no-progress"]
    assert main(argv) == 0
    assert "trajectories per minute" in capsys.readouterr().out
    meta = json.loads((out / "metadata.json").read_text())
    check_metadata(meta)
    assert meta["dim"] == 3 and meta["case"] == "abc_flow_3d"
    assert meta["bounds"] == [[0.0, 1.0]] * 3
    assert meta["periodic_boundary_conditions"] == [True, True, True]
    assert meta["num_particles_max"] == 8**3 and meta["sequence_length_train"] == 3
    assert len(meta["vel_std"]) == 3 and min(meta["vel_std"]) > 0
    train = data.load(out, "train")
    x = train.positions
    assert x.shape == (2, 3, 8**3, 3) and x.dtype == np.float32
    assert np.all((x >= 0.0) & (x < 1.0))
    assert np.all(train.particle_type == 0)
    assert not np.allclose(x[0, 1], x[1, 1])  # each trajectory its own start
    stats = statistics(list(x), list(train.particle_type), meta["bounds"], [True] * 3)
    np.testing.assert_allclose(stats["vel_std"], meta["vel_std"], rtol=1e-6)
