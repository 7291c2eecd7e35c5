"""The ``sphjax dataset`` subcommand."""

from __future__ import annotations

import argparse
import ast

from sphjax import cases as cases_module
from sphjax.dataset.generate import generate_dataset
from sphjax.dataset.perturb import Perturbation


def _parse_range(text: str, what: str) -> tuple[float, float]:
    try:
        lo, hi = text.split(":")
        return float(lo), float(hi)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} must look like LO:HI, got {text!r}") from None


def _parse_vary(text: str):
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"--vary must look like NAME=LO:HI, got {text!r}")
    name, rng = text.split("=", 1)
    return name.strip(), _parse_range(rng, f"--vary {name}")


def _parse_case_arg(text: str):
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"--case-arg must look like KEY=VALUE, got {text!r}")
    key, value = text.split("=", 1)
    try:
        value = ast.literal_eval(value)
    except (ValueError, SyntaxError):
        pass  # a plain string
    return key.strip(), value


def add_dataset_parser(subparsers) -> argparse.ArgumentParser:
    """Add the ``dataset`` subcommand to an ``argparse`` subparsers object."""
    p = subparsers.add_parser(
        "dataset",
        help="simulate an ensemble and write a LagrangeBench-format dataset",
        description=(
            "Simulate an ensemble of CASE (random initial velocities and --vary'd Params) and "
            "write metadata.json, train.h5, valid.h5, test.h5 to --out."
        ),
    )
    p.add_argument("case", help=f"case name ({', '.join(sorted(cases_module.CASES))})")
    p.add_argument("--out", required=True, help="dataset folder")
    p.add_argument("--n-train", type=int, default=8)
    p.add_argument("--n-valid", type=int, default=2)
    p.add_argument("--n-test", type=int, default=2)
    p.add_argument("--steps", type=int, required=True, help="solver steps per trajectory")
    p.add_argument("--write-every", type=int, default=1, help="solver steps between frames")
    p.add_argument(
        "--vary",
        type=_parse_vary,
        action="append",
        default=[],
        metavar="NAME=LO:HI",
        help="draw Params field NAME uniformly per trajectory",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--case-arg",
        type=_parse_case_arg,
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="keyword argument of the case, e.g. n=32",
    )
    p.add_argument(
        "--amplitude",
        type=lambda s: _parse_range(s, "--amplitude"),
        default=(0.75, 1.25),
        metavar="LO:HI",
        help="range of the scale of the case's velocity field",
    )
    p.add_argument(
        "--fourier",
        type=float,
        default=0.2,
        help="relative size of the random divergence-free velocity field",
    )
    p.add_argument("--modes", type=int, default=2, help="largest wavenumber of that field")
    p.add_argument(
        "--jitter",
        type=float,
        default=0.0,
        help="largest random displacement of fluid particles per axis, in units of dx",
    )
    p.add_argument(
        "--same-case-seed",
        action="store_true",
        help="keep the case's own seed (e.g. the Taylor-Green disorder) for every trajectory",
    )
    p.add_argument("--dt", type=float, default=None, help="solver step (default: stable)")
    p.add_argument(
        "--batch-size",
        type=int,
        default=None,
        help="trajectories per compiled call (default 4 per device)",
    )
    p.add_argument("--resume", action="store_true", help="continue an interrupted folder")
    p.add_argument("--overwrite", action="store_true", help="replace the folder")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=main_dataset)
    return p


def main_dataset(args) -> int:
    """Run the ``dataset`` subcommand from parsed ``args``; report the throughput."""
    from sphjax.cli import UsageError

    case_kwargs = dict(args.case_arg)
    timings: dict = {}
    try:
        case = cases_module.get(args.case, **case_kwargs)
        perturbation = Perturbation(
            tuple(args.amplitude),
            args.fourier,
            args.modes,
            case_seed=not args.same_case_seed,
            jitter=args.jitter,
        )
        out = generate_dataset(
            case,
            args.out,
            n_train=args.n_train,
            n_valid=args.n_valid,
            n_test=args.n_test,
            steps=args.steps,
            write_every=args.write_every,
            vary=dict(args.vary),
            perturbation=perturbation,
            seed=args.seed,
            dt=args.dt,
            batch_size=args.batch_size,
            resume=args.resume,
            overwrite=args.overwrite,
            progress=not args.no_progress,
            case_kwargs=case_kwargs,
            timings=timings,
        )
    except (ValueError, FileExistsError, OSError) as error:
        raise UsageError(None, str(error)) from None
    n, seconds = timings.get("trajectories", 0), timings.get("seconds", 0.0)
    print(
        f"wrote {out}: {n} trajectories simulated in {seconds:.1f} s "
        f"({timings.get('per_minute', 0.0):.1f} trajectories per minute, compilation included)"
    )
    return 0
