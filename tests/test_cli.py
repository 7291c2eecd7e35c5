"""The ``sphjax`` command line: run, plot, cases; bad input exits 2 with one line naming the
argument; --help answers without importing JAX."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import h5py
import jax
import numpy as np
import pytest

import sphjax
import sphjax.integration.simulate
import sphjax.integration.timestep
from sphjax._cli_run import default_save_every
from sphjax.cli import main
from sphjax.io import read_trajectory

TINY = ["taylor_green", "--n", "8", "--t-end", "0.011", "--quiet"]  # 64 particles, 4 steps


def cli(*args, env=None):
    """Run the entry point in a fresh interpreter."""
    env = dict(os.environ, JAX_PLATFORMS="cpu", **(env or {}))
    code = "import sys; from sphjax.cli import main; sys.exit(main(sys.argv[1:]))"
    return subprocess.run(
        [sys.executable, "-c", code, *args], env=env, capture_output=True, text=True
    )


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "tg.h5"
    code = main(["run", *TINY, "--save-every", "2", "--out", str(out)])
    return code, out


def test_cases_lists_every_case(capsys):
    assert main(["cases"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == list(sphjax.cases.CASES)
    assert all(len(line.split(maxsplit=1)) == 2 for line in lines)  # a description each


def test_cases_describes_one_case(capsys):
    assert main(["cases", "dam_break"]) == 0
    out = capsys.readouterr().out
    assert "column_width = 0.3" in out and "wall_slip = 'no_slip'" in out  # --case-arg
    assert "gravity = 0,-9.81" in out and "reference_density = 1000" in out  # --set
    # only the parameters the dam break's model reads (no Morris viscosity, no transport
    # velocity): the others would be refused
    assert "artificial_alpha = " in out and "density_diffusion = " in out
    assert "kinematic_viscosity" not in out and "transport_pressure" not in out
    # what --n counts, and what the default gives
    assert "--n counts particles across the column width (dx = L / n); default n = 20" in out


@pytest.mark.parametrize("name", sorted(sphjax.cases.CASES))
def test_every_case_says_what_n_counts(name):
    from sphjax.cli import _argument_doc

    assert _argument_doc(sphjax.cases.CASES[name], "n").startswith("particles ")


@pytest.mark.parametrize("name", ["taylor_green", "oscillating_plate", "hydrostatic_fsi_plate"])
def test_cases_lists_the_parameters_the_model_reads(name, capsys):
    assert main(["cases", name]) == 0
    out = capsys.readouterr().out
    listed = out.split("parameters (--set FIELD=VALUE)")[1].splitlines()[1:]
    case = sphjax.cases.CASES[name](n=2 if name != "taylor_green" else 4)
    used = [field for field, _ in case.params.items(used_only=True)]
    assert [line.split(" = ")[0].strip() for line in listed] == used
    assert not {field for field, _ in case.params.unused} & set(used)


def test_run_writes_frames_and_prints_a_summary(tiny_run, capsys):
    code, out = tiny_run
    assert code == 0
    trajectory, meta = read_trajectory(out)
    assert len(trajectory) == 3  # initial + 4 steps / 2
    assert meta["complete"] and meta["case"] == "taylor_green"
    assert meta["case_info"]["n"] == 8
    assert meta["command"][:3] == ["sphjax", "run", "taylor_green"]
    assert meta["save_every"] == 2 and meta["n_steps"] == 4
    assert out.with_suffix(".xdmf").is_file()


def test_summary(tmp_path, capsys):
    assert main(["run", *TINY, "--out", str(tmp_path / "s.h5")]) == 0
    out = capsys.readouterr().out
    assert "64 particles, 4 steps" in out and " s wall" in out
    assert " s compiling), " in out and "particle-steps/s after compilation" in out


def test_dx_maps_onto_resolution(tmp_path):
    out = tmp_path / "dx.h5"
    args = ["run", "taylor_green", "--dx", "0.125", "--t-end", "0.011", "--quiet"]
    assert main([*args, "--out", str(out)]) == 0
    _, meta = read_trajectory(out)
    assert meta["case_info"]["n"] == 8 and meta["n_particles"] == 64


@pytest.mark.parametrize("field", ["velocity", "pressure", "density", "kind"])
def test_plot(tiny_run, tmp_path, field):
    _, out = tiny_run
    png = tmp_path / f"{field}.png"
    assert main(["plot", str(out), "--field", field, "--frame", "1", "--out", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# ---------------------------------------------------------------------------- saving


def test_save_every_need_not_divide_the_steps(tmp_path):
    """4 steps saved every 3: frames at steps 0, 3 and the last one at step 4."""
    out = tmp_path / "k3.h5"
    assert main(["run", *TINY, "--save-every", "3", "--out", str(out)]) == 0
    trajectory, meta = read_trajectory(out)
    dt = meta["dt"]
    np.testing.assert_allclose(trajectory.times, np.array([0, 3, 4]) * dt, rtol=1e-6)
    np.testing.assert_allclose(trajectory.states.time, trajectory.times, rtol=1e-6)
    assert meta["complete"]


def test_save_dt_puts_frames_on_a_time_grid(tmp_path, capsys):
    """--save-dt 0.004 with the case's dt 0.00342: dt is shortened to 0.004 / 2."""
    out = tmp_path / "grid.h5"
    assert main(["run", *TINY[:3], "--t-end", "0.012", "--save-dt", "0.004", "--quiet",
                 "--out", str(out)]) == 0  # fmt: skip
    trajectory, meta = read_trajectory(out)
    np.testing.assert_allclose(trajectory.times, [0, 0.004, 0.008, 0.012], rtol=1e-5)
    assert meta["dt"] == pytest.approx(0.002)
    assert "shortened from" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("n_steps", "save_every", "frames"),
    [(40, 1, 41), (1941, 20, 99), (2000, 20, 101), (1174, 12, 99), (100_003, 1001, 101)],
)
def test_default_saving_gives_about_100_frames(n_steps, save_every, frames):
    assert default_save_every(n_steps) == save_every
    full, rest = divmod(n_steps, save_every)
    assert 1 + full + (rest > 0) == frames


# ---------------------------------------------------------------------------- parameters


def test_set_and_case_arg(tmp_path):
    out = tmp_path / "set.h5"
    case = sphjax.cases.get("taylor_green", n=8, reynolds=50.0)
    argv = ["run", *TINY, "--set", "kinematic_viscosity=0.02", "--set", "sound_speed=40",
            "--set", "gravity=0,-1.5", "--case-arg", "reynolds=50", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    _, meta = read_trajectory(out)
    params = meta["params"]
    assert float(params.kinematic_viscosity) == pytest.approx(0.02)
    assert float(params.sound_speed) == pytest.approx(40.0)
    np.testing.assert_allclose(params.gravity, [0.0, -1.5])
    assert meta["case_info"]["reynolds"] == 50.0
    # a faster sound speed shortens the case's step in proportion to the stable step
    stable = sphjax.integration.timestep.stable_time_step
    new = case.params.replace(sound_speed=40.0, kinematic_viscosity=0.02)
    ratio = stable(case.state, case.model, new) / stable(case.state, case.model, case.params)
    assert ratio < 1
    assert meta["dt"] == pytest.approx(case.dt * ratio, rel=1e-6)


# ---------------------------------------------------------------------------- bad input


def _existing(name):
    def make(path):
        (path / name).write_bytes(b"")

    return make


def _folder_with_a_file(path):
    (path / "data").mkdir()
    (path / "data" / "x").write_text("x")


def _not_hdf5(path):
    (path / "bad.h5").write_bytes(b"this is not an HDF5 file" * 10)


RUN = ["run", *TINY]
BAD_INPUT = [
    # (argv, expected fragment, set-up of the working folder)
    (["rnu"], "unknown command 'rnu'; did you mean 'run'?", None),
    (["frobnicate"], "unknown command 'frobnicate'; choose one of run", None),
    ([], "the following arguments are required: COMMAND", None),
    (["run", "nope"], "unknown case 'nope'; available cases: taylor_green", None),
    (["run", "taylor_green", "--dx", "0"], "argument --dx: must be a positive number", None),
    (
        ["run", "taylor_green", "--n", "8", "--neighbor-margin=-0.1"],
        "--neighbor-margin: Model.neighbor_margin must be a finite number >= 0",
        None,
    ),  # fmt: skip
    (["run", "taylor_green", "--dx", "-0.1"], "argument --dx: must be a positive number", None),
    (["run", "taylor_green", "--dx", "0.5"], "--dx: dx=0.5 is too coarse", None),
    (["run", "taylor_green", "--n", "0"], "argument --n: must be a positive whole number", None),
    (["run", "taylor_green", "--n", "2"], "--n: n must be an integer >= 4", None),
    (["run", "taylor_green", "--t-end", "0"], "argument --t-end: must be a positive number", None),
    (["run", "taylor_green", "--t-end", "-1"], "argument --t-end: must be a positive number", None),
    (["run", "taylor_green", "--t-end", "abc"], "argument --t-end: expected a number", None),
    (["run", "taylor_green", "--t-end", "nan"], "argument --t-end: must be a finite number", None),
    (["run", "taylor_green", "--dt", "10"], "--dt: dt=10 exceeds the stability limit", None),
    (["run", "taylor_green", "--n", "4", "--dx", "0.1"], "not allowed with argument", None),
    ([*RUN, "--save-every", "0"], "argument --save-every: must be a positive whole number", None),
    ([*RUN, "--save-every", "2", "--save-dt", "0.1"], "not allowed with argument", None),
    ([*RUN, "--save-dt", "-1"], "argument --save-dt: must be a positive number", None),
    ([*RUN, "--dt", "0.001", "--save-dt", "0.0015"], "--save-dt: 0.0015 is not a whole", None),
    (
        [*RUN, "--set", "nope=1"],
        "--set: 'nope' is not a parameter of this case; choose one of",
        None,
    ),
    ([*RUN, "--set", "sound_speed=abc"], "sound_speed=abc: the value must be a number", None),
    ([*RUN, "--set", "sound_speed"], "argument --set: must look like FIELD=VALUE", None),
    ([*RUN, "--set", "sound_speed=inf"], "sound_speed=inf: the value must be finite", None),
    ([*RUN, "--set", "gravity=1"], "--set: gravity takes 2 comma-separated numbers", None),
    ([*RUN, "--set", "sound_speed=1,2"], "--set: sound_speed takes a number", None),
    (
        ["run", "dam_break", "--n", "4", "--set", "kinematic_viscosity=0.5", "--quiet"],
        "sphjax run: error: --set: kinematic_viscosity is not used by this fluid (artificial "
        "viscosity only): add MorrisViscosity() to the fluid's viscosity to use it",
        None,
    ),
    (
        [*RUN, "--set", "artificial_alpha=0.1"],
        "--set: artificial_alpha is not used by this fluid (Morris viscosity only): add "
        "ArtificialViscosity() to the fluid's viscosity to use it",
        None,
    ),
    (
        ["run", "oscillating_plate", "--n", "2", "--set", "penalty_alpha=0.1", "--quiet"],
        "--set: penalty_alpha is not used by this solid (no penalty force)",
        None,
    ),
    (
        ["run", "floating_body", "--n", "4", "--set", "contact_friction=0.3", "--quiet"],
        "--set: contact_friction is not used by this rigid body (it has no wall contact): "
        "give it RigidSystem(wall_contact=WallContact()) to use it",
        None,
    ),
    (
        [
            "dataset",
            "dam_break",
            "--out",
            "d",
            "--steps",
            "8",
            "--vary",
            "kinematic_viscosity=0.01:0.02",
        ],
        "--vary: kinematic_viscosity is not used by this fluid (artificial viscosity only)",
        None,
    ),  # fmt: skip
    (
        [*RUN, "--case-arg", "nope=1"],
        "case 'taylor_green' has no argument 'nope'; it accepts n,",
        None,
    ),  # fmt: skip
    (
        [*RUN, "--case-arg", "reynolds=fast"],
        "reynolds='fast': case 'taylor_green' expects a",
        None,
    ),  # fmt: skip
    ([*RUN, "--case-arg", "n=8"], "--case-arg: n is also given by --n; give it once", None),
    ([*RUN, "--case-arg", "disorder=-3"], "--case-arg disorder: disorder must lie in", None),
    (
        ["run", "oscillating_plate", "--n", "4", "--case-arg", "poisson_ratio=0.7", "--quiet"],
        "--case-arg poisson_ratio: Params.poisson_ratio must be a number in (-1, 0.5), got 0.7",
        None,
    ),
    (
        ["run", "taylor_green", "--n", "8", "--case-arg", "t_end=-1", "--quiet"],
        "--case-arg t_end: t_end must be a positive number (the end time in s), got -1",
        None,
    ),
    ([*RUN, "--case-arg", "reynolds=inf"], "reynolds=inf: case 'taylor_green' expects a", None),
    (
        ["run", "dam_break", "--case-arg", "density_diffusion=5"],
        "--case-arg: density_diffusion=5: case 'dam_break' expects a name or None",
        None,
    ),
    (
        ["run", "hydrostatic_fsi_plate", "--case-arg", "substeps=fast"],
        "--case-arg substeps: substeps must be a positive integer or 'auto'",
        None,
    ),
    (
        ["run", "taylor_green", "--n", "8", "--save-dt", "1.0", "--t-end", "0.01", "--quiet"],
        "--save-dt: 1 s is longer than the run (--t-end 0.01 s), so no frame would fall",
        None,
    ),
    (
        ["run", "taylor_green", "--tend", "0.01"],
        "run: error: unknown option --tend; did you mean --t-end? see 'sphjax run --help'",
        None,
    ),  # fmt: skip
    (["run", "taylor_green", "--t-end=0.1", "x"], "unexpected argument 'x'", None),
    (
        ["plot", "a.h5", "--frmae", "1", "--out", "x.png"],
        "unknown option --frmae; did you mean --frame?",
        None,
    ),
    ([*RUN, "--out", "/no/such/dir/x.h5"], "--out: cannot write", None),
    (
        [*RUN, "--out", "/proc/x.h5"],
        "--out: cannot write '/proc/x.h5': files cannot be created in the folder '/proc'",
        None,
    ),
    (
        [*RUN, "--out", "f/x.h5"],
        "--out: cannot write 'f/x.h5': 'f' is not a directory",
        _existing("f"),
    ),  # fmt: skip
    (
        [*RUN, "--out", "x.txt"],
        "--out: 'x.txt' has an unknown extension '.txt'; use one of",
        None,
    ),  # fmt: skip
    ([*RUN, "--out", "x.h5"], "--out: 'x.h5' exists; pass --overwrite", _existing("x.h5")),
    ([*RUN, "--out", "x.h5"], "--out: 'x.xdmf' exists; pass --overwrite", _existing("x.xdmf")),
    (
        ["plot", "missing.h5", "--out", "x.png"],
        "sphjax plot: error: --out: 'x.png' exists; pass --overwrite to replace it, or choose "
        "another path",
        _existing("x.png"),
    ),
    (
        ["animate", "missing.h5", "--out", "x.gif"],
        "sphjax animate: error: --out: 'x.gif' exists; pass --overwrite to replace it, or "
        "choose another path",
        _existing("x.gif"),
    ),
    (["plot", "missing.h5", "--out", "x.png"], "FILE.h5: no trajectory file", None),
    (["plot", "bad.h5", "--out", "x.png"], "FILE.h5: 'bad.h5' is not a readable HDF5", _not_hdf5),
    (["plot", "bad.h5", "--out", "p.xyz"], "--out: 'p.xyz' has an unknown extension", None),
    (
        ["plot", "bad.h5", "--out", "x.png", "--frame", "x"],
        "argument --frame: expected a whole",
        None,
    ),  # fmt: skip
    (["animate", "bad.h5", "--out", "m.avi"], "--out: 'm.avi' has an unknown extension", None),
    (
        ["animate", "bad.h5", "--out", "m.gif", "--fps", "0"],
        "argument --fps: must be a positive",
        None,
    ),  # fmt: skip
    (["animate", "missing.h5", "--out", "m.gif"], "FILE.h5: no trajectory file", None),
    (["export", "missing.h5", "--vtk", "out"], "FILE.h5: no trajectory file", None),
    (["export", "x.h5", "--vtk", "f"], "--vtk: 'f' is a file; give a folder name", _existing("f")),
    (
        ["export", "x.h5", "--vtk", "data"],
        "--vtk: 'data' is not empty; pass --overwrite",
        _folder_with_a_file,
    ),  # fmt: skip
    (["export", "x.h5", "--vtk", "no/such/dir"], "--vtk: cannot create 'no/such/dir'", None),
    (
        ["dataset", "taylor_green", "--out", "data", "--steps", "8"],
        "--out: 'data' holds files;",
        _folder_with_a_file,
    ),  # fmt: skip
    (
        ["dataset", "taylor_green", "--out", "d", "--steps", "0"],
        "argument --steps: must be a positive whole number",
        None,
    ),  # fmt: skip
    (
        ["dataset", "taylor_green", "--out", "d", "--steps", "10", "--write-every", "3"],
        "--write-every: 3 must divide --steps 10",
        None,
    ),  # fmt: skip
    (
        ["dataset", "taylor_green", "--out", "d", "--steps", "4", "--write-every", "4"],
        "--write-every: 4 must divide --steps 4 and give at least 3 frames",
        None,
    ),  # fmt: skip
    (
        ["dataset", "taylor_green", "--out", "d", "--steps", "8", "--amplitude", "2:1"],
        "argument --amplitude: needs finite LO <= HI",
        None,
    ),  # fmt: skip
    (
        ["dataset", "taylor_green", "--out", "d", "--steps", "8", "--amplitude", "abc"],
        "argument --amplitude: must look like LO:HI",
        None,
    ),  # fmt: skip
    (
        [
            "dataset",
            "taylor_green",
            "--out",
            "d",
            "--steps",
            "8",
            "--amplitude=-1:1",
            "--case-arg",
            "n=8",
        ],
        "--amplitude: Perturbation.amplitude must satisfy 0 <= lo",
        None,
    ),  # fmt: skip
    (
        ["dataset", "taylor_green", "--out", "d", "--steps", "8", "--case-arg", "nope=1"],
        "--case-arg: case 'taylor_green' has no argument 'nope'",
        None,
    ),  # fmt: skip
    (
        ["dataset", "taylor_green", "--out", "d", "--steps", "8", "--case-arg", "n"],
        "argument --case-arg: must look like KEY=VALUE",
        None,
    ),  # fmt: skip
    (
        [
            "dataset",
            "taylor_green",
            "--out",
            "d",
            "--steps",
            "8",
            "--vary",
            "nope=0:1",
            "--case-arg",
            "n=8",
        ],
        "--vary: 'nope' is not a scalar Params field",
        None,
    ),  # fmt: skip
    (
        [
            "dataset",
            "taylor_green",
            "--out",
            "d",
            "--steps",
            "8",
            "--vary",
            "sound_speed=0:10",
            "--case-arg",
            "n=8",
        ],
        "--vary: sound_speed=0:10: Params.sound_speed must be a positive number, got 0.0; "
        "give a range of valid values",
        None,
    ),  # fmt: skip
    (
        ["dataset", "taylor_green", "--out", "d", "--steps", "8", "--vary", "nu=1"],
        "argument --vary: nu: must look like LO:HI",
        None,
    ),  # fmt: skip
    (
        ["dataset", "taylor_green", "--out", "d", "--steps", "8", "--n-train", "0"],
        "argument --n-train: must be a positive whole number",
        None,
    ),  # fmt: skip
    (["dataset", "nope", "--out", "d", "--steps", "8"], "CASE: unknown case 'nope'", None),
    (
        ["dataset", "taylor_green", "--out", "data", "--steps", "8", "--resume"],
        "--resume: 'data' holds no interrupted dataset to continue",
        _folder_with_a_file,
    ),  # fmt: skip
]


@pytest.mark.parametrize(
    ("argv", "message", "setup"), BAD_INPUT, ids=[" ".join(a[0]) or "(none)" for a in BAD_INPUT]
)
def test_bad_input_exits_2_with_one_line(argv, message, setup, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    if setup is not None:
        setup(tmp_path)
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err
    assert len(err.strip().splitlines()) == 1, err
    assert "Traceback" not in err
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before  # nothing new


def _damage(path, tmp_path, how):
    data = bytearray(path.read_bytes())
    if how == "truncated":
        data = data[: len(data) // 2]
    else:  # a block of the file's metadata zeroed, past the superblock
        data[96:2048] = bytes(2048 - 96)
    damaged = tmp_path / f"{how}.h5"
    damaged.write_bytes(bytes(data))
    return damaged


@pytest.mark.parametrize("how", ["truncated", "zeroed"])
@pytest.mark.parametrize("command", ["plot", "animate", "export"])
def test_damaged_file_is_bad_input(tiny_run, tmp_path, capsys, how, command):
    damaged = _damage(tiny_run[1], tmp_path, how)
    out = ["--vtk", str(tmp_path / "vtk")] if command == "export" else [
        "--out", str(tmp_path / ("x.png" if command == "plot" else "x.gif"))]  # fmt: skip
    assert main([command, str(damaged), *out, *(["--quiet"] if command == "animate" else [])]) == 2
    err = capsys.readouterr().err
    assert "FILE.h5:" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err


def test_animate_needs_two_frames(tiny_run, tmp_path, capsys):
    _, out = tiny_run  # 3 frames
    gif = tmp_path / "m.gif"
    assert main(["animate", str(out), "--every", "1000", "--out", str(gif), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "--every: 1000 leaves 1 of the 3 saved frames; an animation needs two or more: " \
        "use --every 2 or less" in err  # fmt: skip
    assert len(err.strip().splitlines()) == 1 and not gif.exists()


def test_case_args_take_what_the_python_api_takes():
    """Every case argument's default passes the --case-arg check unchanged, and split
    integration (``substeps="auto"``) and ``None`` reach the cases that accept them."""
    import inspect

    from sphjax._cli_run import _check_case_value, build_case

    for name, factory in sphjax.cases.CASES.items():
        for key, parameter in inspect.signature(factory).parameters.items():
            value = _check_case_value(name, key, parameter.default, parameter)
            assert value == parameter.default, (name, key)
            if "str" in str(parameter.annotation).split(" | ") and key == "substeps":
                assert _check_case_value(name, key, "auto", parameter) == "auto"
    case = build_case("hydrostatic_fsi_plate", {"substeps": "auto", "t_end": 0.01}, n=2)
    assert isinstance(case.info["substeps"], int) and case.info["substeps"] > 1
    case = build_case("dam_break", {"density_diffusion": None}, n=4)
    assert case.model.systems[0].density_diffusion is None


def test_cases_output_into_a_closed_pipe_exits_quietly():
    code = "import sys; from sphjax.cli import main; sys.exit(main(sys.argv[1:]))"
    child = subprocess.Popen(
        [sys.executable, "-c", code, "cases"],
        env=dict(os.environ, JAX_PLATFORMS="cpu"),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    child.stdout.close()  # `sphjax cases | head -0`: the reader is gone before the output
    err = child.stderr.read()
    assert child.wait() == 141
    assert err == "", err


def test_overwrite(tiny_run, tmp_path):
    out = tmp_path / "o.h5"
    out.write_text("old")
    assert main(["run", *TINY, "--out", str(out), "--overwrite"]) == 0
    assert len(read_trajectory(out)[0]) == 5
    png = tmp_path / "o.png"
    png.write_text("old")
    assert main(["plot", str(tiny_run[1]), "--out", str(png), "--overwrite"]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_unwritable_out_is_caught_before_the_case_is_built(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sphjax.cases, "get", lambda *a, **k: pytest.fail("case was built"))
    assert main(["run", "taylor_green", "--out", str(tmp_path)]) == 2
    assert "--out:" in capsys.readouterr().err


def test_plot_bad_frame_and_field(tiny_run, tmp_path, capsys):
    _, out = tiny_run
    png = str(tmp_path / "x.png")
    assert main(["plot", str(out), "--frame", "3", "--out", png]) == 2
    assert "--frame: 3 is out of range; the file holds 3 frames" in capsys.readouterr().err
    assert main(["plot", str(out), "--field", "nope", "--out", png]) == 2
    assert "--field: unknown field 'nope'; choose one of" in capsys.readouterr().err


def test_unstable_run_exits_nonzero_and_keeps_frames(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sphjax.integration.simulate, "check_time_step", lambda *args: None)
    monkeypatch.setattr(sphjax.integration.timestep, "check_time_step", lambda *args: None)
    monkeypatch.setattr(sphjax._cli_run, "check_time_step", lambda *args: None)
    case = sphjax.cases.get("dam_break", n=4)
    out = tmp_path / "blowup.h5"
    argv = ["run", "dam_break", "--n", "4", "--dt", str(30 * case.dt), "--t-end",
            str(40 * 30 * case.dt), "--save-every", "1", "--quiet", "--out", str(out),
            "--set", "artificial_alpha=0.05"]  # fmt: skip
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "unstable at step" in err and "particle" in err and "Traceback" not in err
    # what the command changed from the case's defaults is named as a candidate cause
    assert "candidates for the cause: --set artificial_alpha=0.05 (the case's value: 0.1); " \
        f"--dt {30 * case.dt:g} (the case's stable step: {case.dt:.4g})" in err  # fmt: skip
    trajectory, meta = read_trajectory(out)
    assert 1 <= len(trajectory) < 41
    assert not meta["complete"] and "unstable" in meta["error"]
    assert f"the {len(trajectory)} frames before it are in {out}" in err


def test_neighbour_overflow_is_one_line(tmp_path, capsys, monkeypatch):
    from sphjax.neighbors import NeighborOverflowWarning

    simulate = sphjax.integration.simulate.simulate

    def overflowing(*args, **kwargs):
        import warnings

        message = "neighbour list overflowed at step 3; re-allocated"
        warnings.warn(message, NeighborOverflowWarning, stacklevel=2)
        return simulate(*args, **kwargs)

    monkeypatch.setattr(sphjax.integration.simulate, "simulate", overflowing)
    assert main(["run", *TINY, "--out", str(tmp_path / "o.h5")]) == 0
    err = capsys.readouterr().err
    line = "note: neighbour list overflowed at step 3; re-allocated (one more compilation)"
    assert line in err.splitlines()
    assert ".py:" not in err and "Warning" not in err


def test_long_run_prints_its_estimate_after_the_first_chunk(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sphjax._cli_run, "CHUNK_STEPS", 2)  # two chunks of 2 steps
    monkeypatch.setattr(sphjax._cli_run, "LONG_RUN_SECONDS", 0.0)  # every run is "long"
    assert main(["run", *TINY, "--save-every", "1", "--out", str(tmp_path / "e.h5")]) == 0
    err = capsys.readouterr().err
    assert "estimated wall time: about " in err
    assert "particle-steps/s after compilation on the first 2 steps); Ctrl-C stops" in err


def test_long_run_prints_its_estimate_before_it_starts(tmp_path, capsys, monkeypatch):
    import sphjax._compile

    rates = tmp_path / "rates.json"
    monkeypatch.setattr(sphjax._compile, "rates_file", lambda environ=None: rates)
    sphjax._compile.remember_rate(f"taylor_green {jax.default_backend()}", 1.0)
    monkeypatch.setattr(sphjax._cli_run, "LONG_RUN_SECONDS", 60.0)
    assert main(["run", *TINY, "--out", str(tmp_path / "e.h5")]) == 0
    err = capsys.readouterr().err.splitlines()
    assert err[1].startswith(  # before the run: 64 particles x 4 steps at 1 per second
        "estimated wall time: about 4 min (at the 1 particle-steps/s a previous taylor_green "
        "run measured here, after compilation); Ctrl-C stops"
    )


# ---------------------------------------------------------------------------- compilation


def test_compilation_cache_folder(tmp_path):
    from sphjax._compile import cache_dir_setting, default_cache_dir

    assert default_cache_dir({"XDG_CACHE_HOME": "/c"}) == Path("/c/sphjax/jax")
    assert default_cache_dir({}) == Path.home() / ".cache" / "sphjax" / "jax"
    for off in ("off", "0", "", "none"):
        assert cache_dir_setting({"SPHJAX_CACHE_DIR": off})[0] is None
    assert cache_dir_setting({"SPHJAX_CACHE_DIR": str(tmp_path)}) == (tmp_path, "SPHJAX_CACHE_DIR")
    # tests/conftest.py sets JAX's own folder, which the CLI then leaves alone
    assert cache_dir_setting({})[1] == "JAX_COMPILATION_CACHE_DIR"


def test_second_run_loads_its_programs_from_the_cache(tmp_path):
    cache = tmp_path / "cache"
    argv = ["run", *TINY, "--overwrite", "--out", str(tmp_path / "c.h5")]
    first = cli(*argv, env={"SPHJAX_CACHE_DIR": str(cache)})
    assert first.returncode == 0, first.stderr
    assert len(list(cache.iterdir())) > 10  # the chunk program and the small ones
    second = cli(*argv, env={"SPHJAX_CACHE_DIR": str(cache)})
    assert second.returncode == 0, second.stderr

    def compiling(result):
        return float(result.stdout.split(" s wall (")[1].split(" s compiling")[0])

    assert compiling(second) < compiling(first)


# ---------------------------------------------------------------------------- entry point


def test_entry_point_user_error_has_no_traceback():
    result = cli("run", "taylor_green", "--out", "/no/such/dir/x.h5")  # before JAX is imported
    assert result.returncode == 2
    assert result.stderr.startswith("sphjax run: error: --out: cannot write '/no/such/dir/x.h5'")
    assert len(result.stderr.splitlines()) == 1


FAST = [["--help"], ["--version"], ["run", "--help"], ["plot", "--help"], ["animate", "--help"],
        ["export", "--help"], ["dataset", "--help"], ["cases", "--help"], ["rnu"],
        ["run", "taylor_green", "--dx", "0"]]  # fmt: skip


def test_help_version_and_typos_answer_without_jax():
    """Each answer in a fresh interpreter takes < 1.5 s (measured ~0.1 s; importing JAX and
    the solver takes 7-15 s), and JAX is never imported."""
    code = (
        "import sys, time; t = time.perf_counter(); from sphjax.cli import main\n"
        "for argv in {argvs!r}:\n"
        "    try:\n"
        "        main(argv)\n"
        "    except SystemExit:\n"
        "        pass\n"
        "assert 'jax' not in sys.modules, 'jax was imported'\n"
    )
    for argv in FAST:
        start = time.perf_counter()
        result = subprocess.run(
            [sys.executable, "-c", code.format(argvs=[argv])],
            env=dict(os.environ, JAX_PLATFORMS="cpu"),
            capture_output=True,
            text=True,
        )
        elapsed = time.perf_counter() - start
        assert result.returncode == 0, result.stderr
        assert elapsed < 1.5, (argv, elapsed)
    assert cli("--version").stdout.strip() == f"sphjax {sphjax.__version__}"


def test_float64_run_is_scoped_to_the_command(tmp_path):
    out = tmp_path / "x64.h5"
    before = jax.config.jax_enable_x64  # tests/conftest.py turns float64 on
    jax.config.update("jax_enable_x64", False)
    try:
        assert main(["run", *TINY, "--float64", "--out", str(out)]) == 0
        with h5py.File(out, "r") as f:
            assert f["states/position"].dtype == "float64"
            assert f["params"].attrs["sound_speed"].dtype == "float64"
            assert f["times"].shape == (5,)
        assert not jax.config.jax_enable_x64  # the rest of the session stays in float32
    finally:
        jax.config.update("jax_enable_x64", before)
