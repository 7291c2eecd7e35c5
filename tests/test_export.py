"""ParaView output and animations, read back with real readers: the XDMF description through
VTK's XDMF reader (the one ParaView uses), the .vtu/.pvd export through meshio, GIF frames
through Pillow and MP4 frames through ffmpeg.  About 20 s in all (one Taylor-Green compile)."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import jax
import meshio
import numpy as np
import pytest

import sphjax
from sphjax.cli import main
from sphjax.io import TrajectoryWriter, read_trajectory

FIELDS = [name for name in vars(sphjax.cases.get("taylor_green", n=4).state) if name != "time"]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """Taylor-Green at n = 8, 5 steps saved every 2: frames at steps 0, 2, 4, 5."""
    path = tmp_path_factory.mktemp("export") / "db.h5"
    case = sphjax.cases.get("taylor_green", n=8)
    with TrajectoryWriter(path, case) as writer:
        trajectory = sphjax.simulate(case, n_steps=5, save_every=2, on_frames=writer)
    return path, trajectory


def _padded(x):
    x = np.asarray(x)
    return np.concatenate([x, np.zeros((x.shape[0], 3 - x.shape[1]), x.dtype)], 1)


def _read_xdmf(path):
    """(times, [(points, {name: array})]) through vtkXdmfReader."""
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline
    from vtkmodules.vtkIOXdmf2 import vtkXdmfReader

    reader = vtkXdmfReader()
    reader.SetFileName(str(path))
    reader.UpdateInformation()
    times = reader.GetOutputInformation(0).Get(vtkStreamingDemandDrivenPipeline.TIME_STEPS())
    frames = []
    for t in times:
        reader.UpdateTimeStep(t)
        grid = reader.GetOutputDataObject(0)
        data = grid.GetPointData()
        arrays = {
            data.GetArrayName(i): vtk_to_numpy(data.GetArray(i))
            for i in range(data.GetNumberOfArrays())
        }
        frames.append((vtk_to_numpy(grid.GetPoints().GetData()), arrays))
    return np.asarray(times), frames


def test_xdmf_beside_the_trajectory_reads_back_in_vtk(run):
    path, trajectory = run
    xdmf = path.with_suffix(".xdmf")
    assert xdmf.is_file()
    times, frames = _read_xdmf(xdmf)
    np.testing.assert_allclose(times, trajectory.times, rtol=1e-6)
    assert len(frames) == 4
    for i, (points, arrays) in enumerate(frames):
        state = trajectory.frame(i)
        np.testing.assert_array_equal(points, _padded(state.position))
        assert set(arrays) == set(FIELDS) - {"position"}
        for name, values in arrays.items():
            expected = np.asarray(getattr(state, name))
            expected = _padded(expected) if expected.ndim == 2 else expected
            np.testing.assert_array_equal(values, expected, err_msg=name)


def test_xdmf_follows_the_frames_written_so_far(tmp_path):
    """Rewritten after a block of frames; none while there are no frames (and a stale one from an
    earlier run is removed: an empty time series crashes VTK's reader)."""
    case = sphjax.cases.get("taylor_green", n=4)
    one = jax.tree_util.tree_map(lambda x: np.asarray(x)[None], case.state)
    xdmf = tmp_path / "t.xdmf"
    xdmf.write_text("stale")
    writer = TrajectoryWriter(tmp_path / "t.h5", case, overwrite=True)  # a stale description
    # the description is rewritten at a pace set by its own cost (XDMF_PACE times the last
    # rewrite's time); a busy machine could stretch that past any sleep, so pace it at zero
    writer.XDMF_PACE = 0.0
    assert not xdmf.exists()
    for k in range(3):
        writer(one, np.full(1, float(k)))
        grids = ET.parse(xdmf).getroot().find("Domain/Grid").findall("Grid")
        assert [float(g.find("Time").get("Value")) for g in grids] == list(range(k + 1))
    writer.close()
    np.testing.assert_array_equal(_read_xdmf(xdmf)[0], [0.0, 1.0, 2.0])


def test_export_vtk_round_trip(run, tmp_path, capsys):
    path, trajectory = run
    folder = tmp_path / "vtk"
    assert main(["export", str(path), "--vtk", str(folder)]) == 0
    pvd = ET.parse(folder / "db.pvd").getroot()
    assert pvd.get("type") == "Collection"
    datasets = pvd.find("Collection").findall("DataSet")
    np.testing.assert_allclose([float(d.get("timestep")) for d in datasets], trajectory.times)
    for i, entry in enumerate(datasets):
        mesh = meshio.read(folder / entry.get("file"))
        state = trajectory.frame(i)
        np.testing.assert_array_equal(mesh.points, _padded(state.position))
        assert mesh.cells[0].type == "vertex" and len(mesh.cells[0].data) == state.n_particles
        assert set(mesh.point_data) == set(FIELDS) - {"position"}
        for name, values in mesh.point_data.items():
            expected = np.asarray(getattr(state, name))
            expected = _padded(expected) if expected.ndim == 2 else expected
            np.testing.assert_array_equal(values, expected, err_msg=name)
    # a second export into the same folder needs --overwrite
    assert main(["export", str(path), "--vtk", str(folder)]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert main(["export", str(path), "--vtk", str(folder), "--overwrite"]) == 0


def test_python_writers_refuse_to_replace_an_output(run, tmp_path):
    """``export_vtk``, ``FramePlot.save`` and ``animate`` refuse an existing output with one
    FileExistsError line naming the path and ``overwrite=True``; with it they replace it."""
    from sphjax.plot import FramePlot, animate
    from sphjax.vtk_export import export_vtk

    path, _ = run
    trajectory, meta = read_trajectory(path)
    folder = tmp_path / "vtk"
    pvd = export_vtk(trajectory, folder, name="db")
    stamp = pvd.stat().st_mtime_ns
    with pytest.raises(FileExistsError) as error:
        export_vtk(trajectory, folder, name="db")
    assert str(error.value) == (
        f"folder: '{pvd}' exists; pass overwrite=True to replace it, or choose another path"
    )
    assert pvd.stat().st_mtime_ns == stamp
    (folder / "db_0003.vtu").unlink()  # any one file of the export is enough to refuse
    pvd.unlink()
    with pytest.raises(
        FileExistsError, match=r"^folder: '.*db_0000\.vtu' exists; pass overwrite=True"
    ):
        export_vtk(trajectory, folder, name="db")
    assert not pvd.exists()
    assert export_vtk(trajectory, folder, name="db", overwrite=True) == pvd
    assert export_vtk(trajectory, folder, name="other") == folder / "other.pvd"

    image = tmp_path / "p.png"
    figure = FramePlot(trajectory, meta, "kind")
    try:
        figure.save(image)
        assert image.read_bytes()[:4] == b"\x89PNG"
        image.write_bytes(b"mine")
        with pytest.raises(FileExistsError, match=r"^path: '.*p\.png' exists; pass overwrite=True"):
            figure.save(image)
        assert image.read_bytes() == b"mine"
        figure.save(image, overwrite=True)
        assert image.read_bytes()[:4] == b"\x89PNG"
    finally:
        figure.close()

    movie = tmp_path / "m.gif"
    movie.write_bytes(b"mine")
    with pytest.raises(FileExistsError, match=r"^path: '.*m\.gif' exists; pass overwrite=True"):
        animate(trajectory, meta, "kind", movie, progress=False)
    assert movie.read_bytes() == b"mine"
    assert animate(trajectory, meta, "kind", movie, progress=False, overwrite=True) == 4
    assert movie.read_bytes()[:3] == b"GIF"


def test_animate_gif_has_one_frame_per_saved_frame(run, tmp_path):
    from PIL import Image

    path, trajectory = run
    gif = tmp_path / "m.gif"
    assert main(["animate", str(path), "--field", "kind", "--out", str(gif), "--quiet"]) == 0
    with Image.open(gif) as image:
        assert image.n_frames == len(trajectory)
    every = tmp_path / "every2.gif"
    argv = ["animate", str(path), "--every", "2", "--out", str(every), "--quiet"]
    assert main(argv) == 0
    with Image.open(every) as image:
        assert image.n_frames == 2  # frames 0 and 2 of 4


def test_animate_mp4(run, tmp_path):
    import imageio_ffmpeg

    path, trajectory = run
    mp4 = tmp_path / "m.mp4"
    argv = ["animate", str(path), "--field", "pressure", "--out", str(mp4), "--fps", "10"]
    assert main([*argv, "--quiet"]) == 0
    n_frames, seconds = imageio_ffmpeg.count_frames_and_secs(str(mp4))
    assert n_frames == len(trajectory)
    assert seconds == pytest.approx(len(trajectory) / 10, abs=0.11)


def test_read_back_matches_after_export(run):
    """Exporting and animating leave the trajectory file as it was."""
    path, trajectory = run
    read, meta = read_trajectory(path)
    assert meta["complete"]
    np.testing.assert_array_equal(read.states.position, trajectory.states.position)


def test_frame_titles_name_the_frames_of_the_file(run):
    """An animation of every second frame titles frame 1 of the movie as frame 2 of 4."""
    from sphjax.plot import FramePlot

    path, _ = run
    every2, meta = read_trajectory(path, frames=slice(None, None, 2))
    plot = FramePlot(every2, meta, "kind", frame_numbers=range(0, meta["n_frames"], 2))
    plot.set_frame(1)
    assert "frame 2/3" in plot.title.get_text() and plot.title.get_text().startswith("taylor_green")
    plot.close()
