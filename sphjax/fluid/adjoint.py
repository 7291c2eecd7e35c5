"""Fluid rates with a hand-derived adjoint: reverse mode without scatters.

Autodiff transposes every neighbour gather ``q[j]`` of a pair sum into a scatter-add and
writes a dozen per-pair intermediates ``[N, K]`` to memory; on the CPU the reverse pass of
a step then costs about twice its forward.  For a neighbour list that is symmetric (``b``
in ``N(a)`` iff ``a`` in ``N(b)``, true of the full lists used here) the adjoint of a pair
sum can instead be written per particle ``k`` over its own row, gathering only
per-particle arrays (``abar_b``, ``m_b``, ...), and evaluated in blocks of particles
whose per-pair arrays stay in cache.  With the pair vector ``r_kb = x_k - x_b``,
``F = W'(r) / r``, ``G = F'(r) / r``, the output cotangents ``abar`` (acceleration),
``sbar`` (shift acceleration) and ``rhobar`` (density), and the pair weights
``w_kb = m_k abar_b - m_b abar_k``, ``ws_kb = m_k sbar_b - m_b sbar_k``:

* density, eq. 5, ``rho_a = m_a W(0) + sum_b m_b W_ab``:
  ``xbar_k = sum_b F r_kb (rhobar_k m_b + rhobar_b m_k)``, ``mbar_k = sum_b rhobar_b W_kb``;
* pressure (eq. 10) and the transport stress of Adami, Hu & Adams (2013) as one term
  ``a_a = sum_b m_b (C_a + C_b) F r_ab`` with ``C = -P I + u dv^T``, ``P = p / rho^2``,
  ``u = v / rho``, ``dv`` the transport velocity minus the velocity:
  ``Pbar_k = sum_b F r_kb . w_kb``, ``ubar_k = -sum_b F (r_kb . dv_k) w_kb``,
  ``dvbar_k = -sum_b F (w_kb . u_k) r_kb``, ``mbar_k = -sum_b F abar_b . (C_k + C_b) r_kb``,
  ``xbar_k = -sum_b [F c + G (r_kb . c) r_kb]`` with ``c = (C_k + C_b)^T w_kb``;
* the transport-velocity shift ``s_a = -sum_b m_b (Q_a + Q_b) F r_ab``, ``Q = p_b / rho^2``:
  ``Qbar_k = sum_b F r_kb . ws_kb``, ``mbar_k = sum_b (Q_k + Q_b) F r_kb . sbar_b``,
  ``xbar_k = sum_b (Q_k + Q_b) [F ws_kb + G (r_kb . ws_kb) r_kb]``;
* Morris viscosity ``a_a = sum_b m_b (B_a + B_b) H(r) v_ab``, ``B = nu / rho``,
  ``H = F r^2 / (r^2 + 0.01 h^2)``: ``vbar_k = -sum_b (B_k + B_b) H w_kb``,
  ``Bbar_k = -sum_b H v_kb . w_kb``, ``mbar_k = -sum_b (B_k + B_b) H abar_b . v_kb``,
  ``xbar_k = -sum_b (B_k + B_b) (H'/r) (v_kb . w_kb) r_kb``.

The per-particle maps in between (eq. 12 and ``P``, ``u``, ``B``, ``Q``) are
differentiated by JAX, and so is forward mode (:func:`sphjax._linear_call.custom_adjoint`).
The forward is the package's own terms.  Used for fluid-only models with summation
density and no artificial viscosity or density diffusion (:func:`supports`) unless
``Model.pair_adjoint`` is off; ``tests/test_gradients.py`` checks it against autodiff.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from sphjax import kernels
from sphjax._linear_call import custom_adjoint
from sphjax.fluid.density import summation_density
from sphjax.fluid.eos import tait_pressure
from sphjax.fluid.momentum import pressure_acceleration, transport_stress_acceleration
from sphjax.fluid.viscosity import ETA2, morris_acceleration
from sphjax.neighbors import pair_geometry
from sphjax.space import displacement_fn
from sphjax.state import Kind, Model

#: particles per block of the adjoint's passes (see ``_rowwise``)
_BLOCK = 2048

#: differentiable arguments of :func:`fluid_rates`, in order
ARGUMENTS = (
    "position",
    "velocity",
    "mass",
    "delta_v",
    "reference_density",
    "sound_speed",
    "reference_pressure",
    "background_pressure",
    "kinematic_viscosity",
    "transport_pressure",
)


def supports(model: Model) -> bool:
    """True where :func:`fluid_rates` covers the model's fluid right-hand side."""
    return (
        tuple(int(k) for k in model.particle_kinds) == (int(Kind.FLUID),)
        and model.density == "summation"
        and not model.artificial_viscosity
        and model.density_diffusion is None
    )


def _pairs(position, idx, model):
    return pair_geometry(position, position, idx, displacement_fn(model.domain), model)


def _particle_fields(model, neighbour_density, velocity, mass, *params):
    """Per-particle quantities of the pair sums: ``rho`` (eq. 5), ``p`` (eq. 12) and the
    coefficients ``P = p / rho^2``, ``u = v / rho``, ``B = nu / rho``, ``Q = p_b / rho^2``."""
    rho0, c0, p0, p_bg, nu, p_transport = params
    h, dim = model.smoothing_length, model.dim
    density = mass * kernels.W(model.kernel, 0.0, h, dim) + neighbour_density
    pressure = tait_pressure(density, rho0, c0, model.gamma, p0, p_bg)
    P = pressure / density**2
    u = velocity / density[:, None]
    return density, pressure, P, u, nu / density, p_transport / density**2


def _forward(model, stress, position, velocity, mass, delta_v, *rest):
    """The fluid rates, composed from the package's terms (as ``sphjax.rhs`` does).

    Returns ``(acceleration without gravity, shift acceleration, density, pressure)``.
    """
    *params, idx = rest
    rho0, c0, p0, p_bg, nu, p_transport = params
    h = model.smoothing_length
    pairs = _pairs(position, idx, model)
    self_weight = kernels.W(model.kernel, 0.0, h, model.dim)
    density = summation_density(mass, pairs, self_weight)
    pressure = tait_pressure(density, rho0, c0, model.gamma, p0, p_bg)
    acceleration = pressure_acceleration(mass, density, pressure, pairs, 0.0)
    j = pairs.j
    if model.physical_viscosity:
        v_ab = velocity[:, None, :] - velocity[j]
        visc = morris_acceleration(v_ab, pairs, mass[j], density[:, None], density[j], nu, h)
        acceleration = acceleration + jnp.sum(jnp.where(pairs.mask[..., None], visc, 0.0), 1)
    shift = jnp.zeros_like(acceleration)
    if model.transport_velocity:
        p_b = jnp.broadcast_to(p_transport, pressure.shape)
        shift = pressure_acceleration(mass, density, p_b, pairs, 0.0)
    if stress:
        acceleration = acceleration + transport_stress_acceleration(
            mass, density, velocity, delta_v, pairs
        )
    return acceleration, shift, density, pressure


def _rowwise(fn, rows):
    """``fn`` over blocks of ``_BLOCK`` particles (rows) with ``lax.map``.

    Each block's per-pair arrays (``[block, K]``) stay in cache; over all particles at
    once they would be written to and read from memory between XLA's loop fusions, which
    on the CPU costs more than the arithmetic.  ``rows`` is a tuple of ``[N, ...]`` arrays;
    ``fn`` returns a pytree of ``[block, ...]`` arrays.  Padding rows carry neighbour
    index ``N`` (no neighbours).
    """
    n = rows[0].shape[0]
    block = min(_BLOCK, n)
    n_blocks = -(-n // block)
    pad = n_blocks * block - n

    def split(a):
        a = jnp.pad(
            a, [(0, pad)] + [(0, 0)] * (a.ndim - 1), constant_values=n if a.dtype.kind == "i" else 0
        )
        return a.reshape((n_blocks, block) + a.shape[1:])

    out = jax.lax.map(fn, tuple(split(a) for a in rows))
    return jax.tree_util.tree_map(lambda a: a.reshape((n_blocks * block,) + a.shape[2:])[:n], out)


def _geometry(model, position_k, idx_k, position):
    """Pairs of a block of particles: neighbour index, ``r_kb``, ``r``, ``W``, ``F = W'/r``
    and ``G = F'/r`` (0 outside the support and at ``r = 0``)."""
    n = position.shape[0]
    valid = idx_k < n
    j = jnp.where(valid, idx_k, 0)
    dr = displacement_fn(model.domain)(position_k[:, None, :], position[j])
    r2 = _dot(dr, dr)
    in_support = valid & (r2 < model.cutoff**2)
    inside = in_support & (r2 > 0)  # coincident particles: W(0), no gradient
    r = jnp.sqrt(jnp.where(inside, r2, 1.0))
    dr = jnp.where(inside[..., None], dr, 0.0)
    h, dim = model.smoothing_length, model.dim
    first, second = jax.jvp(
        lambda r: kernels.dW_dr(model.kernel, r, h, dim), (r,), (jnp.ones_like(r),)
    )
    W = jnp.where(in_support, kernels.W(model.kernel, jnp.where(inside, r, 0.0), h, dim), 0.0)
    F = jnp.where(inside, first / r, 0.0)
    G = jnp.where(inside, (second - first / r) / r**2, 0.0)
    return j, dr, r, W, F, G


def _dot(a, b):
    """``a . b`` over the last (spatial) axis, written out: XLA on the CPU ends a loop
    fusion at a reduction, even over two or three components."""
    return sum(a[..., i] * b[..., i] for i in range(a.shape[-1]))


def _adjoint(model, stress, args, cotangents):
    """Cotangents of the :data:`ARGUMENTS` from those of ``_forward``'s outputs."""
    position, velocity, mass, delta_v, *rest = args
    *params, idx = rest
    abar, sbar, rhobar_out, pbar_out = cotangents
    h = model.smoothing_length

    def neighbour_density(rows):
        x_k, idx_k = rows
        j, _, _, W, _, _ = _geometry(model, x_k, idx_k, position)
        return jnp.sum(mass[j] * W, axis=1)

    fields = functools.partial(_particle_fields, model)
    density_sum = _rowwise(neighbour_density, (position, idx))
    (_, _, P, u, B, Q), pull_fields = jax.vjp(fields, density_sum, velocity, mass, *params)

    def momentum(rows):
        x_k, idx_k, m_k, abar_k, sbar_k, P_k, u_k, B_k, Q_k, v_k, dv_k = rows
        j, dr, r, _, F, G = _geometry(model, x_k, idx_k, position)
        m_b, abar_b = mass[j], abar[j]
        w = m_k[:, None, None] * abar_b - m_b[..., None] * abar_k[:, None, :]
        out = {"Pbar": jnp.sum(F * _dot(dr, w), axis=1)}
        # pressure and transport stress, (C_k + C_b) with C = -P I + u dv^T
        P_kb = (P_k[:, None] + P[j])[..., None]
        c = -P_kb * w  # (C_k + C_b)^T w
        C_dr = -P_kb * dr  # (C_k + C_b) r_kb
        if stress:
            u_b, dv_b = u[j], delta_v[j]
            u_k, dv_k = u_k[:, None], dv_k[:, None]
            c = c + dv_k * _dot(u_k, w)[..., None] + dv_b * _dot(u_b, w)[..., None]
            C_dr = C_dr + u_k * _dot(dv_k, dr)[..., None] + u_b * _dot(dv_b, dr)[..., None]
            out["ubar"] = -jnp.sum((F * _dot(dr, dv_k))[..., None] * w, axis=1)
            out["dvbar"] = -jnp.sum((F * _dot(w, u_k))[..., None] * dr, axis=1)
        mbar = -F * _dot(abar_b, C_dr)
        xbar = -(F[..., None] * c + (G * _dot(dr, c))[..., None] * dr)
        if model.physical_viscosity:
            eta2 = ETA2 * h**2
            q = r**2 + eta2
            H = F * r**2 / q
            H_r = G * r**2 / q + 2.0 * F * eta2 / q**2  # H'(r) / r
            B_kb = B_k[:, None] + B[j]
            v_kb = v_k[:, None, :] - velocity[j]
            v_w = _dot(v_kb, w)
            out["vbar"] = -jnp.sum((B_kb * H)[..., None] * w, axis=1)
            out["Bbar"] = -jnp.sum(H * v_w, axis=1)
            mbar = mbar - B_kb * H * _dot(abar_b, v_kb)
            xbar = xbar - (B_kb * H_r * v_w)[..., None] * dr
        if model.transport_velocity:
            sbar_b = sbar[j]
            ws = m_k[:, None, None] * sbar_b - m_b[..., None] * sbar_k[:, None, :]
            Q_kb = Q_k[:, None] + Q[j]
            out["Qbar"] = jnp.sum(F * _dot(dr, ws), axis=1)
            mbar = mbar + Q_kb * F * _dot(dr, sbar_b)
            xbar = xbar + (Q_kb * F)[..., None] * ws + (Q_kb * G * _dot(dr, ws))[..., None] * dr
        out["xbar"] = jnp.sum(xbar, axis=1)
        out["mbar"] = jnp.sum(mbar, axis=1)
        return out

    rows = (position, idx, mass, abar, sbar, P, u, B, Q, velocity, delta_v)
    bars = _rowwise(momentum, rows)
    zeros = jnp.zeros_like
    rhobar_sum, vbar_fields, mbar_fields, *param_bars = pull_fields(
        (
            rhobar_out,
            pbar_out,
            bars["Pbar"],
            bars.get("ubar", zeros(u)),
            bars.get("Bbar", zeros(B)),
            bars.get("Qbar", zeros(Q)),
        )
    )

    def density(rows):
        x_k, idx_k, m_k, rhobar_k = rows
        j, dr, _, W, F, _ = _geometry(model, x_k, idx_k, position)
        rhobar_b = rhobar_sum[j]
        weight = F * (rhobar_k[:, None] * mass[j] + rhobar_b * m_k[:, None])
        return jnp.sum(weight[..., None] * dr, axis=1), jnp.sum(rhobar_b * W, axis=1)

    xbar_density, mbar_density = _rowwise(density, (position, idx, mass, rhobar_sum))
    return (
        bars["xbar"] + xbar_density,
        bars.get("vbar", zeros(velocity)) + vbar_fields,
        bars["mbar"] + mbar_fields + mbar_density,
        bars.get("dvbar", zeros(delta_v)),
        *param_bars,
    )


@functools.lru_cache(maxsize=64)
def _rates_fn(model: Model, stress: bool):
    return custom_adjoint(
        functools.partial(_forward, model, stress),
        functools.partial(_adjoint, model, stress),
        n_linear=len(ARGUMENTS),
    )


def fluid_rates(position, velocity, mass, delta_v, params, idx, model: Model):
    """Fluid rates of a model that :func:`supports` covers, with the hand adjoint.

    Args:
      delta_v: ``[N, d]`` transport velocity minus velocity of the drift just taken, or
        ``None`` (no transport stress).
      params: :class:`sphjax.Params`.
    Returns:
      ``(acceleration without gravity, shift acceleration, density, pressure)``.
    """
    stress = delta_v is not None
    if not stress:
        delta_v = jnp.zeros_like(velocity)
    scalars = [jnp.asarray(getattr(params, name), position.dtype) for name in ARGUMENTS[4:]]
    return _rates_fn(model, stress)(position, velocity, mass, delta_v, *scalars, idx)
