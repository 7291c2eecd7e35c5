"""The ``sphjax`` command line: run a case to HDF5, plot a frame, list the cases.

    sphjax cases
    sphjax run taylor_green --n 20 --t-end 0.05 --out tg.h5
    sphjax plot tg.h5 --field velocity --out tg.png

Exit codes: 0 success; 1 the simulation went unstable (the frames written before the
failure stay in the output file); 2 bad input (the message names the argument).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import sys
import time
from pathlib import Path

EXIT_OK, EXIT_UNSTABLE, EXIT_USAGE = 0, 1, 2
DEFAULT_MAX_FRAMES = 100
CHUNK_STEPS = 500  # steps per compiled chunk: the progress bar moves once per chunk


class UsageError(Exception):
    """Bad command-line input; the message starts with the offending argument."""

    def __init__(self, argument: str | None, message: str):
        super().__init__(message if argument is None else f"{argument}: {message}")
        self.argument = argument


# ---------------------------------------------------------------------------- argument types


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive whole number, got {text}")
    return value


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="sphjax",
        description=(
            "Differentiable SPH in JAX: run a case, plot a saved frame, list cases, "
            "generate a learned-surrogate dataset."
        ),
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    run = sub.add_parser(
        "run",
        help="run a case and write its trajectory to HDF5",
        description="Run a case; frames are appended to --out as the run goes.",
    )
    run.add_argument("case", metavar="CASE", help="case name (see `sphjax cases`)")
    res = run.add_mutually_exclusive_group()
    res.add_argument("--n", type=_positive_int, help="particles across the case's length")
    res.add_argument(
        "--dx", type=_positive_float, help="particle spacing (converted to the nearest n)"
    )
    run.add_argument(
        "--t-end", type=_positive_float, help="simulated end time (default: the case's)"
    )
    run.add_argument(
        "--dt", type=_positive_float, help="time step (default: the case's stable step)"
    )
    run.add_argument(
        "--save-every",
        type=_positive_int,
        help=f"steps between saved frames; must divide the number of steps "
        f"(default: about {DEFAULT_MAX_FRAMES} frames)",
    )
    run.add_argument("--out", default="trajectory.h5", help="output HDF5 file")
    run.add_argument("--float64", action="store_true", help="run in double precision")
    run.add_argument("--quiet", action="store_true", help="no progress bar")

    plot = sub.add_parser(
        "plot",
        help="draw the particles of one saved frame coloured by a field",
        description="Draw one frame of a trajectory file as a PNG.",
    )
    plot.add_argument("file", metavar="FILE.h5", help="trajectory written by `sphjax run`")
    plot.add_argument("--frame", type=int, default=-1, help="frame index (default: last)")
    plot.add_argument(
        "--field",
        default="velocity",
        help="State field to colour by; vector fields are drawn by magnitude",
    )
    plot.add_argument("--out", required=True, help="output image, e.g. frame.png")

    sub.add_parser("cases", help="list the available cases", description="List the cases.")

    from sphjax.dataset import add_dataset_parser

    add_dataset_parser(sub)
    return parser


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


def cmd_cases(args) -> int:
    from sphjax.cases import CASES

    width = max(len(name) for name in CASES)
    for name, factory in CASES.items():
        print(f"{name:<{width}}  {_summary(factory)}")
    return EXIT_OK


# ---------------------------------------------------------------------------- run


def _divisors(n: int) -> list[int]:
    small = [d for d in range(1, math.isqrt(n) + 1) if n % d == 0]
    return sorted(set(small + [n // d for d in small]))


def _default_save_every(n_steps: int) -> int:
    """The smallest divisor of ``n_steps`` that saves at most DEFAULT_MAX_FRAMES frames."""
    return next(d for d in _divisors(n_steps) if n_steps // d <= DEFAULT_MAX_FRAMES)


def _frames_per_chunk(n_frames: int, save_every: int) -> int:
    """A divisor of ``n_frames`` so every chunk has the same length (one compilation)."""
    fitting = [d for d in _divisors(n_frames) if d * save_every <= CHUNK_STEPS]
    return max(fitting) if fitting else 1


def _build_case(args):
    from sphjax import cases

    if args.case not in cases.CASES:
        raise UsageError(
            "CASE", f"unknown case {args.case!r}; available cases: {', '.join(cases.CASES)}"
        )
    kwargs = {}
    if args.n is not None:
        kwargs["n"] = args.n
    if args.t_end is not None:
        kwargs["t_end"] = args.t_end
    try:
        if args.dx is not None:
            return cases.get(args.case, dx=args.dx, **kwargs)
        return cases.get(args.case, **kwargs)
    except ValueError as err:
        argument = "--dx" if args.dx is not None else "--n" if args.n is not None else "CASE"
        raise UsageError(argument, str(err)) from None


def _plan(case, args) -> tuple[float, int, int]:
    """Time step, number of steps and save interval, checked before anything runs."""
    from sphjax.integration.timestep import check_time_step

    dt = case.dt if args.dt is None else args.dt
    if args.dt is not None:
        try:
            check_time_step(dt, case.state, case.model, case.params)
        except ValueError as err:
            raise UsageError("--dt", str(err)) from None
    t_end = case.t_end if args.t_end is None else args.t_end
    n_steps = max(1, int(math.ceil(t_end / dt - 1e-9)))  # the rule of sphjax.simulate
    save_every = _default_save_every(n_steps) if args.save_every is None else args.save_every
    if n_steps % save_every:
        options = [d for d in _divisors(n_steps) if d <= max(save_every * 4, 10)][-6:]
        raise UsageError(
            "--save-every",
            f"{save_every} does not divide the {n_steps} steps of this run "
            f"(t-end {t_end:g} / dt {dt:.4g}); use a divisor of {n_steps}, "
            f"e.g. {', '.join(map(str, options))}, or change --t-end",
        )
    return dt, n_steps, save_every


def cmd_run(args) -> int:
    from sphjax.io import check_writable

    try:
        out = check_writable(args.out, "--out")  # before any work
    except ValueError as err:
        raise UsageError(None, str(err)) from None
    if args.float64:
        import jax

        precision = jax.enable_x64(True)
    else:
        precision = contextlib.nullcontext()
    with precision:
        return _run(args, out)


def _run(args, out: Path) -> int:
    from tqdm import tqdm

    from sphjax.integration.simulate import NeighborOverflowError, SimulationError, simulate
    from sphjax.io import TrajectoryWriter

    case = _build_case(args)
    dt, n_steps, save_every = _plan(case, args)
    n_frames = n_steps // save_every
    chunk = _frames_per_chunk(n_frames, save_every) * save_every
    dx = case.info.get("dx", float("nan"))
    print(
        f"{case.name}: {case.n_particles} particles (dx = {dx:.4g}), "
        f"{n_steps} steps of dt = {dt:.4g} to t = {n_steps * dt:.4g}, "
        f"saving every {save_every} steps ({n_frames + 1} frames) to {out}",
        file=sys.stderr,
    )
    attrs = {"command": ["sphjax", *args.argv], "n_steps": n_steps, "save_every": save_every}
    bar = tqdm(total=n_steps, unit="step", disable=args.quiet, file=sys.stderr)
    start = time.perf_counter()
    first_chunk_end = []

    def progress(n):
        if not first_chunk_end:
            first_chunk_end.append((time.perf_counter(), n))
        bar.update(n)

    with TrajectoryWriter(out, case, dt=dt, attrs=attrs, argument="--out") as writer:
        try:
            simulate(
                case, dt=dt, n_steps=n_steps, save_every=save_every, on_frames=writer,
                progress=progress, steps_per_chunk=chunk,
            )  # fmt: skip
        except SimulationError as err:
            bar.close()
            writer.set_error(str(err))
            print(
                f"sphjax run: error: {err}\nstopped at step {err.step}, particle "
                f"{err.particle}; the {writer.n_frames} frames before it are in {out}. "
                "Try a smaller --dt.",
                file=sys.stderr,
            )
            return EXIT_UNSTABLE
        except NeighborOverflowError as err:
            bar.close()
            writer.set_error(str(err))
            print(
                f"sphjax run: error: {err}\nthe {writer.n_frames} frames before it are in {out}.",
                file=sys.stderr,
            )
            return EXIT_UNSTABLE
    bar.close()
    wall = time.perf_counter() - start
    rate = case.n_particles * n_steps / wall
    lines = [
        f"done: {case.n_particles} particles, {n_steps} steps, {wall:.2f} s wall, "
        f"{rate:.3g} particle-steps/s",
    ]
    if first_chunk_end and first_chunk_end[0][1] < n_steps:
        t1, n1 = first_chunk_end[0]
        steady = case.n_particles * (n_steps - n1) / (time.perf_counter() - t1)
        lines.append(f"      {steady:.3g} particle-steps/s after the first chunk (compilation)")
    lines.append(f"      {writer.n_frames} frames in {out}")
    print("\n".join(lines))
    return EXIT_OK


# ---------------------------------------------------------------------------- plot


def cmd_plot(args) -> int:
    import numpy as np

    from sphjax.core.state import Kind
    from sphjax.io import check_writable, read_metadata, read_trajectory

    try:
        out = check_writable(args.out, "--out")
    except ValueError as err:
        raise UsageError(None, str(err)) from None
    try:
        meta = read_metadata(args.file)
    except (FileNotFoundError, ValueError) as err:
        raise UsageError("FILE.h5", str(err)) from None
    n = meta["n_frames"]
    if n == 0:
        raise UsageError("FILE.h5", f"'{args.file}' holds no frames")
    if not -n <= args.frame < n:
        raise UsageError("--frame", f"{args.frame} is out of range; the file holds {n} frames")
    trajectory, _ = read_trajectory(args.file, frames=args.frame)
    state = trajectory.frame(0)
    fields = [f for f in vars(type(state))["__dataclass_fields__"] if f != "time"]
    if args.field not in fields:
        raise UsageError("--field", f"unknown field {args.field!r}; choose one of {fields}")
    values = np.asarray(getattr(state, args.field), dtype=float)
    label = args.field
    if values.ndim == 2:
        values, label = np.linalg.norm(values, axis=-1), f"|{args.field}|"
    position = np.asarray(state.position, dtype=float)
    kind = np.asarray(state.kind)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    model = meta.get("model", {})
    domain = model.get("domain")
    fig, ax = plt.subplots(figsize=(6, 5), dpi=120)
    lo, hi = position.min(axis=0)[:2], position.max(axis=0)[:2]
    if domain and all(math.isfinite(float(v)) for v in domain["lower"] + domain["upper"]):
        lo = np.minimum(lo, domain["lower"][:2])
        hi = np.maximum(hi, domain["upper"][:2])
    extent = float(max(hi - lo))
    size = max(0.5, min(40.0, (300.0 / max(extent, 1e-30)) ** 2 * _spacing(meta, extent) ** 2))
    wall = kind == Kind.WALL if args.field != "kind" else np.zeros_like(kind, bool)
    if wall.any():
        ax.scatter(*position[wall, :2].T, s=size, c="0.75", marker="s", linewidths=0)
    points = ax.scatter(*position[~wall, :2].T, s=size, c=values[~wall], cmap="viridis",
                        linewidths=0)  # fmt: skip
    fig.colorbar(points, ax=ax, label=label)
    ax.set_aspect("equal")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    frame = args.frame % n
    ax.set_title(f"{meta.get('case', '?')}  frame {frame}/{n - 1}  t = {float(state.time):.4g}")
    if position.shape[1] == 3:
        ax.set_title(ax.get_title() + "  (x-y projection)")
    fig.tight_layout()
    try:
        fig.savefig(out)
    except OSError as err:
        raise UsageError("--out", f"cannot write '{out}': {err}") from None
    finally:
        plt.close(fig)
    print(f"wrote {out}", file=sys.stderr)
    return EXIT_OK


def _spacing(meta, extent) -> float:
    dx = meta.get("case_info", {}).get("dx")
    return float(dx) if dx else extent / 50.0


# ---------------------------------------------------------------------------- main


def cmd_dataset(args) -> int:
    from sphjax.dataset import main_dataset

    return main_dataset(args)


COMMANDS = {"run": cmd_run, "plot": cmd_plot, "cases": cmd_cases, "dataset": cmd_dataset}


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``sphjax`` command; returns the exit code."""
    parser = _parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:  # argparse has printed its message (or --help)
        return exit_.code if isinstance(exit_.code, int) else EXIT_USAGE
    args.argv = list(sys.argv[1:] if argv is None else argv)
    try:
        return COMMANDS[args.command](args)
    except UsageError as err:
        print(f"sphjax {args.command}: error: {err}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"sphjax {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
