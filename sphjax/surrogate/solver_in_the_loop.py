"""Solver in the loop: a learned correction of a coarse sphjax simulation.

A coarse simulation (fewer particles, a larger time step) is cheap but wrong; a fine one
is the reference.  After every coarse solver step a graph network adds a velocity
correction to the fluid particles (Um et al. 2020, "Solver-in-the-Loop: Learning from
Differentiable Physics to Interact with Iterative PDE-Solvers", NeurIPS):

    s_{k+1} = C_theta(S_coarse(s_k)),   C_theta(s): v_i <- v_i + c * GNS_theta(s)_i

and ``theta`` is trained by back-propagating through ``unroll`` such steps, the solver
included (:func:`sphjax.simulate` is differentiable in the state and the Params), so the
network learns what the coarse solver gets wrong *along its own trajectory*.

The two resolutions have different particles, so they are compared on a fixed set of
probe points: the velocity field is interpolated with the SPH kernel, normalised by
Shepard's sum (``u(p) = sum_b V_b u_b W(p - x_b, h) / sum_b V_b W(p - x_b, h)``, ``V_b =
m_b / rho_b``, fluid particles, minimum image), for both simulations with the coarse
kernel and smoothing length, so that the comparison sees the fine field at the coarse
resolution rather than the difference of two smoothings.  The error at step ``k`` is the relative
L2 error of the probe field against the fine simulation at the same time,
``e_k = (sum_p |u_k(p) - u^fine_k(p)|^2 / sum_p |u^fine_k(p)|^2)^(1/2)``.

The pure-network baseline (``mode="gns"``) is the same graph network used without the
solver: ``v <- v + a GNS(s)``, ``x <- x + dt v`` (wrapped on periodic axes), trained the
same way; the solver alone is ``net=None``.
"""

from __future__ import annotations

import dataclasses
import math
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from sphjax import kernels
from sphjax.core.case import Case
from sphjax.core.params import Params
from sphjax.core.space import covered, minimum_image, safe_norm
from sphjax.core.state import Kind, State
from sphjax.integration.simulate import failures_as_nan, simulate
from sphjax.surrogate.gns import GNS
from sphjax.surrogate.graph import RadiusGraph, overflowed

MODES = ("correction", "gns")
LOSSES = ("relative", "relative_to_coarse")


def probe_grid(case: Case, per_side: int, box=None) -> np.ndarray:
    """Cell centres of a ``per_side^d`` grid over ``box`` (``[[lo, hi]] * d``; default the
    case's domain), ``[P, d]``."""
    domain = case.model.domain
    box = tuple(zip(domain.lower, domain.upper, strict=True)) if box is None else box
    axes = [lo + (np.arange(per_side) + 0.5) * (hi - lo) / per_side for lo, hi in box]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(axes))


def probe_velocity(state: State, case: Case, probes, smoothing_length=None) -> jax.Array:
    """SPH-interpolated velocity at ``probes`` ``[P, d]`` (Shepard-normalised, fluid only)
    with the kernel of ``case`` and ``smoothing_length`` (default the case's ``h``)."""
    model = case.model
    h = model.smoothing_length if smoothing_length is None else smoothing_length
    domain = model.domain
    size = jnp.asarray(domain.size, state.position.dtype)
    dr = minimum_image(
        jnp.asarray(probes, state.position.dtype)[:, None, :] - state.position[None, :, :],
        size,
        domain.periodic,
    )
    # safe_norm: a probe on top of a particle (a lattice start, a wall particle) would
    # otherwise give a NaN gradient (d|dr|/d dr = dr / 0), which poisons training
    r = safe_norm(dr)
    w = kernels.W(model.kernel, r, h, model.dim)
    fluid = (state.kind == Kind.FLUID).astype(w.dtype)
    wv = w * (state.mass / state.density * fluid)[None, :]
    # a probe with no fluid particle in reach reads 0; the floor of `covered` keeps the
    # quotient's derivative finite in float32 (a NaN gradient would poison training)
    shepard = jnp.sum(wv, -1, keepdims=True)
    ok = covered(shepard)
    return jnp.where(ok, (wv @ state.velocity) / jnp.where(ok, shepard, 1.0), 0.0)


def relative_error(u, reference) -> jax.Array:
    """``(sum |u - u_ref|^2 / sum |u_ref|^2)^(1/2)`` over the probes (last two axes)."""
    num = jnp.sum((u - reference) ** 2, (-2, -1))
    return jnp.sqrt(num / jnp.maximum(jnp.sum(reference**2, (-2, -1)), 1e-30))


@dataclasses.dataclass(frozen=True)
class Problem:
    """A coarse set-up, its fine reference and the probes (built by :func:`make_problem`).

    Attributes:
      coarse, fine: the two cases (same physics, different resolution; ``fine`` is the
        first of the fine ensemble).
      ratio: fine solver steps per coarse step (``dt_coarse = ratio * dt_fine``).
      dt: the coarse step.
      probes: ``[P, d]`` comparison points.
      conditions: per training/test condition, the coarse and fine Params.
      reference: ``[n_conditions, horizon + 1, P, d]`` fine probe velocities at the
        coarse step times.
      speed: velocity scale of the network's inputs and outputs.
    """

    coarse: Case
    fine: Case
    ratio: int
    dt: float
    probes: np.ndarray
    conditions: tuple
    reference: np.ndarray
    speed: float

    @property
    def horizon(self) -> int:
        return self.reference.shape[1] - 1


def make_problem(
    coarse: Case,
    fine,
    *,
    horizon: int,
    ratio: int,
    viscosities=None,
    conditions=None,
    probes_per_side: int = 16,
    probe_box=None,
    dt: float | None = None,
    speed: float | None = None,
) -> Problem:
    """Simulate the fine reference for each condition.

    A condition is a dict of Params fields to replace (``conditions=[{"artificial_alpha":
    0.05}, ...]``); ``viscosities=[nu, ...]`` is short for
    ``[{"kinematic_viscosity": nu}, ...]``; neither: the cases' own Params.

    ``fine`` is a Case or a list of Cases (an ensemble, e.g. Taylor-Green with several
    ``seed``s of the disordered start): the reference is the mean of their probe fields,
    which removes the part of the fine field that comes from one particular particle
    disorder (no coarse model could predict it).  The coarse step is ``dt`` (default the
    coarse case's stable step) and the fine one ``dt / ratio`` (checked against the fine
    stability limit by :func:`sphjax.simulate`).

    The two cases must agree on the periodic axes (flags and bounds); on closed axes their
    domains may differ (a tank's wall layers scale with ``dx``).  The probes are a
    ``probes_per_side^d`` grid over ``probe_box`` (default: the part of the domain common
    to all cases).  ``speed`` scales the network's inputs and outputs (default: the
    largest initial speed, or ``sqrt(|g| H)`` over the probe box's height ``H`` for a case
    at rest).
    """
    if isinstance(ratio, bool) or int(ratio) != ratio or int(ratio) < 1:
        raise ValueError(
            f"ratio must be a positive integer (fine steps per coarse step), got {ratio}"
        )
    if int(horizon) < 1:
        raise ValueError(f"horizon must be a positive number of coarse steps, got {horizon}")
    fines = list(fine) if isinstance(fine, list | tuple) else [fine]
    if not fines:
        raise ValueError("fine must be a Case or a non-empty list of Cases")
    if viscosities is not None and conditions is not None:
        raise ValueError("give viscosities or conditions, not both")
    if viscosities is not None:
        conditions = [{"kinematic_viscosity": nu} for nu in viscosities]
    conditions = [{}] if conditions is None else [dict(c) for c in conditions]
    if not conditions:
        raise ValueError("conditions must list at least one condition (a dict of Params)")
    dc = coarse.model.domain
    for f in fines:
        df = f.model.domain
        same = df.periodic == dc.periodic and all(
            (lc, uc) == (lf, uf)
            for lc, uc, lf, uf, per in zip(
                dc.lower, dc.upper, df.lower, df.upper, dc.periodic, strict=True
            )
            if per
        )
        if not same:
            raise ValueError(
                "coarse and fine cases must share the periodic axes and their bounds "
                "(the probes lie in one domain)"
            )
    if probe_box is None:
        probe_box = tuple(
            (
                max(d.model.domain.lower[a] for d in [coarse, *fines]),
                min(d.model.domain.upper[a] for d in [coarse, *fines]),
            )
            for a in range(coarse.model.dim)
        )
    probe_box = tuple((float(lo), float(hi)) for lo, hi in probe_box)
    if len(probe_box) != coarse.model.dim or any(lo >= hi for lo, hi in probe_box):
        raise ValueError(f"probe_box must be [[lo, hi]] * dim with lo < hi, got {probe_box}")
    dt = float(coarse.dt if dt is None else dt)
    probes = probe_grid(coarse, probes_per_side, probe_box)
    params_of, reference = [], []

    def with_(params, condition):
        return params.replace(
            **{k: jnp.asarray(v, getattr(params, k).dtype) for k, v in condition.items()}
        )

    for condition in conditions:
        fields = []
        for f in fines:
            traj = simulate(
                f,
                with_(f.params, condition),
                n_steps=horizon * ratio,
                save_every=ratio,
                dt=dt / ratio,
            )
            # the fine field seen at the coarse resolution: the coarse kernel and h
            fields.append(jax.vmap(lambda s: probe_velocity(s, coarse, probes))(traj.states))
        params_of.append((with_(coarse.params, condition), with_(fines[0].params, condition)))
        reference.append(np.mean(np.stack([np.asarray(u) for u in fields]), 0))
    if speed is None:
        speed = float(np.abs(np.asarray(coarse.state.velocity)).max())
        if speed == 0.0:
            g = float(np.linalg.norm(np.asarray(coarse.params.gravity)))
            speed = float(np.sqrt(g * (probe_box[-1][1] - probe_box[-1][0]))) or 1.0
    return Problem(
        coarse=coarse,
        fine=fines[0],
        ratio=int(ratio),
        dt=dt,
        probes=probes,
        conditions=tuple(params_of),
        reference=np.stack(reference),
        speed=float(speed),
    )


class Corrector(eqx.Module):
    """Graph network on the coarse particles: velocity increments ``[N, d]`` per step."""

    gns: GNS
    scale: float = eqx.field(static=True)
    # (rho0, (c0 / U)^2) when the density is an input, else None
    density: tuple | None = eqx.field(static=True)
    # time constants (coarse steps) of the inputs exp(-k / tau), or None
    time_scales: tuple | None = eqx.field(static=True)

    def __init__(
        self,
        problem: Problem,
        key,
        mode: str = "correction",
        latent=16,
        steps=2,
        scale=None,
        density: bool = False,
        time_scales=None,
    ):
        """``scale``: velocity per unit network output and step (default ``0.01 U`` for
        the correction, ``2 pi U^2 dt`` for the pure network, ``U = problem.speed``).  For a
        flow that starts at rest give the correction about the solver's own velocity change
        per step (the dam break: ``|g| dt``); ``0.01 sqrt(g H)`` is nine times that there.

        The network's node inputs are the velocities ``v / U``; with ``density=True`` also
        the density deviation ``(rho / rho0 - 1) (c0 / U)^2`` (the pressure over ``rho0
        U^2`` to first order, eq. 12, with the coarse case's ``rho0`` and ``c0``), which
        carries the acoustic waves that the velocities alone show only after they act.
        ``steps``: message-passing steps (each widens what a particle sees by one
        neighbour radius).

        ``time_scales=(tau_1, ...)`` (coarse steps): also the inputs ``exp(-k / tau_i)``,
        ``k`` the coarse steps since the case's initial state, the same on every particle:
        the time since the start, for a start-up transient whose correction depends on
        it (and that the velocities do not tell apart from a later state)."""
        if mode not in MODES:
            raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
        if scale is not None and not float(scale) > 0:
            raise ValueError(f"scale must be a positive velocity per step, got {scale}")
        d = problem.coarse.model.dim
        self.density = None
        if density:
            params = problem.coarse.params
            rho0 = float(np.asarray(params.reference_density))
            c0 = float(np.asarray(params.sound_speed))
            self.density = (rho0, (c0 / problem.speed) ** 2)
        if time_scales is not None:
            time_scales = tuple(float(t) for t in time_scales)
            if not time_scales or not all(t > 0 for t in time_scales):
                raise ValueError(
                    f"time_scales must be positive numbers of coarse steps, got {time_scales}"
                )
        self.time_scales = time_scales
        node_in = d + (1 if density else 0) + len(time_scales or ())
        gns = GNS(node_in, 2 * d + 1, d, key, latent=latent, hidden=latent, steps=steps)
        # start from "no correction": the zero decoder output (the coarse solver exactly)
        last = gns.decoder.weights[-1]
        gns = eqx.tree_at(lambda g: g.decoder.weights[-1], gns, jnp.zeros_like(last))
        self.gns = gns
        u, dt = problem.speed, problem.dt
        # a correction is a small fraction of the speed per step; the pure network must
        # carry the whole acceleration, ~ 2 pi U^2 / L per unit time (L = 1)
        default = 0.01 * u if mode == "correction" else 2 * np.pi * u * u * dt
        self.scale = default if scale is None else float(scale)

    def __call__(self, state: State, graph: RadiusGraph, neighbors, speed: float, step=None):
        """The velocity increments and the updated neighbour list; ``step``: the coarse
        steps since the initial state, required with ``time_scales`` (else not read)."""
        if self.time_scales is not None and step is None:
            raise ValueError(
                "a Corrector with time_scales needs step, the coarse steps since the "
                "initial state: net(state, graph, neighbors, speed, step)"
            )
        x, v = state.position, state.velocity
        n = x.shape[0]
        neighbors = graph.update(x, neighbors)
        idx = neighbors.idx
        senders = jnp.where(idx < n, idx, 0)
        size = jnp.asarray([hi - lo for lo, hi in graph.bounds], x.dtype)
        dr = minimum_image(x[:, None, :] - x[senders], size, graph.periodic) / graph.radius
        r2 = jnp.sum(dr * dr, -1, keepdims=True)
        r = jnp.sqrt(jnp.where(r2 > 0, r2, 1.0)) * (r2 > 0)
        mask = (idx < n) & (r[..., 0] < 1.0)
        dv = (v[:, None, :] - v[senders]) / speed
        edge = jnp.where(mask[..., None], jnp.concatenate([dr, r, dv], -1), 0.0)
        fluid = (state.kind == Kind.FLUID)[:, None]
        types = jnp.where(fluid[:, 0], 0, 1).astype(jnp.int32)  # fluid 0, wall 1
        nodes = v / speed
        if self.density is not None:
            rho0, factor = self.density
            deviation = (state.density / rho0 - 1.0) * factor
            nodes = jnp.concatenate([nodes, deviation[:, None].astype(v.dtype)], -1)
        if self.time_scales is not None:
            k = jnp.asarray(step, v.dtype)
            clock = jnp.exp(-k / jnp.asarray(self.time_scales, v.dtype))
            nodes = jnp.concatenate([nodes, jnp.broadcast_to(clock, (n, clock.size))], -1)
        out = self.gns(nodes, types, edge, senders, mask)
        return jnp.where(fluid, self.scale * out, 0.0), neighbors


class StagedCorrector(eqx.Module):
    """Two corrections in turn: ``early`` at the coarse steps ``k < switch`` (a start-up
    transient's), ``late`` from step ``switch`` on.  ``early`` is held fixed: its
    parameters get no gradient (so :func:`train` changes ``late`` only; Adam's update of a
    parameter that never had a gradient is zero), and only the network of the step is
    evaluated (``jax.lax.cond``).

    For a flow whose start-up and later steps ask different corrections of one network
    (the solver-in-the-loop Taylor-Green: a network trained over the whole window gives
    back at the start-up what it gains later, and one trained on the start-up loses the
    later steps), each is trained on its own steps: ``early`` over the first
    ``switch - 1`` steps, then ``StagedCorrector(early, late, switch)`` over the whole
    window, the loss of the steps before ``switch`` then fixed.  The step is the one of
    ``Corrector(time_scales=...)``: the coarse steps since the initial state, required.
    Meant for ``mode="correction"``; in ``mode="gns"`` :func:`step` hands the network
    ``k - 1``, so the late network would take over one step later."""

    early: eqx.Module
    late: eqx.Module
    switch: int = eqx.field(static=True)

    def __init__(self, early, late, switch: int):
        if isinstance(switch, bool) or int(switch) != switch or not switch >= 2:
            raise ValueError(
                f"switch must be an integer >= 2 (the first coarse step of the late "
                f"correction; step 1 is the first corrected step), got {switch!r}"
            )
        self.early, self.late, self.switch = early, late, int(switch)

    def __call__(self, state: State, graph: RadiusGraph, neighbors, speed: float, step=None):
        """The velocity increments of the network of ``step`` and the updated list."""
        if step is None:
            raise ValueError(
                "a StagedCorrector needs step, the coarse steps since the initial state: "
                "net(state, graph, neighbors, speed, step)"
            )
        arrays, rest = eqx.partition(self.early, eqx.is_array)
        early = eqx.combine(jax.lax.stop_gradient(arrays), rest)
        return jax.lax.cond(
            jnp.asarray(step) < self.switch,
            lambda s, n: early(s, graph, n, speed, step),
            lambda s, n: self.late(s, graph, n, speed, step),
            state,
            neighbors,
        )


def _graph(problem: Problem) -> RadiusGraph:
    model = problem.coarse.model
    domain = model.domain
    bounds = tuple(zip(domain.lower, domain.upper, strict=True))
    return RadiusGraph(bounds, tuple(domain.periodic), float(model.cutoff), 2.0)


def _wrap(x, case: Case):
    domain = case.model.domain
    lo = jnp.asarray(domain.lower, x.dtype)
    size = jnp.asarray(domain.size, x.dtype)
    return jnp.where(jnp.asarray(domain.periodic), lo + jnp.mod(x - lo, size), x)


def step(problem: Problem, net, mode: str, state: State, params: Params, graph, neighbors, k=None):
    """One coarse step, the ``k``-th since the initial state (``k >= 1``; required by a
    network with ``time_scales``): the solver then the correction (``mode="correction"``,
    the network reading the state after ``k`` steps), the solver alone (``net=None``), or
    the network alone (``mode="gns"``, reading the state after ``k - 1``)."""
    case = problem.coarse
    if mode == "gns":
        dv, neighbors = net(state, graph, neighbors, problem.speed, None if k is None else k - 1)
        v = state.velocity + dv
        x = _wrap(state.position + problem.dt * v, case)
        return state.replace(position=x, velocity=v), neighbors
    state = simulate(case, params, n_steps=1, dt=problem.dt, state=state).final
    if net is not None:
        dv, neighbors = net(state, graph, neighbors, problem.speed, k)
        state = state.replace(velocity=state.velocity + dv)
    return state, neighbors


def rollout(
    problem: Problem,
    net,
    mode: str,
    state: State,
    params: Params,
    n_steps: int,
    neighbors,
    truncate: int | None = None,
    start=0,
):
    """``n_steps`` coarse steps from ``state``, the state after ``start`` steps from the
    initial one: ``(states [n_steps], probe fields [n_steps, P, d], overflow)``.

    ``truncate=K``: the state is cut from the gradient (``jax.lax.stop_gradient``) after
    every ``K`` steps, so the derivative of the probe field at step ``k`` reaches the
    network only through the steps since the last cut (``k - K floor((k - 1) / K)``
    of them, 1..K); the values are unchanged."""
    graph = _graph(problem)
    probes = jnp.asarray(problem.probes, state.position.dtype)

    def body(carry, i):
        s, nbrs, over = carry
        if truncate is not None:
            cut = (i % truncate == 0) & (i > 0)
            s = jax.tree_util.tree_map(lambda a: jnp.where(cut, jax.lax.stop_gradient(a), a), s)
        s, nbrs = step(problem, net, mode, s, params, graph, nbrs, start + i + 1)
        u = probe_velocity(s, problem.coarse, probes)
        return (s, nbrs, over | overflowed(nbrs)), (s, u)

    (_, _, over), (states, fields) = jax.lax.scan(
        body, (state, neighbors, jnp.asarray(False)), jnp.arange(n_steps)
    )
    return states, fields, over


def allocate(problem: Problem):
    """The correction network's neighbour list for the coarse initial state."""
    return _graph(problem).allocate(problem.coarse.state.position)


def errors(
    problem: Problem, net, mode: str = "correction", n_steps: int | None = None
) -> np.ndarray:
    """Relative probe-velocity error ``[n_conditions, n_steps + 1]`` at coarse steps
    0..n (step 0: the two initial states, the floor set by the particle sampling)."""
    n_steps = problem.horizon if n_steps is None else int(n_steps)
    if not 1 <= n_steps <= problem.horizon:
        raise ValueError(
            f"n_steps must lie in 1..{problem.horizon} (the reference horizon), got {n_steps}"
        )
    neighbors = allocate(problem)
    run = eqx.filter_jit(
        lambda net, params: rollout(
            problem, net, mode, problem.coarse.state, params, n_steps, neighbors
        )
    )
    out = []
    for k, (pc, _) in enumerate(problem.conditions):
        _, fields, over = run(net, pc)
        if bool(over):
            raise RuntimeError("the correction's neighbour list overflowed; raise its capacity")
        u0 = probe_velocity(problem.coarse.state, problem.coarse, problem.probes)
        fields = jnp.concatenate([u0[None], fields])
        ref = jnp.asarray(problem.reference[k, : n_steps + 1])
        out.append(np.asarray(relative_error(fields, ref)))
    return np.stack(out)


def coarse_weights(problem: Problem) -> np.ndarray:
    """``1 / (e^c_k)^2`` ``[n_conditions, horizon + 1]``: the weights of
    ``train(loss="relative_to_coarse")``, from the coarse solver's own error ``e^c_k``
    (:func:`errors` with ``net=None``; step 0 is never in a loss and weighs 0).  Refuses
    a coarse error of zero after step 0 (a coarse run that is the reference leaves no
    ratio to optimise)."""
    coarse = errors(problem, None)
    if not np.all(coarse[:, 1:] > 0):
        raise ValueError(
            'loss="relative_to_coarse" needs a non-zero coarse-solver error at every step '
            'after the start (the coarse run equals the reference); use loss="relative"'
        )
    weights = np.zeros_like(coarse)
    weights[:, 1:] = 1.0 / coarse[:, 1:] ** 2
    return weights


@dataclasses.dataclass
class TrainResult:
    """What :func:`train` returns.

    Attributes:
      net: the trained network.
      losses: the loss of every iteration of this call (before its update).
      seconds, cpu_seconds: wall and process CPU seconds of this call, after compiling.
      iterations: the iterations of this call.
      opt_state: the optimiser state after the last update (Adam's moments and its step
        count, which is the schedule's step): pass it back as ``train(opt_state=...)`` to
        continue this training.
    """

    net: object
    losses: list
    seconds: float
    iterations: int
    cpu_seconds: float = float("nan")
    opt_state: object = None


def optimizer(lr: float | optax.Schedule = 1e-3, clip: float = 1.0):
    """The optimiser of :func:`train`: Adam with learning rate (or optax schedule) ``lr``,
    gradients clipped to global norm ``clip``.  ``optimizer(lr, clip).init(eqx.filter(net,
    eqx.is_array))`` has the structure of ``TrainResult.opt_state`` (a template to read a
    saved state into, e.g. with ``eqx.tree_deserialise_leaves``)."""
    # clipped gradients: an unrolled solver has occasional large gradients
    return optax.chain(optax.clip_by_global_norm(clip), optax.adam(lr))


def completed_iterations(opt_state) -> int:
    """The updates an optimiser state of :func:`train` has made (Adam's step count)."""
    counts = [
        s.count
        for s in jax.tree_util.tree_leaves(
            opt_state, is_leaf=lambda s: isinstance(s, optax.ScaleByAdamState)
        )
        if isinstance(s, optax.ScaleByAdamState)
    ]
    if len(counts) != 1:
        raise ValueError("opt_state is not an optimiser state of train (one Adam state)")
    return int(counts[0])


def train(
    problem: Problem,
    net,
    *,
    mode: str = "correction",
    unroll: int = 10,
    iterations: int | None = None,
    seconds: float | None = None,
    lr: float | optax.Schedule = 1e-3,
    clip: float = 1.0,
    refresh_every: int = 25,
    seed: int = 0,
    loss: str = "relative",
    startup_steps: int | None = None,
    startup_weight: float | None = None,
    truncate: int | None = None,
    power: float = 2.0,
    opt_state=None,
    log=print,
) -> TrainResult:
    """Train ``net`` by back-propagating through ``unroll`` coarse steps (solver included).

    Each iteration draws a condition and a start step ``s`` (a multiple of ``unroll``);
    the start state is the model's own rollout at ``s`` (refreshed every
    ``refresh_every`` iterations, no gradient through it).  The loss over the window's
    steps ``k = s+1 .. s+unroll``, with ``e_k`` the relative probe-velocity error against
    the fine reference:

    - ``loss="relative"`` (default): ``mean_k e_k^2``; steps where every model errs little
      (a start-up transient's minima) weigh little.
    - ``loss="relative_to_coarse"``: ``mean_k e_k^2 / (e^c_k)^2``, ``e^c_k`` the coarse
      solver's own error at step ``k`` from the case's initial state (computed once per
      condition before training, no gradient through it): the mean squared ratio to the
      coarse solver, which weighs every step by what the comparison asks of it (at most
      a fraction of the coarse error at each step).  The untrained (zero) correction
      gives 1 on a window from step 0.

    ``startup_steps=m`` (with ``startup_weight=w``, default 1) adds to either loss the
    mean over the first ``m`` steps of the same per-step term ``q_k`` (``e_k^2`` or
    ``e_k^2 / (e^c_k)^2``), weighted by ``w``:

        L = mean_{k in window} q_k  +  (w / m) sum_{k in window, k <= m} q_k

    With ``unroll`` equal to the horizon (one window from step 0) that is ``mean_{k=1..H}
    q_k + w mean_{k=1..m} q_k``: both terms from the same rollout, at no extra cost, and
    with ``w = 1`` the first ``m`` steps count as much in total as the whole window.  A
    window that starts after step ``m`` has no start-up term.

    ``power=p`` (default 2): the per-step term is ``q_k = r_k^p`` with ``r_k = e_k`` (or
    ``e_k / e^c_k``) and the loss is the ``2/p`` power of the sum above,

        L = ( mean_{k in window} r_k^p  +  (w / m) sum_{k in window, k <= m} r_k^p )^(2/p)

    the same as above at ``p = 2``; as ``p`` grows it tends to the square of the largest
    ratio in the window (a soft maximum over the steps), so the steps furthest from the
    target weigh most, whichever they are.

    ``truncate=K``: truncated back-propagation through the window's rollout (see
    :func:`rollout`): a step's loss trains the network only through the last (at most
    ``K``) steps before it, not through the whole window; the loss values are those of the
    full rollout.

    Adam with gradients clipped to global norm ``clip`` (:func:`optimizer`); ``lr`` is a
    number or an optax schedule of the iteration (e.g. ``optax.exponential_decay``, so the
    steps shrink as the correction settles).  Budget of this call: ``iterations`` and/or
    wall-clock ``seconds`` (after compiling); the result also records the process's CPU
    seconds over the same span.

    ``opt_state``: continue an earlier training, given its network and its
    ``TrainResult.opt_state`` (default: a new Adam state).  The state carries Adam's
    moments and its step count ``n``; the schedule continues from step ``n``, and the
    windows are drawn by iteration number (``seed`` and the iteration since the first
    piece) and the start states refreshed at every ``refresh_every``-th of them, so a
    training split into pieces, each given the network and state of the one before (and
    the same arguments), equals one uninterrupted training to round-off; only the start
    states are recomputed at every piece's start (with the network they then have).
    """
    if loss not in LOSSES:
        raise ValueError(f"loss must be one of {', '.join(LOSSES)}, got {loss!r}")
    if iterations is None and seconds is None:
        raise ValueError("give iterations or seconds (the training budget)")
    if not callable(lr) and not float(lr) > 0:
        raise ValueError(f"lr must be a positive number or an optax schedule, got {lr}")
    if not 1 <= unroll <= problem.horizon:
        raise ValueError(
            f"unroll must lie in 1..{problem.horizon} (the reference horizon), got {unroll}"
        )
    if startup_weight is not None and startup_steps is None:
        raise ValueError(
            "startup_weight has no effect without startup_steps; give startup_steps=m "
            "(the first m steps of the rollout) or leave startup_weight out"
        )
    if startup_steps is not None:
        if isinstance(startup_steps, bool) or int(startup_steps) != startup_steps:
            raise ValueError(f"startup_steps must be an integer, got {startup_steps!r}")
        if not 1 <= startup_steps < problem.horizon:
            raise ValueError(
                f"startup_steps must lie in 1..{problem.horizon - 1} (fewer than the horizon; "
                f"all {problem.horizon} steps would only rescale the loss), got {startup_steps}"
            )
        startup_weight = 1.0 if startup_weight is None else float(startup_weight)
        if not startup_weight > 0:
            raise ValueError(
                f"startup_weight must be positive (0 adds nothing; leave startup_steps out), "
                f"got {startup_weight}"
            )
    if truncate is not None and (
        isinstance(truncate, bool) or int(truncate) != truncate or not 1 <= truncate < unroll
    ):
        raise ValueError(
            f"truncate must be an integer in 1..{unroll - 1} (steps back-propagated, fewer "
            f"than unroll; leave it out for the whole window), got {truncate!r}"
        )
    if isinstance(power, bool) or not (math.isfinite(float(power)) and float(power) >= 2):
        raise ValueError(
            f"power must be a finite number >= 2 (2: the mean square; larger: nearer the "
            f"largest step), got {power!r}"
        )
    power = float(power)
    neighbors = allocate(problem)
    n_starts = problem.horizon // unroll
    reference = jnp.asarray(problem.reference)
    # per condition and step 0..horizon, the weight of e_k^2 in the loss
    if loss == "relative_to_coarse":
        weights = coarse_weights(problem)
    else:
        weights = np.ones(problem.reference.shape[:2])
    weights = jnp.asarray(weights, reference.dtype)
    # per step 0..horizon, the start-up term's factor: w / m on steps 1..m, else 0
    startup = np.zeros(problem.horizon + 1)
    if startup_steps is not None:
        startup[1 : startup_steps + 1] = startup_weight / startup_steps
    startup = jnp.asarray(startup, reference.dtype)

    def loss_fn(net, state, params, ref, weight, extra, start):
        _, fields, over = rollout(
            problem, net, mode, state, params, unroll, neighbors, truncate=truncate, start=start
        )
        q = (weight * relative_error(fields, ref) ** 2) ** (power / 2)
        value = jnp.mean(q)
        if startup_steps is not None:
            value = value + jnp.sum(extra * q)
        if power != 2.0:
            value = value ** (2 / power)
        return value, over

    adam = optimizer(lr, clip)
    fresh = adam.init(eqx.filter(net, eqx.is_array))
    if opt_state is None:
        opt_state = fresh
    elif jax.tree_util.tree_structure(opt_state) != jax.tree_util.tree_structure(fresh) or any(
        np.shape(a) != np.shape(b)
        for a, b in zip(
            jax.tree_util.tree_leaves(opt_state), jax.tree_util.tree_leaves(fresh), strict=True
        )
    ):
        raise ValueError(
            "opt_state does not fit this network and lr (a schedule's state differs from a "
            "constant learning rate's): pass the TrainResult.opt_state of a training of the "
            "same network with the same kind of lr"
        )
    first = completed_iterations(opt_state)

    @eqx.filter_jit
    def update(net, opt_state, state, params, ref, weight, extra, start):
        (loss, over), grads = eqx.filter_value_and_grad(loss_fn, has_aux=True)(
            net, state, params, ref, weight, extra, start
        )
        leaves = jax.tree_util.tree_leaves(eqx.filter(grads, eqx.is_array))
        finite = jnp.all(jnp.stack([jnp.all(jnp.isfinite(g)) for g in leaves]))
        updates, opt_state = adam.update(grads, opt_state, eqx.filter(net, eqx.is_array))
        return eqx.apply_updates(net, updates), opt_state, loss, over, finite

    @eqx.filter_jit
    def starts_of(net, params):
        states, _, _ = rollout(
            problem, net, mode, problem.coarse.state, params, n_starts * unroll, neighbors
        )
        return states

    def refresh(net):
        out = []
        for pc, _ in problem.conditions:
            states = starts_of(net, pc)  # after steps 1..n; prepend the initial state
            first = jax.tree_util.tree_map(lambda a: a[None], problem.coarse.state)
            allst = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), first, states)
            out.append(jax.tree_util.tree_map(lambda a: a[0 : n_starts * unroll : unroll], allst))
        return out

    # the training programs are traced with the solver's failures reported as NaN (which
    # the finite-gradient check below stops on), not by host callbacks: JAX writes no
    # program with a host callback to its persistent compilation cache
    with failures_as_nan():
        starts = refresh(net)
    losses = []
    t0, c0 = time.perf_counter(), time.process_time()
    k = 0
    while True:
        elapsed = time.perf_counter() - t0
        if (iterations is not None and k >= iterations) or (
            seconds is not None and elapsed >= seconds
        ):
            break
        # the window of iteration first + k, whichever piece of a split training runs it
        rng = np.random.default_rng((seed, first + k))
        c = int(rng.integers(len(problem.conditions)))
        j = int(rng.integers(n_starts))
        state = jax.tree_util.tree_map(lambda a, j=j: a[j], starts[c])
        window = slice(j * unroll + 1, (j + 1) * unroll + 1)
        with failures_as_nan():
            new_net, new_opt_state, value, over, finite = update(
                net,
                opt_state,
                state,
                problem.conditions[c][0],
                reference[c, window],
                weights[c, window],
                startup[window],
                jnp.asarray(j * unroll),  # traced: one program for every window
            )
        if bool(over):
            raise RuntimeError("the correction's neighbour list overflowed; raise its capacity")
        if not bool(finite):  # Adam would write NaN into every weight
            raise FloatingPointError(
                f"train: the gradient through the unrolled solver is not finite at iteration "
                f"{first + k + 1} (condition {c}, start {j}, loss {float(value):.4g}); stopped "
                f"before an update that would make every weight NaN (an unstable coarse step "
                f"gives NaN too): lower lr or unroll, or use float64"
            )
        net, opt_state = new_net, new_opt_state
        losses.append(float(value))
        k += 1
        if k == 1:
            t0, c0 = time.perf_counter(), time.process_time()  # budget: after compiling
        if (first + k) % refresh_every == 0:
            with failures_as_nan():
                starts = refresh(net)
            mean = np.mean(losses[-refresh_every:])
            log(f"iteration {first + k:5d}  t={time.perf_counter() - t0:7.1f}s  loss {mean:.4e}")
    return TrainResult(
        net, losses, time.perf_counter() - t0, k, time.process_time() - c0, opt_state
    )
