"""Per-pair neighbour lists against dense cell blocks for one pair sum, forward and reverse.

    python benchmarks/pair_layouts.py            # Taylor-Green, 100 x 100 particles
    python benchmarks/pair_layouts.py --n 200

sphjax sums pairs over dense neighbour lists ``[N, K]``: every pair gathers the
neighbour's fields.  The alternative this benchmark measures keeps no per-pair index: the
particles are binned into cells one support radius wide, stored as blocks ``[cells, C]``
(``C`` the fullest cell), and each cell meets the 3 x 3 cells around it as whole blocks
(a periodic roll of the block array, no gather per pair), ``[cells, C, 9 C]`` candidate
pairs.  Both evaluate the same summand (pressure and Morris viscosity on the Taylor-Green
start, float32) and are compiled; the benchmark prints CPU-milliseconds (best of
``--repeat``) of the forward and of the gradient of a scalar of its result, autodiff's
transpose in both, the binning, the pair counts, and the largest difference of the two
results.  The two layouts in one variant concatenate the 9 neighbour cells and in the
other loop over them.  A benchmark reports; it asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

import sphjax
from sphjax.core import kernels
from sphjax.neighbors.search import points_within

SHIFTS = [(i, j) for i in (-1, 0, 1) for j in (-1, 0, 1)]


def pair_term(dx, dy, mask, a, b, h, cutoff, kernel, nu):
    """Pressure and Morris viscosity of one pair (``a``, ``b``: dicts of fields)."""
    r2 = dx * dx + dy * dy
    inside = mask & (r2 < cutoff**2) & (r2 > 0)
    r = jnp.sqrt(jnp.where(inside, r2, 1.0))
    F = jnp.where(inside, kernels.dW_dr(kernel, r, h, 2) / r, 0.0)
    pressure = -b["m"] * (a["p"] / a["rho"] ** 2 + b["p"] / b["rho"] ** 2) * F
    viscous = b["m"] * 2.0 * nu / (a["rho"] * b["rho"]) * F * r2 / (r2 + 0.01 * h * h)
    return (
        pressure * dx + viscous * (a["u"] - b["u"]),
        pressure * dy + viscous * (a["v"] - b["v"]),
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, default=100, help="particles per side")
    parser.add_argument("--repeat", type=int, default=10)
    args = parser.parse_args()

    case = sphjax.cases.taylor_green(n=args.n)
    state = case.state
    fields = {
        "x": np.asarray(state.position, np.float32),
        "u": np.asarray(state.velocity[:, 0], np.float32),
        "v": np.asarray(state.velocity[:, 1], np.float32),
        "rho": np.asarray(state.density, np.float32),
        "m": np.asarray(state.mass, np.float32),
    }
    fields["p"] = (10.0**2 * (fields["rho"] - 1.0)).astype(np.float32)
    n = fields["x"].shape[0]
    h, kernel = float(case.model.smoothing_length), case.model.kernel
    cutoff, nu = kernel.support * h, float(case.params.fluid.kinematic_viscosity)

    # the neighbour list, at the width the package would allocate (1.5 x the fullest row)
    rows = points_within(fields["x"], cutoff, [0.0, 0.0], [1.0, 1.0], [True, True])
    most = int(np.max(np.sum(rows < n, axis=1)))
    width = int(1.5 * most)
    idx = np.full((n, width), n, np.int32)
    idx[:, : min(width, rows.shape[1])] = rows[:, :width]

    cells = int(np.floor(1.0 / cutoff))
    cell = 1.0 / cells
    ij = np.floor(fields["x"] / cell).astype(int) % cells
    fullest = int(np.bincount(ij[:, 0] * cells + ij[:, 1], minlength=cells**2).max())

    def wrap(d):
        return d - jnp.round(d)

    def by_list(f):
        valid = idx < n
        j = jnp.where(valid, idx, 0)
        a = {k: q[:, None] for k, q in f.items() if k != "x"}
        b = {k: q[j] for k, q in f.items() if k != "x"}
        dx = wrap(f["x"][:, None, 0] - f["x"][j, 0])
        dy = wrap(f["x"][:, None, 1] - f["x"][j, 1])
        ax, ay = pair_term(dx, dy, valid, a, b, h, cutoff, kernel, nu)
        return jnp.stack([ax.sum(1), ay.sum(1)], -1)

    def binning(x):
        c = jnp.floor(x / cell).astype(jnp.int32) % cells
        cid = c[:, 0] * cells + c[:, 1]
        order = jnp.argsort(cid)
        sorted_cid = cid[order]
        start = jnp.searchsorted(sorted_cid, jnp.arange(cells * cells, dtype=jnp.int32))
        slot = sorted_cid * fullest + jnp.arange(n, dtype=jnp.int32) - start[sorted_cid]
        slot_of = jnp.zeros(n, jnp.int32).at[order].set(slot)
        particle_of = jnp.full(cells * cells * fullest, n, jnp.int32).at[slot].set(order)
        return particle_of, slot_of

    particle_of, slot_of = jax.jit(binning)(jnp.asarray(fields["x"]))

    def blocks_of(f):
        padding = {"x": 1e3, "u": 0.0, "v": 0.0, "p": 0.0, "rho": 1.0, "m": 0.0}
        out = {}
        for k, q in f.items():
            pad = jnp.full((1,) + q.shape[1:], padding[k], q.dtype)
            out[k] = jnp.concatenate([q, pad])[particle_of].reshape(
                (cells, cells, fullest) + q.shape[1:]
            )
        return out, (particle_of < n).reshape(cells, cells, fullest)

    def rolled(q, di, dj):
        return jnp.roll(q, (-di, -dj), axis=(0, 1))

    def by_blocks(f, loop):
        B, valid = blocks_of(f)
        a = {k: q[:, :, :, None] for k, q in B.items() if k != "x"}
        xa = B["x"][:, :, :, None]
        groups = [[s] for s in SHIFTS] if loop else [SHIFTS]
        total = 0.0
        for group in groups:
            nb = {k: jnp.concatenate([rolled(q, *s) for s in group], 2) for k, q in B.items()}
            nv = jnp.concatenate([rolled(valid, *s) for s in group], 2)
            b = {k: q[:, :, None] for k, q in nb.items() if k != "x"}
            xb = nb["x"][:, :, None]
            mask = valid[:, :, :, None] & nv[:, :, None, :]
            ax, ay = pair_term(
                wrap(xa[..., 0] - xb[..., 0]),
                wrap(xa[..., 1] - xb[..., 1]),
                mask,
                a,
                b,
                h,
                cutoff,
                kernel,
                nu,
            )
            total = total + jnp.stack([ax.sum(-1), ay.sum(-1)], -1)
        return total.reshape(cells * cells * fullest, 2)[slot_of]

    def cpu_ms(fn, *inputs):
        jax.block_until_ready(fn(*inputs))
        best = float("inf")
        for _ in range(args.repeat):
            t0 = time.process_time()
            jax.block_until_ready(fn(*inputs))
            best = min(best, time.process_time() - t0)
        return 1e3 * best

    f = {k: jnp.asarray(q) for k, q in fields.items()}
    layouts = {
        "neighbour list": by_list,
        "cell blocks, 9 cells at once": lambda f: by_blocks(f, loop=False),
        "cell blocks, one cell at a time": lambda f: by_blocks(f, loop=True),
    }
    reference = np.asarray(jax.jit(by_list)(f))
    print(
        f"{n} particles, support {cutoff:.4f}; list: {width} slots per particle "
        f"({most} at most inside the support); blocks: {cells}^2 cells of at most {fullest}, "
        f"{9 * fullest} candidates per particle"
    )
    print(f"binning: {cpu_ms(jax.jit(binning), f['x']):.2f} CPU-ms")
    print(f"{'layout':34s} {'forward ms':>11s} {'gradient ms':>12s} {'ratio':>6s} {'max diff':>9s}")
    for name, fn in layouts.items():
        forward = jax.jit(fn)
        gradient = jax.jit(jax.grad(lambda f, fn=fn: jnp.sum(fn(f) ** 2)))
        diff = float(np.max(np.abs(np.asarray(forward(f)) - reference)))
        t_f, t_g = cpu_ms(forward, f), cpu_ms(gradient, f)
        print(f"{name:34s} {t_f:11.2f} {t_g:12.2f} {t_g / t_f:6.2f} {diff:9.2e}")
    load = ", ".join(f"{v:.2f}" for v in os.getloadavg())
    print(f"(largest |result| {np.max(np.abs(reference)):.3g}; load average {load})")


if __name__ == "__main__":
    main()
