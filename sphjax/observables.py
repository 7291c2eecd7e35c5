"""Observables: what is measured on a trajectory, apart from the set-ups that produce it.

* :func:`surge_front` — the dam-break surge front ``Z`` (Martin & Moyce 1952);
* :func:`probe_pressure` — the pressure the fluid exerts at a probe point (a wall sensor);
* :func:`poiseuille_centreline_speed` — the channel's centre-line speed;
* :func:`tip_displacement` — the displacement of a solid's tip probe (plate, Turek-Hron);
* :func:`oscillation_stats` — mean, amplitude and period of a signal.

Each reads the probes the case put in ``case.info``.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from sphjax.core import kernels
from sphjax.core.case import Case
from sphjax.core.state import Kind


def poiseuille_centreline_speed(state, case: Case) -> float:
    """Centreline speed ``u(L/2)`` of a Poiseuille state.

    With an even number of rows the centreline lies between the rows at ``L/2 -+ dx/2``;
    their mean speed is corrected by the curvature of the parabola,
    ``F / (2 nu) (dx / 2)^2``.
    """
    info = case.info
    L, dx = info["width"], info["dx"]
    fluid = np.asarray(state.kind) == Kind.FLUID
    y = np.asarray(state.position)[fluid, 1]
    u = np.asarray(state.velocity)[fluid, 0]
    near = np.abs(y - L / 2) < 0.6 * dx
    curvature = info["body_force"] / (2 * info["viscosity"]) * (dx / 2) ** 2
    return float(np.mean(u[near])) + curvature


def surge_front(states, case: Case):
    """Surge front ``Z / L`` of a dam break: the rightmost fluid particle plus ``dx / 2``.

    ``states`` may carry a leading time axis.
    """
    x = states.position[..., 0]
    fluid = states.kind == Kind.FLUID
    front = jnp.max(jnp.where(fluid, x, -jnp.inf), axis=-1) + 0.5 * case.info["dx"]
    return front / case.info["column_width"]


def probe_pressure(states, case: Case, point):
    """Fluid pressure at a probe ``point`` (a pressure sensor on a wall), the kernel
    (Shepard) average over the fluid particles within one support of it:

        p(x) = sum_f p_f W(x - x_f) V_f / sum_f W(x - x_f) V_f,     V_f = m_f / rho_f,

    with the case's kernel and smoothing length; 0 where no fluid particle is within the
    support (the sensor is dry).  Wall particles are left out: their pressure is itself
    extrapolated from the fluid.  A probe on a wall's face sees fluid on one side only,
    which the normalisation accounts for.

    Args:
      states: a State (or a Trajectory's ``states``), with or without a leading time axis.
      point: ``[d]`` probe position, e.g. ``(case.info["tank_length"], 0.16)`` on the
        right wall of a dam break.
    Returns:
      the pressure, ``[T]`` or a scalar; differentiable (jax.numpy).
    """
    states = getattr(states, "states", states)
    model = case.model
    point = jnp.asarray(point, states.position.dtype)
    r = jnp.linalg.norm(states.position - point, axis=-1)
    fluid = states.kind == Kind.FLUID
    weight = kernels.W(model.kernel, r, model.smoothing_length, model.dim)
    weight = jnp.where(fluid & (r < model.cutoff), weight * states.mass / states.density, 0.0)
    total = jnp.sum(weight, axis=-1)
    wet = total > 0
    average = jnp.sum(weight * states.pressure, axis=-1) / jnp.where(wet, total, 1.0)
    return jnp.where(wet, average, 0.0)


def tip_displacement(trajectory, case: Case):
    """Tip displacement ``x - X`` of ``case.info["tip_indices"]`` (averaged), ``[T, d]``.

    Args:
      trajectory: a :class:`sphjax.Trajectory`, a State (with or without a leading time
        axis) or a ``[T, N, d]`` / ``[N, d]`` position array.
      case: the Case the trajectory was run from.
    Returns:
      ``[T, d]`` displacement of the probe; differentiable (jax.numpy).
    """
    states = getattr(trajectory, "states", trajectory)
    position = getattr(states, "position", states)
    position = jnp.asarray(position)
    idx = jnp.asarray(case.info["tip_indices"])
    anchor = case.state.reference_position[idx]
    if position.ndim == 2:
        position = position[None]
    return jnp.mean(position[:, idx, :] - anchor, axis=-2)


def oscillation_stats(times, signal) -> dict:
    """Mean, amplitude, period and frequency of an oscillating signal (numpy).

    ``mean = (max + min) / 2`` and ``amplitude = (max - min) / 2`` over the whole signal
    (the convention of the Turek-Hron tables); the period is the mean spacing of
    successive crossings of the mean level in the same direction (linear interpolation),
    ``nan`` with fewer than two crossings in one direction.
    """
    t = np.asarray(times, float)
    s = np.asarray(signal, float)
    top, bottom = s.max(), s.min()
    mean = 0.5 * (top + bottom)
    d = s - mean
    spacings = []
    for rising in (True, False):
        sel = (d[:-1] < 0) & (d[1:] >= 0) if rising else (d[:-1] > 0) & (d[1:] <= 0)
        k = np.flatnonzero(sel)
        tc = t[k] - d[k] * (t[k + 1] - t[k]) / (d[k + 1] - d[k])
        spacings.extend(np.diff(tc))
    period = float(np.mean(spacings)) if spacings else float("nan")
    return dict(
        mean=float(mean),
        amplitude=float(0.5 * (top - bottom)),
        period=period,
        frequency=1.0 / period if spacings else float("nan"),
    )
