"""Cost of each pair sum of a case's right-hand side, forward and reverse.

    python benchmarks/pair_costs.py                      # Taylor-Green 10k, dam break, plate
    python benchmarks/pair_costs.py --case dam_break --n 40

Every pair sum that one evaluation of the case's right-hand side makes is recorded (its
summand, fields, list and parameters) and then timed on its own, float32, compiled, in
CPU-milliseconds of this process (best of ``--repeat``): the forward, and the forward
and reverse together (``jax.vjp`` and its pull-back of a unit cotangent), with the pair
sums' custom adjoint (``adjoint``, also for summands marked
:func:`~sphjax.physics.pairs.transpose_by_autodiff`) and with autodiff's transpose
(``autodiff``), and which of the two the package uses (``chosen``).  Beside
them, XLA's temporary memory for the reverse pass per neighbour slot of the list
(``temp bytes per slot``: the per-pair arrays it keeps; a block of ``pair_block`` rows at
a time for the custom adjoint).  A benchmark reports; it asserts nothing.
"""

from __future__ import annotations

import argparse
import functools
import time

import jax
import jax.numpy as jnp

import sphjax
from sphjax.physics import pairs as pair_module
from sphjax.physics import rhs

DEFAULT = (("taylor_green", 100), ("dam_break", 40), ("oscillating_plate", 16))


def _name(f) -> str:
    func = f.func if isinstance(f, functools.partial) else f
    return func.__name__.strip("_")


def record_pair_sums(case):
    """The pair sums one right-hand-side evaluation of ``case`` makes, as keyword sets."""
    model, params = case.model, case.params
    with jax.ensure_compile_time_eval():
        neighbors = rhs.build_neighbors(case.state, model, compact_rows=False, margin=None)
    from sphjax.integration.simulate import _with_reference

    neighbors = _with_reference(case.state, neighbors, model)
    calls = []
    original = pair_module.pair_sum

    def recording(f, rows, cols, pairs, geometry, shared=(), **options):
        calls.append(
            dict(
                f=f, rows=rows, cols=cols, pairs=pairs, geometry=geometry, shared=shared, **options
            )
        )
        return original(f, rows, cols, pairs, geometry, shared, **options)

    pair_module.pair_sum = recording
    try:  # the right-hand side traced here, op by op, so that the calls hold its arrays
        dt = jnp.asarray(case.dt, case.state.position.dtype)
        rhs._evaluate(case.state, neighbors, model, params, density_step=dt)
    finally:
        pair_module.pair_sum = original
    return calls


def _cpu_ms(compiled, args, repeat):
    jax.block_until_ready(compiled(*args))
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        jax.block_until_ready(compiled(*args))
        best = min(best, time.process_time() - t0)
    return 1e3 * best


def time_call(call, adjoint: bool, repeat: int):
    """CPU-ms of the forward and of forward + reverse, and the reverse's temporary bytes;
    ``adjoint``: the custom adjoint, also for a summand marked ``transpose_by_autodiff``."""
    f = call["f"]
    func = f.func if isinstance(f, functools.partial) else f
    marked = getattr(func, "transpose_by_autodiff", False)
    func.transpose_by_autodiff = False if adjoint else marked
    try:
        return _time_call(call, adjoint, repeat)
    finally:
        func.transpose_by_autodiff = marked


def _time_call(call, adjoint: bool, repeat: int):
    options = {
        k: v
        for k, v in call.items()
        if k not in ("f", "rows", "cols", "pairs", "geometry", "shared")
    }
    options["adjoint"] = adjoint

    def forward(rows, cols, shared):
        return pair_module.pair_sum(
            call["f"], rows, cols, call["pairs"], call["geometry"], shared, **options
        )

    def reverse(rows, cols, shared):
        out, pull = jax.vjp(forward, rows, cols, shared)
        return pull(jax.tree_util.tree_map(jnp.ones_like, out))

    args = (call["rows"], call["cols"], call["shared"])
    fwd = jax.jit(forward).lower(*args).compile()
    rev = jax.jit(reverse).lower(*args).compile()
    memory = rev.memory_analysis()
    temp = getattr(memory, "temp_size_in_bytes", 0) if memory is not None else 0
    return _cpu_ms(fwd, args, repeat), _cpu_ms(rev, args, repeat), temp


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", default=None, help="one case (default: three)")
    parser.add_argument("--n", type=int, default=None, help="the case's n")
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args(argv)
    runs = DEFAULT if args.case is None else ((args.case, args.n or 20),)
    print(
        f"{'case':>18} {'pair sum':>28} {'slots':>9} {'fwd ms':>7} "
        f"{'adjoint':>8} {'ratio':>6} {'autodiff':>9} {'ratio':>6} {'temp B/slot':>11} "
        f"{'chosen':>8}"
    )
    for name, n in runs:
        case = sphjax.cases.get(name, n=n)
        for call in record_pair_sums(case):
            idx = call["pairs"].idx
            slots = idx.shape[0] * idx.shape[1]
            fwd, rev, temp = time_call(call, True, args.repeat)
            _, rev_auto, _ = time_call(call, False, args.repeat)
            block = case.model.pair_block or idx.shape[0]
            per_slot = temp / (min(block, idx.shape[0]) * idx.shape[1])
            chosen = "autodiff" if pair_module._autodiff_transposes(call["f"]) else "adjoint"
            print(
                f"{name:>18} {_name(call['f']):>28} {slots:>9d} {fwd:7.2f} {rev:8.2f} "
                f"{rev / fwd:6.2f} {rev_auto:9.2f} {rev_auto / fwd:6.2f} {per_slot:11.0f} "
                f"{chosen:>8}",
                flush=True,
            )


if __name__ == "__main__":
    main()
