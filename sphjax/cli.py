"""Command line interface: ``sphjax <command> ...``.

Minimal version holding only the ``dataset`` subcommand (see :mod:`sphjax.dataset`); the
full CLI adds its subcommands beside it with ``add_dataset_parser(subparsers)``.
"""

from __future__ import annotations

import argparse
import sys

from sphjax.dataset import add_dataset_parser


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="sphjax", description="Differentiable SPH in JAX.")
    subparsers = parser.add_subparsers(dest="command", required=True)
    add_dataset_parser(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
