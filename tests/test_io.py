"""HDF5 trajectories: exact round trip, metadata, frames kept when a run is killed, a run
read by other processes while it is written, a locked file reported as locked, no file
replaced without overwrite=True."""

from __future__ import annotations

import dataclasses
import os
import re
import subprocess
import sys
import textwrap

import h5py
import jax
import numpy as np
import pytest

import sphjax
import sphjax.io
from sphjax.cli import main
from sphjax.io import (
    FileLockedError,
    TrajectoryWriter,
    read_metadata,
    read_trajectory,
    write_trajectory,
)


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


# ---------------------------------------------------------------------------- overwrite


def _frames(case, k):
    states = jax.tree_util.tree_map(lambda x: np.stack([np.asarray(x)] * k), case.state)
    return sphjax.Trajectory(states=states, times=np.arange(k, dtype=float))


def test_writer_replaces_a_file_only_with_overwrite(case, tmp_path):
    path = tmp_path / "o.h5"
    write_trajectory(path, _frames(case, 1), case)
    refusal = r"^path: '.*o.h5' exists; pass overwrite=True to replace it, or choose another path$"
    with pytest.raises(FileExistsError, match=refusal):
        TrajectoryWriter(path, case)
    with pytest.raises(FileExistsError, match=refusal):
        write_trajectory(path, _frames(case, 2), case)
    assert len(read_trajectory(path)[0]) == 1  # untouched
    path.unlink()  # its XDMF description is an output of the writer too
    with pytest.raises(FileExistsError, match=r"^--out: '.*o.xdmf' exists; pass --overwrite to"):
        TrajectoryWriter(path, case, argument="--out")
    write_trajectory(path, _frames(case, 2), case, overwrite=True)
    assert len(read_trajectory(path)[0]) == 2
    TrajectoryWriter(tmp_path / "x.h5", case, xdmf=False).close()  # no description, no check
    TrajectoryWriter(tmp_path / "x.h5", case, xdmf=False, overwrite=True).close()


# ---------------------------------------------------------------------------- read while written

SLOW_WRITER = """
import sys
import numpy as np
import sphjax
import sphjax.io
from sphjax.io import TrajectoryWriter

sphjax.io.WRITER_LOCK_WAIT_S = 0.2  # a reader holding the file open is stepped around sooner
TrajectoryWriter.XDMF_PACE = 0.0  # the description after every block
case = sphjax.cases.get("taylor_green", n=4)
with TrajectoryWriter({path!r}, case) as writer:
    for block in range(3):
        states = sphjax.State(**{{
            name: np.stack([np.asarray(x) + 2 * block + k for k in range(2)])
            for name, x in vars(case.state).items()
        }})
        writer(states, np.array([2 * block, 2 * block + 1], dtype=np.float32))
        print("wrote", writer.n_frames, flush=True)
        sys.stdin.readline()  # the test reads the file, then lets the run go on
"""


def _xdmf_times_and_positions(path):
    """Times and the last frame's points, through VTK's XDMF reader (ParaView's)."""
    numpy_support = pytest.importorskip("vtkmodules.util.numpy_support")
    from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline
    from vtkmodules.vtkIOXdmf2 import vtkXdmfReader

    reader = vtkXdmfReader()
    reader.SetFileName(str(path))
    reader.UpdateInformation()
    times = reader.GetOutputInformation(0).Get(vtkStreamingDemandDrivenPipeline.TIME_STEPS())
    reader.UpdateTimeStep(times[-1])
    points = reader.GetOutputDataObject(0).GetPoints()
    assert points is not None, "VTK read no points"
    return np.asarray(times), numpy_support.vtk_to_numpy(points.GetData())


def _next_line(process):
    line = process.stdout.readline()
    if not line:
        process.kill()
        raise AssertionError(process.communicate()[1][-3000:])
    return line.split()


def test_a_run_is_readable_while_it_is_written(tmp_path):
    """A second process writes three blocks of two frames, waiting after each; this one
    reads the file in between with read_trajectory, h5py, VTK's XDMF reader and
    `sphjax plot`, and sees exactly the frames written so far.  A reader that keeps the
    file open across a block does not stop the writer."""
    path = tmp_path / "live.h5"
    script = textwrap.dedent(SLOW_WRITER.format(path=str(path)))
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    writer = subprocess.Popen(
        [sys.executable, "-c", script], env=env, text=True,
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip
    start = np.asarray(sphjax.cases.get("taylor_green", n=4).state.position)
    held = None
    try:
        for block in range(3):
            n = 2 * (block + 1)
            assert _next_line(writer) == ["wrote", str(n)]
            if held is not None:  # it was open while the writer appended the block
                held.close()
            trajectory, meta = read_trajectory(path)
            assert len(trajectory) == n and meta["n_frames"] == n and not meta["complete"]
            np.testing.assert_array_equal(trajectory.times, np.arange(n))
            for frame in range(n):  # the writer ran in float32
                np.testing.assert_allclose(
                    trajectory.states.position[frame], start + frame, rtol=1e-6
                )
            with h5py.File(path, "r") as f:  # plain h5py, HDF5's file locking on
                assert f["times"].shape == (n,) and f["states/position"].shape[0] == n
            times, points = _xdmf_times_and_positions(path.with_suffix(".xdmf"))
            np.testing.assert_array_equal(times, np.arange(n))
            np.testing.assert_allclose(points[:, :2], start + n - 1, rtol=1e-6)
            if block == 0:
                held = h5py.File(path, "r")  # kept open while the next block is written
            if block == 2:
                png = tmp_path / "live.png"
                assert main(["plot", str(path), "--field", "density", "--out", str(png)]) == 0
            writer.stdin.write("\n")
            writer.stdin.flush()
        _, err = writer.communicate(timeout=60)
        assert writer.returncode == 0, err[-3000:]
    finally:
        if writer.poll() is None:
            writer.kill()
        if held is not None:
            held.close()
    trajectory, meta = read_trajectory(path)
    assert len(trajectory) == 6 and meta["complete"]


HOLDER = """
import sys
import h5py

f = h5py.File({path!r}, "a")  # another program that keeps the file open for writing
print("holding", flush=True)
sys.stdin.readline()
f.close()
"""


@pytest.mark.skipif(
    os.environ.get("HDF5_USE_FILE_LOCKING", "").upper() == "FALSE",
    reason="HDF5 file locking is turned off here (HDF5_USE_FILE_LOCKING=FALSE)",
)
def test_a_locked_file_is_reported_as_locked(case, tmp_path, monkeypatch, capsys):
    path = tmp_path / "held.h5"
    write_trajectory(path, _frames(case, 1), case)
    monkeypatch.setattr(sphjax.io, "LOCK_WAIT_S", 0.2)
    monkeypatch.setattr(sphjax.io, "WRITER_LOCK_WAIT_S", 0.2)
    holder = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(HOLDER.format(path=str(path)))],
        text=True, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip
    try:
        assert _next_line(holder) == ["holding"]
        locked = (
            f"'{path}' is locked: another process has it open for writing; wait until that "
            "process closes it"
        )
        with pytest.raises(FileLockedError, match=re.escape(locked)):
            read_trajectory(path)
        with pytest.raises(FileLockedError):
            read_metadata(path)
        assert main(["plot", str(path), "--out", str(tmp_path / "p.png")]) == 2
        err = capsys.readouterr().err
        assert f"sphjax plot: error: FILE.h5: {locked}" in err
        assert "damaged" not in err and "not a readable" not in err
        assert len(err.strip().splitlines()) == 1, err
        with pytest.raises(FileLockedError, match=r"^path: cannot replace '.*': another process"):
            TrajectoryWriter(path, case, overwrite=True)
    finally:
        holder.communicate("\n", timeout=60)
    assert len(read_trajectory(path)[0]) == 1  # released: readable again
