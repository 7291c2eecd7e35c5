"""The ``sphjax`` command line.

    sphjax cases
    sphjax run taylor_green --n 20 --t-end 0.05 --out tg.h5
    sphjax plot tg.h5 --field velocity --out tg.png
    sphjax animate tg.h5 --field velocity --out tg.gif
    sphjax export tg.h5 --vtk tg_vtk
    sphjax dataset taylor_green --out data --steps 40 --write-every 4

Exit codes: 0 success; 1 the simulation went unstable (the frames written before the
failure stay in the output file); 2 bad input: one line naming the argument and the fix;
141 the reader of the output went away (``sphjax cases | head``), quietly.

This module imports only the standard library at the top: JAX and the solver are imported
by the commands that run something, so ``--help``, ``--version`` and a mistyped command
answer at once.
"""

from __future__ import annotations

import argparse
import ast
import difflib
import math
import os
import sys
from pathlib import Path

EXIT_OK, EXIT_UNSTABLE, EXIT_USAGE = 0, 1, 2
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE, as a Unix tool whose reader has gone
DEFAULT_FRAMES = 100
CHUNK_STEPS = 500  # steps per compiled chunk: the progress bar moves once per chunk


class UsageError(Exception):
    """Bad command-line input; the message starts with the offending argument."""

    def __init__(self, argument: str | None, message: str):
        super().__init__(message if argument is None else f"{argument}: {message}")
        self.argument = argument


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``sphjax run: error: argument --dx: ... (see ...)``."""

    def error(self, message):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


# ---------------------------------------------------------------------------- argument types


def _number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text}")
    return value


def _positive_float(text: str) -> float:
    value = _number(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


def _non_negative_float(text: str) -> float:
    value = _number(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a number >= 0, got {text}")
    return value


def _whole(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None


def _positive_int(text: str) -> int:
    value = _whole(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive whole number, got {text}")
    return value


def _non_negative_int(text: str) -> int:
    value = _whole(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 0, got {text}")
    return value


def _key_value(text: str, example: str) -> tuple[str, str]:
    key, sep, value = text.partition("=")
    if not sep or not key.strip() or not value.strip():
        raise argparse.ArgumentTypeError(f"must look like {example}, got {text!r}")
    return key.strip(), value.strip()


def _set_value(text: str):
    """``FIELD=VALUE`` of ``--set``: a number, or comma-separated numbers for a vector."""
    name, value = _key_value(text, "FIELD=VALUE, e.g. kinematic_viscosity=0.02")
    parts = value.strip("()[] ").split(",")
    try:
        numbers = [float(p) for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{name}={value}: the value must be a number (or comma-separated numbers for a "
            "vector, e.g. gravity=0,-9.81)"
        ) from None
    if not all(math.isfinite(v) for v in numbers):
        raise argparse.ArgumentTypeError(f"{name}={value}: the value must be finite")
    return name, numbers[0] if len(parts) == 1 and "," not in value else tuple(numbers)


def _case_arg(text: str):
    """``KEY=VALUE`` of ``--case-arg``: a Python literal (number, string, tuple, bool)."""
    key, value = _key_value(text, "KEY=VALUE, e.g. young_modulus=5.6e6")
    try:
        return key, ast.literal_eval(value)
    except (ValueError, SyntaxError):
        pass
    try:
        return key, float(value)  # inf, nan: refused by the case argument's check
    except ValueError:
        return key, value  # a plain string, e.g. kernel=wendland_c2


def _range(text: str) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"must look like LO:HI, e.g. 0.5:1.5, got {text!r}"
        ) from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise argparse.ArgumentTypeError(f"needs finite LO <= HI, got {text!r}")
    return lo, hi


def _vary(text: str):
    name, value = _key_value(text, "NAME=LO:HI, e.g. kinematic_viscosity=0.01:0.02")
    try:
        return name, _range(value)
    except argparse.ArgumentTypeError as err:
        raise argparse.ArgumentTypeError(f"{name}: {err}") from None


# ---------------------------------------------------------------------------- the parser


def _version() -> str:
    from sphjax import __version__

    return __version__


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="sphjax",
        description=(
            "Differentiable SPH in JAX: run a case, plot, animate or export a trajectory, "
            "list the cases, generate a learned-surrogate dataset."
        ),
    )
    parser.add_argument("--version", action="version", version=f"sphjax {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    parser.commands = sub.choices  # name -> sub-parser, for "did you mean" on options
    _add_run(sub)
    _add_plot(sub)
    _add_animate(sub)
    _add_export(sub)
    cases = sub.add_parser(
        "cases",
        help="list the available cases, or show one case's arguments and parameters",
        description="List the cases; with a name, show its --case-arg arguments and its "
        "--set parameters with their default values.",
    )
    cases.add_argument("name", metavar="CASE", nargs="?", help="a case to describe")
    _add_dataset(sub)
    return parser


def _add_run(sub) -> None:
    run = sub.add_parser(
        "run",
        help="run a case and write its trajectory to HDF5 (with an XDMF file for ParaView)",
        description=(
            "Run a case, or the set-up a TOML file describes; frames are appended to --out "
            "as the run goes, and an XDMF file beside it (same name, .xdmf) opens the time "
            "series in ParaView."
        ),
    )
    run.add_argument(
        "case",
        metavar="CASE",
        help="case name (see `sphjax cases`) or a set-up file FILE.toml (see docs/setups.md)",
    )
    res = run.add_mutually_exclusive_group()
    res.add_argument("--n", type=_positive_int, help="particles across the case's length")
    res.add_argument(
        "--dx", type=_positive_float, help="particle spacing in m (converted to the nearest n)"
    )
    run.add_argument(
        "--t-end", type=_positive_float, help="simulated end time in s (default: the case's)"
    )
    run.add_argument(
        "--dt", type=_positive_float, help="time step in s (default: the case's stable step)"
    )
    save = run.add_mutually_exclusive_group()
    save.add_argument(
        "--save-every",
        type=_positive_int,
        metavar="STEPS",
        help="save a frame every STEPS steps, and the last one at the end time "
        f"(default: about {DEFAULT_FRAMES} frames)",
    )
    save.add_argument(
        "--save-dt",
        type=_positive_float,
        metavar="SECONDS",
        help="save frames at the multiples of SECONDS (the time step is shortened, if "
        "needed, so that they fall on whole steps)",
    )
    run.add_argument(
        "--set",
        type=_set_value,
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="set a physical parameter (a Params field the case's model reads, listed by "
        "'sphjax cases CASE'), e.g. --set kinematic_viscosity=0.02 "
        "or --set gravity=0,-9.81; repeatable",
    )
    run.add_argument(
        "--case-arg",
        type=_case_arg,
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="keyword argument of the case, e.g. --case-arg young_modulus=5.6e6; repeatable",
    )
    run.add_argument("--out", default="trajectory.h5", help="output HDF5 file")
    run.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    run.add_argument("--float64", action="store_true", help="run in double precision")
    run.add_argument(
        "--pair-loop",
        choices=("xla", "native"),
        default="xla",
        help="'native': pair sums as compiled loops (a fluid's own, each pair once, and "
        "against walls, solids and bodies; an elastic solid's deformation gradient and "
        "momentum, first-order correction) "
        "(CPU only; built with the machine's C++ compiler at first use); see "
        "Model.pair_loop",
    )
    run.add_argument(
        "--neighbor-margin",
        type=float,
        default=None,
        metavar="FRACTION",
        help="room above the largest neighbour count in the lists at the start (default "
        "0.05); more, e.g. 0.5, for a flow that crowds its particles, when the run notes "
        "re-allocations (each one more compilation); see Model.neighbor_margin",
    )
    run.add_argument("--quiet", action="store_true", help="no progress bar")


_SLICE_HELP = (
    "3D trajectories: draw only the particles within one kernel support of a plane, e.g. "
    "z=0.5 (default: a side view, the vertical axis against gravity and the view along the "
    "shorter horizontal extent, e.g. x-z for gravity along -z; x-y without gravity)"
)


def _slice_plane(args):
    """``--slice AXIS=VALUE`` as ``(axis, value)``, or ``None``."""
    from sphjax.plot import parse_slice

    if args.slice is None:
        return None
    try:
        return parse_slice(args.slice)
    except ValueError as err:
        raise UsageError("--slice", str(err)) from None


def _plot_error(err: ValueError) -> UsageError:
    """The option a FramePlot error is about (a field or a slice)."""
    flag = "--field" if str(err).startswith("unknown field") else "--slice"
    return UsageError(flag, str(err))


def _add_plot(sub) -> None:
    plot = sub.add_parser(
        "plot",
        help="draw the particles of one saved frame coloured by a field",
        description="Draw one frame of a trajectory file as an image (PNG, PDF, SVG, ...).",
    )
    plot.add_argument("file", metavar="FILE.h5", help="trajectory written by `sphjax run`")
    plot.add_argument("--frame", type=_whole, default=-1, help="frame index (default: last)")
    plot.add_argument(
        "--field",
        default="velocity",
        help="State field to colour by; vector fields are drawn by magnitude, `kind` by "
        "particle type",
    )
    plot.add_argument("--out", required=True, help="output image, e.g. frame.png")
    plot.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    plot.add_argument("--slice", metavar="AXIS=VALUE", default=None, help=_SLICE_HELP)


def _add_animate(sub) -> None:
    animate = sub.add_parser(
        "animate",
        help="write an animation (GIF or MP4) of a trajectory",
        description="Animate every saved frame of a trajectory file into a GIF or MP4.",
    )
    animate.add_argument("file", metavar="FILE.h5", help="trajectory written by `sphjax run`")
    animate.add_argument("--field", default="velocity", help="State field to colour by")
    animate.add_argument("--out", required=True, help="output movie: movie.gif or movie.mp4")
    animate.add_argument("--fps", type=_positive_int, default=20, help="frames per second")
    animate.add_argument(
        "--every", type=_positive_int, default=1, help="use every EVERY-th saved frame"
    )
    animate.add_argument("--slice", metavar="AXIS=VALUE", default=None, help=_SLICE_HELP)
    animate.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    animate.add_argument("--quiet", action="store_true", help="no progress bar")


def _add_export(sub) -> None:
    export = sub.add_parser(
        "export",
        help="export a trajectory to VTK for ParaView (one .vtu per frame and a .pvd)",
        description=(
            "Write one VTK unstructured-grid file (.vtu) per frame with every field, and a "
            ".pvd collection that ParaView opens as a time series."
        ),
    )
    export.add_argument("file", metavar="FILE.h5", help="trajectory written by `sphjax run`")
    export.add_argument("--vtk", required=True, metavar="DIR", help="output folder")
    export.add_argument("--overwrite", action="store_true", help="write into a non-empty DIR")


def _add_dataset(sub) -> None:
    p = sub.add_parser(
        "dataset",
        help="simulate an ensemble and write a LagrangeBench-format dataset",
        description=(
            "Simulate an ensemble of CASE (random initial velocities and --vary'd Params) and "
            "write metadata.json, train.h5, valid.h5, test.h5 to --out."
        ),
    )
    p.add_argument("case", metavar="CASE", help="case name (see `sphjax cases`)")
    p.add_argument("--out", required=True, help="dataset folder")
    p.add_argument("--n-train", type=_positive_int, default=8, help="training trajectories")
    p.add_argument("--n-valid", type=_non_negative_int, default=2, help="validation trajectories")
    p.add_argument("--n-test", type=_non_negative_int, default=2, help="test trajectories")
    p.add_argument("--steps", type=_positive_int, required=True, help="solver steps per run")
    p.add_argument(
        "--write-every", type=_positive_int, default=1, help="solver steps between frames"
    )
    p.add_argument(
        "--vary",
        type=_vary,
        action="append",
        default=[],
        metavar="NAME=LO:HI",
        help="draw Params field NAME uniformly per trajectory",
    )
    p.add_argument("--seed", type=_whole, default=0, help="base random seed")
    p.add_argument(
        "--case-arg",
        type=_case_arg,
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="keyword argument of the case, e.g. n=32",
    )
    p.add_argument(
        "--amplitude",
        type=_range,
        default=(0.75, 1.25),
        metavar="LO:HI",
        help="range of the scale of the case's velocity field (0 <= LO <= HI)",
    )
    p.add_argument(
        "--fourier",
        type=_non_negative_float,
        default=0.2,
        help="relative size of the random divergence-free velocity field",
    )
    p.add_argument("--modes", type=_positive_int, default=2, help="largest wavenumber of it")
    p.add_argument(
        "--jitter",
        type=_non_negative_float,
        default=0.0,
        help="largest random displacement of fluid particles per axis, in units of dx",
    )
    p.add_argument(
        "--same-case-seed",
        action="store_true",
        help="keep the case's own seed (e.g. the Taylor-Green disorder) for every trajectory",
    )
    p.add_argument(
        "--dt",
        type=_positive_float,
        default=None,
        help="solver step (default: the stable step of the fastest start the perturbation "
        "and --vary ranges allow, the same for every --seed)",
    )
    p.add_argument(
        "--batch-size",
        type=_positive_int,
        default=None,
        help="trajectories per compiled call (default 4 per device)",
    )
    p.add_argument("--resume", action="store_true", help="continue an interrupted folder")
    p.add_argument("--overwrite", action="store_true", help="replace the folder")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


# ---------------------------------------------------------------------------- shared checks


def _output_file(path, argument: str, overwrite: bool, suffixes=None) -> Path:
    """Check an output file before any work: writable, suffix known, not silently replaced."""
    from sphjax._paths import check_writable, exists_message

    try:
        out = check_writable(path, argument)
    except ValueError as err:
        raise UsageError(None, str(err)) from None
    if suffixes is not None and out.suffix.lower() not in suffixes:
        raise UsageError(
            argument,
            f"'{out}' has an unknown extension {out.suffix or '(none)'!r}; use one of "
            f"{', '.join(sorted(suffixes))}",
        )
    if out.exists() and not overwrite:
        raise UsageError(argument, exists_message(out, argument))
    return out


def _trajectory_metadata(path) -> dict:
    """The metadata of a trajectory file, or a UsageError naming FILE.h5."""
    from sphjax.io import read_metadata

    try:
        meta = read_metadata(path)
    except (FileNotFoundError, ValueError) as err:
        raise UsageError("FILE.h5", str(err)) from None
    if meta["n_frames"] == 0:
        raise UsageError("FILE.h5", f"'{path}' holds no frames (the run stopped before the first)")
    return meta


def _read_frames(path, frames=None):
    """``read_trajectory`` with damaged files reported as bad input."""
    from sphjax.io import FileLockedError, read_trajectory

    try:
        return read_trajectory(path, frames=frames)
    except FileLockedError as err:  # in use, not damaged
        raise UsageError("FILE.h5", str(err)) from None
    except (FileNotFoundError, ValueError, OSError, KeyError, RuntimeError) as err:
        raise UsageError(
            "FILE.h5", f"cannot read the frames of '{path}' (the file is damaged?): {err}"
        ) from None


# ---------------------------------------------------------------------------- cases


def _summary(factory) -> str:
    """First sentence of a case's docstring, without reST markup."""
    doc = " ".join((factory.__doc__ or "").strip().split("\n\n")[0].split())
    doc = doc.replace("``", "")
    for end in (". ", ":"):
        if end in doc:
            doc = doc[: doc.index(end) + 1].rstrip(":")
            break
    return doc


def _argument_doc(factory, name: str) -> str:
    """The first sentence of argument ``name``'s entry in a case's docstring."""
    lines = (factory.__doc__ or "").splitlines()
    for i, line in enumerate(lines):
        if line.strip().startswith(f"{name}:"):
            indent = len(line) - len(line.lstrip())
            text = [line.strip()[len(name) + 1 :]]
            for more in lines[i + 1 :]:
                if not more.strip() or len(more) - len(more.lstrip()) <= indent:
                    break
                text.append(more.strip())
            doc = " ".join(" ".join(text).split()).replace("``", "")
            return doc[: doc.index(". ") + 1] if ". " in doc else doc
    return ""


def cmd_cases(args) -> int:
    from sphjax.cases import CASES

    if args.name is None:
        width = max(len(name) for name in CASES)
        for name, factory in CASES.items():
            print(f"{name:<{width}}  {_summary(factory)}")
        return EXIT_OK
    import inspect

    import numpy as np

    from sphjax._cli_run import build_case

    case = build_case(args.name, {})
    factory = CASES[args.name]
    print(f"{args.name}: {_summary(factory)}")
    counts = _argument_doc(factory, "n")
    if counts:
        print(
            f"--n counts {counts.rstrip('.')}; default n = {case.info.get('n', '?')}: dx = "
            f"{case.info.get('dx', float('nan')):.4g}, {case.n_particles} particles"
        )
    print("case arguments (--case-arg KEY=VALUE):")
    for key, parameter in inspect.signature(factory).parameters.items():
        print(f"  {key} = {parameter.default!r}")
    print("parameters (--set FIELD=VALUE), as the case sets them (those its model reads):")
    for name, value in case.params.items(used_only=True):
        value = np.asarray(value)
        shown = ",".join(f"{v:g}" for v in value.ravel()) if value.ndim else f"{float(value):g}"
        print(f"  {name} = {shown}")
    return EXIT_OK


# ---------------------------------------------------------------------------- run


def _compilation_cache() -> None:
    """JAX's persistent compilation cache on (sphjax._compile), before anything compiles."""
    from sphjax._compile import enable_compilation_cache

    _, note = enable_compilation_cache()
    if note:
        print(note, file=sys.stderr)


def cmd_run(args) -> int:
    from sphjax._paths import exists_message
    from sphjax.xdmf import xdmf_path

    out = _output_file(args.out, "--out", args.overwrite, {".h5", ".hdf5"})
    if xdmf_path(out).exists() and not args.overwrite:  # the run writes its description too
        raise UsageError("--out", exists_message(xdmf_path(out), "--out"))
    _compilation_cache()
    if args.float64:
        import jax

        with jax.enable_x64(True):
            return _run(args, out)
    return _run(args, out)


def _run(args, out: Path) -> int:
    from sphjax._cli_run import run_case

    return run_case(args, out)


# ---------------------------------------------------------------------------- plot, animate


def cmd_plot(args) -> int:
    from sphjax.plot import IMAGE_SUFFIXES, FramePlot

    out = _output_file(args.out, "--out", args.overwrite, IMAGE_SUFFIXES)
    meta = _trajectory_metadata(args.file)
    n = meta["n_frames"]
    if not -n <= args.frame < n:
        raise UsageError("--frame", f"{args.frame} is out of range; the file holds {n} frames")
    plane = _slice_plane(args)
    # by its number: a run in progress may have written more frames since
    trajectory, _ = _read_frames(args.file, frames=args.frame % n)
    try:
        figure = FramePlot(
            trajectory, meta, args.field, frame_offset=args.frame % n, slice_plane=plane
        )
    except ValueError as err:
        raise _plot_error(err) from None
    try:
        figure.save(out, overwrite=args.overwrite)
    except OSError as err:
        raise UsageError("--out", f"cannot write '{out}': {err}") from None
    finally:
        figure.close()
    print(f"wrote {out}", file=sys.stderr)
    return EXIT_OK


def cmd_animate(args) -> int:
    from sphjax.plot import MOVIE_SUFFIXES, animate

    out = _output_file(args.out, "--out", args.overwrite, MOVIE_SUFFIXES)
    meta = _trajectory_metadata(args.file)
    n = meta["n_frames"]
    if n < 2:
        raise UsageError(
            "FILE.h5", f"'{args.file}' holds one frame; an animation needs two or more "
            "(draw the frame with 'sphjax plot', or save more frames with 'sphjax run')"
        )  # fmt: skip
    if len(range(0, n, args.every)) < 2:
        raise UsageError(
            "--every", f"{args.every} leaves 1 of the {n} saved frames; an animation needs two "
            f"or more: use --every {n - 1} or less"
        )  # fmt: skip
    plane = _slice_plane(args)
    trajectory, _ = _read_frames(args.file, frames=slice(0, meta["n_frames"], args.every))
    try:
        n = animate(
            trajectory, meta, args.field, out, fps=args.fps, progress=not args.quiet,
            frame_numbers=range(0, meta["n_frames"], args.every), slice_plane=plane,
            overwrite=args.overwrite,
        )  # fmt: skip
    except ValueError as err:
        raise _plot_error(err) from None
    except OSError as err:
        raise UsageError("--out", f"cannot write '{out}': {err}") from None
    print(f"wrote {out} ({n} frames)", file=sys.stderr)
    return EXIT_OK


# ---------------------------------------------------------------------------- export


def cmd_export(args) -> int:
    from sphjax.vtk_export import export_vtk

    folder = Path(args.vtk)
    if folder.exists() and not folder.is_dir():
        raise UsageError("--vtk", f"'{folder}' is a file; give a folder name")
    if folder.is_dir() and any(folder.iterdir()) and not args.overwrite:
        raise UsageError(
            "--vtk", f"'{folder}' is not empty; pass --overwrite or choose another folder"
        )
    if not folder.parent.is_dir():
        raise UsageError(
            "--vtk", f"cannot create '{folder}': '{folder.parent}' does not exist (mkdir -p it)"
        )
    _trajectory_metadata(args.file)
    trajectory, _ = _read_frames(args.file)
    try:
        pvd = export_vtk(trajectory, folder, name=Path(args.file).stem, overwrite=args.overwrite)
    except OSError as err:
        raise UsageError("--vtk", f"cannot write into '{folder}': {err}") from None
    print(f"wrote {len(trajectory)} frames and {pvd}", file=sys.stderr)
    return EXIT_OK


# ---------------------------------------------------------------------------- dataset


def cmd_dataset(args) -> int:
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError("--out", f"'{out}' is a file; give a folder name")
    if out.is_dir() and any(out.iterdir()) and not (args.overwrite or args.resume):
        incomplete = (out / "INCOMPLETE").exists()
        what = "an incomplete dataset; pass --resume to continue it or" if incomplete else "files;"
        raise UsageError(
            "--out", f"'{out}' holds {what} pass --overwrite to replace it, or choose a new folder"
        )
    if args.resume and not args.overwrite and out.is_dir() and any(out.iterdir()):
        if not (out / "INCOMPLETE").exists():
            raise UsageError(
                "--resume",
                f"'{out}' holds no interrupted dataset to continue; pass --overwrite to "
                "replace what it holds, or choose a new folder",
            )
    if not out.parent.is_dir() or not os.access(out.parent, os.W_OK):
        raise UsageError("--out", f"cannot create '{out}': '{out.parent}' is not a writable folder")
    if args.steps % args.write_every or args.steps < 2 * args.write_every:
        n = args.steps // args.write_every * args.write_every
        raise UsageError(
            "--write-every",
            f"{args.write_every} must divide --steps {args.steps} and give at least 3 frames "
            f"(--steps >= 2 x --write-every); e.g. --steps {max(n, 2 * args.write_every)}",
        )
    _compilation_cache()
    from sphjax._cli_run import build_case

    case = build_case(args.case, dict(args.case_arg))
    from sphjax.dataset import Perturbation, check_vary, generate_dataset

    try:
        vary = check_vary(case.params, dict(args.vary))
    except ValueError as err:
        raise UsageError("--vary", str(err).removeprefix("vary: ")) from None
    try:
        perturbation = Perturbation(
            tuple(args.amplitude),
            args.fourier,
            args.modes,
            case_seed=not args.same_case_seed,
            jitter=args.jitter,
        )
    except ValueError as err:
        raise UsageError("--amplitude", str(err)) from None
    timings: dict = {}
    try:
        out = generate_dataset(
            case,
            out,
            n_train=args.n_train,
            n_valid=args.n_valid,
            n_test=args.n_test,
            steps=args.steps,
            write_every=args.write_every,
            vary=vary,
            perturbation=perturbation,
            seed=args.seed,
            dt=args.dt,
            batch_size=args.batch_size,
            resume=args.resume,
            overwrite=args.overwrite,
            progress=not args.no_progress,
            case_kwargs=dict(args.case_arg),
            timings=timings,
        )
    except (ValueError, FileExistsError) as err:
        argument = "--dt" if args.dt is not None and "dt" in str(err) else "--out"
        raise UsageError(argument, str(err).removeprefix("out: ")) from None
    except RuntimeError as err:  # a trajectory went unstable
        print(f"sphjax dataset: error: {err}", file=sys.stderr)
        return EXIT_UNSTABLE
    n, seconds = timings.get("trajectories", 0), timings.get("seconds", 0.0)
    compiling, per_minute = timings.get("compile_seconds", 0.0), timings.get("per_minute")
    rate = f"{per_minute:.3g}" if per_minute is not None and math.isfinite(per_minute) else "?"
    print(
        f"wrote {out}: {n} trajectories simulated in {seconds:.2f} s wall "
        f"({compiling:.2f} s compiling), {rate} trajectories per minute after compilation"
    )
    return EXIT_OK


# ---------------------------------------------------------------------------- main


COMMANDS = {
    "run": cmd_run,
    "plot": cmd_plot,
    "animate": cmd_animate,
    "export": cmd_export,
    "cases": cmd_cases,
    "dataset": cmd_dataset,
}


def _unknown_command(argv: list[str]) -> str | None:
    """A one-line answer to a mistyped command (argparse lists the choices only)."""
    first = next((a for a in argv if not a.startswith("-")), None)
    if first is None or first in COMMANDS or argv[: argv.index(first)]:
        return None
    close = difflib.get_close_matches(first, COMMANDS, n=1)
    hint = f"did you mean '{close[0]}'? " if close else ""
    return f"sphjax: error: unknown command {first!r}; {hint}choose one of {', '.join(COMMANDS)}"


def _unknown_options(parser, command: str, unknown: list[str]) -> str:
    """One line for arguments the command does not take, with the closest options."""
    sub = parser.commands[command]
    options = [o for action in sub._actions for o in action.option_strings if o.startswith("--")]
    first = unknown[0]
    if first.startswith("-"):
        flag = first.split("=", 1)[0]
        close = difflib.get_close_matches(flag, options, n=1, cutoff=0.6)
        hint = f"did you mean {close[0]}? " if close else ""
        what = f"unknown option {flag}; {hint}"
    else:
        what = f"unexpected argument {first!r}; "
    return f"sphjax {command}: error: {what}see 'sphjax {command} --help'"


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``sphjax`` command; returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    message = _unknown_command(argv)
    if message:
        print(message, file=sys.stderr)
        return EXIT_USAGE
    parser = _parser()
    try:
        args, unknown = parser.parse_known_args(argv)
    except SystemExit as exit_:  # argparse has printed its message (or --help, --version)
        return exit_.code if isinstance(exit_.code, int) else EXIT_USAGE
    if unknown:
        print(_unknown_options(parser, args.command, unknown), file=sys.stderr)
        return EXIT_USAGE
    args.argv = argv
    try:
        code = COMMANDS[args.command](args)
        sys.stdout.flush()  # here, so that a closed pipe is caught below
        return code
    except UsageError as err:
        print(f"sphjax {args.command}: error: {err}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"sphjax {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `sphjax cases | head`: the reader has all it wanted
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # so the flush at exit finds no closed pipe
        return EXIT_BROKEN_PIPE


if __name__ == "__main__":
    sys.exit(main())
