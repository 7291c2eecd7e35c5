"""The ``sphjax`` command line: run, plot, cases; bad input exits 2 with a named argument."""

from __future__ import annotations

import os
import subprocess
import sys

import h5py
import jax
import pytest

import sphjax
import sphjax.integration.simulate
import sphjax.integration.timestep
from sphjax.cli import main
from sphjax.io import read_trajectory

TINY = ["taylor_green", "--n", "8", "--t-end", "0.011", "--quiet"]  # 64 particles, 4 steps


def cli(*args, env=None):
    """Run the installed entry point in a fresh interpreter."""
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


def test_run_writes_frames_and_prints_a_summary(tiny_run, capsys):
    code, out = tiny_run
    assert code == 0
    trajectory, meta = read_trajectory(out)
    assert len(trajectory) == 3  # initial + 4 steps / 2
    assert meta["complete"] and meta["case"] == "taylor_green"
    assert meta["case_info"]["n"] == 8
    assert meta["command"][:3] == ["sphjax", "run", "taylor_green"]
    assert meta["save_every"] == 2 and meta["n_steps"] == 4


def test_summary(tmp_path, capsys):
    assert main(["run", *TINY, "--out", str(tmp_path / "s.h5")]) == 0
    out = capsys.readouterr().out
    assert "64 particles, 4 steps" in out and "particle-steps/s" in out and " s wall" in out


def test_dx_maps_onto_resolution(tmp_path):
    out = tmp_path / "dx.h5"
    args = ["run", "taylor_green", "--dx", "0.125", "--t-end", "0.011", "--quiet"]
    assert main([*args, "--out", str(out)]) == 0
    _, meta = read_trajectory(out)
    assert meta["case_info"]["n"] == 8 and meta["n_particles"] == 64


@pytest.mark.parametrize("field", ["velocity", "pressure", "density"])
def test_plot(tiny_run, tmp_path, field):
    _, out = tiny_run
    png = tmp_path / f"{field}.png"
    assert main(["plot", str(out), "--field", field, "--frame", "1", "--out", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


BAD_INPUT = [
    (["run", "nope"], "unknown case 'nope'; available cases: taylor_green"),
    (["run", "taylor_green", "--dx", "0"], "argument --dx: must be a positive number"),
    (["run", "taylor_green", "--dx", "-0.1"], "argument --dx: must be a positive number"),
    (["run", "taylor_green", "--dx", "0.5"], "--dx: dx=0.5 is too coarse"),
    (["run", "taylor_green", "--n", "0"], "argument --n: must be a positive whole number"),
    (["run", "taylor_green", "--n", "2"], "--n: n must be an integer >= 4"),
    (["run", "taylor_green", "--t-end", "0"], "argument --t-end: must be a positive number"),
    (["run", "taylor_green", "--t-end", "-1"], "argument --t-end: must be a positive number"),
    (["run", "taylor_green", "--t-end", "abc"], "argument --t-end: expected a number"),
    (["run", "taylor_green", "--dt", "10"], "--dt: dt=10 exceeds the stability limit"),
    (["run", "taylor_green", "--n", "4", "--dx", "0.1"], "not allowed with argument"),
    (["run", *TINY[:5], "--save-every", "3"], "--save-every: 3 does not divide the 4 steps"),
    (["run", "taylor_green", "--out", "/no/such/dir/x.h5"], "--out: cannot write"),
    (["plot", "missing.h5", "--out", "x.png"], "FILE.h5: no trajectory file"),
    (["frobnicate"], "invalid choice: 'frobnicate'"),
]


@pytest.mark.parametrize(("argv", "message"), BAD_INPUT, ids=[" ".join(a) for a, _ in BAD_INPUT])
def test_bad_input_exits_2_naming_the_argument(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err
    assert "Traceback" not in err
    assert not list(tmp_path.iterdir())  # nothing written


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
    monkeypatch.setattr(sphjax.integrate, "check_time_step", lambda *args: None)
    monkeypatch.setattr(sphjax.timestep, "check_time_step", lambda *args: None)
    case = sphjax.cases.get("dam_break", n=4)
    out = tmp_path / "blowup.h5"
    argv = ["run", "dam_break", "--n", "4", "--dt", str(30 * case.dt), "--t-end",
            str(40 * 30 * case.dt), "--save-every", "1", "--quiet", "--out", str(out)]  # fmt: skip
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "unstable at step" in err and "particle" in err and "Traceback" not in err
    trajectory, meta = read_trajectory(out)
    assert 1 <= len(trajectory) < 41
    assert not meta["complete"] and "unstable" in meta["error"]
    assert f"the {len(trajectory)} frames before it are in {out}" in err


def test_entry_point_user_error_has_no_traceback():
    result = cli("run", "nope")
    assert result.returncode == 2
    assert "available cases:" in result.stderr and "Traceback" not in result.stderr


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
