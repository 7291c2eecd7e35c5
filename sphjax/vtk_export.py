"""VTK files of a trajectory for ParaView: one ``.vtu`` per frame and a ``.pvd`` collection.

Each frame is an unstructured grid of vertex cells, one per particle, with every State
field (``time`` aside) as point data; points and vector fields are padded to three
components (VTK's convention), so a 2D run lies in the plane ``z = 0``.  The ``.pvd`` file
lists the frames with their simulated times, so ParaView plays them as a time series.
The ``.vtu`` files are written by meshio.

    sphjax export run.h5 --vtk run_vtk      # run_vtk/run.pvd, run_vtk/run_0000.vtu, ...
"""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np


def _three(x: np.ndarray) -> np.ndarray:
    """``[N, d]`` -> ``[N, 3]`` with zeros (VTK points and vectors have three components)."""
    if x.ndim == 2 and x.shape[1] < 3:
        return np.concatenate([x, np.zeros((x.shape[0], 3 - x.shape[1]), x.dtype)], axis=1)
    return x


def point_data(state) -> dict[str, np.ndarray]:
    """The State fields of one frame as VTK point data (``time`` left out)."""
    out = {}
    for name, value in vars(state).items():
        if name in ("time", "position"):
            continue
        x = np.asarray(value)
        if x.dtype == bool:
            x = x.astype(np.uint8)
        if x.ndim > 2:
            x = x.reshape(x.shape[0], -1)
        out[name] = _three(x)
    return out


def export_vtk(trajectory, folder, name: str = "trajectory", *, overwrite: bool = False) -> Path:
    """Write ``folder/<name>_<i>.vtu`` per frame and ``folder/<name>.pvd``; returns the pvd.

    Args:
      trajectory: a :class:`~sphjax.Trajectory` (e.g. from :func:`sphjax.io.read_trajectory`).
      folder: output folder (created if missing).
      name: the stem of the file names.
      overwrite: replace files of an earlier export; without it, a file this export would
        write that exists already raises :class:`FileExistsError` (``folder: '...pvd'
        exists; pass overwrite=True to replace it, ...``) before anything is written.
    """
    import meshio

    from sphjax._paths import check_new

    folder = Path(folder)
    n = len(trajectory)
    width = max(4, len(str(n - 1)))
    outputs = [folder / f"{name}.pvd", *(folder / f"{name}_{i:0{width}d}.vtu" for i in range(n))]
    check_new(outputs, "folder", overwrite)
    folder.mkdir(parents=True, exist_ok=True)
    times = np.asarray(trajectory.times, dtype=float)
    entries = []
    for i in range(n):
        state = trajectory.frame(i)
        points = _three(np.asarray(state.position))
        cells = [("vertex", np.arange(points.shape[0], dtype=np.int64)[:, None])]
        file = f"{name}_{i:0{width}d}.vtu"
        mesh = meshio.Mesh(points, cells, point_data=point_data(state))
        meshio.write(folder / file, mesh, file_format="vtu", binary=True)
        entries.append(
            f'    <DataSet timestep="{float(times[i])!r}" part="0" file={quoteattr(file)}/>'
        )
    pvd = folder / f"{name}.pvd"
    pvd.write_text(
        '<?xml version="1.0"?>\n'
        '<VTKFile type="Collection" version="0.1">\n'
        "  <Collection>\n" + "\n".join(entries) + "\n  </Collection>\n</VTKFile>\n"
    )
    return pvd
