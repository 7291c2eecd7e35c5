"""Rollout metrics: LagrangeBench's definitions beside the original sphjax ones.

LagrangeBench (Toshev et al. 2023, "LagrangeBench: A Lagrangian Fluid Mechanics
Benchmarking Suite", NeurIPS Datasets and Benchmarks; ``lagrangebench.evaluate.metrics``)
scores a rollout ``x^k`` (``k = 1 .. n``: predicted frames, the input history excluded)
against the ground truth ``y^k`` with

* ``MSE_n = (1/n) sum_{k<=n} (1/(N d)) sum_{i,a} (x^k_ia - y^k_ia)^2``: the per-step
  squared error averaged over particles *and* dimensions, then averaged over the first
  ``n`` steps (:func:`lb_mse_curve`, :func:`lb_mse`);
* the kinetic-energy error ``mean_k (E^k_pred - E^k_true)^2`` with
  ``E^k = dx^d sum_i |v^k_i|^2``, ``v^k = (x^{k+1} - x^k) / (dt write_every)`` at every
  ``stride``-th rollout frame (no factor 1/2, no mass: their convention;
  :func:`lb_kinetic_energy`);
* the Sinkhorn divergence between the two particle clouds (uniform weights, squared
  minimum-image distance as cost, ott-jax's default entropic regularisation
  ``epsilon = 0.05 std(cost)``, threshold 1e-4) at every ``stride``-th frame
  (:func:`sinkhorn_distance`).

Displacements use the minimum image on periodic axes.  LagrangeBench averages over all
particles; walls follow the ground truth in a rollout, so they add zero error.

The original sphjax metrics stay available under explicit names: ``mse_sumdim_at_{r}``
is ``(1/N_f) sum_i |x^r_i - y^r_i|^2`` over fluid particles at step ``r`` (summed over
dimensions: ``d`` times LagrangeBench's per-step value on all-fluid data) and
``ke_mse_specific`` the mean over the rollout of ``(e_pred - e_true)^2`` with the
specific kinetic energy ``e = 0.5 <|v|^2>`` over fluid particles.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from sphjax.dataset.format import check_same_geometry
from sphjax.surrogate.data import FLUID, PAD, Trajectories, displacement, frame_velocities

LB_HORIZONS = (5, 10, 20, 50, 100)
REPORT = (1, 5, 10, 20, 50, 100)


# ---------------------------------------------------------------------------- LagrangeBench


def lb_mse_curve(pred, truth, bounds, periodic, mask=None):
    """Per-step squared error averaged over particles and dimensions, ``[n]``.

    ``pred`` and ``truth`` are ``[n, N, d]``; ``mask`` (``[N]`` bool) selects the real
    particles (padding excluded)."""
    d = displacement(jnp.asarray(pred), jnp.asarray(truth), bounds, periodic)
    se = jnp.mean(d * d, -1)  # [n, N]
    if mask is None:
        return jnp.mean(se, -1)
    w = jnp.asarray(mask, se.dtype)
    return jnp.sum(se * w, -1) / jnp.maximum(jnp.sum(w), 1.0)


def lb_mse(curve, n: int) -> float:
    """``MSE_n``: the mean of the per-step values over the first ``n`` steps."""
    curve = np.asarray(curve)
    if not 1 <= n <= len(curve):
        raise ValueError(f"MSE{n} needs a rollout of at least {n} steps, got {len(curve)}")
    return float(np.mean(curve[:n]))


def lb_kinetic_energy(frames, bounds, periodic, frame_dt, dx, stride: int = 10, mask=None):
    """``E = dx^d sum_i |v_i|^2`` at rollout frames ``0, stride, ...`` (``[ceil((n-1)/stride)]``),
    ``v`` from the next frame: ``(x^{k+1} - x^k) / frame_dt``."""
    frames = jnp.asarray(frames)
    dim = frames.shape[-1]
    v = displacement(frames[1::stride], frames[0:-1:stride], bounds, periodic) / frame_dt
    e = jnp.sum(v * v, -1)
    if mask is not None:
        e = e * jnp.asarray(mask, e.dtype)
    return jnp.sum(e, -1) * dx**dim


def lb_ekin_mse(pred, truth, bounds, periodic, frame_dt, dx, stride: int = 10, mask=None):
    """LagrangeBench's kinetic-energy error ``mean_k (E_pred - E_true)^2``."""
    e_p = lb_kinetic_energy(pred, bounds, periodic, frame_dt, dx, stride, mask)
    e_t = lb_kinetic_energy(truth, bounds, periodic, frame_dt, dx, stride, mask)
    return float(jnp.mean((e_p - e_t) ** 2))


def _cost(x, y, bounds, periodic):
    """Squared minimum-image distances ``[len(x), len(y)]``."""
    d = displacement(x[:, None, :], y[None, :, :], bounds, periodic)
    return jnp.sum(d * d, -1)


def sinkhorn_distance(x, y, bounds, periodic, threshold: float = 1e-4) -> float:
    """Sinkhorn divergence (ott-jax) between two particle clouds ``[N, d]``, ``[M, d]``
    with uniform weights and the squared minimum-image distance as cost.

    ``S(x, y) = OT_eps(x, y) - (OT_eps(x, x) + OT_eps(y, y)) / 2`` (Genevay et al. 2018),
    with one ``epsilon`` shared by the three problems (ott's default, 0.05 times the
    standard deviation of the ``x``-``y`` cost).  For a cloud translated by ``delta``
    (no periodic wrap) it equals ``|delta|^2`` exactly, whatever ``epsilon``.
    """
    from ott.geometry.geometry import Geometry
    from ott.tools.sinkhorn_divergence import sinkhorn_divergence

    x, y = jnp.asarray(x), jnp.asarray(y)
    a = jnp.full(x.shape[0], 1.0 / x.shape[0], x.dtype)
    b = jnp.full(y.shape[0], 1.0 / y.shape[0], y.dtype)
    value, _ = sinkhorn_divergence(
        Geometry,
        _cost(x, y, bounds, periodic),
        _cost(x, x, bounds, periodic),
        _cost(y, y, bounds, periodic),
        a=a,
        b=b,
        solve_kwargs={"threshold": threshold},
    )
    return float(value)


# ---------------------------------------------------------------------------- sphjax (old)


def kinetic_energy(frames, bounds, periodic, frame_dt, fluid):
    """Specific kinetic energy ``0.5 <|v|^2>`` over fluid particles per frame,
    ``v`` = displacement / frame_dt.  ``frames`` is ``[T, N, d]``; returns ``[T-1]``."""
    v = frame_velocities(frames, bounds, periodic) / frame_dt
    w = fluid.astype(v.dtype)
    return 0.5 * jnp.sum(jnp.sum(v * v, -1) * w, -1) / jnp.maximum(jnp.sum(w), 1.0)


def mse_sumdim_curve(pred, truth, bounds, periodic, fluid):
    """``(1/N_f) sum_i |x_i - y_i|^2`` over fluid particles per step (summed over axes)."""
    d = displacement(jnp.asarray(pred), jnp.asarray(truth), bounds, periodic)
    w = jnp.asarray(fluid, d.dtype)
    return jnp.sum(jnp.sum(d * d, -1) * w, -1) / jnp.maximum(jnp.sum(w), 1.0)


# ---------------------------------------------------------------------------- rollouts


def check_compatible(sim, data: Trajectories, name: str = "dataset") -> None:
    """``ValueError`` unless ``data`` has the model's dimension, box, periodic axes and
    frame time (a mismatched dataset would be scored without a word)."""
    check_same_geometry(sim.metadata, data.metadata, name)


def _check_rollout(n_frames: int, history: int, n_steps, starts) -> list[int]:
    if isinstance(n_steps, bool) or not isinstance(n_steps, int | np.integer) or n_steps < 1:
        raise ValueError(f"n_steps must be a positive integer, got {n_steps!r}")
    starts = [int(s) for s in starts]
    if not starts:
        raise ValueError("starts is empty; give at least one start frame, e.g. starts=(0,)")
    for s in starts:
        need = s + history + 1 + n_steps
        if s < 0 or need > n_frames:
            most = n_frames - history - 1 - max(s, 0)
            raise ValueError(
                f"start frame {s}: a rollout of n_steps={n_steps} after history={history} needs "
                f"{need} frames, the trajectories have {n_frames}; "
                + (f"use n_steps <= {most} from this start" if most >= 1 else "use a lower start")
            )
    return starts


def rollout_metrics(
    sim,
    model,
    data: Trajectories,
    n_steps: int = 20,
    starts=(0,),
    report=REPORT,
    stride: int = 10,
    sinkhorn: bool = True,
) -> dict:
    """Roll ``model`` out (``None``: the constant-velocity baseline) from each start frame
    of each trajectory of ``data`` and score it against the ground truth.

    Raises ``ValueError`` if ``data`` does not match the simulator's geometry or frame
    time, or if a rollout of ``n_steps`` from a start frame does not fit the trajectories
    (never shortened or dropped).

    Returns a dict (means over trajectories and start frames):
      ``lb_mse{n}`` (``n`` in 5, 10, 20, 50, 100 up to ``n_steps``), ``lb_mse_curve``,
      ``lb_ekin_mse``, ``lb_sinkhorn`` (if ``sinkhorn``; every ``stride``-th frame):
      LagrangeBench's definitions (module docstring);
      ``mse_sumdim_at_{r}`` (``r`` in ``report``), ``mse_sumdim_mean``,
      ``mse_sumdim_curve``, ``ke_mse_specific``: the original sphjax definitions;
      ``n_steps``, ``n_rollouts``.
    """
    check_compatible(sim, data)
    h = sim.config.history
    n_frames = data.positions.shape[1]
    starts = _check_rollout(n_frames, h, n_steps, starts)
    n_steps = int(n_steps)
    if "dx" not in data.metadata:
        raise ValueError("the dataset's metadata.json has no dx (needed by lb_ekin_mse)")
    dx = float(data.metadata["dx"])
    neighbors = sim.allocate(data.positions[0, h])
    run = sim.compiled_rollout(n_steps)
    ours, ours_ke, lb_curves, lb_ekin, lb_sink = [], [], [], [], []
    for k in range(len(data)):
        types = jnp.asarray(data.particle_type[k])
        fluid = types == FLUID
        real = types != PAD
        for s in starts:
            x0 = jnp.asarray(data.positions[k, s : s + h + 1])
            truth = jnp.asarray(data.positions[k, s + h + 1 : s + h + 1 + n_steps])
            for _ in range(5):
                frames, over = run(model, x0, types, truth, neighbors)
                if not bool(over):
                    break
                neighbors = sim.allocate(data.positions[k, s + h], 4 + neighbors.idx.shape[-1])
            else:
                raise RuntimeError("neighbour list kept overflowing; raise capacity_multiplier")
            ours.append(
                np.asarray(mse_sumdim_curve(frames, truth, sim.bounds, sim.periodic, fluid))
            )
            seq_p = jnp.concatenate([x0[-1:], frames])
            seq_t = jnp.concatenate([x0[-1:], truth])
            ke_p = kinetic_energy(seq_p, sim.bounds, sim.periodic, sim.frame_dt, fluid)
            ke_t = kinetic_energy(seq_t, sim.bounds, sim.periodic, sim.frame_dt, fluid)
            ours_ke.append(float(jnp.mean((ke_p - ke_t) ** 2)))
            lb_curves.append(
                np.asarray(lb_mse_curve(frames, truth, sim.bounds, sim.periodic, real))
            )
            if n_steps >= 2:
                lb_ekin.append(
                    lb_ekin_mse(
                        frames, truth, sim.bounds, sim.periodic, sim.frame_dt, dx, stride, real
                    )
                )
            if sinkhorn:
                keep = np.asarray(real)
                picks = range(0, max(n_steps - 1, 1), stride)
                lb_sink.append(
                    np.mean(
                        [
                            sinkhorn_distance(
                                frames[j][keep], truth[j][keep], sim.bounds, sim.periodic
                            )
                            for j in picks
                        ]
                    )
                )
    out: dict = {}
    lb_curve = np.mean(np.stack(lb_curves), 0)
    for n in LB_HORIZONS:
        if n <= n_steps:
            out[f"lb_mse{n}"] = lb_mse(lb_curve, n)
    out["lb_mse_curve"] = lb_curve.tolist()
    if lb_ekin:
        out["lb_ekin_mse"] = float(np.mean(lb_ekin))
    if sinkhorn:
        out["lb_sinkhorn"] = float(np.mean(lb_sink))
    curve = np.mean(np.stack(ours), 0)
    for r in report:
        if r <= n_steps:
            out[f"mse_sumdim_at_{r}"] = float(curve[r - 1])
    out["mse_sumdim_mean"] = float(curve.mean())
    out["mse_sumdim_curve"] = curve.tolist()
    out["ke_mse_specific"] = float(np.mean(ours_ke))
    out["n_steps"] = n_steps
    out["n_rollouts"] = len(ours)
    return out


__all__ = [
    "LB_HORIZONS",
    "check_compatible",
    "kinetic_energy",
    "lb_ekin_mse",
    "lb_kinetic_energy",
    "lb_mse",
    "lb_mse_curve",
    "mse_sumdim_curve",
    "rollout_metrics",
    "sinkhorn_distance",
]
