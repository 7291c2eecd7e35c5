"""HDF5 trajectories: exact round trip, metadata, frames kept when a run is killed."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import textwrap

import h5py
import jax
import numpy as np
import pytest

import sphjax
from sphjax.io import TrajectoryWriter, read_metadata, read_trajectory, write_trajectory


@pytest.fixture(scope="module")
def case():
    return sphjax.cases.get("taylor_green", n=8)


@pytest.fixture(scope="module")
def run(case, tmp_path_factory):
    """A 4-step run written through the writer as ``on_frames``."""
    path = tmp_path_factory.mktemp("io") / "tg.h5"
    with TrajectoryWriter(path, case) as writer:
        trajectory = sphjax.simulate(case, n_steps=4, save_every=2, on_frames=writer)
    return path, trajectory


def assert_same_tree(a, b):
    assert jax.tree_util.tree_structure(a) == jax.tree_util.tree_structure(b)
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True):
        assert x.dtype == y.dtype and x.shape == y.shape
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def test_round_trip_is_exact(run):
    path, trajectory = run
    read, _ = read_trajectory(path)
    assert len(read) == 3
    assert_same_tree(read, trajectory)


def test_layout_one_dataset_per_field_with_extendable_time_axis(run):
    path, trajectory = run
    with h5py.File(path, "r") as f:
        assert set(f["states"]) == {f.name for f in dataclasses.fields(sphjax.State)}
        for name, dataset in f["states"].items():
            assert dataset.maxshape[0] is None, name
            assert dataset.chunks is not None, name
            assert dataset.shape[0] == len(trajectory)
        assert f["times"].shape == (3,)


def test_metadata(run, case):
    path, _ = run
    _, meta = read_trajectory(path)
    assert meta["case"] == "taylor_green"
    assert meta["dt"] == case.dt
    assert meta["sphjax_version"] == sphjax.__version__
    assert meta["complete"] and meta["error"] == ""
    assert meta["n_frames"] == 3 and meta["n_particles"] == case.n_particles
    assert_same_tree(meta["params"], case.params)
    model = meta["model"]
    assert model["kernel"] == "quintic_spline"
    assert model["domain"] == {
        "type": "Domain",
        "lower": [0.0, 0.0],
        "upper": [1.0, 1.0],
        "periodic": [True, True],
    }
    assert [system["type"] for system in model["systems"]] == ["FluidSystem"]
    assert model["smoothing_length"] == case.model.smoothing_length
    assert set(model) == {f.name for f in dataclasses.fields(sphjax.Model)}
    assert meta["case_info"]["n"] == 8
    assert read_metadata(path)["case"] == "taylor_green"


def test_read_one_frame(run):
    path, trajectory = run
    last, _ = read_trajectory(path, frames=-1)
    assert len(last) == 1
    assert_same_tree(last.frame(0), trajectory.final)
    with pytest.raises(IndexError, match="holds 3 frames"):
        read_trajectory(path, frames=3)


def test_write_trajectory_float64(tmp_path):
    with jax.enable_x64(True):
        case = sphjax.cases.get("taylor_green", n=4)
        states = jax.tree_util.tree_map(lambda x: np.stack([x, x]), case.state)
        trajectory = sphjax.Trajectory(states=states, times=np.array([0.0, 0.5]))
        write_trajectory(tmp_path / "x64.h5", trajectory, case)
        read, meta = read_trajectory(tmp_path / "x64.h5")
        assert read.states.position.dtype == np.float64
        assert_same_tree(read, jax.tree_util.tree_map(jax.numpy.asarray, trajectory))
        assert meta["params"].sound_speed.dtype == np.float64


def test_not_a_trajectory(tmp_path):
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["x"] = np.zeros(3)
    with pytest.raises(ValueError, match="not an sphjax trajectory"):
        read_trajectory(tmp_path / "other.h5")
    with pytest.raises(FileNotFoundError, match="no trajectory file"):
        read_trajectory(tmp_path / "missing.h5")


def test_writer_rejects_frames_of_another_shape(case, tmp_path):
    one = jax.tree_util.tree_map(lambda x: x[None], case.state)
    other = sphjax.cases.get("taylor_green", n=4).state
    with TrajectoryWriter(tmp_path / "t.h5", case) as writer:
        writer(one, np.zeros(1))
        with pytest.raises(ValueError, match="per-frame shape"):
            writer(jax.tree_util.tree_map(lambda x: x[None], other), np.ones(1))
    assert len(read_trajectory(tmp_path / "t.h5")[0]) == 1


def test_writer_records_an_exception_and_keeps_frames(case, tmp_path):
    one = jax.tree_util.tree_map(lambda x: x[None], case.state)
    with pytest.raises(KeyboardInterrupt):
        with TrajectoryWriter(tmp_path / "t.h5", case) as writer:
            writer(one, np.zeros(1))
            raise KeyboardInterrupt
    trajectory, meta = read_trajectory(tmp_path / "t.h5")
    assert len(trajectory) == 1
    assert not meta["complete"] and meta["error"].startswith("KeyboardInterrupt")


CRASH = """
import os
import numpy as np
import sphjax
from sphjax.io import TrajectoryWriter

case = sphjax.cases.get("taylor_green", n=4)
writer = TrajectoryWriter({path!r}, case)
for block in range(3):
    states = sphjax.State(**{{
        name: np.stack([np.asarray(x) + block + k for k in range(2)])
        for name, x in vars(case.state).items()
    }})
    writer(states, np.array([2 * block, 2 * block + 1], dtype=np.float32))
os._exit(9)  # die without closing the file, as a killed run would
"""


def test_killed_run_keeps_written_frames(tmp_path):
    path = tmp_path / "crash.h5"
    script = textwrap.dedent(CRASH.format(path=str(path)))
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    result = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True)
    assert result.returncode == 9, result.stderr.decode()[-2000:]
    trajectory, meta = read_trajectory(path)
    assert not meta["complete"]
    assert len(trajectory) == 6
    np.testing.assert_array_equal(trajectory.times, np.arange(6, dtype=np.float32))
    case = sphjax.cases.get("taylor_green", n=4)
    for frame in range(6):
        expected = np.asarray(case.state.position) + frame // 2 + frame % 2
        # the killed process ran in float32, this session in float64
        np.testing.assert_allclose(trajectory.states.position[frame], expected, rtol=1e-6)


def test_save_every_that_does_not_divide_the_steps(case, tmp_path):
    """simulate(save_every=3) over 7 steps: frames at steps 0, 3, 6 and the last at 7, the
    same states as saving every step, handed to on_frames with their true times."""
    every = sphjax.simulate(case, n_steps=7, save_every=1)
    with TrajectoryWriter(tmp_path / "k3.h5", case) as writer:
        three = sphjax.simulate(case, n_steps=7, save_every=3, on_frames=writer)
    np.testing.assert_allclose(three.times / case.dt, [0, 3, 6, 7], rtol=1e-12)
    # the two runs are different compiled programs (scans of 3 and of 1 step): equal to
    # round-off (measured 1 ulp), not bit for bit
    for name in ("position", "velocity", "density"):
        np.testing.assert_allclose(
            np.asarray(getattr(three.states, name)),
            np.asarray(getattr(every.states, name))[[0, 3, 6, 7]],
            rtol=1e-13,
            atol=1e-15,
        )
    read, _ = read_trajectory(tmp_path / "k3.h5")
    assert_same_tree(read, three)
    more = sphjax.simulate(case, n_steps=5, save_every=9)  # longer than the run
    np.testing.assert_allclose(more.times / case.dt, [0, 5], rtol=1e-12)
