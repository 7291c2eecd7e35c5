"""Pictures of trajectories: one frame as an image, all frames as a GIF or MP4.

Used by ``sphjax plot`` and ``sphjax animate``; works on what :func:`sphjax.io.read_trajectory`
returns, so any trajectory file can be drawn.  The view is fitted to the particles (over
all frames drawn), lengths are shown in m, mm or µm to keep the tick labels short, the
colour bar carries the field's SI unit (and a power of ten when the values are very small
or large), ``kind`` is drawn with one colour per particle type and a legend, and a rigid
cylinder recorded in the case information (Turek-Hron) is drawn as a disc.  A 3D
trajectory is drawn as a side view when its run has gravity (the gravity recorded in the
file's Params): a projection along one horizontal axis, the one along which the particles
extend least (the second of the two when they extend equally), with the vertical axis
upwards, so a 3D dam break with gravity along -z is drawn in x and z
(:func:`projection_axes`).  Without gravity it is drawn as its x-y projection.  Or as a
slice: the particles within one kernel support of a plane such as ``z = 0.5``
(:func:`parse_slice`), drawn in the plane's axes.

    from sphjax.io import read_trajectory
    from sphjax.plot import FramePlot

    trajectory, meta = read_trajectory("run.h5", frames=-1)
    FramePlot(trajectory, meta, "pressure").save("p.png")
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

IMAGE_SUFFIXES = {".png", ".pdf", ".svg", ".jpg", ".jpeg", ".tif", ".tiff", ".webp", ".eps"}
MOVIE_SUFFIXES = {".gif", ".mp4"}

# particle kinds (sphjax.Kind) with their legend names and colours
KIND_NAMES = {0: "fluid", 1: "wall", 2: "elastic solid", 3: "clamped solid"}
KIND_COLOURS = {0: "#1f77b4", 1: "#9e9e9e", 2: "#ff7f0e", 3: "#5d4037"}

# SI unit of each State field in d dimensions (2D quantities are per unit depth)
_UNITS = {
    "position": "m",
    "reference_position": "m",
    "velocity": "m/s",
    "acceleration": "m/s²",
    "shift_acceleration": "m/s²",
    "density": "kg/m³",
    "density_rate": "kg/(m³ s)",
    "pressure": "Pa",
}


def unit(field: str, dim: int) -> str:
    """The SI unit of a State field, e.g. ``unit("velocity", 2) == "m/s"``."""
    if field == "mass":
        return "kg" if dim == 3 else "kg/m" if dim == 2 else "kg/m²"
    if field == "volume":
        return f"m{'³' if dim == 3 else '²' if dim == 2 else ''}"
    return _UNITS.get(field, "")


AXES = "xyz"


def parse_slice(text: str) -> tuple[int, float]:
    """``"z=0.5"`` -> ``(2, 0.5)``: the axis (x, y or z) and position of a slicing plane."""
    name, sep, value = str(text).partition("=")
    name = name.strip().lower()
    try:
        position = float(value)
    except ValueError:
        position = None
    if not sep or name not in AXES or position is None or not math.isfinite(position):
        raise ValueError(f"a slice is AXIS=VALUE with AXIS x, y or z, e.g. z=0.5; got {text!r}")
    return AXES.index(name), position


def _gravity(meta: dict):
    """The gravity vector recorded in a trajectory's metadata, or None."""
    params = meta.get("params")
    if params is None:
        return None
    try:
        gravity = params["gravity"] if isinstance(params, dict) else params.gravity
        gravity = np.asarray(gravity, dtype=float).reshape(-1)
    except (AttributeError, KeyError, TypeError, ValueError):
        return None
    return gravity if gravity.size and np.all(np.isfinite(gravity)) else None


def projection_axes(position, meta: dict) -> tuple[int, int, bool]:
    """The two axes a 3D trajectory is drawn in by default, and whether the vertical one
    points against its coordinate (gravity along ``+axis``).

    With gravity (``meta["params"].gravity``, a run's Params as :func:`~sphjax.io.
    read_trajectory` returns them): ``(horizontal, vertical, flipped)``, ``vertical`` the axis
    along which gravity mostly acts, ``horizontal`` the one of the other two along which the
    particles extend more (the first of the two when they extend equally), so the view
    looks along the shortest horizontal extent.  Without gravity (zero, or not recorded, as
    in files written before it was): ``(0, 1, False)``, the x-y projection.

    Args:
      position: ``[..., 3]`` particle positions (all frames drawn).
      meta: the metadata of the trajectory's file.
    """
    gravity = _gravity(meta)
    if gravity is None or gravity.shape != (3,) or not np.any(gravity != 0):
        return 0, 1, False
    vertical = int(np.argmax(np.abs(gravity)))
    first, second = (a for a in range(3) if a != vertical)
    points = np.asarray(position, dtype=float).reshape(-1, 3)
    extent = points.max(axis=0) - points.min(axis=0)
    tolerance = 1e-9 * max(float(extent.max()), 1e-300)
    horizontal = second if extent[second] > extent[first] + tolerance else first
    return horizontal, vertical, bool(gravity[vertical] > 0)


def slice_half_width(meta: dict) -> float:
    """Half the thickness of a slice: the kernel support ``k h`` of the run's Model (two
    particle spacings if the file does not record it)."""
    model = meta.get("model") or {}
    try:
        from sphjax.core.kernels import as_kernel

        return float(as_kernel(model["kernel"]).support * model["smoothing_length"])
    except (KeyError, TypeError, ValueError):
        return 2.0 * float((meta.get("case_info") or {}).get("dx") or 0.0)


def _length_scale(extent: float) -> tuple[float, str]:
    """Factor and name of the length unit that keeps tick labels short."""
    if extent >= 0.1:
        return 1.0, "m"
    if extent >= 1e-4:
        return 1e3, "mm"
    return 1e6, "µm"


def _power_of_ten(values) -> int:
    """A power of ten to move into the label when values are very small or large."""
    peak = float(np.nanmax(np.abs(values))) if np.size(values) else 0.0
    if not (peak > 0 and math.isfinite(peak)):
        return 0
    exponent = math.floor(math.log10(peak))
    return exponent if exponent < -2 or exponent > 4 else 0


def _superscript(n: int) -> str:
    return str(n).translate(str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹"))


class FramePlot:
    """A figure of the particles of a trajectory coloured by ``field``; ``set_frame(i)``
    redraws frame ``i`` (for animations).

    Args:
      trajectory: a :class:`~sphjax.Trajectory` (all frames drawn share the view and the
        colour range).
      meta: the metadata of its file (case name, ``case_info`` and, for the view of a 3D
        trajectory, the gravity of its ``params`` are used).
      field: a State field; vectors are drawn by their magnitude, ``kind`` by type.
      frame_offset: the index of ``trajectory``'s first frame in its file (for the title).
      frame_numbers: the index in its file of each frame of ``trajectory`` (for the title;
        default ``frame_offset + i``), e.g. ``range(0, n, 4)`` for every fourth frame.
      slice_plane: ``None`` (3D: a side view with gravity, else the x-y projection; see
        :func:`projection_axes`) or ``(axis, value)`` from
        :func:`parse_slice`: only the particles within one kernel support of that plane
        are drawn, in the other two axes (3D trajectories only).
    Raises:
      ValueError: ``field`` is not a State field (the message lists them), or a slice of
        a 2D trajectory.
    Attributes:
      axes: the coordinate axes drawn as the figure's horizontal and vertical axes, e.g.
        ``(0, 2)`` for x and z.
    """

    def __init__(
        self,
        trajectory,
        meta: dict,
        field: str,
        frame_offset: int = 0,
        frame_numbers=None,
        slice_plane=None,
    ):
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib import patches, ticker

        states = trajectory.states
        fields = [f for f in vars(states) if f != "time"]
        if field not in fields:
            raise ValueError(f"unknown field {field!r}; choose one of {', '.join(fields)}")
        self.meta, self.field = meta, field
        if frame_numbers is None:
            frame_numbers = range(frame_offset, frame_offset + len(trajectory))
        self.frame_numbers = list(frame_numbers)
        self.n_frames_in_file = int(meta.get("n_frames", len(trajectory)))
        self.times = np.asarray(trajectory.times, dtype=float)
        position = np.asarray(states.position, dtype=float)
        self.dim = position.shape[-1]
        self.kind = np.asarray(states.kind)
        info = meta.get("case_info", {}) or {}
        axes = [0, 1]
        flipped = False
        self.visible = np.ones(position.shape[:-1], bool)
        self.slice_text = ""
        if slice_plane is not None:
            if self.dim != 3:
                raise ValueError(f"a slice needs a 3D trajectory; this one is {self.dim}D")
            axis, value = slice_plane
            half = slice_half_width(meta)
            axes = [a for a in range(3) if a != axis]
            self.visible = np.abs(position[..., axis] - value) <= half
            if not self.visible.any():
                lo_a, hi_a = position[..., axis].min(), position[..., axis].max()
                raise ValueError(
                    f"no particle within {half:.3g} of {AXES[axis]}={value:g}; the particles "
                    f"span {AXES[axis]} = {lo_a:.3g} to {hi_a:.3g}"
                )
            self.slice_text = f"  ({AXES[axis]} = {value:g} ± {half:.2g})"
        elif self.dim == 3:
            horizontal, vertical, flipped = projection_axes(position, meta)
            axes = [horizontal, vertical]
            self.slice_text = f"  ({AXES[horizontal]}-{AXES[vertical]} projection)"
        self.axes = tuple(axes) if self.dim > 1 else (0,)
        position = position[..., axes] if self.dim > 1 else position

        # view fitted to the particles over all frames, a couple of spacings of margin
        shown = position[self.visible]
        lo, hi = shown[:, :2].min(axis=0), shown[:, :2].max(axis=0)
        if self.dim == 1:
            lo, hi = np.append(lo, -0.5), np.append(hi, 0.5)
        disc = None
        if "cylinder_centre" in info and "cylinder_radius" in info:
            centre, radius = (
                np.asarray(info["cylinder_centre"], float),
                float(info["cylinder_radius"]),
            )
            disc = (centre, radius)
            lo, hi = np.minimum(lo, centre - radius), np.maximum(hi, centre + radius)
        spacing = float(info.get("dx") or max(hi - lo) / 50.0)
        lo, hi = lo - 2 * spacing, hi + 2 * spacing
        scale, length_unit = _length_scale(float(max(hi - lo)))
        self.scale = scale
        xy = position[..., :2] * scale
        self.xy = xy if self.dim > 1 else np.stack([xy[..., 0], np.zeros_like(xy[..., 0])], -1)

        # a wide, flat set-up (a plate, a beam) gets its colour bar below the particles
        width = 7.0
        aspect = float((hi[1] - lo[1]) / (hi[0] - lo[0]))
        flat = aspect < 0.4
        plot_width = width - (0.0 if flat else 1.6)
        height = min(max(plot_width * aspect + (2.2 if flat else 1.2), 2.4), 7.5)
        self.fig, self.ax = plt.subplots(figsize=(width, height), dpi=120, layout="constrained")
        ax = self.ax
        ax.set_aspect("equal")
        ax.set_xlim(lo[0] * scale, hi[0] * scale)
        ax.set_ylim(lo[1] * scale, hi[1] * scale)
        if flipped:  # gravity along +axis: up is towards smaller values
            ax.invert_yaxis()
        ax.xaxis.set_major_locator(ticker.MaxNLocator(nbins=6))
        ax.yaxis.set_major_locator(ticker.MaxNLocator(nbins=int(np.clip(round(8 * aspect), 3, 6))))
        ax.set_xlabel(f"{AXES[axes[0]]} [{length_unit}]")
        ax.set_ylabel(f"{AXES[axes[1]]} [{length_unit}]")
        size = 1.0  # set from the spacing on screen once the layout is known

        if disc is not None:
            ax.add_patch(
                patches.Circle(
                    disc[0] * scale, disc[1] * scale, facecolor="0.85", edgecolor="0.3",
                    linewidth=1.0, zorder=0, label="rigid cylinder",
                )
            )  # fmt: skip

        self.values = None
        if field == "kind":
            present = sorted(int(k) for k in np.unique(self.kind))
            colours = np.array([KIND_COLOURS.get(k, "k") for k in range(max(present) + 1)])
            self._colour_of = colours
            first = self.visible[0]
            self.points = ax.scatter(
                *self.xy[0][first].T, s=size, c=list(colours[self.kind[0][first]]), linewidths=0
            )
            handles = [
                matplotlib.lines.Line2D(
                    [], [], marker="o", linestyle="", color=KIND_COLOURS.get(k, "k"),
                    label=KIND_NAMES.get(k, f"kind {k}"),
                )
                for k in present
            ]  # fmt: skip
            if disc is not None:
                handles.append(patches.Patch(facecolor="0.85", edgecolor="0.3",
                                             label="rigid cylinder"))  # fmt: skip
            ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0),
                      borderaxespad=0.0, frameon=False)  # fmt: skip
        else:
            values = np.asarray(getattr(states, field), dtype=float)
            label = field.replace("_", " ")
            if values.ndim == 3:
                values, label = np.linalg.norm(values, axis=-1), f"|{label}|"
            values = values.reshape(values.shape[0], -1)[:, : self.xy.shape[1]]
            self.wall = self.kind == 1
            coloured = values[~self.wall] if (~self.wall).any() else values.ravel()
            power = _power_of_ten(coloured)
            self.values = values / 10.0**power
            u = unit(field, self.dim)
            if power:
                u = f"10{_superscript(power)} {u}".strip()
            label = f"{label} [{u}]" if u else label
            drawn = self.visible & ~self.wall
            shown = self.values[drawn] if drawn.any() else self.values[self.visible]
            vmin, vmax = float(np.nanmin(shown)), float(np.nanmax(shown))
            if not vmax > vmin:
                vmin, vmax = vmin - 0.5, vmax + 0.5
            self.walls = ax.scatter(
                *self.xy[0][self.wall[0] & self.visible[0]].T,
                s=size,
                c="0.75",
                marker="s",
                linewidths=0,
            )
            mobile = ~self.wall[0] & self.visible[0]
            self.points = ax.scatter(
                *self.xy[0][mobile].T, s=size, c=self.values[0][mobile], cmap="viridis",
                vmin=vmin, vmax=vmax, linewidths=0,
            )  # fmt: skip
            bar = self.fig.colorbar(
                self.points, ax=ax, label=label, shrink=0.9 if not flat else 0.6,
                orientation="horizontal" if flat else "vertical", aspect=30 if flat else 20,
            )  # fmt: skip
            bar.formatter = ticker.ScalarFormatter(useOffset=False)
            bar.update_ticks()
        self.title = ax.set_title("")
        self.set_frame(0)
        # marker area in points² from the particle spacing on screen
        self.fig.canvas.draw()
        bbox = ax.get_window_extent()
        points_per_unit = bbox.width * 72.0 / self.fig.dpi / ((hi[0] - lo[0]) * scale)
        size = float(np.clip((0.9 * spacing * scale * points_per_unit) ** 2, 0.2, 80.0))
        for collection in (self.points, getattr(self, "walls", None)):
            if collection is not None:
                collection.set_sizes([size])

    def set_frame(self, i: int) -> None:
        """Draw frame ``i`` of the trajectory."""
        visible = self.visible[i]
        if self.values is None:
            self.points.set_offsets(self.xy[i][visible])
            self.points.set_color(list(self._colour_of[self.kind[i][visible]]))
        else:
            mobile = ~self.wall[i] & visible
            self.walls.set_offsets(self.xy[i][self.wall[i] & visible])
            self.points.set_offsets(self.xy[i][mobile])
            self.points.set_array(self.values[i][mobile])
        n = self.n_frames_in_file
        name = self.meta.get("case", "?")
        self.title.set_text(
            f"{name}   t = {self.times[i]:.4g} s   frame {self.frame_numbers[i]}/{n - 1}"
            f"{self.slice_text}"
        )

    def save(self, path, *, overwrite: bool = False) -> Path:
        """Write the figure to ``path`` (its suffix picks the format).  An existing file
        raises :class:`FileExistsError` (``path: 'p.png' exists; pass overwrite=True ...``)
        unless ``overwrite``."""
        from sphjax._paths import check_new

        check_new([path], "path", overwrite)
        self.fig.savefig(path, bbox_inches="tight", pad_inches=0.1)
        return Path(path)

    def close(self) -> None:
        import matplotlib.pyplot as plt

        plt.close(self.fig)


def animate(
    trajectory,
    meta: dict,
    field: str,
    path,
    *,
    fps: int = 20,
    progress=True,
    frame_numbers=None,
    slice_plane=None,
    overwrite: bool = False,
) -> int:
    """Write every frame of ``trajectory`` coloured by ``field`` to a GIF or an MP4.

    GIFs are written with Pillow; MP4s (H.264) with the ffmpeg binary of the
    ``imageio-ffmpeg`` package.  ``frame_numbers``: see :class:`FramePlot`.  Returns the
    number of frames written; ``slice_plane``: see :class:`FramePlot`.  An existing
    ``path`` raises :class:`FileExistsError` (``path: 'a.gif' exists; pass overwrite=True
    ...``) before any frame is drawn, unless ``overwrite``.
    """
    from matplotlib import animation
    from tqdm import tqdm

    from sphjax._paths import check_new

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in MOVIE_SUFFIXES:
        raise ValueError(f"unknown movie extension {suffix!r}; use .gif or .mp4")
    check_new([path], "path", overwrite)
    plot = FramePlot(trajectory, meta, field, frame_numbers=frame_numbers, slice_plane=slice_plane)
    n = len(trajectory)
    if suffix == ".gif":
        writer = animation.PillowWriter(fps=fps)
    else:
        import imageio_ffmpeg
        import matplotlib

        matplotlib.rcParams["animation.ffmpeg_path"] = imageio_ffmpeg.get_ffmpeg_exe()
        writer = animation.FFMpegWriter(
            fps=fps, codec="libx264", extra_args=["-pix_fmt", "yuv420p"]
        )
        # H.264 in yuv420p needs an even number of pixels each way
        dpi = plot.fig.dpi
        w, h = (2 * math.ceil(x * dpi / 2) / dpi for x in plot.fig.get_size_inches())
        plot.fig.set_size_inches(w, h)
    movie = animation.FuncAnimation(plot.fig, plot.set_frame, frames=n, blit=False)
    bar = tqdm(total=n, unit="frame", disable=not progress, desc=path.name)
    try:
        movie.save(path, writer=writer, progress_callback=lambda i, total: bar.update(1))
    finally:
        bar.close()
        plot.close()
    return n
