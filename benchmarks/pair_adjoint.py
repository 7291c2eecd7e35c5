"""A hand-derived adjoint of one SPH pair sum against JAX's autodiff (prototype).

The reverse pass through a simulation costs 1.7-2.1 forward steps per step
(``docs/performance_gradients.md``).  This measures what a hand-derived adjoint would gain
on the pressure term of eq. 10 alone,

    a_a = - sum_b m_b (P_a + P_b) F(r_ab) r_ab,   P = p / rho^2,   F(r) = W'(r) / r,

whose adjoint, written with the symmetry of the neighbour list (b in N(a) iff a in N(b)),
is one pass over each particle's own row with gathers only (no scatter):

    w_ab   = m_a abar_b - m_b abar_a
    S_a    = sum_b F_ab r_ab . w_ab
    pbar_a = S_a / rho_a^2,   rhobar_a = -2 p_a / rho_a^3 S_a
    mbar_a = sum_b (P_a + P_b) F_ab r_ab . abar_b
    xbar_a = sum_b (P_a + P_b) [F_ab w_ab + G_ab (r_ab . w_ab) r_ab],   G = F'(r) / r.

The forward is the package's own term (``pair_geometry``, ``pressure_acceleration``); only
the adjoint is written here.  It prints the float64 agreement with autodiff and the float32
times of the forward and the gradient for the Taylor-Green vortex (default 100 x 100
particles).

    python benchmarks/pair_adjoint.py [--n-side 100]
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp


def build(n_side: int):
    """The Taylor-Green case, the package's pressure term (``pair_geometry`` and
    ``fluid.momentum.pressure_acceleration``) and the same term with the hand adjoint."""
    import sphjax
    from sphjax import integrate, kernels
    from sphjax.fluid.momentum import pressure_acceleration
    from sphjax.neighbors import pair_geometry
    from sphjax.space import displacement_fn

    case = sphjax.cases.taylor_green(n=n_side)
    model = case.model
    kernel, h, dim = model.kernel, model.smoothing_length, model.dim
    idx = integrate.build_neighbors(case.state, model).fluid.idx
    displacement = displacement_fn(model.domain)

    def pressure_term(x, rho, p, m):
        pairs = pair_geometry(x, x, idx, displacement, model)
        return pressure_acceleration(m, rho, p, pairs, 0.0)

    @jax.custom_vjp
    def pressure_term_hand(x, rho, p, m):
        return pressure_term(x, rho, p, m)

    def forward(x, rho, p, m):
        return pressure_term(x, rho, p, m), (x, rho, p, m)

    def backward(residuals, abar):
        x, rho, p, m = residuals
        pairs = pair_geometry(x, x, idx, displacement, model)
        j, dr = pairs.j, pairs.dr
        inside = pairs.mask & (pairs.r > 0)
        r = jnp.where(inside, pairs.r, 1.0)
        # W'(r) and W''(r): the kernel's derivative and its derivative along r
        first, second = jax.jvp(
            lambda r: kernels.dW_dr(kernel, r, h, dim), (r,), (jnp.ones_like(r),)
        )
        F = jnp.where(inside, first / r, 0.0)
        G = jnp.where(inside, (second - first / r) / r**2, 0.0)
        P = p / rho**2
        PP = P[:, None] + P[j]
        abar_b = abar[j]
        w = m[:, None, None] * abar_b - m[j][..., None] * abar[:, None, :]
        dr_w = jnp.sum(dr * w, -1)
        S = jnp.sum(F * dr_w, 1)
        xbar = jnp.sum((PP * F)[..., None] * w + (PP * G * dr_w)[..., None] * dr, 1)
        mbar = jnp.sum(PP * F * jnp.sum(dr * abar_b, -1), 1)
        return xbar, -2.0 * p / rho**3 * S, S / rho**2, mbar

    pressure_term_hand.defvjp(forward, backward)
    s = case.state
    x = s.position
    args = (
        x,
        s.density * (1 + 0.01 * jnp.sin(40 * x[:, 0])),
        3.0 * s.density + jnp.cos(30 * x[:, 1]),
        s.mass * (1 + 0.1 * jnp.sin(20 * x[:, 1])),
    )
    weight = jnp.cos(7.0 * x)
    return case, pressure_term, pressure_term_hand, args, weight


def best_ms(fn, args, repeat=9):
    jax.block_until_ready(fn(*args))
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        best = min(best, time.perf_counter() - t0)
    return 1e3 * best


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-side", type=int, default=100)
    args = parser.parse_args(argv)

    jax.config.update("jax_enable_x64", True)
    _, auto, hand, inputs, weight = build(args.n_side)

    def gradient(term):
        return jax.jit(jax.grad(lambda *a: jnp.sum(term(*a) * weight), argnums=(0, 1, 2, 3)))

    grads = zip("x rho p m".split(), gradient(auto)(*inputs), gradient(hand)(*inputs), strict=True)
    for name, a, b in grads:
        error = float(jnp.max(jnp.abs(a - b)) / jnp.max(jnp.abs(a)))
        print(f"float64 gradient w.r.t. {name:>3}: hand vs autodiff, max relative {error:.1e}")

    jax.config.update("jax_enable_x64", False)
    case, auto, hand, inputs, weight = build(args.n_side)
    print(f"{case.n_particles} particles, float32")
    for name, term in (("autodiff", auto), ("hand adjoint", hand)):
        forward_ms = best_ms(jax.jit(lambda *a, t=term: jnp.sum(t(*a) * weight)), inputs)
        gradient_ms = best_ms(gradient(term), inputs)
        print(
            f"{name:>12}: forward {forward_ms:6.2f} ms  gradient {gradient_ms:6.2f} ms  "
            f"backward {gradient_ms - forward_ms:6.2f} ms"
        )


if __name__ == "__main__":
    main()
