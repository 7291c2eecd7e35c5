"""HDF5 trajectories: write frames as a run goes, read them back to the same pytree.

File layout (one file per run, h5py)::

    /times                    [T]            simulated time of each frame
    /states/<field>           [T, ...]       one dataset per State field (position, ...)
    /params                   (group)        one attribute per Params field
    /  attributes             format, format_version, sphjax_version, case, dt,
                              model (JSON), case_info (JSON), complete, error, ...

Every dataset has an unlimited, chunked leading time axis (one chunk per frame).
:class:`TrajectoryWriter` is an ``on_frames`` callback for :func:`sphjax.simulate`: it
opens the file, appends a block of frames and closes it again, so a run that is killed or
goes unstable keeps every frame already written, and other processes (``sphjax plot``,
:func:`read_trajectory`, h5py, ParaView) can read the file while the run writes it.
``complete`` becomes true only when the writer is closed after a run that raised
nothing.  Beside the file it keeps an XDMF description (``run.h5`` -> ``run.xdmf``,
:mod:`sphjax.xdmf`) that ParaView opens.

Why not HDF5's single-writer/multiple-reader mode: a file in SWMR mode can be opened only
by readers that ask for it (``h5py.File(path, "r", swmr=True)``); VTK's XDMF reader
(ParaView's) and plain h5py are refused ("file is already open for write"), and the file
needs HDF5 >= 1.10 to be read at all.  Releasing the file between blocks serves every
reader, and the file stays in the oldest HDF5 format.  HDF5's file lock still separates
the two sides for the milliseconds of an append: a reader that finds the file locked
waits for the append to finish (:data:`LOCK_WAIT_S`); a file locked for longer, by
another writer, is reported as locked (:class:`FileLockedError`), not as damaged.

    with sphjax.io.TrajectoryWriter("run.h5", case) as writer:
        sphjax.simulate(case, t_end=0.1, save_every=10, on_frames=writer)
    trajectory, metadata = sphjax.io.read_trajectory("run.h5")
"""

from __future__ import annotations

import dataclasses
import errno
import json
import math
import os
import time
import warnings
from pathlib import Path
from typing import Any

import h5py
import jax
import jax.numpy as jnp
import numpy as np

from sphjax._paths import check_new, check_writable
from sphjax.core.case import Case
from sphjax.core.kernels import KERNELS
from sphjax.core.params import Params, make_params
from sphjax.core.state import State, Trajectory
from sphjax.xdmf import write_xdmf, xdmf_path

FORMAT = "sphjax-trajectory"
FORMAT_VERSION = 1
STATE_FIELDS = tuple(f.name for f in dataclasses.fields(State))

# How long (s) a reader waits for a writer's append to finish, and a writer for a reader
# that holds the file, before a file lock is reported (reader) or stepped around (writer).
LOCK_WAIT_S = 5.0
WRITER_LOCK_WAIT_S = 2.0
_LOCK_POLL_S = 0.02


# ---------------------------------------------------------------------------- metadata


def _jsonable(value):
    """Best-effort conversion of Model/Case values to JSON types."""
    if value is None or isinstance(value, bool | int | str):
        return value
    if isinstance(value, float | np.floating):
        value = float(value)
        return value if math.isfinite(value) else str(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.ndarray | jax.Array):
        return _jsonable(np.asarray(value).tolist())
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        fields = {f.name: _jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
        return {"type": type(value).__name__, **fields}
    if callable(value):
        return getattr(value, "__qualname__", repr(value))
    return repr(value)


def _kernel_name(kernel) -> str:
    for name, cls in KERNELS.items():
        if type(kernel) is cls:
            return name
    return type(kernel).__name__


def model_to_dict(model) -> dict[str, Any]:
    """The fields of a Model as JSON-ready values (kernel by name, domain as a dict)."""
    out = {}
    for f in dataclasses.fields(model):
        value = getattr(model, f.name)
        if f.name == "kernel":
            out["kernel"] = _kernel_name(value)
        elif f.name == "clamped_motion":
            out[f.name] = None if value is None else getattr(value, "__qualname__", repr(value))
        else:
            out[f.name] = _jsonable(value)
    return out


# ---------------------------------------------------------------------------- file locks


class FileLockedError(ValueError):
    """A trajectory file that another process holds open for writing: a file in use, not
    a damaged one.  The message names the file and what to do."""


def _is_lock_error(err: BaseException) -> bool:
    """Whether h5py failed to take HDF5's file lock (another process holds the file)."""
    return isinstance(err, OSError) and (
        err.errno in (errno.EAGAIN, errno.EWOULDBLOCK, errno.EACCES) and "lock" in str(err).lower()
    )


def _locked_message(path) -> str:
    return (
        f"'{path}' is locked: another process has it open for writing; wait until that "
        "process closes it (a run releases the file between blocks of frames), then try again"
    )


def _open_waiting(path, mode: str, wait: float, **kwargs) -> h5py.File:
    """``h5py.File(path, mode)``, retrying for up to ``wait`` seconds while another
    process holds HDF5's lock on the file."""
    deadline = time.monotonic() + wait
    while True:
        try:
            return h5py.File(path, mode, **kwargs)
        except OSError as err:
            if not _is_lock_error(err) or time.monotonic() >= deadline:
                raise
        time.sleep(_LOCK_POLL_S)


def _identity(path) -> tuple[int, int] | None:
    """The file at ``path`` (device, inode), or None if there is none."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return None
    return st.st_dev, st.st_ino


def _held_by_a_writer(path) -> bool:
    """Whether another process holds an exclusive lock on ``path`` (a writer), rather than
    only shared ones (readers).  HDF5 locks with ``flock`` on POSIX systems."""
    try:
        import fcntl
    except ImportError:  # no flock: assume the worst
        return True
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:  # unreadable or gone: no lock to find
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)  # releases the probe's lock
    return False


def _open_for_reading(path) -> h5py.File:
    """Open a trajectory file for reading, also while a run writes it.

    Waits out an append in progress (:data:`LOCK_WAIT_S`); a file locked for longer raises
    :class:`FileLockedError`.  A file that an HDF5 SWMR writer holds is opened in SWMR
    read mode."""
    try:
        return _open_waiting(path, "r", LOCK_WAIT_S)
    except OSError as err:
        if _is_lock_error(err):
            raise FileLockedError(_locked_message(path)) from None
        if "already open for write" not in str(err):  # h5py gives no errno for this one
            raise
    try:  # marked as open for writing: an SWMR writer, or a writer that was killed
        return h5py.File(path, "r", swmr=True)
    except OSError:
        raise FileLockedError(
            f"'{path}' is marked as open for writing by another program; wait until it "
            f"closes the file, or, if that program was killed, clear the mark with "
            f"`h5clear -s {path}`"
        ) from None


# ---------------------------------------------------------------------------- writer


class TrajectoryWriter:
    """Append frames of a run to an HDF5 file; usable as ``simulate(..., on_frames=writer)``.

    The file is created when the writer is made, so an unwritable path fails before the
    run starts; an existing file (or its XDMF description) is replaced only with
    ``overwrite=True``, as ``sphjax run --overwrite``.  Each call opens the file, appends a
    block of frames and closes it, so other processes can read the run while it is
    written (h5py, :func:`read_trajectory`, ParaView on the XDMF description), and a
    killed run leaves a readable file.

    Args:
      path: the ``.h5`` file to write.
      case: the :class:`~sphjax.Case` being run (its name, Model, Params, dt, info are
        stored as attributes).  May be None for frames of unknown origin.
      params: the Params actually used (default ``case.params``).
      dt: the time step actually used (default ``case.dt``).
      attrs: extra attributes (JSON-able values) to store on the file.
      argument: the name to use for ``path`` in error messages (e.g. ``"--out"``).
      xdmf: also write an XDMF description beside the file (``run.h5`` -> ``run.xdmf``,
        see :mod:`sphjax.xdmf`), so ParaView opens the run: after a block of frames (at
        most ~5 % of the run's time goes to it; long series are rewritten less often)
        and when the writer is closed.
      overwrite: replace an existing file (and description); without it an existing one
        raises :class:`FileExistsError` (``path: 'run.h5' exists; pass overwrite=True to
        replace it, or choose another path``).

    A reader that keeps the file open for longer than :data:`WRITER_LOCK_WAIT_S` (h5py in
    a notebook) does not stall the run: the writer then appends without HDF5's file lock,
    and that reader sees the new frames when it opens the file again.  Another *writer*
    holding the file raises :class:`FileLockedError`.
    """

    def __init__(
        self,
        path,
        case: Case | None = None,
        *,
        params: Params | None = None,
        dt: float | None = None,
        attrs: dict[str, Any] | None = None,
        argument: str = "path",
        xdmf: bool = True,
        overwrite: bool = False,
    ):
        self.path = check_writable(path, argument)
        self.xdmf = xdmf_path(self.path) if xdmf else None
        check_new([self.path, *([self.xdmf] if xdmf else [])], argument, overwrite)
        self._argument = argument
        self._xdmf_done, self._xdmf_cost = 0.0, 0.0  # when the last rewrite ended, its time
        self._closed = False
        self._reader_holds = False  # a reader kept the file open past WRITER_LOCK_WAIT_S
        self.n_frames = 0
        if self.path.exists():  # overwrite=True
            if _held_by_a_writer(self.path):
                raise FileLockedError(
                    f"{argument}: cannot replace '{self.path}': another process has it open "
                    "for writing; wait until it closes it, or choose another path"
                )
            # a new file rather than a truncated one: a reader of the old one keeps it
            self.path.unlink()
        try:
            f = h5py.File(self.path, "w-")
        except OSError as err:
            raise ValueError(f"{argument}: cannot create '{self.path}': {err}") from None
        self._identity = _identity(self.path)
        with f:
            a = f.attrs
            from sphjax import __version__

            a["format"] = FORMAT
            a["format_version"] = FORMAT_VERSION
            a["sphjax_version"] = __version__
            a["complete"] = False
            a["error"] = ""
            a["n_frames"] = 0
            if case is not None:
                params = case.params if params is None else params
                dt = case.dt if dt is None else dt
                a["case"] = case.name
                a["model"] = json.dumps(model_to_dict(case.model))
                a["case_info"] = json.dumps(_jsonable(case.info))
                a["n_particles"] = case.n_particles
            if dt is not None:
                a["dt"] = float(dt)
            if params is not None:
                group = f.create_group("params")
                for name, value in params.items():
                    group.attrs[name] = np.asarray(value)
                if params.unused:  # the refused fields, so that the Params read back refuse them
                    group.attrs[_UNUSED] = json.dumps([list(item) for item in params.unused])
            for key, value in (attrs or {}).items():
                a[key] = json.dumps(_jsonable(value))
            self._write_xdmf(f)

    # The XDMF text grows with the frames, so it is rewritten only when at least this many
    # times the duration of its last rewrite has passed (at most ~5 % of a run's time).
    XDMF_PACE = 20.0

    def _write_xdmf(self, f: h5py.File, now: bool = True) -> None:
        start = time.perf_counter()
        due = self._xdmf_done + self.XDMF_PACE * self._xdmf_cost  # the pace read now
        if self.xdmf is not None and (now or start >= due):
            write_xdmf(f, self.xdmf)
            self._xdmf_done = time.perf_counter()
            self._xdmf_cost = self._xdmf_done - start

    def _open(self) -> h5py.File:
        """The file, opened for one block of writes (closed again after it)."""
        if self._closed:
            raise RuntimeError(f"TrajectoryWriter for '{self.path}' is already closed")
        if _identity(self.path) != self._identity:
            raise FileNotFoundError(
                f"{self._argument}: '{self.path}' was removed or replaced while the run "
                f"wrote it; the frames from now on are not saved"
            )
        try:
            wait = 0.0 if self._reader_holds else WRITER_LOCK_WAIT_S
            return _open_waiting(self.path, "r+", wait)
        except OSError as err:
            if not _is_lock_error(err):
                raise
            if _held_by_a_writer(self.path):
                raise FileLockedError(_locked_message(self.path)) from None
        # only readers hold it, longer than an append takes: append without the lock
        self._reader_holds = True
        return h5py.File(self.path, "r+", locking=False)

    # on_frames protocol
    def __call__(self, states: State, times) -> None:
        self.append(states, times)

    def append(self, states: State, times) -> None:
        """Append frames: ``states`` with a leading frame axis, ``times`` of shape ``[k]``."""
        if self._closed:
            raise RuntimeError(f"TrajectoryWriter for '{self.path}' is already closed")
        times = np.asarray(times)
        k = int(times.shape[0])
        if k == 0:
            return
        arrays = {name: np.asarray(getattr(states, name)) for name in STATE_FIELDS}
        for name, x in arrays.items():
            if x.shape[:1] != (k,):
                raise ValueError(f"states.{name} has {x.shape[:1]} frames but times has {k}")
        with self._open() as f:
            group = f.require_group("states")
            if self.n_frames == 0 and "times" not in f:
                for name, x in arrays.items():
                    group.create_dataset(
                        name, shape=(0, *x.shape[1:]), maxshape=(None, *x.shape[1:]),
                        dtype=x.dtype, chunks=(1, *x.shape[1:]) if x.ndim > 1 else (256,),
                    )  # fmt: skip
                f.create_dataset(
                    "times", shape=(0,), maxshape=(None,), dtype=times.dtype, chunks=(256,)
                )
            for name, x in arrays.items():
                if group[name].shape[1:] != x.shape[1:]:
                    raise ValueError(
                        f"states.{name} has per-frame shape {x.shape[1:]}, but the file holds "
                        f"frames of shape {group[name].shape[1:]}"
                    )
            end = self.n_frames + k
            for name, x in arrays.items():
                dataset = group[name]
                dataset.resize(end, axis=0)
                dataset[self.n_frames :] = x
            f["times"].resize((end,))
            f["times"][self.n_frames :] = times
            self.n_frames = end
            f.attrs["n_frames"] = end
            self._write_xdmf(f, now=False)

    def set_error(self, message: str) -> None:
        """Record why a run stopped (kept in the ``error`` attribute)."""
        if not self._closed:
            with self._open() as f:
                f.attrs["error"] = str(message)

    def close(self, complete: bool = True) -> None:
        if self._closed:
            return
        with self._open() as f:
            f.attrs["complete"] = bool(complete and not f.attrs["error"])
            self._write_xdmf(f)
        self._closed = True

    def __enter__(self) -> TrajectoryWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc is None:
            self.close()
            return
        try:  # record why the run stopped; the run's own exception is the one raised
            self.set_error(f"{exc_type.__name__}: {exc}")
            self.close(complete=False)
        except (OSError, ValueError):
            self._closed = True


def write_trajectory(path, trajectory: Trajectory, case: Case | None = None, **kwargs) -> Path:
    """Write a whole :class:`~sphjax.Trajectory` at once (see :class:`TrajectoryWriter`)."""
    with TrajectoryWriter(path, case, **kwargs) as writer:
        writer.append(trajectory.states, trajectory.times)
    return writer.path


# ---------------------------------------------------------------------------- reader


def _decode(value):
    if isinstance(value, bytes):
        value = value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value


def read_metadata(path) -> dict[str, Any]:
    """The attributes of a trajectory file as Python values (no frames are read)."""
    with _open(path) as f, _damaged(path):
        return _metadata(f)


class _damaged:
    """Report an HDF5 error while reading as a ValueError naming the file."""

    def __init__(self, path):
        self.path = path

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None and issubclass(exc_type, OSError | KeyError | RuntimeError):
            raise ValueError(
                f"'{self.path}' cannot be read, the file is damaged ({exc_type.__name__}: {exc})"
            ) from None
        return False


def _open(path):
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no trajectory file at '{path}'")
    try:
        f = _open_for_reading(path)
    except (OSError, KeyError, RuntimeError) as err:
        raise ValueError(f"'{path}' is not a readable HDF5 file: {err}") from None
    try:
        format_ = _decode(f.attrs.get("format"))
    except (OSError, KeyError, RuntimeError) as err:
        f.close()
        raise ValueError(f"'{path}' is not a readable HDF5 file: {err}") from None
    if format_ != FORMAT:
        f.close()
        raise ValueError(f"'{path}' is not an sphjax trajectory (no format='{FORMAT}' attribute)")
    return f


_PLAIN_ATTRS = {"format", "sphjax_version", "case", "error"}
_UNUSED = "unused"  # attribute of the params group: Params.unused as JSON [[field, refusal]]


def _metadata(f) -> dict[str, Any]:
    meta = {key: _decode(value) for key, value in f.attrs.items()}
    for key, value in meta.items():  # model, case_info and extra attrs are stored as JSON
        if isinstance(value, str) and key not in _PLAIN_ATTRS:
            meta[key] = json.loads(value)
    meta["complete"] = bool(meta.get("complete", False))
    meta["n_frames"] = int(f["times"].shape[0]) if "times" in f else 0
    if "params" in f:
        attrs = dict(f["params"].attrs.items())
        unused = tuple(tuple(item) for item in json.loads(_decode(attrs.pop(_UNUSED, "[]"))))
        values = {name: np.asarray(value) for name, value in attrs.items()}
        gravity = values.pop("gravity")
        params = make_params(gravity.shape[0], gravity=gravity, **values)
        meta["params"] = dataclasses.replace(params, unused=unused)
    return meta


def read_trajectory(path, frames=None) -> tuple[Trajectory, dict[str, Any]]:
    """Read a trajectory file written by :class:`TrajectoryWriter`, also while a run is
    still writing it (the frames written so far; ``complete`` is false).

    Raises :class:`FileLockedError` (a ValueError) if another program holds the file open
    for writing for longer than :data:`LOCK_WAIT_S`.

    Args:
      path: the ``.h5`` file.
      frames: optional index or slice of frames to read (default: all); an index keeps
        the leading time axis (one frame).
    Returns:
      ``(trajectory, metadata)``: a :class:`~sphjax.Trajectory` with the stored dtypes and
      a dict of the file attributes (``case``, ``dt``, ``sphjax_version``, ``model`` and
      ``case_info`` as dicts, ``params`` as :class:`~sphjax.Params`, ``complete``,
      ``error``, ``n_frames``).
    """
    with _open(path) as f, _damaged(path):
        meta = _metadata(f)
        if "states" not in f:
            raise ValueError(f"'{path}' holds no frames (the run stopped before the first one)")
        n = int(f["times"].shape[0])
        if frames is None:
            select = slice(None)
        elif isinstance(frames, slice):
            select = frames
        else:
            i = int(frames)
            if not -n <= i < n:
                raise IndexError(f"frame {i} out of range: '{path}' holds {n} frames")
            select = slice(i % n, i % n + 1)
        arrays = {name: f["states"][name][select] for name in STATE_FIELDS}
        times = f["times"][select]
    if any(x.dtype == np.float64 for x in arrays.values()) and not jax.config.jax_enable_x64:
        warnings.warn(
            f"'{path}' holds float64 data but jax_enable_x64 is off, so it is read as "
            "float32; enable it (jax.config.update('jax_enable_x64', True)) for an exact read",
            stacklevel=2,
        )
    states = State(**{name: jnp.asarray(x) for name, x in arrays.items()})
    return Trajectory(states=states, times=jnp.asarray(times)), meta


__all__ = [
    "LOCK_WAIT_S",
    "FileLockedError",
    "TrajectoryWriter",
    "check_writable",
    "model_to_dict",
    "read_metadata",
    "read_trajectory",
    "write_trajectory",
    "write_xdmf",
    "xdmf_path",
]
