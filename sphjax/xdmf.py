"""XDMF descriptions of trajectory files, so ParaView opens them as a time series.

An XDMF file is XML that points into the HDF5 file: it copies no data.  For a trajectory
``run.h5`` (see :mod:`sphjax.io`) the description ``run.xdmf`` has one temporal collection
with one grid per frame: ``<Time>`` from ``/times``, the particles as a ``Polyvertex``
topology, the geometry and every State field (``time`` aside) as hyperslabs of frame ``i``
of ``/states/<field>``.  Scalars ``[T, N]`` become scalar attributes, ``[T, N, d]`` vectors
and anything larger a matrix of ``N`` rows.  XDMF 2 is used, which ParaView's "Xdmf Reader"
and the XDMF 3 reader both read (open ``run.xdmf``, not ``run.h5``).

:class:`sphjax.io.TrajectoryWriter` rewrites the description after every block of frames,
so it always matches the frames already in the file.
"""

from __future__ import annotations

import os
from pathlib import Path
from xml.sax.saxutils import escape, quoteattr

import h5py
import numpy as np

# numpy kind and item size -> XDMF NumberType and Precision
_NUMBER_TYPES = {"f": "Float", "i": "Int", "u": "UInt", "b": "UChar"}


def xdmf_path(h5_path) -> Path:
    """``run.h5`` -> ``run.xdmf`` (the description written beside a trajectory file)."""
    return Path(h5_path).with_suffix(".xdmf")


def _number_type(dtype: np.dtype) -> str:
    dtype = np.dtype(dtype)
    try:
        kind = _NUMBER_TYPES[dtype.kind]
    except KeyError:
        raise ValueError(f"no XDMF number type for the dtype {dtype}") from None
    return f'NumberType="{kind}" Precision="{dtype.itemsize}"'


def _frame(reference: str, shape: tuple[int, ...], dtype, i: int) -> str:
    """A hyperslab DataItem selecting frame ``i`` of a ``[T, ...]`` dataset."""
    n_frames, *rest = shape
    count = " ".join(map(str, rest))
    zeros = " ".join(["0"] * len(rest))
    ones = " ".join(["1"] * len(rest))
    return (
        f'<DataItem ItemType="HyperSlab" Dimensions="{count}" Type="HyperSlab">'
        f'<DataItem Dimensions="3 {len(shape)}" Format="XML">'
        f"{i} {zeros} 1 {ones} 1 {count}</DataItem>"
        f'<DataItem Dimensions="{n_frames} {count}" {_number_type(dtype)} Format="HDF">'
        f"{escape(reference)}</DataItem></DataItem>"
    )


def _attribute_type(shape: tuple[int, ...]) -> str:
    return {2: "Scalar", 3: "Vector"}.get(len(shape), "Matrix")


def describe(f: h5py.File, h5_name: str) -> str | None:
    """The XDMF text for the open trajectory file ``f``, referring to it as ``h5_name``;
    None while the file holds no frames (an empty time series is not valid XDMF)."""
    states = f["states"] if "states" in f else {}
    times = np.asarray(f["times"][()]) if "times" in f else np.zeros(0)
    fields = {
        name: (tuple(d.shape), d.dtype)
        for name, d in states.items()
        if name not in ("time", "position") and d.ndim >= 2
    }
    grids = []
    if "position" in states:
        shape, dtype = tuple(states["position"].shape), states["position"].dtype
        n_particles, dim = shape[1], shape[2]
        geometry = "XY" if dim == 2 else "XYZ" if dim == 3 else None
        for i, t in enumerate(times[: shape[0]]):
            parts = [
                f'<Grid Name="frame {i}" GridType="Uniform">',
                f'<Time Value="{float(t)!r}"/>',
                f'<Topology TopologyType="Polyvertex" NumberOfElements="{n_particles}" '
                'NodesPerElement="1"/>',
            ]
            if geometry is not None:
                parts.append(
                    f'<Geometry GeometryType="{geometry}">'
                    f"{_frame(f'{h5_name}:/states/position', shape, dtype, i)}</Geometry>"
                )
            for name, (fshape, fdtype) in fields.items():
                if fshape[0] <= i or fshape[1] != n_particles:
                    continue
                parts.append(
                    f"<Attribute Name={quoteattr(name)} AttributeType="
                    f'"{_attribute_type(fshape)}" Center="Node">'
                    f"{_frame(f'{h5_name}:/states/{name}', fshape, fdtype, i)}</Attribute>"
                )
            parts.append("</Grid>")
            grids.append("\n    ".join(parts))
    if not grids:
        return None
    body = "\n   ".join(grids)
    return (
        '<?xml version="1.0" ?>\n'
        '<Xdmf Version="2.0">\n'
        " <Domain>\n"
        '  <Grid Name="particles" GridType="Collection" CollectionType="Temporal">\n'
        f"   {body}\n"
        "  </Grid>\n"
        " </Domain>\n"
        "</Xdmf>\n"
    )


def write_xdmf(h5, path=None) -> Path:
    """Write the XDMF description of a trajectory file; returns its path.

    While the file holds no frames there is nothing to describe, and a stale description
    at ``path`` is removed.

    Args:
      h5: the trajectory file (a path, or an open ``h5py.File``).
      path: where to write (default: beside the HDF5 file, ``.xdmf`` instead of ``.h5``).
        The HDF5 file is referred to by a path relative to this file's folder.
    """
    if isinstance(h5, h5py.File):
        h5_file = Path(h5.filename)
        path = xdmf_path(h5_file) if path is None else Path(path)
        text = describe(h5, os.path.relpath(h5_file.resolve(), path.resolve().parent))
    else:
        with h5py.File(h5, "r") as f:
            return write_xdmf(f, path)
    if text is None:
        path.unlink(missing_ok=True)
        return path
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)  # a reader never sees half a file
    return path
